"""Writers: fixes to CSV and GeoJSON (every record kept; failed ones with their status and no point)."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..result import Fixes, Status
from .records import Coded, Records

FIX_COLUMNS = ("lat_deg", "lon_deg", "h_m", "range_m", "status")


STATUS_NAMES = np.array([None] * (max(Status) + 1), dtype=object)
for _s in Status:
    STATUS_NAMES[_s] = _s.name


def fix_records(fixes: Fixes, extra: Mapping[str, Sequence] | None = None,
                after: Mapping[str, Sequence] | None = None, *, status_codes: bool = False,
                coded: Mapping[str, Coded] | None = None) -> Records:
    """The fixes as records: the ``extra`` columns first (ids, times, pixels), then the fix
    (lat_deg, lon_deg, h_m, range_m, status by name), then the ``after`` columns (e.g. its
    uncertainty). ``status_codes``: the status as its int8 code instead of its name (for a
    writer that names it from :data:`STATUS_NAMES` itself, e.g. ``geotable.arrow_table``'s
    ``labels``); else the names, also coded. ``coded``: extra columns held as codes too (ids
    as read, see :attr:`eoloc.io.table.Table.coded`)."""
    cols = {k: np.asarray(v).ravel() for k, v in (extra or {}).items()}
    cols.update({k: np.ravel(getattr(fixes, k)).astype(np.float64, copy=False) for k in FIX_COLUMNS[:-1]})
    codes = np.ravel(fixes.status)
    cols["status"] = codes.astype(np.int8) if status_codes else STATUS_NAMES[codes.astype(np.intp)]
    cols.update({k: np.asarray(v).ravel() for k, v in (after or {}).items()})
    coded = dict(coded or {})
    if not status_codes:
        coded["status"] = Coded(codes.astype(np.int8), STATUS_NAMES)
    return Records(cols, coded)


def utc_times(time_s, origin: str | None) -> np.ndarray | None:
    """ISO 8601 UTC instants (millisecond, "Z") of times in seconds: ``origin`` "unix" (seconds since
    1970, as MISB ST 0601 sends them) or an ISO 8601 instant that time_s = 0 stands for; None when
    no origin is known (relative times are never dressed up as dates). Unknown times give None."""
    if origin is None:
        return None
    from datetime import UTC, datetime

    t0_ms = 0
    if origin != "unix":
        t0 = datetime.fromisoformat(origin.replace("Z", "+00:00"))
        t0_ms = round((t0 if t0.tzinfo else t0.replace(tzinfo=UTC)).timestamp() * 1000)
    t = np.asarray(time_s, dtype=np.float64)
    ok = np.isfinite(t) & (np.abs(t) < 1e13)
    ms = np.where(ok, np.floor(np.where(ok, t, 0.0) * 1000.0 + 1e-6), 0).astype(np.int64) + t0_ms
    out = (np.datetime_as_string(ms.astype("datetime64[ms]"), unit="ms").astype(object) + "Z")
    out[~ok] = None
    return out


def with_utc(extra: Mapping[str, Sequence], origin: str | None) -> dict:
    """``extra`` with a ``time_utc`` column after ``time_s`` when the clock's origin is known."""
    extra = dict(extra)
    iso = utc_times(extra["time_s"], origin) if "time_s" in extra else None
    if iso is None:
        return extra
    out = {}
    for k, v in extra.items():
        out[k] = v
        if k == "time_s":
            out["time_utc"] = iso
    return out


