"""M3 — range-free geolocation on the surface of constant ellipsoidal height ([Q] §2.2, exact)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..geodesy import WGS84
from ..kernels.core import STOP_ELLIPSOID
from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from .base import KernelRule


@dataclass(frozen=True)
class AtHeight(KernelRule):
    """M3: the first point along each ray whose geodetic height is ``h_m`` (ellipsoidal m).

    [Q] intersects the ray with the inflated ellipsoid (a + h, b + h), which is not the surface of
    geodetic height h (1.4e-6 |h| off). eoloc starts there and certifies the answer. Geodetic
    height along a line is convex, so a crossing where the ray descends is the first one. A point
    within 1 µm of the surface on a descending ray is certain. Anything else is decided exactly
    by Newton steps from the camera side, which never overshoot the first crossing
    (``eoloc.kernels.core.ellipsoid_exact``).

    Validity domain (the same on both backends): target heights from -100 km to +10 000 km; the
    camera above the surface (on it, to 1 µm, or below it: BELOW_SURFACE, never a point); only
    the near crossing; near-tangent rays decided to the contract (a point only on the surface to
    < 1 mm, and only if the ray reaches it); a ray that misses or points away gets
    NO_INTERSECTION. Monte Carlo perturbs the height by the budget's ``terrain_m`` source.
    """

    h_m: ArrayLike = 0.0

    name = "height"
    error_sources = ("terrain_m",)
    kernel = "stop_at_ellipsoid"
    value_field = "h_m"
    scalar_kind = STOP_ELLIPSOID

    def ground_height(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> np.ndarray:
        return np.broadcast_to(self.h_m, np.broadcast_shapes(np.shape(lat_deg), np.shape(lon_deg), np.shape(self.h_m)))


def stop_at_ellipsoid(rays: Rays, height_m: ArrayLike = 0.0, *, sensor: SensorModel | None = None) -> Fixes:
    """First point along each ray at ellipsoidal height ``height_m`` (m)."""
    return AtHeight(height_m).stop(rays, WGS84 if sensor is None else sensor.ellipsoid)


def locate_ellipsoid(sensor: SensorModel, pose: Pose, height_m: ArrayLike = 0.0,
                     pixels: ArrayLike | None = None) -> Fixes:
    """M3: pixels (default: principal point) of ``pose`` to the ground at ellipsoidal height ``height_m``."""
    return AtHeight(height_m).locate(sensor, pose, pixels)
