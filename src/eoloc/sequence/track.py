"""M7 - moving targets: constant-velocity Kalman tracks in a local ENU frame ([Z15] §4.5).

State per track: x = (east, north, v_east, v_north) in metres and m/s, in the ENU frame at
``origin``; the fix's height is carried along (ground targets move on the terrain). Motion: nearly
constant velocity driven by white acceleration of spectral density ``accel_psd`` (m^2/s^3), the
discretised Q of Bar-Shalom's "continuous white noise acceleration" model. Measurement: each fix's
east/north with its covariance (the per-fix covariance of the error budget, else an isotropic
``meas_sigma_m``). Update in Joseph form, P = (I - KH) P (I - KH)^T + K R K^T, which stays
symmetric and positive definite in floating point where the short form does not.

Errors that do not change from frame to frame do not average down in a track either. Given the
fixes' error structure (the budget sources' effects on each fix and their behaviour in time,
:class:`eoloc.accuracy.FixCovariance`), each fix is weighed by its noise only and the biases and
Gauss–Markov errors are carried as *consider* parameters (the Schmidt–Kalman filter: their
cross-covariance with the track state is propagated, exp(-dt / tau) for a Gauss–Markov source, 1 for
a bias, but they are not estimated), so the track's covariance P is that of its true error, bias
included, exact for the linearised errors.

Detections with target ids go to their own track. Without ids (``associate=True``) each frame's
fixes are assigned to the predicted tracks by global nearest neighbour (Hungarian algorithm,
scipy ``linear_sum_assignment``) on the Mahalanobis distance, inside a chi-square gate of
probability ``gate_prob``; an unassigned fix starts a tentative track, confirmed after
``confirm_hits`` updates; a track not updated for ``max_coast_s`` ends.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from .. import geodesy
from ..errors import InputError
from ..result import Fixes

if TYPE_CHECKING:
    from ..accuracy.covariance import FixCovariance

H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class TrackerConfig:
    """accel_psd: white-acceleration spectral density (m^2/s^3; ~ (typical accel)^2 x manoeuvre time;
    0.1 follows vehicles cruising on roads, raise it for manoeuvring targets);
    meas_sigma_m: fix sigma per horizontal axis when no covariance is given; init_speed_sigma_mps:
    prior sigma of each velocity component at a track's start; gate_prob: association gate;
    confirm_hits: updates before a tentative track is confirmed; max_coast_s: time without an
    update after which a track ends."""

    accel_psd: float = 0.1
    meas_sigma_m: float = 10.0
    init_speed_sigma_mps: float = 30.0
    gate_prob: float = 0.999
    confirm_hits: int = 3
    max_coast_s: float = 2.0

    def __post_init__(self) -> None:
        for name in ("accel_psd", "meas_sigma_m", "init_speed_sigma_mps", "max_coast_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"TrackerConfig.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.gate_prob < 1:
            raise ValueError(f"TrackerConfig.gate_prob must be in (0, 1), got {self.gate_prob!r}")


@dataclass
class Track:
    """One target's filtered history. Arrays per update: time_s, state (n, 4) ENU m and m/s,
    cov (n, 4, 4), up_m (n,) the fixes' up, detection (n,) index of the fix used."""

    track_id: str
    time_s: list[float] = field(default_factory=list)
    state: list[np.ndarray] = field(default_factory=list)
    cov: list[np.ndarray] = field(default_factory=list)
    up_m: list[float] = field(default_factory=list)
    detection: list[int] = field(default_factory=list)
    confirmed: bool = False

    @property
    def speed_mps(self) -> np.ndarray:
        s = np.asarray(self.state)
        return np.hypot(s[:, 2], s[:, 3])

    @property
    def heading_deg(self) -> np.ndarray:
        """Course over ground, degrees clockwise from north."""
        s = np.asarray(self.state)
        return np.degrees(np.arctan2(s[:, 2], s[:, 3])) % 360.0

    @property
    def speed_sigma_mps(self) -> np.ndarray:
        """1-sigma of the speed (first order, from the velocity covariance); NaN where the velocity
        is exactly zero (a track's first fix: no direction, so no first-order sigma; unknown is
        not zero)."""
        s, P = np.asarray(self.state), np.asarray(self.cov)
        v = s[:, 2:]
        sp = np.hypot(v[:, 0], v[:, 1])
        g = v / np.maximum(sp, 1e-300)[:, None]
        sig = np.sqrt(np.einsum("ni,nij,nj->n", g, P[:, 2:, 2:], g))
        return np.where(sp > 0.0, sig, np.nan)


