"""First-order covariance of every fix: the error budget propagated through the chain's Jacobian.

For each target, J = d(east, north, up) / d(source) is taken by central differences through the
SAME chain as the fixes and the Monte Carlo (:func:`eoloc.accuracy.montecarlo.chain_fixes`):
one batched call evaluates the nominal fix and every source stepped by +-h (h = ``rel_step`` x
its sigma), so no derivative is written by hand and none can drift from the model. (USGS CSM
computes its sensor partials the same way.) Then

    cov_enu = J diag(sigma^2) J^T        (m^2, local east/north/up at the fix)

which is exact for a linear chain and first-order otherwise. The chain is not linear everywhere:
on a DEM a ray that grazes a slope or a ridge jumps to another surface under a small attitude
error; near the horizon the range grows without bound. So every target also gets a
**nonlinearity** figure: the same propagation with secants over +-1 sigma, compared with the
derivative (relative Frobenius difference of the sigma-scaled Jacobians; infinite when a +-1
sigma ray no longer reaches the surface). Where it exceeds ~0.1 the first-order sigma is not to
be trusted and Monte Carlo is the tool (``linear(tol)`` gives the mask).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..result import Fixes, Status
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel, split_pixels
from .budget import ErrorBudget
from .cep import LE90_PER_SIGMA, cep_zero_mean, error_ellipses
from .montecarlo import chain_fixes, metres_per_degree, usable_rule

DEFAULT_REL_STEP = 1e-2


@dataclass(frozen=True)
class FixCovariance:
    """First-order uncertainty of fixes of shape T (NaN where the fix is not OK).

    cov_enu (*T, 3, 3) m^2 in the local east/north/up frame at each fix; jacobian_enu (*T, 3, S)
    m per source unit; sources / sigma_in (S,) the budget's source names and standard deviations;
    nonlinearity (*T,) (see the module doc; inf where a +-1 sigma ray fails); lat_deg / h_m (*T,)
    the fixes' latitude and height (for the metric-to-degree conversion); kinds / tau_s (S,) how
    each source behaves in time (:mod:`eoloc.accuracy.budget`: "bias", "noise", "markov" and its
    correlation time), which decides what averages down when fixes are combined.
    """

    cov_enu: np.ndarray
    jacobian_enu: np.ndarray
    sources: tuple[str, ...]
    sigma_in: np.ndarray
    nonlinearity: np.ndarray
    lat_deg: np.ndarray
    h_m: np.ndarray
    kinds: tuple[str, ...] = ()
    tau_s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def take(self, index) -> FixCovariance:
        """The covariance of the fixes at ``index`` of the flattened batch."""
        def pick(x: np.ndarray, tail: int) -> np.ndarray:
            return np.reshape(x, (-1, *np.shape(x)[len(np.shape(x)) - tail:]) if tail else -1)[index]

        return FixCovariance(pick(self.cov_enu, 2), pick(self.jacobian_enu, 2), self.sources, self.sigma_in,
                             pick(np.broadcast_to(self.nonlinearity, self.shape), 0),
                             pick(np.broadcast_to(self.lat_deg, self.shape), 0),
                             pick(np.broadcast_to(self.h_m, self.shape), 0), self.kinds, self.tau_s)

    @property
    def scaled_jacobian(self) -> np.ndarray:
        """(*T, 3, S) J diag(sigma): each source's 1-sigma effect on the fix (m, ENU)."""
        return self.jacobian_enu * self.sigma_in

    def part(self, *kinds: str) -> np.ndarray:
        """(*T, 3, 3) the covariance of the sources of these kinds only (e.g. "bias": what no
        averaging removes; "noise", "markov": the random part)."""
        keep = np.array([k in kinds for k in self.kinds], dtype=bool)
        a = self.scaled_jacobian[..., keep]
        return a @ np.swapaxes(a, -1, -2)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.cov_enu.shape[:-2]

    @property
    def sigma_enu(self) -> np.ndarray:
        """(*T, 3) 1-sigma east, north, up (m)."""
        return np.sqrt(np.diagonal(self.cov_enu, axis1=-2, axis2=-1))

    @property
    def rho_en(self) -> np.ndarray:
        s = self.sigma_enu
        with np.errstate(invalid="ignore", divide="ignore"):
            r = self.cov_enu[..., 0, 1] / (s[..., 0] * s[..., 1])
        return np.clip(np.where(np.isfinite(r), r, 0.0), -1.0, 1.0)

    @property
    def sigma_lat_deg(self) -> np.ndarray:
        return self.sigma_enu[..., 1] / metres_per_degree(self.lat_deg, self.h_m, geodesy.WGS84)[0]

    @property
    def sigma_lon_deg(self) -> np.ndarray:
        return self.sigma_enu[..., 0] / metres_per_degree(self.lat_deg, self.h_m, geodesy.WGS84)[1]

    @property
    def sigma_h_m(self) -> np.ndarray:
        return self.sigma_enu[..., 2]

    @property
    def drms(self) -> np.ndarray:
        """Horizontal radial RMS sqrt(sigma_e^2 + sigma_n^2) (m)."""
        return np.hypot(self.sigma_enu[..., 0], self.sigma_enu[..., 1])

    @property
    def le90(self) -> np.ndarray:
        """90 % vertical error (m) of the normal up error."""
        return LE90_PER_SIGMA * self.sigma_enu[..., 2]

    def ellipse(self, p: float | None = None) -> np.ndarray:
        """(*T, 3): semi-major, semi-minor (m) and azimuth of the major axis (deg from north) of the
        horizontal error ellipse holding probability p (default: 1 sigma)."""
        return error_ellipses(self.cov_enu[..., :2, :2], p)

    def cep(self, p: float = 0.5) -> np.ndarray:
        """(*T,) radius (m) around the fix holding probability p of the zero-mean horizontal normal:
        the exact parametric CEP (:func:`eoloc.accuracy.cep_zero_mean`), not a rule of thumb."""
        e = self.ellipse()
        return cep_zero_mean(e[..., 0], e[..., 1], p)

    def contributions(self) -> np.ndarray:
        """(*T, S) share of each source in the horizontal variance sigma_e^2 + sigma_n^2 (sums to 1)."""
        a = self.jacobian_enu[..., :2, :] * self.sigma_in
        v = (a * a).sum(axis=-2)
        with np.errstate(invalid="ignore", divide="ignore"):
            return v / v.sum(axis=-1, keepdims=True)

    def linear(self, tol: float = 0.1) -> np.ndarray:
        """True where the first-order covariance can be trusted (nonlinearity <= tol)."""
        return self.nonlinearity <= tol


