"""Writers: fixes to CSV and GeoJSON (every record kept; failed ones with their status and no point)."""

from __future__ import annotations

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
    if not ms.size:
        return np.zeros(ms.shape, dtype=object)
    flat = ms.ravel()
    change = np.empty(flat.size, bool)
    change[0] = True
    np.not_equal(flat[1:], flat[:-1], out=change[1:])
    first = np.flatnonzero(change)  # one string per run of one instant (a packet's targets)
    text = np.datetime_as_string(flat[first].astype("datetime64[ms]"), unit="ms", timezone="UTC").astype(object)
    out = np.repeat(text, np.diff(first, append=flat.size)).reshape(ms.shape)
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


def fix_features(records: Records | Sequence[Mapping]) -> list[dict]:
    """GeoJSON Point features of fix records (RFC 7946: lon, lat, h); failed fixes have a null geometry."""
    return [_point_feature(row) for row in Records.of(records).rows()]


def _point_feature(row: dict) -> dict:
    props = {k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}
    ok = row.get("status") == "OK"
    geom = {"type": "Point", "coordinates": [row["lon_deg"], row["lat_deg"], row["h_m"]]} if ok else None
    return {"type": "Feature", "geometry": geom, "properties": props}


def write_feature_collection(path: str | Path, features: list[dict], indent: int | None = None) -> Path:
    """Write GeoJSON features as a FeatureCollection (creating the folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=indent) + "\n",
                    encoding="utf-8")
    return path
