"""CEP and LE90 against scipy (quadrature of the density, the normal's quantile): no eoloc code
in the references (issue 55)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc


@settings(max_examples=40, deadline=None)
@given(st.floats(0.01, 1.0), st.sampled_from([0.5, 0.9, 0.95]))
def test_55_cep_of_an_elongated_ellipse_against_a_quadrature(ratio, p):
    """cep_zero_mean(σ1, σ2, p) = the radius R with P(|e| < R) = p for e ~ N(0, diag(σ1², σ2²)),
    R found here by scipy's quadrature of the polar density and a root search (no eoloc code)."""
    from scipy import integrate, optimize

    from eoloc.accuracy.cep import cep_zero_mean

    s1, s2 = 10.0, 10.0 * ratio

    def inside(R):
        f = lambda r, t: r * np.exp(-0.5 * ((r * np.cos(t) / s1) ** 2 + (r * np.sin(t) / s2) ** 2)) / (  # noqa: E731
            2 * np.pi * s1 * s2)
        return integrate.dblquad(f, 0.0, 2 * np.pi, 0.0, R, epsabs=1e-10, epsrel=1e-9)[0] - p

    want = optimize.brentq(inside, 1e-6, 10.0 * s1)
    assert float(cep_zero_mean(s1, s2, p)) == pytest.approx(want, rel=2e-3)


def test_55_le90_is_the_two_sided_90_percent_of_a_normal():
    """A fix's LE90 = the 90 % quantile of |N(0, σ_u)| = scipy's norm.ppf(0.95) σ_u."""
    from scipy.stats import norm

    from eoloc.accuracy import ErrorBudget, locate_with_covariance

    sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(20.0, 1280, 720), eoloc.AzElGimbal())
    pose = eoloc.Pose(40.0, -105.0, 3000.0, 30.0, 1.0, -2.0, (250.0, -25.0))
    _, cov = locate_with_covariance(sensor, pose, ErrorBudget.from_mapping({"h_m": {"normal": 4.0},
                                                                            "range_m": {"normal": 2.0}}),
                                    (300.0, 200.0), eoloc.AtRange(5000.0))
    assert float(cov.le90) == pytest.approx(norm.ppf(0.95) * float(cov.sigma_enu[2]), rel=1e-12)
