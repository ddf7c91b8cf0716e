"""Telemetry and detections CSVs (the schemas are documented in the README and `eoloc locate --help`).

Telemetry, one row per image/record:
    time_s | frame (at least one), lat_deg, lon_deg, h_m (ellipsoidal), yaw_deg, pitch_deg,
    roll_deg, gimbal1_deg, gimbal2_deg (az-el: azimuth_deg, elevation_deg; roll-pitch:
    frame_roll_deg, frame_pitch_deg), optional sensor_roll_deg, optional range_m.
Detections, one row per target seen in an image:
    time_s | frame, target_id, u_px, v_px, optional range_m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..sensor.model import Pose
from .table import Column, Issue, Table, TableError, read_table

TELEMETRY_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("lat_deg", ("lat", "latitude"), lo=-90, hi=90, unit="deg"),
    Column("lon_deg", ("lon", "longitude"), lo=-180, hi=360, unit="deg"),
    Column("h_m", ("height_m", "hae_m", "alt_hae_m"), lo=-12_000, hi=100_000, unit="m"),
    Column("yaw_deg", ("heading_deg",), lo=-360, hi=360, unit="deg"),
    Column("pitch_deg", (), lo=-90, hi=90, unit="deg"),
    Column("roll_deg", (), lo=-180, hi=180, unit="deg"),
    Column("gimbal1_deg", ("azimuth_deg", "frame_roll_deg"), required=False, lo=-360, hi=360, unit="deg"),
    Column("gimbal2_deg", ("elevation_deg", "frame_pitch_deg"), required=False, lo=-360, hi=360, unit="deg"),
    Column("sensor_roll_deg", (), required=False, lo=-360, hi=360, unit="deg"),
    Column("range_m", ("slant_range_m",), required=False, lo=0, hi=1e7, unit="m"),
]

DETECTION_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("target_id", ("id", "target"), text=True),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("range_m", ("slant_range_m",), required=False, lo=0, hi=1e7, unit="m"),
]


GCP_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("gcp_id", ("id", "gcp", "name"), text=True),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("lat_deg", ("lat", "latitude"), lo=-90, hi=90, unit="deg"),
    Column("lon_deg", ("lon", "longitude"), lo=-180, hi=360, unit="deg"),
    Column("h_m", ("height_m", "hae_m"), lo=-12_000, hi=100_000, unit="m"),
]


#: Calibration observations (compensation training): one row per sighting of a surveyed point,
#: with the pose as the telemetry reported it, the pixel, and the point's surveyed position.
OBSERVATION_COLUMNS = [
    Column("flight", ("flight_id", "sortie"), required=False, text=True),
    Column("time_s", required=False, unit="s"),
    *TELEMETRY_COLUMNS[2:10],
    Column("sensor_roll_deg", (), required=False, lo=-360, hi=360, unit="deg"),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("gcp_id", ("gcp",), required=False, text=True),
    Column("gcp_lat_deg", ("true_lat_deg",), lo=-90, hi=90, unit="deg"),
    Column("gcp_lon_deg", ("true_lon_deg",), lo=-180, hi=360, unit="deg"),
    Column("gcp_h_m", ("true_h_m",), lo=-12_000, hi=100_000, unit="m"),
]


def read_observations(path: str | Path) -> Table:
    """Read calibration observations: flight (id; held out together in cross-validation), pose
    (lat_deg, lon_deg, h_m ellipsoidal, yaw/pitch/roll_deg, gimbal1/2_deg, optional
    sensor_roll_deg), u_px, v_px and the surveyed gcp_lat_deg, gcp_lon_deg, gcp_h_m (ellipsoidal).
    Without a flight column every row counts as one flight."""
    t = read_table(path, OBSERVATION_COLUMNS, what="calibration observations", key=("u_px", "v_px"))
    t.columns.setdefault("flight", np.full(len(t), Path(path).stem, dtype=object))
    t.columns.setdefault("sensor_roll_deg", np.zeros(len(t)))
    for name in ("gimbal1_deg", "gimbal2_deg", "time_s"):
        t.columns.setdefault(name, np.full(len(t), np.nan))
    return t


def read_gcps(path: str | Path) -> Table:
    """Read GCP observations: time_s or frame, gcp_id, u_px, v_px (where the GCP is in that image)
    and the GCP's surveyed lat_deg, lon_deg, h_m (ellipsoidal)."""
    t = read_table(path, GCP_COLUMNS, what="GCP observations", key=("time_s", "frame"))
    for name in ("time_s", "frame"):
        t.columns.setdefault(name, np.full(len(t), np.nan))
    return t


def with_heading_bias(t: Table, heading_bias_deg: float) -> Table:
    """The telemetry with a calibrated INS heading bias removed from every yaw (true = measured - bias)."""
    if heading_bias_deg == 0.0:
        return t
    return replace(t, columns={**t.columns, "yaw_deg": t.columns["yaw_deg"] - heading_bias_deg})


def read_telemetry(path: str | Path) -> Table:
    """Read a telemetry CSV; bad values become NaN (reported), unusable lines are skipped (reported)."""
    t = read_table(path, TELEMETRY_COLUMNS, what="telemetry", key=("time_s", "frame"))
    for name in ("gimbal1_deg", "gimbal2_deg", "sensor_roll_deg", "range_m", "time_s", "frame"):
        t.columns.setdefault(name, np.full(len(t), np.nan))
    return _without_repeated_times(t)


