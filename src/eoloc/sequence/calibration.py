"""Boresight / mounting calibration from ground control points (GCPs) seen in frames.

[Q]'s flight test shows the installation's systematic error dominates: this estimates it. Unknowns
(any subset, by name):

- ``mount``: the gimbal base's misalignment to the INS, three small angles about body x, y, z (deg)
- ``boresight``: the optical axis' misalignment to the gimbal, about camera x, y, z (deg)
- ``heading``: a heading bias of the INS (deg; measured yaw = true yaw + bias)
- ``time``: the telemetry clock minus the video clock (s; needs the telemetry records)

Each observation is a pixel (u, v) at which a GCP of known WGS-84 position appears. The model is
the sensor's own ground -> image projection (:meth:`SensorModel.ground_to_image`) at the
observation's pose, so the residuals are in pixels, where the measurement error lives, and no
stop rule is involved. Gauss-Newton / Levenberg-Marquardt by scipy ``least_squares`` (optionally
a robust soft-L1 loss for GCPs that were misidentified), derivatives by central differences.

Reported: the parameters with their covariance, scaled by the a-posteriori variance factor
s0^2 = chi^2 / (2N - p) (s0 > 1: the pixel sigma given was optimistic); correlations, with a
warning when two parameters cannot be told apart by this geometry (|rho| > 0.95, e.g. a heading
bias against the mount's z angle in level flight); pixel residuals before and after; and the
horizontal error of each GCP located from its pixel at its own height, before and after.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from .. import geodesy
from ..errors import InputError
from ..rules import locate_ellipsoid
from ..sensor.model import Pose, SensorModel
from .interp import interpolate_poses

GROUPS = {"mount": ("mount_x_deg", "mount_y_deg", "mount_z_deg"),
          "boresight": ("boresight_x_deg", "boresight_y_deg", "boresight_z_deg"),
          "heading": ("heading_bias_deg",), "time": ("time_offset_s",)}


@dataclass(frozen=True)
class TelemetryTrack:
    """Telemetry records (time_s (M,) s, telemetry clock; pose of (M,) fields) to interpolate the
    pose at each observation's video time + time offset (needed to estimate ``time``)."""

    time_s: np.ndarray
    pose: Pose
    max_gap_s: float = 0.5


class Estimates:
    """What a least-squares answer holding ``names``, ``values`` and their covariance ``cov`` shows:
    the 1-sigma, the correlations and the values by name."""

    names: tuple[str, ...]
    values: np.ndarray
    cov: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diagonal(self.cov))

    @property
    def correlation(self) -> np.ndarray:
        s = self.sigma
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.cov / np.outer(s, s)

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.values, strict=True)}

    @staticmethod
    def rms(r: np.ndarray) -> float:
        """RMS of pixel residuals (N, 2) (radial) or of distances (N,), NaN ones left out (NaN if
        there is none)."""
        r = np.asarray(r, dtype=np.float64)
        r = np.hypot(r[..., 0], r[..., 1]) if r.ndim == 2 else r
        return float(np.sqrt(np.nanmean(r**2))) if np.isfinite(r).any() else math.nan


def correlation_warnings(names, corr: np.ndarray, fix: str) -> list[str]:
    """One warning per pair of parameters correlated beyond 0.95 (``fix``: how to separate them)."""
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(corr[i, j]) > 0.95:
                out.append(f"{names[i]} and {names[j]} are {corr[i, j]:+.3f} correlated: this geometry cannot tell "
                           f"them apart ({fix})")
    return out


@dataclass(frozen=True)
class Calibration(Estimates):
    """Result of :func:`calibrate`. values/sigma in the parameters' units (deg, s), by ``names``."""

    names: tuple[str, ...]
    values: np.ndarray
    cov: np.ndarray
    s0: float
    residual_px_before: np.ndarray
    residual_px_after: np.ndarray
    ground_error_before_m: np.ndarray
    ground_error_after_m: np.ndarray
    used: np.ndarray
    sensor: SensorModel
    heading_bias_deg: float
    time_offset_s: float
    warnings: list[str] = field(default_factory=list)
    undetermined: list[str] = field(default_factory=list)  # parameters these observations cannot fix



