"""Synthetic MISB ST 0601 streams: an aircraft circling a point with its turret on the centre and
a few VMTI targets in view - for testing a pipeline, and for the archive benchmark.

Everything an encoder sends is there (time, attitude, position with MSL altitude, field of view,
turret angles, slant range, frame centre computed on the geoid, ST 0903 VMTI targets), one packet
per ``1 / rate_hz`` s, seeded: the same arguments give the same bytes.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .encode import encode_uas_packet, encode_vmti

START_UNIX_S = datetime(2026, 7, 14, 16, 0, 0, tzinfo=UTC).timestamp()


def circling_flight_klv(n_packets: int, *, seed: int = 0, lat_deg: float = 40.0, lon_deg: float = -105.0,
                        radius_m: float = 3000.0, height_msl_m: float = 3000.0, rate_hz: float = 10.0,
                        n_targets: int = 5, hfov_deg: float = 20.0, start_unix_s: float = START_UNIX_S) -> bytes:
    """``n_packets`` ST 0601 packets (raw KLV) of a circling flight centred ``seed``-dependently
    near (lat_deg, lon_deg); the ground is the geoid (MSL 0)."""
    from ...ground.frame import frame_geometry, misb_sensor
    from ...rules import AtHeight
    from ...sensor import Pose
    from ...terrain.geoid import default_geoid

    rng = np.random.default_rng(seed)
    lat0 = lat_deg + rng.uniform(-0.5, 0.5)
    lon0 = lon_deg + rng.uniform(-0.5, 0.5)
    geoid = default_geoid()
    n0 = float(geoid.undulation(lat0, lon0))
    m_lat, m_lon = 111_133.0, 111_319.5 * np.cos(np.radians(lat0))  # near enough for a made-up circle
    t = np.arange(n_packets) / rate_hz
    speed = 40.0
    phase = rng.uniform(0, 2 * np.pi) + speed * t / radius_m
    lat = lat0 + radius_m * np.cos(phase) / m_lat
    lon = lon0 + radius_m * np.sin(phase) / m_lon
    heading = (np.degrees(phase) + 90.0) % 360.0  # counter-clockwise seen from above: centre on the left
    h = np.full(n_packets, height_msl_m + n0)
    elevation = -np.degrees(np.arctan2(height_msl_m, radius_m))
    pitch = rng.normal(0, 1.0, n_packets)
    roll = np.full(n_packets, -8.0) + rng.normal(0, 0.5, n_packets)
    az = np.full(n_packets, 270.0) + rng.normal(0, 0.3, n_packets)
    el = np.full(n_packets, elevation) + rng.normal(0, 0.3, n_packets)
    width, height = 1280, 720
    vfov = float(np.degrees(2 * np.arctan(np.tan(np.radians(hfov_deg) / 2) * height / width)))
    pose = Pose(lat, lon, h, heading, pitch, roll, (az, el))
    geom = frame_geometry(misb_sensor(), pose, np.full(n_packets, hfov_deg), np.full(n_packets, vfov), AtHeight(n0))
    c = geom.centre
    u = rng.uniform(100, width - 100, (n_packets, n_targets))
    v = rng.uniform(100, height - 100, (n_packets, n_targets))
    packets = []
    for i in range(n_packets):
        values = {2: datetime.fromtimestamp(start_unix_s + float(t[i]), UTC), 5: float(heading[i]),
                  6: float(pitch[i]), 7: float(roll[i]), 13: float(lat[i]), 14: float(lon[i]),
                  15: float(height_msl_m), 16: hfov_deg, 17: vfov, 18: float(az[i] % 360.0), 19: float(el[i]),
                  20: 0.0}
        if c.ok[i]:
            values.update({21: float(c.range_m[i]), 23: float(c.lat_deg[i]), 24: float(c.lon_deg[i]), 25: 0.0})
        values[74] = encode_vmti([(k + 1, u[i, k], v[i, k]) for k in range(n_targets)], width, height)
        packets.append(encode_uas_packet(values))
    return b"".join(packets)


def write_circling_flights(folder: str | Path, n_files: int, n_packets: int, *, seed: int = 0) -> list[Path]:
    """``n_files`` synthetic streams ``flight_000.klv`` ... in ``folder`` (seeds seed, seed+1, ...)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k in range(n_files):
        p = folder / f"flight_{k:03d}.klv"
        p.write_bytes(circling_flight_klv(n_packets, seed=seed + k, start_unix_s=START_UNIX_S + 3600.0 * k))
        out.append(p)
    return out
