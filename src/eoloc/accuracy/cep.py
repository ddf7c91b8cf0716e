"""Circular error statistics of 2-D (east, north) errors: empirical and parametric CEP, DRMS, ellipses.

CEP is the radius of the circle centred on the TRUE point that holds a probability p (0.5) of the
errors. The parametric CEP ([Z15] eqs. 23-25) treats the errors as a bivariate normal with means
(mu_x, mu_y), sigmas (sigma_x, sigma_y) and correlation rho and solves P(|X| <= R) = p exactly: in
the principal axes of the covariance the two components are independent, so
    P(|X| <= R) = int_{-R}^{R} phi_1(x) [Phi_2(sqrt(R^2 - x^2)) - Phi_2(-sqrt(R^2 - x^2))] dx,
one 1-D integral (scipy quad) and a root find (brentq) - no rule-of-thumb formula.
DRMS = sqrt(sigma_x^2 + sigma_y^2) is a radial RMS, not a 50 % radius ([Q] eq. 18 computes it and
calls it CEP); it is reported under its own name.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy import integrate, interpolate, optimize, stats

_SQRT_2PI = math.sqrt(2.0 * math.pi)


def _ncdf(x: float) -> float:
    """Standard normal CDF (erfc keeps the tails accurate)."""
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


def cep_empirical(ex: ArrayLike, ey: ArrayLike, p: float = 0.5) -> float:
    """Radius around the true point holding a fraction p of the samples (median for p = 0.5)."""
    r = np.hypot(np.asarray(ex, dtype=np.float64), np.asarray(ey, dtype=np.float64))
    return float(np.quantile(r[np.isfinite(r)], p))


def prob_within(radius: float, mu_x: float, mu_y: float, sigma_x: float, sigma_y: float, rho: float) -> float:
    """P(sqrt(X^2 + Y^2) <= radius) for (X, Y) bivariate normal (exact, by 1-D quadrature)."""
    if radius <= 0.0:
        return 0.0
    cov = np.array([[sigma_x**2, rho * sigma_x * sigma_y], [rho * sigma_x * sigma_y, sigma_y**2]])
    lam, vec = np.linalg.eigh(cov)
    m = vec.T @ np.array([mu_x, mu_y])
    s1, s2 = math.sqrt(max(lam[1], 0.0)), math.sqrt(max(lam[0], 0.0))  # s1 the major axis
    m1, m2 = m[1], m[0]
    if s1 == 0.0:  # no spread: the point itself
        return 1.0 if math.hypot(m1, m2) <= radius else 0.0
    lo, hi = max(-radius, m1 - 12.0 * s1), min(radius, m1 + 12.0 * s1)
    if lo >= hi:
        return 0.0

    def inner(x: float) -> float:
        half = math.sqrt(max(radius * radius - x * x, 0.0))
        if s2 == 0.0:
            band = 1.0 if abs(m2) <= half else 0.0
        else:
            band = _ncdf((half - m2) / s2) - _ncdf((-half - m2) / s2)
        t = (x - m1) / s1
        return math.exp(-0.5 * t * t) / (_SQRT_2PI * s1) * band

    points = [x for x in (m1,) if lo < x < hi]
    value, _ = integrate.quad(inner, lo, hi, points=points or None, epsabs=1e-13, epsrel=1e-11, limit=400)
    return float(min(max(value, 0.0), 1.0))


def cep_bivariate(mu_x: float, mu_y: float, sigma_x: float, sigma_y: float, rho: float = 0.0,
                  p: float = 0.5) -> float:
    """Parametric CEP: the radius R with P(|X| <= R) = p for a bivariate normal with bias."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    if not (sigma_x >= 0 and sigma_y >= 0 and -1.0 <= rho <= 1.0):
        raise ValueError(f"need sigma >= 0 and |rho| <= 1, got {sigma_x}, {sigma_y}, {rho}")
    top = math.hypot(mu_x, mu_y) + 12.0 * math.hypot(sigma_x, sigma_y) + 1e-300
    if sigma_x == 0.0 and sigma_y == 0.0:
        return math.hypot(mu_x, mu_y)
    return float(optimize.brentq(lambda r: prob_within(r, mu_x, mu_y, sigma_x, sigma_y, rho) - p, 0.0, top,
                                 xtol=1e-12 * top, rtol=1e-12))


def drms(sigma_x: float, sigma_y: float) -> float:
    """Radial RMS about the mean, sqrt(sigma_x^2 + sigma_y^2) ([Q] eq. 18's figure, not a CEP)."""
    return math.hypot(sigma_x, sigma_y)


