"""The compiled kernels against references that are not eoloc (issue 55).

- The compiled single-target chain (``SensorModel.locate_one``: the numba twins of
  ``r_body_cam_azel`` / ``r_body_cam_rollpitch`` / the fixed mount, the pose frame and the M1 stop)
  against scipy ``Rotation`` + pyproj (the oracle, tests/helpers/oracle_lib.py), for every gimbal
  kind: the camera's rotation recovered from three rays, to 1e-9 rad.
- A DEM ray that enters and leaves the terrain inside one cell (the surface bilinear, a ray dipping
  a few centimetres to metres under its crest): eoloc's M4 point is the first root, found here by a
  dense walk along the ray on scipy's bilinear interpolation of the posts and refined by
  bisection. Taking the later root (the `np.maximum` mutant of issue 55) is 15 m off.
- Points behind the camera have no pixel (the projection kernel), every gimbal kind.
"""

from __future__ import annotations

import numpy as np
import oracle_lib as O
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc.rules import AtRange

ANGLE = st.floats(-179.0, 179.0)


LEVER = st.tuples(*(st.floats(-5.0, 5.0),) * 3)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(O.KINDS), st.floats(-70, 70), st.floats(-170, 170), st.floats(100, 9000), ANGLE,
       st.floats(-60, 60), st.floats(-60, 60), ANGLE, st.floats(-85, 85), st.floats(-45, 45), LEVER)
def test_55_compiled_camera_rotation_equals_scipy(kind, lat, lon, h, yaw, pitch, roll, g1, g2, g3, lever):
    """R_ecef_cam of the compiled chain = the oracle's (scipy Rotation of the README's conventions),
    every gimbal kind, with a lever arm (the camera's offset in body axes): the rays of the
    principal point and two other pixels, stopped at 1 km by the compiled single-target kernel,
    end where scipy's rotation and the oracle's ray origin say (1 km x 1e-9 rad + rounding)."""
    from dataclasses import replace

    if "numba" not in eoloc.available_backends():
        pytest.skip("numba not installed")  # the compiled chain is what this tests
    sensor = replace(O._sensor(eoloc, kind), lever_arm_m=lever)
    c = {"lat": lat, "lon": lon, "h": h, "yaw": yaw, "pitch": pitch, "roll": roll, "g1": g1, "g2": g2, "g3": g3}
    gim = O._gimbal_tuple({k: np.atleast_1d(v) for k, v in c.items()}, kind)
    angles = [float(np.ravel(a)[0]) for a in gim] + [0.0] * (3 - len(gim))
    pix = [(O.CAMERA.cx, O.CAMERA.cy), (100.0, 80.0), (1100.0, 900.0)]
    origin = O.to_ecef(lat, lon, h)
    for u, v in pix:
        if kind == "fixed":
            out = sensor.locate_one(lat, lon, h, yaw, pitch, roll, angles[0], 0.0, u, v, rule=AtRange(1000.0))
        else:
            out = sensor.locate_one(lat, lon, h, yaw, pitch, roll, angles[0], angles[1], u, v, g3_deg=angles[2],
                                    rule=AtRange(1000.0))
        assert out[4] == 0
        o, d, _ = O.rays(O.CAMERA, kind, lat, lon, h, yaw, pitch, roll, g1, g2, g3, np.array(u), np.array(v),
                         lever=lever, R_fixed=O.R_FIXED)
        got = O.to_ecef(out[0], out[1], out[2]) - origin
        want = o.reshape(3) - origin + 1000.0 * d.reshape(3)
        assert np.linalg.norm(got - want) < 2e-6, (kind, u, v, got, want)
        assert abs(out[3] - 1000.0) < 1e-9


def _one_cell_dem(crest_m: float):
    """A flat 1000 m tile, 3" posts, one cell whose two anti-diagonal corners are raised: along the
    cell's diagonal the bilinear surface is a parabola peaking crest_m / 2 + 1000 at its middle."""
    n = 12
    z = np.full((n, n), 1000.0)
    i = j = 5
    z[i, j + 1] = z[i + 1, j] = 1000.0 + crest_m
    d = 1.0 / 1200.0
    return z, 40.0, -105.0, d, d, (i, j)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.02, 3.0), st.floats(-0.15, 0.15), st.floats(8.0, 30.0))
