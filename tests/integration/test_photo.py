"""Issue 48 (first part): drone photos located from their own EXIF/XMP (`eoloc photo`).

The independent references: DJI's own laser-range target written in a real Zenmuse H20N photo;
synthetic DJI photos whose XMP/EXIF the test writes (tests/helpers/dronephoto.py) from a camera pose and a
ground point chosen first, the pixel found by the oracle's projection (scipy, pyproj).
"""

from __future__ import annotations

import contextlib
import json
import math
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import coverage_lib as C
import numpy as np
import oracle_lib as O
import pytest
from demtruth import TILE, first_crossing, tile_grid
from dronephoto import write_photo
from hypothesis import given, settings
from hypothesis import strategies as st
from where import DATA

import eoloc

DRONE = DATA / "drone"
H20N = DRONE / "H20N__DJI_0006_R.JPG"
MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
EOLOC = str(Path(sys.executable).parent / "eoloc")


def _photo(*args, check=True):
    out = tempfile.mkdtemp(prefix="eoloc-photo-")  # its photo_fixes.csv (not into the working folder)
    r = subprocess.run([EOLOC, "photo", *map(str, args), "--json", "--out", out], capture_output=True, text=True,
                       timeout=120)
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
    assert r.returncode == 3 and "no photo could be located" in r.stderr  # ran, located nothing (CONVENTIONS)


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


# -- every vendor over a real DEM tile -----------------------------------------------------------------

