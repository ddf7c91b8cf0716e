"""Files-level geolocation: telemetry (+ detections) + sensor + stop rule -> one row per target.

No file access here: takes parsed tables, returns rows and issues; the CLI reads and writes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..io.records import Coded
from ..io.table import Issue, Table
from ..result import Fixes, Status, with_status
from ..rules import RangeFromRecords, StopRule
from ..sensor import Pose, SensorModel

if TYPE_CHECKING:  # the accuracy modules load scipy's statistics: imported only when a budget is given
    # (and the telemetry tables only by the functions that read them: one observation needs neither)
    from ..accuracy.budget import ErrorBudget
    from ..accuracy.covariance import FixCovariance


@dataclass
class Located:
    """Fixes, the per-target descriptive columns (time, frame, id, pixel, source line) and issues."""

    fixes: Fixes
    extra: dict[str, np.ndarray]
    issues: list[Issue] = field(default_factory=list)
    covariance: FixCovariance | None = None
    compensation: dict[str, np.ndarray] | None = None
    coded: dict[str, Coded] = field(default_factory=dict)  # extra's text columns as read, coded
    pose: Pose | None = None  # the poses the targets were located from (see target_pose)
    pose_index: np.ndarray | None = None  # each target's element of pose (None: one pose per target)
    pixels: tuple[np.ndarray, np.ndarray] | None = None  # each target's (u, v)
    rule: StopRule | None = None  # the stop rule, with one value per target where it has one

    def target_pose(self) -> Pose | None:
        """Each target's pose (as located, before any compensation)."""
        return self.pose if self.pose is None or self.pose_index is None else self.pose.take(self.pose_index)


def locate_tables(sensor: SensorModel, tel: Table, det: Table | None, rule: StopRule, *,
                  time_tolerance_s: float = 0.02, budget: ErrorBudget | None = None, interpolate: bool = False,
                  max_gap_s: float = 0.5, time_offset_s: float = 0.0, compensation=None) -> Located:
    """Geolocate every detection (or, without detections, every record's image centre).

    Stop ``rule``: a :class:`eoloc.StopRule`; :class:`eoloc.rules.RangeFromRecords` for M1 with
    each detection's ``range_m`` column (without detections: the telemetry's boresight range; a
    telemetry range is never applied along another pixel's ray). The keywords ``height_m``,
    ``dem``, ``range_m`` name the rule instead. With an error ``budget`` every
    fix also gets its first-order covariance (:func:`eoloc.accuracy.locate_with_covariance`).
    ``interpolate``: each detection's pose is interpolated to its time (+ ``time_offset_s``,
    telemetry minus video clock) instead of taken from the nearest record; detections in a gap
    longer than ``max_gap_s`` or outside the telemetry get NO_TELEMETRY and an issue.
    ``compensation``: a :class:`eoloc.accuracy.compensation.CompensationModel` whose predicted
    correction is added to every fix inside its trained range (the others are flagged); its
    per-fix columns come back in ``Located.compensation``.
    """
    from ..io.telemetry import match_detections, telemetry_pose

    if not isinstance(rule, StopRule):
        raise TypeError(f"rule must be a stop rule, got {rule!r}")
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
        coded = {}
    else:
        if interpolate:
            record, pose, more = _interpolated(tel, det, max_gap_s, time_offset_s, sensor.camera)
        else:
            matched = match_detections(tel, det, time_tolerance_s=time_tolerance_s)
            record, more = matched.record, matched.issues
        issues += more
        u, v = det.columns["u_px"], det.columns["v_px"]
        extra = {"line": det.line, "time_s": det.columns["time_s"], "frame": det.columns["frame"],
                 "target_id": det.columns["target_id"], "u_px": u, "v_px": v}
        file_range = det.columns["range_m"]
        range_source = (det.path, det.line)
        coded = {k: c for k, c in det.coded.items() if k in extra}
    has_pose = record >= 0
    pose_index = None
    if not (interpolate and det is not None):
        index = np.where(has_pose, record, 0)
        if det is not None and len(tel) < len(det):  # several targets per image: each frame computed once
            pose, pose_index = telemetry_pose(tel, camera=sensor.camera), index
        else:
            pose = telemetry_pose(tel, index, sensor.camera)
    if isinstance(rule, RangeFromRecords):  # M1 with each target's own range
        rule = rule.with_ranges(np.asarray(file_range))
        path, lines = range_source
        for j in np.flatnonzero(~np.isfinite(rule.range_m) & has_pose):
            issues.append(Issue(path, int(lines[j]), "no range_m for this target: give one in the file, "
                                                     "a constant --range R, or use --target-height H"))
    fixes, cov = locate_by_rule(sensor, pose, (u, v), rule, budget=budget, pose_index=pose_index)
    fixes = with_status(fixes, ~has_pose, Status.NO_TELEMETRY)
    comp = None
    if compensation is not None:
        from ..accuracy.compensation import compensate

        per_target = pose if pose_index is None else pose.take(pose_index)
        fixes, comp = compensate(compensation, sensor, per_target, fixes, (u, v), rule=rule)
    extra["record_line"] = np.where(has_pose, tel.line[np.where(has_pose, record, 0)], -1)
    if tel.has("file"):  # drone photos: the photo each fix was made in
        extra["file"] = np.where(has_pose, np.asarray(tel.columns["file"], dtype=object)[np.where(has_pose, record, 0)],
                                 "")
    return Located(fixes, extra, issues, cov, comp, coded, pose, pose_index, (u, v), rule)


