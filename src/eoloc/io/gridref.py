"""Grid references beside latitude/longitude, on request (``--grid mgrs``, ``--grid utm``).

- ``mgrs``: the Military Grid Reference System string at 1 m (e.g. ``13TDE4490045400``), from
  the ``mgrs`` package (GeoTrans's conversion); none outside its latitude range or for a failed fix.
- ``utm``: ``utm_zone`` (e.g. ``13N``), ``utm_easting_m``, ``utm_northing_m`` in the zone of each
  point (pyproj, one transformer per zone present; UPS is not used: none beyond 84°N/80°S).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from .records import Records

GRIDS = ("mgrs", "utm")
MGRS_DIGITS = 5  # 1 m


def utm_zone_numbers(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """UTM zone numbers (1-60) with the Norway and Svalbard exceptions; 0 where none applies."""
    lon = (np.asarray(lon_deg, dtype=np.float64) + 180.0) % 360.0 - 180.0
    lat = np.asarray(lat_deg, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        zone = np.floor((lon + 180.0) / 6.0).astype(np.int64) % 60 + 1
        zone = np.where((lat >= 56) & (lat < 64) & (lon >= 3) & (lon < 12), 32, zone)
        sval = (lat >= 72) & (lat < 84)
        for lo, hi, z in ((0, 9, 31), (9, 21, 33), (21, 33, 35), (33, 42, 37)):
            zone = np.where(sval & (lon >= lo) & (lon < hi), z, zone)
        ok = np.isfinite(lat) & np.isfinite(lon) & (lat >= -80) & (lat < 84)
    return np.where(ok, zone, 0)


def utm_columns(lat_deg: np.ndarray, lon_deg: np.ndarray) -> dict[str, np.ndarray]:
    from pyproj import Transformer

    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    zone = utm_zone_numbers(lat, lon)
    east = np.full(lat.shape, np.nan)
    north = np.full(lat.shape, np.nan)
    label = np.full(lat.shape, None, dtype=object)
    south = lat < 0
    for z in np.unique(zone[zone > 0]):
        for s in (False, True):
            m = (zone == z) & (south == s)
            if not m.any():
                continue
            t = Transformer.from_crs("EPSG:4326", f"EPSG:{(32700 if s else 32600) + int(z)}", always_xy=True)
            east[m], north[m] = t.transform(lon[m], lat[m])
            label[m] = f"{int(z)}{'S' if s else 'N'}"
    return {"utm_zone": label, "utm_easting_m": east, "utm_northing_m": north}


def mgrs_column(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    import mgrs

    conv = mgrs.MGRS()
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = (np.asarray(lon_deg, dtype=np.float64) + 180.0) % 360.0 - 180.0
    out = np.full(lat.shape, None, dtype=object)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(lat) & np.isfinite(lon) & (lat >= -80) & (lat <= 84)
    for i in np.flatnonzero(ok):
        out[i] = conv.toMGRS(float(lat[i]), float(lon[i]), MGRSPrecision=MGRS_DIGITS)
    return out


def with_grid_columns(records: Records, grids: Iterable[str]) -> Records:
    """The records with the asked grid references added after lon_deg (point layers only)."""
    grids = [g for g in dict.fromkeys(grids)]
    unknown = [g for g in grids if g not in GRIDS]
    if unknown:
        raise ValueError(f"unknown grid {unknown[0]!r}: choose from {', '.join(GRIDS)}")
    if not grids or not records.has_points:
        return records
    lat, lon = records["lat_deg"], records["lon_deg"]
    extra: dict[str, np.ndarray] = {}
    if "mgrs" in grids:
        extra["mgrs"] = mgrs_column(lat, lon)
    if "utm" in grids:
        extra.update(utm_columns(lat, lon))
    out: dict[str, np.ndarray] = {}
    for k, v in records.columns.items():
        if k not in extra:
            out[k] = v
        if k == "lon_deg":
            out.update(extra)
    return Records(out, records.coded)
