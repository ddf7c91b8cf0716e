"""The GeoJSON writer for point layers: fix records to a FeatureCollection, a million fixes in
well under a second.

One Feature per line, in the records' order: a Point (longitude, latitude, ellipsoidal height)
where the status is OK, else a null geometry; every column but lat_deg/lon_deg a property.
Numbers are written as the CSV writes them (angles to 9 decimals, < 0.1 mm, other numbers to 4,
each in its shortest form, a column of whole numbers as integers; RFC 7946 §11.2 asks for no more
precision than the data has); no value, NaN or infinity: null. Keys and text as Python's json
module writes them (ASCII, escaped). Each line is a row of :mod:`eoloc.io.rows` specs, rendered
on two threads, so no feature is ever a dict.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from . import rows
from .csvfile import compiled_floats, decimals, fits_int64, rounded_to, whole_column
from .records import Coded, Records

_POINT = b'{"type": "Point", "coordinates": ['


def write_fix_geojson(path: str | Path, records: Records, *, chunk: int | None = None) -> Path:
    """GeoJSON FeatureCollection of fix records (lat_deg, lon_deg, h_m, status and any other
    columns); failed fixes have a null geometry. ``chunk``: rows per rendering call (default
    :data:`eoloc.io.rows.CHUNK`)."""
    recs = Records.of(records)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as fh:
        fh.write(b'{"type": "FeatureCollection", "features": [')
        if len(recs):
            columns = _feature_columns(recs)

            def render(start: int, stop: int) -> bytes:
                return rows.render(start, stop - start, [c.spec(start, stop) for c in columns])

            rows.write_chunks(fh, len(recs), render, chunk or rows.CHUNK)
            fh.seek(-1, 2)  # the last feature's comma
        fh.write(b"\n]}\n")
    return path


def _feature_columns(recs: Records) -> list:
    """The specs of one Feature line: '\\n{"type": "Feature", "geometry": ' Point or null,
    ', "properties": {' the columns '}},'."""
    cols = recs.columns
    n = len(recs)
    status = recs.coded.get("status")
    if status is not None:
        ok = (status.names == "OK")[status.codes]
    elif "status" in cols:
        ok = np.asarray(cols["status"] == "OK", dtype=bool)
    else:
        ok = np.zeros(n, dtype=bool)
    point = [np.asarray(cols[k], dtype=np.float64) if k in cols else np.full(n, np.nan)
             for k in ("lon_deg", "lat_deg", "h_m")]
    ok = ok & np.isfinite(point[0]) & np.isfinite(point[1]) & np.isfinite(point[2])
    lon, lat, h = (np.where(ok, v, np.nan) for v in point)
    out: list = [_Const(b'\n{"type": "Feature", "geometry": '),
                 _Numbers(lon, 9, False, _POINT, b", ", b"null"), _Numbers(lat, 9, False, b"", b", ", b""),
                 _Numbers(h, 4, False, b"", b"]}", b""), _Const(b', "properties": {')]
    names = [k for k in cols if k not in ("lat_deg", "lon_deg")]
    for i, k in enumerate(names):
        key = (", " if i else "") + json.dumps(k) + ": "
        out.append(_property(k, np.asarray(cols[k]), recs.coded.get(k), key.encode()))
    out.append(_Const(b"}},"))
    return out


def _property(name: str, v: np.ndarray, coded: Coded | None, key: bytes):
    if coded is not None:
        return _Coded(coded.codes, [key + json.dumps(x).encode() for x in coded.names.tolist()])
    if v.dtype.kind == "b":
        return _Coded(v.view(np.int8), [key + b"false", key + b"true"])
    if v.dtype.kind in "iu" and fits_int64(v):
        return _Ints(np.ascontiguousarray(v, dtype=np.int64), key)
    if v.dtype.kind == "f":
        v = np.where(np.isinf(v), np.nan, v.astype(np.float64))  # JSON has no infinity: null
        d = decimals(name)
        return _Numbers(v, d, whole_column(v, d), key, b"", key + b"null")
    index: dict = {}  # text (or anything else): coded here, each distinct value written once
    codes = np.fromiter((index.setdefault(_json_key(x), len(index)) for x in v.tolist()), dtype=np.int64, count=len(v))
    return _Coded(codes, [key + json.dumps(x).encode() for x in (k[1] for k in index)])


def _json_key(x):
    """A value as a dict key that keeps 1, 1.0 and True apart: numpy scalars as Python ones, NaN
    and infinity as None (null)."""
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        x = None
    return type(x).__name__, x


class _Const:
    def __init__(self, text: bytes) -> None:
        self.text = text

    def spec(self, start: int, stop: int) -> tuple:
        return 0, self.text


class _Ints:
    def __init__(self, v: np.ndarray, key: bytes) -> None:
        self.v, self.key = v, key

    def spec(self, start: int, stop: int) -> tuple:
        return 2, self.v, self.key, b""


class _Coded:
    def __init__(self, codes: np.ndarray, names: list[bytes]) -> None:
        codes = np.ascontiguousarray(codes)
        self.codes = codes if codes.dtype.kind == "i" else codes.astype(np.int64)
        self.offsets = np.cumsum([0] + [len(x) for x in names], dtype=np.int32)
        self.data = b"".join(names)

    def spec(self, start: int, stop: int) -> tuple:
        return 3, self.codes, self.offsets, self.data


class _Numbers:
    """A float column between prefix and suffix, NaN: ``empty``; past what csvrows writes itself
    (a rounded number of more than 15 digits), its cells through orjson, chunk by chunk."""

    def __init__(self, v: np.ndarray, decimals: int, whole: bool, prefix: bytes, suffix: bytes, empty: bytes) -> None:
        self.v, self.decimals, self.whole = v, decimals, whole
        self.prefix, self.suffix, self.empty = prefix, suffix, empty
        self.floats = compiled_floats(v, decimals)

    def spec(self, start: int, stop: int) -> tuple:
        if self.floats is not None:
            return 1, self.floats, self.decimals, self.whole, self.prefix, self.suffix, self.empty
        import orjson
        import pyarrow as pa

        r = rounded_to(self.v[start:stop], self.decimals)
        cells = [self.empty if x != x else self.prefix + (str(int(x)).encode() if self.whole else orjson.dumps(x))
                 + self.suffix for x in r.tolist()]
        arr = pa.array(cells, type=pa.binary())
        validity, offsets, data = arr.buffers()
        return 4, offsets, b"" if data is None else data, validity, arr.offset