def _vendor_case(vendor: str, rng, *, w=1280, h=960, resized=1, ir=False):
    """(tags, exif gps, make, model, extra writer kwargs, the camera the test expects, camera pose
    as written) of one synthetic photo per vendor's rules (each rule restated here, not eoloc's)."""
    from dronephoto import gps_as_written

    from eoloc.terrain.geoid import default_geoid  # the geoid grid is tested against its source elsewhere

    grid = tile_grid()
    lat, lon = float(np.mean(grid.lat_range)) + rng.uniform(-0.05, 0.05), float(np.mean(grid.lon_range)) + \
        rng.uniform(-0.05, 0.05)
    h_cam = grid.hmax + rng.uniform(200, 600)
    yaw, pitch, roll = round(rng.uniform(-180, 180), 4), round(rng.uniform(-80, -45), 4), round(rng.uniform(-2, 2), 4)
    n = float(default_geoid().undulation(lat, lon))
    f35 = 24.0
    cam = O.Camera(w, h, f35 / 36.0 * w, f35 / 36.0 * w, (w - 1) / 2, (h - 1) / 2)  # EXIF 35 mm: OpenAthena's rule
    kw: dict = {"f35_mm": f35}
    if vendor in ("dji", "dji-old"):  # Version 7.0: ellipsoidal; Version 1.4 without RTK: above EGM96
        old = vendor == "dji-old"
        alt = round(h_cam - n if old else h_cam, 3)
        tags = {"Version": "1.4" if old else "7.0", "GpsStatus": "Normal", "GpsLatitude": f"{lat:.9f}",
                "GpsLongitude": f"{lon:.9f}", "AbsoluteAltitude": f"{alt:.3f}", "GimbalYawDegree": yaw,
                "GimbalPitchDegree": pitch, "GimbalRollDegree": roll}
        return tags, None, "DJI", "FC-TEST", kw, cam, (round(lat, 9), round(lon, 9), alt + (n if old else 0.0), yaw,
                                                       pitch, roll)
    if vendor == "skydio":
        full_w, full_h = w * resized, h * resized
        fx, cx, cy = 1100.0 * resized, full_w / 2 - 0.5 + 3.0 * resized, full_h / 2 - 0.5 - 2.0 * resized
        tags = {"Latitude": f"{lat:.9f}", "Longitude": f"{lon:.9f}", "AbsoluteAltitude": f"{h_cam - n:.4f}",
                "CameraOrientationNED": {"Yaw": yaw, "Pitch": pitch, "Roll": roll},
                "CalibratedFocalLengthX": fx, "CalibratedFocalLengthY": fx * 1.001,
                "CalibratedOpticalCenterX": cx, "CalibratedOpticalCenterY": cy}
        h_true = float(f"{h_cam - n:.4f}") + n
        if ir:  # an IR frame carries the visible camera's calibration (another aspect): the 35 mm rule instead
            tags.update(CalibratedFocalLengthX=2376.5625, CalibratedFocalLengthY=2376.5625,
                        CalibratedOpticalCenterX=2027.5, CalibratedOpticalCenterY=1519.5)
        else:
            s = 1.0 / resized
            cam = O.Camera(w, h, fx * s, fx * 1.001 * s, (cx + 0.5) * s - 0.5, (cy + 0.5) * s - 0.5)
        return tags, None, "Skydio", "X2-Test", kw, cam, (lat, lon, h_true, yaw, pitch, roll)
    glat, glon, galt = gps_as_written(lat, lon, h_cam - n)
    if vendor == "parrot-ai":  # ANAFI Ai: ellipsoidal
        glat, glon, galt = gps_as_written(lat, lon, h_cam)
        n_used = 0.0
    else:
        n_used = float(default_geoid().undulation(glat, glon))
    pose = (glat, glon, galt + n_used, yaw, pitch, roll)
    if vendor in ("parrot", "parrot-ai"):
        tags = {"CameraYawDegree": yaw, "CameraPitchDegree": pitch, "CameraRollDegree": roll}
        return tags, (glat, glon, galt), "Parrot", "ANAFI Ai" if vendor == "parrot-ai" else "ANAFI USA", kw, cam, pose
    if vendor == "autel-old":  # Pix4D's Camera:Pitch: 0 at nadir, 90 at the horizon
        tags = {"Yaw": yaw, "Pitch": round(pitch + 90.0, 4), "Roll": roll}
        return tags, (glat, glon, galt), "Autel Robotics", "XT701", kw, cam, pose
    if vendor == "teal":  # platform + camera, as rationals
        p_yaw, p_pitch, p_roll = 12.5, 1.25, -0.75
        tags = {"PlatformYaw": f"{round(p_yaw * 1e4)}/10000", "CameraYaw": f"{round((yaw - p_yaw) * 1e4)}/10000",
                "PlatformPitch": f"{round(p_pitch * 1e4)}/10000",
                "CameraPitch": f"{round((pitch - p_pitch) * 1e4)}/10000",
                "PlatformRoll": f"{round(p_roll * 1e4)}/10000", "CameraRoll": f"{round((roll - p_roll) * 1e4)}/10000"}
        return tags, (glat, glon, galt), "Teledyne FLIR", "Teal 2", kw, cam, pose
    raise AssertionError(vendor)


VENDORS = ["dji", "dji-old", "skydio", "skydio-resized", "skydio-struct", "skydio-ir", "parrot", "parrot-ai",
           "autel-old", "teal"]


