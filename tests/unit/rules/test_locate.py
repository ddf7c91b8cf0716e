"""Sensor chain and stop rules M1 (range) and M3 (ellipsoid) against references and edge values."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc import AtHeight, AtRange, AzElGimbal, Camera, FixedMount, Pose, RollPitchGimbal, SensorModel, Status, geodesy
from eoloc.rotation import R_ned_body

TO_GEO = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
CAM = Camera.from_focal_mm(50.0, 5.5, 1024, 768)
AZEL = SensorModel(CAM, AzElGimbal())
M_PER_DEG = 111_320.0


def horizontal_m(lat1, lon1, lat2, lon2):
    """Horizontal distance (m) between nearby points, by GeographicLib's geodesic (pyproj.Geod)."""
    _, _, d = pyproj.Geod(ellps="WGS84").inv(lon1, lat1, lon2, lat2)
    return np.asarray(d)


# ---------------------------------------------------------------- [S13] Table 2 -> Table 3


S13_POSE = Pose(lat_deg=42.0, lon_deg=125.0, h_m=10_000.0, yaw_deg=10.0, pitch_deg=5.0, roll_deg=-2.0,
                gimbal_deg=(45.0, -75.0))
S13_TARGET = (42.02058646, 125.03195512, 419.58)  # [S13] Table 3


def test_S13_table3_ranged_within_1cm(backend):
    f = eoloc.locate_range(AZEL, S13_POSE, 10_200.0)
    assert f.status == Status.OK
    assert horizontal_m(f.lat_deg, f.lon_deg, S13_TARGET[0], S13_TARGET[1]) < 0.01
    assert abs(f.h_m - S13_TARGET[2]) < 0.01


def test_S13_table3_single_call_path(backend):
    lat, lon, h, rng, status = AZEL.locate_one(42, 125, 10_000, 10, 5, -2, 45, -75, rule=AtRange(10_200))
    assert status == Status.OK and rng == 10_200
    assert horizontal_m(lat, lon, S13_TARGET[0], S13_TARGET[1]) < 0.01
    assert abs(h - S13_TARGET[2]) < 0.01


def test_S13_range_free_gives_the_same_point_at_its_height(backend):
    f = eoloc.locate_ellipsoid(AZEL, S13_POSE, height_m=419.5826441)
    assert horizontal_m(f.lat_deg, f.lon_deg, S13_TARGET[0], S13_TARGET[1]) < 0.01
    assert abs(f.range_m - 10_200.0) < 0.01


# ---------------------------------------------------------------- M3 against references


def _los_ned(sensor, pose, pixels=None):
    rays = sensor.rays(pose, pixels)
    R = geodesy.R_ecef_ned(pose.lat_deg, pose.lon_deg)
    return np.einsum("...ji,...j->...i", R, rays.dir_ecef)


def test_M3_against_pymap3d_lookAtSpheroid(backend):
    lookAtSpheroid = pytest.importorskip("pymap3d.los").lookAtSpheroid
    rng = np.random.default_rng(11)
    n = 300
    pose = Pose(rng.uniform(-80, 80, n), rng.uniform(-180, 180, n), rng.uniform(100, 20_000, n),
                rng.uniform(0, 360, n), rng.uniform(-10, 10, n), rng.uniform(-20, 20, n),
                (rng.uniform(-180, 180, n), rng.uniform(-89, -20, n)))
    f = eoloc.locate_ellipsoid(AZEL, pose, 0.0)
    los = _los_ned(AZEL, pose)
    az = np.degrees(np.arctan2(los[:, 1], los[:, 0]))
    tilt = np.degrees(np.arccos(los[:, 2]))
    lat, lon, d = lookAtSpheroid(pose.lat_deg, pose.lon_deg, pose.h_m, az, tilt)
    ok = f.ok
    assert ok.sum() > 250
    np.testing.assert_array_equal(np.isnan(lat), ~ok)  # both agree on which rays miss
    assert np.max(horizontal_m(f.lat_deg[ok], f.lon_deg[ok], lat[ok], lon[ok])) < 0.01
    assert np.max(np.abs(f.range_m[ok] - d[ok])) < 0.01


