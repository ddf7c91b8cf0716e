"""What every stop rule does around its kernel: run it, mask bad inputs, shape the Fixes."""

from __future__ import annotations

import numpy as np

from .._backend import run
from ..geodesy import WGS84, Ellipsoid
from ..result import Fixes, Status, mask_invalid
from ..sensor.model import Rays


def stop(kernel: str, rays: Rays, value, ell: Ellipsoid = WGS84) -> Fixes:
    """Run stop-rule ``kernel`` with its parameter ``value`` (range, height, ...) on ``rays``."""
    out = run(kernel, rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz, value, *ell.constants)
    return to_fixes(out, rays.invalid, rays.out_of_image)


def to_fixes(out, invalid, out_of_image=False) -> Fixes:
    """Kernel outputs (lat rad, lon rad, h, range, status) -> Fixes, INVALID_INPUT where ``invalid``
    (the pose could not be used), OUT_OF_IMAGE where ``out_of_image`` (the pixel is not in the image)."""
    lat, lon, h, t, st = (np.asarray(x) for x in out)
    arrays = (np.degrees(lat), np.degrees(lon), h, t, st.astype(np.int8, copy=False))
    arrays = mask_invalid(arrays, np.broadcast_to(out_of_image, st.shape), Status.OUT_OF_IMAGE)
    lat, lon, h, t, st = mask_invalid(arrays, np.broadcast_to(invalid, st.shape))
    return Fixes(*(a[()] if a.ndim == 0 else a for a in (lat, lon, h, t, st)))
