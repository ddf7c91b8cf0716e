"""The `eoloc` command: geolocate targets from telemetry, or one observation given as options."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table as RichTable

from .cli_common import (
    CONVENTIONS,
    dem_options,
    err_console,
    fail,
    load_config,
    load_config_or_fail,
    locate_with_config,
    main,
    open_dem_or_fail,
    progress,
    read_inputs,
    report_issues,
    stop_rule,
    target_height_option,
)
from .errors import ConfigError
from .footprint import write_footprints_geojson
from .io.export import fix_rows, plain_value, write_csv, write_geojson
from .pipeline import RANGE_FROM_FILES, locate_by_rule
from .result import Status
from .rules import StopRule
from .sensor import Camera, GimbalKind, Pose, SensorModel, gimbal_from_name

LOCATE_HELP = """Geolocate targets: from files, or one observation given as options.

\b
FILE MODE:  eoloc locate TELEMETRY.csv [DETECTIONS.csv] --config CAMERA.toml
              (--range [R] | --target-height H | --dem F)
  TELEMETRY.csv columns: time_s and/or frame, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg,
    roll_deg, gimbal1_deg, gimbal2_deg (or azimuth_deg, elevation_deg / frame_roll_deg,
    frame_pitch_deg), optional sensor_roll_deg, optional range_m (laser slant range).
  DETECTIONS.csv columns: time_s or frame, target_id, u_px, v_px, optional range_m.
  Without DETECTIONS the image centre of every record is located.
  --range alone takes each target's range_m from the files; --range R uses R metres for all;
  --target-height H stops at ellipsoidal height H; --dem FILE (repeat for
  tiles: GeoTIFF, DTED, SRTM .hgt/.zip, ESRI ASCII) stops at the first hit on the terrain
  (heights taken as EGM96 and converted with the bundled geoid unless --vertical says otherwise).
  Writes fixes.csv and fixes.geojson into --out. Bad lines are reported (file:line) and skipped;
  every good record is kept.
  --interpolate: each detection's pose is interpolated to its time_s (position by a spline in
  ECEF, attitude by slerp, gimbal angles unwrapped) instead of the nearest record; --time-offset
  S is the telemetry clock minus the video clock; detections in a gap longer than --max-gap are
  reported and get NO_TELEMETRY, never a bridged pose.
  --covariance adds each fix's first-order uncertainty from the config's [accuracy.budget]:
  sigma east/north/up, CEP50/CE90, LE90, the error ellipse, and a nonlinearity figure (> 0.1:
  the linearisation does not hold there, e.g. a ray grazing a ridge; use eoloc accuracy).

\b
ONE OBSERVATION:  eoloc locate --lat 42 --lon 125 --aircraft-height 10000 --yaw 10 --pitch 5
                  --roll -2 --gimbal az-el --gimbal-angles 45 -75 --range 10200 [--json]
  --aircraft-height is the aircraft's ellipsoidal height (m); the stop rule as in file mode;
  --pixel U V needs --config for the camera (image centre when omitted).
