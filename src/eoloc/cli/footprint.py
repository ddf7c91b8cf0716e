"""`eoloc footprint`: the ground outline of every telemetry record's image."""

from __future__ import annotations

import click

from .common import ground, load_config, open_dem, progress
from .main import console, err_console, report_issues
from .options import (
    CONVENTIONS,
    config_option,
    flight_log_option,
    formats_option,
    grid_option,
    out_option,
    rule_options,
    with_flight_log,
)

FOOTPRINT_HELP = """Frame footprints: the ground outline of every telemetry record's image.

\b
eoloc footprint TELEMETRY.csv --config CAMERA.toml (--target-height H | --dem FILE...) [--edge-samples N]
  The image border (N points per side, clockwise from the top-left corner) is located on the
  ellipsoidal height H or on the DEM. Where the border sees sky or leaves the DEM, the outline is
  clipped at the grazing ray / the DEM edge (found by bisection), never extended to a made-up
  point. Writes footprints.geojson (polygons, RFC 7946, counter-clockwise) and footprints.csv
  (one row per frame: status, area, vertex counts, the image centre's fix) into --out;
  --format kml adds a KML of the outlines.
"""


@click.command(help=FOOTPRINT_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path())
@config_option(required=False, help_text="Camera/gimbal/installation TOML (see the README; optional for drone "
                                         "photos, which carry their camera).")
@rule_options(ground=True, role="Ground")
@click.option("--edge-samples", type=click.IntRange(1, 1000), default=16, show_default=True,
              help="Points per image side.")
@out_option("footprints.*")
@formats_option()
@grid_option()
@flight_log_option
def footprint(telemetry, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, edge_samples, out_dir,
              formats, grid, flight_log) -> None:
    telemetry = with_flight_log(telemetry, flight_log)
    from ..io.writers import write_layer
    from ..jobs.footprints import footprint_job

    rule = ground(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs))
    cfg = load_config(config_path) if config_path else None  # drone photos carry their camera
    with progress() as bar:
        task = bar.add_task("footprints", total=None)
        job = footprint_job(cfg, telemetry, rule, edge_samples=edge_samples,
                            progress=lambda k: bar.advance(task, k))
    report_issues(job.issues)
    written = write_layer(out_dir, "footprints", job.rows, formats, features=job.features, grid=grid)
    console.print(f"{len(job.prints)} footprints: " + ", ".join(f"{k} {v}" for k, v in job.status_counts().items())
                  + f"; {job.clipped} clipped at the horizon or the DEM edge")
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
