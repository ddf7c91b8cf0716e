"""Stop rules: where a ray ends. Each takes Rays (or a sensor, a pose and pixels) -> Fixes."""

from .ellipsoid import locate_ellipsoid, stop_at_ellipsoid
from .flat import locate_flat
from .ranged import locate_range, stop_at_range
from .terrain import locate_dem, stop_at_dem

__all__ = [
    "locate_dem",
    "locate_ellipsoid",
    "locate_flat",
    "locate_range",
    "stop_at_dem",
    "stop_at_ellipsoid",
    "stop_at_range",
]
