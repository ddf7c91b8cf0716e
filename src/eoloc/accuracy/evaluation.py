"""Accuracy of fixes against surveyed points: the statistics of a flight-test accuracy report.

Every function takes arrays and returns arrays or small frozen results; no file is read here.

- :func:`error_enu`: fix minus truth as east, north, up metres in the tangent plane at the truth.
- :func:`match_nearest` / :func:`match_ids`: which surveyed point each fix is a fix of.
- :func:`statistics`: CEP (median horizontal error), CE90, LE90, MAE, RMSE, mean bias E/N/U and
  the largest error, vectorised over leading axes so that :func:`summarize` draws all bootstrap
  resamples of a batch at once (percentile bootstrap, seeded; each resample held as counts per
  value, see :func:`bootstrap_statistics`) for their confidence intervals.
- :func:`tle_fit`: the linear target-location-error model in slant range (OpenAthena publishes
  one per drone model): intercept and slope with their standard errors, R², the slope's p-value;
  outliers removed once by Cook's distance (default threshold 4/n).
- :func:`coverage`: whether the fixes' own covariance was honest - the share of truths inside
  each fix's predicted p-ellipse for p = 5 %...95 %, inside its own CE50/CE90 circles and LE90,
  each with its Clopper-Pearson interval.
- :func:`binned`: error statistics in bins of a factor (slant range, oblique angle, ...).

Quantiles (CEP = the 50 % quantile of the horizontal errors, CE90 the 90 %, LE90 the 90 % of the
absolute vertical errors) interpolate linearly between order statistics: numpy's default,
Hyndman & Fan's type 7, which is also R's default (so R scripts give the same numbers).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy

STATISTICS = {  # name: (label, what it is)
    "cep50_m": ("CEP", "median horizontal error"),
    "ce90_m": ("CE90", "90 % quantile of the horizontal error"),
    "le90_m": ("LE90", "90 % quantile of |vertical error|"),
    "mae_h_m": ("MAE horizontal", "mean horizontal error"),
    "mae_v_m": ("MAE vertical", "mean |vertical error|"),
    "rmse_h_m": ("RMSE horizontal", "sqrt(mean(east² + north²))"),
    "rmse_v_m": ("RMSE vertical", "sqrt(mean(up²))"),
    "bias_e_m": ("bias east", "mean east error"),
    "bias_n_m": ("bias north", "mean north error"),
    "bias_u_m": ("bias up", "mean vertical error"),
    "max_h_m": ("max horizontal", "largest horizontal error"),
}
HORIZONTAL = ("cep50_m", "ce90_m", "mae_h_m", "rmse_h_m", "bias_e_m", "bias_n_m", "max_h_m")
VERTICAL = ("le90_m", "mae_v_m", "rmse_v_m", "bias_u_m")


def error_enu(fix_lat_deg: ArrayLike, fix_lon_deg: ArrayLike, fix_h_m: ArrayLike, truth_lat_deg: ArrayLike,
              truth_lon_deg: ArrayLike, truth_h_m: ArrayLike) -> np.ndarray:
    """(N, 3) error of each fix (fix minus truth) in east, north, up metres at the truth. Where
    either height is unknown (NaN) the up error is NaN and the horizontal error is taken at the
    truth's height (or 0 m when that is unknown too)."""
    lat, lon, h, tlat, tlon, th = (np.asarray(a, dtype=np.float64) for a in np.broadcast_arrays(
        fix_lat_deg, fix_lon_deg, fix_h_m, truth_lat_deg, truth_lon_deg, truth_h_m))
    no_h = ~(np.isfinite(h) & np.isfinite(th))
    base = np.where(np.isfinite(th), th, 0.0)
    h = np.where(no_h, base, h)
    p_fix = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
    enu = geodesy.ecef_to_enu(p_fix, tlat, tlon, base)
    enu[..., 2] = np.where(no_h, np.nan, enu[..., 2])
    return enu


@dataclass(frozen=True)
class Match:
    """Per fix: ``index`` of its truth point (-1: none), the horizontal ``distance_m`` to it and to
    the next-nearest truth point (``second_m``; NaN when matched by id), and ``ambiguous``: a
    nearest match whose runner-up is less than ``ratio`` times as far."""

    index: np.ndarray
    distance_m: np.ndarray
    second_m: np.ndarray
    ambiguous: np.ndarray


