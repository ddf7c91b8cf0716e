"""M3 — range-free geolocation on the surface of constant ellipsoidal height ([Q] §2.2, exact).

[Q] intersects the ray with the inflated ellipsoid (a + h, b + h); that is not the surface of
geodetic height h (1.4 cm off at 10 km), so eoloc refines along the ray by Newton steps until the
point's geodetic height equals h (< 1 µm in practice; tested < 1 mm). A ray above the horizon or
pointing away gets NO_INTERSECTION and NaN, never the nearest point on the ray.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from ._common import stop


def stop_at_ellipsoid(rays: Rays, height_m: ArrayLike = 0.0, *, sensor: SensorModel | None = None) -> Fixes:
    """First point along each ray at ellipsoidal height ``height_m`` (m)."""
    return stop("stop_at_ellipsoid", rays, height_m, *(() if sensor is None else (sensor.ellipsoid,)))


def locate_ellipsoid(sensor: SensorModel, pose: Pose, height_m: ArrayLike = 0.0,
                     pixels: ArrayLike | None = None) -> Fixes:
    """M3: pixels (default: principal point) of ``pose`` to the ground at ellipsoidal height ``height_m``."""
    return stop_at_ellipsoid(sensor.rays(pose, pixels), height_m, sensor=sensor)
