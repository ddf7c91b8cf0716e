"""Layers as Arrow tables with a WKB geometry column: GeoParquet and GeoPackage.

One table per layer: every record column as it is (floats with nulls where there is no value,
integers, booleans, text) plus ``geometry`` (WKB, longitude/latitude/ellipsoidal height: a
``Point Z`` per located fix, null for a fix that failed; polygons and lines for footprint and
track features). Geometries are built by shapely in vectorised calls.

GeoParquet: GeoParquet 1.1 metadata (``geo`` key: encoding, geometry types, bbox, and the CRS as
PROJJSON - EPSG:4979, WGS 84 with ellipsoidal heights, or EPSG:4326 for 2-D layers), written by
pyarrow; read back by geopandas and by DuckDB's spatial extension (tested). GeoPackage: the same
table through pyogrio/GDAL (``write_arrow``), one layer per file.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from .records import Records

GEOPARQUET_VERSION = "1.1.0"
GEOMETRY_TYPES = {0: "Point", 1: "LineString", 3: "Polygon", 4: "MultiPoint", 5: "MultiLineString", 6: "MultiPolygon",
                  7: "GeometryCollection"}


def _column(v: np.ndarray):
    import pyarrow as pa

    if v.dtype.kind == "f":
        return pa.array(v, mask=np.isnan(v))
    if v.dtype.kind in "iub":
        return pa.array(v)
    try:  # text and None (ids, status, ISO times)
        return pa.array(v, type=pa.string(), from_pandas=True)
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        return pa.array([None if x is None or (isinstance(x, float) and math.isnan(x)) else str(x) for x in v.tolist()],
                        type=pa.string())


def point_geometries(records: Records):
    """Shapely points (N,) of point records: Point Z where h_m is known, Point where only the
    horizontal position is, None where there is no position."""
    import shapely

    lon = np.asarray(records["lon_deg"], dtype=np.float64)
    lat = np.asarray(records["lat_deg"], dtype=np.float64)
    h = np.asarray(records["h_m"], dtype=np.float64) if "h_m" in records.columns else np.full(lon.shape, np.nan)
    geoms = np.full(lon.shape, None, dtype=object)
    where = np.isfinite(lon) & np.isfinite(lat)
    z = where & np.isfinite(h)
    geoms[z] = shapely.points(lon[z], lat[z], h[z])
    flat = where & ~z
    geoms[flat] = shapely.points(lon[flat], lat[flat])
    return geoms


def feature_geometries(features):
    """Shapely geometries (N,) of GeoJSON features, or the geometries themselves where
    ``features`` is already an array of them (None: no geometry)."""
    if isinstance(features, np.ndarray):
        return features
    from shapely.geometry import shape

    return np.array([None if f.get("geometry") is None else shape(f["geometry"]) for f in features], dtype=object)


def geo_table(records: Records, features: list[dict] | np.ndarray | WKBColumn | None = None):
    """(pyarrow table with a WKB ``geometry`` column, the GeoParquet column metadata); ``features``:
    GeoJSON features or an array of shapely geometries, one per record (None: the records' points)."""
    import pyarrow as pa
    import shapely

    if features is None:
        column, gtypes, has_z, bounds = point_wkb(records)
        return _with_geometry(records, column, gtypes, has_z, bounds)
    if isinstance(features, WKBColumn):
        if len(records) != len(features):
            raise ValueError(f"geo_table: {len(records)} records for {len(features)} geometries")
        return _with_geometry(records, features.column, features.gtypes, features.has_z, features.bounds)
    geoms = feature_geometries(features)
    if len(records) != len(features):
        raise ValueError(f"geo_table: {len(records)} records for {len(features)} features")
    present = ~shapely.is_missing(geoms)
    sub = geoms[present]
    kinds = shapely.get_type_id(sub) if sub.size else np.zeros(0, dtype=int)
    zs = shapely.has_z(sub) if sub.size else np.zeros(0, dtype=bool)
    has_z = bool(zs.any())
    wkb = np.full(geoms.shape, None, dtype=object)
    if sub.size:
        wkb[present] = shapely.to_wkb(sub, output_dimension=3 if has_z else 2, flavor="iso")
    pairs = np.unique(np.asarray(kinds, dtype=np.int64) * 2 + np.asarray(zs, dtype=np.int64))
    gtypes = sorted({GEOMETRY_TYPES[int(p) // 2] + (" Z" if p % 2 else "") for p in pairs})
    bounds = shapely.total_bounds(sub) if sub.size else [math.nan] * 4
    return _with_geometry(records, pa.array(wkb.tolist(), type=pa.binary()), gtypes, has_z, bounds)


def _with_geometry(records: Records, column, gtypes: list[str], has_z: bool, bounds):
    return arrow_table(records).append_column("geometry", column), column_metadata(gtypes, has_z, bounds)


@cache
def _crs_json(has_z: bool) -> dict:
    from pyproj import CRS

    return CRS.from_epsg(4979 if has_z else 4326).to_json_dict()


def column_metadata(gtypes: list[str], has_z: bool, bounds) -> dict:
    """GeoParquet column metadata: WKB of ``gtypes``, EPSG:4979 (with heights) or 4326, the 2-D
    ``bounds`` as bbox where they are finite."""
    meta = {"encoding": "WKB", "geometry_types": gtypes, "crs": _crs_json(has_z), "edges": "planar"}
    if np.all(np.isfinite(bounds)):
        meta["bbox"] = [float(b) for b in bounds]
    return meta


_POINT_2D = np.dtype([("order", "u1"), ("kind", "<u4"), ("x", "<f8"), ("y", "<f8")])  # packed: 21 bytes
_POINT_Z = np.dtype([("order", "u1"), ("kind", "<u4"), ("x", "<f8"), ("y", "<f8"), ("z", "<f8")])  # 29 bytes


@dataclass
class WKBColumn:
    """Geometries already written as an Arrow binary column of ISO WKB (null: no geometry), with
    what GeoParquet's metadata needs: geometry types, has Z, 2-D bounds. :func:`geo_table` takes
    it as it is, without a shapely object per row."""

    column: Any
    gtypes: list[str]
    has_z: bool
    bounds: list[float]

    def __len__(self) -> int:
        return len(self.column)

    @property
    def drawn(self) -> bool:
        """At least one row has a geometry."""
        return self.column.null_count < len(self.column)

    def geometries(self) -> np.ndarray:
        """As shapely geometries (None where null)."""
        import shapely

        return shapely.from_wkb(np.array(self.column.to_pylist(), dtype=object))


def _binary_column(size: np.ndarray, groups: list[tuple[np.ndarray, np.ndarray]], loose: dict[int, bytes]):
    """An Arrow binary column of ``size[i]`` bytes per row (null where 0): rows ``mask`` of each
    group from its packed records (one per row, in order), the ``loose`` rows from their bytes."""
    import pyarrow as pa

    offsets = np.zeros(size.size + 1, np.int64)
    np.cumsum(size, out=offsets[1:])
    data = np.zeros(int(offsets[-1]), np.uint8)
    for rows, rec in groups:
        if rows.any():
            width = rec.dtype.itemsize
            data[offsets[:-1][rows][:, None] + np.arange(width)] = rec.view(np.uint8).reshape(-1, width)
    for i, b in loose.items():
        data[offsets[i]:offsets[i + 1]] = np.frombuffer(b, np.uint8)
    where = size > 0
    kind = pa.large_binary() if offsets[-1] >= 2**31 else pa.binary()
    width = np.int64 if kind == pa.large_binary() else np.int32
    return pa.Array.from_buffers(kind, size.size, [pa.py_buffer(np.packbits(where, bitorder="little")),
                                                   pa.py_buffer(offsets.astype(width)), pa.py_buffer(data)],
                                 null_count=int((~where).sum()))


def point_wkb(records: Records):
    """The records' points as an Arrow binary column of ISO WKB (little-endian ``Point Z`` where
    h_m is known, ``Point`` where only the horizontal position is, null where there is none: what
    shapely's ``to_wkb`` writes for :func:`point_geometries`, byte for byte), built with numpy
    without a Python object per point; and (geometry types, has Z, 2-D bounds)."""
    lon = np.asarray(records["lon_deg"], dtype=np.float64)
    lat = np.asarray(records["lat_deg"], dtype=np.float64)
    h = np.asarray(records["h_m"], dtype=np.float64) if "h_m" in records.columns else np.full(lon.shape, np.nan)
    where = np.isfinite(lon) & np.isfinite(lat)
    z = where & np.isfinite(h)
    flat = where & ~z
    size = np.where(z, _POINT_Z.itemsize, np.where(flat, _POINT_2D.itemsize, 0))
    groups = []
    for rows, dtype, kind in ((z, _POINT_Z, 1001), (flat, _POINT_2D, 1)):
        rec = np.zeros(int(rows.sum()), dtype)
        rec["order"], rec["kind"], rec["x"], rec["y"] = 1, kind, lon[rows], lat[rows]
        if kind == 1001:
            rec["z"] = h[rows]
        groups.append((rows, rec))
    column = _binary_column(size, groups, {})
    gtypes = sorted({"Point"} if flat.any() else set()) + (["Point Z"] if z.any() else [])
    bounds = ([float(lon[where].min()), float(lat[where].min()), float(lon[where].max()), float(lat[where].max())]
              if where.any() else [math.nan] * 4)
    return column, gtypes, bool(z.any()), bounds


def ring_wkb(rings: np.ndarray, simple: np.ndarray, others: np.ndarray) -> WKBColumn:
    """Polygons as ISO WKB: rows ``simple`` from ``rings`` (m, k, 3): one closed ring of k points
    (lon, lat, h) each, written as little-endian ``Polygon Z`` with numpy (what shapely writes for
    ``shapely.polygons(rings)``, byte for byte); the other rows from the shapely geometries
    ``others`` (None: no geometry)."""
    import shapely

    m, k = rings.shape[:2]
    dtype = np.dtype([("order", "u1"), ("kind", "<u4"), ("rings", "<u4"), ("points", "<u4"), ("xyz", "<f8", (k, 3))])
    rec = np.zeros(int(simple.sum()), dtype)
    rec["order"], rec["kind"], rec["rings"], rec["points"], rec["xyz"] = 1, 1003, 1, k, rings[simple]
    rest = np.flatnonzero(~simple & ~shapely.is_missing(others))
    loose = {}
    if rest.size:
        geoms = others[rest]
        zs = shapely.has_z(geoms)
        loose = dict(zip(rest.tolist(), shapely.to_wkb(geoms, output_dimension=3, flavor="iso").tolist(),
                         strict=True))
    size = np.zeros(m, np.int64)
    size[simple] = dtype.itemsize
    size[rest] = [len(b) for b in loose.values()]
    types = {"Polygon Z"} if simple.any() else set()
    bounds = np.full((0, 4), np.nan)
    if simple.any():
        lon, lat = rings[simple][..., 0], rings[simple][..., 1]
        bounds = np.array([[lon.min(), lat.min(), lon.max(), lat.max()]])
    if rest.size:
        kinds = shapely.get_type_id(geoms)
        types |= {GEOMETRY_TYPES[int(t)] + (" Z" if z else "") for t, z in zip(kinds, zs, strict=True)}
        bounds = np.vstack([bounds, shapely.total_bounds(geoms)[None]])
    box = ([float(bounds[:, 0].min()), float(bounds[:, 1].min()), float(bounds[:, 2].max()),
            float(bounds[:, 3].max())] if len(bounds) else [math.nan] * 4)
    has_z = simple.any() or bool(rest.size and zs.any())
    return WKBColumn(_binary_column(size, [(simple, rec)], loose), sorted(types), bool(has_z), box)


def arrow_table(records: Records, *, labels: dict[str, np.ndarray] | None = None):
    """The records as a pyarrow table (no geometry): floats with nulls, integers, booleans, text.
    ``labels``: columns held as integer codes, written as the text ``labels[name][code]``; text
    columns the records also hold as codes (:attr:`Records.coded`) are written from their codes
    the same way (by Arrow's dictionary cast, without a Python string per row)."""
    import pyarrow as pa

    def from_codes(codes: np.ndarray, names) -> pa.Array:
        names = pa.array(list(names), type=pa.string())
        return pa.DictionaryArray.from_arrays(pa.array(np.asarray(codes).astype(np.int32)), names).cast(pa.string())

    def column(k: str, v: np.ndarray):
        if labels and k in labels:
            return from_codes(v, labels[k])
        if k in records.coded:
            return from_codes(records.coded[k].codes, records.coded[k].names)
        return _column(v)

    return pa.table({k: column(k, v) for k, v in records.columns.items() if k != "geometry"})


def write_geoparquet(path: str | Path, records: Records, features: list[dict] | np.ndarray | None = None) -> Path:
    """One layer as a GeoParquet file (zstd)."""
    import pyarrow.parquet as pq

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table, meta = geo_table(records, features)
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), b"geo": geo_metadata(meta)})
    pq.write_table(table, path, **parquet_options(table.schema))
    return path


def parquet_options(schema) -> dict:
    """How eoloc writes Parquet: zstd, dictionary encoding for the text columns only (ids, statuses,
    streams, times: few distinct values; on floats and WKB it costs time and gives larger files)."""
    import pyarrow as pa

    text = [f.name for f in schema if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]
    return {"compression": "zstd", "use_dictionary": text}


def geo_metadata(column: dict) -> bytes:
    """The GeoParquet file metadata (the ``geo`` key) of a file whose geometry column is ``column``."""
    return json.dumps({"version": GEOPARQUET_VERSION, "primary_column": "geometry",
                       "columns": {"geometry": column}}).encode()


class ParquetLayer:
    """One layer written a chunk at a time (a long file read in segments), each chunk a row group
    of ``folder/part-0.parquet``: GeoParquet where the chunks have geometries (its ``geo``
    metadata, geometry types, CRS and bbox over every chunk, written when it is closed), plain
    Parquet (zstd) otherwise. A chunk whose columns differ from the file's in name or type, or
    that has geometries where the file has none (or the reverse), starts the next file,
    ``part-1.parquet`` ...: every row kept, each file valid on its own. Files are written under a
    temporary name and given theirs when :meth:`close`d; memory holds one chunk. ``stem``: the
    files' names before ``-0.parquet`` (a byte range of a file: ``range-00002-part``)."""

    def __init__(self, folder: str | Path, *, stem: str = "part") -> None:
        self.folder = Path(folder)
        self.stem = stem
        self.parts: list[Path] = []
        self._writer = None
        self._tmp: Path | None = None
        self._schema = None
        self._geo: dict | None = None

    def write(self, records: Records, features: list[dict] | np.ndarray | None = None) -> None:
        import pyarrow.parquet as pq

        if not len(records):
            return
        geo = None
        if records.has_points or features is not None:
            table, geo = geo_table(records, features)
        else:
            table = arrow_table(records)
        table = table.replace_schema_metadata(None)
        if self._writer is not None and (table.schema != self._schema or (geo is None) != (self._geo is None)):
            self._finish()
        if self._writer is None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._tmp = self.folder / f".{self.stem}-{len(self.parts)}.parquet.tmp"
            self._writer = pq.ParquetWriter(self._tmp, table.schema, store_schema=False,
                                            **parquet_options(table.schema))
            self._schema, self._geo = table.schema, None if geo is None else {"types": set(), "z": False,
                                                                              "bounds": []}
        self._writer.write_table(table)
        if geo is not None:
            self._geo["types"] |= set(geo["geometry_types"])
            self._geo["z"] |= any(t.endswith(" Z") for t in geo["geometry_types"])
            if "bbox" in geo:
                self._geo["bounds"].append(geo["bbox"])

    def _finish(self) -> None:
        if self._geo is not None:
            b = np.array(self._geo["bounds"], dtype=np.float64).reshape(-1, 4)
            bbox = [*b[:, :2].min(axis=0), *b[:, 2:].max(axis=0)] if len(b) else [math.nan] * 4
            meta = column_metadata(sorted(self._geo["types"]), self._geo["z"], bbox)
            self._writer.add_key_value_metadata({"geo": geo_metadata(meta).decode()})
        self._writer.close()
        final = self.folder / f"{self.stem}-{len(self.parts)}.parquet"
        os.replace(self._tmp, final)
        self.parts.append(final)
        self._writer = None

    def close(self) -> list[Path]:
        """Finish the files; their paths (none for a layer that had no row)."""
        if self._writer is not None:
            self._finish()
        return self.parts

    def abort(self) -> None:
        """Drop the file being written (an error before :meth:`close`)."""
        if self._writer is not None:
            self._writer.close()
            self._tmp.unlink(missing_ok=True)
            self._writer = None


def _without_nul(table):
    """The table with NUL characters in its text replaced by U+FFFD: GDAL hands text to SQLite as C
    strings, which would end at the NUL and silently lose the rest of the value."""
    import pyarrow as pa

    from . import arrowfn

    for k, name in enumerate(table.column_names):
        col = table.column(k)
        if pa.types.is_string(col.type) and arrowfn.any_true(arrowfn.matches(col, "\x00")):
            table = table.set_column(k, name, arrowfn.replace_all(col, "\x00", "\ufffd"))
    return table


def write_gpkg(path: str | Path, records: Records, features: list[dict] | None = None, *, layer: str) -> Path:
    """One layer as a GeoPackage (GDAL through pyogrio); the file is replaced."""
    import pyogrio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table, meta = geo_table(records, features)
    if path.exists():
        path.unlink()
    table = _without_nul(table)
    kinds = {t.removesuffix(" Z") for t in meta["geometry_types"]}
    gtype = "Unknown" if len(kinds) != 1 else next(iter(kinds)) + (" Z" if any(" Z" in t for t in meta[
        "geometry_types"]) else "")
    pyogrio.write_arrow(table, path, layer=layer, driver="GPKG", geometry_name="geometry", geometry_type=gtype,
                        crs="EPSG:4979" if meta["crs"]["id"]["code"] == 4979 else "EPSG:4326")
    return path