def _on_ellipsoid(lat_deg, lon_deg) -> np.ndarray:
    return np.stack(geodesy.geodetic_to_ecef(lat_deg, lon_deg, np.zeros(np.shape(lat_deg))), -1)


def match_nearest(fix_lat_deg: ArrayLike, fix_lon_deg: ArrayLike, truth_lat_deg: ArrayLike,
                  truth_lon_deg: ArrayLike, *, max_distance_m: float, ratio: float = 2.0) -> Match:
    """Each fix's nearest truth point within ``max_distance_m`` horizontally (a k-d tree over the
    points' ECEF positions on the ellipsoid: the chord differs from the geodesic by < 1 mm up to
    10 km). Fixes with none that close get index -1."""
    from scipy.spatial import cKDTree

    f = _on_ellipsoid(np.asarray(fix_lat_deg, dtype=np.float64), np.asarray(fix_lon_deg, dtype=np.float64))
    t = _on_ellipsoid(np.asarray(truth_lat_deg, dtype=np.float64), np.asarray(truth_lon_deg, dtype=np.float64))
    n = f.shape[0]
    index = np.full(n, -1, dtype=np.intp)
    d1 = np.full(n, np.nan)
    d2 = np.full(n, np.nan)
    ok = np.all(np.isfinite(f), -1)
    if t.shape[0] and ok.any():
        k = min(2, t.shape[0])
        dist, idx = cKDTree(t).query(f[ok], k=k)
        dist, idx = dist.reshape(-1, k), idx.reshape(-1, k)
        near = dist[:, 0] <= max_distance_m
        where = np.flatnonzero(ok)
        index[where[near]] = idx[near, 0]
        d1[where] = dist[:, 0]
        if k == 2:
            d2[where] = dist[:, 1]
    with np.errstate(invalid="ignore"):
        ambiguous = (index >= 0) & (d2 < ratio * d1)
    return Match(index, d1, d2, ambiguous)


def match_ids(fix_ids: ArrayLike, truth_ids: ArrayLike) -> Match:
    """Each fix's truth point by id (strings compared after stripping blanks); -1 where the id is
    not among the truth points. Truth ids must be unique (the first of a repeated id is used)."""
    lookup: dict[str, int] = {}
    for i, t in enumerate(np.asarray(truth_ids, dtype=object).ravel()):
        if t is not None and str(t).strip():  # a blank id names nothing
            lookup.setdefault(str(t).strip(), i)
    fids = np.asarray(fix_ids, dtype=object).ravel()
    index = np.array([lookup.get(str(x).strip(), -1) if x is not None else -1 for x in fids], dtype=np.intp)
    nan = np.full(index.shape, np.nan)
    return Match(index, nan, nan.copy(), np.zeros(index.shape, dtype=bool))


def _quantile(x: np.ndarray, q: float) -> np.ndarray:
    return np.quantile(x, q, axis=-1) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def _mean(x: np.ndarray) -> np.ndarray:
    return x.mean(axis=-1) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def statistics(en_m: np.ndarray, up_m: np.ndarray) -> dict[str, np.ndarray]:
    """The accuracy statistics of horizontal errors ``en_m`` (..., N, 2) (east, north) and vertical
    errors ``up_m`` (..., M) (finite; M may differ from N when some fixes have no height): arrays
    of the leading shape. See :data:`STATISTICS`."""
    en_m, up_m = np.asarray(en_m, dtype=np.float64), np.asarray(up_m, dtype=np.float64)
    e, n = en_m[..., 0], en_m[..., 1]
    r2 = e * e + n * n
    r = np.sqrt(r2)
    a = np.abs(up_m)
    return {"cep50_m": _quantile(r, 0.5), "ce90_m": _quantile(r, 0.9), "le90_m": _quantile(a, 0.9),
            "mae_h_m": _mean(r), "mae_v_m": _mean(a), "rmse_h_m": np.sqrt(_mean(r2)),
            "rmse_v_m": np.sqrt(_mean(up_m * up_m)), "bias_e_m": _mean(e), "bias_n_m": _mean(n),
            "bias_u_m": _mean(up_m), "max_h_m": r.max(axis=-1) if r.shape[-1] else np.full(r.shape[:-1], np.nan)}