def test_M3_lands_on_the_height_surface_to_1mm(backend):
    rng = np.random.default_rng(12)
    n = 20_000
    pose = Pose(rng.uniform(-89, 89, n), rng.uniform(-180, 180, n), rng.uniform(9_000, 20_000, n),
                rng.uniform(0, 360, n), rng.uniform(-15, 15, n), rng.uniform(-30, 30, n),
                (rng.uniform(-180, 180, n), rng.uniform(-89, -5, n)))
    ht = rng.uniform(-400, 8_800, n)
    rays = AZEL.rays(pose)
    f = eoloc.stop_at_ellipsoid(rays, ht)
    ok = f.ok
    assert ok.mean() > 0.9
    p = rays.origin_ecef + f.range_m[..., None] * rays.dir_ecef
    _, _, h_proj = TO_GEO.transform(p[ok, 0], p[ok, 1], p[ok, 2])
    assert np.max(np.abs(h_proj - ht[ok])) < 1e-3  # PROJ's own inverse is good to 0.1 mm here
    assert np.max(np.abs(f.h_m[ok] - ht[ok])) < 1e-6
    # and the point is where the fix says it is
    x, y, z = eoloc.geodetic_to_ecef(f.lat_deg[ok], f.lon_deg[ok], f.h_m[ok])
    assert np.max(np.abs(np.stack([x, y, z], -1) - p[ok])) < 1e-6


def test_inflated_ellipsoid_alone_is_off_by_cm_at_10km():
    """Regression named after [Q]'s shortcut: (a + h, b + h) is not the surface of height h."""
    a, b = eoloc.WGS84.a, eoloc.WGS84.b
    ht = 10_000.0
    lat = np.radians(45.0)
    # a point on the inflated ellipsoid at geodetic latitude ~45 deg
    x, z = (a + ht) * np.cos(lat), (b + ht) * np.sin(lat)
    _, _, h = eoloc.ecef_to_geodetic(x, 0.0, z)
    assert 0.005 < abs(h - ht) < 0.02  # the 1.4 cm the refinement removes


# ---------------------------------------------------------------- round trips, all gimbals


SENSORS = {
    "az-el": SensorModel(CAM, AzElGimbal(), mount_misalignment_deg=(0.1, -0.2, 0.3),
                         boresight_misalignment_deg=(0.05, 0.02, -0.1), lever_arm_m=(0.5, -0.2, 0.3)),
    "roll-pitch": SensorModel(Camera.from_hfov(20.0, 4000, 3000), RollPitchGimbal(), lever_arm_m=(1.0, 0.0, 0.2)),
    "fixed": SensorModel(Camera.from_hfov(60.0, 640, 512),
                         FixedMount(quaternion=(0.9238795325112867, 0.0, 0.3826834323650898, 0.0))),
}
GIMBAL_ANGLES = {
    "az-el": lambda a, b: (a * 180.0, -20.0 - 70.0 * abs(b)),
    "roll-pitch": lambda a, b: (a * 60.0, b * 20.0),
    "fixed": lambda a, b: (a * 180.0,),
}


@settings(max_examples=150, deadline=None)
@given(
    kind=st.sampled_from(sorted(SENSORS)),
    lat=st.floats(-85, 85), lon=st.floats(-180, 180), h=st.floats(200, 15_000),
    yaw=st.floats(0, 360), pitch=st.floats(-10, 10), roll=st.floats(-15, 15),
    ga=st.floats(-1, 1), gb=st.floats(-1, 1), fu=st.floats(0, 1), fv=st.floats(0, 1),
    ht=st.floats(-100, 150),
)
def test_round_trip_pixel_ground_pixel(kind, lat, lon, h, yaw, pitch, roll, ga, gb, fu, fv, ht):
    sensor = SENSORS[kind]
    pose = Pose(lat, lon, h, yaw, pitch, roll, GIMBAL_ANGLES[kind](ga, gb))
    u = fu * (sensor.camera.width - 1)
    v = fv * (sensor.camera.height - 1)
    f = eoloc.locate_ellipsoid(sensor, pose, ht, (u, v))
    if f.status != Status.OK:
        # only a ray that truly misses may fail: its direction must not reach the surface
        assert f.status == Status.NO_INTERSECTION
        assert np.isnan(f.lat_deg)
        return
    u2, v2 = sensor.ground_to_image(pose, f.p_ecef())
    assert abs(u2 - u) < 1e-6 and abs(v2 - v) < 1e-6


# ---------------------------------------------------------------- gimbal conventions


def _boresight_body(sensor, angles):
    return sensor.R_body_cam(angles)[..., :, 2]


