"""`eoloc live` on MPEG-TS over real UDP sockets, with Cursor-on-Target out: the mountain flight
and a second encoder as two KLV PIDs muxed by libavformat (PyAV), cut into ST 1402 datagrams
(seven transport packets) and sent over loopback, some datagrams duplicated and one lost; CoT
received on a multicast group by a receiver that parses every datagram as one XML event.
Checked against `eoloc klv` on the same TS (the batch path): every target of every packet that
arrived whole, to 1e-8 degrees (CoT's printed precision), ce/le from the same covariance,
the frame centre and the sensor's field of view; stale times from the stream rate. Also: the
same TS replayed at its own clock (PTS) into `eoloc live` with CoT by unicast (none lost), and
from stdin."""

from __future__ import annotations

import json
import math
import signal
import socket
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from livecmd import CotReceiver, settle, summary_of, until_listening
from ports import free_udp_port

import eoloc
from eoloc.io.klv import read_klv
from eoloc.io.klv.mux import write_klv_ts
from eoloc.io.klv.reader import split_klv
from eoloc.io.klv.synthetic import circling_flight_klv
from eoloc.jobs.klv import klv_job
from eoloc.jobs.setup import misb_setup
from eoloc.live.sources import file_datagrams, ts_packet_times
from eoloc.terrain import open_dem

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT, DEM, CONFIG = MOUNTAIN / "flight.klv", MOUNTAIN / "longs_peak_srtmgl3.tif", MOUNTAIN / "klv.toml"
EOLOC = str(Path(sys.executable).parent / "eoloc")


def _two_pid_ts(path: Path) -> tuple[Path, int]:
    """The mountain flight (its corrupt packet too) and a circling flight as two KLV PIDs; returns
    the path and the number of good packets."""
    mountain = [raw for raw, _ in split_klv(FLIGHT.read_bytes())]
    other = [raw for raw, _ in split_klv(circling_flight_klv(40, seed=3, rate_hz=1.0, start_unix_s=1.6e9))]
    write_klv_ts(path, [[(raw, k) for k, raw in enumerate(mountain)], [(raw, k + 0.5) for k, raw in enumerate(other)]])
    s = read_klv(path)
    assert s.streams == ["PID 256", "PID 257"] and s.n_bad == 1
    return path, s.n_good


def _parse_time(iso: str) -> float:
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