def apply_parameters(sensor: SensorModel, names: tuple[str, ...], x: np.ndarray, heading0: float,
                     time0: float) -> tuple[SensorModel, float, float]:
    """The sensor with the installation angles among ``names`` set to ``x``'s, and the heading bias
    and time offset (``x``'s where named, else ``heading0`` / ``time0``)."""
    v = dict(zip(names, x, strict=True))
    mount = tuple(v.get(n, b) for n, b in zip(GROUPS["mount"], sensor.mount_misalignment_deg, strict=True))
    bore = tuple(v.get(n, b) for n, b in zip(GROUPS["boresight"], sensor.boresight_misalignment_deg, strict=True))
    s = dataclasses.replace(sensor, mount_misalignment_deg=mount, boresight_misalignment_deg=bore)
    return s, float(v.get("heading_bias_deg", heading0)), float(v.get("time_offset_s", time0))


def pose_with_biases(pose: Pose | None, track: TelemetryTrack | None, time_s, heading_bias: float,
                     offset: float) -> Pose:
    """The poses at video times ``time_s`` (``track`` interpolated at time_s + offset, or ``pose``
    as given) with the heading bias taken out of the yaw."""
    if track is not None:
        p = interpolate_poses(track.time_s, track.pose, time_s, time_offset_s=offset, max_gap_s=track.max_gap_s).pose
    else:
        p = pose
    return dataclasses.replace(p, yaw_deg=np.asarray(p.yaw_deg) - heading_bias)


