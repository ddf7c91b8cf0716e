"""M4 ray ∩ DEM: synthetic scenes checked both ways, first hit, ridges, statuses, [Q]'s descent.

The scenes' truths are made without eoloc (issue 55): the aircraft placed and the gimbal aimed by
the oracle's geometry (pyproj ECEF, its own NED frame, the conventions of SPEC §2), the terrain's
heights and the dense first-hit scan by the oracle's bilinear grid over the DEM's posts (scipy)."""

from __future__ import annotations

import numpy as np
import oracle_lib as O
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from where import DATA

import eoloc
from eoloc import DEM, Camera, Pose, SensorModel, Status, geodesy, open_dem

DEMS = DATA / "dem"
GEOD = pyproj.Geod(ellps="WGS84")
SENSOR = SensorModel(Camera.from_hfov(20.0, 1000, 800))


@pytest.fixture(scope="module")
def srtm():
    return open_dem(DEMS / "srtm_ref.tif")


@pytest.fixture(scope="module")
def front_range():
    return open_dem(DEMS / "SRTMGL3_boulder_front_range.asc", assume_crs="EPSG:4326")


def analytic():
    """Smooth hills with a 400 m relief over 0.2 x 0.2 deg, posts every 1 arc-second (~30 m)."""
    def f(lat, lon):
        return 800.0 + 200.0 * np.sin(lat * 180.0) * np.cos(lon * 150.0) + 150.0 * np.cos((lat + lon) * 90.0)
    return DEM.from_function(f, (10.0, 45.0, 10.2, 45.2), 1.0 / 3600.0, source="analytic hills")


def ground(dem, lat, lon) -> np.ndarray:
    """The terrain's height under (lat, lon) by the oracle's bilinear grid over the DEM's posts."""
    g = dem.grid
    lat, lon = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float))
    return O.Grid(g.z, g.lat0, g.lon0, g.dlat, g.dlon).sample(lat.ravel(), lon.ravel())[0].reshape(lat.shape)


def aim(target_lat, target_lon, target_h, off_nadir_deg, azimuth_deg, height_above_m):
    """Aircraft pose (level, heading north) that looks at the target with the given off-nadir
    angle from the given direction, and the az-el gimbal angles that put it on the boresight: the
    aircraft set back along the line of sight in the target's NED frame, the angles the line of
    sight's azimuth from north and elevation from the horizontal in the aircraft's own NED frame (a
    level aircraft heading north has its body axes along NED; SPEC §2). The oracle's geometry only."""
    off = np.radians(off_nadir_deg)
    horiz = height_above_m * np.tan(off)
    az = np.radians(azimuth_deg)
    ned = np.stack([-horiz * np.cos(az), -horiz * np.sin(az), -np.full_like(horiz, height_above_m)], -1)
    t = O.to_ecef(target_lat, target_lon, target_h)
    p = t + np.einsum("...ij,...j->...i", O.r_ecef_ned(target_lat, target_lon), ned)
    lat, lon, h = O.geodetic(p)
    los = np.einsum("...ji,...j->...i", O.r_ecef_ned(lat, lon), t - p)  # north, east, down at the aircraft
    gaz = np.degrees(np.arctan2(los[..., 1], los[..., 0]))
    gel = np.degrees(np.arctan2(-los[..., 2], np.hypot(los[..., 0], los[..., 1])))
    return Pose(lat, lon, h, 0.0, 0.0, 0.0, (gaz, gel)), t


def first_crossing_brute_force(rays, dem, t_max, step=0.25):
    """Smallest t (to ``step``) where the ray is at or below the terrain, by dense sampling with
    the oracle's geodetic conversion and bilinear grid."""
    out = np.full(rays.shape, np.nan)
    for i in range(rays.shape[0]):
        t = np.arange(0.0, t_max[i] + step, step)
        p = rays.origin_ecef[i] + t[:, None] * rays.dir_ecef[i]
        lat, lon, h = O.geodetic(p)
        below = h - ground(dem, lat, lon) <= 0.0
        if below.any():
            out[i] = t[np.argmax(below)]
    return out