def test_ts_over_udp_to_cot_multicast_equals_the_batch_path(tmp_path):
    ts, n_good = _two_pid_ts(tmp_path / "two.ts")
    port, group = free_udp_port(), f"udp://239.2.3.1:{free_udp_port()}?ttl=0"
    rx = CotReceiver(group.split("?")[0])
    out = tmp_path / "live.ndjson"
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--dem", str(DEM), "--config", str(CONFIG),
                             "--cot", group, "--ndjson", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    datagrams = [d for d, _ in file_datagrams(str(ts), lambda: False)]
    lost = len(datagrams) // 2
    sends = [d for i, d in enumerate(datagrams) if i != lost]  # one datagram lost
    sends.insert(10, sends[9])  # and two sent twice: their KLV packets are seen again and dropped
    sends.insert(30, sends[29])
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    until_listening(proc)
    for d in sends:
        tx.sendto(d, ("127.0.0.1", port))
        time.sleep(0.002)
    settle(out)
    proc.send_signal(signal.SIGINT)
    log, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log, "eoloc live stopped (SIGINT)")
    rx.wait_for(summary["cot"][0]["sent"])
    rx.stop()
    assert rx.bad == []
    # what the lost datagram carried (at most the KLV packets in its transport packets) is all that is missing
    assert n_good - 2 <= summary["packets"] < n_good and 1 <= summary["duplicates"] <= 4
    assert set(summary["streams"]) == {"PID 256", "PID 257"}
    job = klv_job(ts, dem=open_dem(DEM), sensor=misb_setup(eoloc.io.config.load_config(CONFIG))[0],
                  budget=misb_setup(eoloc.io.config.load_config(CONFIG))[1])
    r = job.records
    ref = {(str(s), str(t), float(ts_)): i for i, (s, t, ts_, st) in
           enumerate(zip(r["stream"], r["target_id"], r["time_s"], r["status"], strict=True)) if st == "OK"}
    targets = [e for e in rx.events if e.get("type") == "a-u-G"]
    assert len(targets) == summary["fixes_ok"] == summary["cot"][0]["sent"] - (len(rx.events) - len(targets))
    # each target event: the batch fix of the same stream, target and packet time
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    live_targets = [f for f in rows if f["properties"]["what"] == "target" and f["properties"]["status"] == "OK"]
    assert len(live_targets) == len(targets) >= len(ref) - 10
    for ev, f in zip(targets, live_targets, strict=True):
        p = f["properties"]
        i = ref[(p["stream"], str(p["target_id"]), p["time_s"])]
        pt = ev.find("point")
        assert abs(float(pt.get("lat")) - r["lat_deg"][i]) < 1e-8 and abs(float(pt.get("lon")) - r["lon_deg"][i]) < 1e-8
        assert abs(float(pt.get("hae")) - r["h_m"][i]) < 0.006
        ce = r["ce90_m"][i] / math.sqrt(-2 * math.log(0.1))  # the batch CE90 by io.cot convention
        assert abs(float(pt.get("ce")) - ce) < 0.006 and abs(float(pt.get("le")) - r["sigma_u_m"][i]) < 0.006
        assert ev.find("detail/link").get("relation") == "p-p"
        # stale: 10 packet intervals of a 1 Hz stream, from the time of sending
        assert _parse_time(ev.get("stale")) - _parse_time(ev.get("time")) == pytest.approx(10.0, abs=0.01)
    # the platforms: the sensor's field of view as the packet sent it, the frame centre as the batch computes it
    platforms = [e for e in rx.events if e.get("type") == "a-f-A-M-F-Q"]
    spis = [e for e in rx.events if e.get("type") == "b-m-p-s-p-i"]
    assert {e.get("uid") for e in platforms} == {"eoloc-PID_256", "eoloc-PID_257"}
    tel = job.telemetry.columns
    hfov = dict(zip(zip(tel["stream"], np.round(tel["lat_deg"], 8), strict=True), tel["hfov_deg"], strict=True))
    for e in platforms:
        key = (e.get("uid").replace("eoloc-", "").replace("_", " "), round(float(e.find("point").get("lat")), 8))
        assert float(e.find("detail/sensor").get("fov")) == pytest.approx(hfov[key], abs=1e-3)
    centres = job.check.geometry.centre
    mine = tel["stream"] == "PID 256"
    ref_c = {round(la, 6) for la, ok in zip(centres.lat_deg[mine], centres.ok[mine], strict=True) if ok}
    got_c = {round(float(e.find("point").get("lat")), 6) for e in spis if e.get("uid") == "eoloc-PID_256-spi"}
    assert got_c and got_c <= ref_c
    shapes = [e for e in rx.events if e.get("type") == "u-d-f"]
    assert shapes and all(len(e.findall("detail/link[@point]")) >= 4 for e in shapes)


def test_ts_replayed_at_its_own_rate_every_packet_and_cot_event_arrives(tmp_path):
    """A 10 Hz TS (two PIDs, 5 targets each) sent at its own clock (PTS) to `eoloc live` with CoT
    to a unicast receiver: every packet processed, one event per located target, none lost."""
    a = split_klv(circling_flight_klv(40, seed=1))
    b = split_klv(circling_flight_klv(40, seed=2))  # the same clock as a
    ts = write_klv_ts(tmp_path / "ten_hz.ts", [a, b])
    t = ts_packet_times(ts.read_bytes())
    assert t[-1] - t[0] == pytest.approx(3.9, abs=0.01)  # the PTS of the last packet pair
    port, cot_port = free_udp_port(), free_udp_port()
    rx = CotReceiver(f"udp://127.0.0.1:{cot_port}")
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--cot", f"udp://127.0.0.1:{cot_port}",
                             "--packets", "80"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    until_listening(proc)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    started = time.monotonic()
    for d, _ in file_datagrams(str(ts), lambda: False, realtime=True):
        tx.sendto(d, ("127.0.0.1", port))
    took = time.monotonic() - started
    log, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log, "eoloc live stopped (80 packets)")
    rx.wait_for(summary["cot"][0]["sent"])
    rx.stop()
    # paced by the stream's own clock, not sent at once: the last datagram not before its time (no
    # upper bound: a loaded machine may send it late)
    assert took >= 3.85
    assert summary["packets"] == 80 and summary["corrupt"] == 0 and summary["fixes_ok"] == 400
    targets = [e for e in rx.events if e.get("type") == "a-u-G"]
    assert len(targets) == 400 and rx.bad == []
    assert len({e.get("uid") for e in targets}) == 10  # a target keeps its uid from packet to packet
    assert len(rx.events) == summary["cot"][0]["sent"] == summary["cot_events"]


