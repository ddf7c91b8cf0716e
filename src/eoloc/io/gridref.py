"""Grid references beside latitude/longitude, on request (``--grid mgrs``, ``--grid utm``).

- ``mgrs``: the Military Grid Reference System string at 1 m (e.g. ``13TDE4490045400``): the UTM
  zone (Norway and Svalbard exceptions) and latitude band, the 100 km square's letters (the
  "AA" lettering WGS-84 uses: columns A-H / J-R / S-Z by zone, rows A-V offset by 5 in even zones)
  and the easting and northing within it *truncated* to the metre, as MGRS requires (the ``mgrs``
  package rounded: 1 m off within half a millimetre of a grid line); from pyproj's UTM, vectorised;
  tested against GeographicLib's GeoConvert; none beyond 84°N / 80°S (UPS) or for a failed fix.
- ``utm``: ``utm_zone`` (e.g. ``13N``), ``utm_easting_m``, ``utm_northing_m`` in the zone of each
  point (pyproj, one transformer per zone present; UPS is not used: none beyond 84°N/80°S).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from .records import Records

GRIDS = ("mgrs", "utm")


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


BANDS = "CDEFGHJKLMNPQRSTUVWX"  # 8° latitude bands from 80°S; X is 12° (72°N to 84°N)
COLUMN_SETS = ("STUVWXYZ", "ABCDEFGH", "JKLMNPQR")  # by zone number mod 3
ROWS = "ABCDEFGHJKLMNPQRSTUV"


def mgrs_column(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """MGRS strings at 1 m (see the module), None where there is none."""
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    utm = utm_columns(lat, lon)
    zone = utm_zone_numbers(lat, lon)
    e, n = utm["utm_easting_m"], utm["utm_northing_m"]
    out = np.full(lat.shape, None, dtype=object)
    with np.errstate(invalid="ignore"):
        ok = (zone > 0) & np.isfinite(e) & np.isfinite(n) & (lat <= 84.0)
    if not ok.any():
        return out
    z = zone[ok]
    ei = np.floor(e[ok]).astype(np.int64)  # truncated, not rounded
    ni = np.floor(n[ok]).astype(np.int64)
    band = np.minimum(((lat[ok] + 80.0) // 8.0).astype(np.int64), 19)
    col = np.array([list(c) for c in COLUMN_SETS])[z % 3, ei // 100_000 - 1]
    row = np.array(list(ROWS))[(ni // 100_000 + np.where(z % 2 == 0, 5, 0)) % 20]
    bands = np.array(list(BANDS))[band]
    out[ok] = [f"{a:02d}{b}{c}{r}{x:05d}{y:05d}" for a, b, c, r, x, y in
               zip(z.tolist(), bands.tolist(), col.tolist(), row.tolist(), (ei % 100_000).tolist(),
                   (ni % 100_000).tolist(), strict=True)]
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
