"""`eoloc live --detect`: movers found in a live stream's own video. The scene is rendered without
eoloc (tests/helpers/moving_scene.py: OpenCV's warpPerspective of a textured plane, three vehicles
driving at known speeds, the camera's pose turned into ST 0601 by pymap3d), encoded as H.264 with
its KLV in one MPEG-TS (PyAV), sent over real UDP on loopback at the stream's own pace into
`eoloc live`, which writes NDJSON and sends CoT to a UDP receiver. Truth: the vehicles' tracks in
pymap3d's ENU. Tolerances: a ground pixel is ~1 m; the plane departs from the flat DEM by < 0.1 m."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import xml.etree.ElementTree as ET
from datetime import datetime
from pathlib import Path

import moving_scene as ms
import numpy as np
import pymap3d
import pytest
import rasterio
from browser import chromium
from livecmd import CotReceiver, settle, summary_of, until_listening
from ports import free_udp_port
from rasterio.transform import from_origin
from where import DATA

from eoloc.io.klv.mux import write_klv_ts
from eoloc.live.sources import file_datagrams
from eoloc.live.video import PesAssembler, VideoDecoder

EOLOC = str(Path(sys.executable).parent / "eoloc")
N = 60  # frames (and KLV packets) at ms.FPS: 6 s


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The scene as a TS (H.264 + ST 0601 at the frame rate) and a flat DEM at the plane's height."""
    d = tmp_path_factory.mktemp("drive")
    tex = ms.ground_texture()
    images = [ms.render(tex, ms.CARS, i / ms.FPS) for i in range(N)]
    ts = write_klv_ts(d / "drive.ts", [ms.klv_packets(N)], video_fps=ms.FPS, video_size=(ms.W, ms.H),
                      frame_source=lambda i: images[i])
    lat0, lon0, h0 = ms.ORIGIN
    with rasterio.open(d / "flat.tif", "w", driver="GTiff", width=200, height=200, count=1, dtype="float32",
                       crs="EPSG:4326", transform=from_origin(lon0 - 0.05, lat0 + 0.05, 0.0005, 0.0005)) as f:
        f.write(np.full((1, 200, 200), h0, np.float32))
    return ts, d / "flat.tif", images


def test_the_video_pes_decoded_as_ffmpeg_demuxes_it(drive):
    """The transport packets of the video PID put together and decoded = PyAV's own demuxer and
    decoder on the file: the same pictures at the same times; a lost transport packet costs its
    PES packet (counted), not the stream."""
    import av

    ts, _, _ = drive
    with av.open(str(ts)) as c:
        ref = [(float(f.pts * f.time_base), f.to_ndarray(format="rgb24")) for f in c.decode(c.streams.video[0])]
        pid, t0 = c.streams.video[0].id, float(c.streams.video[0].start_time * c.streams.video[0].time_base)
    data = ts.read_bytes()
    cells = [data[k:k + 188] for k in range(0, len(data), 188) if (data[k + 1] & 0x1F) << 8 | data[k + 2] == pid]

    def decode(cells):
        a, d, got = PesAssembler(), VideoDecoder(0x1B), []
        for cell in cells:
            for pes in a.feed(cell):
                got += d.decode(pes)
        for pes in a.flush():
            got += d.decode(pes)
        return got + d.flush(), a, d

    got, _, _ = decode(cells)
    assert len(got) == len(ref) == N
    for f, (t, img) in zip(got, ref, strict=True):
        assert f.pts_s - t0 == pytest.approx(t - t0, abs=1e-6)
        assert np.array_equal(f.image, img)
    # one transport packet lost in the middle of frame 30's PES: that PES is dropped, counted; the
    # decoder goes on (frames that lean on the lost one may be lost too, never made up)
    starts = [k for k, c in enumerate(cells) if c[1] & 0x40]
    lost = starts[30] + 2
    got, a, d = decode(cells[:lost] + cells[lost + 1:])
    assert a.dropped == 1 and 30 <= len(got) < N
    assert {round(t, 6) for t, _ in ref[:30]} <= {round(f.pts_s, 6) for f in got}


def _score(movers: list[dict]) -> dict:
    """Per mover id: its vehicle (nearest by median distance, within 10 m, else None), the
    distances of its points from that vehicle's true centre, its speeds and headings."""
    out = {}
    for tid in sorted({f["properties"]["track_id"] for f in movers}):
        ff = [f for f in movers if f["properties"]["track_id"] == tid]
        t = np.array([f["properties"]["pts_s"] for f in ff]) - ff[0]["properties"]["pts_s"] + \
            ff[0]["properties"]["frame"] / ms.FPS
        lon, lat = np.array([f["geometry"]["coordinates"][:2] for f in ff]).T
        dist = []
        for c in ms.CARS:
            tl, tn = ms.truth_geodetic(c, t)
            e, n, _ = pymap3d.geodetic2enu(lat, lon, ms.ORIGIN[2], tl, tn, ms.ORIGIN[2])
            dist.append(np.hypot(e, n))
        k = int(np.argmin([np.median(x) for x in dist]))
        out[tid] = {"car": k if np.median(dist[k]) < 10 else None, "err": dist[k],
                    "frames": {f["properties"]["frame"] for f in ff},
                    "speed": np.array([f["properties"]["speed_mps"] for f in ff]),
                    "heading": np.array([f["properties"]["heading_deg"] for f in ff]),
                    "ce90": np.array([f["properties"].get("ce90_m") or np.nan for f in ff])}
    return out