def test_stdin_gives_what_the_file_gives(tmp_path):
    ts, _ = _two_pid_ts(tmp_path / "two.ts")
    from_file = subprocess.run([EOLOC, "live", str(ts), "--ndjson", "-"], capture_output=True, text=True,
                               timeout=120)
    with open(ts, "rb") as fh:
        from_stdin = subprocess.run([EOLOC, "live", "-", "--ndjson", "-"], stdin=fh, capture_output=True,
                                    text=True, timeout=120)
    assert from_file.returncode == from_stdin.returncode == 0, from_stdin.stderr
    assert from_file.stdout == from_stdin.stdout and from_file.stdout.count('"target"') > 100
    raw = subprocess.run([EOLOC, "live", "-", "--ndjson", "-"], input=FLIGHT.read_bytes(), capture_output=True,
                         timeout=120)
    raw_file = subprocess.run([EOLOC, "live", str(FLIGHT), "--ndjson", "-"], capture_output=True, timeout=120)
    assert raw.returncode == 0 and b"checksum" in raw.stderr  # the demo's corrupt packet, named
    assert raw.stdout == raw_file.stdout and raw.stdout.count(b'"what": "target"') > 100


def test_cot_feed_events_of_one_packet_and_the_silence():
    """The events of one packet parse as CoT with the ST 0805 types and links; the stale time
    follows the stream's rate (median interval, a gap does not move it); silence re-sends the
    aircraft already stale; --cot-interval holds events back per uid."""
    from eoloc.live.cotfeed import CotFeed
    from eoloc.live.session import LiveSession

    packets = [raw for raw, _ in split_klv(circling_flight_klv(12, seed=5, rate_hz=5.0))]
    session, feed = LiveSession("test"), CotFeed()
    now = datetime.fromisoformat("2026-11-24T12:00:00+00:00")
    events = []
    for k, raw in enumerate(packets):
        if k == 6:
            continue  # a lost packet: one interval of 0.4 s among 0.2 s ones
        for u in session.feed(raw):
            events = [ET.fromstring(e) for e in feed.events(u, now=now)]
    types = [e.get("type") for e in events]
    assert types == ["a-f-A-M-F-Q", "b-m-p-s-p-i", "u-d-f"] + ["a-u-G"] * 5
    for e in events:
        assert _parse_time(e.get("stale")) - _parse_time(e.get("time")) == pytest.approx(2.0)  # 10 x 0.2 s
        assert e.get("uid").startswith("eoloc-stream")
    assert all(e.find("detail/link[@uid]").get("uid") == "eoloc-stream" for e in events[1:])
    quiet = [ET.fromstring(e) for e in feed.silence(7.0, now=now)]
    assert len(quiet) == 1 and quiet[0].get("stale") == quiet[0].get("time")
    assert "no metadata for 7 s" in quiet[0].find("detail/remarks").text
    hello = ET.fromstring(feed.presence(now=now))
    assert hello.find("detail/takv").get("platform") == "eoloc" and hello.get("type") == "a-f-G-E-S"
    held = CotFeed(interval_s=10.0)
    u = LiveSession("test").feed(packets[0])[0]
    assert len(held.events(u, now=now)) == 8 and held.events(u, now=now) == [] and held.held == 8


