"""Files-level geolocation: telemetry (+ detections) + sensor + stop rule -> one row per target.

No file access here: takes parsed tables, returns rows and issues; the CLI reads and writes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .accuracy.budget import ErrorBudget
from .accuracy.covariance import FixCovariance, locate_with_covariance
from .io.table import Issue, Table
from .io.telemetry import match_detections, telemetry_pose
from .locate import locate_dem, locate_ellipsoid, locate_range
from .result import Fixes, Status, with_status
from .sensor import SensorModel

RANGE_FROM_FILES = "files"


@dataclass
class Located:
    """Fixes, the per-target descriptive columns (time, frame, id, pixel, source line) and issues."""

    fixes: Fixes
    extra: dict[str, np.ndarray]
    issues: list[Issue] = field(default_factory=list)
    covariance: FixCovariance | None = None


def locate_tables(sensor: SensorModel, tel: Table, det: Table | None = None, *,
                  range_m: float | str | None = None, height_m: float | None = None, dem=None,
                  time_tolerance_s: float = 0.02, budget: ErrorBudget | None = None) -> Located:
    """Geolocate every detection (or, without detections, every record's image centre).

    Stop rule (exactly one): ``height_m`` (M3, ellipsoidal metres), ``dem`` (M4, a
    :class:`eoloc.DEM`) or ``range_m`` (M1): a number for all, or ``"files"`` to take each
    detection's ``range_m`` column (without detections: the telemetry's boresight range). A
    telemetry range is never applied along another pixel's ray. With an error ``budget`` every
    fix also gets its first-order covariance (:func:`eoloc.accuracy.locate_with_covariance`).
    """
    if sum(x is not None for x in (range_m, height_m, dem)) != 1:
        raise ValueError("choose one stop rule: a range (range_m), a target height (height_m) or a DEM (dem)")
    issues: list[Issue] = []
    cx, cy = sensor.camera.centre_px
    if det is None:
        record = np.arange(len(tel))
        u = np.full(len(tel), cx)
        v = np.full(len(tel), cy)
        extra = {"line": tel.line, "time_s": tel.columns["time_s"], "frame": tel.columns["frame"],
                 "target_id": np.full(len(tel), "centre", dtype=object), "u_px": u, "v_px": v}
        file_range = tel.columns["range_m"]
        range_source = (tel.path, tel.line)
    else:
        matched = match_detections(tel, det, time_tolerance_s=time_tolerance_s)
        issues += matched.issues
        record = matched.record
        u, v = det.columns["u_px"], det.columns["v_px"]
        extra = {"line": det.line, "time_s": det.columns["time_s"], "frame": det.columns["frame"],
                 "target_id": det.columns["target_id"], "u_px": u, "v_px": v}
        file_range = det.columns["range_m"]
        range_source = (det.path, det.line)
    has_pose = record >= 0
    pose = telemetry_pose(tel, np.where(has_pose, record, 0))
    if dem is not None:
        stop = {"dem": dem}
    elif height_m is not None:
        stop = {"height_m": height_m}
    else:
        rng = np.asarray(file_range if range_m == RANGE_FROM_FILES else np.full(u.shape, float(range_m)))
        if range_m == RANGE_FROM_FILES:
            path, lines = range_source
            for j in np.flatnonzero(~np.isfinite(rng) & has_pose):
                issues.append(Issue(path, int(lines[j]), "no range_m for this target: give one in the file, "
                                                         "a constant --range R, or use --height H"))
        stop = {"range_m": rng}
    cov = None
    if budget is not None:
        fixes, cov = locate_with_covariance(sensor, pose, budget, (u, v), **stop)
    elif dem is not None:
        fixes = locate_dem(sensor, pose, dem, (u, v))
    elif height_m is not None:
        fixes = locate_ellipsoid(sensor, pose, height_m, (u, v))
    else:
        fixes = locate_range(sensor, pose, stop["range_m"], (u, v))
    fixes = with_status(fixes, ~has_pose, Status.NO_TELEMETRY)
    extra["record_line"] = np.where(has_pose, tel.line[np.where(has_pose, record, 0)], -1)
    return Located(fixes, extra, issues, cov)
