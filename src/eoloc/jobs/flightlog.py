"""A video's telemetry (a DJI .SRT) completed by the flight log of the same flight.

Most DJI SRT formats carry no attitude, and old ones only a height above take-off and a position
rounded to ~10 m; the flight log (an Airdata CSV: 10 Hz, full-precision position, the gimbal's
earth-referenced attitude) has it all, on its own clock (seconds since the motors started). The
two are put on one clock by what they share:

1. candidate offsets (log clock minus video clock): the log's ``isVideo`` rising edges (the camera
   starting to record: the video's time 0), else every 0.5 s of the log;
2. each candidate refined over ±2 s in 0.1 s steps; the offset kept is the one where the SRT's
   positions and heights above take-off best match the log's, interpolated at the SRT's times
   (cost: horizontal misfit / 5 m and vertical / 0.5 m, squared, averaged);
3. refused when even the best offset leaves the tracks apart (RMS > 25 m horizontally or 3 m
   vertically: not this flight's log), and said when a second, distinct offset fits almost as
   well (a hover: the match is ambiguous).

Each SRT record then takes the log's pose interpolated at its time + the offset
(:func:`eoloc.sequence.interp.interpolate_poses`: position by a spline in ECEF, attitude by slerp),
and keeps its own time (the video's clock) and frame. A record outside the log, or in a gap of it,
gets no pose and is named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..io.sources import SourceData
from ..io.table import Issue, Table

SIGMA_H_M = 5.0  # the SRT's positions: rounded to 1e-4 degrees on old models
SIGMA_V_M = 0.5  # heights above take-off: barometric, decimetres
MAX_RMS_H_M = 25.0
MAX_RMS_V_M = 3.0
REFINE_S = 2.0
STEP_S = 0.1


@dataclass(frozen=True)
class WithFlightLog:
    """A telemetry file (the video's) with the flight log that completes it: given wherever a
    telemetry path is (``os.fspath`` gives the video's telemetry)."""

    path: str
    log: str

    def __fspath__(self) -> str:
        return str(self.path)

    def __str__(self) -> str:
        return f"{self.path} + {self.log}"


@dataclass(frozen=True)
class LogSync:
    """The offset found (log clock minus video clock, s), how well the tracks then agree (RMS, m),
    and the runner-up offset when it fits almost as well (None otherwise)."""

    offset_s: float
    rms_h_m: float
    rms_v_m: float
    ambiguous_with_s: float | None = None


def _misfit(video: Table, log: Table, offset: float) -> tuple[float, float, float]:
    """(cost, RMS horizontal m, RMS vertical m) of the video's records against the log at
    time + offset (NaN where the log does not cover them)."""
    v, lg = video.columns, log.columns
    t = v["time_s"] + offset
    lt = lg["time_s"]
    inside = (t >= lt[0]) & (t <= lt[-1]) & np.isfinite(v["lat_deg"])
    if inside.sum() < max(2, 0.5 * np.isfinite(v["lat_deg"]).sum()):
        return np.inf, np.nan, np.nan
    lat = np.interp(t[inside], lt, lg["lat_deg"])
    lon = np.interp(t[inside], lt, lg["lon_deg"])
    dn = (v["lat_deg"][inside] - lat) * 111_320.0
    de = (v["lon_deg"][inside] - lon) * 111_320.0 * np.cos(np.radians(lat))
    h2 = dn**2 + de**2
    cost = h2 / SIGMA_H_M**2
    rms_v = np.nan
    if "h_rel_m" in v and "h_rel_m" in lg and np.isfinite(v["h_rel_m"][inside]).any():
        dv = v["h_rel_m"][inside] - np.interp(t[inside], lt, lg["h_rel_m"])
        cost = cost + np.nan_to_num(dv, nan=0.0) ** 2 / SIGMA_V_M**2
        rms_v = float(np.sqrt(np.nanmean(dv**2)))
    return float(np.nanmean(cost)), float(np.sqrt(np.nanmean(h2))), rms_v


def find_log_offset(video: Table, log: Table) -> LogSync:
    """The log clock minus the video clock that makes the two tracks agree (see the module)."""
    lt = log.columns["time_s"]
    if len(log) < 2 or not np.isfinite(lt).all() or np.any(np.diff(lt) <= 0):
        raise InputError(f"{log.path}: the flight log's times are not increasing: cannot be synced")
    if not np.isfinite(video.columns["time_s"]).any():
        raise InputError(f"{video.path}: no times on the video's clock: cannot be synced with a flight log")
    if "is_video" in log.columns and np.isfinite(log.columns["is_video"]).any():
        rec = np.nan_to_num(log.columns["is_video"]) > 0.5
        starts = lt[np.flatnonzero(np.diff(rec.astype(np.int8)) == 1) + 1]
        candidates = np.r_[lt[0] if rec[0] else [], starts]
    else:
        candidates = np.arange(lt[0], lt[-1], 0.5)
    if not candidates.size:
        raise InputError(f"{log.path}: the flight log never records video (isVideo is never 1): is it this "
                         f"video's flight?")
    best: list[tuple[float, float, float, float]] = []  # (cost, offset, rms_h, rms_v) per candidate
    for c in candidates:
        trials = c + np.arange(-REFINE_S, REFINE_S + STEP_S / 2, STEP_S)
        fits = [(m[0], o, m[1], m[2]) for o in trials for m in [_misfit(video, log, o)]]
        best.append(min(fits, key=lambda f: f[0]))
    best.sort(key=lambda f: f[0])
    cost, offset, rms_h, rms_v = best[0]
    if not np.isfinite(cost) or rms_h > MAX_RMS_H_M or (np.isfinite(rms_v) and rms_v > MAX_RMS_V_M):
        raise InputError(f"{video.path} does not match the flight log {log.path} at any time (best: log clock = "
                         f"video clock + {offset:.1f} s, still {rms_h:.0f} m apart horizontally, "
                         f"{rms_v:.1f} m vertically): is it this video's flight?")
    rival = next((f for f in best[1:] if abs(f[1] - offset) > REFINE_S and f[0] < 1.2 * cost + 1e-9), None)
    return LogSync(float(offset), rms_h, rms_v, None if rival is None else float(rival[1]))


def with_flight_log(video: SourceData, log: SourceData) -> SourceData:
    """The video's records with the log's poses at their times (see the module)."""
    from ..io.telemetry import telemetry_pose
    from ..sequence.interp import interpolate_poses

    v, lg = video.telemetry, log.telemetry
    sync = find_log_offset(v, lg)
    got = interpolate_poses(lg.columns["time_s"], telemetry_pose(lg), v.columns["time_s"],
                            time_offset_s=sync.offset_s, max_gap_s=1.0)
    p = got.pose
    cols = dict(v.columns)
    cols.update({"lat_deg": np.where(got.ok, p.lat_deg, np.nan), "lon_deg": np.where(got.ok, p.lon_deg, np.nan),
                 "h_m": np.where(got.ok, p.h_m, np.nan), "yaw_deg": np.where(got.ok, p.yaw_deg, np.nan),
                 "pitch_deg": np.where(got.ok, p.pitch_deg, np.nan), "roll_deg": np.where(got.ok, p.roll_deg, 0.0),
                 "gimbal1_deg": np.zeros(len(v)), "gimbal2_deg": np.zeros(len(v)), "sensor_roll_deg": np.zeros(len(v))})
    issues = [i for i in v.issues if not _superseded(i)] + list(lg.issues)
    missing = np.flatnonzero(~got.ok)
    if missing.size:
        issues.append(Issue(v.path, int(v.line[missing[0]]), f"{missing.size} record(s) outside the flight log "
                            f"{lg.path} or in a gap of it (> 1 s): not located"))
    vertical = f", {sync.rms_v_m:.1f} m in height above take-off" if np.isfinite(sync.rms_v_m) else ""
    notes = [f"poses from the flight log {lg.path} at the video's time + {sync.offset_s:.1f} s (the tracks agree to "
             f"{sync.rms_h_m:.1f} m RMS horizontally{vertical})", *[n for n in log.notes]]
    if sync.ambiguous_with_s is not None:
        notes.append(f"the match with the flight log is ambiguous: + {sync.ambiguous_with_s:.1f} s fits almost as "
                     "well (the drone hovered?): check the time offset")
    table = Table(v.path, cols, v.line, sorted(issues, key=lambda i: i.line))
    return SourceData(table, f"{video.source}+{log.source}", camera=video.camera or log.camera,
                      camera_attitude=True, notes=notes)


def _superseded(issue: Issue) -> bool:
    """The video telemetry's own complaints the log answers (no attitude, no height)."""
    m = issue.message
    return "no camera attitude" in m or "placed in height" in m or "without the gimbal's attitude" in m