@pytest.mark.parametrize("az, el", [(0, 0), (90, 0), (30, -60), (-120, -10), (45, -90)])
def test_azel_boresight_formula(az, el):
    a, e = np.radians(az), np.radians(el)
    expected = [np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), -np.sin(e)]
    np.testing.assert_allclose(_boresight_body(AZEL, (az, el)), expected, atol=1e-15)


def test_azel_camera_axes_and_sensor_roll():
    R = AZEL.R_body_cam((0.0, 0.0))
    # looking along the nose: image right = right wing, image down = body down
    np.testing.assert_allclose(R, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)
    R90 = AZEL.R_body_cam((0.0, 0.0, 90.0))
    np.testing.assert_allclose(R90[:, 2], [1, 0, 0], atol=1e-15)  # roll keeps the boresight
    np.testing.assert_allclose(R90[:, 0], [0, 0, 1], atol=1e-15)  # image right turns to body down


@pytest.mark.parametrize("r, p", [(0, 0), (30, 0), (0, 20), (50, -2.6), (-40, 10)])
def test_rollpitch_boresight_formula_Q(r, p):
    sensor = SensorModel(CAM, RollPitchGimbal())
    tr, tp = np.radians(r), np.radians(p)
    expected = [np.sin(tp), -np.sin(tr) * np.cos(tp), np.cos(tr) * np.cos(tp)]
    np.testing.assert_allclose(_boresight_body(sensor, (r, p)), expected, atol=1e-15)


def test_rollpitch_positive_roll_looks_left_and_Q_pixel_layout():
    sensor = SensorModel(CAM, RollPitchGimbal())
    assert _boresight_body(sensor, (10.0, 0.0))[1] < 0  # left wing side
    R = sensor.R_body_cam((0.0, 0.0))
    M, N = CAM.height, CAM.width
    a, f = 1.0, CAM.fx  # pixel pitch 1 in pixel units
    i, j = 100, 900  # [Q]'s 1-based row and column
    los_S = -np.array([a * ((M + 1) / 2 - i), a * (j - (N + 1) / 2), -f])
    los_cam = CAM.pixel_to_los_cam(j - 1, i - 1)
    np.testing.assert_allclose(R @ los_cam, los_S / np.linalg.norm(los_S), atol=1e-15)


def test_fixed_mount_matrix_equals_quaternion_and_azel():
    R_azel = AZEL.R_body_cam((30.0, -50.0))
    via_matrix = SensorModel(CAM, FixedMount(matrix=R_azel.tolist())).R_body_cam(())
    from eoloc.rotation import quaternion_from_matrix
    via_quat = SensorModel(CAM, FixedMount(quaternion=tuple(quaternion_from_matrix(R_azel)))).R_body_cam(())
    np.testing.assert_allclose(via_matrix, R_azel, atol=1e-15)
    np.testing.assert_allclose(via_quat, R_azel, atol=1e-14)
    with pytest.raises(ValueError, match="proper 3x3 rotation"):
        FixedMount(matrix=[[1, 0, 0], [0, 1, 0], [0, 0, -1]])


def test_mount_yaw_misalignment_equals_heading_change(backend):
    tilted = SensorModel(CAM, AzElGimbal(), mount_misalignment_deg=(0.0, 0.0, 1.0))
    a = eoloc.locate_ellipsoid(tilted, Pose(30, 40, 3000, 100, 0, 0, (20, -40)))
    b = eoloc.locate_ellipsoid(AZEL, Pose(30, 40, 3000, 101, 0, 0, (20, -40)))
    assert horizontal_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg) < 1e-6


def test_boresight_misalignment_tilts_the_ray_by_its_angle():
    tilted = SensorModel(CAM, AzElGimbal(), boresight_misalignment_deg=(0.5, 0.0, 0.0))
    c = np.dot(tilted.R_body_cam((0, -90))[:, 2], AZEL.R_body_cam((0, -90))[:, 2])
    assert np.degrees(np.arccos(c)) == pytest.approx(0.5, abs=1e-9)


