"""Frame footprints: image border on the ground, clipped at the horizon and at the DEM edge."""

from __future__ import annotations

import json

import numpy as np
import pyproj
import pytest

import eoloc
from eoloc import DEM, AtHeight, Camera, OnDEM, Pose, SensorModel, Status, geodesy
from eoloc.ground.footprint import border_pixels, footprint_features, footprints
from eoloc.io.writers import write_layer

SENSOR = SensorModel(Camera.from_hfov(60.0, 640, 480))
GEOD = pyproj.Geod(ellps="WGS84")


def test_nadir_footprint_is_the_image_border_on_the_ground_both_ways():
    pose = Pose(40.0, 10.0, 3000.0, 30.0, 0.0, 0.0, (0.0, -90.0))
    fp = footprints(SENSOR, pose, AtHeight(200.0), edge_samples=8)[0]
    assert fp.status == Status.OK and len(fp) == 32 and not fp.clipped.any()
    np.testing.assert_allclose(fp.h_m, 200.0, atol=1e-6)
    # independent way back: project the vertices into the camera, they are the border pixels
    p = np.stack(eoloc.geodetic_to_ecef(fp.lat_deg, fp.lon_deg, fp.h_m), -1)
    u, v = SENSOR.ground_to_image(pose, p)
    np.testing.assert_allclose(np.column_stack([u, v]), border_pixels(SENSOR.camera, 8), atol=1e-6)
    # flat-Earth area 2h tan(hfov/2) x 2h tan(vfov/2) at 2800 m above the surface; curvature < 0.1 %
    hw = 2800.0 * np.tan(np.radians(30.0))
    hv = 2800.0 * 240.0 / SENSOR.camera.fy
    assert fp.area_m2 == pytest.approx(4 * hw * hv, rel=1e-3)


@pytest.mark.parametrize("elevation", [-5.0, 10.0])
def test_horizon_clips_the_outline_at_grazing_rays(elevation):
    """Looking at the horizon: the sky part of the border is replaced by the rays that graze the
    ellipsoid, found by bisection: they are tangent there (ray . up ~ 0) at the horizon distance."""
    pose = Pose(40.0, 10.0, 3000.0, 0.0, 0.0, 0.0, (0.0, elevation))
    fp = footprints(SENSOR, pose, AtHeight(0.0))[0]
    assert fp.status == Status.OK and fp.clipped.any() and (~fp.clipped).any()
    assert set(fp.clip_status[fp.clipped].tolist()) == {Status.NO_INTERSECTION}
    k = fp.clipped
    cam = np.array(eoloc.geodetic_to_ecef(40.0, 10.0, 3000.0))
    p = np.stack(eoloc.geodetic_to_ecef(fp.lat_deg[k], fp.lon_deg[k], fp.h_m[k]), -1)
    ray = (p - cam) / np.linalg.norm(p - cam, axis=-1, keepdims=True)
    up = -geodesy.R_ecef_ned(fp.lat_deg[k], fp.lon_deg[k])[..., :, 2]
    assert np.max(np.abs((ray * up).sum(-1))) < 2e-4  # grazing: 0.01 deg from tangent
    _, _, dist = GEOD.inv(np.full(k.sum(), 10.0), np.full(k.sum(), 40.0), fp.lon_deg[k], fp.lat_deg[k])
    r_sphere = np.sqrt(2 * 6_371_000.0 * 3000.0)
    assert np.all(np.abs(dist - r_sphere) < 0.01 * r_sphere)
    np.testing.assert_allclose(fp.h_m, 0.0, atol=1e-6)
    # unclipped vertices are the border rays themselves
    pu = np.stack(eoloc.geodetic_to_ecef(fp.lat_deg[~k], fp.lon_deg[~k], fp.h_m[~k]), -1)
    u, v = SENSOR.ground_to_image(pose, pu)
    np.testing.assert_allclose(np.column_stack([u, v]), np.column_stack([fp.u_px[~k], fp.v_px[~k]]), atol=1e-6)


def test_nothing_in_view_and_bad_pose_get_a_status_not_a_polygon():
    up = footprints(SENSOR, Pose(40.0, 10.0, 3000.0, 0.0, 0.0, 0.0, (0.0, 60.0)), AtHeight(0.0))[0]
    assert up.status == Status.NO_INTERSECTION and len(up) == 0 and up.geojson_geometry() is None
    bad = footprints(SENSOR, Pose(np.nan, 10.0, 3000.0, 0.0, 0.0, 0.0, (0.0, -60.0)), AtHeight(0.0))[0]
    assert bad.status == Status.INVALID_INPUT and len(bad) == 0


def test_dem_footprint_is_clipped_at_the_dem_edge(backend):
    def hills(lat, lon):
        return 500.0 + 80.0 * np.sin(lat * 300.0) * np.cos(lon * 250.0)
    dem = DEM.from_function(hills, (7.0, 45.0, 7.05, 45.05), 1.0 / 3600.0, source="hills")  # W, S, E, N
    # 2 km over the middle of a 5.6 x 3.9 km DEM, 35 deg off nadir: the far edge is off the DEM
    pose = Pose(45.025, 7.025, 2500.0, 0.0, 0.0, 0.0, (0.0, -55.0))
    fp = footprints(SENSOR, pose, OnDEM(dem), edge_samples=8)[0]
    assert fp.status == Status.OK and fp.clipped.any() and (~fp.clipped).any()
    assert Status.OUT_OF_COVERAGE in set(fp.clip_status[fp.clipped].tolist())
    # every vertex is on the DEM surface, inside the DEM, and the clipped ones at its edge (< 1 cell)
    np.testing.assert_allclose(fp.h_m, dem.height(fp.lat_deg, fp.lon_deg), atol=0.01)
    lon0, lat0, lon1, lat1 = dem.bounds
    edge = np.minimum.reduce([fp.lat_deg - lat0, lat1 - fp.lat_deg, (fp.lon_deg - lon0), lon1 - fp.lon_deg])
    assert np.all(edge >= -1e-9)
    out = fp.clip_status == Status.OUT_OF_COVERAGE
    assert np.all(edge[out] < 1.0 / 3600.0)


def test_several_frames_and_geojson(tmp_path):
    pose = Pose(np.array([40.0, 40.01, np.nan]), 10.0, 3000.0, 0.0, 0.0, 0.0, (0.0, np.array([-90.0, -2.0, -90.0])))
    prints = footprints(SENSOR, pose, AtHeight(0.0), edge_samples=4)
    assert [p.status for p in prints] == [Status.OK, Status.OK, Status.INVALID_INPUT]
    feats = footprint_features(prints, [{"frame": k} for k in range(3)])
    (path,) = write_layer(tmp_path, "fp", [f["properties"] for f in feats], ["geojson"], features=feats)
    doc = json.loads(path.read_text())
    f0, f1, f2 = doc["features"]
    ring = np.array(f0["geometry"]["coordinates"][0])
    assert np.array_equal(ring[0], ring[-1]) and ring.shape == (17, 3)
    # RFC 7946: exterior rings counter-clockwise (pyproj's signed area is positive)
    area, _ = GEOD.polygon_area_perimeter(ring[:-1, 0], ring[:-1, 1])
    assert area > 0 and f0["properties"]["area_m2"] == pytest.approx(area, rel=1e-6)
    assert f1["properties"]["clipped_by"] == ["NO_INTERSECTION"] and f1["properties"]["frame"] == 1
    assert f2["geometry"] is None and f2["properties"]["status"] == "INVALID_INPUT"
