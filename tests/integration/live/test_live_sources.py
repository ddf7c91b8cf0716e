"""`eoloc live` on the network sources FFmpeg opens, each from a real sender on loopback:

- RTSP: GStreamer's RTSP server (tests/helpers/rtsp_server.py; Debian's gst-rtsp-server, `make streams`)
  serving a two-PID transport stream as MPEG-TS over RTP at its own clock; read through PyAV's
  RTSP demultiplexer.
- SRT: SRT's own `srt-live-transmit` as the encoder's SRT output (a listener fed by UDP), eoloc
  the caller through its srt-live-transmit bridge (PyAV's FFmpeg has no libsrt).
- TCP and HTTP: a socket server and Python's http.server sending the TS bytes, read through
  FFmpeg's protocols and cut into whole transport packets.

Each must give exactly what `eoloc live FILE` gives on the same TS (the NDJSON lines, compared as
sorted sets: two PIDs may interleave differently), with every packet and CoT event accounted for;
and a source that cannot be reached gets a message naming it, with no traceback."""

from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from livecmd import summary_of
from ports import free_tcp_port, free_udp_port
from where import HELPERS

from eoloc.io.klv.mux import write_klv_ts
from eoloc.io.klv.reader import split_klv
from eoloc.io.klv.synthetic import circling_flight_klv
from eoloc.live.sources import file_datagrams

EOLOC = str(Path(sys.executable).parent / "eoloc")
SYSTEM_PYTHON = "/usr/bin/python3"  # Debian's, which has python3-gi for the RTSP server
RTSP_SERVER = HELPERS / "rtsp_server.py"
N_PACKETS, N_TARGETS = 80, 400  # two 10 Hz streams of 40 packets, 5 VMTI targets each


@pytest.fixture(scope="module")
def stream(tmp_path_factory):
    """The two-PID TS and what `eoloc live FILE --ndjson -` makes of it."""
    tmp = tmp_path_factory.mktemp("sources")
    ts = write_klv_ts(tmp / "ten_hz.ts", [split_klv(circling_flight_klv(40, seed=1)),
                                          split_klv(circling_flight_klv(40, seed=2))])
    ref = subprocess.run([EOLOC, "live", str(ts), "--ndjson", "-"], capture_output=True, text=True, timeout=120)
    assert ref.returncode == 0, ref.stderr
    lines = sorted(ref.stdout.splitlines())
    assert sum('"what": "target"' in x for x in lines) == N_TARGETS
    return ts, lines


@pytest.fixture(scope="module")
def slow_stream(tmp_path_factory):
    """The same two flights at 2 Hz (20 s of stream): long enough that a server killed once eoloc
    has written a few packets dies mid-stream, however long FFmpeg's RTSP probe buffers first."""
    tmp = tmp_path_factory.mktemp("slow")
    ts = write_klv_ts(tmp / "two_hz.ts", [split_klv(circling_flight_klv(40, seed=1, rate_hz=2.0)),
                                          split_klv(circling_flight_klv(40, seed=2, rate_hz=2.0))])
    ref = subprocess.run([EOLOC, "live", str(ts), "--ndjson", "-"], capture_output=True, text=True, timeout=120)
    assert ref.returncode == 0, ref.stderr
    return ts, sorted(ref.stdout.splitlines())


def _live(source: str, *extra: str, started=None, timeout: float = 60.0) -> tuple[list[str], dict]:
    """`eoloc live SOURCE --ndjson - --packets 80 ...`; ``started(proc)`` runs once it says where it
    reads from. Returns its NDJSON lines, sorted, and its summary."""
    proc = subprocess.Popen([EOLOC, "live", source, "--ndjson", "-", "--packets", str(N_PACKETS), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err: list[str] = []
    out: list[str] = []
    readers = [threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True),
               threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True)]
    for r in readers:
        r.start()
    deadline = time.monotonic() + 30
    while not any("eoloc live: " in line for line in err):
        assert proc.poll() is None and time.monotonic() < deadline, "".join(err)
        time.sleep(0.05)
    if started is not None:
        started(proc)
    proc.wait(timeout=timeout)
    for r in readers:
        r.join()
    log = "".join(err)
    assert proc.returncode == 0 and "Traceback" not in log, log
    return sorted(line.rstrip("\n") for line in out), summary_of(log)


