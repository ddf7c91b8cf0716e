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

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..geodesy import WGS84, Ellipsoid
from ..kernels import core as kernels
from ..kernels.backend import backend, implements, run
from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel, split_pixels
from .base import StopRule, f64, to_fixes


@dataclass(frozen=True)
class FlatGround(StopRule):
    """M2 ([Z15]): the flat local ground through the main target, ranged at ``main_pixel``
    (default: the principal point) at slant range ``main_range_m`` (m).

    Validity domain: the main range as for :class:`AtRange`; the camera above the plane
    (BELOW_SURFACE otherwise); rays at or above the plane's horizon, or meeting it beyond
    ``MAX_RANGE_M``, get NO_INTERSECTION; pixels outside the image OUT_OF_IMAGE.
    """

    main_range_m: ArrayLike
    main_pixel: ArrayLike | None = None

    name = "flat"

    def __post_init__(self) -> None:
        object.__setattr__(self, "main_range_m", f64(self.main_range_m))

    def stop(self, rays: Rays, ell: Ellipsoid = WGS84, errors=None) -> Fixes:
        raise TypeError("FlatGround needs the camera and the main target's ray: use "
                        "eoloc.locate(sensor, pose, FlatGround(...), pixels)")

    def locate(self, sensor: SensorModel, pose: Pose, pixels: ArrayLike | None = None,
               pose_index: ArrayLike | None = None) -> Fixes:
        pose = pose if pose_index is None else pose.take(pose_index)
        return locate_flat(sensor, pose, self.main_range_m, pixels, main_pixel=self.main_pixel)

    error_sources = ("range_m",)

    def stop_in_frame(self, sensor: SensorModel, frame, xn, yn, outside, ell: Ellipsoid = WGS84, errors=None,
                      normalize=None) -> Fixes:
        """The error analysis' form (see :meth:`StopRule.stop_in_frame`): the plane through the main
        target seen in the same perturbed ``frame`` at the main range plus its ``range_m`` error,
        the main pixel normalised with the same camera errors."""
        cam = sensor.camera
        main = np.array([cam.cx, cam.cy] if self.main_pixel is None else np.ravel(self.main_pixel), dtype=np.float64)
        if normalize is None:
            xn0, yn0 = cam.pixel_to_normalized(main[0], main[1])
        else:
            xn0, yn0 = normalize(main[0], main[1])
        main_range = self.main_range_m + (errors("range_m") if errors is not None else 0.0)
        c = ell.constants
        with np.errstate(all="ignore"):
            nx, ny, nz, H = kernels.flat_plane(frame.R, frame.ox, frame.oy, frame.oz, xn0, yn0, main_range, *c)
        out = run("flat_target", frame.R, frame.ox, frame.oy, frame.oz, nx, ny, nz, H, xn, yn, *c)
        return to_fixes(out, frame.invalid, outside)

    @property
    def value_shape(self) -> tuple[int, ...]:
        return self.main_range_m.shape

    def describe(self) -> str:
        return "flat ground" if self.main_range_m.ndim else f"flat ground, main range {float(self.main_range_m):g} m"


def locate_flat(sensor: SensorModel, pose: Pose, main_range_m: ArrayLike, pixels: ArrayLike | None = None, *,
                main_pixel: ArrayLike | None = None) -> Fixes:
    """M2: targets at ``pixels`` on the flat ground through the main target at ``main_pixel``
    (default: the principal point) whose slant range is ``main_range_m`` (m).

    Pose fields and ``main_range_m`` broadcast against the pixels like every stop rule (F frames
    of K targets: pose fields and ranges (F, 1), pixels (F, K)). One frame (scalar pose and
    range) on the numba backend runs as a single compiled call, undistortion included: the
    real-time path.
    """
    return backend().locate_flat(sensor, pose, main_range_m, pixels, main_pixel)


@implements("locate_flat", "numpy")
def _locate_flat_arrays(sensor: SensorModel, pose: Pose, main_range_m: ArrayLike, pixels, main_pixel) -> Fixes:
    """M2 on arrays: the plane of each frame, then every target's ray on it."""
    ell = sensor.ellipsoid.constants
    frame = sensor.camera_frame(pose)
    xn0, yn0 = sensor.normalized(main_pixel, pose.focal_scale)
    with np.errstate(all="ignore"):
        nx, ny, nz, H = kernels.flat_plane(frame.R, frame.ox, frame.oy, frame.oz, xn0, yn0,
                                           np.asarray(main_range_m, dtype=np.float64), *ell)
    u, v = split_pixels(pixels, sensor.camera)
    xn, yn = sensor.camera.pixel_to_normalized(u, v, focal_scale=pose.focal_scale)
    out = run("flat_target", frame.R, frame.ox, frame.oy, frame.oz, nx, ny, nz, H, xn, yn, *ell)
    return to_fixes(out, frame.invalid, sensor.camera.outside(u, v, xn, yn, focal_scale=pose.focal_scale))


def _one_frame(pose: Pose, main_range_m, main_pixel) -> bool:
    fields = (pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg, pose.roll_deg, *pose.gimbal_deg)
    return (all(np.ndim(f) == 0 for f in fields) and pose.focal_scale == 1.0 and np.ndim(main_range_m) == 0
            and (main_pixel is None or np.size(main_pixel) == 2))


@implements("locate_flat", "numba")
def _locate_flat_compiled(sensor: SensorModel, pose: Pose, main_range_m: ArrayLike, pixels, main_pixel) -> Fixes:
    """M2 compiled: one frame (scalar pose and range) as a single call, undistortion included;
    several frames as the arrays path."""
    if not _one_frame(pose, main_range_m, main_pixel):
        return _locate_flat_arrays(sensor, pose, main_range_m, pixels, main_pixel)
    from ..kernels import compiled

    main_range_m = float(main_range_m)
    pose9 = np.radians([pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg, pose.roll_deg, 0, 0, 0])
    pose9[2] = pose.h_m
    pose9[6:] = sensor.gimbal.angles(pose.gimbal_deg)
    cam = sensor.camera
    main = np.array([cam.cx, cam.cy] if main_pixel is None else np.ravel(main_pixel), dtype=np.float64)
    u, v = split_pixels(pixels, cam)
    shape = np.broadcast_shapes(np.shape(u), np.shape(v))
    u = np.ascontiguousarray(np.broadcast_to(u, shape)).reshape(-1)
    v = np.ascontiguousarray(np.broadcast_to(v, shape)).reshape(-1)
    out = [np.empty(u.size) for _ in range(4)] + [np.empty(u.size, dtype=np.int8)]
    dist = cam.distortion
    compiled.flat_frame(sensor.kernel_params, 0 if dist is None else dist.kind,
                        _NO_DIST if dist is None else dist.packed, float(cam.width), float(cam.height), pose9, main,
                        main_range_m, u, v, *out)
    return to_fixes([o.reshape(shape) for o in out], False)


_NO_DIST = np.zeros(1)
