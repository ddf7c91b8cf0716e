"""Accuracy analysis: error budgets, Monte Carlo through the same kernels, CEP, sensitivities."""

from .budget import SOURCES, ErrorBudget, ErrorSource
from .cep import cep_bivariate, cep_empirical, drms, error_ellipse, prob_within
from .montecarlo import MonteCarloResult, Scenario, Sensitivity, TargetStats, monte_carlo, sensitivity, truth_fixes
from .scenarios import SCENARIOS, q_dem, q_ellipsoid, s13

__all__ = [
    "SCENARIOS",
    "SOURCES",
    "ErrorBudget",
    "ErrorSource",
    "MonteCarloResult",
    "Scenario",
    "Sensitivity",
    "TargetStats",
    "cep_bivariate",
    "cep_empirical",
    "drms",
    "error_ellipse",
    "monte_carlo",
    "prob_within",
    "q_dem",
    "q_ellipsoid",
    "s13",
    "sensitivity",
    "truth_fixes",
]
