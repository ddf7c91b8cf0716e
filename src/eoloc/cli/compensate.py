"""`eoloc compensate simulate|train|evaluate`: learned error compensation at large oblique angles ([P])."""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from .common import load_config, open_dem, progress, stop_rule, working
from .main import console, err_console, fail, report_issues, warn
from .options import config_option, json_option, out_option, rule_options
from .render import print_bands

COMPENSATE_HELP = """Learned error prediction and compensation at large oblique angles (after Peng et al.'s
error prediction and compensation at large oblique angles).

\b
  eoloc compensate simulate --config CAMERA.toml --out cal/     synthetic calibration flights
  eoloc compensate train cal/train.csv --config CAMERA.toml --dem cal/dem.tif --vertical ellipsoid -o model.json
  eoloc compensate evaluate model.json cal/test.csv --config CAMERA.toml --dem cal/dem.tif --vertical ellipsoid
  eoloc locate TEL.csv DET.csv --config CAMERA.toml --dem DEM.tif --compensate model.json

\b
Observations CSV (one row per sighting of a surveyed point; `eoloc compensate simulate` writes one):
  flight            flight id: cross-validation holds whole flights out
  time_s            optional
  lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, gimbal1_deg, gimbal2_deg[, sensor_roll_deg]
                    the pose as the telemetry reported it (same conventions as `eoloc locate`)
  u_px, v_px        where the point is in the image
  gcp_id            optional
  gcp_lat_deg, gcp_lon_deg, gcp_h_m   the point's surveyed WGS-84 position (ellipsoidal m)

Each observation is located with the stop rule you use in operation (--dem, --target-height;
default: each point's own surveyed height), its error (fix minus truth) is learned from the
features oblique angle, look azimuth, height above target (and, by default, the look bearing
relative to the heading), and the model predicts it for new fixes.
"""

BANDS_HELP = "Oblique-angle band edges for the tables (deg)."


def _bands(text: str) -> tuple[float, ...]:
    try:
        edges = tuple(float(x) for x in text.split(","))
    except ValueError:
        fail(f"--bands takes comma-separated degrees, e.g. 0,30,45,60,70,90; got {text!r}")
    if len(edges) < 2 or any(b <= a for a, b in itertools.pairwise(edges)):
        fail(f"--bands must be at least two increasing angles, got {text!r}")
    return edges


@click.group(help=COMPENSATE_HELP)
def compensate() -> None:
    pass


@compensate.command("simulate", help="Write synthetic calibration flights (train.csv, test.csv) and the "
                                     "ground-station DEM they are located on (dem.tif, ellipsoidal heights).")
@click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
              help="Camera/gimbal TOML (the nominal sensor; az-el turret).")
@click.option("--flights", type=click.IntRange(1, 200), default=8, show_default=True, help="Training flights.")
@click.option("--test-flights", type=click.IntRange(0, 200), default=4, show_default=True,
              help="Independent flights for evaluate.")
@click.option("--looks", type=click.IntRange(10, 100_000), default=400, show_default=True,
              help="Observations per flight.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of the flights and their errors.")
@out_option("train.csv, test.csv and dem.tif")
def simulate(config_path, flights, test_flights, looks, seed, out_dir) -> None:
    from ..accuracy.calflight import InstallationErrors, calibration_flights
    from ..io.raster import write_dem

    sensor = load_config(config_path).sensor()
    tr = calibration_flights(sensor, n_flights=flights, looks_per_flight=looks, seed=seed)
    te = (calibration_flights(sensor, n_flights=test_flights, looks_per_flight=looks, seed=seed + 1000,
                              first_flight=flights) if test_flights else None)
    out = Path(out_dir)
    written = [_write_obs(out / "train.csv", tr.columns)]
    if te is not None:
        written.append(_write_obs(out / "test.csv", te.columns))
    written.append(write_dem(tr.dem, out / "dem.tif"))
    e = InstallationErrors()
    console.print(f"{len(tr)} training observations on {flights} flights"
                    + (f", {len(te)} test observations on {test_flights} flights" if te is not None else "")
                    + f". Installation errors: gimbal bias {e.gimbal_bias_deg}°, mount {e.mount_misalignment_deg}°, "
                      f"boresight {e.boresight_misalignment_deg}°, heading bias {e.heading_bias_deg}°, time offset "
                      f"{e.time_offset_s} s, DEM bias {e.dem_bias_m} m.")
    console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))


def _write_obs(path: Path, cols: dict[str, np.ndarray]) -> Path:
    from ..io.records import Records
    from ..io.writers import write_layer

    return write_layer(path.parent, path.stem, Records(dict(cols)), ["csv"])[0]


