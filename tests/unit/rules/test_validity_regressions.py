"""Regression tests for the validity-domain defects found with the hostile-input oracle, one per
numbered case of the report, named after it. Every expected value here has an independent
derivation next to it: pyproj, closed-form geometry, or the other backend."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pyproj
import pytest
from click.testing import CliRunner

import eoloc
from eoloc import AzElGimbal, BrownConrady, Camera, Pose, Rays, SensorModel, Status
from eoloc.cli import main
from eoloc.rules.multiview import DEGENERATE_ANGLE_DEG, triangulate

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
CAM = Camera.from_hfov(60.0, 1280, 960)
SENSOR = SensorModel(CAM, AzElGimbal())


def _ecef(lat, lon, h):
    return np.array(ECEF.transform(lon, lat, h))


def _enu_axes(lat, lon):
    la, lo = np.radians(lat), np.radians(lon)
    east = np.array([-np.sin(lo), np.cos(lo), 0.0])
    north = np.array([-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)])
    up = np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    return east, north, up


def _rays(o, d):
    o, d = np.atleast_2d(o), np.atleast_2d(d)
    return Rays(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2])


# ---------------------------------------------------------------- 1. camera below the surface


def test_case1_cli_camera_below_target_surface_is_below_surface_not_the_antipode():
    r = CliRunner().invoke(main, ["locate", "--lat", "45", "--lon", "7", "--aircraft-height", "50", "--yaw", "0",
                                  "--pitch", "0", "--roll", "0", "--gimbal", "az-el", "--gimbal-angles", "0", "-90",
                                  "--target-height", "100", "--json"])
    assert r.exit_code == 3, r.output  # ran, located nothing (`eoloc --help`: exit status)
    out = json.loads(r.stdout)
    assert out["status"] == "BELOW_SURFACE" and out["lat"] is None and out["range"] is None


def test_case1_cli_file_mode_target_height_above_the_aircraft(tmp_path):
    # the demo flight is at 1110-1150 m: a 1500 m surface is above every record; at 1100 m every
    # fix is a real one, never one at the aircraft (range 0)
    heights = {float(r["time_s"]): float(r["h_m"]) for r in csv.DictReader(
        line for line in (DEMO / "telemetry.csv").open() if not line.startswith("#")) if r["h_m"].strip()}
    for height in ("1500", "1100"):
        out = tmp_path / height
        r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"),
                                      "--config", str(DEMO / "camera.toml"), "--target-height", height,
                                      "--out", str(out)])
        assert r.exit_code == (3 if height == "1500" else 0), r.output  # 3: nothing located, every row written
        rows = list(csv.DictReader((out / "fixes.csv").open()))
        if height == "1500":
            assert {row["status"] for row in rows} <= {"BELOW_SURFACE", "INVALID_INPUT", "NO_TELEMETRY"}
        for row in rows:
            h_cam = heights.get(float(row["time_s"]), np.nan)
            if row["status"] == "OK":
                assert h_cam > float(height) and float(row["range_m"]) > 10.0
            else:
                assert row["lat_deg"] in ("", "nan")
            if h_cam < float(height):  # (a record with a bad field elsewhere is INVALID_INPUT)
                assert row["status"] in ("BELOW_SURFACE", "INVALID_INPUT")
        gj = json.loads((out / "fixes.geojson").read_text())
        assert all(f["geometry"] is None for f in gj["features"] if f["properties"]["status"] != "OK")


def test_case1_cli_footprint_under_the_surface_has_no_polygon(tmp_path):
    out = tmp_path / "fp"
    r = CliRunner().invoke(main, ["footprint", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"),
                                  "--target-height", "1500", "--out", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "footprints.geojson").read_text())
    statuses = [f["properties"]["status"] for f in doc["features"]]
    assert "OK" not in statuses and statuses.count("BELOW_SURFACE") >= len(statuses) - 1
    assert all(f["geometry"] is None for f in doc["features"])


# ---------------------------------------------------------------- 2. far root


def test_case2_far_root_camera_a_millimetre_above_a_deep_surface(backend):
    # camera 1 mm above the -15 km surface at latitude 30, ray 0.5 deg below the horizon: the
    # crossing is 1 mm / sin(0.5 deg) = 0.1146 m ahead (flat to nanometres over that distance)
    f = eoloc.locate_ellipsoid(SENSOR, Pose(30.0, 7.0, -15_000.0 + 1e-3, 0, 0, 0, (0.0, -0.5)), -15_000.0)
    assert f.status == Status.OK
    assert f.range_m == pytest.approx(1e-3 / np.sin(np.radians(0.5)), rel=1e-4)
    assert abs(f.h_m + 15_000.0) < 1e-6


# ---------------------------------------------------------------- 3. near-tangent rays


@pytest.mark.parametrize("ht", [-15_000.0, 0.0, 3_000.0, 120_000.0, 1.0e6])
@pytest.mark.parametrize("depth", [0.02, 0.003, -0.003, -0.02])
def test_case3_near_tangent_rays_decided_to_the_contract(backend, ht, depth):
    # a ray tangent at Q to the surface ht - depth: it dips `depth` below ht (a hit) or stays
    # |depth| above it (a miss); built with pyproj, not eoloc
    lat, lon = 37.0, -122.0
    q = _ecef(lat, lon, ht - depth)
    east, north, _ = _enu_axes(lat, lon)
    d = (east + north) / np.sqrt(2.0)
    o = q - 150_000.0 * d
    f = eoloc.stop_at_ellipsoid(_rays(o, d), ht)
    if depth > 0:
        assert f.status[0] == Status.OK
        p = _ecef(float(f.lat_deg[0]), float(f.lon_deg[0]), float(f.h_m[0]))
        _, _, h = ECEF.transform(*p, direction="INVERSE")
        assert abs(f.h_m[0] - ht) < 1e-3
        assert f.range_m[0] < 150_000.0  # the near crossing, before the tangent point
        assert np.linalg.norm(p - (o + f.range_m[0] * d)) < 1e-4
    else:
        assert f.status[0] == Status.NO_INTERSECTION and np.isnan(f.lat_deg[0])


def test_case3_camera_at_or_just_below_the_surface_looking_down(backend):
    # at the surface or 1 mm under it: BELOW_SURFACE (the ray that comes back up ~22 km away is
    # not an answer); 1 mm above it: the crossing a few centimetres ahead
    for dh, expected in ((0.0, Status.BELOW_SURFACE), (-1e-3, Status.BELOW_SURFACE), (1e-3, Status.OK)):
        f = eoloc.locate_ellipsoid(SENSOR, Pose(45.0, 7.0, 2_000.0 + dh, 0, 0, 0, (0.0, -1.0)), 2_000.0)
        assert f.status == expected, dh
    assert f.range_m == pytest.approx(1e-3 / np.sin(np.radians(1.0)), rel=1e-3)


# ---------------------------------------------------------------- 4. overflow


def test_case4_overflowing_pixels_and_ranges_are_never_ok(backend):
    pose = Pose(45.0, 7.0, 3000.0, 0, 0, 0, (0.0, -45.0))
    for u in (1e154, 1e160, -1e200):
        f = eoloc.locate_range(SENSOR, pose, 1000.0, (u, 480.0))
        assert f.status == Status.OUT_OF_IMAGE and np.isnan(f.lat_deg)
    for rng in (1e155, 1e300, 1.0e7 * 1.01, 0.0, -5.0, np.inf):
        f = eoloc.locate_range(SENSOR, pose, rng)
        assert f.status == Status.INVALID_INPUT and np.isnan(f.lat_deg) and np.isnan(f.h_m), rng
    # a zero (underflowed) direction handed in as Rays: not a point at the camera
    o = _ecef(45.0, 7.0, 3000.0)
    for stop in (lambda r: eoloc.stop_at_range(r, 100.0), lambda r: eoloc.stop_at_ellipsoid(r, 0.0)):
        f = stop(_rays(o, np.zeros(3)))
        assert f.status[0] == Status.INVALID_INPUT and np.isnan(f.lat_deg[0])


# ---------------------------------------------------------------- 5. pixels outside the image


def test_case5_pixels_outside_the_image_on_every_rule(backend):
    lens = SensorModel(CAM.with_distortion(BrownConrady(k1=-0.1)), AzElGimbal())
    pose = Pose(40.0, -105.0, 3000.0, 0, 0, 0, (0.0, -60.0))
    dem = eoloc.DEM.constant(1500.0, (-106.0, 39.0, -104.0, 41.0))
    px = (np.array([2200.0, -1.5, 640.0, 639.5, -1.0]), np.array([480.0, 480.0, 961.0, 479.5, 960.0]))
    expected = [Status.OUT_OF_IMAGE, Status.OUT_OF_IMAGE, Status.OUT_OF_IMAGE, Status.OK, Status.OK]
    for sensor in (SENSOR, lens):
        for f in (eoloc.locate_range(sensor, pose, 3000.0, px), eoloc.locate_ellipsoid(sensor, pose, 1500.0, px),
                  eoloc.locate_dem(sensor, pose, dem, px), eoloc.locate_flat(sensor, pose, 3000.0, px)):
            assert f.status.tolist() == expected
            assert np.isnan(f.lat_deg[:3]).all()
    # with k1 = -0.1 the OK pixels map back to themselves (the old (2200, 480) came back as 2256.6)
    f = eoloc.locate_ellipsoid(lens, pose, 1500.0, px)
    u, v = lens.ground_to_image(pose, f.p_ecef()[3:])
    np.testing.assert_allclose(u, px[0][3:], atol=1e-6)


def test_case5_barrel_lens_past_its_fold_is_not_inverted():
    # r_d = r (1 + k1 r^2) peaks at r = 1/sqrt(3 |k1|): a strong barrel lens on a wide frame has
    # corner pixels beyond the fold's image, which no ideal ray reaches
    k1 = -0.45
    cam = Camera.from_hfov(100.0, 1280, 960).with_distortion(BrownConrady(k1=k1))
    r_peak = 1.0 / np.sqrt(3 * -k1)
    rd_max = r_peak * (1 + k1 * r_peak**2)
    u = cam.cx + cam.fx * np.array([0.5 * rd_max, 0.99 * rd_max, 1.01 * rd_max])
    v = np.full(3, cam.cy)
    xn, yn = cam.pixel_to_normalized(u, v)
    assert cam.outside(u, v, xn, yn).tolist() == [False, False, True]


# ---------------------------------------------------------------- 6. numba M4 grid edges


def _flat_tile():
    z = np.full((60, 60), 100.0)
    z[30, 2] = 300.0  # one high post in the west
    spacing = 100.0 / 111_195.0  # ~100 m posts
    return eoloc.DEM.from_array(z, lat0=40.0, lon0=-105.0, dlat=spacing, dlon=spacing), spacing


def test_case6_ray_from_beyond_the_east_edge_is_out_of_coverage_on_both_backends():
    dem, spacing = _flat_tile()
    lat = 40.0 + 30 * spacing
    lon = -105.0 + (59 + 3) * spacing  # three cells east of the east edge
    pose = Pose(lat, lon, 200.0, 270.0, 0, 0, (0.0, -3.0))
    for backend in eoloc.available_backends():
        with eoloc.use_backend(backend):
            assert eoloc.locate_dem(SENSOR, pose, dem).status == Status.OUT_OF_COVERAGE, backend
    # from every side, looking in: the same on both backends
    for yaw, dlat, dlon in ((90.0, 30, -3), (0.0, -3, 30), (180.0, 62, 30), (270.0, 30, 62)):
        p = Pose(40.0 + dlat * spacing, -105.0 + dlon * spacing, 200.0, yaw, 0, 0, (0.0, -3.0))
        got = set()
        for backend in eoloc.available_backends():
            with eoloc.use_backend(backend):
                got.add(int(eoloc.locate_dem(SENSOR, p, dem).status))
        assert got == {Status.OUT_OF_COVERAGE}, (yaw, got)


def test_case6_void_passed_above_the_highest_post_is_no_void():
    dem, spacing = _flat_tile()
    z = dem.grid.z.copy()
    z[30, 20:24] = np.nan  # a void in the ray's path, which passes over it above the 300 m post
    voided = eoloc.DEM.from_array(z, lat0=40.0, lon0=-105.0, dlat=spacing, dlon=spacing)
    lat = 40.0 + 30 * spacing
    pose = Pose(lat, -105.0 + 40 * spacing, 301.3 + 2000 * np.tan(np.radians(1.0)), 270.0, 0, 0, (0.0, -1.0))
    got = {}
    for backend in eoloc.available_backends():
        with eoloc.use_backend(backend):
            got[backend] = int(eoloc.locate_dem(SENSOR, pose, voided).status)
    # the ray clears the voids by 1-7 m, then meets the 300 m post in the west: a hit on both
    assert set(got.values()) == {Status.OK}, got


# ---------------------------------------------------------------- 7. triangulation, degenerate


def test_case7_near_parallel_rays_are_degenerate_with_no_point():
    target = _ecef(-0.14, 96.87, 100.0)
    east, north, up = _enu_axes(-0.14, 96.87)
    o = np.stack([target + 50_000.0 * up, target + 50_000.0 * up + 0.5 * east])
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = triangulate(_rays(o, d))
    assert r.max_angle_deg < DEGENERATE_ANGLE_DEG
    assert r.status == Status.DEGENERATE and not r.ok
    assert np.isnan([r.lat_deg, r.lon_deg, r.h_m]).all() and np.isnan(r.cov_enu).all()
    assert "parallel" in r.warning
    # a point behind a camera: also no point
    d2 = d.copy()
    d2[1] = -d2[1]
    o2 = np.stack([target + 5_000.0 * up, target + 5_000.0 * east])
    d2 = np.stack([(target - o2[0]) / 5_000.0, (o2[1] - target) / 5_000.0])
    r2 = triangulate(_rays(o2, d2))
    assert r2.status == Status.DEGENERATE and np.isnan(r2.lat_deg) and "behind" in r2.warning
    # a well-conditioned pair finds the target (pyproj) to a tenth of a millimetre
    o3 = np.stack([target + 5_000.0 * up + 3_000.0 * east, target + 4_000.0 * up - 2_000.0 * north])
    d3 = (target - o3) / np.linalg.norm(target - o3, axis=1, keepdims=True)
    r3 = triangulate(_rays(o3, d3))
    assert r3.ok and np.linalg.norm(_ecef(r3.lat_deg, r3.lon_deg, r3.h_m) - target) < 1e-4


def test_case1_the_old_height_flag_is_refused_naming_both_new_flags(tmp_path):
    # --height meant the aircraft in one mode and the target in the other: that is how a user
    # put the target surface above the aircraft. Every command now refuses it and names the fix.
    for args in (["locate", "--lat", "45", "--lon", "7", "--height", "50", "--gimbal-angles", "0", "-90",
                  "--target-height", "100"],
                 ["locate", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"), "--height", "600"],
                 ["footprint", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"), "--height", "600"],
                 ["track", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config",
                  str(DEMO / "camera.toml"), "--height", "600", "--out", str(tmp_path)]):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2, (args, r.output)
        assert "--target-height" in r.output and "--aircraft-height" in r.output and "Traceback" not in r.output


@pytest.mark.parametrize("rule", [eoloc.rules.AtHeight(100.0), eoloc.rules.AtRange(9_000.0),
                                  eoloc.rules.OnDEM(eoloc.open_dem(DEMO / "mountain" / "longs_peak_srtmgl3.tif"))],
                         ids=["height", "range", "dem"])
def test_a_pixel_outside_the_image_has_no_fix_with_an_uncertainty(rule):
    """Found through the HTTP API: with an error budget (first-order covariance, and the Monte
    Carlo chain it shares) a pixel outside the image came back OK with a point and a sigma. The
    statuses must be those of eoloc.locate for the same pixels, whatever the budget."""
    from eoloc.accuracy.budget import ErrorBudget
    from eoloc.accuracy.covariance import locate_with_covariance
    from eoloc.accuracy.montecarlo import chain_fixes

    pose = Pose(40.23, -105.66, 6500.0, 80.0, 1.0, -1.5, (10.0, -35.0, 0.0))
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-100, CAM.width + 100, 400), rng.uniform(-100, CAM.height + 100, 400)
    budget = ErrorBudget.from_mapping({"yaw_deg": {"normal": 0.05}, "pitch_deg": {"normal": 0.05},
                                       "u_px": {"normal": 0.5}, "h_m": {"normal": 5.0}})
    plain = rule.locate(SENSOR, pose, (u, v))
    outside = np.ravel(plain.status) == Status.OUT_OF_IMAGE
    assert 50 < outside.sum() < 300  # both kinds of pixel are there
    fixes, cov = locate_with_covariance(SENSOR, pose, budget, (u, v), rule)
    assert np.array_equal(np.ravel(fixes.status), np.ravel(plain.status))
    assert np.all(np.isnan(np.ravel(fixes.lat_deg)[outside]))
    # the Monte Carlo chain: 50 perturbed rows, each with the same statuses outside the image
    d = {"yaw_deg": rng.normal(0, 0.05, 50), "u_px": rng.normal(0, 0.5, 50)}
    mc = chain_fixes(SENSOR, pose, u, v, rule, d, 50)
    assert mc.status.shape == (50, 400)
    assert np.all(mc.status[:, outside] == Status.OUT_OF_IMAGE)
    assert not np.any(mc.status[:, ~outside] == Status.OUT_OF_IMAGE)