"""


@main.command(help=LOCATE_HELP + CONVENTIONS)
@click.argument("telemetry", required=False, type=click.Path(dir_okay=False))
@click.argument("detections", required=False, type=click.Path(dir_okay=False))
@click.option("--config", "config_path", type=click.Path(dir_okay=False), help="Camera/gimbal/installation TOML.")
@click.option("--range", "range_opt", is_flag=False, flag_value=RANGE_FROM_FILES, default=None,
              help="Stop at a slant range: R metres, or alone to read range_m from the files.")
@target_height_option("Stop rule M3: the targets' ellipsoidal height, metres.")
@click.option("--aircraft-height", "height", type=float,
              help="One observation: the aircraft's (INS point's) ellipsoidal height, metres.")
@click.option("--lat", type=float, help="One observation: aircraft latitude, degrees.")
@click.option("--lon", type=float, help="One observation: aircraft longitude, degrees.")
@click.option("--yaw", type=float, default=0.0, show_default=True, help="Heading, degrees from true north.")
@click.option("--pitch", type=float, default=0.0, show_default=True, help="Pitch, degrees, nose up +.")
@click.option("--roll", type=float, default=0.0, show_default=True, help="Roll, degrees, right wing down +.")
@click.option("--gimbal", type=click.Choice(["az-el", "roll-pitch", "fixed"]), default=None,
              help="Gimbal model (one observation; default: the config's, else az-el).")
@click.option("--gimbal-angles", nargs=2, type=float, default=None, metavar="A B",
              help="az-el: azimuth elevation; roll-pitch: frame roll, frame pitch (degrees).")
@click.option("--sensor-roll", type=float, default=0.0, show_default=True, help="Sensor roll about the boresight.")
@click.option("--pixel", nargs=2, type=float, default=None, metavar="U V", help="Pixel (needs --config).")
@click.option("--json", "as_json", is_flag=True, help="One observation: print one JSON object.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="File mode: folder for fixes.csv and fixes.geojson.")
@click.option("--time-tolerance", type=float, default=0.02, show_default=True,
              help="File mode: max |Δt| (s) pairing a detection with a telemetry record.")
@dem_options("Stop rule M4: DEM file(s); repeat for several tiles.")
@click.option("--covariance", is_flag=True,
              help="Add each fix's first-order uncertainty from the config's [accuracy.budget].")
@click.option("--interpolate", is_flag=True, help="File mode: interpolate the pose to each detection's time.")
@click.option("--max-gap", type=float, default=0.5, show_default=True,
              help="With --interpolate: longest telemetry gap (s) to interpolate across.")
@click.option("--time-offset", type=float, default=None,
              help="With --interpolate: telemetry clock minus video clock (s); default: the config's "
                   "[telemetry] time_offset_s, else 0.")
@click.option("--compensate", "compensate_path", type=click.Path(dir_okay=False), default=None, metavar="MODEL",
              help="File mode: add a learned error correction (eoloc compensate train) to every fix inside the "
                   "model's trained range and report it per fix (default: the config's [compensation] model).")
def locate(telemetry, detections, config_path, range_opt, target_height, height, lat, lon, yaw, pitch, roll, gimbal,
           gimbal_angles, sensor_roll, pixel, as_json, out_dir, time_tolerance, dem_paths, vertical, geoid,
           dem_crs, covariance, interpolate, max_gap, time_offset, compensate_path) -> None:
    budget = None
    if covariance:
        if config_path is None:
            fail("--covariance needs --config FILE with an [accuracy.budget] section (the error sources)")
        from .io.config import error_budget

        try:
            budget = error_budget(load_config(config_path), config_path)
        except ConfigError as exc:
            fail(str(exc))
    dem = open_dem_or_fail(dem_paths, vertical, geoid, dem_crs) if dem_paths else None
    if telemetry is None:
        from ._backend import few_targets

        with few_targets():
            _locate_one(config_path, range_opt, target_height, height, lat, lon, yaw, pitch, roll, gimbal,
                        gimbal_angles, sensor_roll, pixel, as_json, dem, budget)
        return
    if lat is not None or lon is not None or height is not None:
        fail("give either a TELEMETRY file or --lat/--lon/--aircraft-height for one observation, not both")
    stop_height = target_height
    if interpolate and detections is None:
        fail("--interpolate needs a DETECTIONS file (the image centres are located at the records themselves)")
    _locate_files(telemetry, detections, config_path, range_opt, stop_height, out_dir, time_tolerance, dem, budget,
                  dict(interpolate=interpolate, max_gap_s=max_gap, time_offset_s=time_offset), compensate_path)






def _load_sensor(config_path) -> SensorModel:
    return load_config_or_fail(config_path).sensor()








def _locate_one(config_path, range_opt, target_height, height, lat, lon, yaw, pitch, roll, gimbal, gimbal_angles,
                sensor_roll, pixel, as_json, dem=None, budget=None) -> None:
    if lat is None or lon is None or height is None:
        fail("one observation needs --lat, --lon and --aircraft-height (ellipsoidal m), or give a TELEMETRY file")
    rule = stop_rule(range_opt, target_height, dem)
    if rule == RANGE_FROM_FILES:
        fail("--range needs a value (metres) for one observation")
    if config_path is not None:
        sensor = _load_sensor(config_path)
        if gimbal is not None and gimbal != sensor.gimbal.name:
            fail(f"--gimbal {gimbal} contradicts the config's gimbal model {sensor.gimbal.name!r}")
    else:
        if pixel is not None:
            fail("--pixel needs --config FILE to know the camera (without it the image centre is used)")
        # the centre pixel's ray is the boresight whatever the intrinsics: any camera will do
        sensor = SensorModel(Camera(1, 1, 1.0, 1.0, 0.0, 0.0), gimbal_from_name(gimbal or "az-el"))
    if sensor.gimbal.kind == GimbalKind.FIXED:
        angles = (sensor_roll,)
    else:
        if gimbal_angles is None:
            fail(f"--gimbal-angles A B is required for the {sensor.gimbal.name} gimbal "
                  f"({', '.join(sensor.gimbal.angle_names)}, degrees)")
        angles = (*gimbal_angles, sensor_roll)
    pose = Pose(lat, lon, height, yaw, pitch, roll, angles)
    pixels = None if pixel is None else (pixel[0], pixel[1])
    f, cov = locate_by_rule(sensor, pose, pixels, rule, budget=budget)
    status = Status(int(f.status))
    out = {"lat": _num(f.lat_deg), "lon": _num(f.lon_deg), "h": _num(f.h_m), "range": _num(f.range_m),
           "status": status.name}
    if cov is not None:
        from .accuracy.covariance import covariance_columns

        out.update({k: _num(v[0]) for k, v in covariance_columns(cov, f.ok).items()})
    if as_json:
        click.echo(json.dumps(out))
        return
    table = RichTable(title="eoloc fix", show_header=True)
    for k in ("lat", "lon", "h", "range", "status"):
        table.add_column(k + {"lat": " (deg)", "lon": " (deg)", "h": " (m, ellipsoidal)", "range": " (m)"}.get(k, ""))
    table.add_row(*(_cell(k, out[k]) for k in ("lat", "lon", "h", "range", "status")))
    Console().print(table)
    if cov is not None and status == Status.OK:
        _print_uncertainty(out)
    if status != Status.OK:
        err_console.print(f"[yellow]{status.name}[/]: {status.explanation}")


def _print_uncertainty(u: dict) -> None:
    Console().print(f"1σ east {u['sigma_e_m']:.3g} m, north {u['sigma_n_m']:.3g} m, up {u['sigma_u_m']:.3g} m; "
                    f"CEP50 {u['cep50_m']:.3g} m, CE90 {u['ce90_m']:.3g} m, LE90 {u['le90_m']:.3g} m; "
                    f"ellipse {u['ellipse_major_m']:.3g} × {u['ellipse_minor_m']:.3g} m at "
                    f"{u['ellipse_azimuth_deg']:.1f}°")
    nl = u["nonlinearity"]
    if nl is None or nl > 0.1:
        err_console.print("[yellow]warning:[/] the first-order uncertainty does not hold for this fix (nonlinearity "
                          f"{nl if nl is not None else 'inf'}): a ray near grazing or near an edge; run "
                          "eoloc accuracy for a Monte Carlo of it")


def _num(x) -> float | None:
    x = float(x)
    return None if np.isnan(x) else x


def _cell(key: str, v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.8f}" if key in ("lat", "lon") else f"{v:.3f}"
    return str(v)


def _locate_files(telemetry, detections, config_path, range_opt, stop_height, out_dir, time_tolerance,
                  dem=None, budget=None, interp=None, compensate_path=None) -> None:
    if config_path is None:
        fail("file mode needs --config CAMERA.toml (camera, gimbal, installation); see the README")
    rule = stop_rule(range_opt, stop_height, dem)
    cfg = load_config_or_fail(config_path)
    from .io.config import compensation_model

    try:
        model = compensation_model(cfg, config_path, compensate_path)
    except ConfigError as exc:
        fail(str(exc))
    tel, det, issues = read_inputs(telemetry, detections, cfg)
    located = locate_with_config(cfg, tel, det, rule, time_tolerance, budget, interp, model)
    issues += located.issues
    report_issues(issues)
    after = None
    if located.covariance is not None:
        from .accuracy.covariance import covariance_columns

        after = covariance_columns(located.covariance, located.fixes.ok)
        loose = np.flatnonzero(located.fixes.ok & ~(after["nonlinearity"] <= 0.1))
        if loose.size:
            err_console.print(f"[yellow]warning:[/] {loose.size} fixes have a nonlinearity > 0.1 (column "
                              "nonlinearity): their first-order uncertainty is not to be trusted")
    if located.compensation is not None:
        comp = located.compensation
        after = {**(after or {}), **comp}
        applied = comp["comp_applied"] & located.fixes.ok.ravel()
        flagged = located.fixes.ok.ravel() & ~comp["comp_applied"]
        shift = np.hypot(comp["comp_e_m"], comp["comp_n_m"])[applied]
        Console().print(f"compensation: {int(applied.sum())} fixes corrected"
                        + (f" (median shift {np.median(shift):.1f} m, max {shift.max():.1f} m)" if shift.size else "")
                        + f"; {int(flagged.sum())} outside the model's trained range left as located (column "
                          "comp_flag says why)")
    rows = fix_rows(located.fixes, located.extra, after)
    out = Path(out_dir)
    csv_path = write_csv(out / "fixes.csv", rows)
    geo_path = write_geojson(out / "fixes.geojson", rows)
    _summary(rows, located.fixes.status_counts())
    _none_located(located.fixes, rule)
    Console().print(f"wrote [bold]{csv_path}[/] and [bold]{geo_path}[/]")






def _summary(rows: list[dict], counts: dict[str, int], limit: int = 12) -> None:
    table = RichTable(title=f"{len(rows)} targets: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    cols = ("time_s", "frame", "target_id", "lat_deg", "lon_deg", "h_m", "range_m", "status")
    cols = tuple(c for c in cols if any(r.get(c) is not None for r in rows))  # drop empty columns
    for c in cols:
        table.add_column(c)
    for row in rows[:limit]:
        table.add_row(*(_cell("lat" if c.endswith("_deg") else c, row.get(c)) for c in cols))
    if len(rows) > limit:
        table.caption = f"first {limit} of {len(rows)} rows"
    Console().print(table)


def _none_located(fixes, rule) -> None:
    """One line when nothing at all was located: the commonest status, what it means and the rule
    (a DEM that does not overlap the flight, a target height above the aircraft, ...)."""
    counts = fixes.status_counts()
    if not len(fixes) or counts.get("OK"):
        return
    name, n = max(counts.items(), key=lambda kv: kv[1])
    what = rule.describe() if isinstance(rule, StopRule) else "range from the files"
    err_console.print(f"[yellow]warning:[/] no target was located ({escape(what)}): {n} of {len(fixes)} are {name}: "
                      f"{escape(Status[name].explanation)}")


FOOTPRINT_HELP = """Frame footprints: the ground outline of every telemetry record's image.

