"""Why most targets failed, in one line: the commonest failing status, the input at fault (which
pose field, pixel or stop value is missing or out of range, in how many of them) and what to do.

A run where 570 of 570 targets end INVALID_INPUT because the telemetry names its gimbal columns
``gimbal_az,gimbal_el`` must say so once, not leave the user to read 570 identical rows. The
commands print the line as a warning and exit non-zero when nothing at all was located
(:func:`nothing_located`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..result import Fixes, Status
from ..sensor.model import Pose

#: What to do when most targets end with a status (other than INVALID_INPUT, which is explained
#: by the field at fault).
FIXES = {
    Status.NO_INTERSECTION: ("check the pointing: the gimbal elevation is negative below the horizon (-90 = straight "
                             "down), yaw is clockwise from true north, and a target height must be below the aircraft"),
    Status.OUT_OF_COVERAGE: ("give DEM tiles that cover where the camera looks (`eoloc footprint` shows it), or stop "
                             "at a target height instead"),
    Status.DEM_VOID: "fill the DEM's voids (gdal_fillnodata) or give another DEM there",
    Status.NO_TELEMETRY: ("the detections' time_s (or frame) must match a telemetry record: compare the two files' "
                          "clocks, widen --time-tolerance, give --time-offset, or --interpolate"),
    Status.BELOW_SURFACE: ("the camera is at or under the surface it is meant to see: is the height ellipsoidal? "
                           "An MSL height goes in h_msl_m, a height above take-off needs --dem; a target height "
                           "must be below the aircraft"),
    Status.OUT_OF_IMAGE: ("the pixels lie outside the configured image: check the camera's width and height and "
                          "that u_px is the column, v_px the row"),
    Status.DEGENERATE: "the views are too close to parallel: use frames further apart along the flight",
}


def commonest_failure(fixes: Fixes) -> tuple[Status, int] | None:
    """The status (not OK) of at least half of the targets, with its count; None otherwise."""
    counts = fixes.status_counts()
    total = sum(counts.values())
    failing = [(n, name) for name, n in counts.items() if name != "OK"]
    if not total or not failing:
        return None
    n, name = max(failing)
    return (Status[name], n) if 2 * n >= total else None


def nothing_located(fixes: Fixes) -> bool:
    """Whether there were targets and not one of them was located (the commands then exit 3)."""
    return bool(np.size(fixes.status)) and not bool(np.any(np.asarray(fixes.status) == Status.OK))


def _bad(values, lo: float = -np.inf, hi: float = np.inf) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return ~(np.isfinite(v) & (v >= lo) & (v <= hi))


def invalid_fields(pose: Pose | None, pixels, rule, where: np.ndarray, names: Mapping[str, str],
                   more: Mapping[str, np.ndarray | tuple[np.ndarray, str]] | None = None) -> list[str]:
    """Each input that is missing or out of range in the targets ``where`` marks, as "NAME is missing
    or out of range in N of them", the worst first; ``names`` gives each field's user-facing name
    (pose fields, "gimbal1", "gimbal2", ..., "u_px", "v_px", "rule"); ``more``: other inputs of
    the caller's, as a user-facing name and where that input is bad (or (where, what to do))."""
    n = int(where.sum())
    fields: list[tuple[str, np.ndarray, str]] = []
    for name, bad in (more or {}).items():
        bad, advice = bad if isinstance(bad, tuple) else (bad, "")
        fields.append((name, np.broadcast_to(bad, where.shape), advice))
    if pose is not None:
        size = where.shape
        checks = (("lat_deg", pose.lat_deg, -90, 90), ("lon_deg", pose.lon_deg, -360, 360),
                  ("h_m", pose.h_m, -12_000, 1e8), ("yaw_deg", pose.yaw_deg, -1e4, 1e4),
                  ("pitch_deg", pose.pitch_deg, -1e4, 1e4), ("roll_deg", pose.roll_deg, -1e4, 1e4),
                  ("focal_scale", pose.focal_scale, 1e-9, 1e9))
        fields += [(name, np.broadcast_to(_bad(v, lo, hi), size), "") for name, v, lo, hi in checks]
        fields += [(f"gimbal{i + 1}", np.broadcast_to(_bad(a), size), "") for i, a in enumerate(pose.gimbal_deg)]
    if pixels is not None:
        fields += [(name, np.broadcast_to(_bad(p), where.shape), "")
                   for name, p in zip(("u_px", "v_px"), pixels, strict=True)]
    field_name = getattr(rule, "value_field", None)
    if field_name is not None:
        fields.append(("rule", np.broadcast_to(_bad(getattr(rule, field_name)), where.shape), ""))
    found = sorted((-int((bad & where).sum()), order, key, advice) for order, (key, bad, advice) in enumerate(fields))
    out = []
    for k, _, key, advice in found:
        if k:
            share = "" if n == 1 else f" in {'all' if -k == n else -k} of them"
            out.append(f"{names.get(key, key)} is missing or out of range{share}" + (f" ({advice})" if advice else ""))
    return out


def explain_failures(fixes: Fixes, *, pose: Pose | None = None, pixels=None, rule=None,
                     names: Mapping[str, str] | None = None, what: str = "targets",
                     more: Mapping[str, np.ndarray | tuple[np.ndarray, str]] | None = None) -> str | None:
    """One line when at least half of the ``what`` failed for one reason (or the one target failed):
    the status, what it means, the inputs at fault (INVALID_INPUT: which field, in how many) and
    what to do. ``pose``, ``pixels`` and ``rule``: each target's inputs as located (broadcast to
    the fixes); ``more``: the caller's other inputs (:func:`invalid_fields`). Callers whose inputs
    cost work to gather ask :func:`commonest_failure` first: most runs have nothing to explain."""
    common = commonest_failure(fixes)
    if common is None:
        return None
    status, n = common
    total = int(np.size(fixes.status))
    head = (f"{n} of {total} {what} are {status.name} ({status.explanation})" if total > 1 else
            f"{status.name}: {status.explanation}")
    if status == Status.INVALID_INPUT:
        where = np.broadcast_to(np.asarray(fixes.status) == Status.INVALID_INPUT, np.shape(fixes.status))
        causes = invalid_fields(pose, pixels, rule, np.atleast_1d(where), names or {}, more)
        if causes:
            return f"{head}: {'; '.join(causes[:3])}"
        return head
    return f"{head}: {FIXES[status]}" if status in FIXES else head


def telemetry_names(angle_names: tuple[str, ...], rule=None) -> dict[str, str]:
    """The user-facing names of the inputs of a telemetry file (CSV columns, as `eoloc locate
    --help` gives them) for :func:`invalid_fields`."""
    names = {"h_m": "h_m (or h_msl_m)", "focal_scale": "the focal length (hfov_deg, focal_px or focal_mm)"}
    for i, angle in enumerate(angle_names):
        names[f"gimbal{i + 1}"] = f"gimbal{i + 1}_deg (the gimbal's {angle})"
    names[f"gimbal{len(angle_names) + 1}"] = "sensor_roll_deg"
    field_name = getattr(rule, "value_field", None)
    if field_name == "range_m":
        names["rule"] = "range_m (the slant range to stop at; else give a constant --range R or --target-height H)"
    elif field_name is not None:
        names["rule"] = f"the stop value ({field_name})"
    return names
