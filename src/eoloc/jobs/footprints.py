"""The `eoloc footprint` job: the ground outline of every telemetry record's image."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..ground.footprint import Footprint, footprint_features, footprints
from ..io.records import plain_value
from ..io.table import Issue
from ..io.telemetry import telemetry_pose
from ..rules import StopRule
from .inputs import job_inputs


@dataclass
class FootprintJob:
    """One footprint per telemetry record, its row (line, time, frame, status, area, vertices, the
    centre's fix) and GeoJSON feature, and the input issues."""

    prints: list[Footprint]
    rows: list[dict]
    features: list[dict]
    issues: list[Issue] = field(default_factory=list)

    def status_counts(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for p in self.prints:
            counts[p.status.name] = counts.get(p.status.name, 0) + 1
        return counts

    @property
    def clipped(self) -> int:
        return sum(bool(p.clipped.any()) for p in self.prints)


def footprint_job(cfg, telemetry, ground: StopRule, *, edge_samples: int = 16, chunk: int = 64,
                  progress: Callable[[int], None] | None = None) -> FootprintJob:
    """Footprints of every record of ``telemetry`` on the ``ground`` rule's surface (AtHeight or OnDEM),
    in chunks of ``chunk`` frames (``progress(k)`` after each)."""
    inputs = job_inputs(cfg, telemetry, dem=ground.terrain)
    tel = inputs.telemetry
    sensor = inputs.sensor(cfg)
    prints: list[Footprint] = []
    for start in range(0, len(tel), chunk):
        idx = np.arange(start, min(start + chunk, len(tel)))
        prints += footprints(sensor, telemetry_pose(tel, idx, sensor.camera), ground, edge_samples=edge_samples)
        if progress is not None:
            progress(idx.size)
    c = tel.columns
    base = [{"line": int(tel.line[i]), "time_s": plain_value(c["time_s"][i]), "frame": plain_value(c["frame"][i])}
            for i in range(len(tel))]
    features = footprint_features(prints, base)
    rows = [{**b, "status": p.status.name, "area_m2": p.area_m2, "vertices": len(p),
             "clipped_vertices": int(p.clipped.sum()), "centre_lat_deg": plain_value(p.centre[0]),
             "centre_lon_deg": plain_value(p.centre[1]), "centre_h_m": plain_value(p.centre[2])}
            for b, p in zip(base, prints, strict=True)]
    return FootprintJob(prints, rows, features, inputs.issues)
