"""Issue 48 (first part): drone photos located from their own EXIF/XMP (`eoloc photo`).

The independent references: DJI's own laser-range target written in a real Zenmuse H20N photo;
synthetic DJI photos whose XMP/EXIF the test writes (tests/dronephoto.py) from a camera pose and a
ground point chosen first, the pixel found by the oracle's projection (scipy, pyproj).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import coverage_lib as C
import eoloc
import oracle_lib as O
from dronephoto import write_photo

DATA = Path(__file__).resolve().parents[1] / "data" / "drone"
H20N = DATA / "H20N__DJI_0006_R.JPG"
MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
EOLOC = str(Path(sys.executable).parent / "eoloc")


def _photo(*args, check=True):
    r = subprocess.run([EOLOC, "photo", *map(str, args), "--json"], capture_output=True, text=True, timeout=120)
    assert "Traceback" not in r.stderr, r.stderr
    if check:
        assert r.returncode == 0, r.stderr
    return r, [json.loads(x) for x in r.stdout.splitlines() if x.strip()]


def test_48_h20n_photo_alone_lands_on_djis_own_laser_target():
    """`eoloc photo H20N__DJI_0006_R.JPG --json`: the centre by its laser range lands within 0.3 m
    horizontally and 0.3 m vertically of DJI's own LRFTarget (both heights in the photo's datum)."""
    _, rows = _photo(H20N)
    (row,) = rows
    assert row["status"] == "OK" and row["source"] == "laser"
    assert row["camera_yaw"] == pytest.approx(-106.6) and row["camera_pitch"] == pytest.approx(-32.9)
    d = C.enu_error(row["lat"], row["lon"], row["h"], np.array([22.5960255, 114.0066452, 47.000]))
    assert math.hypot(d[0], d[1]) < 0.3 and abs(d[2]) < 0.3, d
    assert row["vendor_offset_h_m"] == pytest.approx(math.hypot(d[0], d[1]), abs=1e-3)


def _dji_tags(lat, lon, h, yaw, pitch, roll, **more):
    return {"Version": "7.0", "GpsStatus": "Normal", "GpsLatitude": f"{lat:+.9f}", "GpsLongitude": f"{lon:+.9f}",
            "AbsoluteAltitude": f"{h:+.3f}", "RelativeAltitude": "+120.000", "GimbalYawDegree": f"{yaw:+.6f}",
            "GimbalPitchDegree": f"{pitch:+.6f}", "GimbalRollDegree": f"{roll:+.6f}", "FlightYawDegree": "+12.0",
            "FlightPitchDegree": "+1.0", "FlightRollDegree": "-2.0", **more}


@pytest.mark.parametrize("how", ["calibrated", "database"])
def test_48_synthetic_dji_photos_every_fix_on_the_truth(tmp_path, how):
    """A DJI photo written by the test with a known camera pose (earth-referenced gimbal angles)
    over a ground point chosen first: its pixel from the oracle's projection, `eoloc photo --pixel
    U V --target-height H` lands within 1 cm of the point. The intrinsics from the photo's own
    CalibratedFocalLength / OpticalCenter, or from the camera database (DJI FC230, no distortion,
    EXIF FocalLength 4.49 mm, the image a quarter of the entry's size: scaled)."""
    rng = np.random.default_rng(48)
    w, h = (1012, 758) if how == "database" else (1280, 960)
    if how == "database":
        fx = 4.49 / (6.17 / 4056.0) * w / 4048  # the entry's pitch, scaled to the image
        fy = 4.49 / (4.55 / 3040.0) * h / 3032
        cam = O.Camera(w, h, fx, fy, (w - 1) / 2, (h - 1) / 2)
    else:
        cam = O.Camera(w, h, 1100.0, 1100.0, 650.25, 470.75)
    for k in range(6):
        lat, lon = rng.uniform(-60, 60), rng.uniform(-180, 180)
        h_cam = rng.uniform(100, 3000)
        yaw, pitch, roll = rng.uniform(-180, 180), rng.uniform(-85, -20), rng.uniform(-3, 3)
        target_h = h_cam - rng.uniform(60, 400)
        # the ground point: the ray of a random pixel, met at target_h by bisection (oracle geometry)
        u0, v0 = rng.uniform(50, w - 50), rng.uniform(50, h - 50)
        o, d, _ = O.rays(cam, "az-el", lat, lon, h_cam, yaw, pitch, roll, 0.0, 0.0, 0.0, np.array(u0), np.array(v0))
        lo, hi = 0.0, 50_000.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if O.height(o + mid * d) > target_h else (lo, mid)
        truth = np.array(O.geodetic(o + lo * d)).ravel()
        u, v = C.project(cam, lat, lon, h_cam, yaw, pitch, roll, 0.0, 0.0, O.to_ecef(*truth))
        extra = {"CalibratedFocalLength": "1100.0", "CalibratedOpticalCenterX": "650.25",
                 "CalibratedOpticalCenterY": "470.75"} if how == "calibrated" else {}
        path = write_photo(tmp_path / f"p{k}.jpg", w, h, _dji_tags(lat, lon, h_cam, yaw, pitch, roll, **extra),
                           model="FC230", focal_mm=4.49)
        _, (row,) = _photo(path, "--pixel", float(u), float(v), "--target-height", target_h)
        assert row["status"] == "OK" and row["source"] == "height"
        e = C.enu_error(row["lat"], row["lon"], row["h"], truth)
        assert np.linalg.norm(e) < 0.01, (k, e)


def test_48_laser_range_locates_the_centre(tmp_path):
    """A DJI photo with LRFTargetDistance: the centre is located by range, at the point that far
    along the optical axis (the oracle's ray), with no surface given."""
    cam = O.Camera(1280, 960, 1100.0, 1100.0, 639.5, 479.5)
    lat, lon, h_cam, yaw, pitch = 35.2, 139.1, 450.0, 72.0, -38.0
    o, d, _ = O.rays(cam, "az-el", lat, lon, h_cam, yaw, pitch, 0.0, 0.0, 0.0, 0.0, np.array(639.5), np.array(479.5))
    truth = np.array(O.geodetic(o + 321.25 * d)).ravel()
    tags = _dji_tags(lat, lon, h_cam, yaw, pitch, 0.0, CalibratedFocalLength="1100.0", LRFStatus="Normal",
                     LRFTargetDistance="321.250")
    _, (row,) = _photo(write_photo(tmp_path / "lrf.jpg", 1280, 960, tags))
    assert row["source"] == "laser" and np.linalg.norm(C.enu_error(row["lat"], row["lon"], row["h"], truth)) < 0.01


def test_48_heights_datum_and_the_plausibility_check(tmp_path):
    """XMP Version < 1.5 without RTK: AbsoluteAltitude is MSL (EGM96) and the camera's ellipsoidal
    height is it plus the geoid's undulation; the same photo as Version 7.0 is taken as ellipsoidal.
    Over the real Front Range DEM a camera height under the terrain is refused, naming the tag."""
    from eoloc.terrain.geoid import default_geoid

    lat, lon = 40.2549, -105.616
    old = write_photo(tmp_path / "old.jpg", 640, 480, {**_dji_tags(lat, lon, 5000.0, 10, -40, 0), "Version": "1.4"},
                      f35_mm=24)
    new = write_photo(tmp_path / "new.jpg", 640, 480, _dji_tags(lat, lon, 5000.0, 10, -40, 0), f35_mm=24)
    _, rows = _photo(old, new, "--target-height", 3000)
    n = float(default_geoid().undulation(lat, lon))
    assert rows[0]["camera_h"] == pytest.approx(5000.0 + n, abs=1e-6) and rows[1]["camera_h"] == 5000.0
    low = write_photo(tmp_path / "low.jpg", 640, 480, _dji_tags(lat, lon, 1200.0, 10, -40, 0), f35_mm=24)
    r, rows = _photo(low, new, "--dem", MOUNTAIN / "longs_peak_srtmgl3.tif")
    assert rows[0]["status"] == "SUSPECT_ALTITUDE" and "AbsoluteAltitude" in rows[0]["reason"]
    assert rows[1]["status"] == "OK" and "below the terrain" in r.stderr


def test_48_bad_photos_are_named_and_the_good_ones_still_located(tmp_path):
    """A non-image, a JPEG with no XMP, an XMP without the gimbal pitch, a gimbal of all zeros (what
    a DJI Mini 2 writes when it does not know), a truncated file: each one line naming the file and
    the tag or the fix, no traceback; the good photo of the same call located (exit 0); all bad:
    exit 2."""
    good = write_photo(tmp_path / "good.jpg", 640, 480, _dji_tags(40, -105, 3000, 0, -60, 0), f35_mm=24)
    text = tmp_path / "notes.jpg"
    text.write_text("not an image")
    bare = write_photo(tmp_path / "bare.jpg", 640, 480, None)
    tags = _dji_tags(40, -105, 3000, 0, -60, 0)
    del tags["GimbalPitchDegree"]
    nopitch = write_photo(tmp_path / "nopitch.jpg", 640, 480, tags)
    zeros = write_photo(tmp_path / "zeros.jpg", 640, 480, _dji_tags(40, -105, 3000, 0, 0, 0))
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(good.read_bytes()[:300])
    bad = [text, bare, nopitch, zeros, cut]
    r, rows = _photo(*bad, good, "--target-height", 1500)
    assert [x["status"] for x in rows] == ["UNREADABLE"] * 5 + ["OK"]
    why = {Path(x["file"]).name: x["reason"] for x in rows[:5]}
    assert "not an image" in why["notes.jpg"] and "no XMP" in why["bare.jpg"]
    assert "GimbalPitchDegree" in why["nopitch.jpg"] and "all 0" in why["zeros.jpg"]
    assert "cut.jpg" in why["cut.jpg"]
    assert all(str(p) in r.stderr for p in bad)
    r, _ = _photo(*bad, check=False)
    assert r.returncode == 2 and "no photo could be located" in r.stderr  # the house's code for bad input


@settings(max_examples=40, deadline=None)
@given(st.floats(0, 3999), st.floats(0, 2999), st.floats(-80, -10), st.floats(-180, 180))
def test_48_pixel_ground_pixel_through_a_drone_camera(u, v, pitch, yaw):
    """pixel -> ground -> pixel < 1e-6 px through a drone photo's camera: the database's DJI FC330
    (Phantom 4) with its Brown–Conrady distortion, at its full 4000 x 3000."""
    from eoloc.sensor import dronemodels

    class Exif(dict):
        def get_ifd(self, tag):
            return {37386: 3.61}

    cam, source = dronemodels.camera_for("DJI", "FC330", 4000, 3000, thermal=False, tags={}, exif=Exif())
    assert cam.distortion is not None and "djiFC330" in source
    sensor = eoloc.SensorModel(cam, eoloc.AzElGimbal())
    pose = eoloc.Pose(40.0, -105.0, 2500.0, yaw, pitch, 0.0, (0.0, 0.0))
    f = eoloc.locate(sensor, pose, eoloc.AtHeight(1800.0), (np.array([u]), np.array([v])))
    if not f.ok[0]:
        return  # a ray above the horizon at a shallow pitch: nothing to project back
    uu, vv = sensor.ground_to_image(pose, f.p_ecef())
    assert abs(uu[0] - u) < 1e-6 and abs(vv[0] - v) < 1e-6
