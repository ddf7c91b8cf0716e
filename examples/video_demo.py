"""The video demo: a synthetic video over Longs Peak with known truth, through `eoloc video`.

1. A 10 s pass north at 6 000 m, 3.5 km east of the summit, the turret sweeping 40° across the
   mountain, 35° below the horizon. Its metadata is an ST 0601 KLV stream at 5 Hz (platform
   pose, turret angles, fields of view, HAE altitude), with ST 0903 VMTI: three "vehicles"
   (20 x 10 m red rectangles driving over the terrain at 10, 14 and 18 m/s) boxed wherever the
   frame sees them.
2. The video (640 x 360, 10 frames/s, H.264) is rendered through eoloc's sensor model, one ray per pixel
   onto the bundled SRTM DEM: every pixel shows the ground texture where its ray lands. The
   texture is a hillshade of the DEM under a checkerboard of 60 m squares in UTM 13N (light
   squares warm, dark squares cool, so the board survives the shading).
3. PyAV muxes the video and the KLV (asynchronous carriage) into one MPEG-TS.
4. `eoloc video --detect motion` rectifies every frame onto the DEM, builds the mosaic, the XYZ
   tiles and the player (player.html: the video beside the map), locates the VMTI targets, and
   finds the vehicles itself in the pixels (what moves on the ground), tracks and locates them.
5. `eoloc refine` on the same TS: the KLV is the truth, so refinement from the pixels must find
   nothing wrong (every estimate within 2 sigma of zero) and say what a straight level pass cannot
   separate (the mount's yaw from the heading).
6. Accuracy against the texture's known geometry: each board corner inside the mosaic is found
   by OpenCV's cornerSubPix in the mosaic and compared with where the corner truly is; the
   movers eoloc found against the vehicles' true tracks (frames found in, distance from the
   true centre, speed, false tracks).

    python examples/video_demo.py [--out out/demo/video]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np
import pyproj
import rasterio

import eoloc
from eoloc import AzElGimbal, Camera, Pose, SensorModel, geodetic_to_ecef, open_dem
from eoloc.io.klv.encode import encode_uas_packet, encode_vmti
from eoloc.io.klv.mux import write_klv_ts
from eoloc.rules import locate_dem
from eoloc.terrain import DEM

DEM_PATH = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"
WIDTH, HEIGHT, HFOV_DEG, FPS, SECONDS, KLV_HZ = 640, 360, 20.0, 10, 10.0, 5
AZ_RATE_DEG_S = 4.0  # the turret's sweep
SQUARE_M = 60.0
CELL_M = 3.0  # the mosaic's cell
UTM = pyproj.CRS.from_epsg(32613)
START_UNIX_S = datetime(2026, 7, 14, 16, 0, 0, tzinfo=UTC).timestamp()
LIGHT, DARK = np.array([215.0, 190.0, 150.0]), np.array([95.0, 115.0, 150.0])
VEHICLE, VEHICLE_L_M, VEHICLE_W_M = np.array([235.0, 30.0, 30.0]), 20.0, 10.0
VEHICLE_AT_S = (2.0, 5.0, 8.0)  # each vehicle passes the frame centre of this moment of the pass
VEHICLE_SPEED_MPS = (10.0, 14.0, 18.0)
VEHICLE_HEADING_DEG = (40.0, 160.0, 285.0)  # clockwise from grid north (UTM 13N)


def truth_pose(t_s: np.ndarray) -> Pose:
    """The pass: north at 60 m/s, 6 000 m ellipsoidal, wings level, turret az 250° -> 290°."""
    t = np.asarray(t_s, dtype=float)
    lat = 40.236 + 60.0 * t / 111_030.0
    az = 250.0 + AZ_RATE_DEG_S * t
    return Pose(lat, np.full_like(t, -105.572), np.full_like(t, 6000.0), np.zeros_like(t), np.zeros_like(t),
                np.zeros_like(t), (az, np.full_like(t, -35.0), np.zeros_like(t)))


def vfov_deg() -> float:
    return float(np.degrees(2 * np.arctan(np.tan(np.radians(HFOV_DEG) / 2) * HEIGHT / WIDTH)))


@dataclass(frozen=True)
class Vehicles:
    """The vehicles' tracks: straight, at constant speed, in UTM 13N: ``start`` (K, 2) at t = 0 s,
    ``velocity`` (K, 2) m/s east and north."""

    start: np.ndarray
    velocity: np.ndarray

    def at(self, t_s: float) -> np.ndarray:
        """(K, 2) UTM centres at time t_s (s since the start of the pass)."""
        return self.start + self.velocity * t_s

    @property
    def heading_rad(self) -> np.ndarray:
        return np.arctan2(self.velocity[:, 0], self.velocity[:, 1])

    @property
    def speed_mps(self) -> np.ndarray:
        return np.hypot(self.velocity[:, 0], self.velocity[:, 1])

    def corners(self, k: int, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """UTM x, y of vehicle k's centre and four corners at t_s."""
        (x, y), h = self.at(t_s)[k], self.heading_rad[k]
        fwd, right = np.array([np.sin(h), np.cos(h)]), np.array([np.cos(h), -np.sin(h)])
        pts = [np.array([x, y])] + [np.array([x, y]) + a * VEHICLE_L_M / 2 * fwd + b * VEHICLE_W_M / 2 * right
                                    for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
        p = np.array(pts)
        return p[:, 0], p[:, 1]

    def on(self, x: np.ndarray, y: np.ndarray, t_s: float) -> list[np.ndarray]:
        """Per vehicle: where (x, y) lies on it at t_s."""
        out = []
        for (cx, cy), h in zip(self.at(t_s), self.heading_rad, strict=True):
            dx, dy = x - cx, y - cy
            along, across = dx * np.sin(h) + dy * np.cos(h), dx * np.cos(h) - dy * np.sin(h)
            out.append((np.abs(along) <= VEHICLE_L_M / 2) & (np.abs(across) <= VEHICLE_W_M / 2))
        return out


def vehicles(dem: DEM, sensor: SensorModel) -> Vehicles:
    """The vehicles: each passes the middle of the board square under the frame centre at its
    time of VEHICLE_AT_S, at its speed and heading."""
    t = np.array(VEHICLE_AT_S)
    c = sensor.camera
    f = locate_dem(sensor, truth_pose(t), dem, (np.full(t.shape, c.cx), np.full(t.shape, c.cy)))
    x, y = pyproj.Transformer.from_crs(4326, UTM, always_xy=True).transform(f.lon_deg, f.lat_deg)
    mid = np.stack([(np.floor(x / SQUARE_M) + 0.5) * SQUARE_M, (np.floor(y / SQUARE_M) + 0.5) * SQUARE_M], -1)
    h = np.radians(VEHICLE_HEADING_DEG)
    vel = np.array(VEHICLE_SPEED_MPS)[:, None] * np.stack([np.sin(h), np.cos(h)], -1)
    return Vehicles(mid - vel * t[:, None], vel)


def vehicle_boxes(dem: DEM, sensor: SensorModel, cars: Vehicles, t_s: float) -> tuple[list, dict]:
    """The VMTI of time ``t_s``: (id, u, v) of each vehicle the frame sees (in the image, not
    hidden by terrain) and its box (the image of its corners)."""
    to_ll = pyproj.Transformer.from_crs(UTM, 4326, always_xy=True)
    p = truth_pose(np.array(t_s))
    targets, boxes = [], {}
    for k in range(len(cars.start)):
        lon, lat = to_ll.transform(*cars.corners(k, t_s))
        h = dem.height(lat, lon)
        u, v = sensor.ground_to_image(p, np.stack(geodetic_to_ecef(lat, lon, h), -1))
        c = sensor.camera
        if not (np.isfinite(u).all() and 0 <= u[0] <= c.width - 1 and 0 <= v[0] <= c.height - 1):
            continue
        seen = locate_dem(sensor, p, dem, (u[:1], v[:1]))  # hidden by terrain: the ray lands elsewhere
        if not (seen.ok[0] and abs(seen.lat_deg[0] - lat[0]) * 111_000 < 10 and
                abs(seen.lon_deg[0] - lon[0]) * 85_000 < 10):
            continue
        targets.append((k + 1, float(u[0]), float(v[0])))
        boxes[k + 1] = (float(u[1:].min()), float(v[1:].min()), float(u[1:].max()), float(v[1:].max()))
    return targets, boxes


def klv_packets(seconds: float = SECONDS, vmti=None) -> list[tuple[bytes, float]]:
    """The pass as ST 0601 packets at KLV_HZ, each with its time (s since the start); ``vmti(t)``:
    the (targets, boxes) of the VMTI set at time t."""
    t = np.arange(int(seconds * KLV_HZ) + 1) / KLV_HZ
    p = truth_pose(t)
    out = []
    for i, ti in enumerate(t):
        values = {2: datetime.fromtimestamp(START_UNIX_S + ti, UTC), 5: 0.0, 6: 0.0, 7: 0.0,
                  13: float(p.lat_deg[i]), 14: float(p.lon_deg[i]), 75: float(p.h_m[i]), 16: HFOV_DEG,
                  17: vfov_deg(), 18: float(p.gimbal_deg[0][i]), 19: float(p.gimbal_deg[1][i]), 20: 0.0}
        if vmti is not None:
            targets, boxes = vmti(float(ti))
            if targets:
                values[74] = encode_vmti(targets, WIDTH, HEIGHT, boxes=boxes)
        out.append((encode_uas_packet(values), float(ti)))
    return out


def hillshade(dem: DEM) -> DEM:
    """The DEM's hillshade (0.25..1, sun from the north-west, 45° up) on the DEM's own grid."""
    g = dem.grid
    lat_mid = g.lat0 + g.dlat * g.z.shape[0] / 2
    dy = g.dlat * 111_132.0
    dx = g.dlon * 111_320.0 * np.cos(np.radians(lat_mid))
    dz_dr, dz_dc = np.gradient(g.z, dy, dx)  # north is -row when dlat < 0: dz_dr is d/dy along the rows
    nx, ny, nz = -dz_dc, -dz_dr, np.ones_like(g.z)
    norm = np.sqrt(nx**2 + ny**2 + nz**2)
    sun = np.array([-np.sqrt(0.5) * np.cos(np.radians(45)), np.sqrt(0.5) * np.cos(np.radians(45)),
                    np.sin(np.radians(45))])
    shade = np.clip((nx * sun[0] + ny * sun[1] + nz * sun[2]) / norm, 0.0, 1.0)
    return DEM.from_array(0.25 + 0.75 * shade, lat0=g.lat0, lon0=g.lon0, dlat=g.dlat, dlon=g.dlon, source="hillshade")


def square_wave(x: np.ndarray, width: np.ndarray | float = 0.0) -> np.ndarray:
    """+1 on even board columns (rows), -1 on odd ones, box-filtered over ``width`` metres (a
    pixel's extent on the ground), so edges are as a sensor would integrate them: no aliasing."""
    k = np.floor(x / SQUARE_M)
    frac = x / SQUARE_M - k
    d = np.minimum(frac, 1.0 - frac) * SQUARE_M  # distance to the nearest edge
    sign = np.where(k % 2 == 0, 1.0, -1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return sign * np.where(width > 0, np.minimum(2.0 * d / np.maximum(width, 1e-9), 1.0), 1.0)


def texture(shade: DEM, lat: np.ndarray, lon: np.ndarray, pixel_extent: bool = False,
            cars: Vehicles | None = None, t_s: float = 0.0) -> np.ndarray:
    """The ground's colour (…, 3) float at (lat, lon): the board in UTM 13N times the hillshade,
    and the vehicles where they are at ``t_s``. ``pixel_extent``: (lat, lon) are an image's pixels,
    and the board is averaged over each pixel's footprint (from the neighbouring pixels' ground
    points)."""
    x, y = pyproj.Transformer.from_crs(4326, UTM, always_xy=True).transform(lon, lat)
    wx = wy = 0.0
    if pixel_extent:
        (dx_dv, dx_du), (dy_dv, dy_du) = np.gradient(x), np.gradient(y)
        wx, wy = np.nan_to_num(np.abs(dx_du) + np.abs(dx_dv)), np.nan_to_num(np.abs(dy_du) + np.abs(dy_dv))
    light = (0.5 + 0.5 * square_wave(x, wx) * square_wave(y, wy))[..., None]
    colour = light * LIGHT + (1.0 - light) * DARK
    for on in cars.on(x, y, t_s) if cars is not None else ():
        colour = np.where(on[..., None], VEHICLE, colour)
    s = shade.height(lat, lon)[..., None]
    return colour * np.nan_to_num(s, nan=0.0)


def board_contrast(rgb: np.ndarray, shade: np.ndarray) -> np.ndarray:
    """The board alone (float32): the image's luma (where video keeps full resolution; its chroma
    is halved) divided by the known hillshade at each cell."""
    y = rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.nan_to_num(y / shade, nan=0.0, posinf=0.0).astype(np.float32)


def render(dem: DEM, shade: DEM, sensor: SensorModel, i: int, cars: Vehicles | None = None) -> np.ndarray:
    """Frame i (RGB uint8): every pixel's ray onto the DEM, coloured by the texture over the
    pixel's footprint there (sky and ground off the DEM grey)."""
    p = truth_pose(np.array(i / FPS))
    u, v = np.meshgrid(np.arange(WIDTH, dtype=float), np.arange(HEIGHT, dtype=float))
    f = locate_dem(sensor, p, dem, (u, v))
    rgb = np.where(f.ok[..., None], texture(shade, f.lat_deg, f.lon_deg, pixel_extent=True, cars=cars,
                                                 t_s=i / FPS), 40.0)
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


def corner_errors(folder: Path, shade: DEM) -> tuple[np.ndarray, np.ndarray]:
    """Each board corner well inside the mosaic (``folder``/mosaic.tif), refined by OpenCV's
    cornerSubPix from where it truly is: its distance from the truth (output cells), and the
    ground sample distance (m) of the frame the mosaic took there (mosaic_source.tif)."""
    with rasterio.open(folder / "mosaic.tif") as ds:
        rgb = np.moveaxis(ds.read(), 0, -1)
        valid = ds.read_masks(1) > 0
        t = ds.transform
    with rasterio.open(folder / "mosaic_source.tif") as ds:
        gsd = ds.read(2)
    rows, cols = valid.shape
    cx, cy = np.meshgrid(t.c + (np.arange(cols) + 0.5) * t.a, t.f + (np.arange(rows) + 0.5) * t.e)
    lon, lat = pyproj.Transformer.from_crs(UTM, 4326, always_xy=True).transform(cx, cy)
    img = board_contrast(rgb, shade.height(lat, lon))
    x0, y1 = t.c, t.f
    xs = np.arange(np.ceil(x0 / SQUARE_M), np.floor((x0 + cols * t.a) / SQUARE_M) + 1) * SQUARE_M
    ys = np.arange(np.ceil((y1 + rows * t.e) / SQUARE_M), np.floor(y1 / SQUARE_M) + 1) * SQUARE_M
    gx, gy = np.meshgrid(xs, ys)
    col = (gx.ravel() - x0) / t.a - 0.5  # OpenCV: pixel centres at integers
    row = (gy.ravel() - y1) / t.e - 0.5
    half = max(round(0.3 * SQUARE_M / t.a), 3)
    keep = []
    for r, c in zip(row, col, strict=True):
        ri, ci = round(r), round(c)
        if half + 1 <= ri < rows - half - 1 and half + 1 <= ci < cols - half - 1 and \
                valid[ri - half - 1:ri + half + 2, ci - half - 1:ci + half + 2].all():
            keep.append((c, r))
    if not keep:
        return np.zeros(0), np.zeros(0)
    truth = np.array(keep, dtype=np.float32)
    got = cv2.cornerSubPix(img, truth.reshape(-1, 1, 2).copy(), (half, half), (-1, -1),
                           (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4))
    at = np.rint(truth).astype(int)
    return np.linalg.norm(got.reshape(-1, 2) - truth, axis=1), gsd[at[:, 1], at[:, 0]]


def read_rows(path: Path) -> list[dict]:
    import csv

    return list(csv.DictReader(path.open())) if path.exists() else []


def utm_of(rows: list[dict]) -> np.ndarray:
    x, y = pyproj.Transformer.from_crs(4326, UTM, always_xy=True).transform(
        np.array([float(r["lon_deg"]) for r in rows]), np.array([float(r["lat_deg"]) for r in rows]))
    return np.stack([x, y], -1).reshape(-1, 2)


def vmti_errors(path: Path, cars: Vehicles) -> np.ndarray:
    """Horizontal distance (m) of each located VMTI detection (vmti.csv) from its vehicle's centre
    at the detection's time."""
    rows = [r for r in read_rows(path) if r["status"] == "OK"]
    if not rows:
        return np.zeros(0)
    xy = utm_of(rows)
    truth = np.array([cars.at(float(r["video_time_s"]))[int(r["target_id"]) - 1] for r in rows])
    return np.hypot(*(xy - truth).T)


def mover_scores(path: Path, cars: Vehicles, visible: dict[int, set[int]], match_m: float = 25.0) -> dict:
    """The movers eoloc found (detections.csv) against the vehicles: each track is the vehicle its
    detections lie nearest to (median within ``match_m``, else a false track); per vehicle the
    fraction of the frames it is visible in (``visible``: frame -> vehicle indices) where its
    track has a detection, the detections' distance from its true centre, and the track's
    filtered speed against the true one."""
    rows = [r for r in read_rows(path) if r["status"] == "OK"]
    out = {"tracks": 0, "false_tracks": 0, "vehicles": []}
    if not rows:
        return out
    xy = utm_of(rows)
    tid = np.array([int(r["track_id"]) for r in rows])
    frame = np.array([int(r["frame"]) for r in rows])
    t = np.array([float(r["time_s"]) for r in rows])
    dist = np.stack([np.hypot(*(xy - np.array([cars.at(ti)[k] for ti in t])).T) for k in range(len(cars.start))])
    owner = {}
    for n in np.unique(tid):
        d = np.median(dist[:, tid == n], axis=1)
        owner[int(n)] = int(np.argmin(d)) if d.min() <= match_m else -1
    out["tracks"] = len(owner)
    out["false_tracks"] = sum(v < 0 for v in owner.values())
    for k in range(len(cars.start)):
        mine = np.array([owner[int(n)] == k for n in tid])
        seen = {f for f, ks in visible.items() if k in ks}
        found = set(frame[mine].tolist()) & seen
        speed = np.array([float(r["speed_mps"]) for r, m, ti in zip(rows, mine, t, strict=True)
                          if m and r["speed_mps"] not in ("", "nan")])
        out["vehicles"].append({"vehicle": k + 1, "visible_frames": len(seen), "found_frames": len(found),
                                "recall": len(found) / len(seen) if seen else float("nan"),
                                "median_error_m": float(np.median(dist[k, mine])) if mine.any() else float("nan"),
                                "speed_mps": float(np.median(speed[len(speed) // 3:])) if speed.size else float("nan"),
                                "true_speed_mps": float(cars.speed_mps[k])})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/demo/video", help="output folder")
    ap.add_argument("--seconds", type=float, default=SECONDS, help="length of the pass (s)")
    args = ap.parse_args(argv)
    out, seconds = Path(args.out), args.seconds
    out.mkdir(parents=True, exist_ok=True)
    dem = open_dem(DEM_PATH)
    shade = hillshade(dem)
    sensor = SensorModel(Camera.from_hfov(HFOV_DEG, WIDTH, HEIGHT, vfov_deg=vfov_deg()), AzElGimbal())
    t0 = time.perf_counter()
    n = int(seconds * FPS) + 1
    cars = vehicles(dem, sensor)
    packets = klv_packets(seconds, vmti=lambda t: vehicle_boxes(dem, sensor, cars, t))
    ts = write_klv_ts(out / "longs_peak_pass.ts", [packets], video_fps=FPS, video_size=(WIDTH, HEIGHT),
                      frame_source=lambda i: render(dem, shade, sensor, i, cars))
    print(f"rendered {n} frames of {WIDTH} x {HEIGHT} through the sensor model onto the DEM and muxed them with "
          f"{int(seconds * KLV_HZ) + 1} ST 0601 packets into {ts} ({time.perf_counter() - t0:.1f} s)", flush=True)
    cmd = [sys.executable, "-m", "eoloc", "video", str(ts), "--dem", str(DEM_PATH), "--gsd", f"{CELL_M:g}",
           "--detect", "motion", "--out", str(out / "eoloc")]
    print("$ eoloc video " + " ".join(cmd[4:]), flush=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    print(f"eoloc video took {time.perf_counter() - t0:.1f} s for {n} frames", flush=True)
    err, gsd = corner_errors(out / "eoloc", shade)
    if not err.size:
        print("no board corner lies well inside the mosaic: nothing to measure")
        return 1
    vmti_m = vmti_errors(out / "eoloc" / "vmti.csv", cars)
    visible = {i: {k - 1 for k, _, _ in vehicle_boxes(dem, sensor, cars, i / FPS)[0]} for i in range(n)}
    movers = mover_scores(out / "eoloc" / "detections.csv", cars, visible)
    (out / "accuracy.json").write_text(json.dumps({"corners": int(err.size), "cells_m": CELL_M,
                                                   "error_cells": err.round(4).tolist(),
                                                   "frame_gsd_m": gsd.round(3).tolist(),
                                                   "vmti_error_m": vmti_m.round(3).tolist(),
                                                   "movers": movers}) + "\n")
    sharp = gsd <= 1.5 * CELL_M
    px = err * CELL_M / gsd
    print(f"accuracy against the texture's known geometry, {err.size} board corners inside the mosaic found by "
          "OpenCV (cornerSubPix) and compared with where they truly are:")
    if sharp.any():
        print(f"  where the frame's pixel is at most 1.5 cells ({sharp.sum()} corners): median "
              f"{np.median(err[sharp]):.2f}, p95 {np.percentile(err[sharp], 95):.2f} output cells of {CELL_M:g} m")
    print(f"  all corners, in the frame's own pixels (GSD {np.median(gsd):.1f} m median, up to {gsd.max():.0f} m on "
          f"slopes seen edge-on): median {np.median(px):.2f}, p95 {np.percentile(px, 95):.2f} px")
    if vmti_m.size:
        print(f"VMTI: {vmti_m.size} detections of the {len(cars.start)} vehicles located by eoloc with their packets' "
              "poses: "
              f"median {np.median(vmti_m):.1f} m, max {vmti_m.max():.1f} m from the vehicles' true centres (the "
              "encoder's centroids are whole pixels)")
    print(f"movers found by eoloc in the pixels (--detect motion): {movers['tracks']} tracks, "
          f"{movers['false_tracks']} false")
    for v in movers["vehicles"]:
        print(f"  vehicle {v['vehicle']}: found in {v['found_frames']} of the {v['visible_frames']} frames it is "
              f"visible in, median {v['median_error_m']:.1f} m from its true centre, speed "
              f"{v['speed_mps']:.1f} m/s (true {v['true_speed_mps']:g})")
    # the pass refined from its own pixels: the KLV is the truth here, so refinement must find nothing
    # wrong (every estimate within 2 sigma of zero) and say what a straight level pass cannot separate;
    # a pass shorter than the demo's leaves too few keyframes for it
    refined = None
    if seconds >= SECONDS:
        cmd = [sys.executable, "-m", "eoloc", "refine", str(ts), "--dem", str(DEM_PATH), "--json",
               "--out", str(out / "refine")]
        print("$ eoloc refine " + " ".join(cmd[4:]), flush=True)
        t0 = time.perf_counter()
        refined = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        print(f"eoloc refine took {time.perf_counter() - t0:.1f} s: {refined['tie_points']} tie points in "
              f"{refined['keyframes']} keyframes, RMS {refined['rms_px_after']:.2f} px; nothing injected, found:")
        for name, v in refined["parameters"].items():
            sig = refined["sigma"][name]
            note = " (not determined by this pass)" if name in refined["undetermined"] else ""
            print(f"  {name} {v:+.3g} +- {sig:.2g}{note}")
        for note in refined.get("klv_notes", []):  # the TS again with its packets' poses corrected in place
            print(f"  {note} ({out / 'refine'})")
    # a figure outside its stated bound fails the demo (and make demo); the movers' on the whole pass
    out_of_bounds = []
    for name, v in (refined or {"parameters": {}})["parameters"].items():
        if abs(v) > 2 * refined["sigma"][name]:
            out_of_bounds.append(f"refine: {name} {v:+.4f} is more than 2 sigma ({refined['sigma'][name]:.4f}) from "
                                 "zero, where nothing is wrong")
    if sharp.any() and np.median(err[sharp]) > 0.15:
        out_of_bounds.append(f"board corners median {np.median(err[sharp]):.2f} cells (bound 0.15)")
    if vmti_m.size and vmti_m.max() > 5.0:
        out_of_bounds.append(f"VMTI up to {vmti_m.max():.1f} m off (bound 5)")
    if seconds >= SECONDS:
        if movers["false_tracks"] > 0:
            out_of_bounds.append(f"{movers['false_tracks']} false movers (bound: none in 10 s)")
        for v in movers["vehicles"]:
            if not (v["recall"] >= 0.95 and v["median_error_m"] <= 5.0
                    and abs(v["speed_mps"] / v["true_speed_mps"] - 1) <= 0.10):
                out_of_bounds.append(f"vehicle {v['vehicle']}: found in {v['recall']:.0%} of its frames, median "
                                     f"{v['median_error_m']:.1f} m, speed {v['speed_mps']:.1f} m/s (bounds 95 %, 5 m, "
                                     f"10 %)")
    for line in out_of_bounds:
        print(f"OUT OF BOUNDS: {line}")
    if out_of_bounds:
        return 1
    print(f"the player: open {out / 'eoloc' / 'player.html'} in a browser (offline), or for exact clicks:")
    print(f"  {json.loads((out / 'eoloc' / 'video.json').read_text())['player']['serve']}")
    print(f"open {out / 'eoloc' / 'mosaic.tif'} in QGIS, or its tiles: {out / 'eoloc' / 'tiles'}/{{z}}/{{x}}/{{y}}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
