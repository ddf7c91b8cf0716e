"""A drone photo's pose as eoloc.io.photo reads it from the tags the test writes
(tests/helpers/dronephoto.py), against what was written: the height datum of each vendor's tag
and the vendors' angle conventions (issue 55)."""

from __future__ import annotations

import pytest
from dronephoto import gps_as_written, write_photo, write_vendor_photo

from eoloc.io.photo import read_photo
from eoloc.terrain.geoid import default_geoid

LAT, LON = 40.2549, -105.616


def _dji(version: str) -> dict:
    return {"Version": version, "GpsStatus": "Normal", "GpsLatitude": f"{LAT:+.9f}", "GpsLongitude": f"{LON:+.9f}",
            "AbsoluteAltitude": "+5000.000", "RelativeAltitude": "+120.000", "GimbalYawDegree": "+10.0",
            "GimbalPitchDegree": "-40.0", "GimbalRollDegree": "+0.0"}


def test_dji_heights_above_the_geoid_become_ellipsoidal_by_adding_the_undulation(tmp_path):
    """DJI XMP Version < 1.5 without RTK: AbsoluteAltitude is above EGM96, so the ellipsoidal
    height is it plus the geoid's undulation N (in the Colorado Front Range EGM96 lies 11-16 m
    under the ellipsoid: N < 0, so the camera is lower than the number written); Version 7.0's is
    ellipsoidal as written."""
    old = read_photo(write_photo(tmp_path / "old.jpg", 640, 480, _dji("1.4"), f35_mm=24))
    new = read_photo(write_photo(tmp_path / "new.jpg", 640, 480, _dji("7.0"), f35_mm=24))
    n = float(default_geoid().undulation(LAT, LON))
    assert -16.0 < n < -11.0
    assert old.h_m == pytest.approx(5000.0 + n, abs=1e-6) and "EGM96" in old.height_rule
    assert new.h_m == 5000.0
    assert (old.yaw_deg, old.pitch_deg, old.roll_deg) == (10.0, -40.0, 0.0)


@pytest.mark.parametrize("camera_pitch, want", [(0.0, -90.0), (25.0, -65.0), (90.0, 0.0)])
def test_old_autel_pix4d_pitch_is_zero_at_nadir(tmp_path, camera_pitch, want):
    """Older Autel firmware writes Pix4D's Camera:Pitch: 0 looking straight down, 90 at the horizon
    (Pix4D's own definition); eoloc's pitch is the optical axis' elevation (-90 at nadir)."""
    lat, lon, alt = gps_as_written(LAT, LON, 4200.0)
    p = read_photo(write_vendor_photo(tmp_path / "autel.jpg", 640, 480, "pix4d",
                                      {"Yaw": 30.0, "Pitch": camera_pitch, "Roll": 1.5}, make="Autel Robotics",
                                      model="XT701", gps=(lat, lon, alt), f35_mm=24))
    assert p.pitch_deg == pytest.approx(want) and p.yaw_deg == 30.0 and p.roll_deg == 1.5
    assert p.h_m == pytest.approx(alt + float(default_geoid().undulation(p.lat_deg, p.lon_deg)), abs=1e-6)


def test_skydio_absolute_altitude_is_above_the_geoid(tmp_path):
    """Skydio's drone-skydio AbsoluteAltitude is above EGM96 (Skydio's XMP documentation): the
    ellipsoidal height is it plus N; its CameraOrientationNED is the camera's yaw, pitch, roll."""
    tags = {"Latitude": f"{LAT:.9f}", "Longitude": f"{LON:.9f}", "AbsoluteAltitude": "4000.0",
            "CameraOrientationNED": {"Yaw": 12.5, "Pitch": -35.0, "Roll": 0.5}}
    p = read_photo(write_vendor_photo(tmp_path / "skydio.jpg", 640, 480, "skydio", tags, make="Skydio",
                                      model="X2-Test", f35_mm=24))
    n = float(default_geoid().undulation(LAT, LON))
    assert p.h_m == pytest.approx(4000.0 + n, abs=1e-6) and n < -11.0
    assert (p.yaw_deg, p.pitch_deg, p.roll_deg) == (12.5, -35.0, 0.5)
