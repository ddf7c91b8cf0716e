"""M2 — many targets from one ranged target on flat local ground ([Z15]).

The main target (by default at the image centre) is located by its laser range (M1). The ground is
taken as the plane through it perpendicular to the local down there. With s the main ray and t_k
the ray of target k (unit, ECEF) and d the down direction:
    H = range_main * (s . d)        height of the camera above the plane, along d
    range_k = H / (t_k . d)         range of target k; target = P0 + range_k t_k
This is the direct projection SPEC §3 asks for ([Z15]'s cos sigma = (tr R - 1) / 2 holds only in
special cases). eoloc takes d at the main target rather than at the aircraft: the plane is then
tangent to the constant-height surface where the targets are, so Earth curvature costs
(distance from the main target)^2 / 2R (0.8 mm at 100 m) instead of centimetres.
Rays at or above the plane's horizon get NO_INTERSECTION.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..geodesy import R_ecef_ned
from ..result import Fixes, Status, with_status
from ..sensor.model import Pose, SensorModel
from ._common import stop
from .ranged import stop_at_range


def locate_flat(sensor: SensorModel, pose: Pose, main_range_m: ArrayLike, pixels: ArrayLike | None = None, *,
                main_pixel: ArrayLike | None = None) -> Fixes:
    """M2: targets at ``pixels`` on the flat ground through the main target at ``main_pixel``
    (default: the principal point) whose slant range is ``main_range_m`` (m).

    Pose fields and ``main_range_m`` broadcast against the pixels like every stop rule (F frames
    of K targets: pose fields and ranges (F, 1), pixels (F, K)).
    """
    main_rays = sensor.rays(pose, main_pixel)
    main = stop_at_range(main_rays, main_range_m, sensor=sensor)
    down = R_ecef_ned(main.lat_deg, main.lon_deg)[..., :, 2]  # NaN where the main fix failed
    cos_main = (main_rays.dir_ecef * down).sum(-1)
    height_above_plane = np.asarray(main.range_m) * cos_main
    rays = sensor.rays(pose, pixels)
    cos_k = (rays.dir_ecef * down).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rng = np.where(cos_k > 0, height_above_plane / cos_k, np.inf)  # inf: parallel or away
    fixes = stop("stop_at_range", rays, rng, sensor.ellipsoid)
    return with_status(fixes, np.isinf(rng) & np.isfinite(height_above_plane), Status.NO_INTERSECTION)
