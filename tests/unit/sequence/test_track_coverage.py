"""The Kalman tracker's uncertainty (eoloc.sequence.track) checked by coverage against a truth
made without eoloc (tests/helpers/coverage_lib.py): ~10^3 targets driving at up to 15 m/s, their
telemetry errors drawn from a budget with biases, noise and Gauss–Markov errors, the biases
carried as consider parameters (issue 47)."""

from __future__ import annotations

import math

import coverage_lib as C
import numpy as np
import pytest

from eoloc.accuracy import locate_with_covariance

N = 1000


@pytest.fixture(params=["height", "range"])
def rule(request):
    return request.param


def test_47_coverage_of_kalman_tracks_with_considered_biases(rule):
    """Targets driving at up to 15 m/s: the constant-velocity Kalman track with the biases and
    Gauss–Markov errors as consider parameters; and, the suite failing it, the same fixes with their
    whole covariance taken as white noise."""
    p = C.simulate(np.random.default_rng(470), N, 30, rule, spread_deg=0.5, speed_mps=15.0)
    C.assert_covers(C.kalman(p, rule), N)
    from eoloc.accuracy.cep import cep_zero_mean, error_ellipses
    from eoloc.sequence.track import track_fixes

    sensor, pose, r, budget = C.eoloc_inputs(p, rule)
    fixes, cov = locate_with_covariance(sensor, pose, budget, (p.measured["u_px"], p.measured["v_px"]), r)
    f_n, k = fixes.status.shape
    ts = track_fixes(np.repeat(p.time_s, k), fixes.flat(), cov.cov_enu.reshape(-1, 3, 3),
                     np.tile(np.arange(k).astype(str), f_n), include_tentative=True)
    last = {tr.track_id: tr for tr in ts.tracks}
    inside = []
    for j in range(k):
        tr = last[str(j)]
        la, lo, hh = ts.geodetic(tr)
        e = error_ellipses(tr.cov[-1][:2, :2])
        r90 = cep_zero_mean(e[0], e[1], 0.9)
        err = C.enu_error(la[-1], lo[-1], hh[-1], p.target[j])
        inside.append(math.hypot(err[0], err[1]) <= r90)
    assert np.mean(inside) < 0.8
