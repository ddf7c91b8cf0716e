"""`eoloc evaluate`: fixes against surveyed points — the figures of a flight-test accuracy report."""

from __future__ import annotations

import json

import click

from .common import load_config, working
from .main import console, err_console, fail, report_issues, warn
from .options import evaluation_options, json_option, out_option

EVALUATE_HELP = """Accuracy of fixes against surveyed points (GCPs): CEP, CE90, LE90, MAE, RMSE and the
mean bias east/north/up, each with a bootstrap confidence interval; by group; error against slant
range and the other geometry the fixes carry, with the linear target-location-error model; and
whether the fixes' own uncertainty was honest.

\b
eoloc evaluate FIXES --truth POINTS [--match id|nearest] [--group COLUMN] [--out DIR]
  FIXES: any eoloc output (fixes CSV/GeoJSON/KML, the CoT data package) or other tools' points
  as CSV, GeoJSON, KML or CoT. POINTS: the surveyed points as CSV, GeoJSON or KML.
  Coordinates: WGS-84 latitude/longitude in degrees, heights in metres above the ellipsoid
  (KML's absolute altitudes are MSL and are converted with EGM96). Columns lat_deg, lon_deg, h_m
  (or lat/latitude, lon/lng/longitude, h/hae/height_m); name others with --fix-columns and
  --truth-columns LAT,LON[,H] (without H: horizontal statistics only).
  Matching: by id (fix target_id/gcp_id/id/name against the truth's) when both files carry ids
  that agree, else each fix to the nearest truth point within --max-distance; fixes farther
  from every truth point are counted as unmatched, and a fix less than twice as far from its
  nearest truth point as from the next is flagged 'ambiguous'.
  Errors are fix minus truth in east, north, up metres at the truth point. CEP is the median
  horizontal error, CE90 its 90 % quantile, LE90 the 90 % quantile of |vertical error|
  (quantiles interpolated linearly between order statistics: numpy's and R's default).
  Intervals: percentile bootstrap (--bootstrap resamples, --seed: the same numbers every run).
  Geometry: range_m (slant range), oblique_deg, azimuth_deg, sensor_roll_deg columns, the pixel's
  distance from the image centre (u_px, v_px with --config), and any --factor COLUMN.
  TLE model: horizontal error = a + b × slant range, least squares after removing points whose
  Cook's distance exceeds --cooks-threshold (default 4/n), as OpenAthena publishes per drone model.
  Honesty: when the fixes carry eoloc's covariance (sigma_e_m, sigma_n_m, rho_en, sigma_u_m,
  cep50_m, ce90_m, le90_m; CoT's ce/le), the share of truth points inside each fix's own CE50,
  CE90 and LE90 and inside its own p-ellipse for p = 5...95 %: ~50 % and ~90 % when honest.
  Writes evaluation_points.csv, evaluation_summary.csv, evaluation.json and PNGs into --out.
"""


def _columns(text: str | None, option: str) -> tuple[str, ...] | None:
    if text is None:
        return None
    cols = tuple(c.strip() for c in text.split(","))
    if len(cols) not in (2, 3) or not all(cols):
        fail(f"{option} takes LAT,LON or LAT,LON,H column names, got {text!r}")
    return cols


@click.command(help=EVALUATE_HELP)
@click.argument("fixes", type=click.Path(dir_okay=False))
@click.option("--truth", "truth_path", required=True, type=click.Path(dir_okay=False), metavar="POINTS",
              help="Surveyed points (CSV, GeoJSON or KML).")
@click.option("--match", type=click.Choice(["id", "nearest"]), default=None,
              help="How fixes find their truth point [default: id when both files carry ids that agree, else "
                   "nearest].")
@click.option("--max-distance", type=click.FloatRange(0.0, min_open=True), default=50.0, show_default=True,
              metavar="M", help="With nearest matching: farthest a fix may be from its truth point (m).")
@click.option("--fix-columns", default=None, metavar="LAT,LON[,H]", help="The fixes' coordinate columns.")
@click.option("--truth-columns", default=None, metavar="LAT,LON[,H]", help="The truth points' coordinate columns.")
@click.option("--fix-id", default=None, metavar="COLUMN", help="The fixes' id column (default: target_id, gcp_id, "
                                                                "id, name, callsign).")
@click.option("--truth-id", default=None, metavar="COLUMN", help="The truth points' id column (default: gcp_id, "
                                                                    "target_id, id, name).")
@click.option("--group", default=None, metavar="COLUMN",
              help="Statistics (and the TLE model) per value of this column, e.g. sensor model or flight.")
@click.option("--factor", "factors", multiple=True, metavar="COLUMN",
              help="Also plot the error against this numeric column of the fixes; repeat for several.")
@click.option("--config", "config_path", default=None, type=click.Path(dir_okay=False), metavar="CONFIG.toml",
              help="Camera config: its principal point gives each pixel's distance from the image centre.")
@evaluation_options
@click.option("--plots/--no-plots", default=True, show_default=True, help="Write the PNGs.")
@json_option("Print the evaluation as one JSON document on stdout (tables and notes go to stderr).")
@out_option("evaluation_points.csv, evaluation_summary.csv, evaluation.json and the PNGs")
def evaluate(fixes, truth_path, match, max_distance, fix_columns, truth_columns, fix_id, truth_id, group, factors,
             config_path, n_boot, level, seed, cooks_threshold, plots, as_json, out_dir) -> None:
    from ..io.export import json_safe
    from ..jobs.evaluate import evaluate_job, evaluation_notes, evaluation_tables, report_dict, write_evaluation
    from .render import rich_table

    centre = None
    if config_path is not None:
        cam = load_config(config_path).sensor().camera
        centre = (cam.cx, cam.cy)
    with working("evaluating..."):
        ev = evaluate_job(fixes, truth_path, fix_columns=_columns(fix_columns, "--fix-columns"),
                          truth_columns=_columns(truth_columns, "--truth-columns"), match=match or "auto",
                          max_distance_m=max_distance, fix_id=fix_id, truth_id=truth_id, group=group,
                          extra_factors=tuple(factors), image_centre_px=centre, n_boot=n_boot, level=level, seed=seed,
                          cooks_threshold=cooks_threshold)
    report_issues(ev.issues)
    out_console = err_console if as_json else console
    for t in evaluation_tables(ev):
        out_console.print(rich_table(t))
    for note in evaluation_notes(ev):
        warn(note, "note")
    written = write_evaluation(ev, out_dir, plots=plots)
    if as_json:
        click.echo(json.dumps(json_safe(report_dict(ev)), allow_nan=False))
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