def test_live_detect_over_udp_finds_locates_and_sends_the_movers(drive, tmp_path):
    ts, dem, _ = drive
    (tmp_path / "budget.toml").write_text("[accuracy.budget]\nyaw_deg = {normal = 0.2}\npitch_deg = {normal = 0.1}\n"
                                          "lat_deg = {normal = 1e-5}\nlon_deg = {normal = 1e-5}\n")
    port, cot_port = free_udp_port(), free_udp_port()
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        http = free.getsockname()[1]
    rx = CotReceiver(f"udp://127.0.0.1:{cot_port}")
    out = tmp_path / "live.ndjson"
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--dem", str(dem), "--vertical", "ellipsoid",
                             "--config", str(tmp_path / "budget.toml"), "--detect", "motion", "--ndjson", str(out),
                             "--detect-lag", "60",  # every frame searched however loaded the machine running the test
                             "--cot", f"udp://127.0.0.1:{cot_port}", "--map", f"127.0.0.1:{http}"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    until_listening(proc)
    d = chromium()
    try:
        d.get(f"http://127.0.0.1:{http}/live")
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for dg, _ in file_datagrams(str(ts), lambda: False, realtime=True):  # at the stream's own pace
            tx.sendto(dg, ("127.0.0.1", port))
        settle(out)
        # the live map (headless Chromium): a marker and a track per mover, where the NDJSON last put it
        page = d.execute_script("return JSON.parse(JSON.stringify(window.eoloc.movers))")
        n_cls = lambda c: d.execute_script(f"return document.querySelectorAll('path.{c}').length")  # noqa: E731
        assert len(page) == n_cls("eoloc-mover") == n_cls("eoloc-mover-track") == 3, page
        so_far = [json.loads(x) for x in out.read_text().splitlines()]
        for tid in {f["properties"]["track_id"] for f in so_far if f["properties"]["what"] == "mover"}:
            last = [f for f in so_far if f["properties"]["what"] == "mover" and f["properties"]["track_id"] == tid][-1]
            got = next(v for k, v in page.items() if k.endswith(f"/M{tid}"))
            assert [got["lon"], got["lat"]] == pytest.approx(last["geometry"]["coordinates"][:2], abs=1e-12)
        assert not [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        d.quit()
        proc.send_signal(signal.SIGINT)
        log, _ = proc.communicate(timeout=60)
        rx.stop()
    assert proc.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log)
    m = summary["movers"]
    assert m["video_frames"] == N and m["frames_posed"] == N and m["decode_errors"] == 0, m
    assert m["frames_searched"] == N and m["frames_skipped"] == 0 and m["movers"] == 3, m
    # the latency: at least the detector's 2 s window (a frame is compared with those after it)
    assert m["latency_ms_median"] >= 2000, m
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    movers = [f for f in rows if f["properties"]["what"] == "mover"]
    # each with its stream, packet and frame time as every live feature (the KLV's clock: t = frame / FPS)
    for f in movers:
        p = f["properties"]
        assert p["stream"] == "PID 257" and 0 <= p["packet"] < N
        t = datetime.fromisoformat(p["time_utc"].replace("Z", "+00:00")).timestamp() - ms.START_UNIX_S
        assert t == pytest.approx(p["frame"] / ms.FPS, abs=1e-3)
    s = _score(movers)
    assert sorted(v["car"] for v in s.values()) == [0, 1, 2], "one mover per vehicle, no false one"
    for v in s.values():
        c = ms.CARS[v["car"]]
        seen = {i for i in range(N) if ms.in_view(c, i / ms.FPS)}
        assert len(v["frames"] & seen) >= 0.95 * len(seen), (v["car"], len(v["frames"]))
        assert np.median(v["err"]) < 1.0 and v["err"].max() < 5.0, (v["car"], np.median(v["err"]))
        # the filtered (not smoothed) speed and heading, once the filter has settled (the second half)
        half = len(v["speed"]) // 2
        assert np.median(v["speed"][half:]) == pytest.approx(c.speed_mps, rel=0.10)
        assert abs((np.median(v["heading"][half:]) - c.heading_deg + 180) % 360 - 180) < 5
        assert np.all(np.isfinite(v["ce90"]) & (v["ce90"] > 0))  # the budget's uncertainty on every fix
    # CoT: valid against MITRE's schema; each mover under one uid with its course and speed
    import xmlschema

    schema = xmlschema.XMLSchema(str(DATA / "conformance" / "cot_event_2_0.xsd"))
    assert rx.bad == []
    mine = [e for e in rx.events if "-mover-" in e.get("uid")]
    assert len({e.get("uid") for e in mine}) == 3
    for e in mine:
        schema.validate(ET.tostring(e))
        assert e.get("type") == "a-u-G" and 0 < float(e.find("point").get("ce")) < 1000
    for uid in {e.get("uid") for e in mine}:
        last = [e for e in mine if e.get("uid") == uid][-1]
        tid = int(uid.rsplit("-", 1)[1])
        c = ms.CARS[s[tid]["car"]]
        assert float(last.find("detail/track").get("speed")) == pytest.approx(c.speed_mps, rel=0.10)