def json_safe(v):
    """Plain JSON values through dicts and lists: numpy scalars as Python ones, and NaN or
    infinity as None (null), which JSON has no other way to say."""
    if isinstance(v, dict):
        return {k: json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def json_column(a, keep: np.ndarray | None = None) -> list:
    """An array as a JSON list: NaN, infinity and (where ``keep`` is False) anything as None."""
    a = np.asarray(a, dtype=np.float64)
    bad = ~np.isfinite(a) if keep is None else ~(np.isfinite(a) & keep)
    out = a.astype(object)
    out[bad] = None
    return out.tolist()


CSV_CHUNK = 1 << 15  # rows rendered per pyarrow call (two at a time, one per core)


def write_csv(path: str | Path, records: Records | Sequence[Mapping]) -> Path:
    """CSV with a header; empty cells where there is no value; angles (``*_deg``) rounded to 9
    decimals (< 0.1 mm), other numbers to 4, written in their shortest form; text quoted only
    when a cell needs it (then every text cell is, and no number). Rendered by pyarrow in chunks
    on two threads; coded text columns (:class:`Coded`) render each name once."""
    import io
    from concurrent.futures import ThreadPoolExecutor

    import pyarrow as pa
    from pyarrow import csv as pacsv

    recs = Records.of(records)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = recs.names or list(FIX_COLUMNS)
    text = {k: _csv_array(k, v) for k, v in recs.columns.items() if v.dtype == object and k not in recs.coded}
    coded = {k: pa.array(c.names.tolist(), type=pa.string()) for k, c in recs.coded.items()}
    in_use = [pa.array(c.names[np.bincount(c.codes, minlength=len(c.names)) > 0].tolist(), type=pa.string())
              for c in recs.coded.values()]
    # a cell to quote makes pyarrow quote every text cell: numbers then stay numbers
    quote = any(_needs_quotes(a) for a in [*text.values(), *in_use])
    options = pacsv.WriteOptions(include_header=False, quoting_style="needed" if quote else "none")
    # float columns of whole numbers (frames, times, heights) are written as integers, the whole
    # column alike (its first chunk decides for most columns: one with a fraction is not whole)
    whole = {k for k, v in recs.columns.items()
             if v.dtype.kind == "f" and _whole(k, v[:CSV_CHUNK]) and _whole(k, v)}

    def render(start: int) -> pa.Buffer:  # conversion, rounding and rendering of one chunk
        part = recs.slice(start, start + CSV_CHUNK)
        table = pa.table({k: pa.DictionaryArray.from_arrays(arrow_ints(part.coded[k].codes), coded[k]) if k in coded
                          else text[k].slice(start, CSV_CHUNK) if k in text
                          else _csv_array(k, v, numbers_as_text=not quote, whole=k in whole)
                          for k, v in part.columns.items()})
        sink = pa.BufferOutputStream()
        pacsv.write_csv(table, sink, options)
        return sink.getvalue()

    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow(names)
    with path.open("wb") as fh:
        fh.write(header.getvalue().encode("utf-8"))
        if len(recs):
            with ThreadPoolExecutor(2) as pool:
                for chunk in pool.map(render, range(0, len(recs), CSV_CHUNK)):
                    fh.write(chunk)
    return path


def _decimals(name: str) -> int:
    return 9 if name.endswith("_deg") else 4


def _whole(name: str, v: np.ndarray) -> bool:
    """Whether a float column, rounded as written, holds only whole numbers (or no value) that
    int64 writes exactly."""
    r = np.round(v[~np.isnan(v)], _decimals(name))
    return bool((np.abs(r) < 2.0**53).all() and (r == np.trunc(r)).all())  # an infinity is not whole


def _csv_array(name: str, v: np.ndarray, numbers_as_text: bool = True, whole: bool = False):
    """One column as pyarrow renders it in CSV: numbers rounded (no value: empty), booleans as
    True/False, anything else as text. ``numbers_as_text``: numbers made text by
    :func:`number_text` (else pyarrow formats them: slower, but unquoted where text is quoted);
    ``whole``: a float column of whole numbers, written as integers ("17", not "17.0")."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if v.dtype.kind == "f":
        nan = np.isnan(v)
        if not numbers_as_text or np.isinf(v).any():  # JSON, so orjson, has no infinity
            return pc.round(pa.array(v, mask=nan), _decimals(name))
        if nan.all():
            return pa.nulls(len(v), pa.string())
        rounded = np.round(v, _decimals(name))
        if whole:
            rounded = np.where(nan, 0.0, rounded).astype(np.int64)
        return number_text(rounded, nan if nan.any() else None)
    if v.dtype.kind in "iu":
        return number_text(v) if numbers_as_text else pa.array(v)
    if v.dtype.kind == "b":
        return pa.DictionaryArray.from_arrays(arrow_ints(v.astype(np.int8)), pa.array(["False", "True"]))
    try:  # text and None (ids, status, ISO times): straight through pyarrow
        return pa.array(v, type=pa.string(), from_pandas=True)
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        pass
    cells = [None if x is None or (isinstance(x, float) and math.isnan(x)) else
             (_fmt(name, x) if isinstance(x, (float, bool, np.generic)) else str(x)) for x in v.tolist()]
    return pa.array(cells, type=pa.string())


def arrow_ints(codes: np.ndarray):
    """A 1-D numpy integer array as a pyarrow array, sharing its memory (``pa.array`` on numpy
    input imports numpy.ma to look for masks: 25 ms)."""
    import pyarrow as pa

    codes = np.ascontiguousarray(codes)
    return pa.Array.from_buffers(pa.from_numpy_dtype(codes.dtype), len(codes), [None, pa.py_buffer(codes)])


def number_text(v: np.ndarray, missing: np.ndarray | None = None):
    """Finite numbers (float or int) as a pyarrow string array in their shortest round-trip
    form (``missing``: cells left empty); one value throughout (a height surface's h_m) as a
    dictionary of that one text. orjson's Ryu formatting (3x faster than pyarrow's float cast,
    the same digits), cut into cells by pyarrow's split (GIL released)."""
    import orjson
    import pyarrow as pa
    import pyarrow.compute as pc

    v = np.ascontiguousarray(v, dtype=np.float64 if v.dtype.kind == "f" and v.itemsize < 4 else None)  # orjson's
    if len(v) == 0:
        return pa.array([], type=pa.string())
    if missing is None and len(v) > 1 and v[0] == v[-1] and bool((v == v[0]).all()):
        one = orjson.dumps(v[:1], option=orjson.OPT_SERIALIZE_NUMPY).decode()[1:-1]
        return pa.DictionaryArray.from_arrays(arrow_ints(np.zeros(len(v), dtype=np.int8)), pa.array([one]))
    raw = orjson.dumps(v, option=orjson.OPT_SERIALIZE_NUMPY)  # b"[a,b,c]": ASCII
    size = len(raw) - 2
    large = size >= 2**31  # 32-bit offsets hold up to 2 GB of text
    whole = pa.Array.from_buffers(pa.large_string() if large else pa.string(), 1,
                                  [None, pa.py_buffer(np.array([0, size], dtype=np.int64 if large else np.int32)),
                                   pa.py_buffer(memoryview(raw)[1:-1])])
    cells = pc.split_pattern(whole, ",").flatten()
    if missing is None:
        return cells
    _, offsets, data = cells.buffers()
    present = np.concatenate([np.zeros(cells.offset, dtype=bool), ~missing])  # bits count from the buffers' start
    return type(cells).from_buffers(len(v), offsets, data, pa.py_buffer(np.packbits(present, bitorder="little")),
                                    offset=cells.offset)


_QUOTED = np.zeros(256, dtype=bool)
_QUOTED[[ord(c) for c in ',"\n\r']] = True  # the bytes that make CSV quote a cell


def _needs_quotes(text) -> bool:
    """Whether a pyarrow string array has a cell that CSV must quote (a comma, quote or line
    break): a look at its character bytes, whatever their cells."""
    data = text.buffers()[2]
    return data is not None and bool(_QUOTED[np.frombuffer(data, dtype=np.uint8)].any())


def _fmt(key: str, v) -> str:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return f"{v:.9f}" if key.endswith("_deg") else f"{v:.4f}"
    return str(v)


def fix_features(records: Records | Sequence[Mapping]) -> list[dict]:
    """GeoJSON Point features of fix records (RFC 7946: lon, lat, h); failed fixes have a null geometry."""
    return [_point_feature(row) for row in Records.of(records).rows()]


def _point_feature(row: dict) -> dict:
    props = {k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}
    ok = row.get("status") == "OK"
    geom = {"type": "Point", "coordinates": [row["lon_deg"], row["lat_deg"], row["h_m"]]} if ok else None
    return {"type": "Feature", "geometry": geom, "properties": props}


def write_fix_geojson(path: str | Path, records: Records, chunk: int = 65536) -> Path:
    """GeoJSON FeatureCollection of fix records, streamed in chunks (a million fixes never sit
    in memory as dicts); failed fixes have a null geometry."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8") as fh:
        fh.write('{"type": "FeatureCollection", "features": [')
        sep = "\n"
        for part in records.chunks(chunk):
            for row in part.rows():
                fh.write(sep + json.dumps(_point_feature(row), allow_nan=False))
                sep = ",\n"
        fh.write("\n]}\n")
    return path


def write_feature_collection(path: str | Path, features: list[dict], indent: int | None = None) -> Path:
    """Write GeoJSON features as a FeatureCollection (creating the folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=indent) + "\n",
                    encoding="utf-8")
    return path
