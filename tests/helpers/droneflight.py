"""Synthetic drone flights over the Longs Peak tile written as a user's files: a P4 RTK .SRT (GPS
(lon, lat), HOME, H, G.PRY), a newer bracket .SRT (FrameCnt, rel_alt, abs_alt, gb_*), an Airdata
log (feet); the poses chosen first, each image centre's truth the oracle's first DEM crossing
(tests/helpers/demtruth.py). Shared by the sources' unit tests and the integration tests."""

from __future__ import annotations

import numpy as np
import oracle_lib as O
from demtruth import first_crossing, tile_grid

W, H, F, CX, CY = 1280, 960, 1100.0, 639.5, 479.5
CAMERA_TOML = f"[camera]\nwidth = {W}\nheight = {H}\nfx = {F}\ncx = {CX}\ncy = {CY}\n"


def flight(n=8, seed=48):
    """Camera poses over the tile (as the files will write them: rounded to their formats'
    decimals) and the take-off point with its ground height (the oracle's bilinear DEM)."""
    rng = np.random.default_rng(seed)
    grid = tile_grid()
    la, lo = grid.lat_range, grid.lon_range
    t_lat, t_lon = round(float(np.mean(la)), 6), round(float(np.mean(lo)), 6)
    g0 = float(grid.sample(np.array([t_lat]), np.array([t_lon]))[0][0])
    rel_min = grid.hmax - g0 + 150.0
    poses = {"lat": np.round(t_lat + rng.uniform(-0.03, 0.03, n), 6),
             "lon": np.round(t_lon + rng.uniform(-0.03, 0.03, n), 6),
             "rel": np.round(rel_min + rng.uniform(0, 300, n), 2), "yaw": np.round(rng.uniform(-180, 180, n), 1),
             "pitch": np.round(rng.uniform(-80, -35, n), 1), "roll": np.round(rng.uniform(-2, 2, n), 1)}
    return grid, (t_lat, t_lon, g0), poses


def truth(grid, g0, poses):
    """The oracle's first DEM crossing of each image centre's ray (tests/helpers/demtruth.py)."""
    cam = O.Camera(W, H, F, F, CX, CY)
    return np.array([first_crossing(grid, cam, poses["lat"][k], poses["lon"][k], g0 + poses["rel"][k],
                                    poses["yaw"][k], poses["pitch"][k], poses["roll"][k], CX, CY)
                     for k in range(poses["lat"].size)])


def write_p4(path, takeoff, poses):
    lines = []
    for k in range(poses["lat"].size):
        lines += [str(k + 1), f"00:00:{k:02d},000 --> 00:00:{k + 1:02d},000",
                  f"F/5.6, SS 400, ISO 100, EV 0, GPS ({poses['lon'][k]:.6f}, {poses['lat'][k]:.6f}, 15), "
                  f"HOME ({takeoff[1]:.6f}, {takeoff[0]:.6f}, 12.00m), D 100.00m, H {poses['rel'][k]:.2f}m, "
                  f"H.S 0.00m/s, V.S 0.00m/s, F.PRY (2.7°, -7.0°, 110.1°), "
                  f"G.PRY ({poses['pitch'][k]:.1f}°, {poses['roll'][k]:.1f}°, {poses['yaw'][k]:.1f}°)", ""]
    path.write_text("\n".join(lines), encoding="utf-8")


def write_bracket(path, takeoff, poses, abs_off_m):
    lines = []
    for k in range(poses["lat"].size):
        rel = 0.0 if k == 0 else poses["rel"][k]  # the clip starts on the ground at take-off
        lat, lon = (takeoff[0], takeoff[1]) if k == 0 else (poses["lat"][k], poses["lon"][k])
        lines += [str(k + 1), f"00:00:00,{k * 40:03d} --> 00:00:00,{k * 40 + 40:03d}",
                  f'<font size="28">FrameCnt: {k + 1}, DiffTime: 40ms', "2026-05-27 13:10:00.015",
                  f"[iso: 200] [shutter: 1/6400.0] [fnum: 1.9] [focal_len: 24.00] [latitude: {lat:.6f}] "
                  f"[longitude: {lon:.6f}] [rel_alt: {rel:.3f} abs_alt: {rel + abs_off_m:.3f}] "
                  f"[gb_yaw: {poses['yaw'][k]:.1f} gb_pitch: {poses['pitch'][k]:.1f} gb_roll: {poses['roll'][k]:.1f}]"
                  "</font>", ""]
    path.write_text("\n".join(lines), encoding="utf-8")


def write_airdata(path, poses, is_video=None):
    head = ("time(millisecond),datetime(utc),latitude,longitude,height_above_takeoff(feet),"
            "altitude_above_seaLevel(feet), compass_heading(degrees), pitch(degrees), roll(degrees),isVideo,"
            "gimbal_heading(degrees),gimbal_pitch(degrees),gimbal_roll(degrees)")
    rows = [head]
    for k in range(poses["lat"].size):
        rel_ft = poses["rel"][k] / 0.3048
        rows.append(f"{k * 100},2024-01-04 22:19:40,{poses['lat'][k]:.6f},{poses['lon'][k]:.6f},{rel_ft:.9f},"
                    f"{rel_ft + 9000:.9f}, 32.2, 1.4, 2.5,{1 if is_video is None else int(is_video[k])},"
                    f"{poses['yaw'][k]:.1f},{poses['pitch'][k]:.1f},"
                    f"{poses['roll'][k]:.1f}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


FLIGHT_FILES = {"p4rtk": "flight.SRT", "bracket": "clip.SRT", "airdata": "log.csv"}


def write_flight(folder, fmt: str, abs_off_m: float = 60.0):
    """:func:`flight` written in ``fmt`` ("p4rtk", "bracket": its record 0 on the ground at
    take-off, abs_alt ``abs_off_m`` off; "airdata": its first record at take-off) into ``folder``:
    (grid, take-off, poses as written, the file)."""
    grid, takeoff, poses = flight()
    path = folder / FLIGHT_FILES[fmt]
    if fmt == "p4rtk":
        write_p4(path, takeoff, poses)
    elif fmt == "bracket":
        write_bracket(path, takeoff, poses, abs_off_m=abs_off_m)
    else:
        poses["lat"][0], poses["lon"][0] = takeoff[0], takeoff[1]
        write_airdata(path, poses)
    return grid, takeoff, poses, path