@pytest.mark.parametrize("case", VENDORS)
def test_48_synthetic_vendor_photos_on_a_real_dem_within_1cm(tmp_path, case):
    """A photo per vendor written by the test with that vendor's own tags (DJI drone-dji, its
    AbsoluteAltitude ellipsoidal (Version 7.0) or above EGM96 (Version 1.4, no RTK); Skydio
    drone-skydio with its calibration, a quarter-size copy, a struct written as a nested Description, an IR frame
    carrying the visible camera's calibration; Parrot ANAFI USA (EGM96) and ANAFI Ai (ellipsoidal);
    old Autel Pix4D Camera: tags; Teal platform + camera rationals) over the real Longs Peak tile:
    `eoloc photo --pixel U V --dem TILE` lands within 1 cm of the oracle's first DEM crossing."""
    from dronephoto import write_vendor_photo

    rng = np.random.default_rng(zlib.crc32(case.encode()))
    vendor = case.split("-")[0] if case.startswith("skydio") else case
    resized = 4 if case == "skydio-resized" else 1
    w, h = (640, 512) if case == "skydio-ir" else (1280, 960)
    tags, gps, make, model, kw, cam, pose = _vendor_case(vendor, rng, w=w, h=h, resized=resized,
                                                         ir=case == "skydio-ir")
    ns = {"dji": "dji", "dji-old": "dji", "skydio": "skydio", "parrot": "parrot", "parrot-ai": "parrot",
          "autel-old": "pix4d", "teal": "exif"}[vendor]
    path = write_vendor_photo(tmp_path / f"{case}.jpg", w, h, ns, tags, make=make, model=model, gps=gps,
                              struct_as_description=case == "skydio-struct", **kw)
    grid = tile_grid()
    for _ in range(3):
        u, v = rng.uniform(20, w - 20), rng.uniform(20, h - 20)
        truth = first_crossing(grid, cam, *pose, u, v)
        _, (row,) = _photo(path, "--pixel", u, v, "--dem", TILE, "--vertical", "ellipsoid")
        assert row["status"] == "OK" and row["source"] == "dem", row
        e = C.enu_error(row["lat"], row["lon"], row["h"], truth)
        assert np.linalg.norm(e) < 0.01, (case, e, row["intrinsics"])
    if case == "skydio-resized":
        assert "scaled" in row["intrinsics"]
    if case == "skydio-ir":
        assert "another camera's" in row["intrinsics"]


@pytest.mark.parametrize("case", ["dji", "dji-old", "skydio", "skydio-struct", "parrot", "autel-old", "teal"])
def test_52_a_refined_pose_goes_back_into_the_photos_own_xmp(tmp_path, case):
    """`eoloc refine PHOTOS`' sidecars (OUT/xmp/NAME.xmp): the photo's own XMP packet with the
    refined attitude in its vendor's tags and, where the XMP carries the position (DJI, Skydio),
    the position moved by the refined change in the photo's own height datum. Put back into the
    photo (the sidecar as its XMP), the photo reads as the refined pose: attitude to 1e-6 deg,
    position to 1e-9 deg and 1 mm; a position kept in EXIF is left, and said."""
    import dronephoto as D

    from eoloc.io.photo import read_photo
    from eoloc.io.xmpsidecar import refined_sidecar

    rng = np.random.default_rng(zlib.crc32(case.encode()))
    vendor = case.split("-")[0] if case.startswith("skydio") else case
    tags, gps, make, model, kw, _, pose = _vendor_case(vendor, rng, w=640, h=480, resized=1, ir=False)
    ns = {"dji": "dji", "dji-old": "dji", "skydio": "skydio", "parrot": "parrot", "autel-old": "pix4d",
          "teal": "exif"}[vendor]
    path = D.write_vendor_photo(tmp_path / f"{case}.jpg", 640, 480, ns, tags, make=make, model=model, gps=gps,
                                struct_as_description=case == "skydio-struct", **kw)
    given = read_photo(path)
    new = ((given.yaw_deg + 0.5 + 180.0) % 360.0 - 180.0, given.pitch_deg - 0.3, given.roll_deg + 0.2)
    shift = (2e-5, -3e-5, 4.25)
    text, notes = refined_sidecar(path, *new, shift)
    root = ET.fromstring(text[text.index("<x:xmpmeta"):text.rindex("</x:xmpmeta>") + 12])  # well-formed, as a
    assert root.tag == "{adobe:ns:meta/}xmpmeta"  # sidecar: the x:xmpmeta element at its root
    back = tmp_path / f"{case}_refined.jpg"
    jpeg = D._jpeg(640, 480, make=make, model=model, gps=gps, focal_mm=kw.get("focal_mm"), f35_mm=kw.get("f35_mm"))
    back.write_bytes(D._with_xmp(jpeg, text.encode("utf-8")))
    got = read_photo(back)
    assert (got.yaw_deg - new[0] + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=2e-6)
    assert got.pitch_deg == pytest.approx(new[1], abs=2e-6) and got.roll_deg == pytest.approx(new[2], abs=2e-6)
    if ns in ("dji", "skydio"):
        assert not notes
        assert got.lat_deg == pytest.approx(given.lat_deg + shift[0], abs=1e-9)
        assert got.lon_deg == pytest.approx(given.lon_deg + shift[1], abs=1e-9)
        assert got.h_m == pytest.approx(given.h_m + shift[2], abs=1e-3)
    else:
        assert (got.lat_deg, got.lon_deg, got.h_m) == (given.lat_deg, given.lon_deg, given.h_m)
        assert any("position is in its EXIF" in n for n in notes), notes


