"""Geodesy against PROJ (pyproj) at < 1 mm (we reach nanometres) and edge values."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc import geodesy

TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
TO_GEO = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
M_PER_DEG = 111_320.0  # upper bound of metres per degree of latitude, to state errors in metres


def _sample(n, seed):
    rng = np.random.default_rng(seed)
    lat = rng.uniform(-90, 90, n)
    lon = rng.uniform(-180, 180, n)
    h = rng.uniform(-10_000, 100_000, n)
    edge_lat = np.array([90, -90, 89.999999, -89.999999, 0, 0, 45, -45, 1e-12, -1e-12, 90, -90])
    edge_lon = np.array([0, 180, -180, 180, 180, -180, 179.9999999, -179.9999999, 0, 90, 123, -45])
    edge_h = np.array([-10_000, 100_000, 0, 0, -10_000, 100_000, 50_000, 0, 0, 0, 100_000, -10_000])
    return np.r_[edge_lat, lat], np.r_[edge_lon, lon], np.r_[edge_h, h]


def test_wgs84_constants_exact():
    assert eoloc.WGS84.a == 6378137.0
    assert eoloc.WGS84.f == 1 / 298.257223563
    # b from a and f, never the rounded 6 356 752 m of the sources
    assert eoloc.WGS84.b == pytest.approx(6356752.314245179, abs=1e-9)


def test_geodetic_to_ecef_matches_proj(backend):
    lat, lon, h = _sample(100_000, 1)
    x, y, z = eoloc.geodetic_to_ecef(lat, lon, h)
    X, Y, Z = TO_ECEF.transform(lon, lat, h)
    assert np.max(np.abs(np.stack([x - X, y - Y, z - Z]))) < 1e-6  # metres


def test_ecef_to_geodetic_matches_proj(backend):
    lat, lon, h = _sample(100_000, 2)
    X, Y, Z = TO_ECEF.transform(lon, lat, h)
    la, lo, hh = eoloc.ecef_to_geodetic(X, Y, Z)
    plo, pla, ph = TO_GEO.transform(X, Y, Z)
    # SPEC: < 1 mm against PROJ. PROJ's inverse is one Bowring step (0.1 mm off at 100 km), so
    # the PROJ comparison is held at 0.2 mm and the exact answer (the forward input) at 10 nm.
    assert np.max(np.abs(la - pla)) * M_PER_DEG < 2e-4
    assert np.max(np.abs(hh - ph)) < 2e-4
    assert np.max(np.abs(la - lat)) * M_PER_DEG < 1e-8
    assert np.max(np.abs(hh - h)) < 1e-8
    dlon = (lo - lon + 180) % 360 - 180
    # longitude is undefined on the polar axis; elsewhere compare its arc length
    arc = np.abs(dlon) * M_PER_DEG * np.cos(np.radians(lat))
    assert np.max(arc) < 1e-8


def test_poles_and_centre_of_earth(backend):
    lat, lon, h = eoloc.ecef_to_geodetic(0.0, 0.0, eoloc.WGS84.b + 123.0)
    assert (lat, lon) == (90.0, 0.0)
    assert h == pytest.approx(123.0, abs=1e-9)
    lat, _, h = eoloc.ecef_to_geodetic(0.0, 0.0, -eoloc.WGS84.b - 5.0)
    assert lat == -90.0 and h == pytest.approx(5.0, abs=1e-9)
    assert np.isnan(eoloc.ecef_to_geodetic(0.0, 0.0, 0.0)[0])


def test_scalar_in_scalar_out_and_shapes(backend):
    x, y, z = eoloc.geodetic_to_ecef(10.0, 20.0, 30.0)
    assert np.ndim(x) == 0 and isinstance(x, np.floating)
    lat = np.zeros((4, 1))
    lon = np.zeros((1, 5))
    assert eoloc.geodetic_to_ecef(lat, lon, 0.0)[0].shape == (4, 5)


def test_nan_propagates_not_raises(backend):
    x, y, z = eoloc.geodetic_to_ecef(np.array([np.nan, 10.0]), 0.0, 0.0)
    assert np.isnan(x[0]) and np.isfinite(x[1])


@settings(max_examples=300, deadline=None)
@given(
    lat=st.floats(-90, 90), lon=st.floats(-180, 180), h=st.floats(-10_000, 100_000),
)
def test_round_trip_geodetic_ecef(lat, lon, h):
    la, lo, hh = eoloc.ecef_to_geodetic(*eoloc.geodetic_to_ecef(lat, lon, h))
    assert abs(la - lat) * M_PER_DEG < 1e-6
    assert abs(hh - h) < 1e-6
    if abs(lat) < 89.9999:
        assert abs((lo - lon + 180) % 360 - 180) * M_PER_DEG * np.cos(np.radians(lat)) < 1e-6


def test_R_ecef_ned_columns_are_north_east_down():
    R = geodesy.R_ecef_ned(0.0, 0.0)
    # at (0, 0): north = +z, east = +y, down = -x
    np.testing.assert_allclose(R, [[0, 0, -1], [0, 1, 0], [1, 0, 0]], atol=1e-15)
    R = geodesy.R_ecef_ned(90.0, 0.0)
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-15)  # down at the north pole


def test_R_ecef_ned_orthonormal_stack():
    lat = np.linspace(-90, 90, 7)[:, None]
    lon = np.linspace(-180, 180, 5)[None, :]
    R = geodesy.R_ecef_ned(lat, lon)
    assert R.shape == (7, 5, 3, 3)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-15)


def test_ned_enu_offsets_against_pymap3d():
    pymap3d = pytest.importorskip("pymap3d")
    lat0, lon0, h0 = 35.5, -120.25, 150.0
    rng = np.random.default_rng(3)
    lat = lat0 + rng.uniform(-0.5, 0.5, 50)
    lon = lon0 + rng.uniform(-0.5, 0.5, 50)
    h = rng.uniform(-100, 3000, 50)
    ned = geodesy.geodetic_to_ned(lat, lon, h, lat0, lon0, h0)
    n, e, d = pymap3d.geodetic2ned(lat, lon, h, lat0, lon0, h0)
    np.testing.assert_allclose(ned, np.stack([n, e, d], -1), atol=1e-6)
    p = np.stack(eoloc.geodetic_to_ecef(lat, lon, h), -1)
    enu = geodesy.ecef_to_enu(p, lat0, lon0, h0)
    np.testing.assert_allclose(enu, np.stack([e, n, -np.asarray(d)], -1), atol=1e-6)
    np.testing.assert_allclose(geodesy.enu_to_ecef(enu, lat0, lon0, h0), p, atol=1e-6)
    np.testing.assert_allclose(geodesy.ned_to_ecef(ned, lat0, lon0, h0), p, atol=1e-6)


def test_backends_agree_to_1e8_m():
    lat, lon, h = _sample(50_000, 9)
    out = {}
    for b in eoloc.available_backends():
        with eoloc.use_backend(b):
            x, y, z = eoloc.geodetic_to_ecef(lat, lon, h)
            out[b] = (x, y, z, *eoloc.ecef_to_geodetic(x, y, z))
    if len(out) == 2:
        a, b = out["numba"], out["numpy"]
        for i in range(3):
            assert np.max(np.abs(a[i] - b[i])) < 1e-8
        assert np.max(np.abs(a[3] - b[3])) * M_PER_DEG < 1e-8
        assert np.max(np.abs(a[5] - b[5])) < 1e-8


def test_auto_backend_is_numba_once_loaded():
    """Once numba is loaded, ``auto`` runs every kernel on it, large atan2-heavy batches included
    (numba's vectorised loops beat numpy's SIMD ufuncs on them, bench/RESULTS.md): a big ECEF ->
    geodetic batch under auto is numba's bit for bit, and not numpy's (their atan2 differ in the
    last bit somewhere in 200 000 points, which is what makes this check able to fail)."""
    if "numba" not in eoloc.available_backends():
        pytest.skip("numba not installed: auto is numpy, nothing to route")
    import importlib

    importlib.import_module("eoloc.kernels.compiled")  # loaded: auto has nothing left to rent

    lat, lon, h = _sample(200_000, 4)
    x, y, z = eoloc.geodetic_to_ecef(lat, lon, h)
    with eoloc.use_backend("auto"):
        auto = eoloc.ecef_to_geodetic(x, y, z)
    forced = {}
    for b in ("numba", "numpy"):
        with eoloc.use_backend(b):
            forced[b] = eoloc.ecef_to_geodetic(x, y, z)
    for a, n in zip(auto, forced["numba"], strict=True):
        np.testing.assert_array_equal(a, n)
    assert any(np.any(a != n) for a, n in zip(auto[:2], forced["numpy"][:2], strict=True))


AUTO_RENTS = """
import sys, numpy as np, eoloc
from eoloc.kernels import backend, core
rng = np.random.default_rng(3)
def batch(n):
    lat, lon, h = rng.uniform(-89, 89, n), rng.uniform(-180, 180, n), rng.uniform(-500, 9000, n)
    return eoloc.ecef_to_geodetic(*eoloc.geodetic_to_ecef(lat, lon, h))
