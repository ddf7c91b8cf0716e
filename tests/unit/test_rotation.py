"""Rotation conventions: one test per sign and axis, and agreement with scipy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from eoloc import rotation as r

X, Y, Z = np.eye(3)


def test_elementary_rotations_right_handed_active():
    np.testing.assert_allclose(r.rot_z(90) @ X, Y, atol=1e-15)
    np.testing.assert_allclose(r.rot_x(90) @ Y, Z, atol=1e-15)
    np.testing.assert_allclose(r.rot_y(90) @ Z, X, atol=1e-15)


def test_yaw_90_turns_the_nose_east():
    nose_ned = r.R_ned_body(90, 0, 0) @ X
    np.testing.assert_allclose(nose_ned, [0, 1, 0], atol=1e-15)


def test_positive_pitch_raises_the_nose():
    nose_ned = r.R_ned_body(0, 10, 0) @ X
    assert nose_ned[2] < 0  # down component negative = up
    np.testing.assert_allclose(nose_ned, [np.cos(np.radians(10)), 0, -np.sin(np.radians(10))], atol=1e-15)


def test_positive_roll_drops_the_right_wing():
    wing_ned = r.R_ned_body(0, 0, 10) @ Y
    assert wing_ned[2] > 0  # right wing goes down


def test_yaw_then_pitch_order_zyx():
    # heading 90 and nose up 30: the nose points east and up
    nose = r.R_ned_body(90, 30, 0) @ X
    np.testing.assert_allclose(nose, [0, np.cos(np.radians(30)), -0.5], atol=1e-15)


def test_body_down_stays_down_with_yaw():
    np.testing.assert_allclose(r.R_ned_body(123, 0, 0) @ Z, Z, atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(st.floats(-360, 360), st.floats(-89.9, 89.9), st.floats(-180, 180))
def test_matches_scipy_intrinsic_ZYX(yaw, pitch, roll):
    ours = r.R_ned_body(yaw, pitch, roll)
    ref = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()
    np.testing.assert_allclose(ours, ref, atol=1e-14)
    y2, p2, r2 = r.euler_from_R_ned_body(ours)
    np.testing.assert_allclose(r.R_ned_body(y2, p2, r2), ours, atol=1e-12)
    assert 0 <= y2 < 360


def test_stacks_broadcast_and_shapes():
    R = r.R_ned_body(np.zeros((3, 1)), np.zeros((1, 4)), 0.0)
    assert R.shape == (3, 4, 3, 3)
    assert r.rot_x(0.0).shape == (3, 3)
    assert r.rot_x([0.0]).shape == (1, 3, 3)


def test_gimbal_lock_warns_and_still_reconstructs():
    R = r.R_ned_body(30, 90, 10)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        y, p, ro = r.euler_from_R_ned_body(R)
    assert any("gimbal lock" in str(x.message) for x in w)
    assert ro == 0.0 and p == pytest.approx(90)
    np.testing.assert_allclose(r.R_ned_body(y, p, ro), R, atol=1e-12)


def test_quaternion_round_trip_scalar_first():
    q = np.array([np.cos(np.pi / 8), 0, 0, np.sin(np.pi / 8)])  # 45 deg about z
    np.testing.assert_allclose(r.matrix_from_quaternion(q), r.rot_z(45), atol=1e-15)
    np.testing.assert_allclose(r.quaternion_from_matrix(r.rot_z(45)), q, atol=1e-15)
    with pytest.raises(ValueError, match="4 components"):
        r.matrix_from_quaternion([1, 0, 0])


def test_small_angle_rotation_order():
    a = r.small_angle_rotation([0.1, 0.2, 0.3])
    np.testing.assert_allclose(a, r.rot_z(0.3) @ r.rot_y(0.2) @ r.rot_x(0.1), atol=1e-15)
