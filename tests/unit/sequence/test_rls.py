"""Recursive least squares (eoloc.sequence.rls) against restatements that share no code with it:
the covariance of the recursion against the brute-force double sum over pairs of fixes, biases
that never average down, near-singular fix covariances that must not add up to a false
certainty, and the consistency test's verdict on fixes that jump between two places (issue 47)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc.accuracy import ErrorBudget, locate_with_covariance
from eoloc.result import Status
from eoloc.sequence.rls import RLSState, rls_static, weights


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 25), st.floats(0.7, 1.0), st.integers(0, 2**31 - 1))
def test_47_rls_covariance_is_the_exact_sum_over_pairs(n, lam, seed):
    """The recursion of RLSState with an error structure equals, to rounding, the brute-force
    A^-1 (sum_j sum_k lam^(n-j) lam^(n-k) W_j C_jk W_k) A^-1 with C_jk = sum_s a_js a_ks^T rho_s(t_k - t_j)
    (rho 1 bias, delta noise, exp(-|dt| / tau) Gauss–Markov), at irregular times and with frames
    where the target is not seen."""
    rng = np.random.default_rng(seed)
    tau = np.array([0.0, np.inf, 3.0, 40.0])
    t = np.cumsum(rng.uniform(0.1, 5.0, n))
    a = rng.normal(0.0, 2.0, (n, 3, tau.size))
    use = rng.random(n) < 0.8
    use[0] = True
    R = a @ np.swapaxes(a, -1, -2)
    W = weights(R, use)
    s = RLSState.empty(1, lam)
    z = rng.normal(size=(n, 3))
    for k in range(n):
        s.update(z[k][None], R[k][None], W[k][None], use[k:k + 1], a=a[k][None], tau_s=tau, time_s=t[k])
    w = lam ** np.arange(n - 1, -1, -1.0)
    A = np.einsum("n,nij->ij", w, W)
    P = np.zeros((3, 3))
    for j in range(n):
        for k in range(n):
            if not (use[j] and use[k]):
                continue
            dt = abs(t[k] - t[j])
            with np.errstate(invalid="ignore", divide="ignore"):
                decay = np.exp(-dt / np.where(tau > 0, tau, 1))
                rho = np.where(tau == np.inf, 1.0, np.where(tau == 0, float(j == k), decay))
            Cjk = (a[j] * rho) @ a[k].T
            P += w[j] * w[k] * W[j] @ Cjk @ W[k]
    want = np.linalg.inv(A) @ P @ np.linalg.inv(A)
    np.testing.assert_allclose(s.covariance()[0], want, rtol=1e-8, atol=1e-10 * np.abs(want).max())


def test_47_averaging_never_beats_the_systematic_floor():
    """A budget of biases only, the same geometry every frame: 200 frames give the one-fix
    covariance back (nothing averages), where the old independent combination said 1/200 of it."""
    sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(20.0, 1280, 720), eoloc.AzElGimbal())
    n = 200
    pose = eoloc.Pose(np.full(n, 40.0), -105.0, 3000.0, 30.0, 1.0, -2.0, (250.0, -25.0))
    budget = ErrorBudget.from_mapping({"gimbal1_deg": {"normal": 0.05}, "mount_y_deg": {"normal": 0.05}})
    fixes, cov = locate_with_covariance(sensor, pose, budget, (np.full(n, 600.0), 300.0), eoloc.AtHeight(1600.0))
    est = rls_static(fixes, covariance=cov, time_s=np.arange(n, dtype=float))
    np.testing.assert_allclose(est.cov_enu[:2, :2], cov.cov_enu[0][:2, :2], rtol=1e-6, atol=1e-9)
    old = rls_static(fixes, cov.cov_enu, correlated_fraction=0.0)
    assert np.trace(old.cov_enu[:2, :2]) < np.trace(cov.cov_enu[0][:2, :2]) / 100


def test_47_near_singular_fix_covariances_make_no_false_certainty():
    """Fixes on surfaces tilted differently, each covariance nearly singular across its own
    surface (the DEM case): their information summed said millimetres; weighed by the floored
    horizontal block, the estimate's covariance is that of the average (~R/n), not less."""
    rng = np.random.default_rng(5)
    n = 40
    R = np.zeros((n, 3, 3))
    for k in range(n):
        normal = np.array([*rng.normal(0, 0.5, 2), 1.0])
        normal /= np.linalg.norm(normal)
        Pt = np.eye(3) - np.outer(normal, normal)  # spread in the facet's plane only
        R[k] = 60.0 * Pt + 1e-10 * np.eye(3)
    use = np.ones(n, bool)
    s = RLSState.empty(1)
    for k in range(n):
        s.update(rng.normal(size=(1, 3)), R[k][None], weights(R[k][None], use[k:k + 1]), use[k:k + 1])
    horiz = np.trace(s.covariance(0.0)[0][:2, :2])
    assert horiz > 0.5 * np.trace(R.mean(0)[:2, :2]) / n
    info = np.linalg.inv(np.sum(np.linalg.inv(R), axis=0))  # the old information sum
    assert np.trace(info[:2, :2]) < 1e-3 * horiz


