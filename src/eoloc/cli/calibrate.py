"""`eoloc calibrate`: boresight / mounting calibration from ground control points."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .common import load_config, working
from .main import console, err_console, report_issues, warn
from .options import config_option, out_option
from .render import titled_table

CALIBRATE_HELP = """Boresight / mounting calibration from ground control points seen in frames.

\b
eoloc calibrate TELEMETRY.csv GCPS.csv --config CAMERA.toml [--estimate mount,heading,time] [--write]
  GCPS.csv columns: time_s or frame, gcp_id, u_px, v_px (where the GCP is in that image), and the
  GCP's surveyed lat_deg, lon_deg, h_m (ellipsoidal). Each observation's pose is the matching
  telemetry record, or interpolated (--interpolate; always when the time offset is estimated).
  --estimate: any of mount (3 angles, gimbal base vs INS), boresight (3 angles, optical axis vs
  gimbal), heading (INS heading bias), time (telemetry minus video clock). Least squares on the
  pixel residuals; prints the values with their sigma, correlations that the geometry cannot
  separate, parameters it cannot determine at all (sigma empty, never written), outliers, and the
  residuals before/after in pixels and metres on the ground.
  --write puts the result into the config file ([installation] / [telemetry]), comments kept;
  every later eoloc command then uses it.
"""


@click.command(help=CALIBRATE_HELP)
@click.argument("telemetry", type=click.Path())
@click.argument("gcps", type=click.Path(dir_okay=False))
@config_option(help_text="Camera/gimbal/installation TOML (the starting values).")
@click.option("--estimate", default="mount", show_default=True,
              help="Comma-separated: mount, boresight, heading, time.")
@click.option("--pixel-sigma", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True,
              help="1-sigma of a GCP's pixel position (px).")
@click.option("--robust", is_flag=True, help="Soft-L1 loss: misidentified GCPs pull less.")
@click.option("--interpolate", is_flag=True, help="Interpolate the pose to each observation's time.")
@click.option("--max-gap", type=click.FloatRange(0.0, min_open=True), default=0.5, show_default=True,
              help="Longest telemetry gap (s) to bridge.")
@click.option("--time-tolerance", type=click.FloatRange(0.0), default=0.02, show_default=True,
              help="Max |Δt| (s) pairing an observation with a record (without --interpolate).")
@click.option("--write", "write_config", is_flag=True, help="Write the result into the config file.")
@out_option("calibration.json and gcp_residuals.csv")
def calibrate(telemetry, gcps, config_path, estimate, pixel_sigma, robust, interpolate, max_gap, time_tolerance,
              write_config, out_dir) -> None:
    from ..io.writers import write_layer
    from ..jobs.calibrate import calibrate_job, write_back

    groups = tuple(e.strip() for e in estimate.split(",") if e.strip())
    cfg = load_config(config_path)
    with working(f"solving for {', '.join(groups)}..."):
        job = calibrate_job(cfg, telemetry, gcps, groups=groups, pixel_sigma_px=pixel_sigma, robust=robust,
                            interpolate=interpolate, max_gap_s=max_gap, time_tolerance_s=time_tolerance)
    report_issues(job.issues)
    _print_calibration(job)
    out = Path(out_dir)
    (csv_path,) = write_layer(out, "gcp_residuals", job.rows, ["csv"])
    js = out / "calibration.json"
    js.parent.mkdir(parents=True, exist_ok=True)
    js.write_text(json.dumps(job.report, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    err_console.print(f"wrote [bold]{js}[/] and [bold]{csv_path}[/]")
    if write_config:
        write_back(job, config_path)
        console.print(f"updated [bold]{config_path}[/]")


def _print_calibration(job) -> None:
    cal, sensor = job.calibration, job.sensor
    start = {**dict(zip(("mount_x_deg", "mount_y_deg", "mount_z_deg"), sensor.mount_misalignment_deg, strict=True)),
             **dict(zip(("boresight_x_deg", "boresight_y_deg", "boresight_z_deg"), sensor.boresight_misalignment_deg,
                        strict=True)), "heading_bias_deg": job.heading_bias_deg, "time_offset_s": job.time_offset_s}
    t = titled_table(f"calibration from {int(cal.used.sum())} GCP observations (s0 = {cal.s0:.2f})")
    for col in ("parameter", "was", "estimate", "± 1σ"):
        t.add_column(col, justify="right")
    for name, v, s in zip(cal.names, cal.values, cal.sigma, strict=True):
        t.add_row(name, f"{start[name]:.4f}", f"{v:.4f}", f"{s:.4f}")
    console.print(t)
    r = titled_table("residuals (RMS)")
    for col in ("", "before", "after"):
        r.add_column(col, justify="right")
    r.add_row("pixels", f"{cal.rms(cal.residual_px_before):.2f}", f"{cal.rms(cal.residual_px_after):.2f}")
    r.add_row("ground (m)", f"{cal.rms(cal.ground_error_before_m):.2f}", f"{cal.rms(cal.ground_error_after_m):.2f}")
    console.print(r)
    if cal.s0 > 1.5:
        warn(f"s0 = {cal.s0:.2f}: the residuals are larger than --pixel-sigma says (telemetry noise shows in pixels "
             "too); the sigmas above are scaled by s0", "note")
    for w in cal.warnings:
        warn(w)