@pytest.mark.parametrize("terrain", ["srtm", "front_range", "analytic"])
def test_synthetic_scene_both_ways_0_to_80_deg(backend, terrain, request):
    dem = analytic() if terrain == "analytic" else request.getfixturevalue(terrain)
    w, s, e, n = dem.bounds
    rng = np.random.default_rng(7)
    k = 400
    lat = rng.uniform(s + 0.3 * (n - s), n - 0.3 * (n - s), k)
    lon = rng.uniform(w + 0.3 * (e - w), e - 0.3 * (e - w), k)
    h = ground(dem, lat, lon)
    off = np.linspace(0.0, 80.0, k)
    pose, t_ecef = aim(lat, lon, h, off, rng.uniform(0, 360, k), rng.uniform(800.0, 2500.0, k))
    u, v = SENSOR.ground_to_image(pose, t_ecef)
    np.testing.assert_allclose([u, v], [np.full(k, 499.5), np.full(k, 399.5)], atol=1e-6)  # truth on the boresight
    rays = SENSOR.rays(pose, (u, v))
    f = eoloc.stop_at_dem(rays, dem, sensor=SENSOR)
    assert (f.status == Status.OK).all()
    true_range = np.linalg.norm(t_ecef - rays.origin_ecef, axis=-1)
    _, _, d = GEOD.inv(f.lon_deg, f.lat_deg, lon, lat)
    visible = np.abs(f.range_m - true_range) < 0.5
    assert np.max(d[visible]) < 0.05  # located back to < 5 cm where the target is the first hit
    assert visible.mean() > 0.6
    # where it is not, something is in front: the march stopped earlier, on the terrain surface
    assert (f.range_m[~visible] < true_range[~visible]).all()
    np.testing.assert_array_less(np.abs(f.h_m - ground(dem, f.lat_deg, f.lon_deg)), 0.01)
    # and it is the FIRST hit: a dense scan finds nothing before it
    pick = np.flatnonzero(~visible)[:20].tolist() + np.flatnonzero(visible)[-10:].tolist()
    sub = eoloc.Rays(*(np.asarray(x)[pick] for x in (rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz)))
    brute = first_crossing_brute_force(sub, dem, f.range_m[pick] + 1.0)
    np.testing.assert_allclose(brute, f.range_m[pick], atol=0.3)


def _flat_with_wall(wall_h):
    """Flat ground at 100 m with a one-post-wide north-south wall of height wall_h at lon 10.05."""
    n = 181
    z = np.full((n, n), 100.0)
    z[:, 90] = wall_h  # lon0 + 90 * 1/1800 = 10.05
    return DEM.from_array(z, lat0=45.05, lon0=10.0, dlat=-1 / 1800, dlon=1 / 1800)


def test_ridge_in_front_of_the_target_is_found(backend):
    dem = _flat_with_wall(400.0)
    # target on the flat ground 118 m east of a one-post-wide wall, seen from the west 24 deg off
    # nadir: the ray crosses the wall's line about 265 m above the ground, 35 m below the crest
    pose, _ = aim(45.025, 10.0515, 100.0, 24.0, 90.0, 1000.0)
    f = eoloc.locate_dem(SENSOR, pose, dem)
    assert f.status == Status.OK
    assert 10.0494 < f.lon_deg < 10.0500 and f.h_m > 300.0  # on the wall's west face, not on the target
    assert abs(f.h_m - ground(dem, f.lat_deg, f.lon_deg)) < 0.01
    # [Q]'s descent samples the ray where it is at 400, 300, 200, 100, 0 m: both samples near the
    # wall fall beside its thin crest, so it lands on a LATER crossing, behind the wall
    desc = eoloc.locate_dem(SENSOR, pose, dem, method="descent", eps_h=100.0)
    assert desc.status == Status.OK and desc.lon_deg > 10.0515


def test_one_post_spike_is_not_tunnelled(backend):
    z = np.full((101, 101), 0.0)
    z[50, 50] = 300.0  # a single post: a bilinear pyramid two cells wide around (0.95, 2.05)
    dem = DEM.from_array(z, lat0=1.0, lon0=2.0, dlat=-0.001, dlon=0.001)
    # aim a nearly horizontal ray (88 deg off nadir) from the west at a point on the spike's EAST
    # flank: it has to stop on the west flank first
    pose, _ = aim(0.95, 2.0502, float(ground(dem, 0.95, 2.0502)), 88.0, 90.0, 100.0)
    f = eoloc.locate_dem(SENSOR, pose, dem)
    assert f.status == Status.OK and f.lon_deg < 2.05 and f.h_m > 200.0


