"""`eoloc video`: frames paired with their metadata frame-accurately (synthetic H.264 video whose
frames show their own index, KLV in three carriages), each frame a valid COG with its visibility,
the mosaic (finest ground sample wins, source frame recorded) and the XYZ tiles."""

from __future__ import annotations

import csv
import json
import math
from datetime import UTC, datetime

import cv2
import httpx
import mercantile
import numpy as np
import pyproj
import pytest
import rasterio
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from rasterio.transform import from_origin
from rio_cogeo.cogeo import cog_validate
from served import eoloc_serve

from eoloc.cli import main
from eoloc.ground.frame import misb_sensor
from eoloc.ground.mosaic import Mosaic, ground_sample_m
from eoloc.ground.rectify import FramePixels, OutputGrid, frame_pixels, output_grid
from eoloc.io.klv.encode import encode_uas_packet
from eoloc.io.klv.mux import add_klv, write_klv_ts
from eoloc.io.videofile import iter_frames, probe_video
from eoloc.jobs.video import FrameSelection, frame_visibility, round_gsd, video_job
from eoloc.rules import AtHeight
from eoloc.sensor import AzElGimbal, Camera, Pose, SensorModel

FPS = 25
SIZE = (160, 96)
UNIX0 = 1.7e9


def shown_index(img: np.ndarray) -> int:
    """The index a frame of :func:`eoloc.io.klv.mux.index_frame` shows (16 blocks, MSB first)."""
    grey = img if img.ndim == 2 else img.mean(-1)
    w, h = grey.shape[1], grey.shape[0]
    bw = w // 16
    bits = [grey[2:h // 4 - 2, b * bw + 2:(b + 1) * bw - 2].mean() > 128 for b in range(16)]
    return int("".join("1" if b else "0" for b in bits), 2)


def packet(t: float, az_deg: float) -> bytes:
    """An ST 0601 packet at UNIX0 + t: 3 km up near Boulder, turret 45° down, relative azimuth az."""
    return encode_uas_packet({2: datetime.fromtimestamp(UNIX0 + t, UTC), 5: 90.0, 6: 0.0, 7: 0.0, 13: 40.0,
                              14: -105.0, 15: 3000.0, 16: 20.0, 17: 12.0, 18: az_deg % 360.0, 19: -45.0, 20: 0.0,
                              25: 0.0, 78: 0.0})


def jumpy_az(i: int) -> float:
    """A per-frame azimuth no interpolation between neighbours reproduces."""
    return (i * i * 0.37) % 40.0


@pytest.fixture(scope="module")
def carriages(tmp_path_factory):
    """Four seconds of 25 fps video with the same flight's metadata carried three ways."""
    d = tmp_path_factory.mktemp("video")
    plain = write_klv_ts(d / "plain.ts", [], video_fps=FPS, video_size=SIZE, duration_s=4.0)
    sync = add_klv(plain, d / "sync.ts", lambda n, t: packet(n / FPS, jumpy_az(n)), carriage="sync")
    # ST 1402 asynchronous: a packet per frame, no PTS, right after the frame's video (timed by arrival)
    arrival = add_klv(plain, d / "arrival.ts", lambda n, t: packet(n / FPS, jumpy_az(n)), carriage="async")
    ten_hz = [(packet(k / 10, 10 * k / 10), k / 10) for k in range(41)]  # azimuth 10°/s, linear
    asyn = write_klv_ts(d / "async.ts", [ten_hz], video_fps=FPS, video_size=SIZE)
    side = d / "side.klv"
    side.write_bytes(b"".join(p for p, _ in ten_hz))
    return d, plain, sync, asyn, side, arrival


def test_synchronous_klv_is_in_its_own_pid_with_stream_type_0x15(carriages):
    from stanag4609.transport.demux import PESStreamEvent, StreamKind, TransportDemuxer

    _, _, sync, _, _, _ = carriages
    demux = TransportDemuxer()
    events = demux.feed(sync.read_bytes()) + demux.finish()
    klv = [e for e in events if isinstance(e, PESStreamEvent) and e.kind is StreamKind.KLV]
    video = [e for e in events if isinstance(e, PESStreamEvent) and e.kind is StreamKind.VIDEO]
    assert len(klv) == len(video) == 4 * FPS
    assert {e.stream.stream_type for e in klv} == {0x15}
    assert [e.pes.stream_id for e in klv[:3]] == [0xFC] * 3
    assert sorted(e.pes.pts for e in klv) == sorted(e.pes.pts for e in video)


@pytest.mark.parametrize("carriage", ["sync", "arrival", "async", "sidecar"])
def test_every_frame_gets_its_own_metadata(carriages, carriage, tmp_path):
    """The frame the job calls n shows n in its pixels, and its pose is the metadata of time n / 25 s:
    exactly the frame's own packet with synchronous carriage and with ST 1402 asynchronous carriage
    (no PTS: each packet timed by the frame it follows) — an azimuth that jumps frame to frame —,
    the 10 Hz packets interpolated with asynchronous carriage with PTS (as FFmpeg writes) and beside
    the video (tag 18's resolution is 8e-8°; one frame off would be 0.4°)."""
    _, plain, sync, asyn, side, arrival = carriages
    video, kw = {"sync": (sync, {}), "arrival": (arrival, {}), "async": (asyn, {}),
                 "sidecar": (plain, {"klv": side})}[carriage]
    shown = {f.index: shown_index(f.image) for f in iter_frames(video)}
    # 4 s of frames (the async stream's video reaches its last packet at 4.0 s: one more)
    assert len(shown) == 4 * FPS + (carriage == "async") and all(shown[i] == i for i in shown)
    job = video_job(video, out=tmp_path, ground=AtHeight(0.0), write_frames=False, mosaic=False, **kw)
    assert len(job.rows) == len(shown)
    for r in job.rows:
        n = shown[r["frame"]]
        assert r["video_time_s"] == pytest.approx(n / FPS, abs=1e-6)
        expected = jumpy_az(n) if carriage in ("sync", "arrival") else 10.0 * n / FPS
        assert r["status"] == "OK", r
        assert r["gimbal1_deg"] == pytest.approx(expected, abs=1e-5)
        assert r["time_s"] == pytest.approx(UNIX0 + n / FPS, abs=1e-5)


def test_frames_outside_the_metadata_have_no_pose_and_say_why(carriages, tmp_path):
    _, plain, _, _, side, _ = carriages
    job = video_job(plain, out=tmp_path, klv=side, ground=AtHeight(0.0), time_offset_s=UNIX0 + 2.0, write_frames=False,
                    mosaic=False)  # the first frame is at 2 s into the KLV: the last 2 s of video have none
    late = [r for r in job.rows if r["video_time_s"] > 2.0 + 1e-6]
    assert late and all(r["status"] == "NO_TELEMETRY" and "outside" in r["note"] for r in late)
    early = [r for r in job.rows if r["video_time_s"] <= 2.0]
    assert all(r["status"] == "OK" for r in early)
    assert early[0]["gimbal1_deg"] == pytest.approx(20.0, abs=1e-5)  # 2 s at 10°/s


def test_frame_cogs_validate_and_mask_what_is_seen(carriages, tmp_path):
    _, _, sync, _, _, _ = carriages
    job = video_job(sync, out=tmp_path, ground=AtHeight(0.0), select=FrameSelection(every=20), tiles=False)
    assert [r["frame"] for r in job.rows] == [0, 20, 40, 60, 80]
    files = sorted((tmp_path / "frames").glob("*.tif"))
    assert len(files) == 5
    for f in [*files, tmp_path / "mosaic.tif", tmp_path / "mosaic_source.tif"]:
        valid, errors, _ = cog_validate(str(f))
        assert valid and not errors, (f, errors)
    with rasterio.open(files[0]) as ds:
        assert ds.count == 4 and ds.descriptions[-1].startswith("visibility")
        vis = ds.read(4)
        assert np.array_equal(ds.read_masks(1) == 255, vis == 2)
        assert (vis == 2).sum() == job.rows[0]["seen_cells"]


def test_a_large_cog_has_overviews_its_mask_and_band_names(tmp_path):
    """Above 512 cells a COG needs overviews (rio-cogeo warns otherwise): written, valid with no
    warning, the data, mask and band names read back unchanged."""
    from eoloc.io.raster import write_cog

    rng = np.random.default_rng(3)
    data = rng.normal(0, 1, (2, 900, 1100)).astype(np.float32)
    mask = rng.random((900, 1100)) < 0.6
    path = write_cog(tmp_path / "big.tif", data, from_origin(500_000.0, 4_400_000.0, 2.0, 2.0),
                     pyproj.CRS.from_epsg(32613), nodata=None, mask=mask, band_names=["a", "b"])
    valid, errors, warnings = cog_validate(str(path))
    assert valid and not errors and not warnings, (errors, warnings)
    with rasterio.open(path) as ds:
        assert ds.overviews(1) and ds.descriptions == ("a", "b") and ds.crs.to_epsg() == 32613
        assert np.array_equal(ds.read(), data) and np.array_equal(ds.read_masks(1) == 255, mask)


def test_mosaic_keeps_the_finest_frame_and_names_it(carriages, tmp_path):
    """Every mosaic cell equals its source frame's own COG at that cell, and that frame had the
    finest GSD there of all the frames that saw it."""
    _, _, sync, _, _, _ = carriages
    job = video_job(sync, out=tmp_path, ground=AtHeight(0.0), select=FrameSelection(every=25), tiles=False)
    m = job.mosaic
    with rasterio.open(tmp_path / "mosaic_source.tif") as ds:
        src = ds.read(1)
        assert np.array_equal(src, m.frame.astype(np.float32))
    used = sorted(set(m.frame[m.valid].tolist()))
    assert set(used) <= {0, 25, 50, 75} and len(used) >= 2
    t = m.grid.transform
    for row in job.rows:
        with rasterio.open(tmp_path / row["file"]) as ds:
            # the frame's window in the mosaic: whole cells, no resampling
            c0 = round((ds.transform.c - t.c) / t.a)
            r0 = round((ds.transform.f - t.f) / t.e)
            data, vis = ds.read()[:3], ds.read(4)
        h, w = vis.shape
        a, b = max(r0, 0), min(r0 + h, m.frame.shape[0])
        c, d = max(c0, 0), min(c0 + w, m.frame.shape[1])
        mine = m.frame[a:b, c:d] == row["frame"]
        assert np.array_equal(m.data[:, a:b, c:d][:, mine], data[:, a - r0:b - r0, c - c0:d - c0][:, mine])
        assert (vis[a - r0:b - r0, c - c0:d - c0][mine] == 2).all()
    with rasterio.open(tmp_path / "mosaic_source.tif") as ds:
        gsd = ds.read(2)
    assert np.isfinite(gsd[m.valid]).all() and (gsd[m.valid] > 0).all()


def test_mosaic_rule_finest_wins_on_an_aligned_grid():
    crs = pyproj.CRS.from_epsg(32613)
    res = (2.0, 2.0)
    mos = Mosaic(crs, res, 1, np.uint8, 0, chunk=8)
    g1 = OutputGrid(crs, from_origin(1000.0, 5000.0, *res), (10, 10), res)
    g2 = OutputGrid(crs, from_origin(1010.0, 4990.0, *res), (10, 10), res)  # 5 cells right, 5 down
    ones = np.ones((10, 10), bool)
    mos.add(1, g1, np.full((1, 10, 10), 10, np.uint8), ones, np.full((10, 10), 1.0, np.float32))
    gsd2 = np.full((10, 10), 2.0, np.float32)
    gsd2[:, 7:] = 0.5  # finer on its right, where frame 1 does not reach
    gsd2[:3, :3] = 0.5  # finer in part of the overlap
    won = mos.add(2, g2, np.full((1, 10, 10), 20, np.uint8), ones, gsd2)
    r = mos.result()
    assert r.grid.shape == (15, 15) and r.grid.transform.c == 1000.0 and r.grid.transform.f == 5000.0
    expect = np.full((15, 15), -1)
    expect[:10, :10] = 1
    expect[5:, 5:] = 2
    expect[5:10, 5:10] = 1
    expect[5:8, 5:8] = 2
    assert np.array_equal(r.frame, expect)
    assert won == int((expect == 2).sum())
    assert np.array_equal(r.data[0], np.select([expect == 1, expect == 2], [10, 20], 0))
    with pytest.raises(ValueError, match="multiples"):
        mos.add(3, OutputGrid(crs, from_origin(1001.0, 5000.0, *res), (2, 2), res), np.zeros((1, 2, 2), np.uint8),
                np.ones((2, 2), bool), np.ones((2, 2), np.float32))


def test_ground_sample_distance_of_a_nadir_view_is_height_over_focal_length():
    """Nadir over flat ground 1500 m below: GSD = H / f at the image centre (the pinhole formula),
    and larger towards the edges."""
    cam = Camera.from_hfov(30.0, 640, 480)
    sensor = SensorModel(cam, AzElGimbal())
    pose = Pose(40.0, -105.0, 1500.0, 0.0, 0.0, 0.0, (0.0, -90.0))
    grid = output_grid(sensor, pose, AtHeight(0.0), gsd_m=2.0)
    px = frame_pixels(sensor, pose, AtHeight(0.0), grid)
    gsd = ground_sample_m(px, grid)
    rows, cols = grid.shape
    centre = gsd[rows // 2 - 2:rows // 2 + 2, cols // 2 - 2:cols // 2 + 2]
    # UTM's scale factor near the zone's edge (lon -105 is the central meridian: k0 = 0.9996)
    assert np.nanmedian(centre) == pytest.approx(1500.0 / cam.fx / 0.9996, rel=2e-3)
    assert np.nanmax(gsd) > np.nanmedian(centre)


def test_visibility_classes():
    u = np.array([[5.0, -3.0, np.nan], [1.0, 2.0, 9.4]])
    px = FramePixels(u, u * 0 + 2.0, np.ones_like(u), np.array([[True, False, False], [False, True, False]]),
                     u.astype(np.float32), u.astype(np.float32))
    assert frame_visibility(px, 10, 5).tolist() == [[2, 0, 0], [1, 2, 1]]


def test_round_gsd():
    assert round_gsd(4.5155) == 4.5 and round_gsd(0.2349) == 0.23 and round_gsd(123.0) == 120.0


def test_xyz_tiles_show_the_mosaic_where_it_is(carriages, tmp_path):
    _, _, sync, _, _, _ = carriages
    job = video_job(sync, out=tmp_path, ground=AtHeight(0.0), select=FrameSelection(every=50), write_frames=False)
    ts, m = job.tiles, job.mosaic
    assert ts.count > 0 and ts.min_zoom <= ts.max_zoom
    to_ll = pyproj.Transformer.from_crs(m.grid.crs, "EPSG:4326", always_xy=True)
    rng = np.random.default_rng(1)
    grey = m.data[0]
    uniform = m.valid.copy()
    for dr in (-2, -1, 0, 1, 2):
        for dc in (-2, -1, 0, 1, 2):
            uniform &= np.roll(np.roll(grey, dr, 0), dc, 1) == grey
            uniform &= np.roll(np.roll(m.valid, dr, 0), dc, 1)
    rr, cc = np.nonzero(uniform[3:-3, 3:-3])
    assert rr.size > 50
    checked = 0
    for k in rng.choice(rr.size, 30, replace=False):
        r, c = rr[k] + 3, cc[k] + 3
        x, y = m.grid.centres(r, c)
        lon, lat = to_ll.transform(x, y)
        t = mercantile.tile(lon, lat, ts.max_zoom)
        png = tmp_path / "tiles" / str(t.z) / str(t.x) / f"{t.y}.png"
        img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        assert img.shape == (256, 256, 4)
        b = mercantile.xy_bounds(t)
        mx, my = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(lon, lat)
        i = int((b.top - my) / (b.top - b.bottom) * 256)
        j = int((mx - b.left) / (b.right - b.left) * 256)
        assert img[i, j, 3] == 255
        assert abs(int(img[i, j, 1]) - int(grey[r, c])) <= 2
        checked += 1
    assert checked == 30


def test_cli_video_writes_everything_and_refuses_bad_input(carriages, tmp_path):
    d, _, sync, *_ = carriages
    r = CliRunner().invoke(main, ["video", str(sync), "--every", "25", "--end", "3", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    rep = json.loads((tmp_path / "video.json").read_text())
    assert rep["frames_selected"] == 4 and rep["statuses"] == {"OK": 4}
    assert "presentation time" in rep["metadata"]
    assert (tmp_path / "frames.csv").read_text().count("\n") == 5
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [f"frame_{i:06d}.tif" for i in (0, 25, 50, 75)]
    gj = json.loads((tmp_path / "footprints.geojson").read_text())
    assert len(gj["features"]) == 4
    # the player has every frame's pose (not only the rectified ones'): served, a click on frame 37
    # (not rectified) is the library's point for that frame's pose, camera and frame-centre height
    js = (tmp_path / "player" / "data.js").read_text()
    data = json.loads(js[js.index("=") + 1:].strip().rstrip(";"))
    F = data["frames"]
    assert len(F["t"]) == 100 and sorted(data["rectified"]) == ["0", "25", "50", "75"]
    assert data["stop"] == {"frame_centre": True} and rep["player"]["serve"] == f"eoloc serve --player {tmp_path}"
    rows = {int(r["frame"]): r for r in csv.DictReader((tmp_path / "frames.csv").open())}
    assert F["g1"][25] == pytest.approx(float(rows[25]["gimbal1_deg"]), abs=1e-8)
    i, u, v = 37, 20.25, 70.5
    body = {"pose": {"lat_deg": F["lat"][i], "lon_deg": F["lon"][i], "h_m": F["h"][i], "yaw_deg": F["yaw"][i],
                     "pitch_deg": F["pitch"][i], "roll_deg": F["roll"][i],
                     "gimbal_deg": [F["g1"][i], F["g2"][i], F["g3"][i]]},
            "gimbal": data["gimbal"], "pixels": [[u, v]], "stop": {"target_height_m": F["ground_h"][i]},
            "camera": {**data["camera"], "fx": F["fx"][i], "fy": F["fy"][i]}}
    with eoloc_serve("--player", str(tmp_path)) as url:
        fix = httpx.post(url + "/v1/locate", json=body).json()["fixes"][0]
    assert F["g1"][i] == pytest.approx(jumpy_az(i), abs=1e-6) and F["g2"][i] == pytest.approx(-45.0, abs=1e-6)
    pose = Pose(F["lat"][i], F["lon"][i], F["h"][i], F["yaw"][i], F["pitch"][i], F["roll"][i],
                (F["g1"][i], F["g2"][i], F["g3"][i]))
    cam = Camera(*SIZE, F["fx"][i], F["fy"][i], (SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2)
    nominal = Camera.from_hfov(20.0, *SIZE, vfov_deg=12.0)  # tags 16, 17 as sent, to their resolution
    assert cam.fx == pytest.approx(nominal.fx, rel=1e-4) and cam.fy == pytest.approx(nominal.fy, rel=1e-4)
    assert F["ground_h"][i] == pytest.approx(0.0, abs=0.2)  # tag 78's 0, to its resolution
    want = AtHeight(F["ground_h"][i]).locate(misb_sensor(camera=cam), pose, (np.array([u]), np.array([v])))
    assert fix["status"] == "OK"
    assert fix["lat_deg"] == pytest.approx(float(want.lat_deg[0]), abs=1e-10)
    assert fix["lon_deg"] == pytest.approx(float(want.lon_deg[0]), abs=1e-10)
    not_video = d / "not_video.ts"
    not_video.write_bytes(b"\x00" * 5000)
    for args, words in [(["video", str(d / "missing.ts")], "does not exist"),
                        (["video", str(not_video)], "cannot be opened"),
                        (["video", str(sync), "--every", "1000", "--start", "3.5"], "no frame"),
                        (["video", str(sync), "--start", "3", "--end", "1"], "before --start"),
                        (["video", str(sync), "--stream", "PID 1"], "no KLV stream"),
                        (["video", str(sync), "--telemetry", "x.csv"], "--config")]:
        r = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "bad")])
        assert r.exit_code == 2, (args, r.output)
        assert words in r.output and "Traceback" not in r.output, (args, r.output)


def test_probe_video(carriages):
    _, plain, *_ = carriages
    info = probe_video(plain)
    assert (info.width, info.height, info.codec) == (*SIZE, "h264")
    assert info.fps == pytest.approx(FPS) and info.container == "mpegts"
    assert math.isfinite(info.duration_s)


# -- properties ----------------------------------------------------------------------------------

FRAME = st.tuples(st.integers(-12, 12), st.integers(-12, 12), st.integers(1, 9), st.integers(1, 9),
                  st.integers(0, 2**32 - 1))


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(FRAME, min_size=1, max_size=6), chunk=st.sampled_from([3, 4, 7, 64]))
def test_mosaic_equals_a_brute_force_paste(frames, chunk):
    """Any frames on the global grid (any offsets, sizes, seen cells and GSDs, chunks of any size):
    each cell holds the first frame with the smallest GSD among those that saw it."""
    crs, res = pyproj.CRS.from_epsg(32633), (5.0, 5.0)
    mos = Mosaic(crs, res, 2, np.int16, -1, chunk=chunk)
    ref_f = {}
    for k, (r0, c0, h, w, seed) in enumerate(frames):
        rng = np.random.default_rng(seed)
        valid = rng.random((h, w)) < 0.7
        gsd = rng.choice([0.5, 1.0, 2.0], (h, w)).astype(np.float32)
        data = np.stack([np.full((h, w), k), rng.integers(0, 100, (h, w))]).astype(np.int16)
        grid = OutputGrid(crs, from_origin(c0 * res[0], -r0 * res[1], *res), (h, w), res)
        mos.add(k, grid, data, valid, gsd)
        for i, j in zip(*np.nonzero(valid), strict=True):
            key = (r0 + i, c0 + j)
            if key not in ref_f or gsd[i, j] < ref_f[key][0]:
                ref_f[key] = (gsd[i, j], k, data[1, i, j])
    if not ref_f:
        with pytest.raises(Exception, match="empty"):
            mos.result()
        return
    r = mos.result()
    top, left = round(-r.grid.transform.f / res[1]), round(r.grid.transform.c / res[0])
    assert top == min(k[0] for k in ref_f) and left == min(k[1] for k in ref_f)
    assert r.grid.shape == (max(k[0] for k in ref_f) - top + 1, max(k[1] for k in ref_f) - left + 1)
    for (gr, gc), (g, k, v) in ref_f.items():
        assert r.frame[gr - top, gc - left] == k and r.data[0, gr - top, gc - left] == k
        assert r.data[1, gr - top, gc - left] == v and r.gsd_m[gr - top, gc - left] == g
    assert int(r.valid.sum()) == len(ref_f)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 30), rate=st.sampled_from([1.0, 5.0, 25.0, 29.97]), seed=st.integers(0, 2**32 - 1))
