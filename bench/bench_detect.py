"""Moving targets found in video (`eoloc video --detect motion`, eoloc.detect): speed and what is
found, against OpenCV's plain frame differencing on the same frames.

1. Throughput, 1280 x 720: a flight over flat textured ground with 20 vehicles (5-20 m/s) rendered
   by OpenCV (tests/helpers/moving_scene.py; ~0.5 m ground pixels). eoloc: every frame warped onto its
   references through the poses, the residual measured, changes -> blobs -> located on the
   ground -> Kalman tracks (detection + tracking + location). The peer: consecutive frames
   differenced as they are (cv2.absdiff, threshold, closing, connected components): what a
   detector does without the camera's motion removed. Per frame, a blob within 10 px of a vehicle
   in view is a hit (one per vehicle), any other a false one.
2. Terrain parallax: a 10 s pass over Longs Peak (the video demo's renderer: 640 x 360 through
   the sensor model onto the SRTM DEM) with 20 vehicles driving on the mountain; eoloc with the
   DEM (terrain parallax taken out) and with a flat ground at the terrain's mean height (what a
   homography-based stabiliser assumes): recall, precision and the movers' distance from the true
   centres.
3. Buildings: tall things not in the ground model (the documented false-alarm source), their
   roofs shifting by parallax: false detections and false tracks with and without the movers'
   minimum speed.
4. Live: `eoloc live --detect motion` on a 1280 x 720 H.264 + KLV stream at 30 frames/s replayed at
   its own clock: frames searched and skipped, the movers' latency, the KLV path's latency beside it.

    python bench/bench_detect.py [--frames 60]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))



def vehicles_in_view(ms, rng, n: int, seconds: float):
    cars = []
    while len(cars) < n:
        t = rng.uniform(0, seconds)
        c, R = ms.camera_enu(t)
        u, v = rng.uniform(80, ms.W - 80), rng.uniform(60, ms.H - 60)
        ray = R.T @ np.linalg.solve(ms.K(), [u, v, 1.0])
        e, nn = (c + ray * (-c[2] / ray[2]))[:2]
        hdg, speed = rng.uniform(0, 360), rng.uniform(5, 20)
        h = np.radians(hdg)
        cars.append(ms.Vehicle(e - speed * t * np.sin(h), nn - speed * t * np.cos(h), hdg, speed))
    return cars


def pixel_of(ms, car, t):
    c, R = ms.camera_enu(t)
    e, n = car.centre(t)
    p = ms.K() @ (R @ (np.array([e, n, 0.0]) - c))
    return p[:2] / p[2]


def count(ms, cars, frames_uv: dict[int, np.ndarray], n: int, radius_px: float = 10.0) -> tuple[int, int, int]:
    """(hits, misses, false blobs) over the frames: per frame each vehicle in view is hit by the
    nearest blob within radius_px (a blob hits one vehicle at most)."""
    hits = misses = false = 0
    for i in range(n):
        t = i / ms.FPS
        uv = frames_uv.get(i, np.zeros((0, 2)))
        used = np.zeros(len(uv), bool)
        for car in cars:
            if not ms.in_view(car, t):
                continue
            if len(uv):
                d = np.hypot(*(uv - pixel_of(ms, car, t)).T)
                d[used] = np.inf
                j = int(np.argmin(d))
                if d[j] <= radius_px:
                    used[j] = True
                    hits += 1
                    continue
            misses += 1
        false += int((~used).sum())
    return hits, misses, false


def posed(ms, images: list) -> list:
    """The scene's frames as the detector takes them: (index, time s, image, sensor, pose), the
    camera a pinhole of the scene's K on an az-el turret, its pose from the scene's telemetry."""
    from eoloc import AzElGimbal, Camera, Pose, SensorModel

    K = ms.K()
    sensor = SensorModel(Camera(ms.W, ms.H, K[0, 0], K[1, 1], K[0, 2], K[1, 2]), AzElGimbal())
    out = []
    for i, img in enumerate(images):
        tel = ms.telemetry(i / ms.FPS)
        out.append((i, i / ms.FPS, img, sensor, Pose(tel["lat_deg"], tel["lon_deg"], tel["h_m"], 0.0, 0.0, 0.0,
                                                     (tel["az_deg"], tel["el_deg"], tel["roll_deg"]))))
    return out


def plain_differencing(images, threshold: float = 40.0) -> dict[int, np.ndarray]:
    import cv2

    out = {}
    for i in range(1, len(images)):
        d = cv2.absdiff(images[i], images[i - 1]).max(axis=-1)
        mask = cv2.morphologyEx((d > threshold).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
        n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
        keep = stats[1:, cv2.CC_STAT_AREA] >= 6
        out[i] = cents[1:][keep]
    return out


def throughput(n_frames: int) -> list[str]:
    import moving_scene as ms

    from eoloc.jobs.detect import detect_movers
    from eoloc.rules import AtHeight

    ms.W, ms.H = 1280, 720
    rng = np.random.default_rng(11)
    seconds = n_frames / ms.FPS
    cars = vehicles_in_view(ms, rng, 20, seconds)
    tex = ms.ground_texture()
    images = [ms.render(tex, cars, i / ms.FPS) for i in range(n_frames)]
    frames = posed(ms, images)
    t0 = time.perf_counter()
    movers = detect_movers(frames, AtHeight(ms.ORIGIN[2]))
    eoloc_s = time.perf_counter() - t0
    uv: dict[int, list] = {}
    for r in movers.rows:
        uv.setdefault(r["frame"], []).append((r["u_px"], r["v_px"]))
    eo = count(ms, cars, {k: np.array(v) for k, v in uv.items()}, n_frames)
    t0 = time.perf_counter()
    plain = plain_differencing(images)
    plain_s = time.perf_counter() - t0
    pl = count(ms, cars, plain, n_frames)
    fps, pfps = n_frames / eoloc_s, n_frames / plain_s
    return [f"| 1280 x 720, 20 movers, {n_frames} frames: detection + tracking + location | {fps:.1f} frames/s; "
            f"found {eo[0]} of {eo[0] + eo[1]} vehicle-frames ({eo[0] / max(eo[0] + eo[1], 1):.1%}), "
            f"{eo[2]} false; {len(movers.tracks)} tracks | plain frame differencing (OpenCV) {pfps:.0f} frames/s: "
            f"found {pl[0]} ({pl[0] / max(pl[0] + pl[1], 1):.1%}), {pl[2]} false | {fps / pfps:.2g}x |"]


def parallax(n_frames: int) -> list[str]:
    import pyproj
    import video_demo as V

    from eoloc import AzElGimbal, Camera, SensorModel, open_dem
    from eoloc.detect import MotionSettings
    from eoloc.jobs.detect import detect_movers
    from eoloc.rules import AtHeight, OnDEM, locate_dem

    dem = open_dem(V.DEM_PATH)
    shade = V.hillshade(dem)
    sensor = SensorModel(Camera.from_hfov(V.HFOV_DEG, V.WIDTH, V.HEIGHT, vfov_deg=V.vfov_deg()), AzElGimbal())
    rng = np.random.default_rng(5)
    seconds = (n_frames - 1) / V.FPS
    t = rng.uniform(0.5, seconds - 0.5, 20)
    pixels = (rng.uniform(60, V.WIDTH - 60, 20), rng.uniform(40, V.HEIGHT - 40, 20))
    f = locate_dem(sensor, V.truth_pose(t), dem, pixels)
    x, y = pyproj.Transformer.from_crs(4326, V.UTM, always_xy=True).transform(f.lon_deg, f.lat_deg)
    h = rng.uniform(0, 2 * np.pi, 20)
    vel = rng.uniform(8, 20, 20)[:, None] * np.stack([np.sin(h), np.cos(h)], -1)
    cars = V.Vehicles(np.stack([x, y], -1) - vel * t[:, None], vel)
    images = [V.render(dem, shade, sensor, i, cars) for i in range(n_frames)]
    poses = [V.truth_pose(np.array(i / V.FPS)) for i in range(n_frames)]
    visible = {i: {k - 1 for k, _, _ in V.vehicle_boxes(dem, sensor, cars, i / V.FPS)[0]} for i in range(n_frames)}
    mean_h = float(np.nanmean(dem.grid.z))  # the grid's heights: a flat ground at the terrain's mean
    to_utm = pyproj.Transformer.from_crs(4326, V.UTM, always_xy=True)
    out = []
    for name, rule in (("DEM (terrain parallax removed)", OnDEM(dem)), (f"flat ground at {mean_h:.0f} m",
                                                                       AtHeight(mean_h + 16.0))):
        frames = [(i, i / V.FPS, images[i], sensor, poses[i]) for i in range(n_frames)]
        t0 = time.perf_counter()
        m = detect_movers(frames, rule, MotionSettings())
        dt = time.perf_counter() - t0
        tp = fp = 0
        err = []
        found = set()
        for r in m.rows:
            xy = np.array(to_utm.transform(r["lon_deg"], r["lat_deg"]))
            d = np.hypot(*(cars.at(r["time_s"]) - xy).T)
            k = int(np.argmin(d))
            if d[k] <= 25 and k in visible.get(r["frame"], set()):
                tp += 1
                err.append(d[k])
                found.add((r["frame"], k))
            else:
                fp += 1
        total = sum(len(v) for v in visible.values())
        e = np.array(err) if err else np.array([np.nan])
        out.append(f"| Longs Peak pass, 640 x 360, 20 movers, {n_frames} frames, ground: {name} | recall "
                   f"{len(found) / max(total, 1):.1%} of {total} vehicle-frames, precision {tp / max(tp + fp, 1):.1%}, "
                   f"{len(m.tracks)} tracks, median {np.median(e):.1f} m / p90 {np.percentile(e, 90):.1f} m from the "
                   f"true centres; {n_frames / dt:.1f} frames/s | - | - |")
    return out


def buildings(n_frames: int) -> list[str]:
    """Tall things not in the ground model (the motion detector's documented false-alarm source):
    the throughput scene at 640 x 360 with 30 box buildings 10-40 m tall among 20 vehicles, the
    ground a flat height, then a surface model holding the buildings (a DSM, as lidar or
    photogrammetry gives). On the flat ground their roofs and walls shift by parallax as the
    aircraft flies (about aircraft speed x height / range); counted: false detections, false tracks
    (movers that are no vehicle), with the movers' minimum speed (2 m/s, the default) and without
    it (0)."""
    import tempfile

    import moving_scene as ms

    from eoloc import open_dem
    from eoloc.detect.movers import MoverSettings
    from eoloc.jobs.detect import detect_movers
    from eoloc.rules import AtHeight, OnDEM

    ms.W, ms.H, ms.FPS = 640, 360, 10.0
    rng = np.random.default_rng(3)
    seconds = n_frames / ms.FPS
    cars = vehicles_in_view(ms, rng, 20, seconds)
    blds = []
    while len(blds) < 30:  # in view at mid-pass, off the vehicles' paths
        e, n = rng.uniform(-350, 350), rng.uniform(-250, 250)
        half, h = rng.uniform(8, 20), rng.uniform(10, 40)
        path_d = min(np.min(np.hypot(*(np.array(c.centre(np.linspace(0, seconds, 50))) - [[e], [n]]))) for c in cars)
        if path_d > half * 1.5 + 10:
            blds.append((e, n, half, h))
    tex = ms.ground_texture()
    images = [ms.draw_buildings(ms.render(tex, cars, i / ms.FPS), blds, i / ms.FPS) for i in range(n_frames)]
    frames = posed(ms, images)
    out = []
    with tempfile.TemporaryDirectory() as d:
        dsm = OnDEM(open_dem(ms.surface_model(blds, Path(d) / "dsm.tif"), vertical="ellipsoid"))
        runs = [(m_label, g_label, rule, settings)
                for g_label, rule in (("a flat ground", AtHeight(ms.ORIGIN[2])), ("a DSM with the buildings", dsm))
                for m_label, settings in (("min speed 2 m/s (default)", MoverSettings()),
                                          ("min speed 0", MoverSettings(min_speed_mps=0.0)))]
        results = [(m_label, g_label, detect_movers(frames, rule, movers=settings))
                   for m_label, g_label, rule, settings in runs]
    for label, ground, m in results:
        uv: dict[int, list] = {}
        track_uv: dict[int, list] = {}
        for r in m.rows:
            uv.setdefault(r["frame"], []).append((r["u_px"], r["v_px"]))
            track_uv.setdefault(r["track_id"], []).append(r)
        eo = count(ms, cars, {k: np.array(v) for k, v in uv.items()}, n_frames)
        false_tracks = 0
        for rows in track_uv.values():  # a track whose detections are mostly no vehicle's
            near = [min(np.hypot(*(pixel_of(ms, c, r["frame"] / ms.FPS) - (r["u_px"], r["v_px"]))) for c in cars)
                    for r in rows]
            false_tracks += np.median(near) > 10
        out.append(f"| 640 x 360, 20 movers among 30 buildings 10-40 m tall, {n_frames} frames, ground: {ground}, "
                   f"{label} | found {eo[0]} of {eo[0] + eo[1]} vehicle-frames "
                   f"({eo[0] / max(eo[0] + eo[1], 1):.1%}), {eo[2]} false detections, {false_tracks} false tracks of "
                   f"{len(m.tracks)} ({m.dropped_tracks} tracks dropped as no mover) | - | - |")
    return out


def live(n_frames: int) -> list[str]:
    """`eoloc live --detect motion` on a 1280 x 720 H.264 + KLV stream at 30 frames/s, replayed at its
    own clock (PCR) in this process: how many frames the worker searched (it skips those over a
    second old rather than lag), the movers' latency from a frame's arrival to its mover sent, and
    the KLV packets' latency with and without the detector running beside them."""
    import os
    import tempfile

    import moving_scene as ms

    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.live import LiveSession, NdjsonSink, run
    from eoloc.live.movers import LiveMovers
    from eoloc.rules import AtHeight

    ms.W, ms.H, ms.FPS = 1280, 720, 30.0
    n = max(n_frames, 90) * 2  # frames at 30 per second: at least 6 s (the window is 2 s each side)
    rng = np.random.default_rng(11)
    cars = vehicles_in_view(ms, rng, 20, n / ms.FPS)
    tex = ms.ground_texture()
    with tempfile.TemporaryDirectory() as d:
        ts = write_klv_ts(Path(d) / "live720.ts", [ms.klv_packets(n)], video_fps=ms.FPS, video_size=(ms.W, ms.H),
                          frame_source=lambda i: ms.render(tex, cars, i / ms.FPS))
        out = {}
        for name, movers in (("detect", LiveMovers(AtHeight(ms.ORIGIN[2]))), ("klv only", None)):
            session = LiveSession(str(ts), movers=movers)
            out[name] = run(str(ts), session, [NdjsonSink(os.devnull)], realtime=True).summary
    m = out["detect"]["movers"]
    ms.FPS = 10.0
    return [f"| `eoloc live --detect motion`, 1280 x 720 H.264 at 30 frames/s, 20 movers, {n} frames replayed at the "
            f"stream's clock | {m['frames_searched']} of {m['video_frames']} frames searched ({m['frames_skipped']} "
            f"skipped), {m['movers']} movers; mover latency p50 {m['latency_ms_median'] / 1e3:.2f} s, p99 "
            f"{m['latency_ms_p99'] / 1e3:.2f} s (window {m['window_s']:g} s); KLV packets p50 "
            f"{out['detect']['latency_ms_median']:.2f} ms | the KLV path alone p50 "
            f"{out['klv only']['latency_ms_median']:.2f} ms | |"]


def main(n_frames: int = 60) -> list[str]:
    return throughput(n_frames) + parallax(max(n_frames, 60)) + buildings(max(n_frames, 60)) + live(n_frames)


if __name__ == "__main__":
    from _common import script

    script(main, __doc__, flag="--frames", default=60, help_text="frames per scene, 10 per second (default 60)")
