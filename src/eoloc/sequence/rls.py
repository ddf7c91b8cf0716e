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

What RLS cannot do: errors that stay the same from frame to frame (attitude and installation
biases, a DEM datum) do not average out. ``correlated_fraction`` says what share of each fix's
covariance is such a bias; the reported covariance then keeps that share undiminished, which is the
honest figure. By default ("auto") it is estimated per target from ``scatter_ratio``, the frames'
horizontal scatter about the estimate against their declared covariance: about 1 for independent
errors, 1 - c when a share c of the declared error is common to all frames (so c = 1 - ratio).
This needs a declared covariance that is right in total (e.g. from the error budget) and a few
tens of frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..accuracy.cep import cep_zero_mean, error_ellipses
from ..errors import InputError
from ..result import Fixes


@dataclass(frozen=True)
class StaticEstimate:
    """RLS result for K targets over F frames (the last axis of the fixes is the target).

    lat_deg, lon_deg, h_m (K,): final estimate; cov_enu (K, 3, 3) its covariance (m^2, ENU);
    enu_m (F, K, 3): the running estimate after each frame, in the ENU frame at ``origin``
    (lat deg, lon deg, h m), NaN before a target's first fix; sigma_m (F, K, 3): its running 1-sigma;
    n_used (K,): fixes used; converged_frame (K,): first frame index from which the estimate has
    moved less than the tolerance over the preceding ``window`` frames and stays so (-1: never);
    scatter_ratio (K,): mean of (z - x)^T R^-1 (z - x) / 2 over the frames, horizontal.
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

    @property
    def cep50_m(self) -> np.ndarray:
        """Predicted CEP50 of each final estimate (zero-mean, from cov_enu), metres."""
        e = error_ellipses(self.cov_enu[..., :2, :2])
        return cep_zero_mean(e[..., 0], e[..., 1], 0.5)


SCATTER_LIMIT = 3.0  # scatter ratio (mean chi^2 / 2 per frame, 1 expected) past which a "static" target is not
# static: it moved, or its sigma is optimistic


def check_forgetting(forgetting: float) -> None:
    if not 0.0 < forgetting <= 1.0:
        raise ValueError(f"forgetting factor must be in (0, 1], got {forgetting!r}")


def weights(R: np.ndarray, use: np.ndarray) -> np.ndarray:
    """R^-1 of each fix used (0 for the others). A height stop fixes the up component (zero
    variance): a 1 mm floor keeps R invertible."""
    eye = np.eye(3)
    Rf = np.where(use[..., None, None], R, eye) + (1e-3) ** 2 * eye
    return np.where(use[..., None, None], np.linalg.inv(Rf), 0.0)


@dataclass
class RLSState:
    """The running state of RLS for K targets, one frame at a time (:meth:`update`): the batch
    :func:`rls_static` steps it over its frames, `eoloc live` packet by packet. Besides the
    information A, the B of the covariance, the weighted sum of R and the weights, it keeps the
    sums that give the horizontal scatter ratio about the present estimate without the past fixes
    (exact for forgetting = 1, as the batch's)."""

    A: np.ndarray
    B: np.ndarray
    Rsum: np.ndarray
    wsum: np.ndarray
    x: np.ndarray
    lam: float
    n: np.ndarray  # fixes used
    s0: np.ndarray  # sum of z_h^T W2 z_h
    s1: np.ndarray  # sum of W2 z_h
    s2: np.ndarray  # sum of W2 (W2: the horizontal block's inverse)

    @classmethod
    def empty(cls, k: int, forgetting: float = 1.0) -> RLSState:
        check_forgetting(forgetting)
        z3 = np.zeros((k, 3, 3))
        return cls(z3, z3.copy(), z3.copy(), np.zeros(k), np.full((k, 3), np.nan), float(forgetting),
                   np.zeros(k, np.int64), np.zeros(k), np.zeros((k, 2)), np.zeros((k, 2, 2)))

    def grow(self, k: int) -> None:
        """``k`` more targets (empty: no fix yet), after those there are."""
        more = RLSState.empty(k, self.lam)
        for name in ("A", "B", "Rsum", "wsum", "x", "n", "s0", "s1", "s2"):
            setattr(self, name, np.concatenate([getattr(self, name), getattr(more, name)]))

    def update(self, z: np.ndarray, R: np.ndarray, W: np.ndarray, use: np.ndarray) -> None:
        """One frame: fixes z (K, 3) ENU m, covariances R (K, 3, 3), weights W = :func:`weights`,
        ``use`` (K,) which fixes count."""
        lam = self.lam
        self.A = lam * self.A + W
        self.B = lam * lam * self.B + W
        self.wsum = lam * self.wsum + use
        self.Rsum = lam * self.Rsum + np.where(use[:, None, None], R, 0.0)
        x = self.x
        first = use & ~np.isfinite(x[:, 0])
        x[first] = z[first]
        upd = use & ~first
        if upd.any():
            gain = np.linalg.solve(self.A[upd], W[upd])  # A^-1 R^-1
            x[upd] = x[upd] + np.einsum("kij,kj->ki", gain, z[upd] - x[upd])
        W2 = np.linalg.inv(np.where(use[:, None, None], R, np.eye(3))[:, :2, :2] + (1e-3) ** 2 * np.eye(2))
        zh = np.where(use[:, None], z[:, :2], 0.0)
        W2 = np.where(use[:, None, None], W2, 0.0)
        self.n += use
        self.s0 += np.einsum("ki,kij,kj->k", zh, W2, zh)
        self.s1 += np.einsum("kij,kj->ki", W2, zh)
        self.s2 += W2

    def scatter_ratio(self) -> np.ndarray:
        """Mean horizontal (z - x)^T R^-1 (z - x) / 2 over the fixes used, about the present x."""
        xh = np.nan_to_num(self.x[:, :2])
        q = self.s0 - 2.0 * np.einsum("ki,ki->k", xh, self.s1) + np.einsum("ki,kij,kj->k", xh, self.s2, xh)
        with np.errstate(invalid="ignore", divide="ignore"):
            return q / (2.0 * np.maximum(self.n - 1, 0))

    def covariance(self, correlated_fraction: float | str = "auto") -> np.ndarray:
        """(K, 3, 3): the estimate's covariance (see the module: the bias share kept undiminished)."""
        c = (np.clip(1.0 - np.nan_to_num(self.scatter_ratio(), nan=1.0), 0.0, 0.99)
             if correlated_fraction == "auto" else np.full(len(self.x), float(correlated_fraction)))
        out = np.full((len(self.x), 3, 3), np.nan)
        seen = self.wsum > 0
        out[seen] = _covariance(self.A[seen], self.B[seen], self.Rsum[seen], self.wsum[seen], c[seen])
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
               forgetting: float = 1.0, correlated_fraction: float | str = "auto", tol_m: float | None = None,
               tol_fraction: float = 0.05, window: int = 30,
               origin: tuple[float, float, float] | None = None) -> StaticEstimate:
    """Filter F frames of fixes of K static targets (``fixes`` of shape (F, K) or (F,)).

    cov_enu: (F, K, 3, 3) per-fix covariance (e.g. ``FixCovariance.cov_enu``), else an isotropic
    ``sigma_m`` (scalar or (K,) or (F, K)). Fixes whose status is not OK or whose covariance is
    not finite are skipped (that frame does not update that target). origin: the local frame
    (default: the first good fix). forgetting: lam in (0, 1]. Convergence: the estimate moved less
    than ``tol_m`` (default ``tol_fraction`` of the single-frame horizontal sigma, sqrt(R_ee + R_nn))
    over the last ``window`` frames, and stays so.
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
    if single:
        fixes = Fixes(*(a[:, None] for a in np.broadcast_arrays(fixes.lat_deg, fixes.lon_deg, fixes.h_m,
                                                                 fixes.range_m, fixes.status)))
        if cov_enu is not None:
            cov_enu = np.asarray(cov_enu)[:, None]
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
    use = fixes.ok & np.all(np.isfinite(z), -1) & np.all(np.isfinite(R), (-1, -2))
    W = weights(R, use)

    state = RLSState.empty(k_n, forgetting)
    hist = np.full((f_n, k_n, 3), np.nan)
    Ahist, Bhist, Rhist = (np.zeros((f_n, k_n, 3, 3)) for _ in range(3))
    whist = np.zeros((f_n, k_n))
    for k in range(f_n):
        state.update(z[k], R[k], W[k], use[k])
        hist[k] = state.x
        Ahist[k], Bhist[k], Rhist[k], whist[k] = state.A, state.B, state.Rsum, state.wsum
    x = state.x
    scatter = state.scatter_ratio()  # horizontal: a height stop leaves no scatter in up to compare
    n_used = use.sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_h = np.sqrt(np.nanmedian(np.where(use, R[..., 0, 0] + R[..., 1, 1], np.nan), axis=0))
    c = np.clip(1.0 - np.nan_to_num(scatter, nan=1.0), 0.0, 0.99) if correlated_fraction == "auto" else \
        np.full(k_n, float(correlated_fraction))
    seen = whist > 0
    covs = np.full((f_n, k_n, 3, 3), np.nan)
    covs[seen] = _covariance(Ahist[seen], Bhist[seen], Rhist[seen], whist[seen], np.broadcast_to(c, (f_n, k_n))[seen])
    cov, sig = covs[-1], np.sqrt(np.diagonal(covs, axis1=-2, axis2=-1))
    tol = np.broadcast_to(tol_fraction * sigma_h if tol_m is None else float(tol_m), (k_n,))
    conv = _converged_frame(hist, tol, window)
    p = geodesy.enu_to_ecef(x, *origin)
    lat, lon, h = geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    out = StaticEstimate(lat, lon, h, cov, hist, sig, n_used, conv, scatter, tuple(origin))
    if single:
        return StaticEstimate(*(a[0] for a in (lat, lon, h, cov)), hist[:, 0], sig[:, 0], n_used[0], conv[0],
                              scatter[0], tuple(origin))
    return out


def _covariance(A, B, Rsum, wsum, c: np.ndarray) -> np.ndarray:
    """(1 - c) A^-1 B A^-1 (the independent share, averaged down) + c R_mean (the common share)."""
    Ai = np.linalg.inv(A)
    c = c[:, None, None]
    return (1.0 - c) * (Ai @ B @ Ai) + c * Rsum / wsum[:, None, None]


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
