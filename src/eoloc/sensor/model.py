"""The sensor model: pose + pixels -> rays in ECEF, and the inverse ground -> image projection.

Chain (SPEC §2.2): pixel -> unit ray in the camera frame -> R_body_cam (mount misalignment .
gimbal . boresight misalignment) -> R_ned_body (yaw, pitch, roll) -> R_ecef_ned (lat, lon), from
the camera origin P0 = ecef(lat, lon, h) + R_ecef_body . lever_arm.

Broadcasting: every pose field and the pixel arrays broadcast together. One pose and N pixels:
pose scalars, pixels (N,). F frames of K targets: pose fields (F, 1), pixels (F, K). Monte
Carlo: everything (n_samples, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from ..geodesy import WGS84, Ellipsoid, as_matrix
from ..kernels import core as kernels
from ..kernels.backend import Gathered, backend, run, take_all
from ..rotation import small_angle_rotation
from .camera import Camera
from .gimbal import AzElGimbal, Gimbal, GimbalKind


def _f64(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


class OneTargetRule(Protocol):
    """What :meth:`SensorModel.locate_one` asks of a stop rule (every :class:`eoloc.rules.StopRule`)."""

    def scalar_stop(self) -> tuple[int, float] | None: ...

    def locate(self, sensor: SensorModel, pose: Pose, pixels=None): ...


@dataclass(frozen=True)
class Pose:
    """Aircraft pose and gimbal angles at the instant of an image (arrays broadcast).

    lat_deg, lon_deg: WGS-84 geodetic degrees of the INS reference point; h_m: its ellipsoidal
    height (m); yaw_deg (heading, clockwise from true north), pitch_deg (nose up +), roll_deg
    (right wing down +); gimbal_deg: the gimbal model's angles in its order, degrees;
    focal_scale: the image's focal length over the camera's (zoom lenses: 2 = zoomed in twice as
    far as the configured focal length; 1 = the camera as configured).
    """

    lat_deg: ArrayLike
    lon_deg: ArrayLike
    h_m: ArrayLike
    yaw_deg: ArrayLike = 0.0
    pitch_deg: ArrayLike = 0.0
    roll_deg: ArrayLike = 0.0
    gimbal_deg: tuple = ()
    focal_scale: ArrayLike = 1.0

    def __post_init__(self) -> None:
        for name in ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "focal_scale"):
            object.__setattr__(self, name, _f64(getattr(self, name)))
        g = self.gimbal_deg
        if not isinstance(g, (tuple, list)):
            g = (g,) if np.ndim(g) == 0 else tuple(g)  # a bare number, or an array of angle rows
        object.__setattr__(self, "gimbal_deg", tuple(_f64(a) for a in g))

    def take(self, index) -> Pose:
        """The poses at ``index`` (fields that are scalars stay scalars: they broadcast)."""
        def pick(x: np.ndarray) -> np.ndarray:
            return x[()] if x.ndim == 0 else x[index]

        return Pose(pick(self.lat_deg), pick(self.lon_deg), pick(self.h_m), pick(self.yaw_deg), pick(self.pitch_deg),
                    pick(self.roll_deg), tuple(pick(g) for g in self.gimbal_deg), pick(self.focal_scale))

    def invalid(self) -> np.ndarray:
        """True where the pose cannot be used: NaN/inf anywhere, |lat| > 90°, a focal scale <= 0."""
        fields = (self.lat_deg, self.lon_deg, self.h_m, self.yaw_deg, self.pitch_deg, self.roll_deg, *self.gimbal_deg,
                  self.focal_scale)
        with np.errstate(invalid="ignore"):
            total = sum(fields)
            return ~np.isfinite(total) | (np.abs(self.lat_deg) > 90.0) | ~(self.focal_scale > 0.0)


@dataclass(frozen=True)
class Rays:
    """Rays in ECEF: origins (camera positions) and unit directions, component arrays (m).
    ``invalid`` (the pose cannot be used) and ``out_of_image`` (the pixel is not to be located)
    broadcast against them: a scalar False where nothing is flagged."""

    ox: np.ndarray
    oy: np.ndarray
    oz: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    invalid: np.ndarray = field(default_factory=lambda: np.bool_(False))
    out_of_image: np.ndarray = field(default_factory=lambda: np.bool_(False))

    @property
    def origin_ecef(self) -> np.ndarray:
        """(..., 3) camera positions, ECEF metres."""
        return np.stack(np.broadcast_arrays(self.ox, self.oy, self.oz), -1)

    @property
    def dir_ecef(self) -> np.ndarray:
        """(..., 3) unit directions, ECEF."""
        return np.stack((self.dx, self.dy, self.dz), -1)

    @property
    def shape(self) -> tuple[int, ...]:
        return np.shape(self.dx)

    def take(self, index) -> Rays:
        """The rays at ``index`` of the flattened batch."""
        def pick(x) -> np.ndarray:
            return np.broadcast_to(x, self.shape).reshape(-1)[index]

        return Rays(*(pick(a) for a in (self.ox, self.oy, self.oz, self.dx, self.dy, self.dz, self.invalid,
                                         self.out_of_image)))


@dataclass(frozen=True)
class CameraFrame:
    """The camera's pose in ECEF for each pose element: R_ecef_cam 9-tuple and origin."""

    R: tuple
    ox: np.ndarray
    oy: np.ndarray
    oz: np.ndarray
    invalid: np.ndarray

    @property
    def R_ecef_cam(self) -> np.ndarray:
        return as_matrix(self.R)

    def take(self, index) -> CameraFrame:
        """The frames at ``index`` (targets that share a pose share its frame, computed once).
        With an integer index into one-dimensional frames, the rotation is left
        :class:`~eoloc.kernels.backend.Gathered`: the ray kernel gathers it chunk by chunk (it is the
        array it stands for anywhere else); the origins are gathered on the threads."""
        parts = [np.asarray(x) for x in (*self.R, self.ox, self.oy, self.oz, self.invalid)]
        index = np.asarray(index)
        arrays = [x for x in parts if x.ndim]
        if not arrays:  # one frame for every target: nothing to gather
            return self
        if index.dtype.kind in "iu" and all(x.ndim == 1 and len(x) == len(arrays[0]) for x in arrays):
            origin = [x for x in parts[9:] if x.ndim]  # (none where only the attitude varies)
            taken = iter(take_all(origin, index) if origin else ())
            out = [Gathered(x, index) if x.ndim else x for x in parts[:9]] + \
                  [next(taken) if x.ndim else x for x in parts[9:]]
        else:
            out = [x if not x.ndim else x[index] for x in parts]
        return CameraFrame(tuple(out[:9]), *out[9:])