def locate_by_rule(sensor: SensorModel, pose: Pose, pixels, rule: StopRule, budget: ErrorBudget | None = None,
                   pose_index: np.ndarray | None = None) -> tuple[Fixes, FixCovariance | None]:
    """Fixes by stop ``rule`` and, with an error ``budget``, their first-order covariance (else
    None); ``pose_index``: each pixel's element of ``pose`` (see :meth:`SensorModel.rays`)."""
    if budget is not None:
        from ..accuracy.covariance import locate_with_covariance

        return locate_with_covariance(sensor, pose if pose_index is None else pose.take(pose_index), budget,
                                      pixels, rule)
    if pose_index is None:
        return rule.locate(sensor, pose, pixels), None
    return rule.locate(sensor, pose, pixels, pose_index=pose_index), None


def _interpolated(tel: Table, det: Table, max_gap_s: float, time_offset_s: float, camera):
    """(index of the telemetry record at or before each detection or -1, interpolated poses, issues)."""
    tt, td = tel.columns["time_s"], det.columns["time_s"]
    if not (np.isfinite(tt).any() and np.isfinite(td).any()):
        raise InputError("pose interpolation needs time_s in both the telemetry and the detections "
                         "(frame numbers alone give no time to interpolate at)")
    from ..io.telemetry import telemetry_pose
    from ..sequence.interp import interpolate_poses

    ip = interpolate_poses(tt, telemetry_pose(tel, camera=camera), td, time_offset_s=time_offset_s, max_gap_s=max_gap_s)
    q = td + time_offset_s
    issues = []
    t0, t1 = ip.span_s
    for j in np.flatnonzero(~ip.ok):
        if ip.reason[j] == ip.IN_GAP:
            g = next(g for g in ip.gaps if g.t_before <= q[j] <= g.t_after)
            msg = (f"time {td[j]:g} s falls in a {g.length_s:.3g} s telemetry gap between lines "
                   f"{int(tel.line[g.before])} and {int(tel.line[g.after])} (longer than --max-gap {max_gap_s:g} s)")
        else:
            msg = f"time {td[j]:g} s is outside the telemetry ({t0:g} to {t1:g} s, offset {time_offset_s:g} s)"
        issues.append(Issue(det.path, int(det.line[j]), msg))
    return ip.record, ip.pose, issues
