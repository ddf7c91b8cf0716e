"""Regenerate the mountain part of the demo in src/eoloc/data/demo/mountain/ (deterministic, seeded).

1. Terrain: a crop of the real SRTMGL3 grid of the Colorado Front Range around Longs Peak
   (tests/data/dem/SRTMGL3_boulder_front_range.asc, NASA SRTM v3, public domain, as landlab's
   example data ships it; see mountain/README.md), written as a compressed GeoTIFF with its CRS
   (EPSG:4326) and the source's no-data value. Heights stay EGM96 (as SRTM); eoloc converts them with the bundled geoid.
2. Flight: a UAV at 6 000 m ellipsoidal passes east of the peak heading north while its az-el
   turret tracks the summit; four more surveyed points on the slopes are detected when in view
   (visibility checked against the terrain with the true pose: a target behind a ridge is not
   detected). The telemetry carries a good INS's noise (position 2 m, attitude 0.03 deg, gimbal
   0.02 deg, pixels 0.7 px). In five frames a far hill near the top of the image is detected
   too: it lies beyond the west edge of the crop, so eoloc must say OUT_OF_COVERAGE.

    python examples/make_mountain_demo.py [--source PATH_TO_ASC]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
import rasterio
from rasterio.windows import from_bounds

import eoloc
from eoloc import geodesy

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "src" / "eoloc" / "data" / "demo" / "mountain"
CROP = (-105.70, 40.20, -105.55, 40.31)  # west, south, east, north (degrees)
TARGETS = {  # surveyed points (lat, lon); heights come from the terrain
    "LONGS_PEAK": (40.2549, -105.6160),
    "CHASM_LAKE": (40.2537, -105.5927),
    "MT_MEEKER": (40.2483, -105.6053),
    "EAST_LONGS": (40.2610, -105.5850),
    "STORM_PEAK": (40.2650, -105.6240),
}
CAMERA = eoloc.Camera.from_hfov(25.0, 1280, 720)
SENSOR = eoloc.SensorModel(CAMERA, eoloc.AzElGimbal())
SIGMA = {"pos_m": 2.0, "h": 3.0, "att": 0.03, "gimbal": 0.02, "px": 0.7}


def crop(source: Path) -> Path:
    OUT.mkdir(parents=True, exist_ok=True)
    dst = OUT / "longs_peak_srtmgl3.tif"
    with rasterio.open(source) as src:
        win = from_bounds(*CROP, transform=src.transform).round_offsets().round_lengths()
        z = src.read(1, window=win).astype(np.int16)
        profile = {"driver": "GTiff", "height": z.shape[0], "width": z.shape[1], "count": 1, "dtype": "int16",
                   "crs": "EPSG:4326", "transform": src.window_transform(win), "nodata": 0,
                   "compress": "deflate", "predictor": 2}
    with rasterio.open(dst, "w", **profile) as out:
        out.write(z, 1)
        out.update_tags(SOURCE="NASA SRTMGL3 v3 via landlab (see README.md)", VERTICAL_DATUM="EGM96")
    return dst


def main(source: Path) -> None:
    rng = np.random.default_rng(4345)
    dem = eoloc.open_dem(crop(source))
    truth = {k: (lat, lon, float(dem.height(lat, lon))) for k, (lat, lon) in TARGETS.items()}
    summit = np.stack(eoloc.geodetic_to_ecef(*truth["LONGS_PEAK"]), -1)
    n = 40
    times = np.arange(n) * 1.0
    # north-bound leg 9 km east of the summit, 60 m/s, at 6 000 m ellipsoidal
    ne = np.c_[(times - times.mean()) * 60.0, np.full(n, 9000.0)]
    p = geodesy.ned_to_ecef(np.c_[ne, np.full(n, -(6000.0 - truth["LONGS_PEAK"][2]))], *truth["LONGS_PEAK"])
    lat, lon, h = eoloc.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    yaw = np.zeros(n)
    pitch = np.full(n, 1.5)
    roll = np.zeros(n)
    p0 = np.stack(eoloc.geodetic_to_ecef(lat, lon, h), -1)
    az, el, _ = eoloc.AzElGimbal.pointing(lat, lon, h, yaw, pitch, roll, summit)  # the turret tracks the summit
    true_pose = eoloc.Pose(lat, lon, h, yaw, pitch, roll, (az, el))

    def noisy(x, s):
        return x + rng.normal(0.0, s, np.shape(x))

    dn = noisy(np.zeros(n), SIGMA["pos_m"]) / 111_000.0
    de = noisy(np.zeros(n), SIGMA["pos_m"]) / (111_000.0 * np.cos(np.radians(lat)))
    with (OUT / "telemetry.csv").open("w", newline="") as fh:
        fh.write("# eoloc mountain demo (synthetic flight over real SRTM terrain; examples/make_mountain_demo.py).\n")
        fh.write("# Heights ellipsoidal.\n")
        w = csv.writer(fh)
        w.writerow(["time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "azimuth_deg",
                    "elevation_deg"])
        for i in range(n):
            w.writerow([f"{times[i]:.2f}", f"{lat[i] + dn[i]:.9f}", f"{lon[i] + de[i]:.9f}",
                        f"{noisy(h[i], SIGMA['h']):.2f}", f"{noisy(yaw[i], SIGMA['att']) % 360:.4f}",
                        f"{noisy(pitch[i], SIGMA['att']):.4f}", f"{noisy(roll[i], SIGMA['att']):.4f}",
                        f"{noisy(az[i], SIGMA['gimbal']):.4f}", f"{noisy(el[i], SIGMA['gimbal']):.4f}"])
    kept = 0
    with (OUT / "detections.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "target_id", "u_px", "v_px"])
        for tid, (tlat, tlon, th) in truth.items():
            pt = np.stack(eoloc.geodetic_to_ecef(tlat, tlon, th), -1)
            u, v = SENSOR.ground_to_image(true_pose, pt)
            seen = (u >= 0) & (u <= CAMERA.width - 1) & (v >= 0) & (v <= CAMERA.height - 1)
            hit = eoloc.locate_dem(SENSOR, true_pose, dem, (u, v))  # hidden behind terrain: not detected
            seen &= np.abs(hit.range_m - np.linalg.norm(pt - p0, axis=-1)) < 1.0
            for i in np.flatnonzero(seen):
                w.writerow([f"{times[i]:.2f}", tid, f"{noisy(u[i], SIGMA['px']):.2f}",
                            f"{noisy(v[i], SIGMA['px']):.2f}"])
                kept += 1
        for i in range(5):  # beyond the DEM's west edge: no truth, the answer must be OUT_OF_COVERAGE
            w.writerow([f"{times[i]:.2f}", "FAR_HILL", "700.00", "20.00"])
            kept += 1
    with (OUT / "truth.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["target_id", "lat_deg", "lon_deg", "h_m"])
        for tid, (tlat, tlon, th) in truth.items():
            w.writerow([tid, tlat, tlon, f"{th:.2f}"])
    (OUT / "camera.toml").write_text(
        "# Mountain demo sensor: 1280 x 720 camera, 25 deg horizontal field of view, az-el turret\n"
        "[camera]\nwidth = 1280\nheight = 720\nhfov_deg = 25.0\n\n[gimbal]\nmodel = \"az-el\"\n"
    )
    print(f"wrote {OUT}: {n} telemetry records, {kept} detections of {len(truth)} targets")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", type=Path, default=ROOT / "tests" / "data" / "dem" / "SRTMGL3_boulder_front_range.asc",
                    help="the SRTMGL3 ESRI ASCII grid of the Front Range (landlab's, as the tests keep it)")
    main(ap.parse_args().source)