@dataclass(frozen=True)
class Summary:
    """Statistics of one set of errors: ``value`` per :data:`STATISTICS` name, the bootstrap
    interval (``low``, ``high``) at ``level`` (NaN with fewer than 2 points or ``n_boot`` 0), the
    numbers of points with a horizontal (``n``) and a vertical (``n_vertical``) error, and the
    parametric view of [Z15]: the bivariate-normal CEP with the systematic (mean) and random
    (sigma, correlation) parts."""

    n: int
    n_vertical: int
    value: dict[str, float]
    low: dict[str, float]
    high: dict[str, float]
    level: float
    n_boot: int
    seed: int
    cep_parametric_m: float
    sigma_e_m: float
    sigma_n_m: float
    rho_en: float

    def row(self) -> dict[str, float | int]:
        """Flat: n, each statistic with its _low/_high, and the parametric figures."""
        out: dict[str, float | int] = {"n": self.n, "n_vertical": self.n_vertical}
        for k in STATISTICS:
            out[k] = self.value[k]
            out[k.removesuffix("_m") + "_low_m"] = self.low[k]
            out[k.removesuffix("_m") + "_high_m"] = self.high[k]
        out.update({"cep_parametric_m": self.cep_parametric_m, "sigma_e_m": self.sigma_e_m,
                    "sigma_n_m": self.sigma_n_m, "rho_en": self.rho_en})
        return out


def resample_counts(rng: np.random.Generator, n: int, b: int) -> np.ndarray:
    """(b, n) float counts: how often each of ``n`` values is drawn in each of ``b`` resamples of
    size ``n`` with replacement (uniform indices, counted with one ``bincount``)."""
    idx = rng.integers(0, n, size=(b, n))
    idx += np.arange(b)[:, None] * n
    return np.bincount(idx.ravel(), minlength=b * n).reshape(b, n).astype(np.float64)


def weighted_quantiles(sorted_x: np.ndarray, counts: np.ndarray, qs: tuple[float, ...]) -> list[np.ndarray]:
    """Quantiles (type 7, as :func:`np.quantile`) of each resample given as ``counts`` (b, n) over
    the ascending values ``sorted_x`` (n,): the j-th order statistic of a resample is the value at
    the first position whose running count exceeds j - one ``searchsorted`` over all rows, whose
    running counts are offset row by row to make one ascending array. O(n) per resample, no sort."""
    b, n = counts.shape
    running = np.cumsum(counts, axis=1)
    running += (np.arange(b, dtype=np.float64) * (n + 1))[:, None]
    flat = running.ravel()
    row0 = np.arange(b) * n

    def order_statistic(j: int) -> np.ndarray:
        at = np.searchsorted(flat, j + np.arange(b, dtype=np.float64) * (n + 1), side="right") - row0
        return sorted_x[at]

    out = []
    for q in qs:
        h = (n - 1) * q
        lo = math.floor(h)
        x_lo = order_statistic(lo)
        out.append(x_lo + (h - lo) * (order_statistic(min(lo + 1, n - 1)) - x_lo) if h > lo else x_lo)
    return out