def test_48_a_wrong_altitude_tag_is_named_on_the_dem(tmp_path):
    """A Parrot photo whose EXIF altitude is 800 m too low puts the camera under the tile: refused,
    naming the tag (no point kilometres off)."""
    from dronephoto import write_vendor_photo

    rng = np.random.default_rng(5)
    tags, gps, make, model, kw, _, _ = _vendor_case("parrot", rng)
    gps = (gps[0], gps[1], gps[2] - 1500.0)
    path = write_vendor_photo(tmp_path / "low.jpg", 1280, 960, "parrot", tags, make=make, model=model, gps=gps, **kw)
    r, (row,) = _photo(path, "--dem", TILE, "--vertical", "ellipsoid", check=False)
    assert row["status"] == "SUSPECT_ALTITUDE" and "GPSAltitude" in row["reason"]


def test_48_the_database_tle_figure_is_given_beside_the_fix(tmp_path):
    """A DJI Mavic 2 Zoom (FC2200) photo: its row carries the database's own target-location-error
    model, tle_m = a + b x slant range, with a and b read here from the bundled JSON."""
    import json as _json

    db = _json.loads((Path(eoloc.__file__).parent / "data" / "drone" / "droneModels.json").read_text())
    e = next(x for x in db["droneCCDParams"] if x["makeModel"] == "djiFC2200")
    path = write_photo(tmp_path / "zoom.jpg", 4000, 3000, _dji_tags(40.0, -105.0, 3000.0, 20.0, -50.0, 0.0),
                       model="FC2200", focal_mm=4.386)
    _, (row,) = _photo(path, "--target-height", 2800)
    assert row["status"] == "OK" and "djiFC2200" in row["intrinsics"]
    assert row["tle_m"] == pytest.approx(e["tle_model_y_intercept"] + e["tle_model_slant_range_coeff"] * row["range_m"],
                                         rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.floats(0, 4383), st.floats(0, 3287), st.floats(-85, -30), st.floats(-180, 180))
