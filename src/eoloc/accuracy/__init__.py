"""Accuracy analysis: error budgets, Monte Carlo through the same kernels, CEP, sensitivities,
first-order covariance of every fix."""

from . import scenarios
from .budget import SOURCES, ErrorBudget, ErrorSource
from .cep import cep_bivariate, cep_empirical, cep_zero_mean, drms, error_ellipse, error_ellipses, prob_within
from .covariance import FixCovariance, covariance_columns, locate_with_covariance
from .montecarlo import MonteCarloResult, Scenario, Sensitivity, TargetStats, monte_carlo, sensitivity, truth_fixes
from .runners import DaskMapper, dask_mapper, local_map
from .scenarios import SCENARIOS, q_dem, q_ellipsoid, relief_dem, s13
from .sweep import SweepPoint, terrain_sweep

__all__ = [
    "SCENARIOS",
    "SOURCES",
    "DaskMapper",
    "ErrorBudget",
    "ErrorSource",
    "FixCovariance",
    "MonteCarloResult",
    "Scenario",
    "Sensitivity",
    "SweepPoint",
    "TargetStats",
    "cep_bivariate",
    "cep_empirical",
    "cep_zero_mean",
    "covariance_columns",
    "dask_mapper",
    "drms",
    "error_ellipse",
    "error_ellipses",
    "local_map",
    "locate_with_covariance",
    "monte_carlo",
    "prob_within",
    "q_dem",
    "q_ellipsoid",
    "relief_dem",
    "s13",
    "scenarios",
    "sensitivity",
    "terrain_sweep",
    "truth_fixes",
]
