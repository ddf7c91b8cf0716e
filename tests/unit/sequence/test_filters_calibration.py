"""Many frames (issue 5): RLS for static targets (M6), Kalman tracks (M7), boresight calibration."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from where import ROOT

from eoloc import AtHeight, AzElGimbal, Camera, Fixes, SensorModel, Status, geodesy, locate_ellipsoid
from eoloc.accuracy import locate_with_covariance
from eoloc.accuracy.budget import ErrorBudget
from eoloc.sequence import TelemetryNoise, rls_static, synthetic_flight
from eoloc.sequence.calibration import TelemetryTrack, calibrate
from eoloc.sequence.simulate import gcp_flight
from eoloc.sequence.track import TrackerConfig, cv_model, joseph_update, track_features, track_fixes

Z15_CAM = Camera.from_focal_mm(50.0, 5.5, 1024, 768)


def _example(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# -- RLS ---------------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 60), st.floats(0.8, 1.0), st.integers(0, 2**31))
def test_rls_is_the_weighted_mean_and_its_covariance(n, lam, seed):
    """lam = 1 with per-fix covariances: the estimate is the information-weighted mean, and its
    covariance (sum R^-1)^-1; with forgetting, the covariance is A^-1 B A^-1 (checked by brute force)."""
    rng = np.random.default_rng(seed)
    truth_enu = np.array([30.0, -20.0, 0.0])
    sig = rng.uniform(2.0, 9.0, (n, 3))
    R = np.stack([np.diag(s**2) for s in sig])
    z = truth_enu + rng.normal(size=(n, 3)) * sig
    origin = (45.0, 7.0, 100.0)
    p = geodesy.enu_to_ecef(z, *origin)
    lat, lon, h = geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    fixes = Fixes(lat, lon, h, np.full(n, 1000.0), np.zeros(n, np.int8))
    est = rls_static(fixes, R, origin=origin, correlated_fraction=0.0)
    W = np.linalg.inv(R)
    want_cov = np.linalg.inv(W.sum(0))
    want = want_cov @ np.einsum("nij,nj->i", W, z)
    np.testing.assert_allclose(est.enu_m[-1], want, atol=1e-6)
    np.testing.assert_allclose(est.cov_enu, want_cov, rtol=1e-6)
    est = rls_static(fixes, R, origin=origin, forgetting=lam, correlated_fraction=0.0)
    w = lam ** np.arange(n - 1, -1, -1)
    A = np.einsum("n,nij->ij", w, W)
    x = np.linalg.solve(A, np.einsum("n,nij,nj->i", w, W, z))
    var = np.linalg.inv(A) @ np.einsum("n,nij->ij", w**2, W) @ np.linalg.inv(A)
    np.testing.assert_allclose(est.enu_m[-1], x, atol=1e-6)
    np.testing.assert_allclose(est.cov_enu, var, rtol=1e-6)


def test_rls_skips_failed_fixes_and_reports_bad_arguments():
    n = 10
    st = np.zeros(n, np.int8)
    st[3] = Status.NO_INTERSECTION
    lat = np.where(st == 0, 45.0, np.nan)
    fixes = Fixes(lat, np.where(st == 0, 7.0, np.nan), np.where(st == 0, 0.0, np.nan), np.ones(n), st)
    est = rls_static(fixes, sigma_m=5.0, correlated_fraction=0.0)
    assert est.n_used == n - 1
    assert est.lat_deg == pytest.approx(45.0, abs=1e-12)
    assert est.cov_enu[0, 0] == pytest.approx(25.0 / (n - 1), rel=1e-6)
    # identical fixes: no scatter at all, so "auto" takes the declared error as common to every frame
    auto = rls_static(fixes, sigma_m=5.0)
    assert auto.scatter_ratio == pytest.approx(0.0, abs=1e-9)
    assert auto.cov_enu[0, 0] == pytest.approx(0.01 * 25.0 / (n - 1) + 0.99 * 25.0, rel=1e-6)
    with pytest.raises(ValueError, match="forgetting"):
        rls_static(fixes, forgetting=1.5)
    with pytest.raises(ValueError, match="no fix"):
        rls_static(Fixes(*(np.full(3, np.nan),) * 4, np.full(3, Status.NO_INTERSECTION, np.int8)))


def test_rls_over_150_frames_cuts_cep_by_a_quarter_and_predicts_its_own_cep():
    """[Z15] Table 1 errors, half of each source's variance a per-flight bias (the model under which
    [Z15]'s -25 % is reached): CEP50 single-frame vs RLS over 150 frames >= 25 % lower; the RLS
    covariance (bias share estimated from the scatter) predicts the filtered CEP within 20 %; the
    estimate converges within the 150 frames ([Z15]: 100-150)."""
    r = _example("rls_static_targets").experiment(0.5, flights=100, seed=0)  # the script's own table row
    assert r["frames"] == 150
    assert r["reduction"] >= 0.25, r
    assert r["cep_predicted_m"] == pytest.approx(r["cep_rls_m"], rel=0.2)
    assert 60 <= r["converged_frame"] <= 150 and r["converged_share"] > 0.8
    white = _example("rls_static_targets").experiment(0.0, flights=10, seed=2)
    assert white["reduction"] > 0.85  # independent errors average down as 1/sqrt(150)
    assert white["cep_predicted_m"] == pytest.approx(white["cep_rls_m"], rel=0.5)


# -- Kalman tracks -------------------------------------------------------------------------------------


def test_joseph_update_equals_the_textbook_form_and_cv_model():
    rng = np.random.default_rng(1)
    F, Q = cv_model(0.5, 2.0)
    assert F[0, 2] == 0.5 and Q[0, 0] == pytest.approx(2.0 * 0.125 / 3) and Q[0, 2] == pytest.approx(0.25)
    M = rng.normal(size=(4, 4))
    P = M @ M.T + np.eye(4)
    R = np.diag([4.0, 9.0])
    x = rng.normal(size=4)
    z = rng.normal(size=2)
    x1, P1 = joseph_update(x, P, z, R)
    Hm = np.eye(2, 4)
    K = P @ Hm.T @ np.linalg.inv(Hm @ P @ Hm.T + R)
    np.testing.assert_allclose(x1, x + K @ (z - Hm @ x), atol=1e-12)
    np.testing.assert_allclose(P1, (np.eye(4) - K @ Hm) @ P, atol=1e-10)
    assert np.allclose(P1, P1.T) and np.all(np.linalg.eigvalsh(P1) > 0)


MOVING_PX = [(453, 342), (476, 251), (504, 213)]
MOVING_VEL = [(8.0, 3.0), (-12.0, 5.0), (0.0, -20.0)]
JITTER = {"lat_deg": 5e-6, "lon_deg": 5e-6, "h_m": 0.5, "yaw_deg": 0.02, "pitch_deg": 0.02, "roll_deg": 0.02,
          "gimbal1_deg": 0.01, "gimbal2_deg": 0.01, "u_px": 1.0, "v_px": 1.0}
INS_BIAS = {"lat_deg": 1e-5, "lon_deg": 1e-5, "h_m": 2.0, "yaw_deg": 0.05, "pitch_deg": 0.02, "roll_deg": 0.02,
            "gimbal1_deg": 0.01, "gimbal2_deg": 0.01}


def moving_scene(seed, bias=INS_BIAS, duration_s=6.0):
    """[Z15]'s moving-target scenario: f 73.6 mm, 2.5 km altitude, ~3.2 km slant range, its three
    sub-target pixels, the targets driving at 8.5, 13 and 20 m/s."""
    sensor = SensorModel(Camera.from_focal_mm(73.6, 5.5, 1024, 768), AzElGimbal())
    fl = synthetic_flight(sensor, centre=(42.6, 120.9, 226.0), targets_px=MOVING_PX, velocity_enu_mps=MOVING_VEL,
                          height_agl_m=2279.0, ground_range_m=2300.0, bearing_deg=190.0, heading_deg=350.2,
                          pitch_deg=2.0, roll_deg=-1.8, speed_mps=50.0, duration_s=duration_s, fps=30.0,
                          noise=TelemetryNoise(bias=bias, white=JITTER), seed=seed)
    budget = ErrorBudget.from_mapping({k: {"normal": v} for k, v in JITTER.items()})
    fixes, cov = locate_with_covariance(sensor, fl.frame_pose(), budget, fl.pixels, AtHeight(fl.ground_h_m),
                                        check_linearity=False)
    f, k = fixes.status.shape
    return fl, fixes.flat(), cov.cov_enu.reshape(-1, 3, 3), np.repeat(fl.time_s, k), np.tile(np.arange(k), f)


@pytest.mark.parametrize("associate", [False, True])
def test_moving_targets_speed_within_half_a_metre_per_second_after_5_s(associate):
    """With ids, and without (gated global nearest neighbour): three tracks, each pure, and the
    speed 5 s in within 0.5 m/s of truth on 6 seeded flights; heading within 3 degrees."""
    errors = []
    for seed in range(6):
        fl, fixes, cov, t, ids = moving_scene(seed)
        ts = track_fixes(t, fixes, cov, None if associate else ids.astype(str), associate=associate)
        assert len(ts.tracks) == 3
        for tr in ts.tracks:
            members = ids[np.asarray(tr.detection)]
            assert np.all(members == members[0]), "a track mixed two targets"
            assert len(tr.time_s) == fl.time_s.size
            k = int(np.searchsorted(tr.time_s, 5.0))
            v = np.asarray(MOVING_VEL[members[0]])
            errors.append(tr.speed_mps[k] - np.hypot(*v))
            hd = np.degrees(np.arctan2(v[0], v[1])) % 360
            assert abs((tr.heading_deg[k] - hd + 180) % 360 - 180) < 3.0
            assert 0.05 < tr.speed_sigma_mps[k] < 1.0
    assert np.max(np.abs(errors)) < 0.5, errors


def test_heading_bias_turns_the_aircraft_motion_into_target_speed_error():
    """A [Z15] Table 1 yaw bias (1.5 deg) rotates the line of sight's motion: the apparent target
    velocity is off by about bias x |v_aircraft - v_target|, ~1 m/s here: the reason the speed
    test above uses an INS-grade bias. The filter cannot know it; this documents the limit."""
    bias = dict(INS_BIAS, yaw_deg=0.0)
    fl, fixes, cov, t, ids = moving_scene(3, bias=bias)
    base = track_fixes(t, fixes, cov, ids.astype(str))
    pose = dataclasses.replace(fl.pose_measured, yaw_deg=np.asarray(fl.pose_measured.yaw_deg) + 1.5)
    sensor = SensorModel(Camera.from_focal_mm(73.6, 5.5, 1024, 768), AzElGimbal())
    from eoloc.sequence.simulate import per_frame

    f2 = locate_ellipsoid(sensor, per_frame(pose), fl.ground_h_m, fl.pixels)
    biased = track_fixes(t, f2.flat(), cov, ids.astype(str))
    for a, b in zip(base.tracks, biased.tracks, strict=True):
        j = ids[a.detection[0]]
        rel = np.hypot(*(np.array([np.sin(np.radians(350.2)), np.cos(np.radians(350.2))]) * 50.0
                         - np.asarray(MOVING_VEL[j])))
        dv = np.hypot(*(np.asarray(b.state)[-1, 2:] - np.asarray(a.state)[-1, 2:]))
        assert dv == pytest.approx(np.radians(1.5) * rel, rel=0.25)


def test_association_gates_out_a_far_clutter_point_and_tracks_export_as_linestrings():
    fl, fixes, cov, t, ids = moving_scene(0, duration_s=2.0)
    far = Fixes(*(np.r_[a, b] for a, b in zip(
        (fixes.lat_deg, fixes.lon_deg, fixes.h_m, fixes.range_m, fixes.status),
        (np.array([fixes.lat_deg[0] + 0.01]), np.array([fixes.lon_deg[0]]), np.array([fixes.h_m[0]]),
         np.array([3000.0]), np.array([0], np.int8)), strict=True)))
    ts = track_fixes(np.r_[t, 1.0], far, np.r_[cov, cov[:1]], config=TrackerConfig(confirm_hits=3))
    assert len(ts.tracks) == 3  # the lone clutter point starts a tentative track that is never confirmed
    assert ts.assigned[-1] == ""
    feats = track_features(ts)
    assert [f["geometry"]["type"] for f in feats] == ["LineString"] * 3
    for f in feats:
        props = f["properties"]
        assert len(props["coordTimes"]) == len(f["geometry"]["coordinates"]) == props["updates"]
        assert props["coordTimes"] == sorted(props["coordTimes"])
        lon, lat, _ = f["geometry"]["coordinates"][0]
        assert abs(lat - 42.6) < 0.05 and abs(lon - 120.9) < 0.05
    with pytest.raises(ValueError, match="associate"):
        track_fixes(t, fixes, associate=False)


# -- calibration ---------------------------------------------------------------------------------------

CAL_JITTER = {"lat_deg": 5e-7, "lon_deg": 5e-7, "h_m": 0.1, "yaw_deg": 0.005, "pitch_deg": 0.005,
              "roll_deg": 0.005, "gimbal1_deg": 0.003, "gimbal2_deg": 0.003, "u_px": 0.5, "v_px": 0.5}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_calibration_recovers_the_misalignment_from_20_gcps(seed):
    """Mount misalignment 0.3/0.2/0.5 deg, 20 GCP observations with a navigation-grade INS's jitter:
    recovered within 0.01 deg, inside 4 of its own sigma; the located GCP error drops from the
    systematic level (~20 m) to the level of the random errors alone (the true sensor's)."""
    nominal = SensorModel(Z15_CAM, AzElGimbal())
    true = dataclasses.replace(nominal, mount_misalignment_deg=(0.3, 0.2, 0.5))
    g = gcp_flight(true, 20, noise=TelemetryNoise(white=CAL_JITTER), seed=seed)
    c = calibrate(nominal, g.pixels, g.gcp_llh, pose=g.obs_pose, pixel_sigma_px=0.5)
    err = c.values - np.array([0.3, 0.2, 0.5])
    assert np.all(np.abs(err) < 0.01), err
    assert np.all(np.abs(err) < 4 * c.sigma)
    assert c.sensor.mount_misalignment_deg == pytest.approx(tuple(c.values))
    assert c.rms(c.ground_error_before_m) > 10.0
    from eoloc.sequence.calibration import _ground_error

    p_gcp = np.stack(geodesy.geodetic_to_ecef(*g.gcp_llh.T), -1)
    random_level = c.rms(_ground_error(true, g.obs_pose, g.pixels, g.gcp_llh, p_gcp))
    assert c.rms(c.ground_error_after_m) < 1.3 * random_level
    assert c.rms(c.residual_px_after) < c.rms(c.residual_px_before) / 10


def test_calibration_with_heading_bias_and_time_offset_from_telemetry():
    """Mount + heading bias 0.2 deg + time offset 0.08 s, poses interpolated from 10 Hz telemetry:
    each within 4 sigma; the heading bias and the mount's z angle are flagged as hard to separate."""
    nominal = SensorModel(Z15_CAM, AzElGimbal())
    true = dataclasses.replace(nominal, mount_misalignment_deg=(0.3, 0.2, 0.5))
    g = gcp_flight(true, 20, noise=TelemetryNoise(white=CAL_JITTER), seed=0, heading_bias_deg=0.2,
                   time_offset_s=0.08)
    c = calibrate(nominal, g.pixels, g.gcp_llh, telemetry=TelemetryTrack(g.tel_time_s, g.tel_pose),
                  time_s=g.obs_time_s, estimate=("mount", "heading", "time"), pixel_sigma_px=0.5)
    assert c.names == ("mount_x_deg", "mount_y_deg", "mount_z_deg", "heading_bias_deg", "time_offset_s")
    assert np.all(np.abs(c.values - [0.3, 0.2, 0.5, 0.2, 0.08]) < 4 * c.sigma), (c.values, c.sigma)
    assert c.heading_bias_deg == c.values[3] and c.time_offset_s == c.values[4]
    assert any("mount_z_deg and heading_bias_deg" in w for w in c.warnings)
    assert c.rms(c.ground_error_after_m) < 1.0


def test_calibration_flags_an_outlier_and_rejects_too_few_observations():
    nominal = SensorModel(Z15_CAM, AzElGimbal())
    true = dataclasses.replace(nominal, mount_misalignment_deg=(0.3, 0.2, 0.5))
    g = gcp_flight(true, 20, noise=TelemetryNoise(white=CAL_JITTER), seed=4)
    px = g.pixels.copy()
    px[7] += (60.0, -40.0)  # a misidentified GCP
    c = calibrate(nominal, px, g.gcp_llh, pose=g.obs_pose, pixel_sigma_px=0.5, robust=True)
    assert any(w.startswith("observation 7:") for w in c.warnings)
    assert np.all(np.abs(c.values - [0.3, 0.2, 0.5]) < 0.02)
    with pytest.raises(ValueError, match="equations for 3 parameters"):
        calibrate(nominal, px[:1], g.gcp_llh[:1], pose=g.obs_pose.take([0]))
    with pytest.raises(ValueError, match="telemetry"):
        calibrate(nominal, px, g.gcp_llh, pose=g.obs_pose, estimate=("time",))
