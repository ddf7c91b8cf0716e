"""Airdata UAV flight logs (CSV export of DJI flight records, 10 Hz): told apart by their header
(``time(millisecond)`` … ``gimbal_heading(degrees)``); feet and mph converted to metres.

A record per row: ``time_s`` the flight clock (``time(millisecond)`` / 1000, 0 at motor start),
``datetime_utc`` as ``datetime(utc)`` gives it (1 s resolution), position ``latitude``/``longitude``, heights
by :mod:`.heights` (``height_above_takeoff(feet)``, the take-off point being the first record with
a position; ``altitude_above_seaLevel(feet)`` as the absolute one), the camera's attitude from
``gimbal_heading``, ``gimbal_pitch``, ``gimbal_roll`` (DJI's gimbal angles: earth-referenced, yaw
from true north — Airdata's column reference), the aircraft's ``compass_heading``, ``pitch``,
``roll`` kept beside it, and ``isVideo`` (1 while the camera records: where a video's clock starts).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..table import Column
from .base import SourceData, is_text

FOOT_M = 0.3048

AIRDATA_COLUMNS = [
    Column("time_ms", ("time(millisecond)",), unit="ms"),
    Column("lat_deg", ("latitude",), lo=-90, hi=90, unit="deg"),
    Column("lon_deg", ("longitude",), lo=-180, hi=180, unit="deg"),
    Column("h_rel_ft", ("height_above_takeoff(feet)",), required=False, lo=-40_000, hi=100_000, unit="ft"),
    Column("h_msl_ft", ("altitude_above_sealevel(feet)",), required=False, lo=-40_000, hi=300_000, unit="ft"),
    Column("gimbal_yaw_deg", ("gimbal_heading(degrees)",), required=False, lo=-360, hi=360, unit="deg"),
    Column("gimbal_pitch_deg", ("gimbal_pitch(degrees)",), required=False, lo=-180, hi=180, unit="deg"),
    Column("gimbal_roll_deg", ("gimbal_roll(degrees)",), required=False, lo=-180, hi=180, unit="deg"),
    Column("aircraft_yaw_deg", ("compass_heading(degrees)",), required=False, lo=-360, hi=360, unit="deg"),
    Column("aircraft_pitch_deg", ("pitch(degrees)",), required=False, lo=-180, hi=180, unit="deg"),
    Column("aircraft_roll_deg", ("roll(degrees)",), required=False, lo=-180, hi=180, unit="deg"),
    Column("is_video", ("isvideo",), required=False, lo=0, hi=1),
    Column("satellites", (), required=False, lo=0, hi=100),
    Column("datetime_utc", ("datetime(utc)",), required=False, text=True),
]


class Airdata:
    name = "airdata"
    summary = "Airdata flight log (CSV: time(millisecond), latitude, …, gimbal_heading(degrees))"

    def sniff(self, path: Path, head: bytes) -> bool:
        if not is_text(head):
            return False
        first = head.lstrip(b"\xef\xbb\xbf").split(b"\n", 1)[0]
        return first.startswith(b"time(millisecond)") and b"latitude" in first

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        return read_airdata(path, geoid=geoid, dem=dem)


def read_airdata(path: str | Path, *, geoid=None, dem=None) -> SourceData:
    """An Airdata CSV as telemetry (camera attitude = the gimbal's; see the module's notes)."""
    from ..table import Issue, read_table
    from ..telemetry import without_repeated_times
    from .heights import resolve_heights

    t = read_table(path, AIRDATA_COLUMNS, what="Airdata flight log", key=("time_ms",))
    c = t.columns
    n = len(t)
    issues = list(t.issues)
    lat, lon = c["lat_deg"], c["lon_deg"]
    with np.errstate(invalid="ignore"):
        nofix = (lat == 0.0) & (lon == 0.0)
    if nofix.any():
        issues.append(Issue(t.path, int(t.line[np.flatnonzero(nofix)[0]]), f"position 0, 0 (no GPS fix) on "
                            f"{nofix.sum()} record(s): not located"))
        lat, lon = np.where(nofix, np.nan, lat), np.where(nofix, np.nan, lon)
    h_rel = c["h_rel_ft"] * FOOT_M if "h_rel_ft" in c else None
    h_msl = c["h_msl_ft"] * FOOT_M if "h_msl_ft" in c else None
    placed = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon))
    takeoff = (float(lat[placed[0]]), float(lon[placed[0]])) if placed.size else None
    h, found, how = resolve_heights(t.path, t.line, lat, lon, h_msl=h_msl, h_rel=h_rel, takeoff=takeoff,
                                    msl_tag="altitude_above_seaLevel", rel_tag="height_above_takeoff",
                                    takeoff_how="the log's first position", geoid=geoid, dem=dem)
    issues += found
    lacking = [k for k in ("gimbal_yaw_deg", "gimbal_pitch_deg") if k not in c]
    if lacking:
        issues.append(Issue(t.path, 1, "the log has no gimbal_heading/gimbal_pitch columns: no camera attitude, no "
                            "record can be located (export the log with every column)"))
    nan = np.full(n, np.nan)
    cols = {"time_s": c["time_ms"] / 1000.0, "frame": nan, "lat_deg": lat, "lon_deg": lon, "h_m": h,
            "yaw_deg": c.get("gimbal_yaw_deg", nan), "pitch_deg": c.get("gimbal_pitch_deg", nan),
            "roll_deg": np.nan_to_num(c.get("gimbal_roll_deg", nan), nan=0.0), "gimbal1_deg": np.zeros(n),
            "gimbal2_deg": np.zeros(n), "sensor_roll_deg": np.zeros(n), "range_m": nan,
            "h_rel_m": h_rel if h_rel is not None else nan, "h_abs_m": h_msl if h_msl is not None else nan}
    for k in ("aircraft_yaw_deg", "aircraft_pitch_deg", "aircraft_roll_deg", "is_video", "satellites"):
        if k in c:
            cols[k] = c[k]
    table = type(t)(t.path, cols, t.line, sorted(issues, key=lambda i: i.line))
    if "datetime_utc" in c:
        table.columns["datetime_utc"] = c["datetime_utc"]
    return SourceData(without_repeated_times(table), Airdata.name, camera_attitude=True, notes=[f"heights: {how}"])