def test_55_dem_ray_entering_and_leaving_inside_one_cell_hits_the_first_root(dip_m, shift, crest_m):
    """A near-horizontal ray along a cell's diagonal, ``dip_m`` under the crest of the bilinear
    surface (so it enters and leaves the terrain inside the cell): eoloc's M4 range = the first
    root of the walk on scipy's bilinear surface, within 5 mm, on both backends."""
    z, lat0, lon0, dlat, dlon, (i, j) = _one_cell_dem(crest_m)
    dem = eoloc.DEM.from_array(z, lat0=lat0, lon0=lon0, dlat=dlat, dlon=dlon)
    grid = O.Grid(z, lat0, lon0, dlat, dlon)
    peak = 1000.0 + crest_m / 2.0
    h_ray = peak - dip_m
    # the ray: from 400 m before the cell's corner (i, j) to beyond (i + 1, j + 1), shifted across
    a = np.array([lat0 + (i - 3 + shift) * dlat, lon0 + (j - 3 - shift) * dlon])
    b = np.array([lat0 + (i + 4 + shift) * dlat, lon0 + (j + 4 - shift) * dlon])
    pa, pb = O.to_ecef(a[0], a[1], h_ray), O.to_ecef(b[0], b[1], h_ray)
    d = (pb - pa) / np.linalg.norm(pb - pa)
    # scipy's bilinear surface along the ray, walked every 2 cm, the first root refined by bisection
    s = np.arange(0.0, np.linalg.norm(pb - pa), 0.02)
    q = pa[None] + s[:, None] * d[None]
    la, lo, hh = O.geodetic(q)
    zt, on, _ = grid.sample(la, lo)
    under = np.flatnonzero(hh - zt < 0)
    if under.size == 0:
        return  # the shifted line passes beside the crest: nothing to hit
    lo_s, hi_s = s[under[0] - 1], s[under[0]]
    for _ in range(60):
        mid = 0.5 * (lo_s + hi_s)
        la, lo, hh = O.geodetic((pa + mid * d)[None])
        lo_s, hi_s = (lo_s, mid) if hh[0] - grid.sample(la, lo)[0][0] < 0 else (mid, hi_s)
    first = 0.5 * (lo_s + hi_s)
    last = s[under[-1]]
    rays = eoloc.Rays(*pa, *d)
    for be in eoloc.available_backends():
        with eoloc.use_backend(be):
            f = eoloc.stop_at_dem(rays, dem)
        assert int(f.status) == 0 and abs(float(f.range_m) - first) < 0.005, (be, float(f.range_m), first, last)


def test_55_points_behind_the_camera_have_no_pixel():
    """ground_to_image: a point in front of the camera gets the oracle's pixel, the same point
    mirrored behind the camera gets none (NaN), every gimbal kind."""
    for kind in O.KINDS:
        sensor = O._sensor(eoloc, kind)
        c = {"lat": 40.0, "lon": -105.0, "h": 3000.0, "yaw": 20.0, "pitch": 2.0, "roll": -1.0, "g1": 200.0,
             "g2": -30.0, "g3": 5.0}
        pose = eoloc.Pose(40.0, -105.0, 3000.0, 20.0, 2.0, -1.0,
                          O._gimbal_tuple({k: np.atleast_1d(v) for k, v in c.items()}, kind))
        pose = eoloc.Pose(*(np.ravel(getattr(pose, f))[0] for f in ("lat_deg", "lon_deg", "h_m", "yaw_deg",
                                                                      "pitch_deg", "roll_deg")),
                          tuple(float(np.ravel(g)[0]) for g in pose.gimbal_deg))
        o, d, _ = O.rays(O.CAMERA, kind, 40.0, -105.0, 3000.0, 20.0, 2.0, -1.0, 200.0, -30.0, 5.0, np.array(400.0),
                         np.array(300.0), R_fixed=O.R_FIXED)
        front, back = o.reshape(3) + 800.0 * d.reshape(3), o.reshape(3) - 800.0 * d.reshape(3)
        u, v = sensor.ground_to_image(pose, np.stack([front, back]))
        assert abs(u[0] - 400.0) < 1e-6 and abs(v[0] - 300.0) < 1e-6
        assert np.isnan(u[1]) and np.isnan(v[1])


@pytest.mark.parametrize("backend", eoloc.available_backends())
def test_55_the_range_stop_takes_only_ranges_in_its_domain(backend):
    """M1's domain, as the README states it: 0 < R <= 10^7 m. A zero, negative, too long or NaN
    range is INVALID_INPUT (no point at the camera, none behind it); the smallest positive range
    and the longest are points at that distance along the ray (pyproj's ECEF of the answer)."""
    from eoloc.kernels.backend import run
    from eoloc.kernels.core import MAX_RANGE_M

    assert MAX_RANGE_M == 1e7
    e = eoloc.WGS84
    o = O.to_ecef(40.0, -105.0, 3000.0)
    d = np.array([0.6, -0.64, -0.48])
    rng = np.array([0.0, -1.0, -1e-9, np.nan, np.inf, 1e7 * (1 + 1e-12), 1e-3, 1.0, 1e7])
    with eoloc.use_backend(backend):
        lat, lon, h, t, status = run("stop_at_range", *o, *d, rng, e.a, e.b, e.e2, e.ep2)
    assert list(status[:6]) == [int(eoloc.Status.INVALID_INPUT)] * 6, status
    assert list(status[6:]) == [0, 0, 0]
    for k in (6, 7, 8):
        p = O.to_ecef(np.degrees(lat[k]), np.degrees(lon[k]), h[k])  # (the kernels answer in radians)
        assert np.linalg.norm(p - (o + rng[k] * d)) < 1e-6 * max(1.0, rng[k] / 1e6)
        assert t[k] == rng[k]