def locate_with_covariance(sensor: SensorModel, pose: Pose, budget: ErrorBudget, pixels: ArrayLike | None,
                           rule: StopRule, *, velocity_ned_mps: ArrayLike = (0.0, 0.0, 0.0),
                           rel_step: float = DEFAULT_REL_STEP,
                           check_linearity: bool = True) -> tuple[Fixes, FixCovariance]:
    """Fixes and their first-order covariance under ``budget`` by stop ``rule``. Pose fields,
    pixels and the rule's range/height broadcast to the targets' shape; velocity_ned_mps (m/s)
    is used by a ``time_s`` source. The fixes are those of :func:`eoloc.locate` with the same rule.
    """
    rule = usable_rule(rule)
    if not rel_step > 0:
        raise ValueError(f"rel_step must be > 0, got {rel_step!r}")
    u, v = split_pixels(pixels, sensor.camera)
    srcs = [s for s in budget if s.sigma > 0]
    names = tuple(s.name for s in srcs)
    sig = np.array([s.sigma for s in srcs], dtype=np.float64)
    n_src = len(srcs)
    steps = [rel_step] + ([1.0] if check_linearity else [])
    rows = 1 + 2 * n_src * len(steps)
    d = {name: np.zeros(rows) for name in names}
    for j, name in enumerate(names):
        for b, k in enumerate(steps):
            base = 1 + 2 * n_src * b
            d[name][base + j] = k * sig[j]
            d[name][base + n_src + j] = -k * sig[j]
    f = chain_fixes(sensor, pose, u, v, rule, d, rows, velocity_ned_mps=velocity_ned_mps)
    shape = f.status.shape[1:]
    lat, lon, h, rng, st = (np.broadcast_to(x, (rows, *shape)) for x in (f.lat_deg, f.lon_deg, f.h_m, f.range_m,
                                                                          f.status))
    fixes = Fixes(*(np.array(x[0]) for x in (lat, lon, h, rng)), np.array(st[0]))
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
    R_enu = geodesy.R_ecef_enu(lat[0], lon[0])  # (*T, 3, 3), columns east/north/up in ECEF
    enu = np.einsum("...ij,r...i->r...j", R_enu, p - p[0])  # (rows, *T, 3) offsets from the fix

    def scaled_jacobian(b: int) -> tuple[np.ndarray, np.ndarray]:
        base = 1 + 2 * n_src * b
        plus, minus = enu[base:base + n_src], enu[base + n_src:base + 2 * n_src]
        a = np.moveaxis((plus - minus) / 2.0, 0, -1)  # (*T, 3, S): J diag(step)
        ok = np.all(st[base:base + 2 * n_src] == Status.OK, axis=0)
        return a, ok

    a, ok = scaled_jacobian(0)
    a = a / rel_step  # J diag(sigma)
    good = ok & (fixes.status == Status.OK)
    a = np.where(good[..., None, None], a, np.nan)
    cov = a @ np.swapaxes(a, -1, -2)
    if check_linearity:
        a1, ok1 = scaled_jacobian(1)
        with np.errstate(invalid="ignore", divide="ignore"):
            nl = np.linalg.norm((a1 - a).reshape(*shape, -1), axis=-1) / np.linalg.norm(a.reshape(*shape, -1), axis=-1)
        nl = np.where(ok1 & good, nl, np.inf)
        nl = np.where(np.isnan(nl) & good, 0.0, nl)  # no source moves the fix: exactly linear
    else:
        nl = np.full(shape, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        jac = a / sig
    return fixes, FixCovariance(cov, jac, names, sig, np.asarray(nl, dtype=np.float64), fixes.lat_deg, fixes.h_m,
                                tuple(s.kind for s in srcs), np.array([s.tau_s for s in srcs], dtype=np.float64))


def covariance_columns(cov: FixCovariance, ok: ArrayLike | None = None) -> dict[str, np.ndarray]:
    """Per-target columns for tables and exports (flattened; NaN where there is no covariance or
    where ``ok`` is False)."""
    e = cov.ellipse()
    s = cov.sigma_enu
    cols = {"sigma_e_m": s[..., 0], "sigma_n_m": s[..., 1], "sigma_u_m": s[..., 2], "rho_en": cov.rho_en,
            "cep50_m": cov.cep(0.5), "ce90_m": cov.cep(0.9), "le90_m": cov.le90, "ellipse_major_m": e[..., 0],
            "ellipse_minor_m": e[..., 1], "ellipse_azimuth_deg": e[..., 2]}
    keep = np.isfinite(s[..., 0]) if ok is None else np.isfinite(s[..., 0]) & np.asarray(ok, dtype=bool)
    out = {k: np.ravel(np.where(keep, v, np.nan)) for k, v in cols.items()}
    out["nonlinearity"] = np.ravel(np.where(ok if ok is not None else True, cov.nonlinearity, np.nan))
    return out


class CovarianceRows:
    """The covariances of ``n`` targets located in groups (one call per camera): each group's
    :meth:`put` fills its rows' uncertainty columns (:func:`covariance_columns`), ENU covariance
    (n, 3, 3) m^2 and each budget source's 1-sigma effect (n, 3, S); NaN where a target is not OK
    or no group held it. ``columns`` stays empty, the arrays None, until a group is put."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.columns: dict[str, np.ndarray] = {}
        self.cov_enu: np.ndarray | None = None
        self.effects: np.ndarray | None = None
        self.tau_s: np.ndarray | None = None

    def put(self, idx: np.ndarray, cov: FixCovariance, ok: np.ndarray) -> None:
        for k, col in covariance_columns(cov, ok).items():
            self.columns.setdefault(k, np.full(self.n, np.nan))[idx] = col
        if self.cov_enu is None:
            self.tau_s = cov.tau_s
            self.cov_enu = np.full((self.n, 3, 3), np.nan)
            self.effects = np.full((self.n, 3, cov.tau_s.size), np.nan)
        keep = np.asarray(ok, dtype=bool)[:, None, None]
        self.cov_enu[idx] = np.where(keep, np.reshape(cov.cov_enu, (-1, 3, 3)), np.nan)
        self.effects[idx] = np.where(keep, np.reshape(cov.scaled_jacobian, (-1, 3, cov.tau_s.size)), np.nan)