def test_frames_at_record_times_get_the_records(n, rate, seed):
    """Frames at the records' own times get the records' pose and values unchanged (the
    synchronous carriage case), whatever the rate and the motion."""
    from eoloc.sequence.sync import Metadata, poses_at_frames

    rng = np.random.default_rng(seed)
    t = 1000.0 + np.arange(n) / rate
    pose = Pose(40 + rng.normal(0, 0.01, n), -105 + rng.normal(0, 0.01, n), 3000 + rng.normal(0, 50, n),
                rng.uniform(0, 360, n), rng.uniform(-20, 20, n), rng.uniform(-30, 30, n),
                (rng.uniform(0, 360, n), rng.uniform(-90, 0, n)))
    hfov = rng.uniform(1, 60, n)
    fp = poses_at_frames(Metadata(t, pose, {"hfov_deg": hfov}, "test"), t, max_gap_s=2.0 / rate)
    assert fp.ok.all()
    np.testing.assert_allclose(fp.values["hfov_deg"], hfov, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fp.pose.lat_deg, pose.lat_deg, atol=1e-9)
    np.testing.assert_allclose(fp.pose.h_m, pose.h_m, atol=1e-6)
    for a, b in zip(fp.pose.gimbal_deg, pose.gimbal_deg, strict=True):
        np.testing.assert_allclose((a - b + 180) % 360 - 180, 0, atol=1e-9)
    from eoloc.rotation import R_ned_body

    np.testing.assert_allclose(R_ned_body(fp.pose.yaw_deg, fp.pose.pitch_deg, fp.pose.roll_deg),
                               R_ned_body(pose.yaw_deg, pose.pitch_deg, pose.roll_deg), atol=1e-9)
