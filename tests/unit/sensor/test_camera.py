"""The camera's pixel convention against OpenCV's (issue 55): the centre of the top-left pixel is
(0, 0), as in cv2.projectPoints / cv2.undistortPoints, whose conventions eoloc's README states it
shares; with and without OpenCV's distortion (Brown–Conrady, cv2 distCoeffs order)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eoloc import Camera
from eoloc.sensor.distortion import BrownConrady

K1 = st.floats(-0.2, 0.2)


@settings(max_examples=40, deadline=None)
@given(st.floats(900.0, 3000.0), st.floats(0.95, 1.05), st.floats(-20.0, 20.0), st.floats(-20.0, 20.0),
       st.sampled_from([None, (0.0, 0.0, 0.0, 0.0, 0.0)]) | st.tuples(K1, st.floats(-0.05, 0.05),
                                                                     st.floats(-0.01, 0.01), st.floats(-0.01, 0.01),
                                                                     st.floats(-0.02, 0.02)))
def test_pixels_and_normalised_coordinates_are_opencvs(fx, aspect, dcx, dcy, dist):
    """(Focal lengths and coefficients of real lenses: the model invertible over the image, its
    pixels within a distorted radius of 0.6.) Pixel -> normalised by eoloc, projected back by
    OpenCV (cv2.projectPoints of the point (x, y, 1) with K and distCoeffs), is the pixel, on a
    grid over the image (1e-6 px); without distortion it is cv2.undistortPoints' answer
    itself (1e-12); normalised -> pixel by eoloc = cv2.projectPoints."""
    w, h = 1280, 960
    cx, cy = (w - 1) / 2 + dcx, (h - 1) / 2 + dcy
    fy = fx * aspect
    distortion = None if dist is None else BrownConrady(*dist)
    cam = Camera(w, h, fx, fy, cx, cy, distortion)
    Kmat = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    D = np.zeros(5) if dist is None else np.array(dist)
    # a grid of pixels out to a distorted radius of 0.6 (where every such lens is invertible) and
    # inside the image
    gx, gy = np.meshgrid(np.linspace(-0.42, 0.42, 9), np.linspace(-0.42, 0.42, 7))
    u, v = np.clip(cx + fx * gx.ravel(), 0, w - 1), np.clip(cy + fy * gy.ravel(), 0, h - 1)
    xn, yn = cam.pixel_to_normalized(u, v)
    if dist is None:
        ref = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), Kmat, D).reshape(-1, 2)
        np.testing.assert_allclose(np.stack([xn, yn], -1), ref, atol=1e-12)
    pts = np.stack([xn, yn, np.ones_like(xn)], -1)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), Kmat, D)
    np.testing.assert_allclose(proj.reshape(-1, 2), np.stack([u, v], -1), atol=1e-6)
    pu, pv = cam.normalized_to_pixel(xn, yn)
    np.testing.assert_allclose(np.stack([pu, pv], -1), proj.reshape(-1, 2), atol=1e-6)


def test_the_top_left_pixels_centre_is_the_origin():
    """cv2.remap samples pixel (0, 0) at map value (0, 0): the ray eoloc gives the pixel (0, 0)
    projects back, through OpenCV, onto it; (-0.5, -0.5) is the image's corner."""
    cam = Camera(640, 480, 500.0, 500.0, 319.5, 239.5)
    xn, yn = cam.pixel_to_normalized(np.array([0.0, -0.5, 639.0]), np.array([0.0, -0.5, 479.0]))
    assert xn[0] == pytest.approx(-319.5 / 500.0) and yn[0] == pytest.approx(-239.5 / 500.0)
    assert xn[1] == pytest.approx(-320.0 / 500.0) and xn[2] == pytest.approx(319.5 / 500.0)
    img = np.zeros((480, 640), np.float32)
    img[0, 0] = 1.0
    mx, my = cam.normalized_to_pixel(xn[:1], yn[:1])
    got = cv2.remap(img, mx.astype(np.float32).reshape(1, 1), my.astype(np.float32).reshape(1, 1), cv2.INTER_LINEAR)
    assert float(got[0, 0]) == pytest.approx(1.0)
