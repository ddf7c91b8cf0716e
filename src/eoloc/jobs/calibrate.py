"""The `eoloc calibrate` job: mount / boresight / heading / time offset from ground control points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..io.export import json_safe
from ..io.records import plain_value
from ..io.table import Issue
from .inputs import job_inputs


@dataclass
class CalibrationJob:
    """The solution (eoloc.sequence.calibration.Calibration), the starting sensor and telemetry corrections,
    one residual row per GCP observation, the report (calibration.json's content, JSON-safe) and
    the input issues."""

    calibration: object
    sensor: object
    heading_bias_deg: float
    time_offset_s: float
    groups: tuple[str, ...]
    rows: list[dict]
    report: dict
    issues: list[Issue] = field(default_factory=list)


def calibrate_job(cfg, telemetry, gcps, *, groups: tuple[str, ...], pixel_sigma_px: float = 1.0,
                  robust: bool = False, interpolate: bool = False, max_gap_s: float = 0.5,
                  time_tolerance_s: float = 0.02) -> CalibrationJob:
    from ..io.telemetry import match_detections, read_gcps, telemetry_pose
    from ..sequence.calibration import GROUPS, TelemetryTrack
    from ..sequence.calibration import calibrate as solve

    bad = [g for g in groups if g not in GROUPS]
    if bad or not groups:
        raise InputError(f"--estimate: unknown {bad or list(groups)}; choose from {', '.join(GROUPS)}")
    # the raw telemetry: the config's heading bias is the starting value, not a correction here
    inputs = job_inputs(cfg, telemetry, gcps, reader=read_gcps, heading_bias=False)
    sensor = inputs.sensor(cfg)
    tel, obs, issues = inputs.telemetry, inputs.other, list(inputs.issues)
    hb0, dt0 = cfg.telemetry.heading_bias_deg, cfg.telemetry.time_offset_s
    keep = np.ones(len(obs), dtype=bool)
    if interpolate or "time" in groups:
        tt, to = tel.columns["time_s"], obs.columns["time_s"]
        if not (np.isfinite(tt).any() and np.isfinite(to).all()):
            raise InputError("interpolation / the time offset needs time_s in both the telemetry and the GCP file",
                             issues)
        kw = {"telemetry": TelemetryTrack(tt, telemetry_pose(tel, camera=sensor.camera), max_gap_s), "time_s": to}
    else:
        m = match_detections(tel, obs, time_tolerance_s=time_tolerance_s)
        issues += m.issues
        keep = m.record >= 0
        kw = {"pose": telemetry_pose(tel, m.record[keep], sensor.camera)}
    c = obs.columns
    uv = np.c_[c["u_px"], c["v_px"]][keep]
    llh = np.c_[c["lat_deg"], c["lon_deg"], c["h_m"]][keep]
    try:
        cal = solve(sensor, uv, llh, estimate=groups, pixel_sigma_px=pixel_sigma_px, heading_bias_deg=hb0,
                    time_offset_s=dt0, robust=robust, **kw)
    except InputError as exc:
        raise InputError(str(exc), issues) from None
    gid = np.asarray(c["gcp_id"])[keep]
    lines = np.asarray(obs.line)[keep]
    rows = [{k: plain_value(v) for k, v in {
        "line": int(lines[i]), "gcp_id": str(gid[i]), "used": bool(cal.used[i]),
        "du_before_px": cal.residual_px_before[i, 0], "dv_before_px": cal.residual_px_before[i, 1],
        "du_after_px": cal.residual_px_after[i, 0], "dv_after_px": cal.residual_px_after[i, 1],
        "ground_error_before_m": cal.ground_error_before_m[i],
        "ground_error_after_m": cal.ground_error_after_m[i]}.items()} for i in range(gid.size)]
    report = {"parameters": cal.as_dict(), "sigma": dict(zip(cal.names, cal.sigma.tolist(), strict=True)),
              "correlation": cal.correlation.tolist(), "s0": cal.s0, "undetermined": cal.undetermined,
              "rms_px_before": cal.rms(cal.residual_px_before), "rms_px_after": cal.rms(cal.residual_px_after),
              "rms_ground_m_before": cal.rms(cal.ground_error_before_m),
              "rms_ground_m_after": cal.rms(cal.ground_error_after_m), "warnings": cal.warnings}
    # JSON has no NaN or Infinity: an unknown sigma or correlation is null
    return CalibrationJob(cal, sensor, hb0, dt0, tuple(groups), rows, json_safe(report), issues)


def write_back(job: CalibrationJob, config_path) -> None:
    """The estimated values into the config file (comments kept); refused, naming them, when the
    observations do not determine some of them."""
    from ..io.config import write_calibration

    cal, groups = job.calibration, job.groups
    if cal.undetermined:
        raise InputError(f"not writing {config_path}: these observations do not determine "
                         f"{', '.join(cal.undetermined)}; add GCPs seen from other attitudes or look directions, or "
                         "leave them out of --estimate")
    write_calibration(config_path,
                      mount_misalignment_deg=cal.sensor.mount_misalignment_deg if "mount" in groups else None,
                      boresight_misalignment_deg=cal.sensor.boresight_misalignment_deg if "boresight" in groups
                      else None,
                      heading_bias_deg=cal.heading_bias_deg if "heading" in groups else None,
                      time_offset_s=cal.time_offset_s if "time" in groups else None)
