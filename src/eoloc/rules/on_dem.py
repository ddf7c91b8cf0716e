"""M4 — range-free geolocation on a DEM ([Q] §2.3): the first crossing of the ray with the terrain."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..geodesy import WGS84, Ellipsoid
from ..kernels import march
from ..kernels.backend import backend, implements, in_chunks
from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from ..terrain.dem import DEM
from .base import Errors, StopRule, no_errors, to_fixes

METHODS = ("march", "descent")


@dataclass(frozen=True)
class OnDEM(StopRule):
    """M4: the first crossing of each ray with ``dem`` (ellipsoidal heights, bilinear surface).

    ``method="march"`` (default): the guaranteed-first-hit march of :mod:`eoloc.kernels.march` (an
    exact solve in each cell, coarse skipping on numba), the point on the bilinear DEM surface
    to < 1 cm. ``method="descent"``: [Q]'s iteration (ellipsoid at H, read the DEM, lower H by
    ``eps_h`` until the terrain is above), kept for comparison. Its height error is <= eps_h and
    it can land on a later crossing than the first.

    Validity domain (the same on both backends): the camera above the terrain (on or below it:
    BELOW_SURFACE); a ray that leaves the grid (any of its four edges, or towards a pole) before
    its first hit, while it is at or below the highest post: OUT_OF_COVERAGE; one that meets a
    void (no-data) cell first, at or below the highest post: DEM_VOID; no crossing:
    NO_INTERSECTION. Monte Carlo raises the whole DEM by the budget's ``terrain_m`` source.
    """

    dem: DEM
    method: str = "march"
    eps_h: float = 1.0

    name = "dem"
    error_sources = ("terrain_m",)

    def __post_init__(self) -> None:
        if not isinstance(self.dem, DEM):
            raise TypeError(f"OnDEM needs an eoloc.DEM (see eoloc.open_dem), got {type(self.dem).__name__}")
        if self.method not in METHODS:
            raise ValueError(f"unknown DEM method {self.method!r}; use 'march' (default) or 'descent'")
        if not self.eps_h > 0:
            raise ValueError(f"eps_h (descent step, m) must be > 0, got {self.eps_h!r}")

    def stop(self, rays: Rays, ell: Ellipsoid = WGS84, errors: Errors = no_errors) -> Fixes:
        shift = errors("terrain_m")
        if np.isscalar(shift) and shift == 0.0:
            return self._march(rays, ell)
        # the DEM raised by `shift`: the camera lowered by it along its local vertical instead
        # (the same geometry to shift x distance / R, ~1e-3 of the shift at 20 km)
        lat, lon, _ = geodesy.ecef_to_geodetic(rays.ox, rays.oy, rays.oz, ell=ell)
        up = -geodesy.R_ecef_ned(lat, lon)[..., :, 2]
        shape = np.broadcast_shapes(np.shape(shift), rays.shape)  # the shift may vary where nothing else does
        s = np.broadcast_to(shift, shape)
        moved = replace(rays, ox=rays.ox - s * up[..., 0], oy=rays.oy - s * up[..., 1], oz=rays.oz - s * up[..., 2],
                        dx=np.broadcast_to(rays.dx, shape), dy=np.broadcast_to(rays.dy, shape),
                        dz=np.broadcast_to(rays.dz, shape))
        f = self._march(moved, ell)
        return replace(f, h_m=f.h_m + s)

    def _march(self, rays: Rays, ell: Ellipsoid) -> Fixes:
        a, b, e2, ep2 = ell.constants
        shape = rays.shape
        flat = [np.ascontiguousarray(np.broadcast_to(x, shape), dtype=np.float64).reshape(-1)
                for x in (rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz)]
        g = self.dem.grid
        hmin, hmax = self.dem.height_range
        if self.method == "descent":
            out = march.descent_numpy(*flat, g.z, g.lat0, g.lon0, g.dlat, g.dlon, hmin, hmax, self.eps_h, a, b, e2,
                                      ep2)
        else:
            fine, coarse, margin = march.march_params(self.dem)
            out = backend().terrain_march(flat, g.z, self.dem.block_max, g.lat0, g.lon0, g.dlat, g.dlon, hmin, hmax,
                                          fine, coarse, margin, a, b, e2, ep2)
        return to_fixes([np.asarray(x).reshape(shape) for x in out], rays.invalid, rays.out_of_image)

    @property
    def terrain(self) -> DEM:
        return self.dem

    def ground_height(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> np.ndarray:
        return self.dem.height(lat_deg, lon_deg)

    def describe(self) -> str:
        w, s, e, n = self.dem.bounds
        return (f"DEM {self.dem.source or 'grid'} covering lat {s:.4f}..{n:.4f}, lon {w:.4f}..{e:.4f}"
                + ("" if self.method == "march" else f", {self.method}"))


@implements("terrain_march", "numpy")
def terrain_march_numpy(rays, z, block_max, lat0, lon0, dlat, dlon, hmin, hmax, fine, coarse, margin, a, b, e2, ep2):
    """The first crossing of each ray (``rays``: ox, oy, oz, dx, dy, dz, 1-D) with the bilinear
    DEM ``z``: (lat rad, lon rad, h, range, status) arrays (numpy:
    :func:`eoloc.kernels.march.march_numpy`, fine steps)."""
    return march.march_numpy(*rays, z, lat0, lon0, dlat, dlon, hmin, hmax, fine, a, b, e2, ep2)


@implements("terrain_march", "numba")
def terrain_march_numba(rays, z, block_max, lat0, lon0, dlat, dlon, hmin, hmax, fine, coarse, margin, a, b, e2,
                        ep2):
    """:func:`terrain_march_numpy` compiled, with coarse skipping over ``block_max``, the rays in
    contiguous slices on the kernel threads."""
    from ..kernels import compiled

    n = rays[0].size
    out = [np.empty(n) for _ in range(4)] + [np.empty(n, dtype=np.int8)]

    def part(i: int, j: int) -> None:  # one contiguous slice of the rays, on a thread of its own
        compiled.terrain_march(j - i, *(x[i:j] for x in rays), z, block_max, lat0, lon0, dlat, dlon, hmin, hmax,
                               fine, coarse, margin, a, b, e2, ep2, *(o[i:j] for o in out))

    in_chunks(n, part)
    return out


def stop_at_dem(rays: Rays, dem: DEM, *, method: str = "march", eps_h: float = 1.0,
                sensor: SensorModel | None = None) -> Fixes:
    """First crossing of each ray with ``dem`` (ellipsoidal heights)."""
    return OnDEM(dem, method, eps_h).stop(rays, WGS84 if sensor is None else sensor.ellipsoid)


def locate_dem(sensor: SensorModel, pose: Pose, dem: DEM, pixels: ArrayLike | None = None, *, method: str = "march",
               eps_h: float = 1.0) -> Fixes:
    """M4: pixels (default: principal point) of ``pose`` to their first hit on ``dem``."""
    return OnDEM(dem, method, eps_h).locate(sensor, pose, pixels)
