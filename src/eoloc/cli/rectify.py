"""`eoloc rectify`: orthorectify one frame to a GeoTIFF (M5)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .common import ground, load_config, open_dem, working
from .main import console, err_console, report_issues
from .options import CONVENTIONS, config_option, flight_log_option, ortho_options, out_option, with_flight_log
from .render import titled_table

RECTIFY_HELP = """Orthorectify one frame (visible or IR, any band count) onto the ellipsoid or a DEM
and write a georeferenced GeoTIFF in UTM, Gauss-Krüger or any CRS (M5).

\b
  eoloc rectify FRAME.png --config CAMERA.toml --telemetry TEL.csv --frame 120 --dem DEM.tif --crs utm

The pose is the telemetry record of --frame N (or the record nearest --time T, which must lie
inside the telemetry). Every output cell is projected into the frame (ground -> image) and
resampled; cells the camera does not see, or that terrain hides (--occlusion, DEM only), are
nodata. Also written: the frame's footprint, a ground grid (pixel -> lat/lon/h every
--grid-step pixels), and the error of Peng et al.'s shortcut (reading lat/lon off the rectified
image's bounds) against the rigorous ray.
"""


@click.command(help=RECTIFY_HELP + CONVENTIONS)
@click.argument("image", type=click.Path(dir_okay=False, exists=True))
@config_option(required=False, help_text="Camera/gimbal/installation TOML (see the README; optional for drone "
                                         "photos, which carry their camera).")
@click.option("--telemetry", required=True, type=click.Path(),
              help="Telemetry with the pose: any source eoloc reads (CSV, KLV, DJI SRT, flight log, photos).")
@click.option("--frame", type=int, default=None, help="The telemetry record of this frame number.")
@click.option("--time", "time_s", type=float, default=None, help="Or: the record nearest this time (s).")
@ortho_options()
@click.option("--grid-step", type=click.FloatRange(0.0, min_open=True), default=32, show_default=True,
              help="Ground grid spacing (pixels).")
@out_option("ortho.tif, footprint.geojson, ground_grid.csv and rectify.json")
@flight_log_option
def rectify(image, config_path, telemetry, frame, time_s, rule_values, dem_paths, vertical, geoid, dem_crs, crs, gsd,
            resampling, nodata, occlusion, grid_step, out_dir, flight_log) -> None:
    telemetry = with_flight_log(telemetry, flight_log)
    from ..io.export import fix_records
    from ..io.raster import write_ortho
    from ..io.writers import write_layer
    from ..jobs.photo import ground_tag
    from ..jobs.rectify import rectify_job

    rule = ground(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs))
    cfg = load_config(config_path) if config_path else None  # drone photos carry their camera
    with working("rectifying..."):
        job = rectify_job(cfg, image, telemetry, rule, frame=frame, time_s=time_s, crs=crs, gsd_m=gsd,
                          resampling=resampling, nodata=nodata, occlusion=occlusion, grid_step_px=grid_step)
    report_issues(job.issues)
    ortho, fp, short = job.ortho, job.footprint, job.shortcut
    out = Path(out_dir)
    tif = write_ortho(ortho, out / "ortho.tif", tags={"EOLOC_SOURCE": Path(image).name,
                                               "EOLOC_TELEMETRY_LINE": job.telemetry_line,
                                               "EOLOC_SURFACE": ground_tag(rule)})
    from ..ground.footprint import footprint_features

    feats = footprint_features([fp], [{"image": Path(image).name}])
    written = [tif, *write_layer(out, "footprint", [f["properties"] for f in feats], ["geojson"], features=feats),
               *write_layer(out, "ground_grid", fix_records(job.grid.fixes, {"u_px": job.grid.u_px,
                                                                          "v_px": job.grid.v_px}), ["csv"])]
    report = {"image": str(image), "telemetry_line": job.telemetry_line, "crs": ortho.crs.to_string(),
              "size": list(ortho.shape), "bands": int(ortho.data.shape[0]), "res": list(ortho.res),
              "valid_fraction": float(ortho.valid.mean()), "footprint_area_m2": fp.area_m2,
              "bounds_shortcut_error": short}
    js = out / "rectify.json"
    js.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    written.append(js)
    t = titled_table(f"{Path(image).name} rectified", show_header=False)
    t.add_row("output", f"{ortho.shape[1]} x {ortho.shape[0]} cells, {ortho.data.shape[0]} band(s), "
                        f"{ortho.data.dtype.name}")
    t.add_row("CRS", f"{ortho.crs.name} ({ortho.crs.to_string()})")
    t.add_row("cell", f"{ortho.res[0]:.6g} x {ortho.res[1]:.6g} {'deg' if ortho.crs.is_geographic else 'm'}")
    t.add_row("seen", f"{100 * ortho.valid.mean():.1f} % of the cells; footprint {fp.area_m2 / 1e6:.3f} km²")
    t.add_row("bounds shortcut", f"median {short['exact_median_m']:.2f} m, max {short['exact_max_m']:.2f} m "
                                 f"(read at cell centres: median {short['cell_median_m']:.2f} m, max "
                                 f"{short['cell_max_m']:.2f} m) over {job.grid_pixels} grid pixels")
    console.print(t)
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