def _without_repeated_times(t: Table) -> Table:
    """Records that repeat a time_s: an exact copy of an earlier record is dropped; records that
    give different poses at one time are all dropped (which one is right cannot be told). Each
    is reported with the line it repeats."""
    times = t.columns["time_s"]
    finite = np.flatnonzero(np.isfinite(times))
    if finite.size < 2:
        return t
    order = finite[np.argsort(times[finite], kind="stable")]
    same = np.flatnonzero(np.diff(times[order]) == 0.0)
    if same.size == 0:
        return t
    drop = np.zeros(len(t), dtype=bool)
    names = [k for k, v in t.columns.items() if v.dtype.kind == "f"]
    for k in same:
        first, later = order[k], order[k + 1]
        while k > 0 and times[order[k - 1]] == times[first]:  # compare with the first record of the time
            k -= 1
            first = order[k]
        identical = all(np.array_equal(t.columns[n][first], t.columns[n][later], equal_nan=True) for n in names)
        if identical:
            drop[later] = True
            t.issues.append(Issue(t.path, int(t.line[later]), f"repeats line {int(t.line[first])} exactly; "
                                                               "record skipped"))
        else:
            drop[[first, later]] = True
            t.issues.append(Issue(t.path, int(t.line[later]), f"time_s {times[later]:g} also at line "
                                  f"{int(t.line[first])} with another pose: neither record is used"))
    return t.keep(~drop)


def read_detections(path: str | Path) -> Table:
    """Read a detections CSV (time_s or frame, target_id, u_px, v_px[, range_m])."""
    t = read_table(path, DETECTION_COLUMNS, what="detections", key=("time_s", "frame"))
    for name in ("range_m", "time_s", "frame"):
        t.columns.setdefault(name, np.full(len(t), np.nan))
    return t


def telemetry_pose(t: Table, index: np.ndarray | slice = slice(None)) -> Pose:
    """The poses of telemetry records ``index`` (gimbal angles: gimbal1, gimbal2, sensor roll)."""
    c = t.columns
    sensor_roll = np.nan_to_num(c["sensor_roll_deg"][index], nan=0.0)
    return Pose(c["lat_deg"][index], c["lon_deg"][index], c["h_m"][index], c["yaw_deg"][index],
                c["pitch_deg"][index], c["roll_deg"][index],
                (c["gimbal1_deg"][index], c["gimbal2_deg"][index], sensor_roll))


@dataclass
class Matched:
    """Detections paired with the telemetry record of their image (-1: none)."""

    record: np.ndarray
    issues: list[Issue]


def match_detections(tel: Table, det: Table, *, time_tolerance_s: float = 0.02) -> Matched:
    """Pair each detection with its telemetry record: same ``frame`` if both files have frames,
    else the record nearest in ``time_s`` within ``time_tolerance_s``. Unmatched detections get -1
    and a reported issue (they end as NO_TELEMETRY; nothing is interpolated here)."""
    n = len(det)
    record = np.full(n, -1, dtype=np.int64)
    issues: list[Issue] = []
    has = {name: (np.isfinite(t.columns["frame"]).any(), np.isfinite(t.columns["time_s"]).any())
           for name, t in (("detections", det), ("telemetry", tel))}
    use_frames = has["detections"][0] and has["telemetry"][0]
    if n and not use_frames and not (has["detections"][1] and has["telemetry"][1]):
        def gives(name: str) -> str:
            f, t = has[name]
            return "frame and time_s" if f and t else "frame only" if f else "time_s only" if t else "neither"

        raise TableError(f"{det.path} gives {gives('detections')} and {tel.path} {gives('telemetry')}: nothing to "
                         "pair them by; add the same column (frame, or time_s) to both files")
    if use_frames:
        lookup = {int(f): i for i, f in enumerate(tel.columns["frame"]) if math.isfinite(f)}
        for j, f in enumerate(det.columns["frame"]):
            record[j] = lookup.get(int(f), -1) if math.isfinite(f) else -1
    else:
        tt = tel.columns["time_s"]
        good = np.flatnonzero(np.isfinite(tt))
        order = good[np.argsort(tt[good], kind="stable")]
        ts = tt[order]
        td = det.columns["time_s"]
        if ts.size:
            pos = np.clip(np.searchsorted(ts, td), 1, max(ts.size - 1, 1))
            left = np.clip(pos - 1, 0, ts.size - 1)
            right = np.clip(pos, 0, ts.size - 1)
            pick = np.where(np.abs(td - ts[left]) <= np.abs(ts[right] - td), left, right)
            close = np.abs(ts[pick] - td) <= time_tolerance_s
            record = np.where(close & np.isfinite(td), order[pick], -1)
    for j in np.flatnonzero(record < 0):
        key = f"frame {det.columns['frame'][j]:g}" if use_frames else f"time {det.columns['time_s'][j]:g} s"
        hint = "" if use_frames else f" within {time_tolerance_s:g} s (widen --time-tolerance?)"
        issues.append(Issue(det.path, int(det.line[j]), f"no telemetry record for {key}{hint}"))
    return Matched(record, issues)
