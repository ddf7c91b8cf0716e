"""Accuracy analysis: error budgets, Monte Carlo through the same kernels, CEP, sensitivities,
first-order covariance of every fix."""

from ..util.lazy import lazy_attributes

# names -> their module, imported on first use (PEP 562): `from eoloc.accuracy import ErrorBudget`
# must not load Monte Carlo, CEP quadrature and scipy (start-up of the command line)
_WHERE = {
    "DaskMapper": "runners",
    "ErrorBudget": "budget",
    "ErrorSource": "budget",
    "FixCovariance": "covariance",
    "MonteCarloResult": "montecarlo",
    "SCENARIOS": "scenarios",
    "SOURCES": "budget",
    "Scenario": "montecarlo",
    "Sensitivity": "montecarlo",
    "SweepPoint": "sweep",
    "TargetStats": "montecarlo",
    "cep_bivariate": "cep",
    "cep_empirical": "cep",
    "cep_zero_mean": "cep",
    "covariance_columns": "covariance",
    "dask_mapper": "runners",
    "drms": "cep",
    "error_ellipse": "cep",
    "error_ellipses": "cep",
    "local_map": "runners",
    "locate_with_covariance": "covariance",
    "monte_carlo": "montecarlo",
    "prob_within": "cep",
    "q_dem": "scenarios",
    "q_ellipsoid": "scenarios",
    "relief_dem": "scenarios",
    "s13": "scenarios",
    "sensitivity": "montecarlo",
    "terrain_sweep": "sweep",
    "truth_fixes": "montecarlo",
}


__getattr__ = lazy_attributes(__name__, _WHERE)


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
