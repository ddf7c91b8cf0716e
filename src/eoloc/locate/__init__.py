"""Stop rules: where a ray ends. Each takes Rays (or a sensor, a pose and pixels) -> Fixes."""

from .ellipsoid import locate_ellipsoid, stop_at_ellipsoid
from .flat import locate_flat
from .ranged import locate_range, stop_at_range
from .terrain import locate_dem, stop_at_dem


def locate_on(sensor, pose, surface, pixels=None):
    """Fixes of ``pixels`` on ``surface``: a :class:`eoloc.DEM` (M4) or a constant ellipsoidal
    height in metres (M3) - the ground of footprints, ground grids and rectification."""
    from ..terrain.dem import DEM

    if isinstance(surface, DEM):
        return locate_dem(sensor, pose, surface, pixels)
    return locate_ellipsoid(sensor, pose, float(surface), pixels)

__all__ = [
    "locate_dem",
    "locate_ellipsoid",
    "locate_flat",
    "locate_on",
    "locate_range",
    "stop_at_dem",
    "stop_at_ellipsoid",
    "stop_at_range",
]
