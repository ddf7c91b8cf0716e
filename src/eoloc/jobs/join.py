"""`eoloc join`: telemetry + GCP sightings (the files `eoloc calibrate` takes) into the one
observations table that `eoloc report` and `eoloc compensate` take, so that one flight's files
serve every flight-test command.

Each GCP sighting (time_s or frame, gcp_id, u_px, v_px, the point's surveyed lat_deg, lon_deg,
h_m) is paired with its telemetry record as `eoloc locate` pairs detections (same frame, else
the nearest time within the tolerance); the row carries the record's pose as eoloc read it
(ellipsoidal height, the config's heading bias not applied: the observations are raw telemetry,
as calibrate and report expect) and the point as gcp_lat_deg, gcp_lon_deg, gcp_h_m. Several
pairs of files join into one table, the flight column telling them apart (each telemetry file's
name, or the names given).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.records import Records
from ..io.table import Issue
from .inputs import job_inputs

POSE_COLUMNS = ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg",
                "sensor_roll_deg")


@dataclass
class JoinJob:
    """The observations (one row per paired sighting), how many sightings each flight had and
    kept, and every issue met (unpaired sightings named by file and line)."""

    records: Records
    flights: dict[str, tuple[int, int]]  # flight -> (sightings, paired)
    issues: list[Issue] = field(default_factory=list)


def join_observations(cfg, pairs, *, flights=None, time_tolerance_s: float = 0.02) -> JoinJob:
    """Join each (telemetry, GCP file) of ``pairs``; ``flights``: their flight ids (default: each
    telemetry file's name without its extension)."""
    from ..io.telemetry import match_detections, read_gcps

    names = list(flights) if flights else [Path(str(t)).stem for t, _ in pairs]
    if len(names) != len(pairs):
        raise InputError(f"{len(names)} flight names for {len(pairs)} pairs of files: give one per pair")
    if len(set(names)) != len(names):
        raise InputError(f"flight names repeat ({', '.join(names)}): give each pair its own with --flight NAME")
    columns: dict[str, list[np.ndarray]] = {}
    counts: dict[str, tuple[int, int]] = {}
    issues: list[Issue] = []
    for name, (telemetry, gcps) in zip(names, pairs, strict=True):
        inputs = job_inputs(cfg, telemetry, gcps, reader=read_gcps, heading_bias=False)
        if inputs.source is not None and inputs.source.camera_attitude:
            raise InputError(f"{telemetry}: this source gives the camera's own attitude (a drone's), not the "
                             "aircraft's and the gimbal's that an observations table holds; calibrate from it "
                             "with `eoloc calibrate TELEMETRY GCPS` directly")
        tel, obs = inputs.telemetry, inputs.other
        issues += inputs.issues
        m = match_detections(tel, obs, time_tolerance_s=time_tolerance_s)
        issues += m.issues
        keep = m.record >= 0
        rec = m.record[keep]
        c, t = obs.columns, tel.columns
        part = {"flight": np.full(int(keep.sum()), name, dtype=object),
                "time_s": np.where(np.isfinite(c["time_s"][keep]), c["time_s"][keep], t["time_s"][rec]),
                "frame": np.where(np.isfinite(c["frame"][keep]), c["frame"][keep], t["frame"][rec]),
                **{k: np.asarray(t[k], dtype=np.float64)[rec] for k in POSE_COLUMNS},
                "u_px": c["u_px"][keep], "v_px": c["v_px"][keep], "gcp_id": np.asarray(c["gcp_id"])[keep],
                "gcp_lat_deg": c["lat_deg"][keep], "gcp_lon_deg": c["lon_deg"][keep], "gcp_h_m": c["h_m"][keep],
                "telemetry_line": np.asarray(tel.line)[rec], "gcp_line": np.asarray(obs.line)[keep]}
        for k, v in part.items():
            columns.setdefault(k, []).append(v)
        counts[name] = (len(obs), int(keep.sum()))
    joined = {k: np.concatenate(v) for k, v in columns.items()}
    if not len(joined["flight"]):
        raise InputError("no GCP sighting could be paired with a telemetry record (the issues above say why)", issues)
    for k in ("time_s", "frame"):  # a column neither file gave is left out, as the readers leave it
        if not np.isfinite(joined[k]).any():
            del joined[k]
    return JoinJob(Records(joined), counts, issues)
