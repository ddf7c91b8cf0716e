"""`eoloc rectify`: orthorectify one frame to a GeoTIFF (M5)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.table import Table as RichTable

from .cli_common import (
    CONVENTIONS,
    dem_options,
    err_console,
    fail,
    load_config_or_fail,
    main,
    open_dem_or_fail,
    read_inputs,
    report_issues,
    target_height_option,
)
from .io.telemetry import telemetry_pose

RECTIFY_HELP = """Orthorectify one frame (visible or IR, any band count) onto the ellipsoid or a DEM
and write a georeferenced GeoTIFF in UTM, Gauss-Krüger or any CRS (M5).

\b
  eoloc rectify FRAME.png --config CAMERA.toml --telemetry TEL.csv --frame 120 --dem DEM.tif --crs utm

The pose is the telemetry record of --frame N (or the record nearest --time T). Every output
cell is projected into the frame (ground -> image) and resampled; cells the camera does not see,
or that terrain hides (--occlusion, DEM only), are nodata. Also written: the frame's footprint,
a ground grid (pixel -> lat/lon/h every --grid-step pixels), and the error of [P]'s shortcut
(reading lat/lon off the rectified image's bounds) against the rigorous ray.
"""


def _read_image(path: str) -> np.ndarray:
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as ds:
                return ds.read()
    except RasterioIOError as exc:
        fail(f"image {path!r} cannot be read (GDAL reads PNG, JPEG, TIFF, ...): {exc}")


@main.command(help=RECTIFY_HELP + CONVENTIONS)
@click.argument("image", type=click.Path(dir_okay=False, exists=True))
@click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
              help="Camera/gimbal/installation TOML.")
@click.option("--telemetry", required=True, type=click.Path(dir_okay=False), help="Telemetry CSV with the pose.")
@click.option("--frame", type=int, default=None, help="The telemetry record of this frame number.")
@click.option("--time", "time_s", type=float, default=None, help="Or: the record nearest this time (s).")
@target_height_option("Ground: this ellipsoidal height (m).")
@dem_options("Ground: DEM file(s); repeat for several tiles.")
@click.option("--crs", default="utm", show_default=True,
              help="Output grid: utm, gk6, gk3 (Gauss-Krüger zones on WGS-84), or EPSG:xxxx / a PROJ string.")
@click.option("--gsd", type=float, default=None, help="Output cell size (m); default: the native GSD at the centre.")
@click.option("--resampling", type=click.Choice(["nearest", "bilinear", "cubic"]), default="bilinear",
              show_default=True)
@click.option("--nodata", type=float, default=0, show_default=True, help="Value of cells with no image.")
@click.option("--occlusion/--no-occlusion", default=True, show_default=True,
              help="On a DEM: blank cells hidden by terrain.")
@click.option("--grid-step", type=float, default=32, show_default=True, help="Ground grid spacing (pixels).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Folder for ortho.tif, footprint.geojson, ground_grid.csv and rectify.json.")
def rectify(image, config_path, telemetry, frame, time_s, target_height, dem_paths, vertical, geoid, dem_crs, crs, gsd,
            resampling, nodata, occlusion, grid_step, out_dir) -> None:
    height = target_height
    from . import rectify as R
    from .footprint import footprints, write_footprints_geojson
    from .io.export import write_csv

    if (height is None) == (not dem_paths):
        fail("choose the ground: --target-height H (ellipsoidal metres) or --dem FILE")
    if (frame is None) == (time_s is None):
        fail("choose the frame's telemetry record: --frame N or --time T")
    cfg = load_config_or_fail(config_path)
    sensor = cfg.sensor()
    tel, _, issues = read_inputs(telemetry, None, cfg)
    report_issues(issues)
    if frame is not None:
        hit = np.flatnonzero(tel.columns["frame"] == frame)
        if hit.size == 0:
            fail(f"{telemetry}: no record of frame {frame}")
        k = int(hit[0])
    else:
        dt = np.abs(tel.columns["time_s"] - time_s)
        if not np.isfinite(dt).any():
            fail(f"{telemetry}: no time_s column to find --time in")
        k = int(np.nanargmin(dt))
        t0, t1 = float(np.nanmin(tel.columns["time_s"])), float(np.nanmax(tel.columns["time_s"]))
        if not t0 - 0.5 <= time_s <= t1 + 0.5:  # the nearest record would be a pose from another moment
            fail(f"--time {time_s:g} s is outside the telemetry of {telemetry} ({t0:g} to {t1:g} s): give a time "
                  "inside it (or --frame N)")
    pose = telemetry_pose(tel, k)
    surface = open_dem_or_fail(dem_paths, vertical, geoid, dem_crs) if dem_paths else height
    img = _read_image(image)
    with err_console.status("rectifying..."):
        try:
            ortho = R.orthorectify(img, sensor, pose, surface, crs=crs, gsd_m=gsd, resampling=resampling,
                                   nodata=nodata, occlusion=occlusion)
        except ValueError as exc:
            fail(f"{image}: {exc}")
        grid = R.ground_grid(sensor, pose, surface, step_px=grid_step)
        ok = grid.fixes.ok.ravel()
        px = np.c_[grid.u_px.ravel(), grid.v_px.ravel()][ok]
        short = R.shortcut_error(ortho, sensor, pose, surface, px).summary()
        fp = footprints(sensor, pose, surface)
    out = Path(out_dir)
    tif = ortho.write(out / "ortho.tif", tags={"EOLOC_SOURCE": Path(image).name, "EOLOC_TELEMETRY_LINE":
                                               int(tel.line[k]), "EOLOC_SURFACE": "DEM" if dem_paths else height})
    geo = write_footprints_geojson(out / "footprint.geojson", fp, [{"image": Path(image).name}])
    grid_csv = write_csv(out / "ground_grid.csv", grid.rows())
    report = {"image": str(image), "telemetry_line": int(tel.line[k]), "crs": ortho.crs.to_string(),
              "size": list(ortho.shape), "bands": int(ortho.data.shape[0]), "res": list(ortho.res),
              "valid_fraction": float(ortho.valid.mean()), "footprint_area_m2": fp[0].area_m2,
              "bounds_shortcut_error": short}
    js = out / "rectify.json"
    js.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    t = RichTable(title=f"{Path(image).name} rectified", show_header=False)
    t.add_row("output", f"{ortho.shape[1]} x {ortho.shape[0]} cells, {ortho.data.shape[0]} band(s), "
                        f"{ortho.data.dtype.name}")
    t.add_row("CRS", f"{ortho.crs.name} ({ortho.crs.to_string()})")
    t.add_row("cell", f"{ortho.res[0]:.6g} x {ortho.res[1]:.6g} {'deg' if ortho.crs.is_geographic else 'm'}")
    t.add_row("seen", f"{100 * ortho.valid.mean():.1f} % of the cells; footprint {fp[0].area_m2 / 1e6:.3f} km²")
    t.add_row("[P] bounds shortcut", f"median {short['exact_median_m']:.2f} m, max {short['exact_max_m']:.2f} m "
                                     f"(read at cell centres: median {short['cell_median_m']:.2f} m, max "
                                     f"{short['cell_max_m']:.2f} m) over {px.shape[0]} grid pixels")
    Console().print(t)
    Console().print(f"wrote [bold]{tif}[/], [bold]{geo}[/], [bold]{grid_csv}[/] and [bold]{js}[/]")
