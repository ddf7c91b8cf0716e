"""The accuracy of the flight you flew: every fix and every target of real telemetry, first-order and
by Monte Carlo side by side, with what does not average (the biases) shown apart from what does.

First order: each fix's covariance from the budget (:func:`eoloc.accuracy.locate_with_covariance`)
split by how its sources behave in time (bias, Gauss–Markov, noise); each target's estimate over
its fixes (:func:`eoloc.sequence.rls.rls_static` with that structure) and the same split.

Monte Carlo: ``n`` copies of the whole flight, each with errors drawn as the budget says they
behave (:func:`flight_errors`): a bias once for the flight, noise anew at every frame time, a
Gauss–Markov error as a stationary first-order process over the frame times; the sources of the
aircraft and sensor (position, attitude, gimbal, camera, installation, time) common to every
target seen at one time, those of a detection (pixel, laser range) its own, the terrain's error
its target's own. Every copy is located by the same chain (:func:`eoloc.accuracy.montecarlo.chain_fixes`)
and every target's fixes are combined again; the spread about the nominal gives each fix's and
each target's empirical CEP50, CE90 and LE90. Where first order and Monte Carlo disagree, the
chain is not linear there (a ridge, a grazing ray) and Monte Carlo is the figure to use.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .. import geodesy
from ..accuracy.budget import ErrorBudget
from ..accuracy.cep import cep_ce_le
from ..accuracy.covariance import FixCovariance
from ..accuracy.montecarlo import chain_fixes
from ..result import Fixes, Status
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel
from .rls import rls_static

PER_DETECTION = ("u_px", "v_px", "range_m")  # measured per detection; the terrain: per target
PER_TARGET = ("terrain_m",)
KINDS = ("bias", "markov", "noise")


def _series(rng: np.random.Generator, sigma: float, kind: str, tau_s: float, times: np.ndarray,
            shape: tuple[int, ...]) -> np.ndarray:
    """Draws (*shape, T) of one source at the sorted ``times``: a bias (one value), noise, or a
    stationary Gauss–Markov process (normal laws)."""
    t_n = times.size
    if kind == "bias":
        return np.broadcast_to(rng.normal(0.0, sigma, (*shape, 1)), (*shape, t_n))
    if kind == "noise":
        return rng.normal(0.0, sigma, (*shape, t_n))
    out = np.empty((*shape, t_n))
    out[..., 0] = rng.normal(0.0, sigma, shape)
    rho = np.exp(-np.diff(times) / tau_s)
    for i in range(1, t_n):
        out[..., i] = rho[i - 1] * out[..., i - 1] + np.sqrt(1.0 - rho[i - 1] ** 2) * rng.normal(0.0, sigma, shape)
    return out


def flight_errors(budget: ErrorBudget, rng: np.random.Generator, time_s: np.ndarray, target_id: np.ndarray,
                  n: int) -> dict[str, np.ndarray]:
    """(n, N) errors of every source for N detections at ``time_s`` of targets ``target_id``, drawn
    as the module says (the aircraft's and sensor's common to a time, a detection's own, the
    terrain's per target). A uniform law keeps its spread as a normal of the same sigma in time."""
    times, t_idx = np.unique(np.asarray(time_s, dtype=np.float64), return_inverse=True)
    ids, k_idx = np.unique(np.asarray(target_id).astype(str), return_inverse=True)
    out = {}
    for src in budget:
        if src.sigma == 0:
            continue
        if src.name in PER_TARGET:
            e = _series(rng, src.sigma, src.kind, src.tau_s, times, (n, ids.size))[:, k_idx, t_idx]
        elif src.name in PER_DETECTION:
            if src.kind == "noise":
                e = rng.normal(0.0, src.sigma, (n, t_idx.size))
            else:  # a pixel or range bias: the same for a target's detections
                e = _series(rng, src.sigma, src.kind, src.tau_s, times, (n, ids.size))[:, k_idx, t_idx]
        else:
            e = _series(rng, src.sigma, src.kind, src.tau_s, times, (n,))[:, t_idx]
        out[src.name] = np.ascontiguousarray(e)
    return out


@dataclass(frozen=True)
class FlightAccuracy:
    """Per fix and per target: first-order and Monte Carlo figures (lists of dict rows for the
    writers), and the Monte Carlo's size."""

    fixes: list[dict]
    targets: list[dict]
    samples: int


def _spread(enu: np.ndarray, ok: np.ndarray) -> dict[str, np.ndarray]:
    """Empirical CEP50, CE90, LE90 over axis 0 of errors ``enu`` (n, ..., 3) where ``ok``."""
    r = np.where(ok, np.hypot(enu[..., 0], enu[..., 1]), np.nan)
    up = np.where(ok, np.abs(enu[..., 2]), np.nan)
    with warnings.catch_warnings():  # a fix no copy located: NaN, said by mc_failed
        warnings.simplefilter("ignore", RuntimeWarning)
        return {"mc_cep50_m": np.nanquantile(r, 0.5, axis=0), "mc_ce90_m": np.nanquantile(r, 0.9, axis=0),
                "mc_le90_m": np.nanquantile(up, 0.9, axis=0)}


def flight_accuracy(sensor: SensorModel, pose: Pose, pixels: tuple[np.ndarray, np.ndarray], rule: StopRule,
                    budget: ErrorBudget, fixes: Fixes, cov: FixCovariance, time_s: np.ndarray, target_id: np.ndarray,
                    *, n: int = 1000, seed: int = 0, chunk: int = 200,
                    progress: Callable[[int], None] | None = None) -> FlightAccuracy:
    """The module's figures for N located detections: their ``pose`` (N,), ``pixels``, stop
    ``rule`` (values per detection where it has them), ``fixes`` and first-order ``cov`` as
    located, times and target ids; ``n`` Monte Carlo copies of the flight in chunks of ``chunk``
    copies (``progress(k)`` after each)."""
    time_s = np.asarray(time_s, dtype=np.float64)
    ids = np.asarray(target_id).astype(str)
    ok = np.asarray(fixes.ok)
    p0 = fixes.p_ecef()
    R = geodesy.R_ecef_enu(np.nan_to_num(fixes.lat_deg), np.nan_to_num(fixes.lon_deg))
    fo = cep_ce_le(cov.cov_enu)
    parts = {k: cep_ce_le(cov.part(k), vertical=False)["ce90_m"] for k in KINDS}
    targets = sorted(set(ids[ok].tolist()))
    sel = {t: np.flatnonzero((ids == t) & ok) for t in targets}
    sel = {t: s[np.argsort(time_s[s], kind="stable")] for t, s in sel.items()}
    nominal = {t: rls_static(fixes.flat(s), covariance=cov.take(s), time_s=time_s[s]) for t, s in sel.items()}

    # each target's fixes as many columns as copies of the flight in a chunk: their structure,
    # the same in every copy, broadcast along the copies
    wide = {}
    for t, s in sel.items():
        c = cov.take(s)
        wide[t] = FixCovariance(c.cov_enu[:, None], c.jacobian_enu[:, None], c.sources, c.sigma_in,
                                c.nonlinearity[:, None], c.lat_deg[:, None], c.h_m[:, None], c.kinds, c.tau_s)
    fix_err, fix_ok = [], []
    est_err = {t: [] for t in targets}
    est_ok = {t: [] for t in targets}
    rng = np.random.default_rng(seed)
    done = 0
    while done < n:
        m = min(chunk, n - done)
        d = flight_errors(budget, rng, time_s, ids, m)
        f = chain_fixes(sensor, pose, pixels[0], pixels[1], rule, d, m)
        enu = np.einsum("nij,mni->mnj", R, f.p_ecef() - p0[None])  # (m, N, 3) about each nominal fix
        good = f.ok & ok[None]
        fix_err.append(enu)
        fix_ok.append(good)
        for t, s in sel.items():
            fm = Fixes(*(np.asarray(a)[:, s].T for a in (f.lat_deg, f.lon_deg, f.h_m, f.range_m, f.status)))
            if not fm.ok.any():
                est_ok[t].append(np.zeros(m, bool))
                est_err[t].append(np.full((m, 3), np.nan))
                continue
            e = rls_static(fm, covariance=wide[t], time_s=time_s[s], origin=nominal[t].origin,
                           check_consistency=False)
            q = np.stack(geodesy.geodetic_to_ecef(e.lat_deg, e.lon_deg, e.h_m), -1)
            est_err[t].append(geodesy.ecef_to_enu(q, nominal[t].lat_deg, nominal[t].lon_deg, nominal[t].h_m))
            est_ok[t].append(np.isfinite(e.lat_deg))
        done += m
        if progress is not None:
            progress(m)
    mc = _spread(np.concatenate(fix_err), np.concatenate(fix_ok))
    failed = 1.0 - np.concatenate(fix_ok).mean(axis=0)
    fix_rows = []
    for i in range(ids.size):
        row = {"target_id": ids[i], "time_s": float(time_s[i]), "lat_deg": float(fixes.lat_deg[i]),
               "lon_deg": float(fixes.lon_deg[i]), "h_m": float(fixes.h_m[i]),
               "status": Status(int(fixes.status[i])).name}
        if ok[i]:
            row |= {k: float(v[i]) for k, v in fo.items()}
            row |= {f"ce90_{k}_m": float(parts[k][i]) for k in KINDS}
            row |= {k: float(v[i]) for k, v in mc.items()}
            row |= {"mc_failed": float(failed[i]), "nonlinearity": float(cov.nonlinearity[i])}
        fix_rows.append(row)
    target_rows = []
    for t in targets:
        est = nominal[t]
        row = {"target_id": t, "fixes": int(sel[t].size), "status": Status(int(est.status)).name}
        if est.status == Status.OK:
            row |= {"lat_deg": float(est.lat_deg), "lon_deg": float(est.lon_deg), "h_m": float(est.h_m)}
            row |= {k: float(v) for k, v in cep_ce_le(est.cov_enu).items()}
            row |= {f"ce90_{k}_m": float(cep_ce_le(est.cov_by_kind[k], vertical=False)["ce90_m"]) for k in KINDS}
            row["single_fix_ce90_m"] = float(np.median(fo["ce90_m"][sel[t]]))
        if est.status == Status.OK:
            row |= {k: float(v) for k, v in _spread(np.concatenate(est_err[t]), np.concatenate(est_ok[t])).items()}
        target_rows.append(row)
    return FlightAccuracy(fix_rows, target_rows, n)
