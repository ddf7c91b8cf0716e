"""Many frames (issue 5, first increment): telemetry at frame times, multi-view triangulation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from eoloc import AzElGimbal, Camera, Pose, Rays, SensorModel, geodesy
from eoloc.rotation import R_ned_body
from eoloc.sequence import interpolate_poses, triangulate


def _still(n, yaw, pitch, roll, gimbal=(0.0, -45.0)):
    return Pose(np.full(n, 45.0), np.full(n, 7.0), np.full(n, 1000.0), yaw, pitch, roll,
                tuple(np.broadcast_to(g, (n,)) for g in gimbal))


def test_constant_velocity_leg_is_dead_reckoning_exactly():
    """10 Hz records of a straight 60 m/s leg: positions between records are on the line (< 1 mm)."""
    t = np.arange(0.0, 10.0, 0.1)
    enu = np.c_[60.0 * t, 10.0 * t, 2.0 * t]
    p = geodesy.enu_to_ecef(enu, 45.0, 7.0, 1000.0)
    lat, lon, h = geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    n = t.size
    pose = Pose(lat, lon, h, np.full(n, 80.0), np.full(n, 2.0), np.zeros(n), (np.full(n, 10.0), np.full(n, -30.0)))
    tq = np.array([0.05, 3.333, 7.77, 9.9])
    r = interpolate_poses(t, pose, tq)
    assert r.ok.all() and r.gaps == []
    got = np.stack(geodesy.geodetic_to_ecef(r.pose.lat_deg, r.pose.lon_deg, r.pose.h_m), -1)
    want = geodesy.enu_to_ecef(np.c_[60.0 * tq, 10.0 * tq, 2.0 * tq], 45.0, 7.0, 1000.0)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-3)
    # the attitude is constant in the local level frame, which turns slightly along 600 m
    np.testing.assert_allclose(r.pose.yaw_deg, 80.0, atol=1e-3)
    np.testing.assert_allclose(r.pose.gimbal_deg[1], -30.0, atol=1e-12)


def test_heading_wrap_and_azimuth_wrap_go_the_short_way():
    r = interpolate_poses([0.0, 1.0], _still(2, np.array([359.0, 1.0]), 0.0, 0.0, (np.array([358.0, 2.0]), -45.0)),
                          [0.25, 0.5], max_gap_s=1.0)
    assert r.ok.all()
    np.testing.assert_allclose((r.pose.yaw_deg + 180.0) % 360.0 - 180.0, [-0.5, 0.0], atol=1e-9)
    np.testing.assert_allclose((r.pose.gimbal_deg[0] + 180.0) % 360.0 - 180.0, [-1.0, 0.0], atol=1e-9)


def test_over_the_top_through_90_pitch_is_a_slerp():
    """Pitch 80 heading 0 -> pitch 80 heading 180 rolled 180 (a loop over the top): the midpoint is
    pitch 90, and every interpolated attitude is scipy's slerp of the two rotations."""
    yaw, pitch, roll = np.array([0.0, 180.0]), np.array([80.0, 80.0]), np.array([0.0, 180.0])
    tq = np.linspace(0.0, 1.0, 11)
    r = interpolate_poses([0.0, 1.0], _still(2, yaw, pitch, roll), tq, max_gap_s=1.0)
    ref = Slerp([0.0, 1.0], Rotation.from_matrix(R_ned_body(yaw, pitch, roll)))(tq).as_matrix()
    got = R_ned_body(r.pose.yaw_deg, r.pose.pitch_deg, r.pose.roll_deg)
    np.testing.assert_allclose(got, ref, atol=1e-9)
    assert r.pose.pitch_deg[5] == pytest.approx(90.0, abs=1e-6)
    assert np.all(r.pose.pitch_deg >= 80.0 - 1e-9)  # never the Euler average (pitch 80, yaw 90, roll 90)


