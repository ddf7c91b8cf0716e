"""The kernels' own sine, cosine and atan2 (fdlibm polynomials the numba backend compiles into
vectorised loops), against CPython's libm and numpy; and the compiled drivers really vectorise."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc.kernels import core as K
from eoloc.rules import AtRange

HAS_NUMBA = "numba" in eoloc.available_backends()


def _ulps(a, ref):
    """|a - ref| in units in the last place of ref (of the smallest normal number near 0)."""
    a, ref = np.asarray(a, float), np.asarray(ref, float)
    return np.abs(a - ref) / np.spacing(np.maximum(np.abs(ref), np.finfo(float).tiny))


def _libm(fn, *args):
    return np.vectorize(fn, otypes=[float])(*args)


@settings(max_examples=300, deadline=None)
@given(st.floats(-K.SINCOS_MAX, K.SINCOS_MAX, allow_nan=False))
def test_sincos_poly_within_an_ulp_of_libm(t):
    s, c = K.sincos_poly(np.float64(t))
    # 1 ulp for every angle a sensor reports; 2 ulp out to a million radians (the reduced
    # argument's own rounding is not carried into the polynomial, as fdlibm's tail does)
    tol = 1.0 if abs(t) <= 1000.0 else 2.0
    assert _ulps(s, math.sin(t)) <= tol
    assert _ulps(c, math.cos(t)) <= tol


def test_sincos_poly_next_to_multiples_of_half_pi():
    """The reduction keeps pi/2 to ~150 bits, so sin(k pi/2 + tiny) keeps its relative precision
    (with pi/2 to 99 bits only, these were millions of ulp off)."""
    k = np.random.default_rng(3).integers(-600_000, 600_000, 20_000)
    t = k * (np.pi / 2)
    t = np.concatenate([t, np.nextafter(t, np.inf), np.nextafter(t, -np.inf)])
    s, c = K.sincos_poly(t)
    assert np.max(_ulps(s, _libm(math.sin, t))) <= 2.0
    assert np.max(_ulps(c, _libm(math.cos, t))) <= 2.0


def test_sincos_poly_special_values():
    t = np.array([0.0, -0.0, 5e-324, -5e-324, np.inf, -np.inf, np.nan, K.SINCOS_MAX, np.nextafter(K.SINCOS_MAX, 2e6)])
    with np.errstate(invalid="ignore"):
        s, c = K.sincos_poly(t)
    np.testing.assert_array_equal(s[:4], t[:4])  # sin(x) = x, sign of zero kept
    assert np.signbit(s[1]) and not np.signbit(s[0])
    np.testing.assert_array_equal(c[:4], 1.0)
    assert np.all(np.isnan(s[4:7])) and np.all(np.isnan(c[4:7]))
    assert np.isfinite(s[7]) and np.isfinite(c[7])
    assert np.isnan(s[8]) and np.isnan(c[8])  # past the reduction's range: corrupt input, not a direction


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False, width=64), st.floats(allow_nan=False,
                                                                              allow_infinity=False, width=64))
def test_atan2_poly_within_two_ulp_of_libm(y, x):
    with np.errstate(invalid="ignore"):  # 0/0 inside, resolved by the select that follows
        got = K.atan2_poly(np.float64(y), np.float64(x))
    assert _ulps(got, math.atan2(y, x)) <= 2.0


def test_atan2_poly_special_values_follow_c():
    """Signed zeros, infinities and NaN give exactly what C's atan2 gives (numpy's arctan2)."""
    sp = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, 5e-324, -5e-324, 1e308, -1e308])
    y, x = (a.ravel() for a in np.meshgrid(sp, sp))
    with np.errstate(all="ignore"):
        got, ref = K.atan2_poly(y, x), np.arctan2(y, x)
    same_nan = np.isnan(got) == np.isnan(ref)
    assert same_nan.all()
    ok = ~np.isnan(ref)
    assert np.all(np.signbit(got[ok]) == np.signbit(ref[ok]))
    assert np.max(_ulps(got[ok], ref[ok])) <= 1.0
    exact = ok & ((x == 0) | (y == 0) | np.isinf(x) | np.isinf(y))  # the octant and axis cases
    np.testing.assert_array_equal(got[exact], ref[exact])


@pytest.mark.skipif(not HAS_NUMBA, reason="numba not installed")
def test_compiled_twins_equal_the_numpy_evaluation_bit_for_bit():
    """The numba twins are the same arithmetic: not one bit apart from the numpy evaluation."""
    import numba

    from eoloc.kernels import compiled

    sincos, atan2 = compiled._g["sincos"], compiled._g["atan2"]

    @numba.njit
    def run(t, y, x, s, c, a):
        for i in range(t.size):
            s[i], c[i] = sincos(t[i])
            a[i] = atan2(y[i], x[i])

    rng = np.random.default_rng(11)
    t = np.concatenate([rng.uniform(-10, 10, 50_000), rng.uniform(-1e6, 1e6, 50_000), [0.0, -0.0, np.nan, 2e6]])
    y = rng.standard_normal(t.size) * 10.0 ** rng.integers(-30, 30, t.size)
    x = rng.standard_normal(t.size) * 10.0 ** rng.integers(-30, 30, t.size)
    s, c, a = np.empty_like(t), np.empty_like(t), np.empty_like(t)
    run(t, y, x, s, c, a)
    with np.errstate(invalid="ignore"):
        s0, c0 = K.sincos_poly(t)
    np.testing.assert_array_equal(s, s0)
    np.testing.assert_array_equal(c, c0)
    np.testing.assert_array_equal(a, K.atan2_poly(y, x))


@pytest.mark.skipif(not HAS_NUMBA, reason="numba not installed")
@pytest.mark.parametrize("name, n_out", [("camera_frame", 12), ("ray_direction", 3), ("stop_at_ellipsoid", 5),
                                          ("stop_at_range", 5), ("ecef_to_geodetic", 3)])
def test_per_element_drivers_compile_to_simd_loops(name, n_out):
    """The speed of the Monte Carlo and of batches rests on LLVM vectorising the drivers' loops.
    Three things each broke it without a visible error (and are guarded here): a libm call per
    sine, runtime overlap checks between many input and output arrays (the drivers are compiled
    with noalias), and a kernel left as a call in the loop body (kernels are always-inline)."""
    from eoloc.kernels import compiled

    n = 64
    rng = np.random.default_rng(0)
    arr = lambda: rng.uniform(0.1, 0.9, n)  # noqa: E731
    ell = (6378137.0, 6356752.314245179, 0.0066943799901413165, 0.006739496742276434)
    fresh = compiled._driver(compiled.DRIVERS[name].py_func, cache=False)  # cached code carries no IR
    if name == "camera_frame":  # az-el turret angles, skew and the pose varying; mount, boresight fixed
        eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        args = [0, arr(), arr(), arr(), *eye, *eye, *eye, arr(), *(arr() for _ in range(6)), 0.1, 0.2, 0.3, ell[0],
                ell[2]]
    elif name == "ray_direction":
        args = [*(arr() for _ in range(11))]
    elif name == "ecef_to_geodetic":
        args = [arr() * 6e6, arr() * 6e6, arr() * 6e6, *ell]
    else:
        args = [arr() * 6e6, arr() * 6e6, arr() * 6e6, -arr(), -arr(), -arr(), 100.0, *ell]

    def outputs():
        out = [np.empty(n) for _ in range(n_out)]
        if name.startswith("stop_"):
            out[-1] = np.empty(n, dtype=np.int8)
        return out

    got, ref = outputs(), outputs()
    fresh(n, *args, *got)
    ir = fresh.inspect_llvm(fresh.signatures[0])
    assert re.search(r"<\d+ x double>", ir), f"{name}: the element loop did not vectorise"
    compiled.DRIVERS[name](n, *args, *ref)  # and the cached driver the library runs gives the same numbers
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_array_equal(a, b)


def test_an_angle_of_a_million_radians_is_invalid_input_on_both_backends(backend):
    """A yaw of 10^9 degrees is corrupt telemetry, not a direction: INVALID_INPUT and NaN on both
    backends (the polynomial's reduction ends at SINCOS_MAX; numpy's path stops there too), in
    batches and in the single-target call, while the good target beside it is located."""
    from eoloc import AzElGimbal, Camera, Pose, SensorModel

    sensor = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())
    pose = Pose(42.0, 125.0, 10_000.0, np.array([10.0, 1e9, -1e9]), 5.0, -2.0, (45.0, -75.0))
    f = eoloc.locate_range(sensor, pose, 10_200.0)
    assert f.status.tolist() == [eoloc.Status.OK, eoloc.Status.INVALID_INPUT, eoloc.Status.INVALID_INPUT]
    assert np.isfinite(f.lat_deg[0]) and np.all(np.isnan(f.lat_deg[1:]))
    one = sensor.locate_one(42.0, 125.0, 10_000.0, 1e9, 5.0, -2.0, 45.0, -75.0, rule=AtRange(10_200.0))
    assert one[4] == eoloc.Status.INVALID_INPUT and np.isnan(one[0])
