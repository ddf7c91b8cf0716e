"""`eoloc join`: telemetry + GCP sightings -> the observations table of report and compensate."""

from __future__ import annotations

from pathlib import Path

import click

from .common import load_config
from .main import err_console, fail, report_issues
from .options import out_option

JOIN_HELP = """Join telemetry and GCP sightings into one observations table.

\b
eoloc join TELEMETRY GCPS.csv [TELEMETRY GCPS.csv ...] [--flight NAME ...] [--config C] [--out DIR]
  The flight-test commands take the same data in two shapes: `eoloc calibrate` a telemetry file
  and a GCP file (time_s or frame, gcp_id, u_px, v_px, the point's surveyed lat_deg, lon_deg,
  h_m ellipsoidal); `eoloc report` and `eoloc compensate` one observations table, a row per
  sighting with its pose: flight, time_s, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg,
  gimbal1_deg, gimbal2_deg, sensor_roll_deg, u_px, v_px, gcp_id, gcp_lat_deg, gcp_lon_deg,
  gcp_h_m. This command turns the first into the second: each sighting paired with its
  telemetry record (same frame, else the nearest time within --time-tolerance), pose as eoloc
  reads it (heights ellipsoidal; telemetry of any source eoloc reads), unpaired sightings named
  (file:line). Several pairs of files make one table; the flight column is each telemetry
  file's name, or the names --flight gives (once per pair, in order).
  --config: the [telemetry] settings (an MSL geoid); the heading bias is not applied (the
  observations are the raw telemetry, as calibrate and report expect). Writes DIR/observations.csv.
"""


@click.command(help=JOIN_HELP)
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option("--flight", "flights", multiple=True, help="The flight id of each pair of files (repeat, in order).")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Its [telemetry] settings (msl_geoid) are used to read the telemetry.")
@click.option("--time-tolerance", type=click.FloatRange(0.0), default=0.02, show_default=True,
              help="Max |Δt| (s) pairing a sighting with a telemetry record.")
@out_option("observations.csv")
def join(files, flights, config_path, time_tolerance, out_dir) -> None:
    if len(files) % 2:
        fail(f"give the files in pairs, TELEMETRY GCPS.csv: {len(files)} file(s) given")
    from ..io.writers import write_layer
    from ..jobs.join import join_observations

    pairs = list(zip(files[::2], files[1::2], strict=True))
    cfg = load_config(config_path) if config_path else None
    job = join_observations(cfg, pairs, flights=flights, time_tolerance_s=time_tolerance)
    report_issues(job.issues)
    for name, (n, kept) in job.flights.items():
        err_console.print(f"{name}: {kept} of {n} sightings paired with their telemetry", highlight=False)
    written = write_layer(Path(out_dir), "observations", job.records, ["csv"])
    err_console.print("wrote " + ", ".join(str(p) for p in written))
