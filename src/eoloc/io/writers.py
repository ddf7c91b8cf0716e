"""The writer registry: every command writes its layers through here, in the formats the user
picks with one repeated option (``--format csv --format kml``).

A layer is point rows (fixes: one dict per target, ``lat_deg``/``lon_deg``/``h_m``/``status``;
failed fixes kept, with no geometry) or GeoJSON features (footprints, tracks) with their rows.
Formats: CSV (every row), GeoJSON (RFC 7946, rings counter-clockwise), KML (simplekml, heights
converted to MSL), CoT (TAK data package of one event per located point; point layers only).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from .export import fix_features, write_csv, write_feature_collection

DEFAULT_FORMATS = ("csv", "geojson")


def _csv(path: Path, rows: list[dict], features: list[dict], name: str) -> Path:
    return write_csv(path.with_suffix(".csv"), rows)


def _geojson(path: Path, rows: list[dict], features: list[dict], name: str) -> Path:
    return write_feature_collection(path.with_suffix(".geojson"), features, indent=1)


def _kml(path: Path, rows: list[dict], features: list[dict], name: str) -> Path:
    from .kml import write_kml

    return write_kml(path.with_suffix(".kml"), {name: features}, name=name)


def _cot(path: Path, rows: list[dict], features: list[dict], name: str) -> Path | None:
    if not all(f.get("geometry") is None or f["geometry"]["type"] == "Point" for f in features):
        return None  # CoT events here are points: footprints and tracks go to KML/GeoJSON
    from .cot import write_cot

    return write_cot(path.with_name(path.name + ".cot.zip"), rows, name=name)[0]


WRITERS: dict[str, Callable[[Path, list[dict], list[dict], str], Path | None]] = {
    "csv": _csv, "geojson": _geojson, "kml": _kml, "cot": _cot,
}
FORMATS = tuple(WRITERS)


def write_layer(out_dir: str | Path, stem: str, rows: list[dict], formats: Iterable[str] = DEFAULT_FORMATS, *,
                features: list[dict] | None = None, name: str | None = None) -> list[Path]:
    """Write one layer as ``out_dir/stem.<ext>`` in each format; point rows become GeoJSON Point
    features unless ``features`` are given. Returns the paths written (a format that does not
    apply to the layer, CoT for polygons, writes nothing)."""
    feats = fix_features(rows) if features is None else features
    base = Path(out_dir) / stem
    written = []
    for fmt in dict.fromkeys(formats):
        p = WRITERS[fmt](base, rows, feats, name or stem)
        if p is not None:
            written.append(p)
    return written
