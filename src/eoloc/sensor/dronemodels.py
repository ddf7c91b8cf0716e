"""Drone camera intrinsics: the bundled database and the rules that pick a photo's camera.

The database is Theta Informatics' DroneModels (``data/drone/droneModels.json``, Apache-2.0, its
licence beside it; github.com/Theta-Limited/DroneModels at 591f9dd, 2025-11-05): 106 cameras keyed
by make + model (``lower(make) + upper(model)``, e.g. ``djiFC330``), visible or thermal, with the
sensor's pixel pitch (mm per pixel), the image size it was measured at, an optional focal length,
OpenCV-style distortion (radialR1..R3, tangentialT1..T2) or a fisheye polynomial, and for some a
target-location-error model from flight tests.

A photo's camera, in order (:func:`camera_for`):

1. the photo's own calibration (``CalibratedFocalLength`` or ``CalibratedFocalLengthX/Y`` and
   ``CalibratedOpticalCenterX/Y``, pixels), scaled to the image when it was resized (by the simple
   ratio its principal point shows), refused when it is another camera's (another aspect ratio);
2. the database entry of its make, model and band (visible/thermal; a model name shared by a
   payload's visible and thermal cameras is told apart by ``isThermal`` and the image size), its
   focal length (the entry's, else EXIF FocalLength in mm) over its pixel pitch, scaled when the
   image is smaller than the entry's; never another band's values; a fisheye entry by Pix4D's
   polynomial and affine (:class:`eoloc.sensor.distortion.FisheyePix4D`);
3. EXIF FocalLengthIn35mmFilm (the horizontal field of view of a 36 mm wide frame), with a note.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from functools import lru_cache
from importlib.resources import files

from ..errors import InputError
from .camera import Camera
from .distortion import BrownConrady


@lru_cache(maxsize=1)
def database() -> list[dict]:
    """The DroneModels entries."""
    raw = files("eoloc").joinpath("data/drone/droneModels.json").read_text(encoding="utf-8")
    return json.loads(raw)["droneCCDParams"]


def _ratio(text) -> float:
    """The database's "7.68/640.0" (Java literals such as "7.68d/640.0d" too) as a number."""
    s = str(text).replace("d", "")
    num, _, den = s.partition("/")
    return float(num) / (float(den) if den else 1.0)


def entry(make: str, model: str, width: int, height: int, *, thermal: bool) -> dict | None:
    """The database entry of this make, model and band whose aspect matches the image (the largest
    one when several); None when there is none."""
    key = make.strip().lower() + model.strip().upper()
    cands = [e for e in database() if e["makeModel"].lower() == key.lower() and bool(e["isThermal"]) == thermal]
    aspect = width / height
    cands = [e for e in cands if abs(e["widthPixels"] / e["heightPixels"] - aspect) < 0.02 or
             e["lensType"] == "fisheye"]
    return max(cands, key=lambda e: e["widthPixels"]) if cands else None


def tle_model(make: str, model: str, width: int, height: int, *, thermal: bool) -> tuple[float, float] | None:
    """(a, b) of the database's target-location-error model of this camera, TLE = a + b x slant
    range (m; fitted by Theta Informatics on flight tests against surveyed points, 33 cameras),
    or None."""
    e = entry(make, model, width, height, thermal=thermal)
    if e is None or "tle_model_y_intercept" not in e:
        return None
    return float(e["tle_model_y_intercept"]), float(e["tle_model_slant_range_coeff"])


def _exif_float(exif, tag: int) -> float | None:
    try:
        v = exif.get_ifd(0x8769).get(tag)
    except Exception:
        v = None
    if v is None:
        v = exif.get(tag)
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def camera_for(make: str, model: str, width: int, height: int, *, thermal: bool, tags: dict, exif,
               path: str = "") -> tuple[Camera, str]:
    """(camera, where its values came from) for a photo (see the module notes)."""
    cal = calibration(tags, width, height, path)
    if cal is not None and not isinstance(cal, str):
        return cal
    camera, source = _from_database(make, model, width, height, thermal, exif, path)
    return camera, source if cal is None else f"{source}; {cal}"  # cal: why the file's own was not used


