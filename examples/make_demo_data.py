"""Regenerate the bundled demo flight in src/eoloc/data/demo/ (deterministic, seeded).

Scenario after [Z15] Table 1 (Shanxi, 112.68 E 35.13 N): a UAV flies a straight leg at 1140 m
ellipsoidal height, heading 290.5°, while its az-el turret tracks target T1 on ground at 600 m
ellipsoidal; T2 and T3 are about 25 m away. The TRUE pose makes the pixels and the laser range;
the telemetry reports the pose with [Z15]'s noise (lat ±1.5e-4°, lon ±2e-4°, h ±15 m, pitch/roll
±0.4°, yaw ±1.5°, gimbal ±0.2°, range ±5 m, pixels ±2 px), so the located points scatter as
the paper's did. One telemetry line is deliberately malformed and one detection has no
telemetry, to show how eoloc reports bad input.

    python examples/make_demo_data.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

import eoloc
from eoloc import geodesy

OUT = Path(__file__).resolve().parents[1] / "src" / "eoloc" / "data" / "demo"
GROUND_H = 600.0
TARGETS = {"T1": (35.1300, 112.6700), "T2": (35.13015, 112.67020), "T3": (35.12985, 112.66985)}
CAMERA = eoloc.Camera.from_focal_mm(50.0, 5.5, 1024, 768)
SENSOR = eoloc.SensorModel(CAMERA, eoloc.AzElGimbal())
SIGMA = {"lat": 1.5e-4, "lon": 2e-4, "h": 15.0, "pitch": 0.4, "roll": 0.4, "yaw": 1.5, "gimbal": 0.2,
         "range": 5.0, "px": 2.0}


def main() -> None:
    rng = np.random.default_rng(2015)
    OUT.mkdir(parents=True, exist_ok=True)
    t1 = np.stack(eoloc.geodetic_to_ecef(*TARGETS["T1"], GROUND_H), -1)
    # straight leg, 40 m/s, heading 290.5 deg, passing 700 m left of T1 (T1 on the right)
    heading = 290.5
    n_frames = 30
    times = np.arange(n_frames) * 1.0
    along = (times - times.mean()) * 40.0
    hd = np.radians(heading)
    right = np.array([np.cos(hd + np.pi / 2), np.sin(hd + np.pi / 2)])
    fwd = np.array([np.cos(hd), np.sin(hd)])
    ne = -700.0 * right[None, :] + along[:, None] * fwd[None, :]
    ac = geodesy.ned_to_ecef(np.c_[ne, np.full(n_frames, -(1140.0 - GROUND_H))], *TARGETS["T1"], GROUND_H)
    lat, lon, _ = eoloc.ecef_to_geodetic(ac[:, 0], ac[:, 1], ac[:, 2])
    h = np.full(n_frames, 1140.0)
    pitch = np.full(n_frames, 2.1)
    roll = np.zeros(n_frames)
    yaw = np.full(n_frames, heading)
    az, el, rng_true = eoloc.AzElGimbal.pointing(lat, lon, h, yaw, pitch, roll, t1)  # T1 on the boresight

    def noisy(x, s):
        return x + rng.normal(0.0, s, np.shape(x))

    with (OUT / "telemetry.csv").open("w", newline="") as fh:
        fh.write("# eoloc demo flight (synthetic, see examples/make_demo_data.py). Heights ellipsoidal.\n")
        fh.write("# The record at time 12 s is deliberately malformed to show error reporting.\n")
        w = csv.writer(fh)
        w.writerow(["time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg",
                    "azimuth_deg", "elevation_deg", "range_m"])
        for i in range(n_frames):
            row = [f"{times[i]:.2f}", f"{noisy(lat[i], SIGMA['lat']):.9f}", f"{noisy(lon[i], SIGMA['lon']):.9f}",
                   f"{noisy(h[i], SIGMA['h']):.2f}", f"{noisy(yaw[i], SIGMA['yaw']) % 360:.4f}",
                   f"{noisy(pitch[i], SIGMA['pitch']):.4f}", f"{noisy(roll[i], SIGMA['roll']):.4f}",
                   f"{noisy(az[i], SIGMA['gimbal']):.4f}", f"{noisy(el[i], SIGMA['gimbal']):.4f}",
                   f"{noisy(rng_true[i], SIGMA['range']):.2f}"]
            if i == 12:
                row[5] = "2.1O"  # a letter O for a zero: the reader must say so and keep the rest
            w.writerow(row)
    with (OUT / "detections.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "target_id", "u_px", "v_px"])
        for i in range(n_frames):
            for tid, (tlat, tlon) in TARGETS.items():
                p = np.stack(eoloc.geodetic_to_ecef(tlat, tlon, GROUND_H), -1)
                true_pose = eoloc.Pose(lat[i], lon[i], h[i], yaw[i], pitch[i], roll[i], (az[i], el[i]))
                u, v = SENSOR.ground_to_image(true_pose, p)
                w.writerow([f"{times[i]:.2f}", tid, f"{noisy(u, SIGMA['px']):.2f}", f"{noisy(v, SIGMA['px']):.2f}"])
        w.writerow(["99.00", "T1", "512.0", "384.0"])  # no telemetry at 99 s
    with (OUT / "truth.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["target_id", "lat_deg", "lon_deg", "h_m"])
        for tid, (tlat, tlon) in TARGETS.items():
            w.writerow([tid, tlat, tlon, GROUND_H])
    (OUT / "camera.toml").write_text(
        "# Demo sensor: 1024 x 768 visible camera, 50 mm lens, 5.5 um pixels, az-el turret ([Z15] Table 1)\n"
        "[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 50.0\npixel_um = 5.5\n\n"
        "[gimbal]\nmodel = \"az-el\"\n\n"
        "[installation]\nmount_misalignment_deg = [0.0, 0.0, 0.0]\nboresight_misalignment_deg = [0.0, 0.0, 0.0]\n"
        "lever_arm_m = [0.0, 0.0, 0.0]\n"
    )
    print(f"wrote demo data to {OUT}")


if __name__ == "__main__":
    main()