def error_ellipses(cov: ArrayLike, p: float | None = None) -> np.ndarray:
    """(..., 3): semi-major, semi-minor and azimuth of the major axis (degrees clockwise from north,
    in [0, 180)) of the ellipses holding probability p of 2-D normals with covariances ``cov``
    (..., 2, 2) [[ee, en], [en, nn]] (default: the 1-sigma ellipse, p = 1 - e^-0.5 = 39.3 %).
    Closed-form eigen-decomposition of the symmetric 2 x 2 matrices, the minor variance as the
    determinant over the major one (``mid - rad`` would lose its digits to cancellation on a thin
    ellipse: 1e-9 relative at an axis ratio of 7000); NaN in, NaN out."""
    cov = np.asarray(cov, dtype=np.float64)
    ee, nn, en = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1]
    major = 0.5 * (ee + nn) + np.hypot(0.5 * (ee - nn), en)
    with np.errstate(invalid="ignore", divide="ignore"):
        minor = np.where(major > 0, (ee * nn - en * en) / major, 0.0)
    k = 1.0 if p is None else math.sqrt(stats.chi2.ppf(p, 2))
    from_east = np.degrees(0.5 * np.arctan2(2.0 * en, ee - nn))  # direction of the major axis
    return np.stack([k * np.sqrt(major), k * np.sqrt(np.maximum(minor, 0.0)), (90.0 - from_east) % 180.0], -1)


def error_ellipse(cov: ArrayLike, p: float | None = None) -> tuple[float, float, float]:
    """One 2 x 2 covariance's ellipse as (semi-major, semi-minor, azimuth deg): see :func:`error_ellipses`."""
    a, b, az = error_ellipses(cov, p)
    return float(a), float(b), float(az)


_RATIO_MIN = 0.05  # below it CEP(1, r) has an r^2 log r term that a spline does not follow; solved exactly
_RATIO_GRID = np.linspace(_RATIO_MIN, 1.0, 48)


@lru_cache(maxsize=8)
def _zero_mean_table(p: float):
    """CEP / sigma_major of a zero-mean bivariate normal as a spline of sigma_minor / sigma_major
    over [0.05, 1], tabulated from the exact :func:`cep_bivariate` (< 1e-6 relative, tested)."""
    values = [cep_bivariate(0.0, 0.0, 1.0, float(r), 0.0, p) for r in _RATIO_GRID]
    return interpolate.CubicSpline(_RATIO_GRID, values)


LE90_PER_SIGMA = 1.6448536269514722  # two-sided 90 % quantile of a standard normal: LE90 / sigma


def cep_ce_le(cov: ArrayLike, vertical: bool = True) -> dict[str, np.ndarray]:
    """``cep50_m``, ``ce90_m`` (exact radii of the zero-mean horizontal normal) and ``le90_m`` (the
    two-sided 90 % of the vertical error) of covariances ``cov`` (..., 3, 3) ENU m^2; without
    ``vertical``, the horizontal pair only."""
    cov = np.asarray(cov, dtype=np.float64)
    e = error_ellipses(cov[..., :2, :2])
    out = {"cep50_m": cep_zero_mean(e[..., 0], e[..., 1], 0.5), "ce90_m": cep_zero_mean(e[..., 0], e[..., 1], 0.9)}
    if vertical:
        out["le90_m"] = LE90_PER_SIGMA * np.sqrt(np.maximum(cov[..., 2, 2], 0.0))
    return out


def cep_zero_mean(sigma_major: ArrayLike, sigma_minor: ArrayLike, p: float = 0.5) -> np.ndarray:
    """Vectorised parametric CEP (m) of zero-mean bivariate normals given their principal sigmas
    (any order; arrays broadcast): the radius holding probability p. NaN where a sigma is NaN."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    a, b = np.broadcast_arrays(np.asarray(sigma_major, dtype=np.float64), np.asarray(sigma_minor, dtype=np.float64))
    big, small = np.maximum(a, b), np.minimum(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(big > 0.0, small / big, np.where(np.isnan(big), np.nan, 0.0))
    out = np.atleast_1d(big * _zero_mean_table(float(p))(np.clip(ratio, _RATIO_MIN, 1.0)))
    flat_big, flat_small = np.atleast_1d(big).reshape(-1), np.atleast_1d(small).reshape(-1)
    for i in np.flatnonzero(np.atleast_1d(ratio) < _RATIO_MIN):
        out.reshape(-1)[i] = cep_bivariate(0.0, 0.0, float(flat_big[i]), float(flat_small[i]), 0.0, p)
    return out.reshape(np.shape(big))