def test_fixes_that_jump_between_two_places_are_inconsistent_and_ones_that_scatter_as_declared_are_not():
    """The consistency test on its own: 40 targets, 60 frames each from a hovering camera, a
    noise-only budget (the fixes' scatter is what their covariance declares): the fixes drawn from their own covariance
    (numpy's multivariate normal) pass for at least 38 of 40 (the test's false alarms are 1e-3);
    the same fixes with every other frame moved 60 m north (a summit and the slope behind it)
    are INCONSISTENT, all 40, with no point."""
    from pymap3d import enu2geodetic

    sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(20.0, 1280, 720), eoloc.AzElGimbal())
    f_n, k_n = 60, 40
    rng = np.random.default_rng(12)
    u = np.broadcast_to(rng.uniform(200.0, 1000.0, k_n), (f_n, k_n))
    v = np.broadcast_to(rng.uniform(150.0, 550.0, k_n), (f_n, k_n))
    pose = eoloc.Pose(np.full((f_n, 1), 40.0), -105.0, 3000.0, 30.0, 1.0, -2.0, (250.0, -25.0))  # a hover
    budget = ErrorBudget.from_mapping({"u_px": {"normal": 1.0}, "v_px": {"normal": 1.0},
                                       "vibration_yaw_deg": {"normal": 0.02}})
    fixes, cov = locate_with_covariance(sensor, pose, budget, (u, v), eoloc.AtHeight(1600.0))
    assert np.all(fixes.status == Status.OK)
    # each fix moved by a draw from its own covariance, in ENU about itself
    c = np.reshape(cov.cov_enu, (-1, 3, 3))
    d = np.array([rng.multivariate_normal(np.zeros(3), ck) for ck in c]).reshape(f_n, k_n, 3)
    lat, lon, h = enu2geodetic(d[..., 0], d[..., 1], d[..., 2], fixes.lat_deg, fixes.lon_deg, fixes.h_m)
    scattered = eoloc.Fixes(lat, lon, h, fixes.range_m, fixes.status)
    t = np.arange(f_n, dtype=float)
    est = rls_static(scattered, covariance=cov, time_s=t)
    assert np.sum(est.status == Status.OK) >= 38, est.status
    jump = np.where((np.arange(f_n) % 2 == 1)[:, None], 60.0, 0.0) * np.ones(k_n)
    lat2, lon2, h2 = enu2geodetic(d[..., 0], d[..., 1] + jump, d[..., 2], fixes.lat_deg, fixes.lon_deg, fixes.h_m)
    est2 = rls_static(eoloc.Fixes(lat2, lon2, h2, fixes.range_m, fixes.status), covariance=cov, time_s=t)
    assert np.all(est2.status == Status.INCONSISTENT) and np.all(np.isnan(est2.lat_deg)), est2.status
