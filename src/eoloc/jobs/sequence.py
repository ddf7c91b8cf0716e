"""The jobs over many frames: `eoloc track` (moving targets by Kalman filter, static ones by RLS)
and `eoloc triangulate` (multi-view, no range or terrain)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..io.export import fix_records
from ..io.records import Records
from ..io.table import Issue
from ..result import Fixes
from .inputs import job_inputs
from .locate import LocateJob, locate_files


def located_detections(cfg, telemetry, detections, rule, **kw) -> LocateJob:
    """Every detection located (with its covariance when the config has [accuracy.budget]); an
    InputError when none could be."""
    from .setup import optional_budget

    budget = optional_budget(cfg)
    job = locate_files(cfg, telemetry, detections, rule, budget=budget, **kw)
    if not job.located.fixes.ok.any():
        why = next((n for n in job.notes if n.startswith("nothing was located")), None)
        raise InputError(why or f"none of the {len(job.located.fixes)} detections could be located; check the stop "
                         "rule (--range needs range_m in the files, else give --range R or --target-height H)",
                         job.issues)
    t = np.asarray(job.located.extra["time_s"], dtype=np.float64)
    if not np.isfinite(t[job.located.fixes.ok]).all():
        raise InputError("tracking needs time_s in the detections file (frame numbers alone give no time)",
                         job.issues)
    return job


@dataclass
class TrackJob:
    """Tracks (eoloc.sequence.track.Tracks), one record per detection (its fix, track and filtered
    state), the track features (LineStrings with coordTimes) and how many fixes joined no track."""

    tracks: object
    records: Records
    features: list[dict]
    unassigned: int


def track_job(job: LocateJob, *, associate: bool, accel_psd: float, meas_sigma_m: float, max_coast_s: float,
              progress=None) -> TrackJob:
    from ..sequence.track import TrackerConfig, track_features, track_fixes

    located = job.located
    t = np.asarray(located.extra["time_s"], dtype=np.float64)
    ids = np.asarray(located.extra["target_id"]).astype(str)
    ts = track_fixes(t, located.fixes, None, None if associate else ids, covariance=located.covariance,
                     associate=associate,
                     config=TrackerConfig(accel_psd=accel_psd, meas_sigma_m=meas_sigma_m, max_coast_s=max_coast_s),
                     progress=progress)
    left = int(np.sum((ts.assigned == "") & np.ravel(located.fixes.ok)))
    return TrackJob(ts, _track_records(ts, job), track_features(ts), left)


def _track_records(ts, job: LocateJob) -> Records:
    """Per detection: its fix, the track it joined and the filtered state there."""
    located = job.located
    n = len(located.fixes)
    cols = {k: np.full(n, np.nan) for k in ("filt_lat_deg", "filt_lon_deg", "speed_mps", "speed_sigma_mps",
                                             "heading_deg", "sigma_e_m", "sigma_n_m")}
    for tr in ts.tracks:
        lat, lon, _ = ts.geodetic(tr)
        idx = np.asarray(tr.detection)
        P = np.asarray(tr.cov)
        cols["filt_lat_deg"][idx], cols["filt_lon_deg"][idx] = lat, lon
        cols["speed_mps"][idx], cols["speed_sigma_mps"][idx] = tr.speed_mps, tr.speed_sigma_mps
        cols["heading_deg"][idx] = tr.heading_deg
        first = idx[:1]  # a track's first fix: position only, its speed and course are not known yet
        cols["speed_mps"][first] = cols["speed_sigma_mps"][first] = cols["heading_deg"][first] = np.nan
        cols["sigma_e_m"][idx], cols["sigma_n_m"][idx] = np.sqrt(P[:, 0, 0]), np.sqrt(P[:, 1, 1])
    extra = dict(job.extra, track_id=ts.assigned)
    return fix_records(located.fixes, extra, cols)


def static_targets(job: LocateJob, *, forgetting: float, meas_sigma_m: float, window: int) -> list[dict]:
    """Recursive least squares per target id over its frames: one row per target, with its sigma,
    CEP50, CE90, LE90, scatter ratio and convergence. With an error budget the uncertainty is the
    budget's over those frames (biases kept whole, noise averaged down, Gauss–Markov errors by
    their correlation in time) and a target whose fixes do not agree with one point gets status
    INCONSISTENT and no point; without one (an assumed ``meas_sigma_m``) a target whose fixes
    scatter more than SCATTER_LIMIT times that sigma gets a warning and the fixes' own scatter as
    its uncertainty."""
    from ..accuracy.cep import LE90_PER_SIGMA, cep_ce_le
    from ..result import Status
    from ..sequence.rls import SCATTER_LIMIT, rls_static, scatter_inflation

    located = job.located
    fixes: Fixes = located.fixes
    t = np.asarray(located.extra["time_s"], dtype=np.float64)
    covariance = located.covariance
    ids = np.asarray(located.extra["target_id"]).astype(str)
    rows = []
    for tid in sorted(set(ids.tolist())):
        sel = np.flatnonzero(ids == tid)
        sel = sel[np.argsort(t[sel], kind="stable")]
        f = fixes.flat(sel)
        if not f.ok.any():
            rows.append({"target_id": tid, "frames": int(sel.size), "used": 0, "status": "NO_FIX"})
            continue
        est = rls_static(f, sigma_m=meas_sigma_m, covariance=None if covariance is None else covariance.take(sel),
                         time_s=t[sel], forgetting=forgetting, window=window)
        ok_f = np.flatnonzero(f.ok)
        single = np.hypot(est.sigma_m[ok_f[0], 0], est.sigma_m[ok_f[0], 1])  # the first fix's own sigma
        conv = int(est.converged_frame)
        ratio = float(est.scatter_ratio)
        row = {"target_id": tid, "frames": int(sel.size), "used": int(est.n_used), "scatter_ratio": ratio}
        if est.status == Status.INCONSISTENT:
            rows.append({**row, "status": "INCONSISTENT", "warning": (
                f"the {int(est.n_used)} fixes scatter {ratio:.1f}x more than their uncertainty allows: "
                f"{Status.INCONSISTENT.explanation} (a moving target: eoloc track without --static)")})
            continue
        cov = est.cov_enu
        inflate = 1.0
        warning = ""
        if covariance is None:
            # an assumed sigma: frames that spread far more than it allows (the target moved, or the
            # sigma is optimistic) make the fixes' own scatter the uncertainty, said
            inflate = float(scatter_inflation(ratio, single, float(np.mean(np.sqrt(np.diagonal(cov)[:2])))))
            if inflate > 1.0:
                warning = (f"the {int(est.n_used)} fixes scatter {ratio:.1f}x more than their sigma allows "
                           f"(> {SCATTER_LIMIT:g}): the target moves, or the sigma is optimistic; its uncertainty is "
                           f"the fixes' own scatter, {inflate:.1f}x the static estimate's (for a moving target use "
                           "eoloc track without --static)")
        s = np.sqrt(np.diagonal(cov)) * inflate
        spread = cep_ce_le(cov[:2, :2] * inflate**2, vertical=False)
        rows.append({**row, "lat_deg": float(est.lat_deg), "lon_deg": float(est.lon_deg), "h_m": float(est.h_m),
                     "sigma_e_m": float(s[0]), "sigma_n_m": float(s[1]), "sigma_u_m": float(s[2]),
                     **{k: float(v) for k, v in spread.items()}, "le90_m": LE90_PER_SIGMA * float(s[2]),
                     "first_fix_sigma_h_m": float(single),
                     "converged_at_s": float(t[sel][conv]) if conv >= 0 else None, "status": "OK",
                     "warning": warning})
    return rows


@dataclass
class TriangulateJob:
    rows: list[dict]
    issues: list[Issue] = field(default_factory=list)


def triangulate_job(cfg, telemetry, detections, *, ray_sigma_deg: float, min_angle_deg: float,
                    time_tolerance_s: float) -> TriangulateJob:
    """Each target id's rays intersected (M8): one row per target with its point, sigma, residuals,
    widest ray angle and warning; TOO_FEW_RAYS / DEGENERATE rows keep the targets that fail."""
    from ..io.telemetry import match_detections, telemetry_pose
    from ..rules.multiview import triangulate as tri

    inputs = job_inputs(cfg, telemetry, detections)
    tel, det = inputs.telemetry, inputs.other
    matched = match_detections(tel, det, time_tolerance_s=time_tolerance_s)
    has = matched.record >= 0
    sensor = inputs.sensor(cfg)
    pose = telemetry_pose(tel, np.where(has, matched.record, 0), sensor.camera)
    rays = sensor.rays(pose, (det.columns["u_px"], det.columns["v_px"]))
    ids = np.asarray(det.columns["target_id"]).astype(str)
    rows = []
    for tid in sorted(set(ids.tolist())):
        sel = np.flatnonzero((ids == tid) & has)
        row = {"target_id": tid, "rays": int(sel.size)}
        try:
            r = tri(rays.take(sel), np.radians(ray_sigma_deg), min_angle_deg=min_angle_deg)
        except InputError as exc:
            rows.append({**row, "status": "TOO_FEW_RAYS", "warning": str(exc)})
            continue
        if not r.ok:
            rows.append({**row, "max_angle_deg": r.max_angle_deg, "status": r.status.name, "warning": r.warning})
            continue
        s = r.sigma_enu * max(1.0, r.s0)
        rows.append({**row, "lat_deg": r.lat_deg, "lon_deg": r.lon_deg, "h_m": r.h_m, "sigma_e_m": s[0],
                     "sigma_n_m": s[1], "sigma_u_m": s[2], "s0": r.s0,
                     "rms_residual_m": float(np.sqrt(np.mean(r.residuals_m**2))),
                     "max_angle_deg": r.max_angle_deg, "status": "OK", "warning": r.warning})
    return TriangulateJob(rows, inputs.issues + matched.issues)
