"""Reading a job's tables: telemetry (the config's heading bias removed) and the second file."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import InputError
from ..io.table import Issue, Table
from ..io.telemetry import read_detections, read_telemetry, with_heading_bias


@dataclass
class Inputs:
    """The telemetry, the second table (detections, GCPs) or None, and every issue met reading them."""

    telemetry: Table
    other: Table | None
    issues: list[Issue] = field(default_factory=list)


def read_inputs(telemetry, other=None, *, heading_bias_deg: float = 0.0, reader=read_detections,
                msl_geoid: str | None = None) -> Inputs:
    """Both tables; an InputError (with the issues that explain it) when either has no usable record.
    ``msl_geoid``: the geoid grid for telemetry heights given as h_msl_m (default EGM96)."""
    geoid = None
    if msl_geoid is not None:
        from ..terrain.geoid import Geoid

        geoid = Geoid(msl_geoid)
    tel = with_heading_bias(read_telemetry(telemetry, geoid=geoid), heading_bias_deg)
    det = reader(other) if other else None
    issues = list(tel.issues) + (list(det.issues) if det is not None else [])
    if len(tel) == 0:
        raise InputError(f"telemetry file {str(telemetry)!r} has no usable record", issues)
    if det is not None and len(det) == 0:
        raise InputError(f"file {str(other)!r} has no usable record (only a header?): nothing to locate", issues)
    return Inputs(tel, det, issues)