\b
eoloc footprint TELEMETRY.csv --config CAMERA.toml (--target-height H | --dem FILE...) [--edge-samples N]
  The image border (N points per side, clockwise from the top-left corner) is located on the
  ellipsoidal height H or on the DEM. Where the border sees sky or leaves the DEM, the outline is
  clipped at the grazing ray / the DEM edge (found by bisection), never extended to a made-up
  point. Writes footprints.geojson (polygons, RFC 7946) and footprints.csv (one row per frame:
  status, area, vertex counts, the image centre's fix) into --out.
"""


@main.command(help=FOOTPRINT_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path(dir_okay=False))
@click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
              help="Camera/gimbal/installation TOML.")
@target_height_option("Ground: this ellipsoidal height (m).")
@dem_options("Ground: DEM file(s); repeat for several tiles.")
@click.option("--edge-samples", type=click.IntRange(1, 1000), default=16, show_default=True,
              help="Points per image side.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Folder for footprints.geojson and footprints.csv.")
def footprint(telemetry, config_path, target_height, dem_paths, vertical, geoid, dem_crs, edge_samples,
              out_dir) -> None:
    height = target_height
    if (height is None) == (not dem_paths):
        fail("choose the ground: --target-height H (ellipsoidal metres) or --dem FILE")
    surface = open_dem_or_fail(dem_paths, vertical, geoid, dem_crs) if dem_paths else height
    cfg = load_config_or_fail(config_path)
    sensor = cfg.sensor()
    tel, _, issues = read_inputs(telemetry, None, cfg)
    report_issues(issues)
    rows, prints = footprint_rows(sensor, tel, surface, edge_samples)
    out = Path(out_dir)
    geo = write_footprints_geojson(out / "footprints.geojson", prints, rows)
    csv_path = write_csv(out / "footprints.csv", [
        {**r, "status": p.status.name, "area_m2": p.area_m2, "vertices": len(p),
         "clipped_vertices": int(p.clipped.sum()), "centre_lat_deg": p.centre[0], "centre_lon_deg": p.centre[1],
         "centre_h_m": p.centre[2]}
        for r, p in zip(rows, prints, strict=True)])
    counts: dict[str, int] = {}
    for p in prints:
        counts[p.status.name] = counts.get(p.status.name, 0) + 1
    clipped = sum(bool(p.clipped.any()) for p in prints)
    Console().print(f"{len(prints)} footprints: " + ", ".join(f"{k} {v}" for k, v in counts.items())
                    + f"; {clipped} clipped at the horizon or the DEM edge")
    Console().print(f"wrote [bold]{geo}[/] and [bold]{csv_path}[/]")


def footprint_rows(sensor, tel, surface, edge_samples: int, chunk: int = 64):
    """Footprints of every telemetry record, in chunks behind a progress bar -> (rows, footprints)."""
    from rich.progress import Progress

    from .footprint import footprints
    from .io.telemetry import telemetry_pose

    prints = []
    with Progress(console=err_console, transient=True) as bar:
        task = bar.add_task("footprints", total=len(tel))
        for start in range(0, len(tel), chunk):
            idx = np.arange(start, min(start + chunk, len(tel)))
            prints += footprints(sensor, telemetry_pose(tel, idx), surface, edge_samples=edge_samples)
            bar.advance(task, idx.size)
    c = tel.columns
    rows = [{"line": int(tel.line[i]), "time_s": plain_value(c["time_s"][i]), "frame": plain_value(c["frame"][i])}
            for i in range(len(tel))]
    return rows, prints


ACCURACY_HELP = """Accuracy budget by Monte Carlo: perturb every input by its error law, locate with the
same chain as real fixes, and report the scatter per target.

\b
eoloc accuracy CONFIG.toml            the config's [accuracy] section (pose, stop rule, budget)
eoloc accuracy --scenario s13         built-in: s13 ([S13] Table 1), q-ellipsoid, q-dem ([Q] Table 1)
  Prints per target: sigma of lat/lon/h, bias and sigma east/north/up (m), CEP50 (empirical and
  parametric bivariate normal), CE90, LE90, DRMS (a radial RMS, not a CEP); then the sensitivity
  of each source alone (mu = sigma_out / sigma_in, as [S13] defines it). Writes accuracy.csv,
  sensitivity.csv and scatter_target<k>.png (error cloud, CEP circles, mean, 95 % ellipse) into
  --out. Seeded: the same --seed gives the same figures, also on a cluster (--dask ADDRESS, or
  --dask local:N for N local worker processes).
"""

DASK_HELP = ("Run on dask.distributed: a scheduler address (tcp://host:8786), or local[:N] for a local "
             "cluster of N worker processes. Same seed, same figures.")


@main.command(help=ACCURACY_HELP)
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--scenario", type=click.Choice(["s13", "q-ellipsoid", "q-dem"]), default=None,
              help="A built-in scenario instead of a config file.")
@click.option("--samples", "-n", type=click.IntRange(min=2), default=None,
              help="Monte Carlo samples (default: the config's, else the source's: 10^6 for s13, 5000 for [Q]).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the config's, else 0).")
@click.option("--sensitivity/--no-sensitivity", default=True, show_default=True,
              help="Also run each source alone.")
@click.option("--sensitivity-samples", type=click.IntRange(min=2), default=100_000, show_default=True,
              help="Samples per source for the sensitivity table.")
@click.option("--plots/--no-plots", default=True, show_default=True, help="Write the error scatter plots (PNG).")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS", help=DASK_HELP)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Folder for accuracy.csv, sensitivity.csv and the plots.")
def accuracy(config_path, scenario, samples, seed, sensitivity, sensitivity_samples, plots, dask_address,
             out_dir) -> None:
    from .accuracy import monte_carlo
    from .accuracy import sensitivity as run_sensitivity

    scn, n, seed = _scenario_from(config_path, scenario, samples, seed)
    total = n + (len(scn.budget) * sensitivity_samples if sensitivity else 0)
    try:
        with _mapper(dask_address) as mapper, progress() as bar:
            task = bar.add_task("Monte Carlo", total=total)
            result = monte_carlo(scn, n, seed=seed, progress=lambda k: bar.advance(task, k), keep_samples=plots,
                                 mapper=mapper)
            rows_s = run_sensitivity(scn, sensitivity_samples, seed=seed, progress=lambda k: bar.advance(task, k),
                                     mapper=mapper) if sensitivity else []
    except ValueError as exc:
        fail(str(exc))
    console = Console()
    console.print(f"[bold]{scn.name}[/]: {n:,} samples, seed {seed}, stop rule {scn.rule.describe()}; budget: "
                  + ", ".join(f"{s.name} {s.describe()}" for s in scn.budget))
    out_rows = []
    for k, st in enumerate(result.stats):
        out_rows.append({"target": k, "truth_lat_deg": st.truth[0], "truth_lon_deg": st.truth[1],
                         "truth_h_m": st.truth[2], "n": st.n, "failed": st.n_failed,
                         "sigma_lat_deg": st.sigma_lat_deg, "sigma_lon_deg": st.sigma_lon_deg,
                         "sigma_h_m": st.sigma_h_m, "bias_e_m": st.bias_enu[0], "bias_n_m": st.bias_enu[1],
                         "bias_u_m": st.bias_enu[2], "sigma_e_m": st.sigma_enu[0], "sigma_n_m": st.sigma_enu[1],
                         "sigma_u_m": st.sigma_enu[2], "rho_en": st.rho_en, "cep50_m": st.cep50,
                         "cep50_parametric_m": st.cep50_parametric, "ce90_m": st.ce90, "le90_m": st.le90,
                         "drms_m": st.drms, "ellipse_major_m": st.ellipse[0], "ellipse_minor_m": st.ellipse[1],
                         "ellipse_azimuth_deg": st.ellipse[2]})
    table = RichTable(title="scatter per target, about the error-free fix")
    table.add_column("quantity")
    for k in range(len(out_rows)):
        table.add_column(f"target {k}", justify="right")
    labels = {"sigma_lat_deg": "σ lat (deg)", "sigma_lon_deg": "σ lon (deg)", "sigma_h_m": "σ h (m)",
              "bias_e_m": "bias east (m)", "bias_n_m": "bias north (m)", "sigma_e_m": "σ east (m)",
              "sigma_n_m": "σ north (m)", "sigma_u_m": "σ up (m)", "cep50_m": "CEP50, empirical (m)",
              "cep50_parametric_m": "CEP50, bivariate normal (m)", "ce90_m": "CE90 (m)", "le90_m": "LE90 (m)",
              "drms_m": "DRMS (m; not a CEP)", "failed": "samples not located"}
    for key, label in labels.items():
        table.add_row(label, *(f"{r[key]:.4g}" if isinstance(r[key], float) else str(r[key]) for r in out_rows))
    console.print(table)
    out = Path(out_dir)
    written = [write_csv(out / "accuracy.csv", out_rows)]
    if rows_s:
        t2 = RichTable(title=f"sensitivity, each source alone (target 0, {sensitivity_samples:,} samples each)")
        for c in ("source", "law", "μ lat (deg/unit)", "μ lon (deg/unit)", "μ h (m/unit)", "σ horizontal (m)"):
            t2.add_column(c, justify="right")
        for r in rows_s:
            t2.add_row(r.source, r.law, f"{r.mu_lat:.4g}", f"{r.mu_lon:.4g}", f"{r.mu_h:.4g}",
                       f"{r.sigma_horizontal_m:.3g}")
        console.print(t2)
        written.append(write_csv(out / "sensitivity.csv", [vars(r) for r in rows_s]))
    if plots:
        from .accuracy.plots import plot_scatter

        for k in range(min(scn.n_targets, 8)):
            written.append(plot_scatter(result, out / f"scatter_target{k}.png", target=k))
    console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))


def _scenario_from(config_path, scenario, samples, seed, default_n=None):
    """(scenario, samples, seed) from a config's [accuracy] section or a built-in scenario."""
    from .accuracy import SCENARIOS
    from .io.config import accuracy_scenario

    if (config_path is None) == (scenario is None):
        fail("give a CONFIG file with an [accuracy] section, or --scenario s13|q-ellipsoid|q-dem")
    if scenario is not None:
        n = samples or default_n or (1_000_000 if scenario == "s13" else 5000)
        return SCENARIOS[scenario](), n, (0 if seed is None else seed)
    try:
        cfg = load_config(config_path)
        scn = accuracy_scenario(cfg, config_path)
    except ConfigError as exc:
        fail(str(exc))
    return scn, samples or default_n or cfg.accuracy.samples, (cfg.accuracy.seed if seed is None else seed)


def _mapper(address):
    """A context giving the mapper for --dask ADDRESS (None: compute here)."""
    import contextlib

    if address is None:
        return contextlib.nullcontext(None)
    from .accuracy.runners import dask_mapper

    return dask_mapper(address)




SWEEP_HELP = """Accuracy against the pointing angle and the terrain relief, ellipsoid vs DEM ([Q] Fig. 10).


eoloc sweep --scenario q-ellipsoid                       [Q]: gimbal roll 10-82 deg, relief sigma 10-100 m
eoloc sweep CONFIG.toml --angle gimbal2 --angles 20:80:10 --terrain-sigmas 10,50
  For every angle and relief sigma, two Monte Carlo runs: on the ellipsoid at the scenario's
  height with the relief as a terrain-height error, and by M4 on a synthetic relief of that
  sigma around the target. Needs a scenario that stops on the ellipsoid (stop = "height").
  Writes sweep.csv (CEP50 empirical and bivariate normal, CE90, DRMS, sigmas, slant range,
  oblique angle, failed samples) and sweep.png into --out.
"""


def _float_list(text: str) -> list[float]:
    """'10,25,50' or 'start:stop:step' (stop included) -> floats."""
    try:
        if ":" in text:
            a, b, c = (float(x) for x in text.split(":"))
            if c <= 0:
                raise ValueError
            values = [float(x) for x in np.arange(a, b + 0.5 * c, c)]
        else:
            values = [float(x) for x in text.split(",") if x.strip()]
        if not values or not all(np.isfinite(values)):
            raise ValueError
        return values
    except ValueError:
        raise click.BadParameter(f"give finite numbers like 10,25,50 or start:stop:step (step > 0, stop >= start), "
                                 f"got {text!r}") from None


@main.command(help=SWEEP_HELP)
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--scenario", type=click.Choice(["q-ellipsoid"]), default=None, help="A built-in scenario.")
@click.option("--angle", type=click.Choice(["gimbal1", "gimbal2"]), default="gimbal1", show_default=True,
              help="Which gimbal angle to sweep (gimbal1: azimuth / frame roll; gimbal2: elevation / frame pitch).")
@click.option("--angles", default="10:82:8", show_default=True, help="Angles (deg): a,b,c or start:stop:step.")
@click.option("--terrain-sigmas", default="10,25,50,75,100", show_default=True, help="Relief sigmas (m).")
@click.option("--samples", "-n", type=click.IntRange(min=2), default=None,
              help="Monte Carlo samples per point (default 5000, as [Q]).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the config's, else 0).")
@click.option("--dask", "dask_address", default=None, metavar="ADDRESS", help=DASK_HELP)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Folder for sweep.csv and sweep.png.")
def sweep(config_path, scenario, angle, angles, terrain_sigmas, samples, seed, dask_address, out_dir) -> None:
    from .accuracy.plots import plot_sweep
    from .accuracy.sweep import terrain_sweep

    angle_list, sigma_list = _float_list(angles), _float_list(terrain_sigmas)
    scn, n, seed = _scenario_from(config_path, scenario, samples, seed, default_n=5000)
    methods = ("ellipsoid", "dem")
    try:
        with _mapper(dask_address) as mapper, progress() as bar:
            task = bar.add_task("sweep points", total=len(angle_list) * len(sigma_list) * len(methods))
            points = terrain_sweep(scn, angle_list, sigma_list, angle=angle, n=n, seed=seed, methods=methods,
                                   mapper=mapper, progress=lambda k: bar.advance(task, k))
    except ValueError as exc:
        fail(str(exc))
    table = RichTable(title=f"{scn.name}: CEP50 (m), {n:,} samples per point; ellipsoid / DEM")
    table.add_column(f"{angle} (deg)", justify="right")
    for s in sigma_list:
        table.add_column(f"relief σ {s:g} m", justify="right")
    cep = {(p.method, p.angle_deg, p.terrain_sigma_m): p.cep50_m for p in points}
    for a in angle_list:
        table.add_row(f"{a:g}", *(f"{cep[('ellipsoid', a, s)]:.4g} / {cep[('dem', a, s)]:.4g}" for s in sigma_list))
    Console().print(table)
    for p in points:
        if p.note:
            err_console.print(f"[yellow]warning:[/] {p.method} {angle} {p.angle_deg:g}° σ {p.terrain_sigma_m:g} m: "
                              f"{escape(p.note)}")
    out = Path(out_dir)
    csv_path = write_csv(out / "sweep.csv", [vars(p) for p in points])
    png = plot_sweep(points, out / "sweep.png", title=f"{scn.name}: CEP50 against {angle}, {n:,} samples per point")
    Console().print(f"wrote [bold]{csv_path}[/] and [bold]{png}[/]")


@main.command(help="Run the bundled example: a short flight over static targets, located by laser range "
                   "and on the ellipsoid, compared with the known truth; plus the [S13] reference case.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-demo", show_default=True,
              help="Folder for the outputs (CSV and GeoJSON).")
def demo(out_dir) -> None:
    from .demo import run_demo

    run_demo(Path(out_dir), console=Console(), data=resources.files("eoloc") / "data" / "demo")


from . import cli_compensate, cli_rectify, cli_sequence, cli_video  # noqa: E402, F401  (register the other commands)

if __name__ == "__main__":  # pragma: no cover
    main()