def test_48_pixel_ground_pixel_through_a_fisheye_drone_camera(u, v, pitch, yaw):
    """The database's fisheye DJI FC200 (Phantom 2 Vision, Pix4D's polynomial): pixel -> ground ->
    pixel < 1e-6 px (hypothesis), and the pixel eoloc projects a ground point to equals Pix4D's
    published formula written out here (theta = 2/pi atan(r), rho(theta), the affine (C D; E F))
    applied to the oracle's camera coordinates."""
    from eoloc.sensor import dronemodels

    db = json.loads((Path(eoloc.__file__).parent / "data" / "drone" / "droneModels.json").read_text())
    e = next(x for x in db["droneCCDParams"] if x["makeModel"] == "djiFC200")

    class Exif(dict):
        def get_ifd(self, tag):
            return {}

    cam, source = dronemodels.camera_for("DJI", "FC200", 4384, 3288, thermal=False, tags={}, exif=Exif())
    assert "fisheye" in source
    sensor = eoloc.SensorModel(cam, eoloc.AzElGimbal())
    # pixels that surely see the ground (the centre, and around it) must be located: a lens model
    # that refused every pixel would pass the rest of this test vacuously
    near = eoloc.locate(sensor, eoloc.Pose(40.0, -105.0, 2500.0, 0.0, -80.0, 0.0, (0.0, 0.0)), eoloc.AtHeight(1800.0),
                        (np.array([2191.5, 1500.0, 2900.0, 2191.5]), np.array([1643.5, 1643.5, 1643.5, 800.0])))
    assert near.ok.all()
    pose = eoloc.Pose(40.0, -105.0, 2500.0, yaw, pitch, 0.0, (0.0, 0.0))
    f = eoloc.locate(sensor, pose, eoloc.AtHeight(1800.0), (np.array([u]), np.array([v])))
    if not f.ok[0]:
        return  # above the horizon at this attitude
    uu, vv = sensor.ground_to_image(pose, f.p_ecef())
    assert abs(uu[0] - u) < 1e-6 and abs(vv[0] - v) < 1e-6
    # Pix4D's formula by hand, on the oracle's camera frame (scipy rotations, pyproj)
    R_ec = O.r_ecef_ned(40.0, -105.0) @ O._euler("ZYX", yaw, pitch, 0.0) @ O.r_body_cam("az-el", 0.0, 0.0, 0.0)
    X, Y, Z = R_ec.T @ (f.p_ecef()[0] - O.to_ecef(40.0, -105.0, 2500.0))
    theta = 2 / np.pi * np.arctan(np.hypot(X, Y) / Z)
    rho = sum(e[f"poly{i}"] * theta**i for i in range(5))
    xh, yh = rho * X / np.hypot(X, Y), rho * Y / np.hypot(X, Y)
    pu = e["c"] * xh + e["d"] * yh + (4384 - 1) / 2
    pv = e["e"] * xh + e["f"] * yh + (3288 - 1) / 2
    assert abs(pu - u) < 1e-5 and abs(pv - v) < 1e-5, (pu - u, pv - v)


def _ray_to_height(o: np.ndarray, d: np.ndarray, h: float) -> np.ndarray:
    """The oracle's point where the ray o + s d comes down to ellipsoidal height h (bisection)."""
    lo, hi = 0.0, 50_000.0
    for _ in range(80):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if O.height((o + mid * d)[None])[0] > h else (lo, mid)
    return o + lo * d


