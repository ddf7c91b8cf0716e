"""Bundle adjustment of what the telemetry gets wrong, from tie points and the DEM.

Unknowns: the installation, heading bias and time offset of :mod:`eoloc.sequence.calibration` (any
of its groups: ``mount``, ``boresight``, ``heading``, ``time``, ``position``), shared by every
frame, each keyframe's own small attitude correction (``frame_sigma_deg``), and the ground position
of every tie-point track (three metres east, north, up from where the starting poses put it).
Observations, each weighted by its standard deviation:

- every tie point's pixel (``pixel_sigma_px``): the sensor's own ground -> image projection at
  the frame's pose (the telemetry interpolated at the frame's time + the time offset, the
  heading bias taken out of the yaw), so the residuals are in pixels;
- every track's height against the DEM under it (``dem_sigma_m``, the DEM's stated vertical
  accuracy): a soft constraint, the only thing that ties a relative solution to the ground;
- a prior on every global unknown (its budget's 1-sigma: ``prior_sigma``).

Solved by Levenberg-Marquardt on the reduced normal equations (each track's 3 x 3 block eliminated:
the Schur complement; each pixel depends on the globals, its own keyframe's attitude correction and
its own track only, so one Jacobian costs the globals + 3 + 3 function evaluations, not 3T; the sums
as sparse products), a robust soft-L1 pass first, then the observations whose residual exceeds
``outlier_sigma`` dropped (named by track; on the tie points' own noise where it is below
``pixel_sigma_px``: :func:`outlier_scale_px`) and a plain least-squares pass. The globals'
covariance is the Schur complement of the tracks' blocks in J^T J, scaled by the a-posteriori
variance factor when it exceeds 1.

What the geometry cannot separate is said, not hidden: a parameter whose posterior sigma is more
than ``prior_share`` of its prior's has not been determined by the images (its value is the
prior's), and pairs correlated beyond 0.95 are named (a straight pass over flat ground cannot tell a
heading bias from a time offset or the mount's yaw).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..rules import StopRule
from ..sensor.model import CameraFrame, Pose, SensorModel
from ..sequence.calibration import (
    GROUPS,
    Estimates,
    TelemetryTrack,
    apply_parameters,
    correlation_warnings,
    pose_with_biases,
)
from ..terrain import DEM
from .register import ControlPoints
from .tiepoints import TiePoints

#: calibrate's groups, and a constant position bias of the GPS (east, north, up of the aircraft, m;
#: measured = true + bias): only a reference (control points) or strong relief determines it
REFINE_GROUPS = {**GROUPS, "position": ("position_e_m", "position_n_m", "position_u_m")}
PRIOR_SIGMA = {"mount": 1.0, "boresight": 1.0, "heading": 2.0, "time": 0.5, "position": 5.0}  # deg, deg, deg, s, m
GLOBAL_STEP = 1e-5  # forward-difference steps: deg or s for the globals
GROUND_STEP_M = 1e-3  # and metres for the tracks (ECEF has ~1e-9 m resolution)
UNSEEN = 1e3  # the residual (in sigmas) of an observation that cannot be projected
#: each keyframe's own attitude error (deg, 1-sigma about each body axis) that the telemetry's
#: records do not resolve: INS noise, isolator vibration, an interpolation between records
FRAME_SIGMA_DEG = 0.01


def outlier_scale_px(residual_px: np.ndarray, pixel_sigma_px: float) -> float:
    """The pixel scale outliers are judged on: the tie points' own noise as the robust pass leaves
    it (1.4826 x the median absolute residual per axis, which mismatches do not move) where that is
    below the stated ``pixel_sigma_px`` (clean images: a match 2 px off the rest is then a mismatch
    along the epipolar line that RANSAC let through, not noise), never below a tenth of it."""
    r = np.abs(np.asarray(residual_px, dtype=np.float64))
    r = r[np.isfinite(r)]
    robust = 1.4826 * float(np.median(r)) if r.size >= 20 else pixel_sigma_px
    return min(pixel_sigma_px, max(robust, 0.1 * pixel_sigma_px))


@dataclass(frozen=True)
class AdjustSettings:
    """estimate: the groups solved for; pixel_sigma_px: a tie point's pixel noise; dem_sigma_m:
    the DEM's vertical 1-sigma; prior_sigma: each group's prior 1-sigma (deg or s) around the
    starting value; outlier_sigma: observations past this many sigma after the robust pass are
    dropped; prior_share: a posterior sigma above this share of the prior's = not determined;
    frame_sigma_deg: each keyframe's own attitude error (roll, pitch, yaw corrections per frame,
    with this prior 1-sigma; 0: none), without which a per-frame error the records cannot show
    would be fitted by the shared biases, and their sigma would claim too much."""

    estimate: tuple[str, ...] = ("mount", "heading", "time")
    pixel_sigma_px: float = 1.0
    dem_sigma_m: float = 10.0
    prior_sigma: dict[str, float] = field(default_factory=lambda: dict(PRIOR_SIGMA))
    outlier_sigma: float = 4.0
    prior_share: float = 0.5
    frame_sigma_deg: float = FRAME_SIGMA_DEG

    def __post_init__(self) -> None:
        bad = [g for g in self.estimate if g not in REFINE_GROUPS]
        if bad or not self.estimate:
            raise InputError(f"estimate: unknown or no groups {bad or list(self.estimate)}; choose from "
                             f"{', '.join(REFINE_GROUPS)}")
        if not (self.pixel_sigma_px > 0 and self.dem_sigma_m > 0 and self.outlier_sigma > 0
                and 0 < self.prior_share <= 1 and self.frame_sigma_deg >= 0):
            raise InputError(f"adjustment settings out of range: {self}")
        missing = [g for g in self.estimate if not self.prior_sigma.get(g, 0) > 0]
        if missing:
            raise InputError(f"no prior sigma for {', '.join(missing)}")


@dataclass(frozen=True)
class Refinement(Estimates):
    """The adjustment's answer: ``names``/``values``/``cov`` of the globals (deg, s), the sensor
    with the installation estimated, the heading bias and time offset to apply, the tracks' ground
    points (lat, lon, h (T,), NaN for dropped tracks), pixel residuals before/after (N, 2) (NaN for
    dropped observations), the variance factor ``s0``, the parameters the images did not
    determine, the outlier tracks and warnings."""

    names: tuple[str, ...]
    values: np.ndarray
    cov: np.ndarray
    prior_sigma: np.ndarray
    sensors: list[SensorModel]
    heading_bias_deg: float
    time_offset_s: float
    track_lat_deg: np.ndarray
    track_lon_deg: np.ndarray
    track_h_m: np.ndarray
    residual_px_before: np.ndarray
    residual_px_after: np.ndarray
    s0: float
    n_observations: int
    n_tracks: int
    undetermined: list[str] = field(default_factory=list)
    outlier_tracks: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    n_control: int = 0  # control points (frame pixels matched to a reference) used
    control_residual_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    frame_attitude_deg: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3) roll, pitch, yaw
    frame_attitude_sigma_deg: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))



class _Problem:
    """The weighted residuals of one set of observations: rows = 2 per tie-point observation (u, v),
    1 per track (its height against the DEM), 1 per global (its prior); ``row_track`` names the
    track each row depends on (-1: a prior's row, which depends on its global only)."""

    def __init__(self, sensors, frame_sensor, telemetry, frame_time_s, ties: TiePoints, x_ground0, dem,
                 names, g0, prior, s: AdjustSettings, heading0: float, time0: float, *, control=None,
                 control_sigma_m: float = 1.0):
        self.sensors, self.telemetry = sensors, telemetry
        self.frame_time_s, self.ties, self.dem, self.names = frame_time_s, ties, dem, names
        self.s, self.heading0, self.time0 = s, heading0, time0
        # the unknowns g: the globals (names), then with frame_sigma_deg each keyframe's attitude
        # correction (roll, pitch, yaw; deg) around 0
        self.n_globals = len(names)
        self.k = len(frame_time_s) if s.frame_sigma_deg > 0 else 0
        self.g0 = np.r_[g0, np.zeros(3 * self.k)]
        self.prior = np.r_[prior, np.full(3 * self.k, s.frame_sigma_deg)]
        self.p, self.t = self.n_globals + 3 * self.k, ties.n_tracks
        self.x_ground0 = x_ground0  # (T, 3) ECEF
        lat, lon, _ = geodesy.ecef_to_geodetic(*x_ground0.T)
        self.R_ecef_enu = geodesy.R_ecef_enu(lat, lon)  # (T, 3, 3): ENU offsets -> ECEF
        self.uv = np.stack([ties.u_px, ties.v_px], -1)
        self.groups = [np.flatnonzero(np.asarray(frame_sensor)[ties.frame] == k) for k in range(len(sensors))]
        # control tracks (their ground given by a reference): east and north held to it (control_sigma_m)
        self.control = np.zeros(self.t, bool) if control is None else np.asarray(control, bool)
        self.control_ids = np.flatnonzero(self.control)
        self.control_sigma_m = control_sigma_m
        self.row_track = np.r_[np.repeat(ties.track, 2), np.arange(self.t), np.repeat(self.control_ids, 2),
                               np.full(self.p, -1)]
        # each row's keyframe (-1: a row no frame's attitude moves)
        self.row_frame = np.r_[np.repeat(ties.frame, 2), np.full(self.row_track.size - 2 * len(ties), -1)]
        self._frames_key: bytes | None = None
        self._frames: list = []

    def ground(self, d: np.ndarray) -> np.ndarray:
        """(T, 3) ECEF of the tracks moved by ENU offsets d (T, 3)."""
        return self.x_ground0 + np.einsum("tij,tj->ti", self.R_ecef_enu, d)

    def frames(self, g: np.ndarray) -> list:
        """Per sensor: (sensor, its camera frames at the K frames, the poses' focal scales) with
        globals g; the last set reused while g is unchanged (the tracks' derivatives)."""
        key = g.tobytes()
        if self._frames_key != key:
            gg = g[:self.n_globals]
            _, hb, dt = apply_parameters(self.sensors[0], self.names, gg, self.heading0, self.time0)
            pose = shift_position(pose_with_biases(None, self.telemetry, self.frame_time_s, hb, dt),
                                  position_bias(self.names, gg))
            if self.k:
                e = g[self.n_globals:].reshape(self.k, 3)
                pose = dataclasses.replace(pose, roll_deg=pose.roll_deg + e[:, 0], pitch_deg=pose.pitch_deg + e[:, 1],
                                           yaw_deg=pose.yaw_deg + e[:, 2])
            made = []
            for sensor in self.sensors:
                s = apply_parameters(sensor, self.names, gg, self.heading0, self.time0)[0]
                made.append((s, s.camera_frame(pose), np.asarray(pose.focal_scale)))
            self._frames, self._frames_key = made, key
        return self._frames

    def project(self, g: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(N, 2) pixels of every observation's track in its frame with globals g."""
        out = np.full(self.uv.shape, np.nan)
        xg = self.ground(d)
        for (sensor, frame, zoom), rows in zip(self.frames(g), self.groups, strict=True):
            if rows.size == 0:
                continue
            idx = self.ties.frame[rows]
            fr = CameraFrame(*(tuple(np.asarray(x)[idx] for x in frame.R),
                               *(np.asarray(x)[idx] if np.ndim(x) else x
                                 for x in (frame.ox, frame.oy, frame.oz, frame.invalid))))
            u, v = sensor.frame_to_image(fr, xg[self.ties.track[rows]], zoom[idx] if zoom.ndim else zoom)
            out[rows, 0], out[rows, 1] = u, v
        return out

    def residuals(self, g: np.ndarray, d: np.ndarray) -> np.ndarray:
        # a point pushed behind a camera, a frame pushed off the telemetry: a large residual, not a crash
        return np.nan_to_num(self.raw_residuals(g, d), nan=UNSEEN)

    def raw_residuals(self, g: np.ndarray, d: np.ndarray) -> np.ndarray:
        """The residuals, NaN where an observation cannot be projected (behind its camera, or its
        frame's time + the offset outside the telemetry)."""
        r_px = (self.project(g, d) - self.uv) / self.s.pixel_sigma_px
        lat, lon, h = geodesy.ecef_to_geodetic(*self.ground(d).T)
        h_dem = self.dem.height(lat, lon) if self.dem is not None else h
        r_dem = np.nan_to_num((h - h_dem) / self.s.dem_sigma_m)  # off the DEM: no constraint
        r_prior = (g - self.g0) / self.prior
        r_control = (d[self.control_ids, :2] / self.control_sigma_m).ravel()
        return np.concatenate([r_px.ravel(), r_dem, r_control, r_prior])

    def jacobian(self, g: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Forward differences: (R, n_globals) by the globals (one evaluation each), (R, 3) by each
        row's own keyframe's attitude correction (three evaluations: every frame moved at once, as
        a row sees one frame; the corrections' prior rows are left to :meth:`normal`) and (R, 3) by
        each row's own track (three evaluations: every track moved at once, as no row sees two)."""
        raw = self.raw_residuals(g, d)

        def difference(step: np.ndarray) -> np.ndarray:
            col = (self.raw_residuals(g + step, d) - raw) / GLOBAL_STEP
            edge = ~np.isfinite(col)
            if edge.any():  # a step that leaves the telemetry (a frame at its end): the other side's difference
                back = (raw - self.raw_residuals(g - step, d)) / GLOBAL_STEP
                col[edge] = back[edge]
            return np.nan_to_num(col, nan=0.0, posinf=0.0, neginf=0.0)

        Jg = np.empty((r.size, self.n_globals))
        for j in range(self.n_globals):
            step = np.zeros(self.p)
            step[j] = GLOBAL_STEP
            Jg[:, j] = difference(step)
        Jf = np.zeros((r.size, 3))
        for c in range(3 if self.k else 0):
            step = np.zeros(self.p)
            step[self.n_globals + c::3] = GLOBAL_STEP
            Jf[:, c] = np.where(self.row_frame >= 0, difference(step), 0.0)
        Jt = np.zeros((r.size, 3))
        for c in range(3):
            dd = d.copy()
            dd[:, c] += GROUND_STEP_M
            Jt[:, c] = np.nan_to_num((self.raw_residuals(g, dd) - raw) / GROUND_STEP_M, nan=0.0, posinf=0.0,
                                     neginf=0.0)
        Jt[self.row_track < 0] = 0.0
        return Jg, Jf, Jt

    def normal(self, Jg, Jf, Jt, r, w):
        """The normal equations' blocks over all the unknowns g (globals, then the keyframes'
        corrections): A (p, p), B (T, p, 3), C (T, 3, 3), gradients (p,), (T, 3). Sums over each
        track's (and each keyframe's) rows as sparse products: a row belongs to one track and
        one keyframe."""
        from scipy.linalg import block_diag
        from scipy.sparse import csr_matrix

        on = np.flatnonzero(self.row_track >= 0)
        M = csr_matrix((w[on], (self.row_track[on], on)), shape=(self.t, r.size))
        ng, nf = self.n_globals, 3 * self.k
        A = np.zeros((self.p, self.p))
        A[:ng, :ng] = Jg.T @ (Jg * w[:, None])
        B = np.zeros((self.t, self.p, 3))
        for c in range(3):
            B[:, :ng, c] = M @ (Jg * Jt[:, [c]])
        C = np.stack([M @ (Jt * Jt[:, [c]]) for c in range(3)], -1)
        bg = np.zeros(self.p)
        bg[:ng] = Jg.T @ (w * r)
        if self.k:
            rows = np.flatnonzero(self.row_frame >= 0)
            cols = 3 * self.row_frame[rows][:, None] + np.arange(3)  # (n, 3): the row's frame's three columns
            F = csr_matrix(((Jf[rows] * w[rows, None]).ravel(), (cols.ravel(), np.repeat(rows, 3))),
                           shape=(nf, r.size))  # (3K, R): w Jf^T
            A[ng:, :ng] = F @ Jg
            A[:ng, ng:] = A[ng:, :ng].T
            blocks = np.zeros((self.k, 3, 3))  # each keyframe's own 3 x 3
            for i in range(3):
                for j in range(3):
                    blocks[:, i, j] = np.bincount(self.row_frame[rows], weights=w[rows] * Jf[rows, i] * Jf[rows, j],
                                                  minlength=self.k)
            prior = self.prior[ng:]
            A[ng:, ng:] = block_diag(*blocks) + np.diag(1.0 / prior ** 2)
            r_prior = r[r.size - self.p + ng:]  # the corrections' prior rows: (g - 0) / sigma
            bg[ng:] = F @ r + r_prior / prior
            track_rows = self.row_track[rows]
            for c in range(3):
                vals = (Jf[rows] * (w[rows] * Jt[rows, c])[:, None]).ravel()
                B[:, ng:, c] = csr_matrix((vals, (np.repeat(track_rows, 3), cols.ravel())),
                                          shape=(self.t, nf)).toarray()
        return A, B, C, bg, M @ (Jt * r[:, None])

    def solve(self, g: np.ndarray, d: np.ndarray, loss: str, max_iter: int = 50):
        """Levenberg-Marquardt on the reduced (Schur complement) normal equations; ``loss``
        "soft_l1" reweights each row by 1 / sqrt(1 + (r / 2)^2) (IRLS). Returns g, d, the
        residuals, the row weights and the globals' inverse normal matrix."""
        lam = 1e-3
        r = self.residuals(g, d)

        def weights(res):
            return np.ones_like(res) if loss == "linear" else 1.0 / np.sqrt(1.0 + (res / 2.0) ** 2)

        def cost(res):
            if loss == "linear":
                return float(np.sum(res ** 2))
            return float(np.sum(8.0 * (np.sqrt(1 + (res / 2) ** 2) - 1)))

        c0 = cost(r)
        for _ in range(max_iter):
            w = weights(r)
            A, B, C, bg, bt = self.normal(*self.jacobian(g, d, r), r, w)
            improved = False
            while lam < 1e10:
                Cd = C + lam * np.einsum("tii->ti", C)[:, :, None] * np.eye(3) + 1e-12 * np.eye(3)
                Ci = np.linalg.inv(Cd)
                BCi = np.einsum("tpj,tjk->tpk", B, Ci)
                S = A + lam * np.diag(np.diag(A)) - reduce(BCi, B)
                rhs = bg - np.einsum("tpk,tk->p", BCi, bt)
                dg = -np.linalg.solve(S, rhs)
                dd = -np.einsum("tij,tj->ti", Ci, bt + np.einsum("tpj,p->tj", B, dg))
                r_new = self.residuals(g + dg, d + dd)
                c_new = cost(r_new)
                if c_new < c0:
                    g, d, r, lam = g + dg, d + dd, r_new, max(lam / 10, 1e-9)
                    # converged: the cost falls by less than 1e-5 of itself, or the globals move by
                    # less than 1e-6 (deg or s; a weakly seen track may still creep along its ray)
                    improved = (c0 - c_new) > 1e-5 * c0 and np.max(np.abs(dg), initial=0.0) > 1e-6
                    c0 = c_new
                    break
                lam *= 10
            if not improved:
                break
        w = weights(r)
        A, B, C, _, _ = self.normal(*self.jacobian(g, d, r), r, w)
        Ci = np.linalg.pinv(C)
        S = A - reduce(np.einsum("tpj,tjk->tpk", B, Ci), B)
        try:
            S_inv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            S_inv = np.full((self.p, self.p), np.inf)
        return g, d, r, w, S_inv, lam < 1e10


def reduce(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """sum over t and k of X[t, p, k] Y[t, q, k] (p, q), as one matrix product (BLAS)."""
    p = X.shape[1]
    return X.transpose(1, 0, 2).reshape(p, -1) @ Y.transpose(1, 0, 2).reshape(p, -1).T


def position_bias(names: Sequence[str], g: np.ndarray) -> np.ndarray:
    """The position bias (east, north, up m) among the globals ``g`` (zeros where not estimated)."""
    v = dict(zip(names, g, strict=True))
    return np.array([v.get(n, 0.0) for n in REFINE_GROUPS["position"]], dtype=np.float64)


def shift_position(pose: Pose, bias_enu_m: np.ndarray) -> Pose:
    """The poses with a GPS position bias taken out (true = measured - bias, in each pose's ENU)."""
    if not np.any(bias_enu_m):
        return pose
    lat, lon, h = (np.asarray(x, dtype=np.float64) for x in (pose.lat_deg, pose.lon_deg, pose.h_m))
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1) - geodesy.R_ecef_enu(lat, lon) @ bias_enu_m
    la, lo, hh = geodesy.ecef_to_geodetic(p[..., 0], p[..., 1], p[..., 2])
    return dataclasses.replace(pose, lat_deg=la, lon_deg=lo, h_m=hh)


def initial_ground(sensors: Sequence[SensorModel], frame_sensor: np.ndarray, poses: Pose, ties: TiePoints,
                   rule: StopRule) -> np.ndarray:
    """(T, 3) ECEF: each track's observations put on the ground by ``rule`` with the starting poses,
    the median per axis (NaN where none of them was located)."""
    p = np.full((len(ties), 3), np.nan)
    for k, s in enumerate(sensors):
        rows = np.flatnonzero(frame_sensor[ties.frame] == k)
        if rows.size:
            f = rule.locate(s, poses.take(ties.frame[rows]), np.stack([ties.u_px[rows], ties.v_px[rows]], -1))
            p[rows] = np.where(f.ok[:, None], f.p_ecef(), np.nan)
    return grouped_median(ties.track, p, ties.n_tracks)


def grouped_median(group: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, C) median of the finite rows of ``values`` (N, C) in each group (NaN for none)."""
    out = np.full((n_groups, values.shape[1]), np.nan)
    for c in range(values.shape[1]):
        ok = np.isfinite(values[:, c])
        g, v = group[ok], values[ok, c]
        order = np.lexsort((v, g))
        g, v = g[order], v[order]
        counts = np.bincount(g, minlength=n_groups)
        start = np.r_[0, np.cumsum(counts)[:-1]]
        has = counts > 0
        lo = start[has] + (counts[has] - 1) // 2
        hi = start[has] + counts[has] // 2
        out[has, c] = 0.5 * (v[lo] + v[hi])
    return out


def adjust(sensors: Sequence[SensorModel], frame_sensor: np.ndarray, telemetry: TelemetryTrack,
           frame_time_s: np.ndarray, ties: TiePoints, rule: StopRule, dem: DEM | None,
           settings: AdjustSettings = AdjustSettings(), *, heading_bias_deg: float = 0.0,
           time_offset_s: float = 0.0, control: ControlPoints | None = None,
           control_sigma_m: float = 1.0, control_shared_sigma_m: float = 0.0) -> Refinement:
    """Adjust ``settings.estimate`` and the tracks' ground points to the tie points.

    ``sensors``: the distinct sensors; ``frame_sensor`` (K,): each frame's sensor in it;
    ``telemetry``: the pose records on the frames' clock; ``frame_time_s`` (K,) the frames' times;
    ``ties``: observations (frame = position in 0..K-1); ``rule``: puts the tracks on the ground at
    the start; ``dem``: the soft height constraint (None: none, a relative solution);
    ``heading_bias_deg``/``time_offset_s``: the starting values (those not estimated stay);
    ``control``: frame pixels matched to a reference (:mod:`.register`), each a track of one
    observation whose east/north are held to the reference's within ``control_sigma_m`` (each
    point's own error); ``control_shared_sigma_m``: the reference's georeferencing error, which
    all its points share: it moves the whole solution, so it is added to the position bias'
    east/north variance (a shift the points' number cannot average away). The solution is then
    absolute, not only relative + the DEM."""
    s = settings
    frame_sensor = np.asarray(frame_sensor, dtype=np.int64)
    frame_time_s = np.asarray(frame_time_s, dtype=np.float64)
    names = tuple(n for g in s.estimate for n in REFINE_GROUPS[g])
    prior = np.array([s.prior_sigma[g] for g in s.estimate for _ in REFINE_GROUPS[g]], dtype=np.float64)
    base = sensors[0]
    start = {**dict(zip(GROUPS["mount"], base.mount_misalignment_deg, strict=True)),
             **dict(zip(GROUPS["boresight"], base.boresight_misalignment_deg, strict=True)),
             "heading_bias_deg": heading_bias_deg, "time_offset_s": time_offset_s,
             **dict.fromkeys(REFINE_GROUPS["position"], 0.0)}
    g0 = np.array([start[n] for n in names], dtype=np.float64)
    poses0 = pose_with_biases(None, telemetry, frame_time_s, heading_bias_deg, time_offset_s)
    x_ground = initial_ground(sensors, frame_sensor, poses0, ties, rule)
    located = np.isfinite(x_ground[:, 0])
    n_obs = np.bincount(ties.track, minlength=ties.n_tracks)
    keep = located & (n_obs >= 2)
    work = ties.keep_tracks(keep)
    if work.n_tracks < 3 or len(work) < len(names) + 3:
        raise InputError(f"{work.n_tracks} tie-point tracks seen in two frames or more could be put on the ground: "
                         "too few to adjust (the frames must overlap and show texture)")
    ids = np.flatnonzero(keep)  # each working track's id among the caller's tracks; -1: a control point
    x_ground = x_ground[keep]
    n_control = 0 if control is None else len(control)
    if n_control:  # each control point a track of one observation whose ground is known
        c = control
        work = TiePoints(np.r_[work.frame, c.frame], np.r_[work.track, work.n_tracks + np.arange(n_control)],
                         np.r_[work.u_px, c.u_px], np.r_[work.v_px, c.v_px], work.pairs, work.verified)
        x_ground = np.r_[x_ground, np.stack(geodesy.geodetic_to_ecef(c.lat_deg, c.lon_deg, c.h_m), -1)]
        ids = np.r_[ids, np.full(n_control, -1)]
    x_given = x_ground.copy()
    warnings: list[str] = []

    def problem(tp: TiePoints, xg0: np.ndarray, tie_ids: np.ndarray) -> _Problem:
        return _Problem(sensors, frame_sensor, telemetry, frame_time_s, tp, xg0, dem, names, g0, prior, s,
                        heading_bias_deg, time_offset_s, control=tie_ids < 0, control_sigma_m=control_sigma_m)

    prob = problem(work, x_ground, ids)
    d0 = np.zeros((work.n_tracks, 3))
    before = prob.project(prob.g0, d0) - prob.uv
    g, d, _, _, _, _ = prob.solve(prob.g0, d0, "soft_l1", max_iter=8)  # only to find the outliers
    r_px = prob.project(g, d) - prob.uv
    r = r_px / outlier_scale_px(r_px[ids[work.track] >= 0], s.pixel_sigma_px)
    bad_obs = ~(np.hypot(r[:, 0], r[:, 1]) <= s.outlier_sigma)
    outliers = sorted({int(ids[t]) for t in np.unique(work.track[bad_obs]) if ids[t] >= 0})
    bad_control = int(np.sum(bad_obs & (ids[work.track] < 0)))
    if bad_obs.any():
        # drop the outlying observations; a tie track left with one observation goes with them
        left = np.bincount(work.track[~bad_obs], minlength=work.n_tracks)
        good_track = np.where(ids < 0, left >= 1, left >= 2)
        rows = ~bad_obs & good_track[work.track]
        sub = TiePoints(work.frame[rows], work.track[rows], work.u_px[rows], work.v_px[rows], work.pairs,
                        work.verified).keep_tracks(good_track)
        ground_now = prob.ground(d)[good_track]
        ids, x_given = ids[good_track], x_given[good_track]
        before = before[rows]
        work = sub
    else:
        ground_now = prob.ground(d)
    ground_now[ids < 0] = x_given[ids < 0]  # the control points' priors stay on the reference's ground
    prob = problem(work, ground_now, ids)
    g, d, res, _, S_inv, converged = prob.solve(g, np.zeros((work.n_tracks, 3)), "linear")
    dof = res.size - (prob.p + 3 * work.n_tracks)
    s0 = float(np.sqrt(np.sum(res ** 2) / dof)) if dof > 0 else float("nan")
    cov_all = S_inv * max(s0, 1.0) ** 2
    frame_attitude = g[len(names):].reshape(-1, 3)
    frame_sigma = np.sqrt(np.diagonal(cov_all)[len(names):]).reshape(-1, 3)
    g_full, g, cov = g, g[:len(names)], cov_all[:len(names), :len(names)].copy()
    if n_control and control_shared_sigma_m > 0:
        for name in REFINE_GROUPS["position"][:2]:
            if name in names:
                cov[names.index(name), names.index(name)] += control_shared_sigma_m ** 2
    sigma = np.sqrt(np.diagonal(cov))
    undetermined = [n for n, sg, pr in zip(names, sigma, prior, strict=True) if not sg <= s.prior_share * pr]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sigma, sigma)
    warnings += correlation_warnings(names, corr, "a pass with turns, gimbal motion or relief separates them")
    if undetermined:
        warnings.append(f"the images do not determine {', '.join(undetermined)}: its sigma is more than "
                        f"{s.prior_share:.0%} of its prior's, so its value is mostly the prior (the starting value)")
    if not converged:
        warnings.append("the adjustment did not converge (no step lowered the residuals)")
    if outliers:
        warnings.append(f"{len(outliers)} tie-point track(s) had observations past {s.outlier_sigma:g} sigma "
                        "(mismatches or moving objects): those observations were left out")
    if bad_control:
        warnings.append(f"{bad_control} control point(s) matched to the reference were past {s.outlier_sigma:g} sigma "
                        "and left out")
    if not n_control:
        warnings.append("no reference: the adjustment is relative (the frames agree with each other) and held to the "
                        "ground by the DEM only; a reference image (--reference) makes it absolute")
    refined = [apply_parameters(x, names, g, heading_bias_deg, time_offset_s)[0] for x in sensors]
    _, hb, dt = apply_parameters(base, names, g, heading_bias_deg, time_offset_s)
    after = prob.project(g_full, d) - prob.uv
    tie_rows = ids[work.track] >= 0
    control_after = after[~tie_rows]
    lat = np.full(ties.n_tracks, np.nan)
    lon, h = lat.copy(), lat.copy()
    la, lo, hh = geodesy.ecef_to_geodetic(*prob.ground(d).T)
    tie_tracks = ids >= 0
    lat[ids[tie_tracks]], lon[ids[tie_tracks]], h[ids[tie_tracks]] = la[tie_tracks], lo[tie_tracks], hh[tie_tracks]
    rb = np.full((len(ties), 2), np.nan)
    ra = rb.copy()
    # map the adjusted tie observations back onto the caller's rows (by track id and frame)
    key_all = ties.track * (ties.frame.max() + 1) + ties.frame
    key_used = ids[work.track[tie_rows]] * (ties.frame.max() + 1) + work.frame[tie_rows]
    where = np.searchsorted(key_all, key_used, sorter=np.argsort(key_all))
    idx = np.argsort(key_all)[where]
    rb[idx], ra[idx] = before[tie_rows], after[tie_rows]
    return Refinement(names, g, cov, prior, refined, hb, dt, lat, lon, h, rb, ra, s0, int(tie_rows.sum()),
                      int(tie_tracks.sum()), undetermined, outliers, warnings, int((~tie_rows).sum()), control_after,
                      frame_attitude, frame_sigma)
