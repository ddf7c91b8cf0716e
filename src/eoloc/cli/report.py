"""`eoloc report`: a flight-test accuracy report (HTML + CSV) from GCP observations."""

from __future__ import annotations

import shlex
import sys

import click

from .common import load_config, open_dem, progress, stop_rule
from .main import console, err_console, report_issues, warn
from .options import config_option, evaluation_options, out_option, rule_options

REPORT_HELP = """A flight-test accuracy report from observations of surveyed points: locate, evaluate,
calibrate (before/after), optionally cross-validate the learned compensation — one
self-contained HTML page (pictures inline, opens offline) plus CSV.

\b
eoloc report OBSERVATIONS.csv --config CAMERA.toml [--dem F | --target-height H] [--estimate mount]
  OBSERVATIONS: the calibration-observations CSV of `eoloc compensate` (one row per sighting of a
  surveyed point: flight, the pose as the telemetry reported it, u_px, v_px, gcp_id and the
  point's gcp_lat_deg, gcp_lon_deg, gcp_h_m; see `eoloc compensate --help`).
  Stop rule: --dem or --target-height as in operation; neither: each point's own surveyed height,
  which isolates the angular errors.
  The report holds CEP, CE90, LE90, MAE, RMSE and the bias with bootstrap intervals, overall and
  per flight; error against slant range, oblique angle, look azimuth, roll and pixel position;
  the linear TLE model in slant range; with an [accuracy.budget] in the config, whether each
  fix's predicted uncertainty was honest; the installation calibration (--estimate: mount,
  boresight, heading) judged in sample and with each flight held out of its own calibration;
  --compensation adds the learned compensation cross-validated by flight; and the inputs
  (SHA-256), configuration and software versions it was made from.
  Writes report.html, report_points.csv and report_summary.csv into --out.
"""


@click.command(help=REPORT_HELP)
@click.argument("observations", type=click.Path(dir_okay=False))
@config_option(help_text="Camera/gimbal/installation TOML (with [accuracy.budget] for the covariance of each fix).")
@rule_options(records=False)
@click.option("--estimate", default="mount", show_default=True,
              help="Installation parameters to calibrate, comma-separated: mount, boresight, heading; 'none' to "
                   "skip the calibration.")
@click.option("--compensation", is_flag=True, help="Also cross-validate the learned compensation by flight.")
@evaluation_options
@out_option("report.html, report_points.csv and report_summary.csv")
def report(observations, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, estimate, compensation,
           n_boot, level, seed, cooks_threshold, out_dir) -> None:
    from ..jobs.report import report_job, write_report

    cfg = load_config(config_path)
    rule = stop_rule(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs), required=False)
    groups = () if estimate.strip().lower() == "none" else tuple(e.strip() for e in estimate.split(",") if e.strip())
    with progress() as bar:
        task = bar.add_task("report", total=None)
        job = report_job(cfg, config_path, observations, rule=rule, estimate=groups,
                         compensation=compensation, n_boot=n_boot, level=level, seed=seed,
                         cooks_threshold=cooks_threshold, command="eoloc " + shlex.join(sys.argv[1:]),
                         progress=lambda text: bar.update(task, description=text))
    report_issues(job.issues)
    for s in job.stages:
        v = s.evaluation.overall
        console.print(f"{s.name:>30}: CEP {v.value['cep50_m']:.2f} m, CE90 {v.value['ce90_m']:.2f} m, "
                      f"LE90 {v.value['le90_m']:.2f} m ({v.n} fixes)")
    for note in job.notes:
        warn(note, "note")
    written = write_report(job, out_dir)
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