def _check(summary: dict) -> None:
    assert summary["packets"] == N_PACKETS and summary["fixes_ok"] == N_TARGETS
    assert summary["corrupt"] == summary["duplicates"] == summary["not_klv"] == 0
    assert summary["streams"] == {"PID 256": 40, "PID 257": 40}


@pytest.fixture
def rtsp_server(stream):
    port = free_tcp_port()
    proc = subprocess.Popen([SYSTEM_PYTHON, str(RTSP_SERVER), str(stream[0]), str(port)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    assert proc.stdout.readline().strip() == "ready", proc.communicate(timeout=10)[0]
    yield f"rtsp://127.0.0.1:{port}/stream"
    proc.terminate()
    proc.wait(timeout=10)


def test_rtsp_from_a_real_rtsp_server_gives_what_the_file_gives(stream, rtsp_server, tmp_path):
    """MPEG-TS over RTP from gst-rtsp-server, paced at the stream's clock (4 s), with CoT out."""
    from livecmd import CotReceiver

    cot_port = free_udp_port()
    with CotReceiver(f"udp://127.0.0.1:{cot_port}") as rx:
        started = time.monotonic()
        lines, summary = _live(rtsp_server, "--cot", f"udp://127.0.0.1:{cot_port}")
        took = time.monotonic() - started
        rx.wait_for(summary["cot"][0]["sent"])
    assert lines == stream[1]
    _check(summary)
    assert took > 3.5  # sent at its own clock (3.9 s of packets), not at once
    targets = [e for e in rx.events if e.get("type") == "a-u-G"]
    assert len(targets) == N_TARGETS and rx.bad == [] and len(rx.events) == summary["cot"][0]["sent"]


def test_srt_through_srt_live_transmit_gives_what_the_file_gives(stream):
    """The encoder's SRT output (srt-live-transmit, listener, fed the TS by UDP at its own clock);
    eoloc live srt://... calls it through its own srt-live-transmit bridge."""
    udp_in, srt_port = free_udp_port(), free_udp_port()
    sender = subprocess.Popen(["srt-live-transmit", f"udp://127.0.0.1:{udp_in}", f"srt://:{srt_port}"],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    said: list[str] = []
    threading.Thread(target=lambda: said.extend(sender.stdout), daemon=True).start()

    def send(_proc) -> None:
        deadline = time.monotonic() + 20
        while not any("Accepted SRT target connection" in line for line in said):  # eoloc's bridge called in
            assert time.monotonic() < deadline, "".join(said)
            time.sleep(0.05)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for d, _ in file_datagrams(str(stream[0]), lambda: False, realtime=True):
            tx.sendto(d, ("127.0.0.1", udp_in))

    try:
        lines, summary = _live(f"srt://127.0.0.1:{srt_port}", started=send)
    finally:
        sender.terminate()
        sender.wait(timeout=10)
    assert lines == stream[1]
    _check(summary)
    assert summary["datagrams"] < N_PACKETS  # SRT carried the 1316-byte datagrams (seven TS packets) as they came


def test_tcp_and_http_byte_streams_give_what_the_file_gives(stream, tmp_path):
    ts, ref = stream
    data = ts.read_bytes()
    srv = socket.create_server(("127.0.0.1", 0))
    port = srv.getsockname()[1]

    def serve_tcp() -> None:
        conn, _ = srv.accept()
        with conn:
            for k in range(0, len(data), 1000):  # pieces that do not fall on transport packet boundaries
                conn.sendall(data[k:k + 1000])
                time.sleep(0.001)

    threading.Thread(target=serve_tcp, daemon=True).start()
    lines, summary = _live(f"tcp://127.0.0.1:{port}")
    srv.close()
    assert lines == ref
    _check(summary)

    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(ts.parent))
    handler.log_message = lambda *a: None
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        lines, summary = _live(f"http://127.0.0.1:{httpd.server_address[1]}/{ts.name}")
    finally:
        httpd.shutdown()
    assert lines == ref
    _check(summary)


def test_unreachable_or_unsupported_sources_are_named_without_a_traceback(tmp_path):
    closed = free_tcp_port()
    for url, said in [(f"rtsp://127.0.0.1:{closed}/x", "Connection refused"),
                      (f"tcp://127.0.0.1:{closed}", "Connection refused"),
                      ("ftp://example.org/x.ts", "eoloc live reads udp://")]:
        r = subprocess.run([EOLOC, "live", url, "--ndjson", "-"], capture_output=True, text=True, timeout=60)
        assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
        assert url in r.stderr and said in r.stderr, r.stderr
    # SRT without srt-live-transmit on the PATH: how to get it, and how to relay by hand
    path = tmp_path / "bin"
    path.mkdir()
    os.symlink(sys.executable, path / "python")
    env = {**os.environ, "PATH": str(path)}
    assert shutil.which("srt-live-transmit", path=str(path)) is None
    r = subprocess.run([EOLOC, "live", "srt://127.0.0.1:9", "--ndjson", "-"], capture_output=True, text=True,
                       timeout=60, env=env)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "apt install srt-tools" in r.stderr and "srt-live-transmit srt://127.0.0.1:9 udp://" in r.stderr


def _targets(lines: list[str]) -> dict:
    """(stream, packet time, target id) -> the target's coordinates, of NDJSON lines."""
    out = {}
    for line in lines:
        f = json.loads(line)
        p = f["properties"]
        if p["what"] == "target" and f["geometry"] is not None:
            out[(p["stream"], p["time_utc"], p["target_id"])] = f["geometry"]["coordinates"]
    return out


def test_rtsp_server_restarting_is_reconnected_and_nothing_is_lost_or_doubled(slow_stream):
    """The RTSP server dies mid-stream and comes back a second later on the same port, serving the
    stream from its start: eoloc live reconnects (with back-off, saying so), drops the packets it
    had already (duplicates) and ends with every packet once: the file's targets exactly."""
    ts, ref = slow_stream
    port = free_tcp_port()

    def serve():
        proc = subprocess.Popen([SYSTEM_PYTHON, str(RTSP_SERVER), str(ts), str(port)], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        assert proc.stdout.readline().strip() == "ready"
        return proc

    servers = [serve()]

    def restart(proc) -> None:
        deadline = time.monotonic() + 60
        # the first server's packets arrive: a few of the 80, so that it dies mid-stream however fast
        # or slow this machine is (not after a fixed time, by which it may have sent them all)
        while sum('"what": "aircraft"' in line for line in list(out_lines)) < 6:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        servers[0].kill()
        servers[0].wait(timeout=10)
        time.sleep(1.0)
        servers.append(serve())

    out_lines: list[str] = []
    try:
        lines, summary, log = _live_collect(f"rtsp://127.0.0.1:{port}/stream", restart, out_lines)
    finally:
        for s in servers:
            s.kill()
            s.wait(timeout=10)
    assert summary["packets"] == N_PACKETS and summary["fixes_ok"] == N_TARGETS and summary["corrupt"] == 0
    assert summary["streams"] == {"PID 256": 40, "PID 257": 40}
    assert summary["reconnects"] == 1 and summary["duplicates"] >= 5, summary  # the replayed start: dropped
    assert "reconnecting in 0.5 s" in log and "reconnected" in log
    assert _targets(lines) == _targets(ref)


def _live_collect(source: str, started, out_lines: list[str]) -> tuple[list[str], dict, str]:
    """As :func:`_live`, the NDJSON lines also appended to ``out_lines`` as they come (for
    ``started`` to watch); returns the log too."""
    proc = subprocess.Popen([EOLOC, "live", source, "--ndjson", "-", "--packets", str(N_PACKETS)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err: list[str] = []
    readers = [threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True),
               threading.Thread(target=lambda: out_lines.extend(proc.stdout), daemon=True)]
    for r in readers:
        r.start()
    started(proc)
    proc.wait(timeout=120)
    for r in readers:
        r.join()
    log = "".join(err)
    assert proc.returncode == 0 and "Traceback" not in log, log
    return sorted(line.rstrip("\n") for line in out_lines), summary_of(log), log
