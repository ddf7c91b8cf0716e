"""`eoloc triangulate`: multi-view triangulation, no range or terrain model."""

from __future__ import annotations

import sys

import click

from .common import load_config
from .main import NOTHING_LOCATED, console, err_console, report_issues, warn
from .options import (
    CONVENTIONS,
    config_option,
    flight_log_option,
    formats_option,
    grid_option,
    out_option,
    with_flight_log,
)
from .render import titled_table

TRIANGULATE_HELP = """Multi-view triangulation (M8): each target seen from two or more poses, located
without a range or a terrain model by intersecting its rays.

\b
eoloc triangulate TELEMETRY.csv DETECTIONS.csv --config CAMERA.toml [--ray-sigma-deg S]
  Groups the detections by target_id; writes triangulated.csv / .geojson with the point, its
  sigma east/north/up, the ray residuals, the widest angle between the rays and a warning when
  the baseline is too short for the range. When the rays scatter more than --ray-sigma-deg says
  (s0 > 1, from three rays on), the sigmas are scaled up by s0; they are never scaled down.
"""


@click.command(help=TRIANGULATE_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path())
@click.argument("detections", type=click.Path(dir_okay=False))
@config_option()
@click.option("--ray-sigma-deg", type=click.FloatRange(0.0, min_open=True), default=0.05, show_default=True,
              help="Angular 1-sigma of each ray (attitude + gimbal + pixel), degrees.")
@click.option("--min-angle", type=click.FloatRange(0.0), default=2.0, show_default=True,
              help="Warn below this angle (deg) between the rays.")
@click.option("--time-tolerance", type=click.FloatRange(0.0), default=0.02, show_default=True,
              help="Max |Δt| (s) pairing a detection with a telemetry record.")
@out_option("triangulated.*")
@formats_option()
@grid_option()
@flight_log_option
def triangulate(telemetry, detections, config_path, ray_sigma_deg, min_angle, time_tolerance, out_dir,
                formats, grid, flight_log) -> None:
    telemetry = with_flight_log(telemetry, flight_log)
    from ..io.writers import write_layer
    from ..jobs.sequence import triangulate_job

    job = triangulate_job(load_config(config_path), telemetry, detections, ray_sigma_deg=ray_sigma_deg,
                          min_angle_deg=min_angle, time_tolerance_s=time_tolerance)
    report_issues(job.issues)
    table = titled_table("triangulated targets (M8)")
    for c in ("target", "rays", "lat (°)", "lon (°)", "h (m)", "σ e/n/u (m)", "angle (°)"):
        table.add_column(c, justify="right")
    for r in job.rows:
        if r["status"] != "OK":
            table.add_row(r["target_id"], str(r["rays"]), "", "", "", "", r["status"])
            continue
        table.add_row(r["target_id"], str(r["rays"]), f"{r['lat_deg']:.7f}", f"{r['lon_deg']:.7f}", f"{r['h_m']:.1f}",
                      f"{r['sigma_e_m']:.1f}/{r['sigma_n_m']:.1f}/{r['sigma_u_m']:.1f}", f"{r['max_angle_deg']:.1f}")
    console.print(table)
    for r in job.rows:
        if r.get("warning"):
            warn(f"target {r['target_id']}: {r['warning']}")
    written = write_layer(out_dir, "triangulated", job.rows, formats, grid=grid)
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
    if job.rows and not any(r["status"] == "OK" for r in job.rows):
        warn("nothing was located: no target was triangulated (the status column says why for each)")
        sys.exit(NOTHING_LOCATED)
