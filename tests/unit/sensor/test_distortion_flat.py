"""Lens distortion (OpenCV as the reference, [Z15]'s table) and M2 flat-ground multi-target."""

from __future__ import annotations

import dataclasses

import numpy as np
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc import AtHeight, BrownConrady, Camera, DistortionRatio, Pose, SensorModel, Status
from eoloc.sensor.distortion import Z15_D_PERCENT, Z15_FIELD

cv2 = pytest.importorskip("cv2")
GEOD = pyproj.Geod(ellps="WGS84")
LENSES = [BrownConrady(-0.28, 0.09, 0.001, -0.0005, -0.012), BrownConrady(0.12, -0.05, 0.0, 0.0, 0.01),
          BrownConrady(-0.05, 0.0, 0.002, 0.001, 0.0)]
CAM = Camera.from_focal_mm(50.0, 5.5, 1024, 768)  # f = 9091 px


def _pixels(n, seed, cam=CAM):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.5, cam.width - 0.5, n), rng.uniform(-0.5, cam.height - 0.5, n)


@pytest.mark.parametrize("lens", LENSES)
def test_brown_conrady_distort_matches_opencv_projectPoints(lens):
    cam = Camera.from_hfov(70.0, 1280, 960).with_distortion(lens)  # a wide lens: strong distortion
    xn, yn = np.random.default_rng(1).uniform(-0.6, 0.6, (2, 2000))
    ours_u, ours_v = cam.normalized_to_pixel(xn, yn)
    obj = np.c_[xn, yn, np.ones_like(xn)].reshape(-1, 1, 3)
    ref = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), cam.K, lens.coefficients)[0].reshape(-1, 2)
    assert np.max(np.abs(ours_u - ref[:, 0])) < 1e-3 and np.max(np.abs(ours_v - ref[:, 1])) < 1e-3


@pytest.mark.parametrize("lens", LENSES)
def test_brown_conrady_undistort_matches_opencv_converged(lens):
    cam = Camera.from_hfov(70.0, 1280, 960).with_distortion(lens)
    u, v = _pixels(2000, 2, cam)
    xn, yn = cam.pixel_to_normalized(u, v)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    ref = cv2.undistortPoints(np.c_[u, v].reshape(-1, 1, 2), cam.K, lens.coefficients, criteria=crit).reshape(-1, 2)
    # compared in pixels: < 1e-3 px
    assert np.max(np.abs(xn - ref[:, 0])) * cam.fx < 1e-3
    assert np.max(np.abs(yn - ref[:, 1])) * cam.fy < 1e-3


@settings(max_examples=100, deadline=None)
@given(k1=st.floats(-0.3, 0.3), k2=st.floats(-0.1, 0.1), p1=st.floats(-0.002, 0.002), p2=st.floats(-0.002, 0.002),
       fu=st.floats(0, 1), fv=st.floats(0, 1))
def test_brown_conrady_round_trip_under_1e3_px(k1, k2, p1, p2, fu, fv):
    cam = Camera.from_hfov(50.0, 1920, 1080).with_distortion(BrownConrady(k1, k2, p1, p2))
    u, v = fu * 1919, fv * 1079
    u2, v2 = cam.normalized_to_pixel(*cam.pixel_to_normalized(u, v))
    assert abs(u2 - u) < 1e-3 and abs(v2 - v) < 1e-3


def test_ratio_model_reproduces_Z15_table_and_round_trips():
    model = DistortionRatio.for_camera(CAM)
    r_max = np.hypot(512 / CAM.fx, 384 / CAM.fy)
    assert model.r_max == pytest.approx(r_max)
    eta = np.tan(np.array(Z15_FIELD) * np.arctan(r_max))
    np.testing.assert_allclose(model.ratio(eta) * 100, Z15_D_PERCENT, atol=1e-12)
    cam = CAM.with_distortion(model)
    u, v = _pixels(5000, 3)
    u2, v2 = cam.normalized_to_pixel(*cam.pixel_to_normalized(u, v))
    assert np.max(np.abs(u2 - u)) < 1e-3 and np.max(np.abs(v2 - v)) < 1e-3


def test_ratio_model_corrects_by_1_plus_D_at_the_corner():
    """[Z15]: x_r = x / (1 + D); D = 2 % at the edge of the field (the image corner)."""
    cam = CAM.with_distortion(DistortionRatio.for_camera(CAM))
    xn, yn = cam.pixel_to_normalized(-0.5, -0.5)  # the outer corner: w = 1
    np.testing.assert_allclose([xn, yn], [(-512 / CAM.fx) / 1.02, (-384 / CAM.fy) / 1.02], rtol=1e-12)