def test_lever_arm_moves_the_camera_in_body_axes(backend):
    nadir = Pose(10.0, 20.0, 1000.0, 90.0, 0.0, 0.0, (0.0, -90.0))  # heading east
    base = eoloc.locate_ellipsoid(AZEL, nadir, 0.0)
    arm = SensorModel(CAM, AzElGimbal(), lever_arm_m=(10.0, 0.0, 0.0))  # 10 m toward the nose
    moved = eoloc.locate_ellipsoid(arm, nadir, 0.0)
    ned = geodesy.ecef_to_ned(moved.p_ecef(), base.lat_deg, base.lon_deg, base.h_m)
    # 10 m east on the ellipsoid; "down" is the earth's curvature over 10 m, d^2 / 2R = 7.8 µm
    np.testing.assert_allclose(ned, [0.0, 10.0, 100.0 / (2 * 6_378_137.0)], atol=1e-7)


# ---------------------------------------------------------------- edge values


def test_nadir_from_level_flight(backend):
    f = eoloc.locate_ellipsoid(AZEL, Pose(35.0, 139.0, 1234.5, 77.0, 0, 0, (0.0, -90.0)), 0.0)
    assert f.lat_deg == pytest.approx(35.0, abs=1e-12)
    assert f.lon_deg == pytest.approx(139.0, abs=1e-12)
    assert f.range_m == pytest.approx(1234.5, abs=1e-6)


@pytest.mark.parametrize("lat", [90.0, -90.0])
def test_at_the_poles(backend, lat):
    f = eoloc.locate_ellipsoid(AZEL, Pose(lat, 0.0, 5000.0, 0, 0, 0, (0.0, -60.0)), 0.0)
    assert f.status == Status.OK
    # 30 deg off nadir from 5 km: about 2887 m away horizontally
    assert horizontal_m(lat, 0.0, f.lat_deg, f.lon_deg) == pytest.approx(5000 * np.tan(np.radians(30)), rel=2e-3)


def test_across_the_antimeridian(backend):
    # heading east from 179.99 E: the target lies across 180
    f = eoloc.locate_ellipsoid(AZEL, Pose(0.0, 179.999, 3000.0, 90.0, 0, 0, (0.0, -45.0)), 0.0)
    assert f.status == Status.OK and -179.98 < f.lon_deg < -179.97  # 3 km = 0.027 deg east
    ned = geodesy.geodetic_to_ned(f.lat_deg, f.lon_deg, f.h_m, 0.0, 179.999, 3000.0)
    assert ned[1] == pytest.approx(3000.0, rel=1e-3)


def test_89_degrees_off_nadir_still_hits(backend):
    # from 300 m the horizon dips 0.56 deg, so a ray 1 deg below horizontal still meets the ground,
    # farther than the flat-earth 300 / sin(1 deg) = 17.2 km because the surface curves away
    f = eoloc.locate_ellipsoid(AZEL, Pose(45.0, 7.0, 300.0, 0, 0, 0, (0.0, -1.0)), 0.0)
    assert f.status == Status.OK and abs(f.h_m) < 1e-6
    assert 300.0 / np.sin(np.radians(1.0)) < f.range_m < 40_000


def test_above_horizon_and_pointing_up_give_no_intersection(backend):
    # from 10 km the horizon dips 3.2 deg: -5 deg hits, -3 deg, horizontal and up miss
    pose = Pose(45.0, 7.0, 10_000.0, 0, 0, 0, (0.0, np.array([-5.0, -3.0, -1.0, 0.0, 30.0])))
    f = eoloc.locate_ellipsoid(AZEL, pose, 0.0)
    assert f.status.tolist() == [Status.OK] + [Status.NO_INTERSECTION] * 4
    assert np.isnan(f.lat_deg[1:]).all() and np.isnan(f.h_m[1:]).all() and np.isnan(f.range_m[1:]).all()
    # straight up from above the surface misses; from below it, see the next test
    assert eoloc.locate_ellipsoid(AZEL, Pose(45.0, 7.0, 10_000.0, 0, 0, 0, (0.0, 90.0)), 0.0).status == 1


def test_camera_on_or_below_the_surface_is_below_surface_never_a_point(backend):
    # M3's validity domain: the camera must be above the target surface. A camera under it
    # (looking up or down) or on it is BELOW_SURFACE with NaN coordinates, not a hit "from inside"
    for h_cam, el in ((400.0, 45.0), (400.0, -45.0), (500.0, -45.0), (10_000.0, 90.0)):
        ht = 12_000.0 if h_cam == 10_000.0 else 500.0
        f = eoloc.locate_ellipsoid(AZEL, Pose(0.0, 0.0, h_cam, 0, 0, 0, (0.0, el)), ht)
        assert f.status == Status.BELOW_SURFACE and np.isnan(f.lat_deg) and np.isnan(f.range_m)