def test_descent_agrees_with_march_within_its_step(backend, srtm):
    rng = np.random.default_rng(3)
    k = 60
    w, s, e, n = srtm.bounds
    lat = rng.uniform(s + 0.3, n - 0.3, k)
    lon = rng.uniform(w + 0.3, e - 0.3, k)
    pose, _ = aim(lat, lon, ground(srtm, lat, lon), rng.uniform(0, 30, k), rng.uniform(0, 360, k), 3000.0)
    march = eoloc.locate_dem(SENSOR, pose, srtm)
    for eps in (1.0, 5.0):
        desc = eoloc.locate_dem(SENSOR, pose, srtm, method="descent", eps_h=eps)
        same = np.abs(desc.range_m - march.range_m) < 200.0  # same crossing (not a later one)
        assert same.mean() > 0.9
        assert np.max(np.abs(desc.h_m[same] - march.h_m[same])) <= eps + 1e-6


def test_flat_terrain_M4_equals_M3_and_M2(backend):
    flat = DEM.constant(587.0, bounds=(112.6, 35.0, 112.8, 35.2))
    pose = Pose(35.125225, 112.680649, 1140.0, 290.5, 2.1, 0.0, (89.9, -35.0))
    u = np.array([386, 352, 511, 379, 854, 756, 685.0])
    v = np.array([304, 379, 277, 524, 463, 584, 706.0])
    cam = Camera.from_focal_mm(50.0, 5.5, 1024, 768)
    sensor = SensorModel(cam)
    m4 = eoloc.locate_dem(sensor, pose, flat, (u, v))
    m3 = eoloc.locate_ellipsoid(sensor, pose, 587.0, (u, v))
    np.testing.assert_allclose(m4.range_m, m3.range_m, atol=1e-4)
    main = eoloc.locate_dem(sensor, pose, flat)
    m2 = eoloc.locate_flat(sensor, pose, float(main.range_m), (u, v))
    _, _, d = GEOD.inv(m2.lon_deg, m2.lat_deg, m4.lon_deg, m4.lat_deg)
    assert np.max(d) < 0.01