def bootstrap_statistics(en_m: np.ndarray, up_m: np.ndarray, *, n_boot: int, seed: int,
                         max_elements: int = 4_000_000) -> dict[str, np.ndarray]:
    """``n_boot`` percentile-bootstrap replicates (n_boot,) of every statistic: the horizontal and
    the vertical errors each resampled with replacement (numpy Generator ``seed``), in batches of
    at most ``max_elements`` resampled values so that memory stays bounded at any N.

    A resample is held as counts per value rather than as a copy of the values: the means are one
    matrix product with the counts, the quantiles and the maximum are read off the running counts
    over the values sorted once (:func:`weighted_quantiles`) - the same numbers as
    :func:`statistics` of the resampled copies, without sorting or partitioning each one."""
    rng = np.random.default_rng(seed)
    en_m, up_m = np.asarray(en_m, dtype=np.float64), np.asarray(up_m, dtype=np.float64)
    n, m = en_m.shape[0], up_m.shape[0]
    r = np.hypot(en_m[:, 0], en_m[:, 1])
    order_h, order_v = np.argsort(r), np.argsort(np.abs(up_m))
    r_s, en_s, up_s = r[order_h], en_m[order_h], up_m[order_v]
    a_s = np.abs(up_s)
    cols_h = np.column_stack([r_s, r_s * r_s, en_s[:, 0], en_s[:, 1]])
    cols_v = np.column_stack([a_s, up_s * up_s, up_s])
    batch = max(1, max_elements // max(n, m, 1))
    out: dict[str, list[np.ndarray]] = {k: [] for k in STATISTICS}
    for start in range(0, n_boot, batch):
        b = min(batch, n_boot - start)
        nan = np.full(b, np.nan)
        if n:
            c = resample_counts(rng, n, b)
            mean_h = c @ cols_h / n
            cep, ce90, top = weighted_quantiles(r_s, c, (0.5, 0.9, 1.0))
            del c
            h = {"cep50_m": cep, "ce90_m": ce90, "mae_h_m": mean_h[:, 0], "rmse_h_m": np.sqrt(mean_h[:, 1]),
                 "bias_e_m": mean_h[:, 2], "bias_n_m": mean_h[:, 3], "max_h_m": top}
        else:
            h = dict.fromkeys(HORIZONTAL, nan)
        if m:
            c = resample_counts(rng, m, b)
            mean_v = c @ cols_v / m
            (le90,) = weighted_quantiles(a_s, c, (0.9,))
            del c
            v = {"le90_m": le90, "mae_v_m": mean_v[:, 0], "rmse_v_m": np.sqrt(mean_v[:, 1]), "bias_u_m": mean_v[:, 2]}
        else:
            v = dict.fromkeys(VERTICAL, nan)
        for k in STATISTICS:
            out[k].append(h[k] if k in h else v[k])
    return {k: np.concatenate(v) if v else np.empty(0) for k, v in out.items()}


def summarize(enu_m: ArrayLike, *, n_boot: int = 2000, level: float = 0.95, seed: int = 0) -> Summary:
    """:class:`Summary` of errors ``enu_m`` (N, 3) east, north, up (rows with a NaN east or north
    are left out; a NaN up leaves the row out of the vertical statistics only)."""
    from scipy import stats as sps

    from .cep import cep_bivariate

    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    enu = np.asarray(enu_m, dtype=np.float64).reshape(-1, 3)
    en = enu[np.all(np.isfinite(enu[:, :2]), -1), :2]
    up = enu[np.isfinite(enu[:, 2]), 2]
    value = {k: float(v) for k, v in statistics(en, up).items()}
    nan = dict.fromkeys(STATISTICS, math.nan)
    low, high = dict(nan), dict(nan)
    if n_boot > 0 and (en.shape[0] >= 2 or up.size >= 2):
        reps = bootstrap_statistics(en, up, n_boot=n_boot, seed=seed)
        a = (1.0 - level) / 2.0
        for k in STATISTICS:
            enough = (en.shape[0] if k in HORIZONTAL else up.size) >= 2
            if enough and k != "max_h_m":  # the bootstrap cannot bound a maximum (it never exceeds the sample's)
                low[k], high[k] = (float(x) for x in np.quantile(reps[k], [a, 1.0 - a]))
    cep_p = se = sn = rho = math.nan
    if en.shape[0] >= 3:
        se, sn = (float(x) for x in en.std(axis=0, ddof=1))
        if se > 0 and sn > 0:
            rho = float(sps.pearsonr(en[:, 0], en[:, 1]).statistic)
        else:
            rho = 0.0
        cep_p = cep_bivariate(float(en[:, 0].mean()), float(en[:, 1].mean()), se, sn, rho)
    return Summary(int(en.shape[0]), int(up.size), value, low, high, level, int(n_boot), int(seed), cep_p, se, sn,
                   rho)


@dataclass(frozen=True)
class LinearFit:
    """error = intercept + slope * x, fitted by least squares (scipy.stats.linregress) after the
    points whose Cook's distance exceeds ``threshold`` were removed (once). ``kept`` and ``cooks``
    are per input point (NaN/False where x or y was not finite)."""

    intercept: float
    slope: float
    intercept_se: float
    slope_se: float
    r2: float
    p_slope: float
    residual_sd: float
    n: int
    n_removed: int
    threshold: float
    kept: np.ndarray
    cooks: np.ndarray

    def row(self) -> dict[str, float | int]:
        return {"intercept_m": self.intercept, "intercept_se_m": self.intercept_se, "slope_m_per_km":
                self.slope * 1000.0, "slope_se_m_per_km": self.slope_se * 1000.0, "r2": self.r2,
                "p_slope": self.p_slope, "residual_sd_m": self.residual_sd, "n": self.n, "n_removed": self.n_removed,
                "cooks_threshold": self.threshold}


def cooks_distance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cook's distance of each point of a straight-line least-squares fit of y on x:
    D_i = e_i² / (p s²) · h_i / (1 - h_i)², p = 2, leverage h_i = 1/n + (x_i - x̄)² / Sxx,
    s² = Σe² / (n - 2)."""
    n = x.size
    xm = x.mean()
    sxx = float(((x - xm) ** 2).sum())
    slope = float(((x - xm) * (y - y.mean())).sum()) / sxx
    resid = y - (y.mean() + slope * (x - xm))
    s2 = float((resid**2).sum()) / (n - 2)
    h = 1.0 / n + (x - xm) ** 2 / sxx
    with np.errstate(divide="ignore", invalid="ignore"):
        return resid**2 / (2.0 * s2) * h / (1.0 - h) ** 2


def tle_fit(x: ArrayLike, error_m: ArrayLike, *, threshold: float | None = None) -> LinearFit | None:
    """The linear target-location-error model error = a + b·x (x: slant range, m) with outliers
    removed by Cook's distance > ``threshold`` (default 4/n). None when fewer than 3 points with
    distinct x remain (no line with a residual to judge it by)."""
    from scipy import stats as sps

    x, y = (np.asarray(a, dtype=np.float64).ravel() for a in (x, error_m))
    fin = np.isfinite(x) & np.isfinite(y)
    kept = np.zeros(x.size, dtype=bool)
    cooks = np.full(x.size, np.nan)
    xf, yf = x[fin], y[fin]
    if xf.size < 3 or np.ptp(xf) == 0:
        return None
    thr = 4.0 / xf.size if threshold is None else float(threshold)
    d = cooks_distance(xf, yf) if np.any(yf != yf[0]) else np.zeros(xf.size)
    d = np.nan_to_num(d, nan=0.0, posinf=np.inf)
    keep = d <= thr
    if keep.sum() < 3 or np.ptp(xf[keep]) == 0:
        return None
    cooks[fin] = d
    kept[np.flatnonzero(fin)[keep]] = True
    res = sps.linregress(xf[keep], yf[keep])
    resid = yf[keep] - (res.intercept + res.slope * xf[keep])
    sd = float(np.sqrt((resid**2).sum() / (keep.sum() - 2))) if keep.sum() > 2 else math.nan
    return LinearFit(float(res.intercept), float(res.slope), float(res.intercept_stderr), float(res.stderr),
                     float(res.rvalue**2), float(res.pvalue), sd, int(keep.sum()), int((~keep).sum()), thr, kept,
                     cooks)


@dataclass(frozen=True)
class Coverage:
    """Whether predicted uncertainties were honest. ``nominal`` probabilities and the ``observed``
    share of truth points inside each fix's own ellipse of that probability (2-D normal, from
    sigma_e, sigma_n, rho_en) with Clopper-Pearson intervals (``low``, ``high``, at 95 %);
    ``circles``: name -> (nominal, observed, low, high, n) for the CE50 and CE90 circles and LE90;
    ``scale``: the factor the stated sigmas would need (sqrt of the mean squared Mahalanobis
    distance over 2; 1 when honest)."""

    n: int
    nominal: np.ndarray
    observed: np.ndarray
    low: np.ndarray
    high: np.ndarray
    circles: dict[str, tuple[float, float, float, float, int]]
    scale: float

    def verdict(self, observed: float, low: float, high: float, nominal: float) -> str:
        if not math.isfinite(observed):
            return "no data"
        if low <= nominal <= high:
            return "honest"
        return "optimistic (errors larger than predicted)" if observed < nominal else "pessimistic (too cautious)"


def _share(inside: np.ndarray) -> tuple[float, float, float, int]:
    from scipy import stats as sps

    n = int(inside.size)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    k = int(inside.sum())
    ci = sps.binomtest(k, n).proportion_ci(0.95, method="exact")
    return k / n, float(ci.low), float(ci.high), n


NOMINAL = np.round(np.arange(0.05, 0.951, 0.05), 2)


def coverage(enu_m: ArrayLike, sigma_e_m: ArrayLike, sigma_n_m: ArrayLike, rho_en: ArrayLike,
             sigma_u_m: ArrayLike | None = None, *, cep50_m: ArrayLike | None = None,
             ce90_m: ArrayLike | None = None, le90_m: ArrayLike | None = None) -> Coverage | None:
    """:class:`Coverage` of errors (N, 3) against each fix's predicted 1-sigma east/north (and up)
    and east-north correlation (NaN rho counts as 0). CE50/CE90/LE90 are taken from the given
    columns, else computed from the sigmas (exact zero-mean bivariate-normal radii; LE90 =
    1.645 sigma_u). None when no fix has a usable covariance."""
    from scipy import stats as sps

    from .cep import cep_zero_mean, error_ellipses

    enu = np.asarray(enu_m, dtype=np.float64).reshape(-1, 3)
    se, sn = (np.asarray(a, dtype=np.float64).ravel() for a in (sigma_e_m, sigma_n_m))
    rho = np.nan_to_num(np.asarray(rho_en, dtype=np.float64).ravel(), nan=0.0)
    cov = np.empty((se.size, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = se * se, sn * sn
    cov[:, 0, 1] = cov[:, 1, 0] = rho * se * sn
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    ok = np.isfinite(se) & np.isfinite(sn) & (se > 0) & (sn > 0) & (det > 0) & np.all(np.isfinite(enu[:, :2]), -1)
    if not ok.any():
        return None
    e, n = enu[ok, 0], enu[ok, 1]
    c = cov[ok]
    d2 = (c[:, 1, 1] * e * e - 2.0 * c[:, 0, 1] * e * n + c[:, 0, 0] * n * n) / det[ok]
    obs, lo, hi = [], [], []
    for p in NOMINAL:
        s, a, b, _ = _share(d2 <= sps.chi2.ppf(p, 2))
        obs.append(s)
        lo.append(a)
        hi.append(b)
    r = np.hypot(e, n)
    ell = error_ellipses(c)
    circles = {}
    for name, p, given in (("CE50", 0.5, cep50_m), ("CE90", 0.9, ce90_m)):
        radius = np.asarray(given, dtype=np.float64).ravel()[ok] if given is not None else np.full(r.size, np.nan)
        radius = np.where(np.isfinite(radius), radius, cep_zero_mean(ell[:, 0], ell[:, 1], p))
        circles[name] = (p, *_share(r <= radius))
    if sigma_u_m is not None:
        su = np.asarray(sigma_u_m, dtype=np.float64).ravel()
        le = np.asarray(le90_m, dtype=np.float64).ravel() if le90_m is not None else np.full(su.size, np.nan)
        le = np.where(np.isfinite(le), le, sps.norm.ppf(0.95) * su)
        v = ok & np.isfinite(enu[:, 2]) & np.isfinite(le) & (le > 0)
        if v.any():
            circles["LE90"] = (0.9, *_share(np.abs(enu[v, 2]) <= le[v]))
    return Coverage(int(ok.sum()), NOMINAL.copy(), np.array(obs), np.array(lo), np.array(hi), circles,
                    float(np.sqrt(d2.mean() / 2.0)))


@dataclass(frozen=True)
class Bin:
    """Errors in one bin of a factor: [lo, hi), count, median and 90 % horizontal error, median
    |vertical| error."""

    lo: float
    hi: float
    n: int
    cep50_m: float
    ce90_m: float
    median_v_m: float


def binned(x: ArrayLike, horizontal_m: ArrayLike, vertical_m: ArrayLike | None = None, *, bins: int = 6,
           min_per_bin: int = 5) -> list[Bin]:
    """Statistics of the errors in up to ``bins`` bins of equal count of factor ``x`` (fewer when
    each would hold fewer than ``min_per_bin`` points)."""
    x, r = (np.asarray(a, dtype=np.float64).ravel() for a in (x, horizontal_m))
    v = np.full(x.size, np.nan) if vertical_m is None else np.abs(np.asarray(vertical_m, dtype=np.float64).ravel())
    ok = np.isfinite(x) & np.isfinite(r)
    x, r, v = x[ok], r[ok], v[ok]
    k = max(1, min(bins, x.size // max(min_per_bin, 1)))
    if x.size == 0:
        return []
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, k + 1)))
    if edges.size < 2:
        edges = np.array([x.min(), x.max()])
    out = []
    for i, (lo, hi) in enumerate(itertools.pairwise(edges)):
        m = (x >= lo) & ((x < hi) if i < edges.size - 2 else (x <= hi))
        if m.any():
            vv = v[m][np.isfinite(v[m])]
            out.append(Bin(float(lo), float(hi), int(m.sum()), float(np.quantile(r[m], 0.5)),
                           float(np.quantile(r[m], 0.9)), float(np.median(vv)) if vv.size else math.nan))
    return out
