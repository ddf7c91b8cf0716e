"""The oracle's first crossing of a pixel's ray with a real DEM tile (no eoloc code): the ray from
oracle_lib (scipy rotations, pyproj), the tile read by rasterio into oracle_lib's Grid (bilinear,
its heights taken as ellipsoidal), the first sample under the terrain found by the oracle's own
walk, then bisection to < 0.1 mm."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import oracle_lib as O

import eoloc

TILE = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"


def tile_grid(path=TILE) -> O.Grid:
    z, lat0, lon0, dlat, dlon = O.real_tile(path, voids=0)
    return O.Grid(z, lat0, lon0, dlat, dlon)


def ground(grid: O.Grid, lat: float, lon: float) -> float:
    return float(grid.sample(np.array([lat]), np.array([lon]))[0][0])


def first_crossing(grid: O.Grid, cam: O.Camera, lat, lon, h, yaw, pitch, roll, u, v) -> np.ndarray:
    """(lat, lon, h) where the ray of pixel (u, v) from a camera whose attitude is (yaw, pitch, roll)
    (az-el gimbal at zero) first meets the tile; an AssertionError when it never does."""
    o, d, _ = O.rays(cam, "az-el", lat, lon, h, yaw, pitch, roll, 0.0, 0.0, 0.0, np.array([u]), np.array([v]))
    o, d = o.reshape(1, 3), d.reshape(1, 3)
    event, s = O.dem_first_event(o, d, grid)
    assert event[0] == 0, "the ray does not meet the tile"

    def gap(x):
        p = o[0] + x * d[0]
        la, lo, hh = O.geodetic(p[None])
        return float(hh[0] - grid.sample(np.atleast_1d(la), np.atleast_1d(lo))[0][0])

    lo_s, hi_s = s[0] - grid.cell_m, s[0]
    assert gap(lo_s) > 0 > gap(hi_s)
    for _ in range(80):
        mid = 0.5 * (lo_s + hi_s)
        lo_s, hi_s = (mid, hi_s) if gap(mid) > 0 else (lo_s, mid)
    return np.array(O.geodetic((o[0] + lo_s * d[0])[None])).ravel()
