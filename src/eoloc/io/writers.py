"""The writer registry: every command writes its layers through here, in the formats the user
picks with one repeated option (``--format csv --format kml``).

A layer is point records (:class:`Records`, or dict rows; one per target, ``lat_deg``/``lon_deg``/
``h_m``/``status``; failed fixes kept, with no geometry) or GeoJSON features (footprints, tracks)
with their records.
Formats: CSV (every row), GeoJSON (RFC 7946, rings counter-clockwise), KML (ElementTree, heights
converted to MSL), CoT (TAK data package of one event per located point; point layers only),
GeoParquet and GeoPackage (:mod:`eoloc.io.geotable`: WKB geometry, EPSG:4979).
Grid references (MGRS, UTM) are added as columns on request (:mod:`eoloc.io.gridref`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from .csvfile import write_csv
from .export import FIX_COLUMNS, fix_features, write_feature_collection
from .geojsonfile import write_fix_geojson
from .records import Records

DEFAULT_FORMATS = ("csv", "geojson")


def _csv(path: Path, records: Records, features: list[dict] | None, name: str) -> Path:
    return write_csv(path.with_suffix(".csv"), records, columns=FIX_COLUMNS)


def _geojson(path: Path, records: Records, features: list[dict] | None, name: str) -> Path:
    if features is None:
        return write_fix_geojson(path.with_suffix(".geojson"), records)
    return write_feature_collection(path.with_suffix(".geojson"), features, indent=1)


def _kml(path: Path, records: Records, features: list[dict] | None, name: str) -> Path:
    from .kml import write_kml

    return write_kml(path.with_suffix(".kml"), {name: fix_features(records) if features is None else features},
                     name=name)


def _cot(path: Path, records: Records, features: list[dict] | None, name: str) -> Path | None:
    if features is not None and not all(f.get("geometry") is None or f["geometry"]["type"] == "Point"
                                        for f in features):
        return None  # CoT events here are points: footprints and tracks go to KML/GeoJSON
    from .cot import write_cot

    return write_cot(path.with_name(path.name + ".cot.zip"), records.rows(), name=name)[0]


def _geoparquet(path: Path, records: Records, features: list[dict] | None, name: str) -> Path:
    from .geotable import write_geoparquet

    return write_geoparquet(path.with_suffix(".parquet"), records, features)


def _gpkg(path: Path, records: Records, features: list[dict] | None, name: str) -> Path:
    from .geotable import write_gpkg

    return write_gpkg(path.with_suffix(".gpkg"), records, features, layer=name)


WRITERS: dict[str, Callable[[Path, Records, list[dict] | None, str], Path | None]] = {
    "csv": _csv, "geojson": _geojson, "kml": _kml, "cot": _cot, "geoparquet": _geoparquet, "gpkg": _gpkg,
}
FORMATS = tuple(WRITERS)


def write_layer(out_dir: str | Path, stem: str, records: Records | Sequence[Mapping],
                formats: Iterable[str] = DEFAULT_FORMATS, *, features: list[dict] | None = None,
                name: str | None = None, grid: Iterable[str] = ()) -> list[Path]:
    """Write one layer as ``out_dir/stem.<ext>`` in each format; point records become GeoJSON
    Point features unless ``features`` are given; records without lat_deg/lon_deg are a table
    (CSV only). ``grid``: grid-reference columns to add to point records (``mgrs``, ``utm``).
    Returns the paths written (a format that does not apply to the layer, CoT for polygons,
    GeoJSON for a table, writes nothing)."""
    recs = Records.of(records)
    if grid:
        from .gridref import with_grid_columns

        recs = with_grid_columns(recs, grid)
    if features is None and not recs.has_points:
        formats = [f for f in formats if f == "csv"]  # a table without geometry (statistics, residuals)
    base = Path(out_dir) / stem
    written = []
    for fmt in dict.fromkeys(formats):
        p = WRITERS[fmt](base, recs, features, name or stem)
        if p is not None:
            written.append(p)
    return written