@dataclass(frozen=True)
class SensorModel:
    """Camera + gimbal + installation: everything constant about the sensor.

    mount_misalignment_deg: small rotation (about body x, y, z) of the gimbal base relative to the
    INS body axes (installation error); boresight_misalignment_deg: small rotation (about camera
    x, y, z) of the optical axis relative to the gimbal (collimation); lever_arm_m: camera
    position relative to the INS reference point, body FRD metres.
    """

    camera: Camera
    gimbal: Gimbal = field(default_factory=AzElGimbal)
    mount_misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    boresight_misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ellipsoid: Ellipsoid = WGS84

    def __post_init__(self) -> None:
        for name in ("mount_misalignment_deg", "boresight_misalignment_deg", "lever_arm_m"):
            value = tuple(float(x) for x in np.ravel(getattr(self, name)))
            if len(value) != 3 or not all(np.isfinite(value)):
                raise ValueError(f"{name} needs three finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)

    # -- constant parts -------------------------------------------------------------------------

    @cached_property
    def _R_mount9(self) -> tuple:
        return tuple(small_angle_rotation(self.mount_misalignment_deg).ravel())

    @cached_property
    def _R_bore9(self) -> tuple:
        return tuple(small_angle_rotation(self.boresight_misalignment_deg).ravel())

    @cached_property
    def kernel_params(self) -> np.ndarray:
        """Parameter vector of the single-target kernel (layout in eoloc.kernels.core)."""
        c = self.camera
        p = np.concatenate([
            [c.fx, c.fy, c.cx, c.cy, float(self.gimbal.kind)],
            self._R_mount9, self.gimbal.R_fixed9, self._R_bore9, self.lever_arm_m, self.ellipsoid.constants,
        ]).astype(np.float64)
        assert p.size == kernels.N_PARAMS
        return p

    # -- chain ----------------------------------------------------------------------------------

    def R_body_cam(self, gimbal_deg: tuple) -> np.ndarray:
        """R_body_cam (..., 3, 3) for gimbal angles (degrees), misalignments included."""
        g1, g2, g3 = self.gimbal.angles(tuple(gimbal_deg))
        return as_matrix(kernels.r_body_cam(self.gimbal.kind, g1, g2, g3, self._R_mount9,
                                             self.gimbal.R_fixed9, self._R_bore9, 0.0))

    def camera_frame(self, pose: Pose, *, mount_misalignment_deg: ArrayLike | None = None,
                     boresight_misalignment_deg: ArrayLike | None = None,
                     gimbal_skew_deg: ArrayLike = 0.0) -> CameraFrame:
        """Camera orientation (R_ecef_cam) and position (ECEF m) for every pose element.

        The keyword arguments replace the sensor's own installation angles (arrays (..., 3) of
        degrees that broadcast with the pose) and add a gimbal axes non-orthogonality: how Monte
        Carlo draws them per sample through the same kernels.
        """
        g1, g2, g3 = self.gimbal.angles(pose.gimbal_deg)
        R_mount = self._R_mount9 if mount_misalignment_deg is None else _rot9(mount_misalignment_deg)
        R_bore = self._R_bore9 if boresight_misalignment_deg is None else _rot9(boresight_misalignment_deg)
        R, ox, oy, oz = run("camera_frame", self.gimbal.kind, g1, g2, g3, R_mount, self.gimbal.R_fixed9, R_bore,
                  np.radians(_f64(gimbal_skew_deg)), np.radians(pose.lat_deg), np.radians(pose.lon_deg), pose.h_m,
                  np.radians(pose.yaw_deg), np.radians(pose.pitch_deg), np.radians(pose.roll_deg),
                  *self.lever_arm_m, self.ellipsoid.a, self.ellipsoid.e2)
        invalid = pose.invalid()
        return CameraFrame(R, ox, oy, oz, invalid)

    def rays_from(self, frame: CameraFrame, xn: ArrayLike, yn: ArrayLike, out_of_image: ArrayLike = False) -> Rays:
        """Rays of normalised, undistorted image points (xn, yn) from camera frame(s) ``frame``
        (``out_of_image``: where the pixels are not to be located, see :meth:`Camera.outside`;
        Monte Carlo leaves it False: a perturbed pixel may stray past the edge)."""
        dx, dy, dz = run("ray_direction", frame.R, xn, yn)
        shape = dx.shape
        return Rays(np.broadcast_to(frame.ox, shape), np.broadcast_to(frame.oy, shape),
                    np.broadcast_to(frame.oz, shape), dx, dy, dz, frame.invalid, out_of_image)

    def normalized(self, pixels: ArrayLike | None, focal_scale: ArrayLike = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (u, v) -> normalised, undistorted image coordinates; None = principal point;
        ``focal_scale``: the pose's (zoom)."""
        u, v = split_pixels(pixels, self.camera)
        return self.camera.pixel_to_normalized(u, v, focal_scale=focal_scale)

    def rays(self, pose: Pose, pixels: ArrayLike | None = None, pose_index: ArrayLike | None = None) -> Rays:
        """Rays through ``pixels`` ((u, v) pair of arrays or an (..., 2) array; None = principal point).
        Pixels outside the image (see :meth:`Camera.outside`) are marked ``out_of_image``: every
        stop rule gives them OUT_OF_IMAGE. ``pose_index``: each pixel's element of ``pose`` (many
        targets per image: each image's camera frame is computed once), instead of broadcasting."""
        frame = self.camera_frame(pose)
        focal = pose.focal_scale
        if pose_index is not None:
            frame = frame.take(pose_index)
            focal = focal if np.ndim(focal) == 0 else focal[pose_index]
        u, v = split_pixels(pixels, self.camera)
        xn, yn = self.camera.pixel_to_normalized(u, v, focal_scale=focal)
        return self.rays_from(frame, xn, yn, self.camera.outside(u, v, xn, yn, focal_scale=focal))

    def ground_to_image(self, pose: Pose, p_ecef: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Project ECEF points (..., 3) into the image: pixels (u, v); NaN where the point is behind
        the camera. Points outside the image bounds still get their (out-of-range) pixel."""
        p = _f64(p_ecef)
        if p.shape[-1:] != (3,):
            raise ValueError(f"p_ecef must have 3 components in its last axis, got shape {p.shape}")
        return self.frame_to_image(self.camera_frame(pose), p, pose.focal_scale)

    def frame_to_image(self, frame: CameraFrame, p_ecef: ArrayLike,
                       focal_scale: ArrayLike = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`ground_to_image` with the camera frames already made (e.g. once per video frame,
        then :meth:`CameraFrame.take` per point): pixels (u, v), NaN behind the camera."""
        p = _f64(p_ecef)
        xn, yn, _depth = run("project_point", frame.R, frame.ox, frame.oy, frame.oz, p[..., 0], p[..., 1], p[..., 2])
        u, v = self.camera.normalized_to_pixel(xn, yn, focal_scale=focal_scale)
        bad = np.broadcast_to(frame.invalid, u.shape)
        return np.where(bad, np.nan, u), np.where(bad, np.nan, v)

    # -- single-target fast path ---------------------------------------------------------------

    def locate_one(self, lat_deg: float, lon_deg: float, h_m: float, yaw_deg: float, pitch_deg: float,
                   roll_deg: float, g1_deg: float, g2_deg: float = 0.0, u: float | None = None,
                   v: float | None = None, *, rule: OneTargetRule, g3_deg: float = 0.0,
                   in_image: bool = True) -> tuple[float, float, float, float, int]:
        """One pose, one pixel, stop ``rule`` -> (lat_deg, lon_deg, h_m, range_m, status code).

        A rule with a compiled single-target kernel (AtRange, AtHeight with one value:
        :meth:`eoloc.rules.StopRule.scalar_stop`) answers in about a microsecond, the others
        (OnDEM, FlatGround, ...) through their array path; the same answer either way. For a fixed
        mount g1_deg is the sensor roll. Compare the status with ``Status.OK``. A pixel past the
        image is OUT_OF_IMAGE, as in :func:`eoloc.locate`; ``in_image=False`` skips that check on
        the kernel path, for a placeholder camera whose "pixels" are normalised image coordinates.
        """
        stop = rule.scalar_stop()
        if stop is None:
            angles = (g1_deg,) if self.gimbal.kind == GimbalKind.FIXED else (g1_deg, g2_deg, g3_deg)
            pose = Pose(lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, angles)
            f = rule.locate(self, pose, None if u is None and v is None else
                            (self.camera.cx if u is None else u, self.camera.cy if v is None else v))
            return float(f.lat_deg), float(f.lon_deg), float(f.h_m), float(f.range_m), int(f.status)
        stop_kind, stop_value = stop
        if self.gimbal.kind == GimbalKind.FIXED:
            g1_deg, g3_deg = 0.0, g1_deg
        if u is not None or v is not None:
            cam = self.camera
            u, v = float(cam.cx if u is None else u), float(cam.cy if v is None else v)
            if cam.distortion is not None:
                # the compiled single-target kernel is distortion-free: undistort the pixel first
                xn, yn = cam.pixel_to_normalized(u, v)
                if in_image and bool(cam.outside(u, v, xn, yn)):
                    return _NOWHERE
                u, v = float(xn * cam.fx + cam.cx), float(yn * cam.fy + cam.cy)
            elif in_image and math.isfinite(u + v) and not (-_EDGE <= u <= cam.width - 1.0 + _EDGE
                                                            and -_EDGE <= v <= cam.height - 1.0 + _EDGE):
                return _NOWHERE  # a pixel the image does not have (kernels.pixel_in_image, without numpy)
        return backend().locate_one(self.kernel_params, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, g1_deg,
                                    g2_deg, g3_deg, self.camera.cx if u is None else u,
                                    self.camera.cy if v is None else v, stop_kind, stop_value)


_NOWHERE = (math.nan, math.nan, math.nan, math.nan, kernels.OUT_OF_IMAGE)
_EDGE = 0.5 + kernels.IMAGE_MARGIN_PX  # how far past the centres of the edge pixels a pixel is still in the image


def _rot9(angles_deg: ArrayLike) -> tuple:
    """Small-angle misalignment rotation(s) from (..., 3) degrees as a 9-tuple of arrays."""
    R = small_angle_rotation(_f64(angles_deg))
    return tuple(R[..., i, j] for i in range(3) for j in range(3))


def split_pixels(pixels: ArrayLike | None, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    if pixels is None:
        return np.float64(camera.cx), np.float64(camera.cy)
    if isinstance(pixels, tuple) and len(pixels) == 2:
        return _f64(pixels[0]), _f64(pixels[1])
    arr = _f64(pixels)
    if arr.shape[-1:] != (2,):
        raise ValueError(f"pixels must be a (u, v) pair of arrays or an (..., 2) array, got shape {arr.shape}")
    return arr[..., 0], arr[..., 1]