def test_gap_outside_and_time_offset():
    t = np.r_[np.arange(0.0, 2.0, 0.1), np.arange(4.0, 6.0, 0.1)]  # a 2 s gap
    n = t.size
    pose = _still(n, 10.0 * t, np.zeros(n), np.zeros(n))
    r = interpolate_poses(t, pose, [1.05, 3.0, 5.0, 7.0, -1.0], max_gap_s=0.5)
    assert [(g.t_before, g.t_after) for g in r.gaps] == [(pytest.approx(1.9), pytest.approx(4.0))]
    assert r.gaps[0].length_s == pytest.approx(2.1)
    assert r.ok.tolist() == [True, False, True, False, False]
    assert r.reason.tolist() == [0, r.IN_GAP, 0, r.OUTSIDE, r.OUTSIDE]
    assert r.record.tolist() == [10, -1, 30, -1, -1] and r.span_s == (0.0, pytest.approx(5.9))
    assert np.isnan(r.pose.lat_deg[1]) and np.isnan(r.pose.yaw_deg[3])
    shifted = interpolate_poses(t, pose, [1.05], time_offset_s=0.3)  # telemetry clock = video + 0.3 s
    assert shifted.pose.yaw_deg[0] == pytest.approx(13.5, abs=1e-6)
    with pytest.raises(ValueError, match="at least two"):
        interpolate_poses([0.0], _still(1, 0.0, 0.0, 0.0), [0.0])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 360), st.floats(-85, 85), st.floats(-170, 170)), min_size=3, max_size=6))
def test_records_are_returned_at_their_own_times(att):
    yaw, pitch, roll = (np.array(x) for x in zip(*att, strict=True))
    t = np.arange(len(att), dtype=float)
    r = interpolate_poses(t, _still(len(att), yaw, pitch, roll), t, max_gap_s=1.0)
    np.testing.assert_allclose(R_ned_body(r.pose.yaw_deg, r.pose.pitch_deg, r.pose.roll_deg),
                               R_ned_body(yaw, pitch, roll), atol=1e-9)


# ---------------------------------------------------------------- triangulation


def _two_views(baseline_m: float, sigma: float, rng=None):
    target = np.array(geodesy.geodetic_to_ecef(45.0, 7.0, 200.0))
    o = geodesy.enu_to_ecef(np.array([[-baseline_m / 2, -2800.0, 1000.0], [baseline_m / 2, -2800.0, 1000.0]]),
                            45.0, 7.0, 200.0)
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if rng is not None:
        d = d + rng.normal(0.0, sigma, d.shape)  # the along-ray part is removed by normalisation
    return Rays(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2], np.zeros(2, bool))


def test_triangulation_accuracy_is_what_its_covariance_predicts():
    """1 km baseline at ~3 km: 2000 seeded noisy pairs (0.2 mrad per ray). The normalised squared
    error (NEES) averages 3 (3-D) within 0.2 (its sampling sd is 0.055), and the sample sigmas
    match the predicted ones within 7 %."""
    rng = np.random.default_rng(7)
    sigma = 2e-4
    err, cov = [], []
    for _ in range(2000):
        tr = triangulate(_two_views(1000.0, sigma, rng), sigma)
        err.append(geodesy.ecef_to_enu(tr.p_ecef, 45.0, 7.0, 200.0))
        cov.append(tr.cov_enu)
    err, cov = np.array(err), np.array(cov)
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err)
    assert nees.mean() == pytest.approx(3.0, abs=0.2)
    np.testing.assert_allclose(err.std(axis=0, ddof=1), np.sqrt(np.diagonal(cov.mean(0))), rtol=0.07)
    assert tr.warning == "" and tr.max_angle_deg == pytest.approx(19.06, abs=0.05)