def _from_database(make, model, width, height, thermal, exif, path) -> tuple[Camera, str]:
    e = entry(make, model, width, height, thermal=thermal)
    if e is not None:
        if e["lensType"] == "fisheye":  # Pix4D's model: the affine holds the focal length in pixels
            from .distortion import FisheyePix4D

            resize = width / e["widthPixels"]
            c, d, ee, f = (float(e[k]) for k in ("c", "d", "e", "f"))
            dist = FisheyePix4D(tuple(float(e[f"poly{i}"]) for i in range(5)), (1.0, d / c, ee / c, f / c))
            return (Camera(width, height, c * resize, c * resize, (width - 1) / 2.0, (height - 1) / 2.0, dist),
                    f"the camera database ({e['makeModel']}, fisheye, Pix4D's polynomial)")
        f_mm = e.get("focalLength") or _exif_float(exif, 37386)  # EXIF FocalLength
        if f_mm is None:
            why = f" ({e['makeModel']} has no focal length and neither has EXIF FocalLength)"
            return _from_35mm(make, model, width, height, thermal, exif, path, why)
        scale = width / e["widthPixels"]
        fx = f_mm / _ratio(e["ccdWidthMMPerPixel"]) * scale
        fy = f_mm / _ratio(e["ccdHeightMMPerPixel"]) * (height / e["heightPixels"])
        k = [float(e.get(n, 0.0) or 0.0) for n in ("radialR1", "radialR2", "tangentialT1", "tangentialT2",
                                                   "radialR3")]
        dist = BrownConrady(*k) if any(k) else None
        band = "thermal" if thermal else "visible"
        return (Camera(width, height, fx, fy, (width - 1) / 2.0, (height - 1) / 2.0, dist),
                f"the camera database ({e['makeModel']}, {band}, {f_mm:g} mm)")
    return _from_35mm(make, model, width, height, thermal, exif, path, "")


ASPECT_TOLERANCE = 0.04  # a calibration's image and the photo: the same aspect ratio within this


def calibration(tags: dict, width: int, height: int, path: str = "") -> tuple[Camera, str] | str | None:
    """The photo's own calibration (``CalibratedFocalLength`` or ``CalibratedFocalLengthX/Y``,
    ``CalibratedOpticalCenterX/Y``, pixels) as a camera for this image: scaled when the image was
    resized (the principal point tells the size the calibration was made for: about twice it);
    a string saying why not when it belongs to an image of another shape (a thermal frame carrying
    the visible camera's calibration); None when there is none."""
    fx = tags.get("CalibratedFocalLengthX", tags.get("CalibratedFocalLength"))
    if fx in (None, ""):
        return None
    try:
        fx = float(fx)
        fy = float(tags.get("CalibratedFocalLengthY", fx))
        cx = float(tags.get("CalibratedOpticalCenterX", (width - 1) / 2.0))
        cy = float(tags.get("CalibratedOpticalCenterY", (height - 1) / 2.0))
    except ValueError:
        raise InputError(f"{path}: XMP CalibratedFocalLength / CalibratedOpticalCenter are not numbers") from None
    if not all(math.isfinite(x) and x > 0 for x in (fx, fy, cx, cy)):
        raise InputError(f"{path}: XMP CalibratedFocalLength / CalibratedOpticalCenter are not positive numbers")
    w0, h0 = 2.0 * cx + 1.0, 2.0 * cy + 1.0  # the calibrated image's size, from its principal point
    if abs((w0 / h0) / (width / height) - 1.0) > ASPECT_TOLERANCE:
        return (f"its calibration (principal point {cx:g}, {cy:g}: a {w0:.0f} x {h0:.0f} image) is another camera's, "
                f"not this {width} x {height} frame's: not used")
    # the resize factor: a simple ratio (1/2, 1/4, 2/3, ...) near width / w0, since the principal
    # point sits a few pixels off the centre
    scale = Fraction(width / w0).limit_denominator(8)
    if abs(float(scale) * w0 / width - 1.0) > ASPECT_TOLERANCE or scale <= 0:
        return (f"its calibration (principal point {cx:g}, {cy:g}) fits no simple resize of this {width} x {height} "
                "image: not used")
    if scale == 1:
        return Camera(width, height, fx, fy, cx, cy), "the photo's calibration (CalibratedFocalLength)"
    k = float(scale)
    cam = Camera(width, height, fx * k, fy * k, (cx + 0.5) * k - 0.5, (cy + 0.5) * k - 0.5)
    return cam, (f"the photo's calibration, made for an image {1 / k:g} times as large, scaled to this {width} x "
                 f"{height} image")


def _from_35mm(make, model, width, height, thermal, exif, path, why: str) -> tuple[Camera, str]:
    f35 = _exif_float(exif, 41989)  # FocalLengthIn35mmFilm
    if f35 is not None:
        fx = f35 / 36.0 * width
        return Camera(width, height, fx, fx, (width - 1) / 2.0, (height - 1) / 2.0), \
            f"EXIF FocalLengthIn35mmFilm ({f35:g} mm){why}"
    raise InputError(f"{path}: {make} {model} ({width}x{height}, {'thermal' if thermal else 'visible'}): no focal "
                     f"length — not in the camera database with one{why}, and no EXIF FocalLengthIn35mmFilm; such a "
                     "photo cannot be located from its own tags")
