"""ground.frame.FrameSensors: the bounded cache of frames' sensors that live VMTI, the live movers
and the video's movers share. The math is checked where the camera is (tests/unit/sensor); here:
a frame's sensor is a pinhole whose fields of view span its frame, on the base sensor's gimbal and
installation; one object per frame kind; no usable field, no sensor; a bounded cache."""

from __future__ import annotations

import math

import numpy as np

from eoloc.ground.frame import FrameSensors, misb_sensor


def test_a_frames_sensor_spans_its_fields_of_view_on_the_base_sensor():
    base = misb_sensor(mount_misalignment_deg=(0.5, -0.2, 0.1))
    cache = FrameSensors(base)
    s = cache.get(1280, 720, 40.0, 25.0)
    assert s is cache.get(1280, 720, 40.0, 25.0)  # one object per (size, fields of view)
    assert s.gimbal == base.gimbal and s.mount_misalignment_deg == base.mount_misalignment_deg
    # the outer edges of the edge pixels (pixel centres at integers: edges at -0.5 and size - 0.5) at the
    # half fields of view
    xn, _ = s.camera.pixel_to_normalized(np.array([-0.5, 1279.5]), np.array([359.5, 359.5]))
    _, yn = s.camera.pixel_to_normalized(np.array([639.5, 639.5]), np.array([-0.5, 719.5]))
    np.testing.assert_allclose(np.abs(xn), math.tan(math.radians(20.0)), rtol=1e-12)
    np.testing.assert_allclose(np.abs(yn), math.tan(math.radians(12.5)), rtol=1e-12)


def test_no_usable_field_of_view_no_sensor_and_a_bad_vertical_one_square_pixels():
    cache = FrameSensors()
    assert cache.get(640, 480, math.nan, 30.0) is None and cache.get(640, 480, 180.0, 30.0) is None
    square = cache.get(640, 480, 60.0, math.nan)
    xn, _ = square.camera.pixel_to_normalized(np.array([639.5]), np.array([239.5]))
    _, yn = square.camera.pixel_to_normalized(np.array([319.5]), np.array([479.5]))
    np.testing.assert_allclose(yn[0] / xn[0], 480 / 640, rtol=1e-12)


def test_the_cache_stays_bounded_when_the_zoom_never_rests():
    cache = FrameSensors(keep=8)
    for k in range(100):
        assert cache.get(1920, 1080, 10.0 + k * 0.1, 6.0) is not None
        assert len(cache.sensors) <= 8