def test_triangulation_of_the_sensor_chain_is_exact_and_warns_on_a_short_baseline():
    sensor = SensorModel(Camera.from_hfov(10.0, 640, 480), AzElGimbal())
    target = np.array(geodesy.geodetic_to_ecef(45.0, 7.0, 200.0))
    ac = geodesy.enu_to_ecef(np.array([[-3000.0, -2000.0, 1500.0], [0.0, -3500.0, 1500.0], [2500.0, -2500.0, 1600.0]]),
                             45.0, 7.0, 200.0)
    lat, lon, h = geodesy.ecef_to_geodetic(ac[:, 0], ac[:, 1], ac[:, 2])
    yaw, pitch, roll = np.array([10.0, 40.0, 80.0]), np.array([2.0, -1.0, 0.5]), np.array([0.0, 5.0, -3.0])
    az, el, _ = AzElGimbal.pointing(lat, lon, h, yaw, pitch, roll, target)
    rays = sensor.rays(Pose(lat, lon, h, yaw, pitch, roll, (az, el)))
    tr = triangulate(rays, 1e-4)
    np.testing.assert_allclose(tr.p_ecef, target, atol=1e-4)
    assert tr.residuals_m.max() < 1e-4 and tr.warning == ""
    short = triangulate(_two_views(10.0, 0.0), 1e-4)
    assert "baseline too short" in short.warning and short.sigma_enu[1] > 50 * short.sigma_enu[0]
    away = _two_views(1000.0, 0.0)
    away = Rays(away.ox, away.oy, away.oz, -away.dx, -away.dy, -away.dz, away.invalid)
    assert "behind" in triangulate(away, 1e-4).warning
    with pytest.raises(ValueError, match="at least 2 usable rays"):
        triangulate(Rays(*(np.array([np.nan, 1.0]),) * 6, np.zeros(2, bool)), 1e-4)


def test_cli_interpolate_reports_the_gap_left_by_a_malformed_record(tmp_path):
    """The demo telemetry's record at 12 s is malformed, leaving a 2 s gap at 1 Hz: with
    --interpolate the three detections at 12 s are reported with the gap's lines and get
    NO_TELEMETRY; allowing 2.5 s they are interpolated across it and land near their truth."""
    import csv
    from pathlib import Path

    from click.testing import CliRunner
    from pyproj import Geod

    import eoloc
    from eoloc.cli import main

    demo = Path(eoloc.__file__).parent / "data" / "demo"
    args = ["locate", str(demo / "telemetry.csv"), str(demo / "detections.csv"), "--config",
            str(demo / "camera.toml"), "--target-height", "600", "--interpolate"]
    r = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "a")])
    assert r.exit_code == 0, r.output
    assert "time 12 s falls in a 2 s telemetry gap between lines 15 and 17" in " ".join(r.output.split())
    rows = list(csv.DictReader((tmp_path / "a" / "fixes.csv").open()))
    at12 = [row for row in rows if row["time_s"] and float(row["time_s"]) == 12.0]
    assert len(at12) == 3 and {row["status"] for row in at12} == {"NO_TELEMETRY"}
    r = CliRunner().invoke(main, [*args, "--max-gap", "2.5", "--out", str(tmp_path / "b")])
    rows = list(csv.DictReader((tmp_path / "b" / "fixes.csv").open()))
    truth = {row["target_id"]: row for row in csv.DictReader((demo / "truth.csv").open())}
    geod = Geod(ellps="WGS84")

    def err(row):
        t = truth[row["target_id"]]
        return geod.inv(float(row["lon_deg"]), float(row["lat_deg"]), float(t["lon_deg"]), float(t["lat_deg"]))[2]

    # the tolerance is the flight's own single-frame scatter: the largest error of the fixes at its
    # recorded poses (CEP ~30 m); interpolated across the gap, the 12 s fixes are no worse
    scatter = max(err(row) for row in rows if row["status"] == "OK" and float(row["time_s"]) != 12.0)
    at12 = [row for row in rows if row["time_s"] and float(row["time_s"]) == 12.0]
    assert len(at12) == 3 and all(row["status"] == "OK" and err(row) <= scatter for row in at12), scatter
    r = CliRunner().invoke(main, ["locate", str(demo / "telemetry.csv"), "--config", str(demo / "camera.toml"),
                                  "--target-height", "600", "--interpolate"])
    assert r.exit_code == 2 and "needs a DETECTIONS file" in r.output
