"""The compiled orthorectification (eoloc.kernels.ortho, issue 22) against the numpy reference path and
against the rays of M4: the same pixel for every cell, the same cells seen except at a
silhouette, and the mirror-free fold test that limits the z-buffer to where terrain folds over."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from where import ROOT

import eoloc
from eoloc import DEM, AtHeight, AzElGimbal, Camera, OnDEM, Pose, SensorModel, geodesy, locate_dem, open_dem
from eoloc.accuracy.calflight import relief
from eoloc.ground import rectify
from eoloc.kernels import compiled
from eoloc.kernels.backend import use_backend
from eoloc.sensor.distortion import BrownConrady

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
CAM = Camera.from_hfov(30.0, 400, 300)
POSE = Pose(35.09, 112.7, 1900.0, 10.0, 1.0, -2.0, (5.0, -50.0))


@cache
def _hills() -> DEM:
    return DEM.from_function(relief((35.1, 112.7), sigma_m=40.0), (112.6, 35.0, 112.8, 35.2), 0.0003)


@cache
def _longs_peak() -> DEM:
    return open_dem(DEMO / "mountain" / "longs_peak_srtmgl3.tif")


def _both(sensor, pose, ground, grid, occlusion=True):
    fast = rectify.frame_pixels(sensor, pose, ground, grid, occlusion=occlusion)
    with use_backend("numpy"):
        ref = rectify.frame_pixels(sensor, pose, ground, grid, occlusion=occlusion)
    return fast, ref


@pytest.mark.parametrize("crs", ["utm", "EPSG:4326", "gk3"])
@pytest.mark.parametrize("lens", [None, BrownConrady(-0.12, 0.05, 0.001, -0.0005, 0.0)], ids=["pinhole", "brown"])
def test_every_cell_lands_on_the_reference_pixel(crs, lens):
    """u, v within 1e-3 px and range within 1 mm of the numpy path (pyproj, the DEM and
    SensorModel.ground_to_image per cell): the nodes' bilinear interpolation costs nothing
    measurable. Cells without ground agree too (NaN on both sides)."""
    sensor = SensorModel(CAM.with_distortion(lens), AzElGimbal())
    grid = rectify.output_grid(sensor, POSE, OnDEM(_hills()), crs=crs, gsd_m=3.0)
    fast, ref = _both(sensor, POSE, OnDEM(_hills()), grid, occlusion=False)
    both = np.isfinite(ref.u_px) & np.isfinite(fast.u_px)
    # the reference projects every cell in front of the camera; the kernel stops past the lens
    # model's field (2 % beyond the image's corners), so it may have fewer, never more
    assert not (np.isfinite(fast.u_px) & ~np.isfinite(ref.u_px)).any()
    inside = ref.valid
    assert both[inside].all()
    assert np.max(np.abs(fast.u_px[both] - ref.u_px[both])) < 1e-3
    assert np.max(np.abs(fast.v_px[both] - ref.v_px[both])) < 1e-3
    assert np.max(np.abs(fast.range_m[both] - ref.range_m[both])) < 1e-3
    np.testing.assert_array_equal(fast.valid, ref.valid)


def _silhouette(sensor, pose, dem, fast, rows, cols):
    """For each cell: do rays through pixels near its pixel both reach it and stop well in front
    of it (it lies on a silhouette, where seen / hidden is a sub-cell call)? Near: within one
    pixel plus the size of one output cell in the image (the z-buffer's mesh places a ridge's edge
    to within a cell)."""
    u, v, d = fast.u_px[rows, cols], fast.v_px[rows, cols], fast.range_m[rows, cols]
    size = np.zeros(rows.size)
    for dr, dc in [(0, 1), (1, 0), (0, -1), (-1, 0)]:
        r1 = np.clip(rows + dr, 0, fast.u_px.shape[0] - 1)
        c1 = np.clip(cols + dc, 0, fast.u_px.shape[1] - 1)
        size = np.fmax(size, np.hypot(fast.u_px[r1, c1] - u, fast.v_px[r1, c1] - v))
    radius = 1.0 + size
    reach = np.zeros(rows.size, bool)
    short = np.zeros(rows.size, bool)
    for k in range(17):
        a, s = 2 * np.pi * k / 16, (1.0 if k < 16 else 0.0)
        f = locate_dem(sensor, pose, dem, (u + s * radius * np.cos(a), v + s * radius * np.sin(a)))
        gap = d - np.where(f.ok, f.range_m, np.inf)
        reach |= gap < 10.0
        short |= gap > 10.0
    return reach & short


@pytest.mark.parametrize("scene", ["wall", "longs-peak"])
def test_hidden_cells_agree_with_the_rays_except_on_a_silhouette(scene):
    """The z-buffer and the reference (each cell's own M4 ray) call the same cells seen, except
    cells on a silhouette: there rays through pixels within a pixel and a cell both reach the
    cell and stop well in front of it. Those are under 1 % of the seen cells."""
    if scene == "wall":
        def wall(lat, lon):
            return 400.0 + 300.0 * np.exp(-(((np.asarray(lat) - 35.0995) / 0.0006) ** 2)) + 0.0 * np.asarray(lon)

        dem, pose, cam, gsd = DEM.from_function(wall, (112.6, 35.0, 112.8, 35.2), 0.0002), POSE, CAM, 5.0
    else:  # real SRTM terrain seen obliquely from 6 km, 1280 x 720 (bench/bench_ortho.py's frame)
        dem, pose, gsd = _longs_peak(), Pose(40.255, -105.55, 6000.0, 0.0, 0.0, 0.0, (-90.0, -30.0)), 6.0
        cam = Camera.from_hfov(25.0, 1280, 720)
    sensor = SensorModel(cam, AzElGimbal())
    grid = rectify.output_grid(sensor, pose, OnDEM(dem), gsd_m=gsd)
    fast, ref = _both(sensor, pose, OnDEM(dem), grid)
    no_occ = rectify.frame_pixels(sensor, pose, OnDEM(dem), grid, occlusion=False)
    hidden = no_occ.valid & ~fast.valid
    assert hidden.sum() > 1000  # the scene does hide terrain
    differ = fast.valid != ref.valid
    assert differ.sum() < 0.01 * ref.valid.sum(), (differ.sum(), ref.valid.sum())
    rows, cols = np.nonzero(differ)
    on_edge = _silhouette(sensor, pose, dem, fast, rows, cols)
    assert on_edge.all(), f"{(~on_edge).sum()} of {rows.size} differing cells are not on a silhouette"


def test_no_fold_means_no_hiding_and_the_camera_position_is_the_range_origin():
    """Gentle hills seen steeply do not fold over in the image: nothing is hidden and the
    z-buffer is skipped (same cells as without occlusion). The range is the distance from the
    camera (the lever arm's origin) to the cell's ground point."""
    sensor = SensorModel(CAM, AzElGimbal())
    steep = Pose(35.09, 112.7, 1900.0, 10.0, 1.0, -2.0, (5.0, -85.0))
    grid = rectify.output_grid(sensor, steep, OnDEM(_hills()), gsd_m=4.0)
    on = rectify.frame_pixels(sensor, steep, OnDEM(_hills()), grid)
    off = rectify.frame_pixels(sensor, steep, OnDEM(_hills()), grid, occlusion=False)
    tiles = np.zeros((19, 25), np.uint8)
    n_front, n_back = compiled.ortho_fold_tiles(on.u_px, on.v_px, rectify.FOLD_TILE_PX, 1.0, tiles)
    assert n_front > 10_000 and n_back == 0 and not tiles.any()  # no fold: the z-buffer pass is skipped
    np.testing.assert_array_equal(on.valid, off.valid)
    rows, cols = np.nonzero(on.valid)
    x, y = grid.centres(rows, cols)
    lon, lat = rectify.transformer(grid.crs, rectify.pyproj.CRS.from_epsg(4326)).transform(x, y)
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, _hills().height(lat, lon)), -1)
    cam = np.array(geodesy.geodetic_to_ecef(35.09, 112.7, 1900.0))
    np.testing.assert_allclose(on.range_m[rows, cols], np.linalg.norm(p - cam, axis=-1), atol=1e-3)


def _scipy(img, u, v, valid, order, nodata):
    """scipy's map_coordinates at (u, v), nodata where not valid, rounded to the dtype."""
    from scipy.ndimage import map_coordinates

    coords = np.stack([np.where(valid, v, 0.0), np.where(valid, u, 0.0)])
    out = np.stack([map_coordinates(b.astype(np.float64), coords, order=order, mode="nearest") for b in img])
    if np.issubdtype(img.dtype, np.integer):
        out = np.rint(out)
    return np.where(valid, out, nodata)


def test_resampling_matches_scipy():
    """Sampling against scipy's map_coordinates, called here directly: nearest and bilinear of
    float images through eoloc's compiled sampler to 1e-5; nearest of integer images to one count
    (rounding of .5); bilinear of 8- and 16-bit images is OpenCV's remap, which reads the float32
    maps: scipy at those positions, to one count (a sample 1/64 px off would be up to 4 and 1 000
    counts off on this noise, as OpenCV's int16 path is: int16 takes eoloc's sampler)."""
    sensor = SensorModel(CAM, AzElGimbal())
    rng = np.random.default_rng(4)
    grid = rectify.output_grid(sensor, POSE, OnDEM(_hills()), gsd_m=3.0)
    px = rectify.frame_pixels(sensor, POSE, OnDEM(_hills()), grid)
    for img in (rng.integers(0, 65535, (1, 300, 400), dtype=np.uint16),
                rng.integers(0, 255, (3, 300, 400), dtype=np.uint8), rng.random((2, 300, 400)).astype(np.float32),
                rng.integers(-30000, 30000, (5, 300, 400), dtype=np.int16)):
        for how in ("bilinear", "nearest"):
            fast = rectify.resample(img, px, resampling=how, nodata=7)
            opencv = how == "bilinear" and img.dtype.name in rectify.REMAP_DTYPES
            u, v = (px.map_x.astype(float), px.map_y.astype(float)) if opencv else (px.u_px, px.v_px)
            ref = _scipy(img, u, v, px.valid, 1 if how == "bilinear" else 0, 7)
            assert fast.dtype == img.dtype and fast.shape == ref.shape
            tol = 1e-5 if img.dtype == np.float32 else 1
            assert np.max(np.abs(fast.astype(float) - ref)) <= tol, (img.dtype, how)
            assert (fast[:, ~px.valid] == 7).all()


def test_orthority_agrees_where_both_see_the_ground():
    """bench/bench_ortho.py's frame (1280 x 720 over Longs Peak, ~1 M cells at 2.25 m): orthority's
    frame camera, fitted to eoloc's projection by OpenCV's PnP (residual < 0.1 px: the flat world
    it works in costs that little here), puts every cell both see within half an output pixel of
    eoloc's pixel for 99 % of cells (measured p99 0.36, median 0.05)."""
    import sys

    sys.path.insert(0, str(ROOT / "bench"))
    import bench_ortho as B

    dem, grid, _ = B.scene(2.25)
    px = rectify.frame_pixels(B.SENSOR, B.POSE, OnDEM(dem), grid)
    x, y, z = B.cell_world(grid, dem)
    fc, rms = B.orthority_camera(px, x, y, z)
    assert rms < 0.1
    ji = fc.world_to_pixel(np.stack([x.ravel(), y.ravel(), z.ravel()]))
    uo, vo = ji[0].reshape(grid.shape), ji[1].reshape(grid.shape)
    d = B.agreement_px(px, uo, vo)
    assert d.size > 500_000
    assert np.percentile(d, 99) < 0.5 and np.median(d) < 0.1


@pytest.mark.parametrize("surface", ["height", "hills"])
def test_every_cell_holds_the_value_an_independent_projection_reads(surface):
    """The orthorectified frame against a reference that shares nothing with eoloc's ortho path:
    each output cell's centre taken to WGS-84 by pyproj, its height the target height or scipy's
    bilinear interpolation of the DEM's posts, projected into the image by the oracle's rotations
    (scipy, pyproj ECEF) and a pinhole, and read off a ramp image (value 3 u + 7 v at pixel centre
    (u, v), so that bilinear resampling is exact). Every cell whose reference pixel lies inside the
    image is valid and within 0.02 of the reference (a 0.5 px shift of the pixel convention would
    be 1.5 to 3.5 off); no cell is valid whose reference pixel lies outside. Occlusion off: the
    terrain is gentle, nothing hides."""
    import coverage_lib as C
    import oracle_lib as O
    import pyproj
    from scipy.interpolate import RegularGridInterpolator

    sensor = SensorModel(CAM, AzElGimbal())
    ground = AtHeight(300.0) if surface == "height" else OnDEM(_hills())
    w, h = CAM.width, CAM.height
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    ramp = (3.0 * uu + 7.0 * vv).astype(np.float32)
    ortho = rectify.orthorectify(ramp, sensor, POSE, ground, crs="utm", gsd_m=3.0, nodata=-1.0, occlusion=False)
    rows, cols = np.mgrid[0:ortho.shape[0], 0:ortho.shape[1]]
    x, y = ortho.transform @ (cols + 0.5, rows + 0.5)
    lon, lat = pyproj.Transformer.from_crs(ortho.crs, "EPSG:4326", always_xy=True).transform(x, y)
    if surface == "height":
        hgt = np.full(lat.shape, 300.0)
    else:
        g = _hills().grid
        lats = g.lat0 + g.dlat * np.arange(g.z.shape[0])
        lons = g.lon0 + g.dlon * np.arange(g.z.shape[1])
        order = np.argsort(lats)
        posts = RegularGridInterpolator((lats[order], lons), g.z[order], bounds_error=False)
        hgt = posts(np.stack([lat, lon], -1))
    cam = O.Camera(w, h, CAM.fx, CAM.fy, CAM.cx, CAM.cy)
    az, el = POSE.gimbal_deg
    u, v = C.project(cam, POSE.lat_deg, POSE.lon_deg, POSE.h_m, POSE.yaw_deg, POSE.pitch_deg, POSE.roll_deg, az, el,
                     O.to_ecef(lat, lon, hgt))
    inside = np.isfinite(hgt) & (u >= 0.05) & (u <= w - 1.05) & (v >= 0.05) & (v <= h - 1.05)
    outside = ~np.isfinite(hgt) | (u < -0.55) | (u > w - 0.45) | (v < -0.55) | (v > h - 0.45)
    assert inside.sum() > 10_000
    assert ortho.valid[inside].all() and not ortho.valid[outside].any()
    err = np.abs(ortho.data[0][inside] - (3.0 * u + 7.0 * v)[inside])
    assert err.max() < 0.02, err.max()
