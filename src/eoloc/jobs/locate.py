"""The `eoloc locate` job in file mode: telemetry (+ detections) + config + stop rule -> one row
per target, with the uncertainty and compensation columns when asked, and the warnings a user
should read."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.export import fix_records, with_utc
from ..io.records import Records
from ..io.table import Issue, Table
from ..rules import StopRule
from .explain import commonest_failure, explain_failures, nothing_located, telemetry_names
from .inputs import Prefetch, job_inputs
from .tables import Located, locate_tables

NONLINEARITY_LIMIT = 0.1  # past it the first-order covariance does not describe the fix


@dataclass
class LocateJob:
    """Records (one per target, every one kept), the Located arrays, the issues of the inputs and
    the notes (whole-run warnings) in the order to show them."""

    records: Records
    located: Located
    extra: dict  # the per-target descriptive columns of the records (located.extra with time_utc when known)
    issues: list[Issue] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    compensation_summary: str | None = None
    telemetry: Table | None = None  # the telemetry as read (its poses, per record)

    @property
    def status_counts(self) -> dict[str, int]:
        return self.located.fixes.status_counts()


def locate_files(cfg, telemetry: str | Path, detections: str | Path | Prefetch | None, rule: StopRule | str, *,
                 time_tolerance_s: float = 0.02, budget=None, interpolate: bool = False, max_gap_s: float = 0.5,
                 time_offset_s: float | None = None, compensation=None, poses: dict | None = None,
                 poses_from: str = "") -> LocateJob:
    """Locate every detection (or every record's image centre) of the files with the config's
    sensor (``detections``: a path, or a :class:`Prefetch` of one started before the config was
    loaded); ``time_offset_s`` None takes the config's [telemetry] time_offset_s. ``poses``: drone
    photos' poses by file name (eoloc refine's, read from ``poses_from``) in place of their own."""
    inputs = job_inputs(cfg, telemetry, detections, dem=rule.terrain)
    if poses is not None:
        from ..io.sources.photos import DronePhotos, with_poses

        if inputs.source.source != DronePhotos.name:
            raise InputError(f"{telemetry}: poses replace drone photos' own (--poses, --refine): give the photos")
        inputs.issues += with_poses(inputs.telemetry, poses, poses_from or "the poses given")
    tel_cfg = cfg.telemetry if cfg is not None else None
    if time_offset_s is None:
        time_offset_s = tel_cfg.time_offset_s if tel_cfg is not None else 0.0
    sensor = inputs.sensor(cfg)
    located = locate_tables(sensor, inputs.telemetry, inputs.other, rule, time_tolerance_s=time_tolerance_s,
                            budget=budget, compensation=compensation, interpolate=interpolate, max_gap_s=max_gap_s,
                            time_offset_s=time_offset_s)
    notes: list[str] = []
    after = None
    if located.covariance is not None:
        from ..accuracy.covariance import covariance_columns

        after = covariance_columns(located.covariance, located.fixes.ok)
        loose = np.flatnonzero(located.fixes.ok & ~(after["nonlinearity"] <= NONLINEARITY_LIMIT))
        if loose.size:
            notes.append(f"{loose.size} fixes have a nonlinearity > {NONLINEARITY_LIMIT:g} (column nonlinearity): "
                         "their first-order uncertainty is not to be trusted")
    summary = None
    if located.compensation is not None:
        comp = located.compensation
        after = {**(after or {}), **comp}
        ok = located.fixes.ok.ravel()
        applied = comp["comp_applied"] & ok
        flagged = ok & ~comp["comp_applied"]
        shift = np.hypot(comp["comp_e_m"], comp["comp_n_m"])[applied]
        summary = (f"compensation: {int(applied.sum())} fixes corrected"
                   + (f" (median shift {np.median(shift):.1f} m, max {shift.max():.1f} m)" if shift.size else "")
                   + f"; {int(flagged.sum())} outside the model's trained range left as located (column comp_flag "
                     "says why)")
    if commonest_failure(located.fixes) is not None:  # each target's pose gathered only to explain a failure
        stop = rule.describe() if isinstance(rule, StopRule) else "range from the files"
        why = explain_failures(located.fixes, pose=located.target_pose(), pixels=located.pixels, rule=located.rule,
                               names=telemetry_names(sensor.gimbal.angle_names, located.rule),
                               what=f"targets ({stop})")
        notes.append(("nothing was located: " if nothing_located(located.fixes) else "") + why)
    extra = with_utc(located.extra, tel_cfg.time_origin if tel_cfg is not None else None)
    return LocateJob(fix_records(located.fixes, extra, after, coded=located.coded), located, extra,
                     inputs.issues + located.issues, notes, summary, inputs.telemetry)