def _observed(obs_path, config_path, rule_values, dem_paths, vertical, geoid, dem_crs):
    """(sensor, observations table, Observed) with the issues of the file reported."""
    from ..accuracy.compensation import locate_observations
    from ..io.telemetry import read_observations

    sensor = load_config(config_path).sensor()
    t = read_observations(obs_path)
    report_issues(t.issues)
    if len(t) == 0:
        fail(f"{obs_path}: no usable observation")
    rule = stop_rule(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs), required=False)
    with working(f"locating {len(t)} observations..."):
        obs = locate_observations(sensor, t.columns, rule)
    bad = np.flatnonzero(~obs.fixes.ok)
    if bad.size:
        err_console.print(f"[yellow]warning:[/] {bad.size} observations could not be located "
                          f"({obs.fixes.status_counts()}), e.g. line {int(t.line[bad[0]])}; they are left out")
    return sensor, t, obs, rule


def stop_options(fn):
    """The stop rule the observations are located with (as in operation; none: each point's own
    surveyed height) and the config."""
    fn = rule_options(records=False)(fn)
    return config_option()(fn)


@compensate.command("train", help="Fit a compensation model to calibration observations; print its "
                                  "cross-validated CEP by oblique band (whole flights held out, then whole "
                                  "bands held out) against a gradient-boosted tree ensemble, and write the model "
                                  "(versioned JSON) and a PNG.")
@click.argument("observations", type=click.Path(dir_okay=False))
@stop_options
@click.option("--features", "feature_set", type=click.Choice(["p", "p+bearing"]), default="p+bearing",
              show_default=True, help="p: Peng et al.'s oblique, azimuth, height; p+bearing adds the look bearing "
                                      "relative to the heading (body-fixed errors need it).")
@click.option("--up", is_flag=True, help="Also predict the vertical error.")
@click.option("--per-bin", type=click.IntRange(1), default=None,
              help="Peng et al.'s sample selection: at most N observations per height x oblique x direction cell.")
@click.option("--height-bins", default="0,1500,2500,3500,6000", show_default=True,
              help="With --per-bin: height-above-target bin edges (m).")
@click.option("--bands", default="0,30,45,60,70,90", show_default=True, help=BANDS_HELP)
@click.option("--compare/--no-compare", default=False, show_default=True,
              help="Also cross-validate the other families (a gradient-boosted tree ensemble, the other feature "
                   "set): minutes instead of seconds.")
@click.option("-o", "--model", "model_path", type=click.Path(dir_okay=False), default=None,
              help="Model file to write (default: compensation.json in --out).")
@out_option("compensation.json, the PNG and the cross-validation CSV")
def train(observations, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, feature_set, up, per_bin,
          height_bins, bands, compare, model_path, out_dir) -> None:
    from ..accuracy import compensation as C
    from ..accuracy.plots import plot_compensation

    edges = _bands(bands)
    _, table, obs, rule = _observed(observations, config_path, rule_values, dem_paths, vertical, geoid, dem_crs)
    keep = np.flatnonzero(obs.fixes.ok)
    if per_bin is not None:
        sel, counts = C.select_bins(obs.features.take(keep), height_edges=[float(x) for x in height_bins.split(",")],
                                    oblique_edges=edges, per_cell=per_bin)
        console.print(f"sample selection: {sel.size} of {keep.size} observations, at most {per_bin} per cell; "
                        f"{int((counts == 0).sum())} of {counts.size} height × oblique × direction cells are empty")
        keep = keep[sel]
    f, e, g = obs.features.take(keep), obs.errors_enu[keep], obs.groups[keep]
    sets = ("p", "p+bearing") if compare else (feature_set,)
    with progress() as bar:
        task = bar.add_task("cross-validating", total=3)
        cv_f = C.cross_validate(f, e, g, by="flight", feature_sets=sets, trees=compare, oblique_edges=edges)
        bar.advance(task)
        try:  # a check of the model, not the model: without it the model is still trained
            cv_b, why_no_bands = C.cross_validate(f, e, g, by="band", feature_sets=sets, trees=compare,
                                                  oblique_edges=edges), ""
        except InputError as exc:
            cv_b, why_no_bands = None, str(exc)
        bar.advance(task)
        model = C.fit(f, e, feature_set=feature_set, up=up, groups=g, oblique_edges=edges,
                      info={"observations": str(observations), "stop": _stop_label(rule, dem_paths)})
        bar.advance(task)
    n_flights = len(np.unique(g))
    print_bands(cv_f.table(edges), f"held-out flights ({cv_f.n_folds} folds over {n_flights} flights): CEP50")
    band_rows = [] if cv_b is None else cv_b.table(edges)
    if cv_b is None:
        warn(f"held-out oblique bands: not computed: {why_no_bands}. The model is trained and used within the "
             "oblique range it saw only (fixes outside it are flagged, column comp_flag)", "note")
    else:
        print_bands(band_rows, "held-out oblique bands (each band predicted by a model that never saw it)")
    out = Path(out_dir)
    png = plot_compensation(cv_f.oblique_deg, cv_f.before_en, {k: v for k, v in cv_f.after_en.items()
                                                               if k == feature_set},
                            cv_f.table(edges), out / "compensation_cv.png",
                            title="held-out flights: location error against oblique angle, before and after")
    csv_path = _write_table(out / "compensation_cv.csv", cv_f.table(edges) + band_rows,
                            ["flight"] * len(cv_f.table(edges)) + ["band"] * len(band_rows))
    info = {"cv_by_flight": _table_dict(cv_f.table(edges)), "cv_by_band": _table_dict(band_rows)}
    model = dataclasses.replace(model, info={**model.info, **info})
    path = model.save(model_path if model_path is not None else out / "compensation.json")
    console.print(f"model: physical, features {feature_set}, ridge {model.ridge:g}, "
                    f"{model.info['n_samples']} samples, "
                    f"oblique {model.oblique_range[0]:.1f}–{model.oblique_range[1]:.1f}°, height "
                    f"{model.height_range[0]:.0f}–{model.height_range[1]:.0f} m")
    console.print(f"wrote [bold]{path}[/], [bold]{png}[/] and [bold]{csv_path}[/]")


