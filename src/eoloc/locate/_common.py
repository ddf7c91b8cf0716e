"""What every stop rule does around its kernel: run it, mask bad inputs, shape the Fixes."""

from __future__ import annotations

import numpy as np

from .._backend import run
from ..geodesy import WGS84, Ellipsoid
from ..result import Fixes, mask_invalid
from ..sensor.model import Rays


def stop(kernel: str, rays: Rays, value, ell: Ellipsoid = WGS84) -> Fixes:
    """Run stop-rule ``kernel`` with its parameter ``value`` (range, height, ...) on ``rays``."""
    out = run(kernel, rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz, value, *ell.constants)
    return to_fixes(out, rays.invalid)


def to_fixes(out, invalid) -> Fixes:
    """Kernel outputs (lat rad, lon rad, h, range, status) -> Fixes, INVALID_INPUT where ``invalid``
    (the pose could not be used)."""
    lat, lon, h, t, st = (np.asarray(x) for x in out)
    lat, lon, h, t, st = mask_invalid((np.degrees(lat), np.degrees(lon), h, t, st.astype(np.int8, copy=False)),
                                      np.broadcast_to(invalid, st.shape))
    return Fixes(*(a[()] if a.ndim == 0 else a for a in (lat, lon, h, t, st)))