def test_statuses_never_a_plausible_wrong_point(backend):
    dem = open_dem(DEMS / "n00_e006_3arc_v2.dt1")
    void_rc = np.argwhere(np.isnan(dem.grid.z))
    r, c = void_rc[len(void_rc) // 2]
    vlat, vlon = dem.grid.lat0 + r * dem.grid.dlat, dem.grid.lon0 + c * dem.grid.dlon
    # the highest cell whose four posts are all valid; the camera 100 m under its centre
    zz = dem.grid.z
    cell_max = np.fmax(np.fmax(zz[:-1, :-1], zz[1:, :-1]), np.fmax(zz[:-1, 1:], zz[1:, 1:]))
    cell_max[np.isnan(zz[:-1, :-1] + zz[1:, :-1] + zz[:-1, 1:] + zz[1:, 1:])] = -np.inf
    tr, tc = np.unravel_index(np.argmax(cell_max), cell_max.shape)
    top_lat, top_lon = dem.grid.lat0 + (tr + 0.5) * dem.grid.dlat, dem.grid.lon0 + (tc + 0.5) * dem.grid.dlon
    top_h = float(dem.height(top_lat, top_lon))
    cases = {
        # straight down onto a void
        "void": (Pose(vlat, vlon, 3000.0, 0, 0, 0, (0.0, -90.0)), Status.DEM_VOID),
        # near the east edge looking east, low: leaves the tile before meeting the sea (0 m)
        "edge": (Pose(0.5, 6.999, 2500.0, 90.0, 0, 0, (0.0, -5.0)), Status.OUT_OF_COVERAGE),
        # above the horizon
        "sky": (Pose(0.3, 6.6, 3000.0, 0, 0, 0, (0.0, 10.0)), Status.NO_INTERSECTION),
        # camera 100 m below the highest (non-void) post
        "underground": (Pose(top_lat, top_lon, top_h - 100.0, 0, 0, 0, (0.0, -90.0)), Status.BELOW_SURFACE),
        "nan": (Pose(np.nan, 6.6, 3000.0, 0, 0, 0, (0.0, -90.0)), Status.INVALID_INPUT),
    }
    for name, (pose, expected) in cases.items():
        f = eoloc.locate_dem(SENSOR, pose, dem)
        assert f.status == expected, name
        assert np.isnan(f.lat_deg) and np.isnan(f.h_m), name


def test_backends_agree_on_M4():
    if len(eoloc.available_backends()) < 2:
        pytest.skip("numba not installed: one backend only")
    dem = analytic()
    rng = np.random.default_rng(5)
    k = 500
    pose = Pose(45.1 + rng.uniform(-0.05, 0.05, k), 10.1 + rng.uniform(-0.05, 0.05, k), 2500.0,
                rng.uniform(0, 360, k), 0.0, 0.0, (rng.uniform(-180, 180, k), rng.uniform(-89, -12, k)))
    out = {}
    for b in ("numba", "numpy"):
        with eoloc.use_backend(b):
            out[b] = eoloc.locate_dem(SENSOR, pose, dem)
    np.testing.assert_array_equal(out["numba"].status, out["numpy"].status)
    ok = out["numba"].ok
    assert ok.mean() > 0.8
    diff = out["numba"].p_ecef()[ok] - out["numpy"].p_ecef()[ok]
    assert np.max(np.abs(diff)) < 1e-5


@settings(max_examples=300, deadline=None)
@given(lat=st.floats(-89.0, 89.0), lon=st.floats(-180.0, 180.0), h=st.floats(0.0, 20_000.0),
       az=st.floats(0.0, 360.0), off_nadir=st.floats(0.0, 89.0), s=st.floats(0.0, 1.0))
def test_march_knot_interpolation_is_exact_to_a_micrometre(lat, lon, h, az, off_nadir, s):
    """The numba march reads grid coordinates along a ray by cubic Hermite interpolation between
    exact knots (eoloc.kernels.march._knot). Checked against the exact conversion inside one knot
    interval, at any latitude, height and obliquity: < 1 µm in height and on the ground."""
    from eoloc.geodesy import WGS84
    from eoloc.kernels import march

    a, b, e2, ep2 = WGS84.constants
    o = np.array(eoloc.geodetic_to_ecef(lat, lon, h))
    el, az_r = np.radians(90.0 - off_nadir), np.radians(az)
    d = geodesy.ned_to_ecef(np.array([np.cos(el) * np.cos(az_r), np.cos(el) * np.sin(az_r), np.sin(el)]),
                            lat, lon, h) - o
    d /= np.linalg.norm(d)
    dlat = dlon = 1.0 / 3600.0
    args = (*o, *d)
    k0 = march._knot(*args, 0.0, a, b, e2, ep2, lat - 1.0, lon - 1.0, dlat, dlon, 3600.0)
    length = march._knot_length(k0[6])
    k1 = march._knot(*args, length, a, b, e2, ep2, lat - 1.0, lon - 1.0, dlat, dlon, k0[1])
    fr, fc, hh = march._hermite(s * length, 0.0, length, k0, k1)
    p = o + s * length * d
    lat_x, lon_x, h_x = eoloc.ecef_to_geodetic(*p)
    lon_i = lon - 1.0 + fc * dlon
    dlon_deg = (lon_i - lon_x + 180.0) % 360.0 - 180.0
    assert abs(hh - h_x) < 1e-6
    assert abs(lat - 1.0 + fr * dlat - lat_x) * 111_000.0 < 1e-6
    assert abs(dlon_deg) * 111_000.0 * np.cos(np.radians(lat_x)) < 1e-6


def test_march_split_over_threads_equals_one_thread(front_range):
    """A large batch is marched in chunks on several threads: the same fixes, bit for bit, as on
    one thread, every status included (rays off the grid, above the horizon, on the terrain)."""
    from eoloc import use_threads
    from eoloc.kernels.backend import MIN_CHUNK
    from eoloc.rules import OnDEM

    rng = np.random.default_rng(5)
    n = 6 * MIN_CHUNK + 123  # chunks of uneven length
    lat0, lon0 = front_range.bounds[1] + 0.1, front_range.bounds[0] + 0.1
    pose = Pose(lat0, lon0, 6000.0, 0.0, 0.0, 0.0, (rng.uniform(0, 360, n), rng.uniform(-90, 5, n)))
    rule = OnDEM(front_range)
    with use_threads(1):
        one = rule.locate(SENSOR, pose)
    with use_threads(3):
        many = rule.locate(SENSOR, pose)
    assert len(set(np.unique(one.status)) & {Status.OK, Status.OUT_OF_COVERAGE, Status.NO_INTERSECTION}) == 3
    for name in ("lat_deg", "lon_deg", "h_m", "range_m", "status"):
        assert np.array_equal(getattr(one, name), getattr(many, name), equal_nan=True), name


def test_numpy_kernels_split_over_threads_equal_one_thread():
    """The numpy backend runs a large batch's kernels in chunks on several threads: the same
    fixes, bit for bit, as on one thread (M3 and M1 with every pixel its own pose; rays above
    the horizon and pixels outside the image among them)."""
    from eoloc import use_threads
    from eoloc.kernels.backend import CHUNK, use_backend
    from eoloc.rules import AtHeight, AtRange

    rng = np.random.default_rng(6)
    n = 5 * CHUNK + 77
    pose = Pose(45.0 + rng.normal(0, 0.1, n), 7.0, rng.uniform(500, 9000, n), rng.uniform(0, 360, n),
                rng.normal(0, 3, n), rng.normal(0, 3, n), (rng.uniform(-180, 180, n), rng.uniform(-95, 10, n)))
    pixels = (rng.uniform(-50, 1100, n), rng.uniform(-50, 800, n))
    with use_backend("numpy"):
        for rule in (AtHeight(120.0), AtRange(rng.uniform(100, 20000, n))):
            with use_threads(1):
                one = rule.locate(SENSOR, pose, pixels)
            with use_threads(2):
                many = rule.locate(SENSOR, pose, pixels)
            seen = set(np.unique(one.status).tolist())
            assert {Status.OK, Status.OUT_OF_IMAGE} <= seen and (Status.NO_INTERSECTION in seen or
                                                                 isinstance(rule, AtRange))
            for name in ("lat_deg", "lon_deg", "h_m", "range_m", "status"):
                assert np.array_equal(getattr(one, name), getattr(many, name), equal_nan=True), name


def test_in_chunks_covers_every_element_once_and_passes_errors_on():
    from eoloc.kernels.backend import MIN_CHUNK, in_chunks, use_threads

    n = 5 * MIN_CHUNK + 7
    seen = np.zeros(n, np.int64)
    with use_threads(2):
        in_chunks(n, lambda i, j: seen.__setitem__(slice(i, j), seen[i:j] + 1))
    assert (seen == 1).all()

    def fails(i, j):
        if i > 0:
            raise ZeroDivisionError("a chunk failed")

    with use_threads(2), pytest.raises(ZeroDivisionError):
        in_chunks(n, fails)


def test_eoloc_threads_must_be_a_number(monkeypatch):
    import eoloc.errors
    from eoloc.kernels import backend

    monkeypatch.setenv("EOLOC_THREADS", "many")
    with pytest.raises(eoloc.errors.ConfigError, match="EOLOC_THREADS='many': give a whole number"):
        backend.default_threads()
    monkeypatch.setenv("EOLOC_THREADS", "1")
    assert backend.default_threads() == 1


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 300), m=st.integers(0, 40_000), seed=st.integers(0, 2**32 - 1),
       stray=st.sampled_from([0, -1, 1]))