def test_live_detect_with_a_model_finds_what_stands_still_too(drive, tmp_path):
    """--detect MODEL.onnx on a live stream (a file, searched whole): the model's boxes located and
    tracked; the parked vehicle, which no motion detector sees, is a target with no speed."""
    from tinymodel import yellow_model

    _, dem, _ = drive
    model = tmp_path / "yellow.onnx"
    yellow_model(model)
    parked = ms.Vehicle(20, 60, 30, 0.0)
    cars = [*ms.CARS, parked]
    tex = ms.ground_texture()
    ts = write_klv_ts(tmp_path / "parked.ts", [ms.klv_packets(40)], video_fps=ms.FPS, video_size=(ms.W, ms.H),
                      frame_source=lambda i: ms.render(tex, cars, i / ms.FPS))
    out = tmp_path / "model.ndjson"
    r = subprocess.run([EOLOC, "live", str(ts), "--dem", str(dem), "--vertical", "ellipsoid", "--detect", str(model),
                        "--detect-point", "centre", "--ndjson", str(out)], capture_output=True, text=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    movers = [json.loads(x) for x in out.read_text().splitlines()]
    movers = [f for f in movers if f["properties"]["what"] == "mover"]
    assert {f["properties"]["class"] for f in movers} == {"vehicle"}
    by_car: dict[int, list] = {}
    for tid in {f["properties"]["track_id"] for f in movers}:
        ff = [f for f in movers if f["properties"]["track_id"] == tid]
        t = np.array([f["properties"]["frame"] for f in ff]) / ms.FPS
        lon, lat = np.array([f["geometry"]["coordinates"][:2] for f in ff]).T
        d = [np.median(np.hypot(*pymap3d.geodetic2enu(lat, lon, ms.ORIGIN[2], *ms.truth_geodetic(c, t),
                                                      ms.ORIGIN[2])[:2])) for c in cars]
        k = int(np.argmin(d))
        assert d[k] < 4.0, d  # the model's box sits on a 4-px cell (~5 m on the ground here)
        by_car.setdefault(k, []).append(np.median([f["properties"]["speed_mps"] for f in ff[len(ff) // 2:]]))
    assert sorted(by_car) == [0, 1, 2, 3] and all(len(v) == 1 for v in by_car.values()), by_car
    # standing: a target, no mover (the live speed is the filter's, not smoothed as in eoloc video
    # (< 0.8 m/s there): the box's 4-px cells make its fixes jitter by a few metres)
    assert by_car[3][0] < 1.5
    for k, c in enumerate(ms.CARS):
        assert by_car[k][0] == pytest.approx(c.speed_mps, rel=0.10)


def test_detect_needs_a_dem_and_a_video(drive, tmp_path):
    """--detect without --dem: one line, exit 2; a raw KLV file (no video): located as always,
    and a warning that no mover could be searched for."""
    ts, dem, _ = drive
    r = subprocess.run([EOLOC, "live", str(ts), "--detect", "motion", "--ndjson", str(tmp_path / "a.ndjson")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--detect needs the ground" in r.stderr and "Traceback" not in r.stderr
    raw = tmp_path / "drive.klv"
    raw.write_bytes(b"".join(p for p, _ in ms.klv_packets(20)))
    r = subprocess.run([EOLOC, "live", str(raw), "--dem", str(dem), "--vertical", "ellipsoid", "--detect", "motion",
                        "--ndjson", str(tmp_path / "b.ndjson")], capture_output=True, text=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "brought no video" in r.stderr
    assert sum('"aircraft"' in x for x in (tmp_path / "b.ndjson").read_text().splitlines()) == 20


def test_a_search_that_falls_behind_skips_frames_and_says_so(drive, tmp_path):
    """A frame the worker reaches more than max_lag_s after it arrived is skipped, counted, never
    queued (here every frame: a lag of 1 ns); the KLV path goes on; the run ends cleanly."""
    import os

    from eoloc.live import LiveMovers, LiveSession, NdjsonSink, run
    from eoloc.rules import AtHeight

    ts, _, _ = drive
    session = LiveSession(str(ts), movers=LiveMovers(AtHeight(ms.ORIGIN[2]), max_lag_s=1e-9))
    summary = run(str(ts), session, [NdjsonSink(os.devnull)]).summary
    m = summary["movers"]
    assert summary["packets"] == N and m["video_frames"] == m["frames_posed"] == m["frames_skipped"] == N
    assert m["frames_searched"] == 0 and m["movers"] == 0 and m["latency_ms_median"] is None
