"""M6 - static targets over many frames: recursive least squares with a forgetting factor ([Z15] §3.2.2).

A static target's position x is the same in every frame; each frame's fix z_k = x + e_k. In a
local metric frame (ENU at ``origin``), with the fix's covariance R_k as its weight, RLS with
forgetting factor lam (0 < lam <= 1) minimises sum_k lam^(n-k) (z_k - x)^T R_k^-1 (z_k - x):

    A_k = lam A_{k-1} + R_k^-1            (information)
    x_k = x_{k-1} + A_k^-1 R_k^-1 (z_k - x_{k-1})

lam = 1 is the weighted mean of all frames; lam < 1 forgets old frames (memory about
1 / (1 - lam) frames) so a slowly drifting error or a target that moved is followed. The
estimate's covariance for independent frame errors is A^-1 B A^-1 with B_k = lam^2 B_{k-1} + R_k^-1
(exact with forgetting; A^-1 alone would overstate it).

What averaging cannot do: errors that stay the same from frame to frame (attitude and
installation biases, a DEM datum) do not average out, and those that wander slowly (an INS's
attitude) only partly. Given the fixes' error structure (:class:`eoloc.accuracy.FixCovariance`
from a budget whose sources say "bias", "noise" or "markov", :mod:`eoloc.accuracy.budget`), the
estimate's covariance is exact for the linearised errors (:class:`RLSState`): a bias is counted
once, whatever the number of frames. Each fix is weighted by its random part, its horizontal block
and up taken apart with a stated floor (:func:`weights`): the near-singular 3-D covariance of a
fix on a surface must not make a false certainty. Fixes that do not agree with one point (a
chi-square test, :meth:`RLSState.consistent`) give status INCONSISTENT, not a mean point.

Without a structure (a covariance per fix only), ``correlated_fraction`` says what share of
each fix's covariance is common to all frames; the reported covariance then keeps that share
undiminished. By default ("auto") it is estimated per target from ``scatter_ratio``, the frames'
horizontal scatter about the estimate against their declared covariance: about 1 for independent
errors, 1 - c when a share c of the declared error is common to all frames (so c = 1 - ratio).
This needs a declared covariance that is right in total and a few tens of frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from statistics import NormalDist
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..accuracy.cep import cep_zero_mean, error_ellipses
from ..errors import InputError
from ..result import Fixes, Status

if TYPE_CHECKING:
    from ..accuracy.covariance import FixCovariance


@dataclass(frozen=True)
class StaticEstimate:
    """RLS result for K targets over F frames (the last axis of the fixes is the target).

    lat_deg, lon_deg, h_m (K,): final estimate; cov_enu (K, 3, 3) its covariance (m^2, ENU);
    enu_m (F, K, 3): the running estimate after each frame, in the ENU frame at ``origin``
    (lat deg, lon deg, h m), NaN before a target's first fix; sigma_m (F, K, 3): its running 1-sigma;
    n_used (K,): fixes used; converged_frame (K,): first frame index from which the estimate has
    moved less than the tolerance over the preceding ``window`` frames and stays so (-1: never);
    scatter_ratio (K,): mean of (z - x)^T R^-1 (z - x) / 2 over the frames, horizontal; status (K,)
    OK, or INCONSISTENT where the fixes do not agree with one point (:meth:`RLSState.consistent`;
    only with a declared covariance): then the point is no estimate of the target.
    """

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    cov_enu: np.ndarray
    enu_m: np.ndarray
    sigma_m: np.ndarray
    n_used: np.ndarray
    converged_frame: np.ndarray
    scatter_ratio: np.ndarray
    origin: tuple[float, float, float]
    status: np.ndarray | int = 0
    cov_by_kind: dict[str, np.ndarray] | None = None  # with an error structure: the covariance of the
    # biases, the noise and the Gauss–Markov errors alone ("bias", "noise", "markov"), summing to cov_enu

    @property
    def cep50_m(self) -> np.ndarray:
        """Predicted CEP50 of each final estimate (zero-mean, from cov_enu), metres."""
        e = error_ellipses(self.cov_enu[..., :2, :2])
        return cep_zero_mean(e[..., 0], e[..., 1], 0.5)


SCATTER_LIMIT = 3.0  # scatter ratio (mean chi^2 / 2 per frame, 1 expected) past which a "static" target is not
# static: it moved, or its sigma is optimistic
INCONSISTENT_P = 1e-3  # false-alarm probability of the consistency test (independent errors)
WEIGHT_FLOOR = 1e-2  # no fix weighs a horizontal direction more than 1 / (1 % of its largest variance)


def check_forgetting(forgetting: float) -> None:
    if not 0.0 < forgetting <= 1.0:
        raise ValueError(f"forgetting factor must be in (0, 1], got {forgetting!r}")


def weights(R: np.ndarray, use: np.ndarray) -> np.ndarray:
    """The weight of each fix used (0 for the others): the inverse of its covariance taken as a
    horizontal block and an independent up, the horizontal block's smaller eigenvalue floored at
    :data:`WEIGHT_FLOOR` x the larger (a 1 mm floor besides keeps a height stop's zero up variance
    invertible). Why: the 3-D covariance of a fix stopped on a surface is nearly singular (a fix on a
    DEM facet "knows" the facet's normal to a micrometre), and the information of fixes on
    differently tilted facets, seen from different sides, would add up to a false certainty of
    millimetres. Any weights give an unbiased estimate; its covariance is computed for the weights
    used (the sandwich A^-1 P A^-1), so the floor costs a little efficiency, never honesty."""
    Rw = np.where(use[..., None, None], R, np.eye(3))
    a, b, d = Rw[..., 0, 0], Rw[..., 0, 1], Rw[..., 1, 1]
    half = 0.5 * (a + d)
    root = np.sqrt(np.maximum(0.25 * (a - d) ** 2 + b * b, 0.0))
    lo, hi = half - root, half + root
    add = np.maximum(WEIGHT_FLOOR * hi - lo, 0.0) + (1e-3) ** 2
    a, d = a + add, d + add
    det = a * d - b * b
    W = np.zeros(R.shape)
    W[..., 0, 0], W[..., 1, 1] = d / det, a / det
    W[..., 0, 1] = W[..., 1, 0] = -b / det
    W[..., 2, 2] = 1.0 / (Rw[..., 2, 2] + (1e-3) ** 2)
    return np.where(use[..., None, None], W, 0.0)


def chi2_quantile(p: float, dof: ArrayLike) -> np.ndarray:
    """The p-quantile of a chi-square law with ``dof`` degrees of freedom (Wilson–Hilferty, the
    normal quantile from the standard library: no scipy import in a live session). At p = 0.999
    within 2.5 % of scipy's at dof 2, 0.3 % at 20, 0.06 % at 76 (tested), a little above it, the
    safe side for a test that should not call a consistent target inconsistent."""
    k = np.asarray(dof, dtype=np.float64)
    z = NormalDist().inv_cdf(p)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = 2.0 / (9.0 * k)
        return k * (1.0 - c + z * np.sqrt(c)) ** 3


@dataclass
class RLSState:
    """The running state of RLS for K targets, one frame at a time (:meth:`update`): the batch
    :func:`rls_static` steps it over its frames, `eoloc live` packet by packet.

    The estimate: information A = sum lam^(n-k) W_k and the recursive mean x. Its covariance is the
    sandwich A^-1 P A^-1, P = sum_j sum_k lam^(n-j) lam^(n-k) W_j C_jk W_k, with C_jk the covariance
    between the errors of fixes j and k. Given each fix's error structure (``a``: every budget
    source's 1-sigma effect on it, and each source's correlation time), P is kept exactly for
    the linearised errors by one recursion over the sources: per source s, M_s (the weighted
    effects of the past fixes, decayed by lam exp(-dt / tau_s) since) and

        P <- lam^2 P + sum_s (g_s g_s^T + g_s M_s^T + M_s g_s^T),  M_s <- lam exp(-dt/tau_s) M_s + g_s,

    g_s = W a_s: a bias (tau infinite) never averages down, noise (tau 0) does as 1/n, a Gauss–Markov
    error in between. Without a structure every fix's covariance counts as independent noise and
    the common share is guessed from the scatter (``correlated_fraction``, see the module notes).
    The sums of the horizontal scatter about the present estimate are kept too (exact for
    forgetting = 1, as the batch's)."""

    A: np.ndarray
    P: np.ndarray
    Rsum: np.ndarray
    wsum: np.ndarray
    x: np.ndarray
    lam: float
    n: np.ndarray  # fixes used
    s0: np.ndarray  # sum of z_h^T W2 z_h
    s1: np.ndarray  # sum of W2 z_h
    s2: np.ndarray  # sum of W2 (W2: the horizontal block's inverse)
    M: np.ndarray | None = None  # (K, 3, S) with an error structure
    tau_s: np.ndarray | None = None  # (S,)
    t_s: np.ndarray | None = None  # (K,) time of each target's last fix
    P_kinds: np.ndarray | None = None  # (K, 3, 3, 3): P's share of the biases, the noise, the Gauss–Markov errors

    @classmethod
    def empty(cls, k: int, forgetting: float = 1.0) -> RLSState:
        check_forgetting(forgetting)
        z3 = np.zeros((k, 3, 3))
        return cls(z3, z3.copy(), z3.copy(), np.zeros(k), np.full((k, 3), np.nan), float(forgetting),
                   np.zeros(k, np.int64), np.zeros(k), np.zeros((k, 2)), np.zeros((k, 2, 2)))

    @property
    def structured(self) -> bool:
        return self.M is not None

    def grow(self, k: int) -> None:
        """``k`` more targets (empty: no fix yet), after those there are."""
        more = RLSState.empty(k, self.lam)
        for name in ("A", "P", "Rsum", "wsum", "x", "n", "s0", "s1", "s2"):
            setattr(self, name, np.concatenate([getattr(self, name), getattr(more, name)]))
        if self.M is not None:
            self.M = np.concatenate([self.M, np.zeros((k, 3, self.M.shape[-1]))])
            self.t_s = np.concatenate([self.t_s, np.full(k, np.nan)])
            self.P_kinds = np.concatenate([self.P_kinds, np.zeros((k, 3, 3, 3))])

    def update(self, z: np.ndarray, R: np.ndarray, W: np.ndarray, use: np.ndarray, *, a: np.ndarray | None = None,
               tau_s: np.ndarray | None = None, time_s: float = np.nan) -> None:
        """One frame: fixes z (K, 3) ENU m, covariances R (K, 3, 3), weights W (:func:`weights`),
        ``use`` (K,) which fixes count; with an error structure, ``a`` (K, 3, S) each source's
        1-sigma effect on each fix (m, the same frame as z), ``tau_s`` (S,) their correlation
        times (0 noise, inf bias) and the frame's ``time_s``."""
        lam = self.lam
        self.A = lam * self.A + W
        self.wsum = lam * self.wsum + use
        self.Rsum = lam * self.Rsum + np.where(use[:, None, None], R, 0.0)
        if a is None:
            if self.M is not None:
                raise ValueError("this filter was started with an error structure: every update needs one")
            self.P = lam * lam * self.P + np.einsum("kij,kjl,kml->kim", W, np.where(use[:, None, None], R, 0.0), W)
        else:
            self._structured(W, use, a, np.asarray(tau_s, dtype=np.float64), float(time_s))
        x = self.x
        first = use & ~np.isfinite(x[:, 0])
        x[first] = z[first]
        upd = use & ~first
        if upd.any():
            gain = np.linalg.solve(self.A[upd], W[upd])  # A^-1 W
            x[upd] = x[upd] + np.einsum("kij,kj->ki", gain, z[upd] - x[upd])
        W2 = np.linalg.inv(np.where(use[:, None, None], R, np.eye(3))[:, :2, :2] + (1e-3) ** 2 * np.eye(2))
        zh = np.where(use[:, None], z[:, :2], 0.0)
        W2 = np.where(use[:, None, None], W2, 0.0)
        self.n += use
        self.s0 += np.einsum("ki,kij,kj->k", zh, W2, zh)
        self.s1 += np.einsum("kij,kj->ki", W2, zh)
        self.s2 += W2

    def _structured(self, W: np.ndarray, use: np.ndarray, a: np.ndarray, tau: np.ndarray, t: float) -> None:
        k_n, s_n = a.shape[0], a.shape[-1]
        if self.M is None:
            if self.n.any():
                raise ValueError("this filter was started without an error structure: no update may have one")
            self.M, self.tau_s, self.t_s = np.zeros((k_n, 3, s_n)), tau.copy(), np.full(k_n, np.nan)
            self.P_kinds = np.zeros((k_n, 3, 3, 3))
        elif self.M.shape[-1] != s_n or not np.array_equal(self.tau_s, tau):
            raise ValueError("the error structure changed between updates (other sources or time constants)")
        lam = self.lam
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            dt = np.where(np.isfinite(self.t_s), t - self.t_s, np.inf)  # (K,)
            if np.any(dt < 0):
                raise ValueError("fixes must come in time order")
            r = np.exp(-dt[:, None] / tau[None, :])  # (K, S): 1 bias, 0 noise (and first fixes)
        r = np.where(np.isnan(r), np.where(np.isinf(tau), 1.0, 0.0)[None, :], r)  # dt 0 x tau 0, dt inf x tau inf
        r = np.where(use[:, None], r, 1.0)  # a target not seen now: its memory ages at its next fix
        g = np.einsum("kij,kjs->kis", W, np.where(use[:, None, None], a, 0.0))
        Md = lam * self.M * r[:, None, :]
        kind = np.stack([np.isinf(tau), tau == 0, np.isfinite(tau) & (tau > 0)], -1).astype(np.float64)  # (S, 3)
        cross = np.einsum("kis,kjs,sq->kijq", g, Md, kind)
        self.P_kinds = lam * lam * self.P_kinds + np.einsum("kis,kjs,sq->kijq", g, g, kind) + cross + \
            np.swapaxes(cross, 1, 2)
        self.P = self.P_kinds.sum(-1)
        self.M = Md + g
        self.t_s = np.where(use, t, self.t_s)

    def scatter_ratio(self) -> np.ndarray:
        """Mean horizontal (z - x)^T R^-1 (z - x) / 2 over the fixes used, about the present x."""
        xh = np.nan_to_num(self.x[:, :2])
        q = self.s0 - 2.0 * np.einsum("ki,ki->k", xh, self.s1) + np.einsum("ki,kij,kj->k", xh, self.s2, xh)
        with np.errstate(invalid="ignore", divide="ignore"):
            return q / (2.0 * np.maximum(self.n - 1, 0))

    def consistent(self) -> np.ndarray:
        """(K,) False where the fixes do not agree with one point: their horizontal chi-square about
        the estimate, 2 (n - 1) scatter_ratio, past its (1 - INCONSISTENT_P) quantile (three fixes
        at least; each fix's whole covariance in the test, so errors common to the fixes, which
        leave no scatter, cannot raise a false alarm). A target that moved, fixes that jump between
        a summit and the slope behind it, or a sigma that is far too small."""
        dof = 2.0 * np.maximum(self.n - 1, 1)
        q = self.scatter_ratio() * dof
        return ~((self.n >= 3) & (q > chi2_quantile(1.0 - INCONSISTENT_P, dof)))

    def covariance(self, correlated_fraction: float | str = "auto", kind: str | None = None) -> np.ndarray:
        """(K, 3, 3): the estimate's covariance, A^-1 P A^-1 with an error structure (``kind``
        "bias", "noise" or "markov": the share of those sources alone); without one the common
        share (``correlated_fraction``, or "auto" from the scatter) kept undiminished."""
        out = np.full((len(self.x), 3, 3), np.nan)
        seen = self.wsum > 0
        Ai = np.linalg.inv(self.A[seen])
        P = self.P if kind is None else self.P_kinds[..., ("bias", "noise", "markov").index(kind)]
        sand = Ai @ P[seen] @ Ai
        if self.structured or kind is not None:
            out[seen] = sand
            return out
        c = (np.clip(1.0 - np.nan_to_num(self.scatter_ratio(), nan=1.0), 0.0, 0.99)
             if correlated_fraction == "auto" else np.full(len(self.x), float(correlated_fraction)))
        c = c[seen][:, None, None]
        out[seen] = (1.0 - c) * sand + c * self.Rsum[seen] / self.wsum[seen][:, None, None]
        return out


def scatter_inflation(ratio: ArrayLike, single_sigma_h_m: ArrayLike, mean_sigma_h_m: ArrayLike) -> np.ndarray:
    """How much to widen a static estimate's sigma whose fixes spread ``ratio`` times more than
    their sigma allows: 1 up to :data:`SCATTER_LIMIT`; past it the target moved (or the sigma is
    optimistic), averaging does not shrink the error, and the uncertainty becomes the fixes' own
    scatter (one fix's sigma times sqrt(ratio)). Arrays broadcast."""
    r = np.asarray(ratio, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        wide = np.maximum(np.sqrt(r), np.asarray(single_sigma_h_m) / np.sqrt(2.0) * np.sqrt(r) /
                          np.asarray(mean_sigma_h_m))
    return np.where(r > SCATTER_LIMIT, wide, 1.0)


def _enu_of(fixes: Fixes, origin) -> np.ndarray:
    return geodesy.ecef_to_enu(fixes.p_ecef(), *origin)


def rls_static(fixes: Fixes, cov_enu: ArrayLike | None = None, *, sigma_m: ArrayLike = 10.0,
               covariance: FixCovariance | None = None, time_s: ArrayLike | None = None,
               forgetting: float = 1.0, correlated_fraction: float | str = "auto", tol_m: float | None = None,
               tol_fraction: float = 0.05, window: int = 30,
               origin: tuple[float, float, float] | None = None, check_consistency: bool = True) -> StaticEstimate:
    """Filter F frames of fixes of K static targets (``fixes`` of shape (F, K) or (F,)).

    covariance: the fixes' :class:`~eoloc.accuracy.FixCovariance` (from the error budget; the
    honest way): each fix weighted by its random part, the estimate's covariance from every
    source's behaviour in time (biases kept whole, noise averaged down, Gauss–Markov errors by
    their correlation over ``time_s``, (F,) s, needed when the budget has such a source), and a
    target whose fixes do not agree with one point gets status INCONSISTENT. Else cov_enu:
    (F, K, 3, 3) per-fix covariance (all taken as independent, the common share guessed from the
    scatter by ``correlated_fraction``), else an isotropic ``sigma_m`` (scalar or (K,) or (F, K)).
    Fixes whose status is not OK or whose covariance is not finite are skipped (that frame does not
    update that target). origin: the local frame (default: the first good fix). forgetting: lam in
    (0, 1]. Convergence: the estimate moved less than ``tol_m`` (default ``tol_fraction`` of the
    single-frame horizontal sigma, sqrt(R_ee + R_nn)) over the last ``window`` frames, and stays so.
    ``check_consistency`` False: no INCONSISTENT status (a Monte Carlo copy of fixes that already
    carry their errors scatters more than they declare, by construction).
    """
    check_forgetting(forgetting)
    if correlated_fraction != "auto" and not 0.0 <= float(correlated_fraction) < 1.0:
        raise ValueError(f"correlated_fraction must be 'auto' or in [0, 1), got {correlated_fraction!r}")
    if window < 1:
        raise ValueError(f"window must be >= 1 frame, got {window!r}")
    single = np.ndim(fixes.status) == 1
    st = np.asarray(fixes.status)
    if st.ndim not in (1, 2):
        raise ValueError(f"fixes must have shape (frames,) or (frames, targets), got {st.shape}")
    a_src = tau = None
    if covariance is not None:
        cov_enu = covariance.cov_enu
        a_src, tau = covariance.scaled_jacobian, covariance.tau_s
    if single:
        fixes = Fixes(*(a[:, None] for a in np.broadcast_arrays(fixes.lat_deg, fixes.lon_deg, fixes.h_m,
                                                                 fixes.range_m, fixes.status)))
        if cov_enu is not None:
            cov_enu = np.asarray(cov_enu)[:, None]
        if a_src is not None:
            a_src = np.asarray(a_src)[:, None]
    f_n, k_n = fixes.status.shape
    if origin is None:
        good = np.flatnonzero(fixes.ok.ravel())
        if good.size == 0:
            raise InputError("no fix with status OK to filter")
        i = good[0]
        origin = tuple(float(np.ravel(a)[i]) for a in (fixes.lat_deg, fixes.lon_deg, fixes.h_m))
    z = _enu_of(fixes, origin)
    if cov_enu is None:
        s2 = np.broadcast_to(np.asarray(sigma_m, dtype=np.float64) ** 2, (f_n, k_n))
        R = s2[..., None, None] * np.eye(3)
    else:
        R = np.broadcast_to(np.asarray(cov_enu, dtype=np.float64), (f_n, k_n, 3, 3))
    times = np.zeros(f_n)
    if a_src is not None:
        # each fix's covariance and source effects turned from its own ENU axes into the origin's
        to_origin = geodesy.enu_turn(geodesy.R_ecef_enu(*origin[:2]), fixes.lat_deg, fixes.lon_deg)
        a_src = to_origin @ np.broadcast_to(a_src, (f_n, k_n, 3, a_src.shape[-1]))
        R = to_origin @ R @ np.swapaxes(to_origin, -1, -2)
        if time_s is not None:
            times = np.broadcast_to(np.asarray(time_s, dtype=np.float64), (f_n,))
        elif np.any(np.isfinite(tau) & (tau > 0)):
            raise InputError("the budget has Gauss–Markov sources: give the fixes' times (time_s) to combine them")
    use = fixes.ok & np.all(np.isfinite(z), -1) & np.all(np.isfinite(R), (-1, -2))
    Rw = R if a_src is None else random_part(a_src, tau, R)
    W = weights(Rw, use)

    state = RLSState.empty(k_n, forgetting)
    hist = np.full((f_n, k_n, 3), np.nan)
    covs = np.full((f_n, k_n, 3, 3), np.nan)
    for k in range(f_n):
        if a_src is None:
            state.update(z[k], R[k], W[k], use[k])
        else:
            state.update(z[k], R[k], W[k], use[k], a=np.nan_to_num(a_src[k]), tau_s=tau, time_s=times[k])
        hist[k] = state.x
        covs[k] = state.covariance(correlated_fraction)
    x = state.x
    scatter = state.scatter_ratio()  # horizontal: a height stop leaves no scatter in up to compare
    n_used = use.sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_h = np.sqrt(np.nanmedian(np.where(use, R[..., 0, 0] + R[..., 1, 1], np.nan), axis=0))
    status = np.where(state.consistent() | (cov_enu is None) | (not check_consistency), Status.OK,
                      Status.INCONSISTENT).astype(np.int8)
    cov, sig = covs[-1], np.sqrt(np.diagonal(covs, axis1=-2, axis2=-1))
    tol = np.broadcast_to(tol_fraction * sigma_h if tol_m is None else float(tol_m), (k_n,))
    conv = _converged_frame(hist, tol, window)
    p = geodesy.enu_to_ecef(np.where((status == Status.OK)[:, None], x, np.nan), *origin)
    lat, lon, h = geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    parts = None if a_src is None else {k: state.covariance(kind=k) for k in ("bias", "noise", "markov")}
    out = StaticEstimate(lat, lon, h, cov, hist, sig, n_used, conv, scatter, tuple(origin), status, parts)
    if single:
        return StaticEstimate(*(a[0] for a in (lat, lon, h, cov)), hist[:, 0], sig[:, 0], n_used[0], conv[0],
                              scatter[0], tuple(origin), status[0], None if parts is None else
                              {k: v[0] for k, v in parts.items()})
    return out


def random_part(a: np.ndarray, tau_s: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The covariance of the sources that change from frame to frame (noise and Gauss–Markov) of
    each fix, from its source effects ``a`` (..., 3, S): what a fix's weight rests on. Where no
    source changes (a budget of biases only) the whole covariance ``R``."""
    keep = np.asarray(tau_s) < np.inf
    ar = np.nan_to_num(a[..., keep])
    Rr = ar @ np.swapaxes(ar, -1, -2)
    tr = np.trace(Rr, axis1=-2, axis2=-1)
    return np.where((tr > 1e-9 * np.trace(R, axis1=-2, axis2=-1))[..., None, None], Rr, R)


def _converged_frame(hist: np.ndarray, tol_m: np.ndarray, window: int) -> np.ndarray:
    """First frame k (>= window) with |x_j - x_k| < tol for all j in [k - window, k] and that stays
    so to the end (an online criterion made definite); -1 if never."""
    f_n, k_n, _ = hist.shape
    out = np.full(k_n, -1, dtype=np.int64)
    if f_n <= window:
        return out
    still = np.zeros((f_n, k_n), dtype=bool)
    for k in range(window, f_n):
        d = np.linalg.norm(hist[k - window:k + 1] - hist[k][None], axis=-1)
        still[k] = np.all(d < tol_m, axis=0) & np.all(np.isfinite(d), axis=0)
    for j in range(k_n):
        bad = np.flatnonzero(~still[window:, j])
        if bad.size == 0:
            out[j] = window
        elif bad[-1] + window < f_n - 1:
            out[j] = bad[-1] + window + 1
    return out
