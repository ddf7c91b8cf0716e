"""M1 — ranged geolocation ([S13], [Z15]): the target is at the laser slant range along the ray."""

from __future__ import annotations

from numpy.typing import ArrayLike

from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from ._common import stop


def stop_at_range(rays: Rays, range_m: ArrayLike, *, sensor: SensorModel | None = None) -> Fixes:
    """Point at ``range_m`` (m, > 0) along each ray. NaN/negative/zero range -> INVALID_INPUT."""
    return stop("stop_at_range", rays, range_m, *(() if sensor is None else (sensor.ellipsoid,)))


def locate_range(sensor: SensorModel, pose: Pose, range_m: ArrayLike, pixels: ArrayLike | None = None) -> Fixes:
    """M1: pixels (default: principal point) of ``pose`` to ground with a measured slant range (m).

    The range is measured from the camera origin (lever arm applied) along the pixel's ray; a
    laser range finder boresighted with the camera gives the range of the image centre.
    """
    return stop_at_range(sensor.rays(pose, pixels), range_m, sensor=sensor)