def test_51_photo_fixes_sent_to_tak_with_coverage_tested_uncertainty(tmp_path):
    """`eoloc photo FOLDER --config budget.toml --cot udp://…` (issue 51, item 4; OpenAthena's
    use): 300 DJI photos whose XMP pose carries errors drawn from the budget, the image centre
    located on the target height (the true ground off it by the budget's terrain error); each CoT
    event a receiver parses is the JSON fix (1e-8 degrees) with ce = CE90 / 2.1460 and le =
    LE90 / 1.6449, and the truths (each true pose's centre ray on the true ground, by the oracle)
    fall inside the stated CEP50, CE90 and LE90 and inside the CoT's own circles as often as
    claimed (binomial 99 % bands)."""
    import socket

    rng = np.random.default_rng(51)
    sigma = {"lat_deg": 2e-5, "lon_deg": 2.5e-5, "h_m": 3.0, "yaw_deg": 1.5, "pitch_deg": 0.5, "roll_deg": 0.5,
             "terrain_m": 2.0}  # the ground is not exactly at the height given either
    budget = tmp_path / "budget.toml"
    budget.write_text("[accuracy.budget]\n" + "".join(f"{k} = {{normal = {v}}}\n" for k, v in sigma.items()))
    cam, target_h, n = O.Camera(640, 480, 550.0, 550.0, 319.5, 239.5), 1500.0, 300
    folder = tmp_path / "photos"
    folder.mkdir()
    truths = []
    for k in range(n):
        lat, lon, h_cam = 40 + rng.uniform(-1, 1), -105 + rng.uniform(-1, 1), target_h + rng.uniform(150, 600)
        yaw, pitch, roll = rng.uniform(-180, 180), rng.uniform(-75, -35), rng.uniform(-3, 3)
        o, d, _ = O.rays(cam, "az-el", lat, lon, h_cam, yaw, pitch, roll, 0.0, 0.0, 0.0, np.array(cam.cx),
                         np.array(cam.cy))
        e = {key: rng.normal(0.0, s) for key, s in sigma.items()}
        ground = target_h + e["terrain_m"]
        truths.append(np.array(O.geodetic(_ray_to_height(o, d, ground))).ravel())  # lat, lon, h
        write_photo(folder / f"p{k:03d}.jpg", 640, 480,
                    _dji_tags(lat + e["lat_deg"], lon + e["lon_deg"], h_cam + e["h_m"], yaw + e["yaw_deg"],
                              pitch + e["pitch_deg"], roll + e["roll_deg"], CalibratedFocalLength="550.0",
                              CalibratedOpticalCenterX="319.5", CalibratedOpticalCenterY="239.5"))
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    rx.settimeout(2.0)
    r, rows = _photo(folder, "--target-height", target_h, "--config", budget, "--cot",
                     f"udp://127.0.0.1:{rx.getsockname()[1]}")
    events = {}
    with contextlib.suppress(TimeoutError):
        while True:
            data = rx.recv(65536)
            ev = ET.fromstring(data[data.find(b"<event"):])
            events[ev.get("uid")] = ev
    rx.close()
    assert len(rows) == n and all(row["status"] == "OK" for row in rows) and len(events) == n, r.stderr
    truth = np.array(truths)
    err = np.array([C.enu_error(row["lat"], row["lon"], row["h"], t) for row, t in zip(rows, truth, strict=True)])
    col = {k: np.array([row[k] for row in rows]) for k in ("cep50_m", "ce90_m", "le90_m", "nonlinearity")}
    ce, le = np.empty(n), np.empty(n)
    for i, row in enumerate(rows):
        ev = events[f"eoloc-{Path(row['file']).stem}"]
        pt = ev.find("point")
        assert abs(float(pt.get("lat")) - row["lat"]) < 1e-8 and abs(float(pt.get("lon")) - row["lon"]) < 1e-8
        ce[i], le[i] = float(pt.get("ce")), float(pt.get("le"))
        assert ce[i] == pytest.approx(row["ce90_m"] / 2.1460, rel=1e-3, abs=0.006)
        assert le[i] == pytest.approx(row["le90_m"] / 1.6449, rel=1e-3, abs=0.006)
    keep = col["nonlinearity"] <= 0.1
    assert keep.mean() > 0.95
    stated = C.coverage("photo fixes", err, col["cep50_m"], col["ce90_m"], col["le90_m"], keep)
    parsed = C.coverage("photo CoT as parsed", err, np.full(n, np.inf), 2.1460 * ce, 1.6449 * le, keep)
    assert all(stated.within().values()), stated.row()
    assert parsed.within()["CE90"] and parsed.within()["LE90"], parsed.row()


def _oracle_ground(cam, pose, u, v, target_h):
    """The oracle's point where pixel (u, v)'s ray meets the ellipsoidal height target_h."""
    o, d, _ = O.rays(cam, "az-el", *pose, 0.0, 0.0, 0.0, np.array(u, float), np.array(v, float))
    return np.array(O.geodetic(_ray_to_height(o, d, target_h))).ravel()


