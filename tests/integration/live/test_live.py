"""`eoloc live` on real UDP sockets over loopback: the mountain flight's packets sent as datagrams
with faults (a corrupt packet, duplicates, reordering, a datagram that is not KLV, an encoder
restart, silence), located as they arrive, written as NDJSON; the result compared with `eoloc klv`
on the same stream (the batch path), and the stop by SIGINT with its summary."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from livecmd import summary_of, until_listening, wait_for_packets
from ports import free_udp_port

import eoloc
from eoloc.io.klv.reader import split_klv
from eoloc.io.klv.synthetic import circling_flight_klv
from eoloc.jobs.klv import klv_job
from eoloc.live.session import LiveSession
from eoloc.terrain import open_dem

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT = MOUNTAIN / "flight.klv"
DEM = MOUNTAIN / "longs_peak_srtmgl3.tif"


def _packets(path: Path) -> list[bytes]:
    return [raw for raw, _ in split_klv(path.read_bytes())]


def _targets(updates) -> list[dict]:
    """The target features of live packet updates."""
    return [f for u in updates for f in u.features() if f["properties"]["what"] == "target"]


def _batch_fixes() -> dict[tuple[float, str], tuple[float, float, float]]:
    """`eoloc klv`'s located targets by (packet time, target id)."""
    job = klv_job(FLIGHT, dem=open_dem(DEM))
    r = job.records
    return {(float(f), str(t)): (la, lo, h) for f, t, la, lo, h, st in
            zip(r["time_s"], r["target_id"], r["lat_deg"], r["lon_deg"], r["h_m"], r["status"], strict=True)
            if st == "OK"}


