"""The telemetry sources (eoloc.io.sources) read a drone flight written by the test in each
format — a P4 RTK .SRT (GPS (lon, lat), HOME, H above take-off, G.PRY as pitch, roll, yaw), a
newer bracket .SRT (latitude/longitude, rel_alt, gb_yaw/gb_pitch/gb_roll) and an Airdata log
(heights in international feet, 0.3048 m by definition) — from poses chosen first
(tests/helpers/droneflight.py): every record's position and attitude as written, and its height
the take-off point's ground (the oracle's bilinear sample of the DEM's posts) plus the height above
take-off (issue 55: the sources' own tests)."""

from __future__ import annotations

import droneflight as DF
import numpy as np
import pytest
from demtruth import TILE

import eoloc
from eoloc.io.sources import read_source


@pytest.mark.parametrize("fmt", ["p4rtk", "bracket", "airdata"])
def test_a_flight_is_read_as_written(tmp_path, fmt):
    _, takeoff, poses, path = DF.write_flight(tmp_path, fmt)
    data = read_source(path, dem=eoloc.open_dem(TILE, vertical="ellipsoid"))  # the oracle reads its posts as they are
    c = data.telemetry.columns
    first = 1 if fmt == "bracket" else 0  # the bracket clip's record 0 sits on the ground at take-off
    np.testing.assert_allclose(c["lat_deg"][first:], poses["lat"][first:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(c["lon_deg"][first:], poses["lon"][first:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(c["h_m"][first:], takeoff[2] + poses["rel"][first:], rtol=0, atol=1e-3)
    for name in ("yaw", "pitch", "roll"):
        np.testing.assert_allclose(c[f"{name}_deg"][first:], poses[name][first:], rtol=0, atol=1e-9, err_msg=name)
    if fmt == "bracket":
        assert c["h_m"][0] == pytest.approx(takeoff[2], abs=1e-3)