def test_48_a_folder_of_photos_gives_footprints_and_orthos(tmp_path):
    """`eoloc photo FOLDER --target-height H --ortho`: for every photo of the folder its footprint
    (photo_footprints.geojson: the image's four outer corners on the ground where the oracle's rays
    meet H, to 2 cm) and an orthorectified COG (ortho/<photo>.tif, valid for rio-cogeo), in which
    the bright square the test painted at a chosen pixel lies where the oracle's ray of that pixel
    meets H (its centroid within one cell). A photo that cannot be read is named, the others done."""
    import pyproj
    import rasterio
    from rio_cogeo.cogeo import cog_validate

    rng = np.random.default_rng(4848)
    w, h = 640, 480
    cam = O.Camera(w, h, 700.0, 700.0, 319.5, 239.5)
    folder = tmp_path / "flight"
    folder.mkdir()
    cases = []
    for k in range(3):
        lat, lon, h_cam = 40.0 + 0.002 * k, -105.0 + 0.003 * k, 2000.0
        yaw, pitch, roll = rng.uniform(-180, 180), rng.uniform(-80, -55), rng.uniform(-2, 2)
        u0, v0 = int(rng.integers(80, w - 80)), int(rng.integers(80, h - 80))
        picture = np.full((h, w, 3), 40, np.uint8)
        picture[v0 - 6:v0 + 7, u0 - 6:u0 + 7] = 255  # 13 x 13 pixels centred on (u0, v0)
        tags = _dji_tags(lat, lon, h_cam, yaw, pitch, roll, CalibratedFocalLength="700.0",
                         CalibratedOpticalCenterX="319.5", CalibratedOpticalCenterY="239.5")
        write_photo(folder / f"DJI_{k:04d}.JPG", w, h, tags, model="FC230", focal_mm=4.49, picture=picture)
        cases.append(((lat, lon, h_cam, yaw, pitch, roll), (u0, v0)))
    (folder / "DJI_9999.JPG").write_bytes(b"not a photo")
    target_h = 1700.0
    out = tmp_path / "out"
    r = subprocess.run([EOLOC, "photo", str(folder), "--target-height", str(target_h), "--ortho", "--gsd", "0.5",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "DJI_9999.JPG" in r.stderr
    prints = json.loads((out / "photo_footprints.geojson").read_text())["features"]
    assert [Path(f["properties"]["file"]).name for f in prints] == [f"DJI_{k:04d}.JPG" for k in range(3)]
    for (pose, _), feature in zip(cases, prints, strict=True):
        ring = np.array(feature["geometry"]["coordinates"][0])
        for u, v in [(-0.5, -0.5), (w - 0.5, -0.5), (w - 0.5, h - 0.5), (-0.5, h - 0.5)]:
            corner = _oracle_ground(cam, pose, u, v, target_h)
            gaps = [np.linalg.norm(C.enu_error(lat_, lon_, target_h, corner)[:2]) for lon_, lat_ in ring[:, :2]]
            assert min(gaps) < 0.02, (u, v, min(gaps))
    for k, (pose, (u0, v0)) in enumerate(cases):
        tif = out / "ortho" / f"DJI_{k:04d}.tif"
        valid, errors, _ = cog_validate(str(tif))
        assert valid and not errors, errors
        with rasterio.open(tif) as ds:
            band = ds.read(1).astype(float)
            rows, cols = np.nonzero(band > 150)
            x, y = ds.xy(rows, cols)
            to_geo = pyproj.Transformer.from_crs(ds.crs, "EPSG:4326", always_xy=True)
            lon_c, lat_c = to_geo.transform(np.mean(x), np.mean(y))
            cell = abs(ds.res[0])
        truth = _oracle_ground(cam, pose, u0, v0, target_h)
        gap = np.linalg.norm(C.enu_error(lat_c, lon_c, target_h, truth)[:2])
        assert cell == pytest.approx(0.5) and gap < cell, (k, gap)


def test_48_the_http_api_locates_a_photo_as_eoloc_photo_does(tmp_path):
    """`POST /v1/photo` on a real `eoloc serve` (its DEM by name): the H20N photo's centre by its
    laser range lands on DJI's own target (0.3 m) and equals `eoloc photo --json`'s row; a
    synthetic DJI photo's pixel at a target height lands within 1 cm of the oracle's point; on the
    served DEM the same row as `eoloc photo --dem`. Bad requests answer 415/422 naming what is
    wrong (a non-image, both grounds, a malformed pixel, an unknown DEM, covariance without a
    budget), never a traceback."""
    import httpx
    from served import eoloc_serve, stop_and_log

    rng = np.random.default_rng(4849)
    w, h = 1280, 960
    cam = O.Camera(w, h, 1100.0, 1100.0, 650.25, 470.75)
    lat, lon, h_cam, yaw, pitch, roll = 40.25, -105.6, 5200.0, 30.0, -60.0, 1.0
    path = write_photo(tmp_path / "dji.jpg", w, h, _dji_tags(lat, lon, h_cam, yaw, pitch, roll,
                                                            CalibratedFocalLength="1100.0",
                                                            CalibratedOpticalCenterX="650.25",
                                                            CalibratedOpticalCenterY="470.75"),
                       model="FC230", focal_mm=4.49)
    jpeg = {"content-type": "image/jpeg"}
    with eoloc_serve("--dem", f"peak={TILE}", "--vertical", "ellipsoid", "--max-body-mb", "32") as url:
        r = httpx.post(url + "/v1/photo", content=H20N.read_bytes(), headers=jpeg, params={"name": H20N.name})
        assert r.status_code == 200, r.text
        (row,) = r.json()["fixes"]
        _, (cli,) = _photo(H20N)
        assert row["source"] == "laser"  # the server's kernels are compiled: equal to a few ulps
        assert [row[k] for k in ("lat", "lon", "h")] == pytest.approx([cli[k] for k in ("lat", "lon", "h")], rel=1e-13)
        d = C.enu_error(row["lat"], row["lon"], row["h"], np.array([22.5960255, 114.0066452, 47.000]))
        assert math.hypot(d[0], d[1]) < 0.3 and abs(d[2]) < 0.3, d
        u, v = rng.uniform(100, w - 100), rng.uniform(100, h - 100)
        truth = _oracle_ground(cam, (lat, lon, h_cam, yaw, pitch, roll), u, v, 3000.0)
        r = httpx.post(url + "/v1/photo", content=path.read_bytes(), headers=jpeg,
                       params={"pixel": f"{u!r},{v!r}", "target_height_m": 3000.0})
        (row,) = r.json()["fixes"]
        assert row["status"] == "OK" and np.linalg.norm(C.enu_error(row["lat"], row["lon"], row["h"], truth)) < 0.01
        r = httpx.post(url + "/v1/photo", content=path.read_bytes(), headers=jpeg,
                       params=[("pixel", "640,480"), ("pixel", "100,900"), ("dem", "peak")])
        _, cli = _photo(path, "--pixel", 640, 480, "--pixel", 100, 900, "--dem", TILE, "--vertical", "ellipsoid")
        got = r.json()["fixes"]
        assert [x["status"] for x in got] == [x["status"] for x in cli] == ["OK", "OK"]
        np.testing.assert_allclose([[x[k] for k in ("lat", "lon", "h")] for x in got],
                                   [[x[k] for k in ("lat", "lon", "h")] for x in cli], rtol=1e-12)
        bad = [(b"not a photo", jpeg, {}, 422, "not an image"),
               (path.read_bytes(), {"content-type": "text/plain"}, {}, 415, "image/jpeg"),
               (path.read_bytes(), jpeg, {"dem": "peak", "target_height_m": 1.0}, 422, "not both"),
               (path.read_bytes(), jpeg, {"pixel": "1;2"}, 422, "U,V"),
               (path.read_bytes(), jpeg, {"dem": "moon"}, 422, "peak"),
               (path.read_bytes(), jpeg, {"covariance": "true"}, 422, "accuracy.budget")]
        for body, headers, params, status, words in bad:
            r = httpx.post(url + "/v1/photo", content=body, headers=headers, params=params)
            assert r.status_code == status and words in r.text, (params, r.status_code, r.text)
        log = stop_and_log(url)
    assert "Traceback" not in log
