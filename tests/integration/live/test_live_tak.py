"""Cursor-on-Target to TAK over TCP: through a real TAK server (FreeTAKServer on loopback) to a
TAK client connected to it, and the sender's faults — the server down at the start, restarting
mid-stream, a full queue — on a plain TCP server."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from livecmd import summary_of, until_listening, wait_for_packets, wait_until
from ports import free_tcp_port, free_udp_port
from tak_server import TakClient, freetakserver

import eoloc
from eoloc.io.klv.reader import decode_klv_bytes, split_klv
from eoloc.live.cotfeed import CotFeed
from eoloc.live.senders import TcpSender

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT, DEM, CONFIG = MOUNTAIN / "flight.klv", MOUNTAIN / "longs_peak_srtmgl3.tif", MOUNTAIN / "klv.toml"
EOLOC = str(Path(sys.executable).parent / "eoloc")


def test_targets_reach_a_tak_client_through_freetakserver(tmp_path):
    """The mountain flight sent to `eoloc live` over UDP, CoT by TCP to FreeTAKServer, read back by
    a TAK client connected to the server: every event arrives, each target where eoloc put it."""
    out = tmp_path / "live.ndjson"
    port_in = free_udp_port()
    with freetakserver(tmp_path) as port:
        client = TakClient(port)
        client.wait_for(lambda evs: any(e.get("type") == "b-t-f" for e in evs), 60)  # its welcome: routing is up
        proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port_in}", "--dem", str(DEM), "--config",
                                 str(CONFIG), "--cot", f"tcp://127.0.0.1:{port}", "--ndjson", str(out),
                                 "--silence", "1"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        until_listening(proc)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for raw, _ in split_klv(FLIGHT.read_bytes()):
            tx.sendto(raw, ("127.0.0.1", port_in))
            time.sleep(0.05)
        ours = lambda evs: [e for e in evs if e.get("uid", "").startswith("eoloc-")]  # noqa: E731
        # the last packet located and its events written (NDJSON is flushed per packet), then stopped:
        # the summary says how many events went out, and the client waits for exactly those
        wait_for_packets(out, len(decode_klv_bytes(FLIGHT.read_bytes()).packets), proc)
        head = []  # and then the stream's silence reported (--silence 1): the stale aircraft sent
        while not head or "nothing received for" not in head[-1]:
            head.append(proc.stdout.readline())
            assert head[-1] or proc.poll() is None, "".join(head)
        proc.send_signal(signal.SIGINT)
        log, _ = proc.communicate(timeout=30)
        log = "".join(head) + log
        summary = summary_of(log)
        client.wait_for(lambda evs: len(ours(evs)) >= summary["cot_events"], 120)  # the server relays at its pace
        client.close()
    assert proc.returncode == 0 and "Traceback" not in log, log
    sent = summary["cot"][0]
    assert sent["sent"] == summary["cot_events"] and sent["lost"] == sent["dropped"] == 0 and sent["connects"] == 1
    relayed = ours(client.events)
    assert len(relayed) == summary["cot_events"]  # every event the server got reached the client
    targets = [e for e in relayed if e.get("type") == "a-u-G"]
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    fixes = [f for f in rows if f["properties"]["what"] == "target" and f["properties"]["status"] == "OK"]
    assert len(targets) == len(fixes) == summary["fixes_ok"] > 100
    # the server's routing workers may reorder events: each relayed target is matched to the fix of its uid
    by_uid: dict[str, list] = {}
    for f in fixes:
        by_uid.setdefault(f"eoloc-stream-{f['properties']['target_id']}", []).append(f["geometry"]["coordinates"])
    for ev in targets:
        pt = ev.find("point")
        lat, lon, hae = float(pt.get("lat")), float(pt.get("lon")), float(pt.get("hae"))
        candidates = by_uid[ev.get("uid")]
        k = min(range(len(candidates)), key=lambda j: abs(candidates[j][1] - lat) + abs(candidates[j][0] - lon))
        lon_f, lat_f, h_f = candidates.pop(k)  # each fix matched once
        assert abs(lat - lat_f) < 1e-8 and abs(lon - lon_f) < 1e-8 and abs(hae - h_f) < 0.006
        assert 0 < float(pt.get("ce")) < 100 and 0 < float(pt.get("le")) < 100  # from the config's error budget
    assert not any(by_uid.values())
    platform = [e for e in relayed if e.get("type") == "a-f-A-M-F-Q" and e.get("stale") != e.get("time")]
    assert len(platform) == summary["packets"] and platform[0].find("detail/sensor").get("fov")
    # and when the stream went quiet (--silence 1; the test waits for it), the aircraft again, already stale
    def remarks(e):  # FreeTAKServer relays <remarks> as an attribute of <detail>
        r = e.find("detail/remarks")
        return r.text if r is not None else e.find("detail").get("remarks", "")

    quiet = [e for e in relayed if e.get("type") == "a-f-A-M-F-Q" and e.get("stale") == e.get("time")]
    assert quiet and all("no metadata for" in remarks(e) for e in quiet)


class TcpSink:
    """A plain TCP server on loopback that keeps what each connection sends; ``restart()`` closes
    every connection and the listening socket, and listens again on the same port."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.received: list[bytes] = []
        self.conns: list[socket.socket] = []
        self.lock = threading.Lock()
        self.listener = None

    def start(self) -> None:
        self.listener = socket.socket()
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", self.port))
        self.listener.listen()
        threading.Thread(target=self._accept, args=(self.listener,), daemon=True).start()

    def _accept(self, listener) -> None:
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            with self.lock:
                self.conns.append(conn)
                self.received.append(b"")
                k = len(self.received) - 1
            threading.Thread(target=self._read, args=(conn, k), daemon=True).start()

    def _read(self, conn, k) -> None:
        while True:
            try:
                data = conn.recv(65536)
            except OSError:
                return
            if not data:
                return
            with self.lock:
                self.received[k] += data

    def stop(self) -> None:
        self.listener.shutdown(socket.SHUT_RDWR)  # wakes the thread blocked in accept(), freeing the port
        self.listener.close()
        with self.lock:
            for c in self.conns:
                c.shutdown(socket.SHUT_RDWR)
                c.close()
            self.conns.clear()

    def events(self, k: int) -> list[bytes]:
        with self.lock:
            data = self.received[k] if k < len(self.received) else b""
        return [e for e in re.split(rb"(?=<event[ >/])", data) if e.strip()]