@pytest.mark.parametrize("backend", eoloc.available_backends())
def test_55_geodetic_kernels_against_proj(backend):
    """The geodetic <-> ECEF kernels against PROJ (EPSG:4979 <-> 4978) from the sea floor to 1000
    km up, both ways: within 1e-8 m (PROJ's own iteration converges to that; one Bowring step less
    is ~1e-4 m off at 100 km, an ECEF z without (1 - e^2) kilometres)."""
    import pyproj

    from eoloc.kernels.backend import run

    rng = np.random.default_rng(3)
    lat, lon = rng.uniform(-89.9, 89.9, 4000), rng.uniform(-180, 180, 4000)
    h = np.concatenate([rng.uniform(-1.1e4, 1e4, 2000), rng.uniform(1e4, 1e6, 2000)])
    e = eoloc.WGS84
    X, Y, Z = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon, lat, h)
    with eoloc.use_backend(backend):
        x, y, z = run("geodetic_to_ecef", np.radians(lat), np.radians(lon), h, e.a, e.e2)
        la, lo, hh = run("ecef_to_geodetic", X, Y, Z, e.a, e.b, e.e2, e.ep2)
    assert np.max(np.abs(np.stack([x - X, y - Y, z - Z]))) < 1e-6
    assert np.max(np.abs(np.degrees(la) - lat)) * 111_000 < 1e-8 * 1e3  # 1e-5 m: PROJ's own rounding
    assert np.max(np.abs(hh - h)) < 1e-5
    assert np.max(np.abs(np.degrees(lo) - lon)) < 1e-12


@settings(max_examples=60, deadline=None)
@given(st.floats(0.5, 3.0), st.floats(-0.3, 0.3), st.floats(-0.05, 0.05), st.floats(-0.01, 0.01),
       st.floats(-0.002, 0.002))
def test_55_fisheye_kernels_against_opencv(p1_scale, k1, k2, k3, k4):
    """Pix4D's fisheye (rho(theta), theta = 2/pi atan(r)) with an odd polynomial is OpenCV's
    fisheye model (theta_d = theta (1 + k1 theta^2 + ...), theta = atan(r)): p1 = pi/2, p3 = k1 (pi/2)^3,
    p5 ... (Pix4D's stops at p4, so k3 = k4 = 0 there). Both directions of eoloc's kernels against
    cv2.fisheye.distortPoints / undistortPoints on normalised points (K = I), with Pix4D's affine
    the identity; and a non-identity affine against applying it by hand."""
    import cv2

    from eoloc.kernels import core

    p1 = np.pi / 2
    dp = np.array([0.0, p1, 0.0, k1 * (np.pi / 2) ** 3, 0.0, 1.0, 0.0, 0.0, 1.0])
    rng = np.random.default_rng(int(abs(k1) * 1e6) % 1000)
    r = rng.uniform(0.0, 2.0 * p1_scale, 300)
    a = rng.uniform(0, 2 * np.pi, 300)
    x, y = r * np.cos(a), r * np.sin(a)
    xd, yd = core.distort_fisheye(x, y, dp)
    pts = np.stack([x, y], -1).reshape(-1, 1, 2)
    want = cv2.fisheye.distortPoints(np.stack([x / 1.0, y / 1.0], -1).reshape(-1, 1, 2).astype(np.float64),
                                     np.eye(3), np.array([k1, 0.0, 0.0, 0.0])).reshape(-1, 2)
    # cv2.fisheye.distortPoints takes undistorted *normalised* points (x, y) = (X/Z, Y/Z)
    np.testing.assert_allclose(np.stack([xd, yd], -1), want, atol=1e-9)
    back = cv2.fisheye.undistortPoints(want.reshape(-1, 1, 2), np.eye(3), np.array([k1, 0.0, 0.0, 0.0]),
                                       criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14))
    ux, uy = core.undistort_fisheye(xd, yd, dp)
    theta = np.arctan(r)
    ok = 1.0 + 3.0 * k1 * theta**2 > 0.2  # where the model is monotonic (d theta_d / d theta > 0): invertible
    np.testing.assert_allclose(np.stack([ux, uy], -1)[ok], pts.reshape(-1, 2)[ok], atol=1e-7)
    near = ok & (r <= 1.0)  # OpenCV's own inverse holds within 45 degrees (past it its iteration stops short)
    np.testing.assert_allclose(np.stack([ux, uy], -1)[near], back.reshape(-1, 2)[near], atol=1e-7)
    aff = dp.copy()
    aff[5:] = [1.02, 0.01, -0.015, 0.98]
    ax, ay = core.distort_fisheye(x, y, aff)
    np.testing.assert_allclose(np.stack([ax, ay], -1), np.stack([xd, yd], -1) @ np.array([[1.02, 0.01],
                                                                                         [-0.015, 0.98]]).T,
                               atol=1e-12)