def test_nan_and_bad_inputs_are_flagged_not_located(backend):
    pose = Pose(np.array([10.0, np.nan, 10.0, 95.0, 10.0]), 20.0, 3000.0, 0.0, 0.0, 0.0,
                (np.array([0.0, 0.0, np.nan, 0.0, 0.0]), -60.0))
    f = eoloc.locate_ellipsoid(AZEL, pose, 0.0, (np.array([1.0, 1.0, 1.0, 1.0, np.nan]), 2.0))
    assert f.status.tolist() == [Status.OK] + [Status.INVALID_INPUT] * 4
    assert np.isnan(f.lat_deg[1:]).all()
    r = eoloc.locate_range(AZEL, Pose(10.0, 20.0, 3000.0, 0, 0, 0, (0, -60)), np.array([100.0, -5.0, 0.0, np.nan]))
    assert r.status.tolist() == [Status.OK] + [Status.INVALID_INPUT] * 3
    lat, *_, status = AZEL.locate_one(95.0, 0, 1000, 0, 0, 0, 0, -90, rule=AtHeight(0.0))
    assert status == Status.INVALID_INPUT and np.isnan(lat)


def test_frames_by_targets_broadcast(backend):
    F, K = 4, 7
    pose = Pose(np.linspace(30, 31, F)[:, None], 10.0, 2000.0, 0.0, 0.0, 0.0, (0.0, -50.0))
    u = np.tile(np.linspace(0, 1023, K), (F, 1))
    f = eoloc.locate_ellipsoid(AZEL, pose, 0.0, (u, 383.5))
    assert f.lat_deg.shape == (F, K)
    for i in range(F):  # same as one frame at a time
        g = eoloc.locate_ellipsoid(AZEL, Pose(float(pose.lat_deg[i, 0]), 10.0, 2000.0, 0, 0, 0, (0.0, -50.0)),
                                   0.0, (u[i], 383.5))
        np.testing.assert_array_equal(f.lat_deg[i], g.lat_deg)


def test_single_call_agrees_with_array_path(backend):
    rng = np.random.default_rng(5)
    for _ in range(50):
        args = (rng.uniform(-60, 60), rng.uniform(-180, 180), rng.uniform(500, 9000), rng.uniform(0, 360),
                rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-180, 180), rng.uniform(-80, -30))
        u, v = rng.uniform(0, 1023), rng.uniform(0, 767)
        one = AZEL.locate_one(*args, u, v, rule=AtHeight(100.0))
        arr = eoloc.locate_ellipsoid(AZEL, Pose(*args[:6], args[6:]), 100.0, (u, v))
        np.testing.assert_allclose(one[:4], [arr.lat_deg, arr.lon_deg, arr.h_m, arr.range_m], rtol=0, atol=1e-9)
        assert one[4] == arr.status


def test_backends_agree_to_1e8_m():
    """numba and numpy differ only in the last bits of sin, cos and atan2. Along a range that stays
    below 1e-8 m; where a ray meets a surface, a last-bit shift of the camera (1e-9 m at 6 000 km
    from the centre) moves the hit by that shift / sin(grazing angle), which is the geometry's own
    conditioning, so there the bound is 1e-8 m x 1 / sin(grazing)."""
    if len(eoloc.available_backends()) < 2:
        pytest.skip("numba not installed: one backend only")
    rng = np.random.default_rng(8)
    n = 50_000
    pose = Pose(rng.uniform(-89, 89, n), rng.uniform(-180, 180, n), rng.uniform(100, 20_000, n),
                rng.uniform(0, 360, n), rng.uniform(-10, 10, n), rng.uniform(-30, 30, n),
                (rng.uniform(-180, 180, n), rng.uniform(-89, -10, n)))
    out = {}
    for b in ("numba", "numpy"):
        with eoloc.use_backend(b):
            out[b] = (eoloc.locate_ellipsoid(AZEL, pose, 250.0), eoloc.locate_range(AZEL, pose, 3000.0),
                      AZEL.rays(pose).dir_ecef)
    (ell_a, rng_a, dir_a), (ell_b, rng_b, _) = out["numba"], out["numpy"]
    lat, lon = np.radians(ell_b.lat_deg), np.radians(ell_b.lon_deg)
    up = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1)
    sin_grazing = np.abs(np.sum(up * dir_a, -1))  # cameras below 250 m meet the surface from below
    gaps = []
    for a, b, scale in ((ell_a, ell_b, 1.0 / sin_grazing), (rng_a, rng_b, 1.0)):
        np.testing.assert_array_equal(a.status, b.status)
        ok = a.ok
        d = np.max(np.abs(a.p_ecef() - b.p_ecef()), axis=-1)[ok]
        assert np.all(d <= 1e-8 * np.broadcast_to(scale, a.shape)[ok])
        gaps.append(d)
    assert np.quantile(gaps[0], 0.99) < 1e-8  # on the ellipsoid too, nearly all within 1e-8 m outright