def test_every_stop_rule_sees_undistorted_rays(backend):
    lens = BrownConrady(-0.2, 0.05)
    cam = Camera.from_hfov(60.0, 1280, 960)
    dist = SensorModel(cam.with_distortion(lens))
    # the same pinhole on a larger sensor: the ideal pixels of the distorted corners fall outside
    # the 1280 x 960 frame, which would make them OUT_OF_IMAGE
    w, h = cam.width, cam.height
    plain = SensorModel(dataclasses.replace(cam, width=3 * w, height=3 * h, cx=cam.cx + w, cy=cam.cy + h))
    pose = Pose(40.0, -105.0, 2000.0, 30.0, 1.0, -2.0, (20.0, -50.0))
    u, v = _pixels(200, 4, cam)
    xu, yu = dist.camera.pixel_to_normalized(u, v)
    ideal = plain.camera.normalized_to_pixel(xu, yu)  # where a perfect lens would have imaged them
    a = eoloc.locate_ellipsoid(dist, pose, 1500.0, (u, v))
    b = eoloc.locate_ellipsoid(plain, pose, 1500.0, ideal)
    np.testing.assert_allclose(a.lat_deg, b.lat_deg, atol=1e-12)
    u2, v2 = dist.ground_to_image(pose, a.p_ecef())  # and back through the distortion
    assert np.max(np.abs(u2 - u)) < 1e-3 and np.max(np.abs(v2 - v)) < 1e-3
    one = dist.locate_one(40.0, -105.0, 2000.0, 30.0, 1.0, -2.0, 20.0, -50.0, float(u[0]), float(v[0]),
                          rule=AtHeight(1500.0))
    assert one[0] == pytest.approx(float(a.lat_deg[0]), abs=1e-11)


# ---------------------------------------------------------------- M2


Z15_POSE = Pose(35.125225, 112.680649, 1140.0, 290.5, 2.1, 0.0, (89.9, -35.0))
Z15_SUBTARGETS = (np.array([386, 352, 511, 379, 854, 756, 685.0]), np.array([304, 379, 277, 524, 463, 584, 706.0]))


def test_M2_agrees_with_ellipsoid_at_the_main_targets_height(backend):
    sensor = SensorModel(CAM)
    main = eoloc.locate_range(sensor, Z15_POSE, 965.0)
    m2 = eoloc.locate_flat(sensor, Z15_POSE, 965.0, Z15_SUBTARGETS)
    m3 = eoloc.locate_ellipsoid(sensor, Z15_POSE, float(main.h_m), Z15_SUBTARGETS)
    assert (m2.status == Status.OK).all()
    _, _, d = GEOD.inv(m2.lon_deg, m2.lat_deg, m3.lon_deg, m3.lat_deg)
    assert np.max(d) < 0.01  # flat ground vs the constant-height surface: curvature only
    assert np.max(np.abs(m2.h_m - main.h_m)) < 0.01
    # the main target itself is where M1 puts it
    c = eoloc.locate_flat(sensor, Z15_POSE, 965.0, (CAM.cx, CAM.cy))
    assert abs(float(c.range_m) - 965.0) < 1e-9


def test_M2_frames_broadcast_and_horizon(backend):
    sensor = SensorModel(Camera.from_hfov(90.0, 1000, 1000))
    # looking 40 deg below the horizon with a 90 deg FOV: the top rows see the sky
    pose = Pose(np.array([[35.0], [35.1]]), 112.7, 1000.0, 0.0, 0.0, 0.0, (0.0, -40.0))
    f = eoloc.locate_flat(sensor, pose, np.array([[1555.7], [1555.7]]), (np.array([[500.0, 500.0]] * 2),
                                                                         np.array([[900.0, 0.0]] * 2)))
    assert f.lat_deg.shape == (2, 2)
    assert (f.status[:, 0] == Status.OK).all() and (f.status[:, 1] == Status.NO_INTERSECTION).all()
    assert np.isnan(f.lat_deg[:, 1]).all()


def test_M2_bad_main_range_flags_every_target(backend):
    f = eoloc.locate_flat(SensorModel(CAM), Z15_POSE, np.nan, Z15_SUBTARGETS)
    assert (f.status == Status.INVALID_INPUT).all() and np.isnan(f.lat_deg).all()


@pytest.mark.parametrize("lens", [None, LENSES[0], "ratio"])
def test_M2_one_frame_compiled_call_equals_the_array_path(lens):
    """One frame on numba runs as a single compiled call with the undistortion inside; it must give
    what the general (numpy, broadcasting) path gives, statuses included."""
    cam = CAM if lens is None else CAM.with_distortion(DistortionRatio.for_camera(CAM) if lens == "ratio" else lens)
    sensor = SensorModel(cam, mount_misalignment_deg=(0.1, -0.2, 0.3), lever_arm_m=(0.5, 0.2, -0.3))
    u, v = _pixels(200, 7, cam)
    pose = Pose(35.125225, 112.680649, 1140.0, 290.5, 0.0, 0.4, (89.9, -1.0))  # shallow: top rows see the sky
    out = {}
    for b in ("numba", "numpy"):
        with eoloc.use_backend(b):
            out[b] = eoloc.locate_flat(sensor, pose, 3000.0, (u, v), main_pixel=(600.0, 500.0))
    np.testing.assert_array_equal(out["numba"].status, out["numpy"].status)
    assert {Status.OK, Status.NO_INTERSECTION} <= set(out["numba"].status.tolist())
    ok = out["numba"].ok
    np.testing.assert_allclose(out["numba"].p_ecef()[ok], out["numpy"].p_ecef()[ok], rtol=0, atol=1e-6)
    with eoloc.use_backend("numba"):
        bad = eoloc.locate_flat(sensor, Pose(np.nan, 112.7, 1140.0, 0.0, 0.0, 0.0, (0.0, -30.0)), 3000.0, (u, v))
    assert (bad.status == Status.INVALID_INPUT).all() and np.isnan(bad.lat_deg).all()