def calibrate(sensor: SensorModel, pixels: ArrayLike, gcp_lat_lon_h: ArrayLike, *, pose: Pose | None = None,
              telemetry: TelemetryTrack | None = None, time_s: ArrayLike | None = None,
              estimate: tuple[str, ...] = ("mount",), pixel_sigma_px: float = 1.0, heading_bias_deg: float = 0.0,
              time_offset_s: float = 0.0, robust: bool = False) -> Calibration:
    """Estimate installation parameters from N GCP observations.

    pixels (N, 2) u, v; gcp_lat_lon_h (N, 3) WGS-84 degrees and ellipsoidal metres. The pose of each
    observation: ``pose`` (fields (N,)), or ``telemetry`` records + ``time_s`` (N,) video times
    (required for ``time``). ``estimate``: names from ``mount``, ``boresight``, ``heading``, ``time``;
    the rest stay at the sensor's values and the given ``heading_bias_deg`` / ``time_offset_s``,
    which are also the starting point. Observations whose GCP projects to no pixel (behind the
    camera, no pose) are left out (``used`` False).
    """
    bad = [e for e in estimate if e not in GROUPS]
    if bad or not estimate:
        raise InputError(f"estimate: unknown or no parameters {bad or estimate!r}; choose from {sorted(GROUPS)}")
    if "time" in estimate and (telemetry is None or time_s is None):
        raise InputError("estimating the time offset needs the telemetry records (telemetry=) and the "
                         "observations' video times (time_s=)")
    if (pose is None) == (telemetry is None):
        raise InputError("give the observations' poses either as pose= or as telemetry= with time_s=")
    if telemetry is not None and time_s is None:
        raise InputError("telemetry= needs the observations' video times (time_s=)")
    if not pixel_sigma_px > 0:
        raise InputError(f"pixel_sigma_px must be > 0, got {pixel_sigma_px!r}")
    uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    llh = np.asarray(gcp_lat_lon_h, dtype=np.float64).reshape(-1, 3)
    if llh.shape[0] != uv.shape[0]:
        raise ValueError(f"{uv.shape[0]} pixels but {llh.shape[0]} GCP coordinates")
    p_gcp = np.stack(geodesy.geodetic_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2]), -1)
    names = tuple(n for g in estimate for n in GROUPS[g])
    base = {**dict(zip(GROUPS["mount"], sensor.mount_misalignment_deg, strict=True)),
            **dict(zip(GROUPS["boresight"], sensor.boresight_misalignment_deg, strict=True)),
            "heading_bias_deg": heading_bias_deg, "time_offset_s": time_offset_s}
    x0 = np.array([base[n] for n in names], dtype=np.float64)
    tq = None if time_s is None else np.asarray(time_s, dtype=np.float64).ravel()

    def project(x):
        s, hb, dt = apply_parameters(sensor, names, x, heading_bias_deg, time_offset_s)
        u, v = s.ground_to_image(pose_with_biases(pose, telemetry, tq, hb, dt), p_gcp)
        return np.stack([np.broadcast_to(u, uv.shape[:1]), np.broadcast_to(v, uv.shape[:1])], -1)

    r0 = project(x0) - uv
    used = np.all(np.isfinite(r0), -1) & np.all(np.isfinite(uv), -1) & np.all(np.isfinite(llh), -1)
    m, p = 2 * int(used.sum()), len(names)
    if m <= p:
        raise InputError(f"{int(used.sum())} usable GCP observations give {m} equations for {p} parameters: "
                         "observe more GCPs (at least one more than half the parameter count)")

    def fun(x):
        r = (project(x) - uv)[used] / pixel_sigma_px
        return np.nan_to_num(r, nan=1e6).ravel()  # a GCP pushed behind the camera: a large residual, not a crash

    steps = np.array([1e-3 if n == "time_offset_s" else 1e-4 for n in names])
    sol = least_squares(fun, x0, jac="3-point", method="trf", loss="soft_l1" if robust else "linear",
                        x_scale=steps * 100, diff_step=None, f_scale=3.0)
    J = sol.jac
    chi2 = float(np.sum(fun(sol.x) ** 2))
    s0 = float(np.sqrt(chi2 / (m - p))) if m > p else float("nan")
    # a parameter the observations do not determine: its column of J is (nearly) zero, or it lies
    # in the near-null space of J (columns scaled to unit norm, singular values below 1e-8)
    colnorm = np.linalg.norm(J, axis=0)
    scaled = J / np.where(colnorm > 0, colnorm, 1.0)
    _, sv, vt = np.linalg.svd(scaled, full_matrices=False)
    null = vt[sv < 1e-8 * max(sv.max(initial=0.0), 1e-300)]
    weak = (colnorm <= 1e-12 * max(colnorm.max(initial=0.0), 1e-300)) | (np.abs(null) > 0.1).any(axis=0)
    undetermined = [names[i] for i in np.flatnonzero(weak)]
    try:
        cov = np.linalg.inv(J.T @ J) * max(s0, 1e-12) ** 2
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.inf)
    if undetermined:
        cov[weak, :] = np.inf
        cov[:, weak] = np.inf
    s_cal, hb, dt = apply_parameters(sensor, names, sol.x, heading_bias_deg, time_offset_s)
    r1 = project(sol.x) - uv
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(np.sqrt(np.diagonal(cov)), np.sqrt(np.diagonal(cov)))
    warnings = correlation_warnings(names, corr, "vary the attitude/look direction, or estimate one of them")
    if not sol.success:
        warnings.append(f"least squares did not converge: {sol.message}")
    if undetermined:
        warnings.append(f"these observations do not determine {', '.join(undetermined)}: their values are not "
                        "estimates (sigma infinite); add GCPs seen from other attitudes/look directions, or do not "
                        "estimate them")
    rms0, rms1 = float(np.sqrt(np.mean(r0[used] ** 2))), float(np.sqrt(np.mean(r1[used] ** 2)))
    if np.allclose(sol.x, x0) and rms1 >= 0.999 * rms0:
        warnings.append(f"the solver did not move from the start (RMS {rms0:.2f} -> {rms1:.2f} px): the "
                        "parameters have no effect on these observations (check --max-gap, the time matching and "
                        "the estimated groups)")
    norm = np.hypot(r1[:, 0], r1[:, 1]) / (pixel_sigma_px * max(s0, 1.0))
    for i in np.flatnonzero(used & (norm > 3.5)):
        warnings.append(f"observation {i}: residual {np.hypot(*r1[i]):.2f} px is an outlier (> 3.5 sigma); "
                        "check the GCP's identification")
    err0 = _ground_error(sensor, pose_with_biases(pose, telemetry, tq, heading_bias_deg, time_offset_s), uv, llh,
                         p_gcp)
    err1 = _ground_error(s_cal, pose_with_biases(pose, telemetry, tq, hb, dt), uv, llh, p_gcp)
    nan2 = np.where(used[:, None], 0.0, np.nan)
    return Calibration(names, sol.x, cov, s0, r0 + nan2, r1 + nan2, np.where(used, err0, np.nan),
                       np.where(used, err1, np.nan), used, s_cal, hb, dt, warnings, undetermined)


def _ground_error(sensor: SensorModel, pose: Pose, uv: np.ndarray, llh: np.ndarray, p_gcp: np.ndarray) -> np.ndarray:
    """Horizontal distance (m) between each GCP and its pixel located at the GCP's own height."""
    f = locate_ellipsoid(sensor, pose, llh[:, 2], (uv[:, 0], uv[:, 1]))
    enu = np.einsum("nji,nj->ni", geodesy.R_ecef_enu(llh[:, 0], llh[:, 1]), f.p_ecef() - p_gcp)
    return np.hypot(enu[:, 0], enu[:, 1])