def test_take_all_equals_numpy_indexing(n, m, seed, stray):
    """The threaded gather of several arrays at one index: numpy's fancy indexing, element for
    element (negative indices from the end), and IndexError where numpy raises one."""
    from eoloc import use_threads
    from eoloc.kernels.backend import take_all

    rng = np.random.default_rng(seed)
    arrays = [rng.normal(size=n), rng.integers(-5, 5, n), rng.random(n) < 0.5]
    index = rng.integers(-n, n, (m // 100, 100) if m >= 100 else m)
    if stray and index.size:  # one index just out of range, either side
        index.flat[rng.integers(index.size)] = n if stray > 0 else -n - 1
    with use_threads(2):
        if stray and index.size:
            with pytest.raises(IndexError):
                take_all(arrays, index)
            return
        got = take_all(arrays, index)
    for a, g in zip(arrays, got, strict=True):
        assert g.shape == index.shape and g.dtype == a.dtype and np.array_equal(g, a[index])


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 200), m=st.integers(0, 60_000), seed=st.integers(0, 2**32 - 1),
       backend=st.sampled_from(["numpy", "numba"]), stray=st.sampled_from([0, 0, -1, 1]))
def test_a_kernel_gathering_its_inputs_chunk_by_chunk_equals_one_on_gathered_arrays(n, m, seed, backend, stray):
    """run() with Gathered rotation components (values[index], taken chunk by chunk inside the
    kernel on numpy, made first on numba) gives, bit for bit, what it gives on the arrays numpy
    indexing makes; negative indices count from the end; an index out of range raises IndexError
    as numpy does; a Gathered whose shape is not the batch's broadcasts as its array would."""
    from eoloc import use_backend, use_threads
    from eoloc.kernels.backend import Gathered, run

    rng = np.random.default_rng(seed)
    R = [rng.normal(size=n) for _ in range(9)]
    index = rng.integers(-n, n, (m // 100, 100) if m >= 100 else m)
    xn, yn = rng.normal(size=index.shape), rng.normal(size=index.shape)
    if stray and index.size:  # one index just out of range, either side
        index.flat[rng.integers(index.size)] = n if stray > 0 else -n - 1
    with use_backend(backend), use_threads(2):
        if stray and index.size:
            with pytest.raises(IndexError):
                run("ray_direction", tuple(Gathered(c, index) for c in R), xn, yn)
            return
        got = run("ray_direction", tuple(Gathered(c, index) for c in R), xn, yn)
        want = run("ray_direction", tuple(c[index] for c in R), xn, yn)
        for g, w in zip(got, want, strict=True):
            assert g.shape == index.shape and np.array_equal(g, w, equal_nan=True)
        if index.ndim == 2:  # one row of pixels against every row of poses: broadcast
            got = run("ray_direction", tuple(Gathered(c, index[:, :1]) for c in R), xn, yn)
            want = run("ray_direction", tuple(c[index[:, :1]] for c in R), xn, yn)
            for g, w in zip(got, want, strict=True):
                assert np.array_equal(g, w, equal_nan=True)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_rays_of_many_targets_per_pose_equal_those_of_the_poses_taken_per_target(backend):
    """SensorModel.rays with pose_index (each pose's camera frame computed once, its rotation
    gathered inside the ray kernel) against the same rays from the poses indexed per target."""
    from eoloc import Camera, Pose, SensorModel, use_backend
    from eoloc.sensor import AzElGimbal

    rng = np.random.default_rng(11)
    n, m = 300, 50_000
    pose = Pose(45 + rng.normal(0, 0.1, n), 7 + rng.normal(0, 0.1, n), 3000 + rng.normal(0, 50, n),
                rng.uniform(0, 360, n), rng.normal(0, 3, n), rng.normal(0, 3, n),
                (rng.uniform(-180, 180, n), rng.uniform(-90, -20, n), np.zeros(n)))
    sensor = SensorModel(Camera(1024, 768, 1200.0, 1200.0, 512.0, 384.0), AzElGimbal(),
                         mount_misalignment_deg=(0.1, -0.2, 0.3))
    index = rng.integers(0, n, m)
    pixels = (rng.uniform(0, 1023, m), rng.uniform(0, 767, m))
    with use_backend(backend):
        got = sensor.rays(pose, pixels, pose_index=index)
        want = sensor.rays(pose.take(index), pixels)
    for k in ("ox", "oy", "oz", "dx", "dy", "dz", "invalid", "out_of_image"):
        assert np.array_equal(np.broadcast_to(getattr(got, k), (m,)), np.broadcast_to(getattr(want, k), (m,))), k


def test_camera_frame_take_keeps_shared_parts_and_gathers_the_rest():
    """CameraFrame.take: a frame of one pose (every part a scalar) is every target's frame; parts
    that are arrays are gathered as numpy indexing would, scalar parts kept as they are."""
    from eoloc.sensor.model import CameraFrame

    one = CameraFrame(tuple(np.float64(k) for k in range(9)), np.float64(1), np.float64(2), np.float64(3),
                      np.bool_(False))
    assert one.take(np.array([0, 0, 0])) is one
    rng = np.random.default_rng(5)
    R = tuple(rng.normal(size=50) if k % 2 else np.float64(k) for k in range(9))
    frame = CameraFrame(R, rng.normal(size=50), rng.normal(size=50), np.float64(7.0), rng.random(50) < 0.3)
    index = rng.integers(-50, 50, 20_000)
    got = frame.take(index)
    for a, g in zip((*frame.R, frame.ox, frame.oy, frame.oz, frame.invalid),
                    (*got.R, got.ox, got.oy, got.oz, got.invalid), strict=True):
        assert np.array_equal(g, a if np.ndim(a) == 0 else a[index])
    turning = CameraFrame(R, np.float64(1), np.float64(2), np.float64(3), np.bool_(False))  # only the attitude varies
    got = turning.take(index)
    assert (got.ox, got.oy, got.oz, got.invalid) == (turning.ox, turning.oy, turning.oz, turning.invalid)
    for a, g in zip(turning.R, got.R, strict=True):
        assert np.array_equal(g, a if np.ndim(a) == 0 else a[index])
