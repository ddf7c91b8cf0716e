"""Writers: fixes to CSV and GeoJSON (every record kept; failed ones with their status and no point)."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..result import Fixes, Status

FIX_COLUMNS = ("lat_deg", "lon_deg", "h_m", "range_m", "status")


def fix_rows(fixes: Fixes, extra: Mapping[str, Sequence] | None = None,
             after: Mapping[str, Sequence] | None = None) -> list[dict]:
    """One dict per target: the ``extra`` columns first (ids, times, pixels), then the fix, then
    the ``after`` columns (e.g. its uncertainty)."""
    extra = dict(extra or {})
    after = dict(after or {})
    n = len(fixes)
    flat = {k: np.ravel(getattr(fixes, k)) for k in FIX_COLUMNS}
    rows = []
    for i in range(n):
        row = {k: plain_value(v[i]) for k, v in extra.items()}
        row.update({k: plain_value(flat[k][i]) for k in FIX_COLUMNS[:-1]})
        row["status"] = Status(int(flat["status"][i])).name
        row.update({k: plain_value(v[i]) for k, v in after.items()})
        rows.append(row)
    return rows


def utc_times(time_s, origin: str | None) -> np.ndarray | None:
    """ISO 8601 UTC instants (millisecond, "Z") of times in seconds: ``origin`` "unix" (seconds since
    1970, as MISB ST 0601 sends them) or an ISO 8601 instant that time_s = 0 stands for; None when
    no origin is known (relative times are never dressed up as dates). Unknown times give None."""
    if origin is None:
        return None
    from datetime import UTC, datetime, timedelta

    t0 = (datetime(1970, 1, 1, tzinfo=UTC) if origin == "unix" else
          datetime.fromisoformat(origin.replace("Z", "+00:00")).astimezone(UTC))
    t = np.asarray(time_s, dtype=np.float64)
    out = np.full(t.shape, None, dtype=object)
    for i in np.flatnonzero(np.isfinite(t)):
        out[i] = (t0 + timedelta(seconds=float(t[i]))).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
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


def plain_value(v):
    """A numpy scalar as a plain Python value; NaN as None (an empty cell / JSON null)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """CSV with a header; empty cells where there is no value. Angles with 9 decimals (< 0.1 mm)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fields = list(rows[0]) if rows else list(FIX_COLUMNS)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for row in rows:
            w.writerow({k: _fmt(k, v) for k, v in row.items()})
    return path


def _fmt(key: str, v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.9f}" if key.endswith("_deg") else f"{v:.4f}"
    return v


def fix_features(rows: list[dict]) -> list[dict]:
    """GeoJSON Point features of fix rows (RFC 7946: lon, lat, h); failed fixes have a null geometry."""
    features = []
    for row in rows:
        props = {k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}
        ok = row.get("status") == "OK"
        geom = {"type": "Point", "coordinates": [row["lon_deg"], row["lat_deg"], row["h_m"]]} if ok else None
        features.append({"type": "Feature", "geometry": geom, "properties": props})
    return features


def write_geojson(path: str | Path, rows: list[dict]) -> Path:
    """GeoJSON FeatureCollection of fix rows; failed fixes have a null geometry."""
    return write_feature_collection(path, fix_features(rows), indent=1)


def write_feature_collection(path: str | Path, features: list[dict], indent: int | None = None) -> Path:
    """Write GeoJSON features as a FeatureCollection (creating the folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=indent) + "\n",
                    encoding="utf-8")
    return path