def test_rays_are_unit_and_start_at_the_camera(backend):
    rays = AZEL.rays(S13_POSE, (np.array([0.0, 1023.0]), np.array([0.0, 767.0])))
    np.testing.assert_allclose(np.linalg.norm(rays.dir_ecef, axis=-1), 1.0, atol=1e-15)
    x, y, z = eoloc.geodetic_to_ecef(42.0, 125.0, 10_000.0)
    np.testing.assert_allclose(rays.origin_ecef, [[x, y, z]] * 2, atol=1e-9)


def test_los_ned_of_centre_pixel_matches_chain():
    # the chain written out with matrices: R_ned_body @ R_body_cam @ z
    los = _los_ned(AZEL, S13_POSE)
    expected = R_ned_body(10.0, 5.0, -2.0) @ AZEL.R_body_cam((45.0, -75.0)) @ [0, 0, 1]
    np.testing.assert_allclose(los, expected, atol=1e-15)


def test_azel_pointing_inverts_the_turret_S13():
    """Cue the turret to [S13]'s published target: its azimuth/elevation and range are the inputs
    of Table 2 (45, -75, 10 200 m) to the precision of the published coordinates (h to the cm:
    1e-6 rad at 10 km, 6e-5 deg)."""
    target = np.stack(eoloc.geodetic_to_ecef(42.02058646, 125.03195512, 419.58), -1)
    az, el, rng = eoloc.AzElGimbal.pointing(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, target)
    assert az == pytest.approx(45.0, abs=6e-5) and el == pytest.approx(-75.0, abs=6e-5)
    assert rng == pytest.approx(10_200.0, abs=0.01)


def test_the_range_from_the_records_is_a_rule_value_that_needs_the_records():
    """`--range` without a value is a rule like the others (RangeFromRecords, not a string):
    locate_tables gives it each target's range_m column, and the fixes equal AtRange with that
    column; used on its own, it refuses, naming the column."""
    from eoloc.errors import InputError
    from eoloc.io.table import Table
    from eoloc.jobs.tables import locate_tables
    from eoloc.rules import AtRange, RangeFromRecords

    sensor = SensorModel(Camera.from_hfov(30.0, 640, 480))
    n = 4
    cols = {"time_s": np.arange(n, dtype=float), "frame": np.full(n, np.nan), "lat_deg": np.full(n, 40.0),
            "lon_deg": np.full(n, -105.0), "h_m": np.full(n, 3000.0), "yaw_deg": np.zeros(n),
            "pitch_deg": np.zeros(n), "roll_deg": np.zeros(n), "gimbal1_deg": np.zeros(n),
            "gimbal2_deg": np.full(n, -60.0), "sensor_roll_deg": np.zeros(n),
            "range_m": np.array([1000.0, 1500.0, np.nan, 2500.0])}
    tel = Table("t.csv", cols, np.arange(2, n + 2))
    assert RangeFromRecords() == RangeFromRecords()
    got = locate_tables(sensor, tel, None, RangeFromRecords())
    want = AtRange(cols["range_m"]).locate(sensor, Pose(40.0, -105.0, 3000.0, 0.0, 0.0, 0.0, (0.0, -60.0)))
    np.testing.assert_array_equal(got.fixes.status, want.status)
    np.testing.assert_allclose(got.fixes.lat_deg, want.lat_deg, rtol=0, atol=1e-12)
    assert [i.line for i in got.issues] == [4] and "range_m" in got.issues[0].message
    with pytest.raises(InputError, match="range_m"):
        RangeFromRecords().locate(sensor, Pose(40.0, -105.0, 3000.0, 0.0, 0.0, 0.0, (0.0, -60.0)))
