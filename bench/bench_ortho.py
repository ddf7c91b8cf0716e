"""Orthorectification of one 1280 x 720 frame onto ~1 M cells of real terrain (issue 22).

The frame: a 25° camera at 6 000 m looking west and 30° down at the SRTM terrain around Longs
Peak (the bundled demo DEM, ellipsoidal heights), rectified in UTM 13N at --gsd metres (2.25 m:
about 1 M cells, 63 % of them seen, terrain hiding some).

- eoloc: ``orthorectify`` (the footprint on the DEM and the output grid around it, the compiled
  forward projection, the z-buffer where the terrain folds over, bilinear sampling of 3 bands),
  one thread; also given the grid; and to a file (a Cloud-Optimised GeoTIFF: deflate, averaged
  overviews, the mask).
- orthority 0.7 (PyPI), one thread, the same frame, camera and DEM: its frame camera is fitted to
  eoloc's projection by OpenCV's PnP (orthority works in a flat world: the projected CRS plus
  height, so the fit absorbs the Earth's curvature and the UTM scale; its residual is printed).
  In memory, the same job as eoloc's core (the headline ratio): orthority's own steps of
  ``Ortho.process`` short of the file, i.e. ``_reproject_dem`` (GDAL's warp of the DEM onto the
  ortho grid) + ``_mask_dem`` (the camera's footprint on it) + ``camera.remap`` on that grid; the
  ``Ortho`` (which reads the DEM file) is made once, outside the timing. Also ``camera.remap``
  alone, given the cells' x, y and DEM height (the DEM already on the grid: a part of the job,
  shown because it favours orthority); end to end: ``Ortho.process`` (all of it and a deflate
  GeoTIFF with overviews) against eoloc's footprint, grid, rectification and COG.
  orthority has no occlusion test (its docs: "will be added in a future release").
- GDAL (rasterio ``reproject``) warping the frame by its ground-control-point grid: the usual
  no-terrain tool, as a reference.

Agreement: per cell that both see, the distance between eoloc's pixel and orthority's, taken
back to the ground through the local Jacobian of the cell -> pixel map, in output pixels
(cells at a fold of the image, where that map is singular, left out).

    python bench/bench_ortho.py [--gsd 2.25]
"""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np

import eoloc
from _common import best_time, row, script
from eoloc import AzElGimbal, Camera, OnDEM, Pose, SensorModel, open_dem
from eoloc.ground import rectify

DEM_PATH = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"
SENSOR = SensorModel(Camera.from_hfov(25.0, 1280, 720), AzElGimbal())
POSE = Pose(40.255, -105.55, 6000.0, 0.0, 0.0, 0.0, (-90.0, -30.0))


def scene(gsd_m: float):
    dem = open_dem(DEM_PATH)
    grid = rectify.output_grid(SENSOR, POSE, OnDEM(dem), gsd_m=gsd_m)
    img = np.random.default_rng(0).integers(0, 256, (3, 720, 1280), dtype=np.uint8)
    return dem, grid, img


