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
import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from ..accuracy.budget import SOURCES, ErrorBudget, ErrorSource
from ..accuracy.montecarlo import metres_per_degree
from ..geodesy import WGS84
from ..sensor.model import Pose, SensorModel
from ..sequence.calibration import TelemetryTrack, pose_with_biases
from .adjust import REFINE_GROUPS, Refinement, position_bias, shift_position

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
    boresight misalignment exactly as ``sensor`` points it at ``pose``, and a mask of the poses
    where that was reached (to FOLD_TOLERANCE_RAD). Started from :func:`euler_start` (exact for
    the az-el-roll turret, gimbal lock included) or the pose's own angles, whichever is nearer,
    then damped Gauss-Newton on the rotation between the two cameras, every pose at once (which
    leaves the az-el start as it is and serves any other three-angle gimbal)."""
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
    if ok.any():  # a start from the turret's own form, an az-el-roll (Z-Y-X) chain, where it is that
        a = np.where((np.linalg.norm(error(guess := euler_start(plain, use, target)), axis=-1)
                      < np.linalg.norm(error(a), axis=-1))[:, None], guess, a)
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


def euler_start(plain: SensorModel, pose: Pose, target: Rotation) -> np.ndarray:
    """Angles (n, 3) that would give ``target`` (R_ecef_cam) if the turret is an azimuth (about z),
    elevation (y), roll (x) chain with the camera looking along its x axis (ST 0601's): from the
    frame at zero angles, R0 = R_ecef_body P, the turret's rotation is P R0^T target P^T. Exact
    across a gimbal lock, where a step from the given angles would have to swing the azimuth."""
    P = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # camera (right, down, ahead) -> turret
    n = len(target)
    zero = dataclasses.replace(pose, gimbal_deg=(np.zeros(n), np.zeros(n), np.zeros(n)))
    R0 = plain.camera_frame(zero).R_ecef_cam.reshape(-1, 3, 3)
    G = P @ np.swapaxes(R0, 1, 2) @ target.as_matrix() @ P.T
    return zyx_angles(G)


def zyx_angles(G: np.ndarray) -> np.ndarray:
    """(n, 3) angles (deg) a, b, c with Rz(a) Ry(b) Rx(c) = G (n, 3, 3), exact also near the gimbal
    lock (b -> +-90 deg). The elevation from atan2 of well-conditioned terms; the azimuth from terms
    of size cos(b) (its error there only moves the product by cos(b) times itself); the roll then
    from Ry(b)^T Rz(a)^T G, so the three compose to G whatever the azimuth came out as. (scipy's
    as_euler treats a rotation within ~1e-7 rad of the lock as locked and sets the roll to 0: 2e-8
    rad off there, past the folding tolerance.)"""
    b = np.arctan2(-G[:, 2, 0], np.hypot(G[:, 0, 0], G[:, 1, 0]))
    a = np.arctan2(G[:, 1, 0], G[:, 0, 0])
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    Rz = np.zeros_like(G)
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = ca, -sa, sa, ca, 1.0
    Ry = np.zeros_like(G)
    Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2], Ry[:, 1, 1] = cb, sb, -sb, cb, 1.0
    M = np.swapaxes(Ry, 1, 2) @ np.swapaxes(Rz, 1, 2) @ G  # = Rx(c)
    c = np.arctan2(M[:, 2, 1], M[:, 1, 1])
    return np.degrees(np.stack([a, b, c], -1))


# -- the error budget after refinement --------------------------------------------------------------

#: each estimated parameter and the budget source (accuracy.budget.SOURCES) it stands for (the
#: position's metres become the budget's degrees as the covariance reads them back:
#: accuracy.montecarlo.metres_per_degree)
BUDGET_TERMS = {"mount_x_deg": "mount_x_deg", "mount_y_deg": "mount_y_deg", "mount_z_deg": "mount_z_deg",
                "boresight_x_deg": "boresight_x_deg", "boresight_y_deg": "boresight_y_deg",
                "heading_bias_deg": "yaw_deg", "time_offset_s": "time_s", "position_n_m": "lat_deg",
                "position_e_m": "lon_deg", "position_u_m": "h_m"}


def refined_budget(budget: ErrorBudget | None, ref: Refinement, span_s: float, lat_deg: float,
                   frame_sigma_deg: float = 0.0) -> tuple[dict[str, dict[str, float | str]], list[str]]:
    """The budget entries a refinement replaces or adds (``{source: {"normal": sigma, "kind":
    "bias"}}``, the config's [accuracy.budget] form) and a line per entry saying what it was.

    What the refinement estimated is no longer an unknown of the budget's size: what is left is
    the estimate's own error (its posterior 1-sigma: a bias over the pass), and of a source that
    varies in time the part the pass's constant could not take out: a Gauss-Markov error's wander
    about its mean over a pass of ``span_s`` (variance sigma^2 min(1, T / 3 tau), the Ornstein-
    Uhlenbeck process' for T << tau), a noise term whole. Both are added in quadrature and written
    as a bias (the part that will not average away over the pass). boresight_z (a roll about the
    optical axis) has no source of its own and is left out; the attitude's pitch and roll errors
    (:data:`ABSORBED`) keep only their wander when the mount's angle was estimated; sources the
    refinement did not touch stay as they are. The per-keyframe attitude error the refinement allowed for
    (``frame_sigma_deg``) goes in as vibration_*_deg noise where the budget has none."""
    given = {s.name: s for s in budget} if budget is not None else {}
    north, east = (float(x) for x in metres_per_degree(lat_deg, 0.0, WGS84))
    unit = {"position_n_m": 1.0 / north, "position_e_m": 1.0 / east}
    out: dict[str, dict[str, float | str]] = {}
    said = []
    for name, sigma in zip(ref.names, ref.sigma, strict=True):
        source = BUDGET_TERMS.get(name)
        if source is None:
            continue
        left = float(sigma) * unit.get(name, 1.0)
        was = given.get(source)
        if was is not None:
            left = math.hypot(left, was.sigma * math.sqrt(unremoved_share(was, span_s)))
        out[source] = {"normal": float(f"{left:.3g}"), "kind": "bias"}
        said.append(f"{source}: {was.describe() if was is not None else 'not in the budget'} -> "
                    f"σ{out[source]['normal']:g} {SOURCES[source][0]} (bias): refined ({name})")
    for source, mount in ABSORBED.items():  # a constant tilt of the platform is a mounting error
        was = given.get(source)
        if was is None or mount not in ref.names or was.kind == "noise":
            continue
        out[source] = {"normal": float(f"{was.sigma * math.sqrt(unremoved_share(was, span_s)):.3g}"), "kind": "bias"}
        said.append(f"{source}: {was.describe()} -> σ{out[source]['normal']:g} {SOURCES[source][0]} (bias): its "
                    f"constant part is estimated with {mount}, only its wander over the pass is left")
    for source in VIBRATION if frame_sigma_deg > 0 else ():
        if source not in given:
            out[source] = {"normal": float(f"{frame_sigma_deg:.3g}"), "kind": "noise"}
            said.append(f"{source}: not in the budget -> σ{frame_sigma_deg:.3g} deg (noise): each keyframe's own "
                        "attitude error the refinement allowed for")
    return out, said


def unremoved_share(source: ErrorSource, span_s: float) -> float:
    """The share of ``source``'s variance a constant estimated over a pass of ``span_s`` seconds
    leaves: none of a bias, all of a noise, of a Gauss-Markov error its wander about the pass's
    mean, min(1, T / 3 tau) (the Ornstein-Uhlenbeck process' for T << tau)."""
    if source.kind == "bias":
        return 0.0
    if source.kind == "noise":
        return 1.0
    return min(1.0, span_s / (3.0 * (source.tau_s or math.inf)))


VIBRATION = ("vibration_roll_deg", "vibration_pitch_deg", "vibration_yaw_deg")
#: attitude sources whose constant part a refinement estimates with a mounting angle: a platform
#: (or a drone camera) pitched or rolled by a constant error is one mounted pitched or rolled
#: (exactly at zero roll; to first order while the roll stays about constant over the pass)
ABSORBED = {"pitch_deg": "mount_y_deg", "roll_deg": "mount_x_deg"}


def budget_priors(budget: ErrorBudget, lat_deg: float) -> dict[str, float]:
    """Each refinement group's prior 1-sigma from a budget (the largest of its sources' sigma, in
    the group's unit): what refinement starts from is what the budget says it does not know; and
    under "frame" each keyframe's own attitude error, the largest vibration_*_deg."""
    given = {s.name: s.sigma for s in budget}
    north, east = (float(x) for x in metres_per_degree(lat_deg, 0.0, WGS84))
    scale = {"lat_deg": north, "lon_deg": east}
    out = {}
    for group, names in REFINE_GROUPS.items():
        sig = [given[BUDGET_TERMS[n]] * scale.get(BUDGET_TERMS[n], 1.0) for n in names
               if n in BUDGET_TERMS and BUDGET_TERMS[n] in given]
        if sig and max(sig) > 0:
            out[group] = max(sig)
    vib = [given[n] for n in VIBRATION if n in given]
    if vib and max(vib) > 0:
        out["frame"] = max(vib)
    return out