def test_tak_server_down_then_restarting_costs_nothing_but_the_gap():
    """Server down at the start: events queue (send never waits); it comes up: the sender connects
    (back-off), says hello and sends the queue. The server restarts: the sender reconnects and
    what is sent after arrives on the new connection."""
    port = free_tcp_port()
    feed = CotFeed()
    sender = TcpSender(f"tcp://127.0.0.1:{port}", hello=feed.presence)
    for i in range(50):
        sender.send(b'<?xml version="1.0"?><event uid="early-%d"/>' % i)
    assert len(sender.queue) == 50 and sender.connects == 0
    sink = TcpSink(port)
    sink.start()
    wait_until(lambda: len(sink.events(0)) == 51, "the hello and the 50 queued events")
    first = sink.events(0)
    assert b"a-f-G-E-S" in first[0] and [e.split(b'uid="')[1].split(b'"')[0] for e in first[1:]] == \
        [b"early-%d" % i for i in range(50)]
    sink.stop()  # the server goes down ...
    time.sleep(0.3)
    sink.start()  # ... and comes back on the same port
    for i in range(20):
        sender.send(b'<?xml version="1.0"?><event uid="late-%d"/>' % i)
        time.sleep(0.02)
    def later():
        return [e for k in range(1, len(sink.received)) for e in sink.events(k)]

    def late_ones():
        return [e.split(b'uid="')[1].split(b'"')[0] for e in later() if b"late-" in e]

    wait_until(lambda: len(late_ones()) + sender.lost == 20, "the 20 late events delivered or counted lost")
    sender.close()
    got = late_ones()
    assert sender.connects == 2 and b"a-f-G-E-S" in later()[0]
    # every event sent after the restart arrives, but those the sender had already written to the dead
    # connection before it noticed (counted as lost)
    assert len(got) + sender.lost == 20 and got == [b"late-%d" % i for i in range(20 - len(got), 20)]


def test_a_full_queue_drops_the_oldest_and_counts_them():
    sender = TcpSender(f"tcp://127.0.0.1:{free_tcp_port()}", queue_events=100)
    for i in range(150):
        sender.send(b"%d" % i)
    assert sender.dropped == 50 and sender.queue[0] == b"50"
    sender.close(timeout_s=0.1)
    assert not sender.thread.is_alive()


@pytest.mark.parametrize("url", ["tcp://127.0.0.1", "ftp://x:1", "udp://:5"])
def test_bad_cot_urls_are_named(url):
    from eoloc.errors import InputError
    from eoloc.live.senders import cot_sender

    with pytest.raises(InputError, match="udp://HOST:PORT"):
        cot_sender(url)
