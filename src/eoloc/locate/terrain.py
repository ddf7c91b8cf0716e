"""M4 — range-free geolocation on a DEM ([Q] §2.3): the first crossing of the ray with the terrain.

``method="march"`` (default): the guaranteed-first-hit march of :mod:`eoloc._march` (exact
per-cell solve, coarse skipping on numba), point on the bilinear DEM surface to < 1 cm.
``method="descent"``: [Q]'s iteration (ellipsoid at H, read the DEM, lower H by ``eps_h`` until
the terrain is above), kept for comparison: height error <= eps_h and it can land on a later
crossing than the first (see tests).
Statuses: OUT_OF_COVERAGE (the ray leaves the DEM first), DEM_VOID (it meets a no-data cell
first), NO_INTERSECTION (it never reaches the terrain), INVALID_INPUT (NaN, camera underground).
"""

from __future__ import annotations

import numpy as np

from .. import _march
from .._backend import get_backend
from ..geodesy import WGS84
from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from ..terrain.dem import DEM
from ._common import to_fixes


def stop_at_dem(rays: Rays, dem: DEM, *, method: str = "march", eps_h: float = 1.0,
                sensor: SensorModel | None = None) -> Fixes:
    """First crossing of each ray with ``dem`` (ellipsoidal heights)."""
    a, b, e2, ep2 = (sensor.ellipsoid if sensor is not None else WGS84).constants
    shape = rays.shape
    flat = [np.ascontiguousarray(np.broadcast_to(x, shape), dtype=np.float64).reshape(-1)
            for x in (rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz)]
    g = dem.grid
    hmin, hmax = dem.height_range
    if method == "descent":
        if not eps_h > 0:
            raise ValueError(f"eps_h (descent step, m) must be > 0, got {eps_h!r}")
        out = _march.descent_numpy(*flat, g.z, g.lat0, g.lon0, g.dlat, g.dlon, hmin, hmax, eps_h, a, b, e2, ep2)
    elif method == "march":
        fine, coarse, margin = _march.march_params(dem)
        if get_backend() == "numba":
            from .. import _nb

            n = flat[0].size
            out = [np.empty(n) for _ in range(4)] + [np.empty(n, dtype=np.int8)]
            _nb.terrain_march(n, *flat, g.z, dem.block_max, g.lat0, g.lon0, g.dlat, g.dlon, hmin, hmax, fine,
                              coarse, margin, a, b, e2, ep2, *out)
        else:
            out = _march.march_numpy(*flat, g.z, g.lat0, g.lon0, g.dlat, g.dlon, hmin, hmax, fine, a, b, e2, ep2)
    else:
        raise ValueError(f"unknown DEM method {method!r}; use 'march' (default) or 'descent'")
    return to_fixes([np.asarray(x).reshape(shape) for x in out], rays.invalid, rays.out_of_image)


def locate_dem(sensor: SensorModel, pose: Pose, dem: DEM, pixels=None, *, method: str = "march",
               eps_h: float = 1.0) -> Fixes:
    """M4: pixels (default: principal point) of ``pose`` to their first hit on ``dem``."""
    return stop_at_dem(sensor.rays(pose, pixels), dem, method=method, eps_h=eps_h, sensor=sensor)
