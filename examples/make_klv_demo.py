"""Encode the mountain demo flight as a MISB ST 0601 KLV stream: src/eoloc/data/demo/mountain/flight.klv.

What an airborne encoder would send for the flight of make_mountain_demo.py (the same measured,
noisy telemetry and detections), one packet per telemetry record (deterministic):

- tag 2 time; 5/6/7 platform heading, pitch, roll; 13/14 position; 15 altitude **MSL** (the
  ellipsoidal height minus the EGM96 undulation: the reader must add it back); 16/17 HFOV/VFOV;
  18/19/20 turret azimuth, elevation, sensor roll; 21 slant range to the frame centre (computed);
- 23/24/25 frame centre, as the encoder computes it: first hit of the boresight on the same SRTM
  terrain, elevation MSL; 82-89 full-range corners on the level surface through that frame centre
  (what encoders commonly do: the top corners of an oblique view often see past any local DEM);
- 74 an ST 0903 VMTI set with the frame size and one VTarget per detection (centroid pixel
  number and row/column);
- packet 17 is corrupted on purpose (one byte flipped after encoding: its checksum fails), so
  the demo shows a bad packet counted, named and skipped while every other one is used.

    python examples/make_klv_demo.py
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from eoloc.ground.frame import frame_geometry, misb_sensor, packet_heights
from eoloc.io.config import load_config
from eoloc.io.klv import encode_uas_packet, encode_vmti
from eoloc.io.telemetry import read_detections, read_telemetry, telemetry_pose
from eoloc.rules import OnDEM
from eoloc.terrain import open_dem
from eoloc.terrain.geoid import default_geoid

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "eoloc" / "data" / "demo" / "mountain"
START = datetime(2026, 7, 14, 16, 0, 0, tzinfo=UTC).timestamp()
CORRUPT = 17


def main() -> None:
    cfg = load_config(DATA / "camera.toml")
    cam = cfg.sensor().camera
    tel = read_telemetry(DATA / "telemetry.csv")
    det = read_detections(DATA / "detections.csv")
    dem = open_dem(DATA / "longs_peak_srtmgl3.tif")
    geoid = default_geoid()
    c = tel.columns
    pose = telemetry_pose(tel)
    hfov, vfov = cam.hfov_deg, cam.vfov_deg
    n = len(tel)
    geom = frame_geometry(misb_sensor(), pose, np.full(n, hfov), np.full(n, vfov), OnDEM(dem))
    level = frame_geometry(misb_sensor(), pose, np.full(n, hfov), np.full(n, vfov), packet_heights(geom.centre.h_m))
    ids = sorted(set(det.columns["target_id"]))
    packets = []
    for i in range(n):
        t = float(c["time_s"][i])
        lat, lon, h = float(c["lat_deg"][i]), float(c["lon_deg"][i]), float(c["h_m"][i])
        values = {
            2: datetime.fromtimestamp(START + t, UTC), 5: float(c["yaw_deg"][i]) % 360.0,
            6: float(c["pitch_deg"][i]), 7: float(c["roll_deg"][i]), 13: lat, 14: lon,
            15: h - float(geoid.undulation(lat, lon)), 16: hfov, 17: vfov,
            18: float(c["gimbal1_deg"][i]) % 360.0, 19: float(c["gimbal2_deg"][i]), 20: 0.0,
        }
        if geom.centre.ok[i]:
            fc_lat, fc_lon, fc_h = (float(x[i]) for x in (geom.centre.lat_deg, geom.centre.lon_deg, geom.centre.h_m))
            values.update({21: float(geom.centre.range_m[i]), 23: fc_lat, 24: fc_lon,
                           25: fc_h - float(geoid.undulation(fc_lat, fc_lon))})
            if level.corners.ok[i].all():
                for k in range(4):  # full-range corners: an oblique view's corners are beyond the offsets' ±0.075°
                    values[82 + 2 * k] = float(level.corners.lat_deg[i, k])
                    values[83 + 2 * k] = float(level.corners.lon_deg[i, k])
        here = np.flatnonzero(np.abs(det.columns["time_s"] - t) < 1e-6)
        targets = [(ids.index(det.columns["target_id"][j]) + 1, det.columns["u_px"][j], det.columns["v_px"][j])
                   for j in here]
        if targets:
            values[74] = encode_vmti(targets, cam.width, cam.height)
        raw = bytearray(encode_uas_packet(values))
        if i == CORRUPT:
            raw[-5] ^= 0x5A  # inside the last value before the checksum: structure intact, checksum wrong
        packets.append(bytes(raw))
    out = DATA / "flight.klv"
    out.write_bytes(b"".join(packets))
    names = DATA / "vmti_targets.csv"
    names.write_text("vmti_target_id,target_id\n" + "".join(f"{k + 1},{name}\n" for k, name in enumerate(ids)))
    print(f"wrote {out} ({len(packets)} packets, {out.stat().st_size} bytes; packet {CORRUPT} corrupted) and {names}")


if __name__ == "__main__":
    main()
