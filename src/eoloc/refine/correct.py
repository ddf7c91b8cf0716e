"""What a refinement changes, put back into the telemetry's own terms.

:func:`refined_poses` gives the poses the refinement believes in at any time (the telemetry
interpolated at the corrected time, the heading bias out of the yaw, the GPS bias out of the
position). :func:`fold_installation` gives, for a sensor with installation terms (mount,
boresight), the gimbal angles that point a sensor without them the same way: a format with no
place for an installation (ST 0601's sensor relative azimuth, elevation and roll) then carries
the refined pointing, and every reader of it gets the refined camera without a config.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from ..sensor.model import Pose, SensorModel
from ..sequence.calibration import TelemetryTrack, pose_with_biases
from .adjust import Refinement, position_bias, shift_position

FOLD_TOLERANCE_RAD = 1e-9  # the pointing left after folding (5e-8 deg: below ST 0601's resolution)


def refined_poses(ref: Refinement, track: TelemetryTrack, time_s: ArrayLike) -> Pose:
    """The poses at video times ``time_s`` as ``ref`` corrects them (NaN where the corrected time
    leaves the telemetry)."""
    pose = pose_with_biases(None, track, np.asarray(time_s, dtype=np.float64), ref.heading_bias_deg,
                            ref.time_offset_s)
    return shift_position(pose, position_bias(ref.names, ref.values))


def fold_installation(sensor: SensorModel, pose: Pose, *, iterations: int = 40) -> tuple[tuple[np.ndarray, ...],
                                                                                       np.ndarray]:
    """Gimbal angles (deg, the gimbal's order) that point ``sensor``'s camera without its mount and
    boresight misalignment exactly as ``sensor`` points it at ``pose`` (its own angles the
    start), and a mask of the poses where that was reached (to FOLD_TOLERANCE_RAD; a three-angle
    gimbal reaches every orientation, but not through a gimbal lock at the end of its travel).
    Damped Gauss-Newton on the rotation between the two cameras, every pose at once."""
    plain = dataclasses.replace(sensor, mount_misalignment_deg=(0.0, 0.0, 0.0),
                                boresight_misalignment_deg=(0.0, 0.0, 0.0))
    shape = np.shape(pose.lat_deg)
    if len(pose.gimbal_deg) != 3:
        raise ValueError(f"folding an installation needs a three-angle gimbal, got {len(pose.gimbal_deg)} angle(s)")
    flat = pose.take(np.arange(int(np.prod(shape)))) if shape else pose.take(np.zeros(1, np.int64))
    angles = np.stack([np.broadcast_to(np.asarray(g, dtype=np.float64), shape).reshape(-1) for g in pose.gimbal_deg],
                      -1)
    ok = ~np.asarray(flat.invalid(), dtype=bool).reshape(-1) & np.isfinite(angles).all(-1)
    use = flat.take(np.flatnonzero(ok))
    target = Rotation.from_matrix(sensor.camera_frame(use).R_ecef_cam.reshape(-1, 3, 3)) if ok.any() else None

    def error(a: np.ndarray) -> np.ndarray:
        now = Rotation.from_matrix(plain.camera_frame(dataclasses.replace(use, gimbal_deg=tuple(a.T)))
                                   .R_ecef_cam.reshape(-1, 3, 3))
        return (target * now.inv()).as_rotvec()  # (n, 3) rad

    a = angles[ok]
    step = 1e-6
    for _ in range(iterations if ok.any() else 0):
        e = error(a)
        if np.all(np.linalg.norm(e, axis=-1) < FOLD_TOLERANCE_RAD):
            break
        J = np.stack([(error(a + step * np.eye(3)[k]) - e) / step for k in range(3)], -1)  # (n, 3, 3)
        JtJ = np.swapaxes(J, 1, 2) @ J
        damping = 1e-9 * np.trace(JtJ, axis1=1, axis2=2)[:, None, None] * np.eye(3)
        a = a - np.linalg.solve(JtJ + damping, np.swapaxes(J, 1, 2) @ e[..., None])[..., 0]
    out = np.full_like(angles, np.nan)
    if ok.any():
        reached = np.linalg.norm(error(a), axis=-1) < FOLD_TOLERANCE_RAD
        out[np.flatnonzero(ok)] = a
        ok[np.flatnonzero(ok)] = reached
    return tuple(x.reshape(shape) for x in out.T), ok.reshape(shape)
