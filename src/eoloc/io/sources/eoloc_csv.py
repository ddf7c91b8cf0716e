"""eoloc's own telemetry CSV (:func:`eoloc.io.telemetry.read_telemetry`): any text file no other
source claims, so that its reader can say what is wrong with it."""

from __future__ import annotations

from pathlib import Path

from .base import SourceData


class EolocCsv:
    name = "csv"
    summary = "eoloc telemetry CSV (time_s/frame, lat_deg, lon_deg, h_m or h_msl_m, attitude, gimbal angles)"

    def sniff(self, path: Path, head: bytes) -> bool:
        return not path.is_dir()  # the last source: its reader names what a file lacks

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        from ..telemetry import read_telemetry

        return SourceData(read_telemetry(path, geoid=geoid), self.name)
