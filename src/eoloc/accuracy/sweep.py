"""Sweeps: how the accuracy changes with the pointing angle and the terrain relief ([Q] Fig. 10).

For every gimbal angle and relief sigma, the scenario is run by Monte Carlo twice:

- ``ellipsoid``: range-free on the ellipsoid at the mean terrain height, the relief entering as a
  terrain-height error of that sigma (what a DEM-less system must live with);
- ``dem``: M4 on a synthetic relief of that sigma (:func:`relief_dem`, centred on the nominal
  target, the same seeded shape for every sigma), without the terrain term.

Each point is an independent, seeded Monte Carlo run (its seed is the sweep's seed), so a point
gives the same figures wherever it is computed (here or on Dask, through a mapper).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..rules import AtHeight, OnDEM
from ..sensor.model import Pose
from .budget import ErrorBudget, ErrorSource
from .montecarlo import Scenario, monte_carlo, truth_fixes
from .runners import Mapper, local_map
from .scenarios import relief_dem

METHODS = ("ellipsoid", "dem")
ANGLES = {"gimbal1": 0, "gimbal2": 1}


@dataclass(frozen=True)
class SweepPoint:
    """One (method, angle, relief sigma) Monte Carlo: metric figures about the error-free fix (m),
    sigmas of lat/lon (deg); oblique_deg: angle of the line of sight from the local vertical at
    the target; failed: samples not located (all n when the nominal ray itself is not: ``note``)."""

    method: str
    angle_deg: float
    terrain_sigma_m: float
    n: int
    failed: int
    slant_range_m: float
    oblique_deg: float
    cep50_m: float
    cep50_parametric_m: float
    ce90_m: float
    drms_m: float
    sigma_e_m: float
    sigma_n_m: float
    sigma_h_m: float
    sigma_lat_deg: float
    sigma_lon_deg: float
    note: str = ""


def _with_angle(pose: Pose, which: int, value: float) -> Pose:
    g = list(pose.gimbal_deg) + [0.0] * max(0, which + 1 - len(pose.gimbal_deg))
    g[which] = value
    return replace(pose, gimbal_deg=tuple(g))


def sweep_point(scn: Scenario, method: str, angle: str, angle_deg: float, sigma_m: float, n: int, seed: int,
                relief_seed: int) -> SweepPoint:
    """One point of :func:`terrain_sweep` (a pure function of its arguments)."""
    base = ErrorBudget(tuple(s for s in scn.budget if s.name != "terrain_m"))
    pose = _with_angle(scn.pose, ANGLES[angle], angle_deg)
    ell = replace(scn, pose=pose, budget=ErrorBudget((*base.sources, ErrorSource("terrain_m", "normal", sigma_m))))
    t = truth_fixes(ell)
    if method == "ellipsoid":
        run = ell
    elif method == "dem":
        run = replace(scn, pose=pose, budget=base,
                      rule=OnDEM(relief_dem(float(t.lat_deg[0]), float(t.lon_deg[0]), float(scn.rule.h_m), sigma_m,
                                            seed=relief_seed, half_deg=0.15)))
    else:
        raise ValueError(f"unknown sweep method {method!r}; use {' or '.join(METHODS)}")
    nan = float("nan")
    try:
        truth = truth_fixes(run)
        st = monte_carlo(run, n, seed=seed).stats[0]
    except ValueError as exc:
        return SweepPoint(method, angle_deg, sigma_m, n, n, nan, nan, *(nan,) * 9, note=str(exc))
    rays = scn.sensor.rays(pose, scn.pixels[0])
    up = geodesy.R_ecef_enu(truth.lat_deg[0], truth.lon_deg[0])[:, 2]
    cos_obl = -(float(rays.dx) * up[0] + float(rays.dy) * up[1] + float(rays.dz) * up[2])
    return SweepPoint(method, float(angle_deg), float(sigma_m), st.n + st.n_failed, st.n_failed,
                      float(truth.range_m[0]), float(np.degrees(np.arccos(np.clip(cos_obl, -1.0, 1.0)))),
                      st.cep50, st.cep50_parametric, st.ce90, st.drms, st.sigma_enu[0], st.sigma_enu[1],
                      st.sigma_h_m, st.sigma_lat_deg, st.sigma_lon_deg)


def terrain_sweep(scn: Scenario, angles_deg: Sequence[float], terrain_sigmas_m: Sequence[float], *,
                  angle: str = "gimbal1", n: int = 5000, seed: int = 0, methods: Sequence[str] = METHODS,
                  relief_seed: int = 62, mapper: Mapper | None = None,
                  progress: Callable[[int], None] | None = None) -> list[SweepPoint]:
    """CEP and sigmas against a gimbal angle (``angle`` "gimbal1": azimuth / frame roll,
    "gimbal2": elevation / frame pitch, degrees) for each relief sigma (m), ellipsoid vs DEM.

    ``scn`` must stop on the ellipsoid (an :class:`eoloc.AtHeight` rule): its height is the mean terrain height;
    a ``terrain_m`` source in its budget is replaced by each sigma. ``progress(1)`` after each point.
    """
    if not isinstance(scn.rule, AtHeight):  # the sweep compares this rule with a DEM: it is its subject
        raise InputError(f"a terrain sweep needs a scenario that stops on the ellipsoid (stop = 'height', the mean "
                         f"terrain height), got stop = {scn.rule.name!r}")
    if angle not in ANGLES:
        raise InputError(f"angle must be one of {', '.join(ANGLES)}, got {angle!r}")
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"unknown sweep method {m!r}; use {' or '.join(METHODS)}")
    jobs = [(scn, m, angle, float(a), float(s), n, seed, relief_seed)
            for m in methods for s in terrain_sigmas_m for a in angles_deg]
    done = None if progress is None else (lambda i: progress(1))
    return (mapper or local_map)(sweep_point, jobs, done)
