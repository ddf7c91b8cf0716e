"""Rotations and attitude, in the one convention eoloc uses everywhere.

**All rotation matrices are active**: ``R_a_b`` rotates/maps a vector expressed in frame ``b``
into frame ``a`` (``v_a = R_a_b @ v_b``); its columns are ``b``'s axes written in ``a``.
Elementary rotations follow the right-hand rule (``rot_z(90°) @ x = y``).

Attitude is ZYX: ``R_ned_body = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)`` with the body frame
FRD (x nose, y right wing, z down): yaw is the heading clockwise from true north, positive pitch
raises the nose, positive roll drops the right wing. Stacks of rotations are arrays
``(..., 3, 3)``; angles broadcast. Degrees by default, ``degrees=False`` for radians.
Gimbal lock: at pitch = ±90° yaw and roll are not separable; :func:`euler_from_R_ned_body`
then returns roll = 0 and puts the whole rotation in yaw, and warns.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike

from .geodesy import as_matrix
from .kernels import core as kernels

__all__ = [
    "R_ned_body",
    "euler_from_R_ned_body",
    "matrix_from_quaternion",
    "quaternion_from_matrix",
    "rot_x",
    "rot_y",
    "rot_z",
    "small_angle_rotation",
]


def _rad(a: ArrayLike, degrees: bool) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return np.radians(a) if degrees else a


def rot_x(angle: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Active rotation about x, (..., 3, 3)."""
    return as_matrix(kernels.rot_x(_rad(angle, degrees)))


def rot_y(angle: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Active rotation about y, (..., 3, 3)."""
    return as_matrix(kernels.rot_y(_rad(angle, degrees)))


def rot_z(angle: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Active rotation about z, (..., 3, 3)."""
    return as_matrix(kernels.rot_z(_rad(angle, degrees)))


def R_ned_body(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Body (FRD) to NED rotation (..., 3, 3) from yaw, pitch, roll: Rz(yaw) Ry(pitch) Rx(roll)."""
    return as_matrix(kernels.r_ned_body(_rad(yaw, degrees), _rad(pitch, degrees), _rad(roll, degrees)))


def euler_from_R_ned_body(R: ArrayLike, *, degrees: bool = True, warn_gimbal_lock: bool = True):
    """(yaw, pitch, roll) of R_ned_body (..., 3, 3); yaw in [0, 360) deg, pitch in [-90, 90].
    ``warn_gimbal_lock=False``: callers for which pitch ±90° is just another rotation (readers,
    interpolation) take the yaw-only form without a warning."""
    R = np.asarray(R, dtype=np.float64)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    locked = np.abs(R[..., 2, 0]) > 1.0 - 1e-12
    if warn_gimbal_lock and np.any(locked):
        warnings.warn("gimbal lock: pitch is ±90°, roll set to 0 and the rotation put in yaw", stacklevel=2)
    yaw = np.where(locked, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    roll = np.where(locked, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.mod(yaw, 2 * np.pi)
    yaw = np.where(yaw >= 2 * np.pi, 0.0, yaw)  # a tiny negative yaw rounds up to exactly 2 pi
    out = (yaw, pitch, roll)
    return tuple(np.degrees(a) for a in out) if degrees else out


def matrix_from_quaternion(q: ArrayLike, *, scalar_first: bool = True) -> np.ndarray:
    """Active rotation matrix (..., 3, 3) from unit quaternion(s) (..., 4), (w, x, y, z) by default.

    A quaternion ``q_a_b`` gives ``R_a_b`` (it rotates b-vectors into a). Normalised on the way in.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"a quaternion needs 4 components in its last axis, got shape {q.shape}")
    from scipy.spatial.transform import Rotation  # here, not at import: scipy.spatial costs 0.2 s

    flat = Rotation.from_quat(q.reshape(-1, 4), scalar_first=scalar_first)
    return flat.as_matrix().reshape((*q.shape[:-1], 3, 3))


def quaternion_from_matrix(R: ArrayLike, *, scalar_first: bool = True) -> np.ndarray:
    """Unit quaternion(s) (..., 4) of rotation matrices (..., 3, 3), w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat(canonical=True, scalar_first=scalar_first)
    return q.reshape((*R.shape[:-2], 4))


def small_angle_rotation(angles_xyz: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Misalignment rotation Rz(c) Ry(b) Rx(a) for angles (a, b, c) about x, y, z (..., 3) -> (..., 3, 3)."""
    a = _rad(angles_xyz, degrees)
    if a.shape[-1:] != (3,):
        raise ValueError(f"misalignment needs three angles (about x, y, z), got shape {a.shape}")
    return R_ned_body(a[..., 2], a[..., 1], a[..., 0], degrees=False)