small = [batch(20_000) for _ in range(3)]
sig = core.SIGNATURES
counted = 3 * 20_000 * (sig["geodetic_to_ecef"].numpy_ns + sig["ecef_to_geodetic"].numpy_ns)
print("after small", backend.numba_loaded(), "numba" in sys.modules, backend._rent["spent_ns"] == counted)
backend.NUMBA_LOAD_NS = backend._rent["spent_ns"] + 1e6   # a budget the next batch passes
lat, lon, h = rng.uniform(-89, 89, 200_000), rng.uniform(-180, 180, 200_000), rng.uniform(-500, 9000, 200_000)
x, y, z = eoloc.geodetic_to_ecef(lat, lon, h)
print("after big", backend.numba_loaded())
auto = eoloc.ecef_to_geodetic(x, y, z)
with eoloc.use_backend("numba"):
    numba = eoloc.ecef_to_geodetic(x, y, z)
print("same as numba", all(np.array_equal(a, b) for a, b in zip(auto, numba)))
"""


def test_auto_rents_numpy_until_numba_pays_for_its_loading():
    """A fresh process under ``auto`` runs small batches on numpy without importing numba (its
    loading costs more than they take), counting their work (elements x the kernel's numpy_ns);
    the first batch that would take the count past the budget loads numba, and from then on auto
    is numba's bit for bit."""
    if "numba" not in eoloc.available_backends():
        pytest.skip("numba not installed: auto is numpy")
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "EOLOC_BACKEND"}
    out = subprocess.run([sys.executable, "-c", AUTO_RENTS], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.splitlines() == ["after small False False True", "after big True", "same as numba True"], \
        out.stdout


def test_use_backend_restores_the_previous_backend():
    """Leaving a ``use_backend`` block must put back what was in force, not keep the inner one."""
    outer = eoloc.get_backend()
    for inner in eoloc.available_backends():
        with eoloc.use_backend(inner):
            assert eoloc.get_backend() == inner
        assert eoloc.get_backend() == outer


def test_horizontal_distance_known_values_and_nan():
    """One degree of longitude on the equator is a·π/180 = 111 319.4908 m; NaN in, NaN out (no crash)."""
    d = geodesy.horizontal_distance_m([0.0, np.nan, 0.0], [0.0, 0.0, 10.0], [0.0, 1.0, 0.0], [1.0, 0.0, 10.0])
    assert d[0] == pytest.approx(6378137.0 * np.pi / 180.0, abs=1e-3)
    assert np.isnan(d[1]) and d[2] == 0.0
