"""A drone photo's camera (eoloc.sensor.dronemodels) for images resized from the size their
calibration or database entry was made for (issue 55): the focal length in pixels scales with the
width, and the principal point follows the pixel-centre convention of an image resized by OpenCV
(a dot at the calibrated principal point, resized by cv2.resize, lands where the scaled camera
says) — references that are not eoloc."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from eoloc.sensor.dronemodels import _ratio, calibration, camera_for, database


def _dot_centroid(w: int, h: int, cx: float, cy: float, k: int) -> tuple[float, float]:
    """A Gaussian dot centred on (cx, cy) of a w x h image, the image shrunk k times by OpenCV
    (INTER_AREA: each output pixel the mean of its k x k block), the dot's centroid measured."""
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    img = np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 6.0**2)).astype(np.float32)
    small = cv2.resize(img, (w // k, h // k), interpolation=cv2.INTER_AREA)
    m = cv2.moments(small)
    return m["m10"] / m["m00"], m["m01"] / m["m00"]


@pytest.mark.parametrize("k", [2, 4])
def test_a_calibration_made_for_a_larger_image_is_scaled_about_pixel_centres(k):
    """Skydio-style XMP calibration (CalibratedFocalLengthX/Y, CalibratedOpticalCenterX/Y) of a
    4056 x 3040 image, on a copy k times smaller: fx, fy / k; the principal point where the dot
    at the calibrated one lands in OpenCV's resized image (within 0.01 px)."""
    w0, h0, fx, fy, cx, cy = 4056, 3040, 2980.0, 2983.0, 2031.25, 1516.75
    tags = {"CalibratedFocalLengthX": fx, "CalibratedFocalLengthY": fy, "CalibratedOpticalCenterX": cx,
            "CalibratedOpticalCenterY": cy}
    cam, why = calibration(tags, w0 // k, h0 // k)
    assert "scaled" in why
    assert cam.fx == pytest.approx(fx / k) and cam.fy == pytest.approx(fy / k)
    ucx, ucy = _dot_centroid(w0, h0, cx, cy, k)
    assert abs(cam.cx - ucx) < 0.01 and abs(cam.cy - ucy) < 0.01, (cam.cx, cam.cy, ucx, ucy)
    same, why1 = calibration(tags, w0, h0)
    assert (same.fx, same.cx, same.cy) == (fx, cx, cy) and "scaled" not in why1


def test_a_database_camera_on_a_resized_photo_has_its_focal_length_scaled():
    """A DroneModels entry (focal length in mm, sensor mm per pixel at its full size): on the full
    image fx = f / (mm per pixel); on a half-width copy half that, and the centre at the copy's."""
    e = next(x for x in database() if x["makeModel"] == "djiFC2403" and x["isThermal"])  # Mavic 2 Enterprise Dual
    assert e["focalLength"] == 20.0 and e["widthPixels"] == 640 and e["isThermal"]
    make, model = e["makeModel"][:3], e["makeModel"][3:]
    w, h = e["widthPixels"], e["heightPixels"]
    fx_full = e["focalLength"] / _ratio(e["ccdWidthMMPerPixel"])
    full, _ = camera_for(make, model, w, h, thermal=True, tags={}, exif=None)
    half, why = camera_for(make, model, w // 2, h // 2, thermal=True, tags={}, exif=None)
    assert "camera database" in why, why
    assert full.fx == pytest.approx(fx_full, rel=1e-12)
    assert half.fx == pytest.approx(fx_full / 2 * (w // 2) / (w / 2), rel=1e-12)
    assert (half.cx, half.cy) == ((w // 2 - 1) / 2.0, (h // 2 - 1) / 2.0)
