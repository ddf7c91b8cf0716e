"""The RLS consistency test's chi-square quantile against scipy's (issue 55)."""

from __future__ import annotations


def test_55_chi2_quantile_against_scipy():
    """The consistency test's chi-square quantile (Wilson–Hilferty, no scipy in a live session)
    against scipy's, at the test's p = 0.999: within what its docstring states, never below."""
    from scipy.stats import chi2

    from eoloc.sequence.rls import INCONSISTENT_P, chi2_quantile

    for dof, tol in ((2, 0.025), (20, 0.003), (76, 0.0006), (400, 1e-4)):
        got, want = float(chi2_quantile(1.0 - INCONSISTENT_P, dof)), chi2.ppf(1.0 - INCONSISTENT_P, dof)
        assert want <= got <= want * (1.0 + tol), (dof, got, want)