def test_live_over_udp_with_faults_equals_the_batch_path(tmp_path):
    port = free_udp_port()
    out = tmp_path / "fixes.ndjson"
    proc = subprocess.Popen([str(Path(sys.executable).parent / "eoloc"), "live", f"udp://127.0.0.1:{port}",
                             "--dem", str(DEM), "--ndjson", str(out), "--silence", "0.5"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    packets = _packets(FLIGHT)
    assert len(packets) == 40  # 39 good + the demo's corrupted packet 17
    sends = list(packets)
    sends.insert(5, packets[4])  # a duplicate
    sends[10], sends[11] = sends[11], sends[10]  # reordered
    sends.insert(20, b"\x00hello, not KLV")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    head = until_listening(proc)  # the receiver has bound its socket (it imports eoloc and reads the DEM first)
    said: list[str] = []
    pump = threading.Thread(target=lambda: said.extend(iter(proc.stdout.readline, "")), daemon=True)
    pump.start()
    for d in sends:
        tx.sendto(d, ("127.0.0.1", port))
        time.sleep(0.01)
    # silence: waited for until eoloc says it (it works off its backlog first, however slow the machine)
    deadline = time.monotonic() + 120
    while not any("silence" in line for line in list(said)):
        assert time.monotonic() < deadline and proc.poll() is None, "".join(said)
        time.sleep(0.05)
    restart = circling_flight_klv(3, seed=1)  # another encoder clock, years earlier: a restart
    tx.sendto(restart, ("127.0.0.1", port))
    assert wait_for_packets(out, 39 + 3, proc) == 39 + 3
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    pump.join(timeout=30)
    log = head + "".join(said)
    assert proc.returncode == 0, log
    assert "Traceback" not in log
    summary = summary_of(log, "eoloc live stopped (SIGINT)")
    assert summary["packets"] == 39 + 3 and summary["duplicates"] == 1 and summary["corrupt"] == 1
    assert summary["not_klv"] == 1 and summary["late"] >= 1 and summary["restarts"] == 1
    assert summary["latency_ms_median"] < 50
    assert "silence" in log and "checksum" in log and "datagram" in log
    rows = [json.loads(line) for line in out.read_text(encoding="utf-8").splitlines()]
    assert {r["properties"]["what"] for r in rows} == {"aircraft", "footprint", "frame centre", "target", "estimate"}
    rows = [r for r in rows if r["properties"]["what"] == "target"]
    mountain = [r for r in rows if r["properties"]["time_s"] > 1.7e9]  # not the restart's packets
    ref = _batch_fixes()
    got = {(r["properties"]["time_s"], str(r["properties"]["target_id"])): r for r in mountain
           if r["properties"]["status"] == "OK"}
    assert len(got) == len(ref) == 103
    for key, (la, lo, h) in ref.items():
        lon_l, lat_l, h_l = got[key]["geometry"]["coordinates"]
        assert abs(lat_l - la) < 1e-12 and abs(lon_l - lo) < 1e-12 and abs(h_l - h) < 1e-6


def test_report_on_change_values_are_carried_between_datagrams(tmp_path):
    """Packets that leave out what has not changed (the field of view, the position) are located
    with the last values sent, as in a file."""
    from eoloc.io.klv.encode import build_uas_packet, uas_items

    full = _packets(FLIGHT)[:3]
    session = LiveSession("udp://test", dem=open_dem(DEM))
    first = _targets(session.feed(full[0]))
    # packet 1 with the field of view (16, 17) and the platform position (13, 14, 15) left out
    thin = build_uas_packet([(t, v) for t, v in uas_items(full[1]) if t not in (16, 17, 13, 14, 15)])
    got = _targets(session.feed(thin))
    assert first and got
    # the file reader fills report-on-change values forward within a file: the same two packets as
    # a file must give the same points
    path = tmp_path / "carried.klv"
    path.write_bytes(full[0] + thin)
    r = klv_job(path, dem=open_dem(DEM)).records
    second = r["frame"] == 1
    assert second.sum() == len(got)
    for a, la, lo, st in zip(got, r["lat_deg"][second], r["lon_deg"][second], r["status"][second], strict=True):
        assert a["properties"]["status"] == st
        if st == "OK":
            lon_l, lat_l = a["geometry"]["coordinates"][:2]
            assert abs(lon_l - lo) < 1e-12 and abs(lat_l - la) < 1e-12
    assert any(a["properties"]["status"] == "OK" for a in got)


@pytest.mark.parametrize("args, words", [
    (["udp://nohost", "--ndjson", "x"], "udp://HOST:PORT"),
    (["rtsp://nohost.invalid/1", "--ndjson", "x"], "FFmpeg cannot open it"),
    (["udp://127.0.0.1:1"], "at least one output"),
    (["udp://127.0.0.1:1", "--cot", "http://tak:8087"], "tcp://HOST:PORT"),
    (["udp://127.0.0.1:1", "--cot", "udp://239.2.3.1:6969?ttl=x"], "ttl must be"),
])
def test_unsupported_sources_and_outputs_are_named(args, words, tmp_path):
    r = subprocess.run([str(Path(sys.executable).parent / "eoloc"), "live", *args], capture_output=True, text=True,
                       timeout=60, cwd=tmp_path)
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_a_late_packet_does_not_replace_the_newer_values_carried(tmp_path):
    """Packets 0, 2, then 1 late, then packet 3 without its position: packet 3 takes packet 2's
    position (the newest sent), as the file reader gives it for 0, 2, 3 in order."""
    from eoloc.io.klv.encode import build_uas_packet, uas_items

    full = _packets(FLIGHT)[:4]
    thin = build_uas_packet([(t, v) for t, v in uas_items(full[3]) if t not in (13, 14, 15)])
    session = LiveSession("udp://test", dem=open_dem(DEM))
    for d in (full[0], full[2], full[1]):
        session.feed(d)
    assert session.counters.late == 1
    got = _targets(session.feed(thin))
    path = tmp_path / "in_order.klv"
    path.write_bytes(full[0] + full[2] + thin)
    r = klv_job(path, dem=open_dem(DEM)).records
    last = r["frame"] == 2
    assert last.sum() == len(got) > 0
    for a, la, lo, st in zip(got, r["lat_deg"][last], r["lon_deg"][last], r["status"][last], strict=True):
        assert a["properties"]["status"] == st
        if st == "OK":
            lon_l, lat_l = a["geometry"]["coordinates"][:2]
            assert abs(lon_l - lo) < 1e-12 and abs(lat_l - la) < 1e-12


def test_the_target_filter_is_chosen_by_track_and_the_old_refine_still_works(tmp_path):
    """`eoloc live FILE --track moving` puts the Kalman estimate of each target in the NDJSON; the
    flag's old name (`--refine moving`, renamed so that --refine means one thing across commands:
    refining the telemetry from the pixels) gives the same lines with a deprecation warning."""
    lines = {}
    for name in ("--track", "--refine"):
        r = subprocess.run([str(Path(sys.executable).parent / "eoloc"), "live", str(FLIGHT), "--ndjson", "-",
                            "--packets", "40", name, "moving"], capture_output=True, text=True, timeout=120,
                           cwd=tmp_path)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        rows = [json.loads(x) for x in r.stdout.splitlines() if x.strip()]
        estimates = [x for x in rows if x["properties"]["what"] == "estimate"]
        assert estimates and all(x["properties"]["model"] == "moving (Kalman)" for x in estimates)
        lines[name] = (r.stdout, r.stderr)
    assert lines["--track"][0] == lines["--refine"][0]
    assert "deprecated" not in lines["--track"][1]
    assert "--refine moving is now --track moving" in lines["--refine"][1]