@dataclass(frozen=True)
class TrackSet:
    """Tracks (confirmed only unless asked) and, per input fix, the track it went to ("" none)."""

    tracks: list[Track]
    assigned: np.ndarray
    origin: tuple[float, float, float]

    def geodetic(self, track: Track) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Filtered positions of a track as (lat deg, lon deg, h m)."""
        s = np.asarray(track.state)
        enu = np.c_[s[:, 0], s[:, 1], np.asarray(track.up_m)]
        p = geodesy.enu_to_ecef(enu, *self.origin)
        return geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])


def cv_model(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition F and process noise Q of the constant-velocity model over dt seconds."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    q3, q2, q1 = q * dt**3 / 3.0, q * dt**2 / 2.0, q * dt
    Q = np.array([[q3, 0, q2, 0], [0, q3, 0, q2], [q2, 0, q1, 0], [0, q2, 0, q1]])
    return F, Q


def joseph_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update of state x (4,), covariance P (4, 4) with position fix z (2,), covariance R."""
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1 (S and P symmetric)
    x = x + K @ (z - H @ x)
    IKH = np.eye(4) - K @ H
    P = IKH @ P @ IKH.T + K @ R @ K.T
    return x, 0.5 * (P + P.T)


def consider_update(x: np.ndarray, P: np.ndarray, Pxc: np.ndarray, z: np.ndarray, R: np.ndarray,
                    A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Schmidt–Kalman update of state x (4,), covariance P (4, 4) and its cross-covariance Pxc
    (4, C) with C consider parameters of unit variance (each the scaled error of one budget source),
    by a position fix z (2,) = H x + A c + noise of covariance R (2, 2), A (2, C)."""
    HP = H @ P + A @ Pxc.T  # cov(z, x)
    S = H @ P @ H.T + H @ Pxc @ A.T + A @ Pxc.T @ H.T + A @ A.T + R
    K = np.linalg.solve(S, HP).T
    x = x + K @ (z - H @ x)
    P = P - K @ S @ K.T
    Pxc = Pxc - K @ (H @ Pxc + A)
    return x, 0.5 * (P + P.T), Pxc


class _Live:
    __slots__ = ("P", "Pxc", "hits", "t", "track", "x")

    def __init__(self, track: Track, x, P, t, Pxc=None):
        self.track, self.x, self.P, self.t, self.hits, self.Pxc = track, x, P, t, 1, Pxc


def track_fixes(time_s: ArrayLike, fixes: Fixes, cov_enu: ArrayLike | None = None, target_id: ArrayLike | None = None,
                *, covariance: FixCovariance | None = None, associate: bool | None = None,
                config: TrackerConfig | None = None, origin: tuple[float, float, float] | None = None,
                include_tentative: bool = False, progress=None) -> TrackSet:
    """Track N fixes (1-D ``fixes``; ``time_s`` (N,) seconds; ``cov_enu`` (N, 3, 3) m^2 or None;
    ``target_id`` (N,) or None). ``covariance``: the fixes' FixCovariance instead of cov_enu (the
    honest way: biases and Gauss–Markov errors as consider parameters, see the module notes).
    ``associate`` defaults to True when no ids are given. Fixes whose status is not OK are left
    out (assigned ""). ``progress(done, total)`` is called per frame."""
    cfg = config or TrackerConfig()
    t = np.asarray(time_s, dtype=np.float64).ravel()
    n = t.size
    if np.size(fixes.status) != n:
        raise ValueError(f"time_s has {n} entries but there are {np.size(fixes.status)} fixes")
    if associate is None:
        associate = target_id is None
    if not associate and target_id is None:
        raise InputError("without target ids the fixes must be associated (associate=True)")
    ok = np.ravel(fixes.ok) & np.isfinite(t)
    if origin is None:
        if not ok.any():
            raise InputError("no fix with status OK to track")
        i = int(np.flatnonzero(ok)[0])
        origin = tuple(float(np.ravel(a)[i]) for a in (fixes.lat_deg, fixes.lon_deg, fixes.h_m))
    z = geodesy.ecef_to_enu(fixes.flat().p_ecef(), *origin)
    A = tau = None
    if covariance is not None or cov_enu is not None:  # each fix's covariance, in its own ENU axes: turned
        turn = geodesy.enu_turn(geodesy.R_ecef_enu(*origin[:2]), np.ravel(fixes.lat_deg), np.ravel(fixes.lon_deg))
    if covariance is not None:
        keep = covariance.tau_s > 0  # noise stays in the fix's weight, the rest is considered
        tau = covariance.tau_s[keep]
        a = np.asarray(covariance.scaled_jacobian).reshape(n, 3, -1)
        A = (turn @ a)[:, :2][..., keep]  # the considered sources' effects, in the tracks' axes
        noise = a[..., ~keep]
        cov_enu = np.where(np.isfinite(a).all(axis=(-1, -2))[:, None, None], noise @ np.swapaxes(noise, -1, -2),
                           np.nan)  # the noise, in each fix's own axes (turned below)
    if cov_enu is None:
        R = np.broadcast_to(cfg.meas_sigma_m**2 * np.eye(2), (n, 2, 2))
    else:
        R = (turn @ np.asarray(cov_enu, dtype=np.float64).reshape(n, 3, 3) @ np.swapaxes(turn, -1, -2))[:, :2, :2]
        ok &= np.all(np.isfinite(R), (-1, -2))
    ids = None if target_id is None else np.asarray(target_id).ravel().astype(str)
    tracker = Tracker(cfg, associate)
    assigned = np.full(n, "", dtype=object)
    good = np.flatnonzero(ok)
    good = good[np.argsort(t[good], kind="stable")]
    frames, starts = np.unique(t[good], return_index=True)
    for fi, (tk, here) in enumerate(zip(frames, np.split(good, starts[1:]), strict=True)):
        for key, j in tracker.frame(tk, here, z, R, ids, A=A, tau_s=tau):
            assigned[j] = key
        if progress is not None:
            progress(fi + 1, frames.size)
    keep = [tr for tr in tracker.tracks() if tr.confirmed or include_tentative]
    kept = {tr.track_id for tr in keep}
    assigned = np.array([a if a in kept else "" for a in assigned], dtype=object)
    return TrackSet(sorted(keep, key=lambda tr: tr.time_s[0]), assigned, tuple(origin))


class Tracker:
    """The tracks one frame at a time (:meth:`frame`): the batch :func:`track_fixes` steps it over
    its frames, `eoloc live` packet by packet. ``live`` holds the tracks being updated (key ->
    state x, covariance P, time t, the :class:`Track`); a track not updated for
    ``config.max_coast_s`` ends."""

    def __init__(self, config: TrackerConfig | None = None, associate: bool = False) -> None:
        self.cfg = config or TrackerConfig()
        self.associate = associate
        self.gate = chi2.ppf(self.cfg.gate_prob, 2)
        self.live: dict[str, _Live] = {}
        self.done: list[Track] = []
        self.counter = 0

    def frame(self, tk: float, here: np.ndarray, z: np.ndarray, R: np.ndarray, ids: np.ndarray | None, *,
              A: np.ndarray | None = None, tau_s: np.ndarray | None = None) -> list[tuple[str, int]]:
        """Update with the fixes ``here`` (indices into z (N, 3) ENU m, R (N, 2, 2) m^2 and ids
        (N,), or None when associating) at time ``tk`` s; (track key, fix index) for each fix.
        With an error structure, R is each fix's noise and ``A`` (N, 2, C) the effects of its C
        other sources (biases, Gauss–Markov errors of correlation times ``tau_s`` (C,)), carried as
        consider parameters."""
        cfg, live = self.cfg, self.live
        for key in [k for k, lv in live.items() if tk - lv.t > cfg.max_coast_s]:  # ended
            self.done.append(live.pop(key).track)
        pred = {}
        for key, lv in live.items():
            F, Q = cv_model(tk - lv.t, cfg.accel_psd)
            pxc = None
            if lv.Pxc is not None:
                with np.errstate(invalid="ignore"):
                    phi = np.where(np.isinf(tau_s), 1.0, np.exp(-(tk - lv.t) / tau_s))
                pxc = (F @ lv.Pxc) * phi
            pred[key] = (F @ lv.x, F @ lv.P @ F.T + Q, pxc)
        if self.associate:
            R_gate = R if A is None else R + A @ np.swapaxes(A, -1, -2)
            pairs, fresh = _associate(here, z, R_gate, pred, self.gate)
        else:
            pairs = [(ids[j], j) for j in here if ids[j] in live]
            fresh = [j for j in here if ids[j] not in live]
            if len({ids[j] for j in here}) != here.size:
                raise InputError(f"target id repeated within the frame at t = {tk:g} s")
        out = []
        for key, j in pairs:
            lv = live[key]
            x, P, pxc = pred[key]
            if pxc is None:
                lv.x, lv.P = joseph_update(x, P, z[j, :2], R[j])
            else:
                lv.x, lv.P, lv.Pxc = consider_update(x, P, pxc, z[j, :2], R[j], A[j])
            lv.t, lv.hits = tk, lv.hits + 1
            lv.track.confirmed |= lv.hits >= cfg.confirm_hits
            _record(lv, j, z)
            out.append((key, int(j)))
        for j in fresh:
            if self.associate:
                self.counter += 1
                key = f"T{self.counter}"
            else:
                key = ids[j]
            x0 = np.array([z[j, 0], z[j, 1], 0.0, 0.0])
            P0 = np.zeros((4, 4))
            P0[:2, :2] = R[j]
            P0[2, 2] = P0[3, 3] = cfg.init_speed_sigma_mps**2
            pxc = None
            if A is not None:  # the first fix's error: its noise and its considered sources
                P0[:2, :2] += A[j] @ A[j].T
                pxc = np.zeros((4, A.shape[-1]))
                pxc[:2] = A[j]
            lv = _Live(Track(key, confirmed=cfg.confirm_hits <= 1), x0, P0, tk, pxc)
            live[key] = lv
            _record(lv, j, z)
            out.append((key, int(j)))
        return out

    def tracks(self) -> list[Track]:
        """Every track so far: those ended, then those still live."""
        return self.done + [lv.track for lv in self.live.values()]


def smooth_track(track: Track, accel_psd: float) -> tuple[np.ndarray, np.ndarray]:
    """The Rauch–Tung–Striebel fixed-interval smoother over a finished track of the plain
    (not consider) filter: every update's state (n, 4) and covariance (n, 4, 4) given all of the
    track's fixes, before and after it (batch work: a track's first speeds are no longer guesses
    from two fixes)."""
    x, P = np.asarray(track.state, dtype=float), np.asarray(track.cov, dtype=float)
    xs, Ps = x.copy(), P.copy()
    for k in range(len(x) - 2, -1, -1):
        F, Q = cv_model(track.time_s[k + 1] - track.time_s[k], accel_psd)
        x_pred, P_pred = F @ x[k], F @ P[k] @ F.T + Q
        C = np.linalg.solve(P_pred, F @ P[k]).T  # P F^T P_pred^-1 (both symmetric)
        xs[k] = x[k] + C @ (xs[k + 1] - x_pred)
        Ps[k] = P[k] + C @ (Ps[k + 1] - P_pred) @ C.T
        Ps[k] = 0.5 * (Ps[k] + Ps[k].T)
    return xs, Ps


def _record(lv: _Live, j: int, z: np.ndarray) -> None:
    tr = lv.track
    tr.time_s.append(float(lv.t))
    tr.state.append(lv.x.copy())
    tr.cov.append(lv.P.copy())
    tr.up_m.append(float(z[j, 2]))
    tr.detection.append(int(j))


def _associate(here: np.ndarray, z: np.ndarray, R: np.ndarray, pred: dict, gate: float):
    """Global nearest neighbour inside the gate: [(track key, fix index)], [unassigned fixes]."""
    keys = list(pred)
    if not keys or here.size == 0:
        return [], list(here)
    cost = np.full((len(keys), here.size), np.inf)
    for a, key in enumerate(keys):
        x, P = pred[key][:2]
        S = H @ P @ H.T + R[here]  # (m, 2, 2)
        r = z[here, :2] - (H @ x)[None]
        d2 = np.einsum("mi,mi->m", r, np.linalg.solve(S, r[..., None])[..., 0])
        cost[a] = np.where(d2 <= gate, d2 + np.log(np.linalg.det(S)), np.inf)
    big = 1e12
    rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, big))
    pairs = [(keys[r], int(here[c])) for r, c in zip(rows, cols, strict=True) if np.isfinite(cost[r, c])]
    used = {j for _, j in pairs}
    return pairs, [int(j) for j in here if j not in used]


def track_features(ts: TrackSet) -> list[dict]:
    """GeoJSON features: one LineString per track (lon, lat, h) with the time of every vertex in
    ``coordTimes`` (seconds, the convention of togeojson/GPX converters), the final speed and
    heading with their sigma."""
    out = []
    for tr in ts.tracks:
        lat, lon, h = ts.geodetic(tr)
        speed, sig, hdg = tr.speed_mps, tr.speed_sigma_mps, tr.heading_deg
        coords = [[float(a), float(b), float(c)] for a, b, c in zip(lon, lat, h, strict=True)]
        geom = {"type": "LineString", "coordinates": coords} if len(coords) > 1 else \
            {"type": "Point", "coordinates": coords[0]}
        props = {"track_id": tr.track_id, "start_s": tr.time_s[0], "end_s": tr.time_s[-1], "updates": len(tr.time_s),
                 "speed_mps": round(float(speed[-1]), 3), "speed_sigma_mps": round(float(sig[-1]), 3),
                 "heading_deg": round(float(hdg[-1]), 2),
                 "coordTimes": [round(t, 4) for t in tr.time_s]}
        out.append({"type": "Feature", "geometry": geom, "properties": props})
    return out