def _stop_label(rule, dem_paths) -> str:
    if dem_paths:
        return "dem: " + ", ".join(str(p) for p in dem_paths)
    return rule.describe() if rule is not None else "each point's surveyed height"


def _table_dict(rows) -> list[dict]:
    return [{"lo_deg": r.lo_deg, "hi_deg": r.hi_deg, "n": r.n, "cep_before_m": round(r.cep_before_m, 3),
             "cep_after_m": {k: round(v, 3) for k, v in r.cep_after_m.items()}} for r in rows]


def _write_table(path: Path, rows, kinds) -> Path:
    from ..io.writers import write_layer

    out = []
    for kind, r in zip(kinds, rows, strict=True):
        row = {"held_out": kind, "lo_deg": r.lo_deg, "hi_deg": r.hi_deg, "n": r.n, "cep_before_m": r.cep_before_m}
        row.update({f"cep_after_{k}_m": v for k, v in r.cep_after_m.items()})
        out.append(row)
    return write_layer(path.parent, path.stem, out, ["csv"])[0]


@compensate.command("evaluate", help="Apply a model to observations it was not trained on: CEP by oblique band "
                                     "before and after, a PNG, and the per-fix corrections and flags (CSV).")
@click.argument("model_path", type=click.Path(dir_okay=False))
@click.argument("observations", type=click.Path(dir_okay=False))
@stop_options
@click.option("--bands", default="0,30,45,60,70,90", show_default=True, help=BANDS_HELP)
@json_option("Print the band table as JSON on stdout (tables go to stderr).")
@out_option("the PNG and the per-fix CSV")
def evaluate(model_path, observations, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, bands,
             as_json, out_dir) -> None:
    from ..accuracy import compensation as C
    from ..accuracy.plots import plot_compensation

    edges = _bands(bands)
    model = C.CompensationModel.load(model_path)
    _, table, obs, _ = _observed(observations, config_path, rule_values, dem_paths, vertical, geoid, dem_crs)
    pred = model.predict(obs.features)
    e0 = obs.errors_enu[:, :2]
    e1 = e0 + pred.correction_enu[:, :2]
    ok = obs.fixes.ok & pred.applied
    rows = C.band_table(np.where(ok, obs.features.oblique_deg, np.nan), e0, {"compensated": e1}, edges)
    print_bands(rows, f"{observations}: CEP50 by oblique band, before and after {model_path}",
                err_console if as_json else console)
    flagged = obs.fixes.ok & ~pred.applied
    reasons = pred.reasons(obs.features, model)
    if flagged.any():
        first = int(np.flatnonzero(flagged)[0])
        err_console.print(f"[yellow]{int(flagged.sum())} fixes outside the trained range were not corrected[/] "
                          f"(left out of the table), e.g. line {int(table.line[first])}: {reasons[first]}")
    out = Path(out_dir)
    png = plot_compensation(obs.features.oblique_deg[ok], e0[ok], {"compensated": e1[ok]}, rows,
                            out / "compensation.png",
                            title=f"{Path(observations).name}: location error against oblique angle")
    from ..io.records import Records
    from ..io.writers import write_layer

    fx = Records({"line": np.asarray(table.line), "flight": np.asarray(table.columns["flight"]),
                  **{k: np.asarray(v) for k, v in obs.features.columns().items()},
                  "err_e_m": e0[:, 0], "err_n_m": e0[:, 1],
                  "comp_e_m": pred.correction_enu[:, 0], "comp_n_m": pred.correction_enu[:, 1],
                  "after_e_m": e1[:, 0], "after_n_m": e1[:, 1], "comp_applied": np.asarray(pred.applied, dtype=bool),
                  "comp_flag": np.asarray(reasons, dtype=object)})
    (csv_path,) = write_layer(out, "compensation_fixes", fx, ["csv"])
    if as_json:
        click.echo(json.dumps(_table_dict(rows)))
    console.print(f"wrote [bold]{png}[/] and [bold]{csv_path}[/]")