def test_cot_carries_the_refined_targets(tmp_path):
    """--cot-targets both on the mountain flight over its DEM: every fix as before, and each
    target's refined estimate (RLS here) as its own marker '<uid>-refined' at the estimate's point,
    ce = its CE90 / 2.1460 (the sigma of a circular normal error with that CE90) and le = LE90 /
    1.6449, the model and fix count in the remarks; the same estimates as --ndjson writes. A
    target whose fixes do not agree with one point (the summits 3 and 4, seen at grazing angles)
    gets no refined marker once it is INCONSISTENT. A Kalman estimate carries its speed and course."""
    from eoloc.live.cotfeed import CotFeed
    from eoloc.live.refine import TargetFilters
    from eoloc.live.session import LiveSession

    cot_port = free_udp_port()
    out = tmp_path / "live.ndjson"
    with CotReceiver(f"udp://127.0.0.1:{cot_port}") as rx:
        r = subprocess.run([EOLOC, "live", str(FLIGHT), "--dem", str(DEM), "--config", str(CONFIG), "--cot",
                            f"udp://127.0.0.1:{cot_port}", "--cot-targets", "both", "--ndjson", str(out)],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        rx.wait_for(summary_of(r.stderr)["cot"][0]["sent"])
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    estimates = [f for f in rows if f["properties"]["what"] == "estimate"]
    shown = [f for f in estimates if f["geometry"] is not None]
    fixes = [f for f in rows if f["properties"]["what"] == "target" and f["properties"]["status"] == "OK"]
    refined = [e for e in rx.events if e.get("uid").endswith("-refined")]
    plain = [e for e in rx.events if e.get("type") == "a-u-G" and not e.get("uid").endswith("-refined")]
    assert len(plain) == len(fixes) == 103 and rx.bad == []
    assert len(refined) == len(shown) < len(estimates) == 103
    assert all(f["properties"]["status"] == "INCONSISTENT" for f in estimates if f["geometry"] is None)
    for ev, f in zip(refined, shown, strict=True):
        p, (lon, lat, h) = f["properties"], f["geometry"]["coordinates"]
        assert ev.get("uid").endswith(f"-{p['target_id']}-refined")
        pt = ev.find("point")
        assert abs(float(pt.get("lat")) - lat) < 1e-8 and abs(float(pt.get("lon")) - lon) < 1e-8
        assert abs(float(pt.get("hae")) - h) < 0.006
        if p["n_fixes"] > 1:
            assert p["cep50_m"] > 0 and abs(float(pt.get("ce")) - p["ce90_m"] / 2.14597) < 0.006
            assert abs(float(pt.get("le")) - p["le90_m"] / 1.64485) < 0.006
        assert f"static (RLS) over {p['n_fixes']} fixes" in ev.find("detail/remarks").text
    # the lake (1) converges: its last marker has all 39 fixes behind it; 3 and 4 stop being sent
    last = {e.get("uid").split("-")[-2]: e for e in refined}
    assert "over 39 fixes" in last["1"].find("detail/remarks").text
    for tid in ("3", "4"):
        final = [f for f in estimates if f["properties"]["target_id"] == tid][-1]
        assert final["properties"]["status"] == "INCONSISTENT" and final["geometry"] is None
        assert f"over {final['properties']['n_fixes']} fixes" not in last[tid].find("detail/remarks").text

    klv = tmp_path / "circling.klv"
    klv.write_bytes(circling_flight_klv(30, seed=4, rate_hz=2.0))
    # moving (Kalman): the same uid as the fixes (estimates only), speed and course in <track>
    session = LiveSession("test", refine=TargetFilters("moving"), budget=misb_setup(
        eoloc.io.config.load_config(CONFIG))[1])
    feed = CotFeed(targets="estimates")
    for raw, _ in split_klv(klv.read_bytes()):
        for u in session.feed(raw):
            events = [ET.fromstring(e) for e in feed.events(u)]
    targets = [e for e in events if e.get("type") == "a-u-G"]
    assert len(targets) == len(u.estimates) == 5
    for ev, est in zip(targets, u.estimates, strict=True):
        p = est["properties"]
        assert ev.get("uid") == f"eoloc-stream-{p['target_id']}" and p["model"] == "moving (Kalman)"
        tr = ev.find("detail/track")
        assert float(tr.get("speed")) == pytest.approx(p["speed_mps"], abs=1e-3)
        assert float(tr.get("course")) == pytest.approx(p["heading_deg"], abs=1e-3)
    bad = subprocess.run([EOLOC, "live", str(klv), "--ndjson", "-", "--cot-targets", "estimates"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "--cot-targets estimates" in bad.stderr and "Traceback" not in bad.stderr