def cell_world(grid: rectify.OutputGrid, dem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, y (the grid's CRS) and ellipsoidal height of every cell centre."""
    import pyproj

    rr, cc = np.meshgrid(np.arange(grid.shape[0]), np.arange(grid.shape[1]), indexing="ij")
    x, y = grid.centres(rr, cc)
    lon, lat = rectify.transformer(grid.crs, pyproj.CRS.from_epsg(4326)).transform(x, y)
    return x, y, dem.height(lat, lon)


def orthority_camera(px: rectify.FramePixels, x, y, z):
    """orthority's FrameCamera fitted to eoloc's projection of the seen cells (OpenCV SQPnP, then
    Levenberg-Marquardt) -> (camera, RMS residual in pixels)."""
    import cv2
    from orthority.camera import FrameCamera
    from orthority.param_io import _rotation_to_opk

    cam = SENSOR.camera
    sel = np.flatnonzero(px.valid.ravel())[:: max(int(px.valid.sum()) // 4000, 1)]
    origin = np.array([x.ravel()[sel].mean(), y.ravel()[sel].mean(), 0.0])
    obj = np.c_[x.ravel()[sel], y.ravel()[sel], z.ravel()[sel]] - origin
    img = np.c_[px.u_px.ravel()[sel], px.v_px.ravel()[sel]]
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    _, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_SQPNP)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, None, rvec, tvec)
    back, _ = cv2.projectPoints(obj, rvec, tvec, K, None)
    rms = float(np.sqrt(np.mean(np.sum((back.reshape(-1, 2) - img) ** 2, axis=1))))
    R_cam_world = cv2.Rodrigues(rvec)[0]
    centre = origin - R_cam_world.T @ tvec.ravel()
    R_patb = R_cam_world.T @ np.diag([1.0, -1.0, -1.0])  # orthority: PATB camera axes -> world
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fc = FrameCamera((cam.width, cam.height), (cam.fx, cam.fy), (cam.width, cam.height),
                         cx=(cam.cx - (cam.width - 1) / 2) / max(cam.width, cam.height),
                         cy=(cam.cy - (cam.height - 1) / 2) / max(cam.width, cam.height), xyz=tuple(centre),
                         opk=_rotation_to_opk(R_patb))
    return fc, rms


def agreement_px(px: rectify.FramePixels, uo: np.ndarray, vo: np.ndarray) -> np.ndarray:
    """|J^-1 (eoloc pixel - orthority pixel)| in output cells, J the cell -> pixel Jacobian (central
    differences of eoloc's map), where both see the cell and J is well conditioned."""
    u, v = px.u_px, px.v_px
    du_c, dv_c = np.gradient(u, axis=1), np.gradient(v, axis=1)
    du_r, dv_r = np.gradient(u, axis=0), np.gradient(v, axis=0)
    det = du_c * dv_r - du_r * dv_c
    eu, ev = u - uo, v - vo
    dc = (dv_r * eu - du_r * ev) / det
    dr = (du_c * ev - dv_c * eu) / det
    scale = np.sqrt(np.abs(det))  # pixels per cell, geometric mean
    use = px.valid & np.isfinite(uo) & np.isfinite(dc) & (scale > 0.2)
    return np.hypot(dc, dr)[use]


def main(gsd_m: float) -> list[str]:
    import cv2
    import rasterio
    from orthority import ortho as oty_ortho
    from rasterio.control import GroundControlPoint
    from rasterio.errors import NotGeoreferencedWarning
    from rasterio.warp import Resampling, reproject

    from eoloc.io.raster import write_dem, write_ortho

    cv2.setNumThreads(1)
    dem, grid, img = scene(gsd_m)
    cells = grid.shape[0] * grid.shape[1]
    px = rectify.frame_pixels(SENSOR, POSE, OnDEM(dem), grid)
    x, y, z = cell_world(grid, dem)
    fc, rms = orthority_camera(px, x, y, z)
    lines = []

    # -- core: one frame onto a given grid, in memory -------------------------------------------
    t_eg = best_time(lambda: rectify.orthorectify(img, SENSOR, POSE, OnDEM(dem), grid=grid), repeat=7)  # the grid given
    # footprint + grid too:
    t_e = best_time(lambda: rectify.orthorectify(img, SENSOR, POSE, OnDEM(dem), gsd_m=gsd_m), repeat=7)
    from orthority.enums import Interp

    t_o = best_time(lambda: fc.remap(img, x, y, z, nodata=0, interp=Interp.bilinear), repeat=3)

    # -- end to end: frame -> GeoTIFF ---------------------------------------------------------------
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = tmp / "frame.tif"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(src, "w", driver="GTiff", width=1280, height=720, count=3, dtype="uint8") as ds:
                ds.write(img)
        dem_tif = write_dem(dem, tmp / "dem.tif")

        def eoloc_file():
            write_ortho(rectify.orthorectify(img, SENSOR, POSE, OnDEM(dem), gsd_m=gsd_m), tmp / "eoloc.tif", threads=1)

        def orthority_file():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                o = oty_ortho.Ortho(src, dem_tif, fc, crs=grid.crs.to_wkt())
                o.process(tmp / "oty.tif", resolution=(gsd_m, gsd_m), interp="bilinear", dem_interp="bilinear",
                          compress="deflate", overwrite=True)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            oty = oty_ortho.Ortho(src, dem_tif, fc, crs=grid.crs.to_wkt())  # reads the DEM file: not timed
        oty_cells = []

        def orthority_in_memory():
            dem_a, tr = oty._reproject_dem(Interp.bilinear, (gsd_m, gsd_m))
            dem_a, tr = oty._mask_dem(dem_a, tr, Interp.bilinear)
            jj, ii = np.meshgrid(np.arange(dem_a.shape[1]) + 0.5, np.arange(dem_a.shape[0]) + 0.5)
            xx, yy = tr * (jj, ii)
            oty_cells.append(dem_a.size)
            return fc.remap(img, xx, yy, dem_a, nodata=0, interp=Interp.bilinear)

        cpu_count = oty_ortho.os.cpu_count
        oty_ortho.os.cpu_count = lambda: 1  # its tile pool and GDAL's warp threads: one, as eoloc
        try:
            t_om = best_time(orthority_in_memory, repeat=3)
            t_ef = best_time(eoloc_file, repeat=3)
            t_of = best_time(orthority_file, repeat=2)
        finally:
            oty_ortho.os.cpu_count = cpu_count
        with rasterio.open(tmp / "oty.tif") as ds:
            oty_file_cells = ds.width * ds.height
    lines.append(row(f"orthorectify 1280x720 on SRTM, {cells / 1e6:.2f} M cells, 3 bands, in memory (the DEM opened): "
                     "footprint, grid, rectification",
                     f"{t_e * 1e3:.1f} ms ({1 / t_e:.1f} fps, {cells / t_e / 1e6:.0f} M cells/s, +occlusion)",
                     f"orthority in memory {t_om * 1e3:.0f} ms ({1 / t_om:.1f} fps, {oty_cells[-1] / 1e6:.2f} M cells: "
                     "DEM warped onto the grid, footprint mask, remap; no occlusion)", t_om / t_e))
    lines.append(row("same, eoloc given its grid; orthority given the DEM's heights on that grid (its remap alone)",
                     f"{t_eg * 1e3:.1f} ms ({1 / t_eg:.1f} fps)",
                     f"orthority remap {t_o * 1e3:.0f} ms ({1 / t_o:.1f} fps)", t_o / t_eg))
    lines.append(row("same, end to end: footprint, grid, rectification, COG with overviews and mask (deflate)",
                     f"{t_ef * 1e3:.0f} ms ({1 / t_ef:.1f} fps)",
                     f"orthority Ortho.process {t_of * 1e3:.0f} ms ({1 / t_of:.1f} fps, "
                     f"{oty_file_cells / 1e6:.2f} M cells)",
                     t_of / t_ef))

    # -- GDAL's GCP warp, no terrain -----------------------------------------------------------------
    gg = rectify.ground_grid(SENSOR, POSE, OnDEM(dem), step_px=80)
    f = gg.fixes.flat()
    gcps = [GroundControlPoint(row=float(v), col=float(u), x=float(lo), y=float(la))
            for u, v, lo, la, ok in zip(gg.u_px.ravel(), gg.v_px.ravel(), f.lon_deg, f.lat_deg, f.ok, strict=True)
            if ok]
    dst = np.zeros((3, *grid.shape), np.uint8)

    def gdal():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            reproject(img, dst, gcps=gcps, src_crs="EPSG:4326", dst_crs=rasterio.crs.CRS.from_wkt(grid.crs.to_wkt()),
                      dst_transform=grid.transform, resampling=Resampling.bilinear, num_threads=1)

    t_g = best_time(gdal, repeat=3)
    lines.append(row("same grid, GDAL GCP polynomial warp (no terrain, no occlusion)", f"{t_eg * 1e3:.1f} ms",
                     f"rasterio reproject {t_g * 1e3:.0f} ms", t_g / t_eg))

    # -- agreement ------------------------------------------------------------------------------------
    ji = fc.world_to_pixel(np.stack([x.ravel(), y.ravel(), z.ravel()]))
    uo, vo = ji[0].reshape(grid.shape), ji[1].reshape(grid.shape)
    inside = (uo >= -0.5) & (uo <= 1279.5) & (vo >= -0.5) & (vo <= 719.5)
    d = agreement_px(px, np.where(inside, uo, np.nan), np.where(inside, vo, np.nan))
    lines.append(row("agreement with orthority where both see the ground (output px)",
                     f"median {np.median(d):.3f}, p99 {np.percentile(d, 99):.3f}, max {d.max():.3f} "
                     f"({d.size / 1e6:.2f} M cells)", f"camera fit residual {rms:.3f} px RMS", None))
    lines.append(f"\northo: eoloc {1 / t_e:.1f} fps, orthority {1 / t_om:.1f} fps, ratio {t_om / t_e:.1f}x, "
                 f"agreement {np.percentile(d, 99):.2f} px (in memory, the same job; file to file "
                 f"{1 / t_ef:.1f} vs {1 / t_of:.1f} fps, {t_of / t_ef:.1f}x)")
    return lines


if __name__ == "__main__":
    script(main, __doc__, flag="--gsd", kind=float, default=2.25, help_text="output cell size, m (default 2.25)")
