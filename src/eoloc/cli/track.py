"""`eoloc track`: moving targets into tracks (Kalman filter), static targets by recursive least squares."""

from __future__ import annotations

import click
from rich.table import Table as RichTable

from .common import load_config, open_dem, progress, stop_rule, working
from .main import console, err_console, fail, report_issues, warn
from .options import (
    CONVENTIONS,
    config_option,
    flight_log_option,
    formats_option,
    grid_option,
    out_option,
    pairing_options,
    stop_rule_options,
    with_flight_log,
)
from .render import titled_table

TRACK_HELP = """Filter detections over time: moving targets into tracks (M7), or static targets by RLS (M6).

\b
eoloc track TELEMETRY.csv DETECTIONS.csv --config CAMERA.toml (--range [R] | --target-height H | --dem F)
  Every detection is located first (as eoloc locate), with its first-order covariance when the
  config has an [accuracy.budget] (else --meas-sigma metres).
  Moving (default): a constant-velocity Kalman filter per target in local ENU (Joseph-form
  update). Detections go to the track of their target_id; --associate ignores the ids and
  assigns each frame's fixes to tracks by gated global nearest neighbour. Writes tracks.geojson
  (LineStrings with coordTimes), track_fixes.csv (filtered position, speed, heading and their
  sigma per detection; empty where not known yet) and prints a table per track.
  With a budget, each fix is weighed by its random part and the estimate's uncertainty keeps what
  does not average: a source with kind = "bias" counts once, "noise" averages down, "markov"
  (Gauss–Markov, tau_s) by its correlation over the frames' times (see docs/uncertainty.md "Uncertainty").
  --static: recursive least squares per target_id (--forgetting 1 = all frames alike); writes
  static_targets.csv / .geojson with the estimate, its sigma, CEP50, CE90, LE90 and the frame
  where it converged. A target whose fixes do not agree with one point (a chi-square test: it
  moves, or its fixes jump between a summit and the slope behind it) gets status INCONSISTENT
  and no point. Without a budget (--meas-sigma) a target whose fixes scatter more than 3x that
  sigma is flagged and its sigma is the fixes' own scatter.
"""


@click.command(help=TRACK_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path())
@click.argument("detections", type=click.Path(dir_okay=False))
@config_option()
@stop_rule_options
@pairing_options
@out_option("the tracks or static targets")
@formats_option()
@grid_option()
@click.option("--static", is_flag=True, help="Static targets: RLS per target id instead of tracks.")
@click.option("--associate", is_flag=True, help="Tracks: ignore target ids, associate fixes to tracks (gated GNN).")
@click.option("--forgetting", type=click.FloatRange(0.0, 1.0, min_open=True), default=1.0, show_default=True,
              help="--static: RLS forgetting factor.")
@click.option("--window", type=click.IntRange(1), default=30, show_default=True,
              help="--static: converged once the estimate moved < 5 % of a fix's sigma over this many frames.")
@click.option("--accel-psd", type=click.FloatRange(0.0, min_open=True), default=0.1, show_default=True,
              help="Tracks: white-acceleration spectral density, m^2/s^3.")
@click.option("--meas-sigma", type=click.FloatRange(0.0, min_open=True), default=10.0, show_default=True,
              help="Fix sigma (m per axis) when the config has no [accuracy.budget].")
@click.option("--max-coast", type=click.FloatRange(0.0, min_open=True), default=2.0, show_default=True,
              help="Tracks: seconds without a detection before a track ends.")
@flight_log_option
def track(telemetry, detections, config_path, rule_values, dem_paths, vertical, geoid, dem_crs,
          time_tolerance, interpolate, max_gap, time_offset, out_dir, formats, grid, static, associate, forgetting,
          window, accel_psd, meas_sigma, max_coast, flight_log) -> None:
    telemetry = with_flight_log(telemetry, flight_log)
    from ..io.writers import write_layer
    from ..jobs.sequence import located_detections, static_targets, track_job

    if static and associate:
        fail("--associate groups fixes into tracks of moving targets; --static estimates each target_id's one "
             "position: give one of them")
    rule = stop_rule(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs))
    cfg = load_config(config_path)
    with working("locating..."):
        job = located_detections(cfg, telemetry, detections, rule, time_tolerance_s=time_tolerance,
                                 interpolate=interpolate, max_gap_s=max_gap, time_offset_s=time_offset)
    report_issues(job.issues)
    if static:
        rows = static_targets(job, forgetting=forgetting, meas_sigma_m=meas_sigma, window=window)
        console.print(_static_table(rows))
        console.print("scatter: the frames' scatter about the estimate against their declared uncertainty (about 1, "
                      "or less where part of the error is common to the frames; far more: the fixes do not agree)")
        for r in rows:
            if r.get("warning"):
                warn(f"target {r['target_id']}: {r['warning']}")
        written = write_layer(out_dir, "static_targets", rows, formats, grid=grid)
    else:
        with progress() as bar:
            task = bar.add_task("tracking", total=None)
            tj = track_job(job, associate=associate, accel_psd=accel_psd, meas_sigma_m=meas_sigma,
                           max_coast_s=max_coast, progress=lambda k, n: bar.update(task, completed=k, total=n))
        table = titled_table(f"{len(tj.tracks.tracks)} tracks from {int(job.located.fixes.ok.sum())} located "
                                "detections")
        for c in ("track", "updates", "from (s)", "to (s)", "speed (m/s)", "heading (°)"):
            table.add_column(c, justify="right")
        for f in tj.features:
            p = f["properties"]
            table.add_row(p["track_id"], str(p["updates"]), f"{p['start_s']:g}", f"{p['end_s']:g}",
                          f"{p['speed_mps']:.2f} ± {p['speed_sigma_mps']:.2f}", f"{p['heading_deg']:.1f}")
        console.print(table)
        if tj.unassigned:
            warn(f"{tj.unassigned} located detections joined no confirmed track (clutter, or a target seen fewer "
                 "than 3 times)")
        written = write_layer(out_dir, "track_fixes", tj.records, [f for f in formats if f != "geojson"], grid=grid)
        written += write_layer(out_dir, "tracks", [f["properties"] for f in tj.features],
                               [f for f in formats if f in ("geojson", "kml")] or ["geojson"], features=tj.features)
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))


def _static_table(rows) -> RichTable:
    table = titled_table("static targets: recursive least squares over all frames")
    for c in ("target", "fixes", "lat, lon (°)", "h (m)", "CEP50 (m)", "scatter", "converged"):
        table.add_column(c, justify="right")
    for r in rows:
        if r["status"] == "INCONSISTENT":
            table.add_row(r["target_id"], f"{r['used']}/{r['frames']}", "INCONSISTENT", "", "",
                          f"{r['scatter_ratio']:.3g}", "no estimate")
            continue
        if r["status"] != "OK":
            table.add_row(r["target_id"], f"0/{r['frames']}", "", "", "", "", "no fix")
            continue
        conv = "no" if r["converged_at_s"] is None else f"{r['converged_at_s']:g} s"
        table.add_row(r["target_id"], f"{r['used']}/{r['frames']}", f"{r['lat_deg']:.6f}, {r['lon_deg']:.6f}",
                      f"{r['h_m']:.1f}", f"{r['cep50_m']:.1f}", f"{r['scatter_ratio']:.2f}", conv)
    return table
