"""`eoloc track`, `eoloc triangulate`, `eoloc calibrate`: commands over many frames."""

from __future__ import annotations

import json
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
from .io.export import fix_rows, write_csv, write_feature_collection, write_geojson
from .pipeline import RANGE_FROM_FILES
from .result import Fixes


def locate_options(fn):
    """Stop rule and pose-matching options shared with `eoloc locate` (file mode)."""
    opts = [
        click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
                     help="Camera/gimbal/installation TOML."),
        click.option("--range", "range_opt", is_flag=False, flag_value=RANGE_FROM_FILES, default=None,
                     help="Stop at a slant range: R metres, or alone to read range_m from the files."),
        target_height_option("Stop rule M3: the targets' ellipsoidal height, metres."),
        dem_options("Stop rule M4: DEM file(s)."),
        click.option("--time-tolerance", type=float, default=0.02, show_default=True,
                     help="Max |Δt| (s) pairing a detection with a telemetry record."),
        click.option("--interpolate", is_flag=True, help="Interpolate the pose to each detection's time."),
        click.option("--max-gap", type=float, default=0.5, show_default=True,
                     help="With --interpolate: longest telemetry gap (s) to interpolate across."),
        click.option("--time-offset", type=float, default=None,
                     help="Telemetry clock minus video clock (s); default: the config's."),
        click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
                     help="Output folder."),
    ]
    for o in reversed(opts):
        fn = o(fn)
    return fn


def _located(telemetry, detections, config_path, range_opt, target_height, dem_paths, vertical, geoid, dem_crs,
             time_tolerance, interpolate, max_gap, time_offset, *, covariance: bool):
    """Locate every detection: (config, located, detections table). With ``covariance`` and an
    [accuracy.budget] in the config, each fix carries its covariance."""
    dem = open_dem_or_fail(dem_paths, vertical, geoid, dem_crs) if dem_paths else None
    rule = stop_rule(range_opt, target_height, dem)
    cfg = load_config_or_fail(config_path)
    tel, det, issues = read_inputs(telemetry, detections, cfg)
    budget = None
    if covariance and cfg.accuracy is not None:
        from .io.config import error_budget

        budget = error_budget(cfg, config_path)
    located = locate_with_config(cfg, tel, det, rule, time_tolerance, budget,
                      dict(interpolate=interpolate, max_gap_s=max_gap, time_offset_s=time_offset))
    report_issues(issues + located.issues)
    if not located.fixes.ok.any():
        fail(f"none of the {len(located.fixes)} detections could be located (see the warnings above); "
              "check the stop rule (--range needs range_m in the files, else give --range R or --target-height H)")
    return cfg, located, det


TRACK_HELP = """Filter detections over time: moving targets into tracks (M7), or static targets by RLS (M6).

\b
eoloc track TELEMETRY.csv DETECTIONS.csv --config CAMERA.toml (--range [R] | --target-height H | --dem F)
  Every detection is located first (as eoloc locate), with its first-order covariance when the
  config has an [accuracy.budget] (else --meas-sigma metres).
  Moving (default): a constant-velocity Kalman filter per target in local ENU (Joseph-form
  update). Detections go to the track of their target_id; --associate ignores the ids and
  assigns each frame's fixes to tracks by gated global nearest neighbour. Writes tracks.geojson
  (LineStrings with coordTimes), track_fixes.csv (filtered position, speed, heading and their
  sigma per detection) and prints a table per track.
  --static: recursive least squares per target_id (--forgetting 1 = all frames alike); writes
  static_targets.csv / .geojson with the estimate, its sigma and CEP50 (the bias share that
  frames cannot average away estimated from the scatter), and the frame where it converged.
"""


@main.command(help=TRACK_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path(dir_okay=False))
@click.argument("detections", type=click.Path(dir_okay=False))
@locate_options
@click.option("--static", is_flag=True, help="Static targets: RLS per target id instead of tracks.")
@click.option("--associate", is_flag=True, help="Ignore target ids: associate fixes to tracks (gated GNN).")
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
def track(telemetry, detections, config_path, range_opt, target_height, dem_paths, vertical, geoid, dem_crs,
          time_tolerance, interpolate, max_gap, time_offset, out_dir, static, associate, forgetting, accel_psd,
          meas_sigma, max_coast, window) -> None:
    cfg, located, det = _located(telemetry, detections, config_path, range_opt, target_height, dem_paths, vertical,
                                 geoid, dem_crs, time_tolerance, interpolate, max_gap, time_offset, covariance=True)
    t = np.asarray(located.extra["time_s"], dtype=np.float64)
    if not np.isfinite(t[located.fixes.ok]).all():
        fail("tracking needs time_s in the detections file (frame numbers alone give no time)")
    cov = None if located.covariance is None else located.covariance.cov_enu
    ids = np.asarray(located.extra["target_id"]).astype(str)
    out = Path(out_dir)
    if static:
        _static(located.fixes, cov, ids, t, forgetting, meas_sigma, window, out)
        return
    from .sequence.track import TrackerConfig, track_features, track_fixes

    with progress() as bar:
        task = bar.add_task("tracking", total=None)
        ts = track_fixes(t, located.fixes, cov, None if associate else ids, associate=associate,
                         config=TrackerConfig(accel_psd=accel_psd, meas_sigma_m=meas_sigma, max_coast_s=max_coast),
                         progress=lambda k, n: bar.update(task, completed=k, total=n))
    rows = _track_rows(ts, located, cov is not None)
    csv_path = write_csv(out / "track_fixes.csv", rows)
    geo = write_feature_collection(out / "tracks.geojson", track_features(ts), indent=1)
    table = RichTable(title=f"{len(ts.tracks)} tracks from {int(located.fixes.ok.sum())} located detections")
    for c in ("track", "updates", "from (s)", "to (s)", "speed (m/s)", "heading (°)"):
        table.add_column(c, justify="right")
    for f in track_features(ts):
        p = f["properties"]
        table.add_row(p["track_id"], str(p["updates"]), f"{p['start_s']:g}", f"{p['end_s']:g}",
                      f"{p['speed_mps']:.2f} ± {p['speed_sigma_mps']:.2f}", f"{p['heading_deg']:.1f}")
    Console().print(table)
    left = int(np.sum((ts.assigned == "") & np.ravel(located.fixes.ok)))
    if left:
        err_console.print(f"[yellow]warning:[/] {left} located detections joined no confirmed track "
                          "(clutter, or a target seen fewer than 3 times)")
    Console().print(f"wrote [bold]{geo}[/] and [bold]{csv_path}[/]")


def _track_rows(ts, located, with_cov: bool) -> list[dict]:
    """Per detection: its fix, the track it joined and the filtered state there."""
    n = len(located.fixes)
    cols = {k: np.full(n, np.nan) for k in ("filt_lat_deg", "filt_lon_deg", "speed_mps", "speed_sigma_mps",
                                             "heading_deg", "sigma_e_m", "sigma_n_m")}
    for tr in ts.tracks:
        lat, lon, _ = ts.geodetic(tr)
        idx = np.asarray(tr.detection)
        P = np.asarray(tr.cov)
        cols["filt_lat_deg"][idx], cols["filt_lon_deg"][idx] = lat, lon
        cols["speed_mps"][idx], cols["speed_sigma_mps"][idx] = tr.speed_mps, tr.speed_sigma_mps
        cols["heading_deg"][idx] = tr.heading_deg
        first = idx[:1]  # a track's first fix: position only, its speed and course are not known yet
        cols["speed_mps"][first] = cols["speed_sigma_mps"][first] = cols["heading_deg"][first] = np.nan
        cols["sigma_e_m"][idx], cols["sigma_n_m"][idx] = np.sqrt(P[:, 0, 0]), np.sqrt(P[:, 1, 1])
    extra = dict(located.extra)
    extra["track_id"] = ts.assigned
    return fix_rows(located.fixes, extra, cols)


SCATTER_LIMIT = 3.0  # scatter ratio (mean chi^2 / 2 per frame, 1 expected) past which a "static" target is not


def _static(fixes: Fixes, cov, ids, t, forgetting, meas_sigma, window, out: Path) -> None:
    from .sequence.rls import rls_static

    rows = []
    for tid in sorted(set(ids.tolist())):
        sel = np.flatnonzero(ids == tid)
        sel = sel[np.argsort(t[sel], kind="stable")]
        f = fixes.flat(sel)
        if not f.ok.any():
            rows.append({"target_id": tid, "frames": int(sel.size), "used": 0, "status": "NO_FIX"})
            continue
        est = rls_static(f, None if cov is None else cov.reshape(-1, 3, 3)[sel], sigma_m=meas_sigma,
                         forgetting=forgetting, window=window)
        ok_f = np.flatnonzero(f.ok)
        single = np.hypot(est.sigma_m[ok_f[0], 0], est.sigma_m[ok_f[0], 1])  # the first fix's own sigma
        conv = int(est.converged_frame)
        s = np.sqrt(np.diagonal(est.cov_enu))
        # frames that spread far more than their sigma allows: the target moved (or the sigma is
        # optimistic), so the "static" model is rejected and averaging does not shrink the error.
        # The uncertainty becomes the fixes' own scatter (one frame's sigma times sqrt(ratio)), said.
        ratio = float(est.scatter_ratio)
        inflate = 1.0
        if ratio > SCATTER_LIMIT:
            inflate = max(np.sqrt(ratio), single / np.sqrt(2.0) * np.sqrt(ratio) / float(np.mean(s[:2])))
        s = s * inflate
        warning = "" if inflate == 1.0 else (
            f"the {int(est.n_used)} fixes scatter {ratio:.1f}x more than their sigma allows (> {SCATTER_LIMIT:g}): "
            f"the target moves, or the sigma is optimistic; its uncertainty is the fixes' own scatter, "
            f"{inflate:.1f}x the static estimate's (for a moving target use eoloc track without --static)")
        rows.append({"target_id": tid, "frames": int(sel.size), "used": int(est.n_used),
                     "lat_deg": float(est.lat_deg), "lon_deg": float(est.lon_deg), "h_m": float(est.h_m),
                     "sigma_e_m": float(s[0]), "sigma_n_m": float(s[1]), "sigma_u_m": float(s[2]),
                     "cep50_m": float(est.cep50_m) * inflate, "first_fix_sigma_h_m": float(single),
                     "scatter_ratio": ratio, "converged_at_s": float(t[sel][conv]) if conv >= 0 else None,
                     "status": "OK", "warning": warning})
    def cells(r):
        if r["status"] != "OK":
            return [r["target_id"], f"0/{r['frames']}", "", "", "", "", "no fix"]
        conv = "no" if r["converged_at_s"] is None else f"{r['converged_at_s']:g} s"
        return [r["target_id"], f"{r['used']}/{r['frames']}", f"{r['lat_deg']:.6f}, {r['lon_deg']:.6f}",
                f"{r['h_m']:.1f}", f"{r['cep50_m']:.1f}", f"{r['scatter_ratio']:.2f}", conv]

    _emit(out, "static_targets", rows, "static targets: recursive least squares over all frames",
          ("target", "fixes", "lat, lon (°)", "h (m)", "CEP50 (m)", "scatter", "converged"), cells)
    Console().print("scatter: the frames' scatter against their declared sigma (1 = independent errors that "
                    "average away; near 0 = a common bias that no number of frames removes)")
    for r in rows:
        if r.get("warning"):
            err_console.print(f"[yellow]warning:[/] target {escape(r['target_id'])}: {escape(r['warning'])}")


def _emit(out: Path, stem: str, rows: list[dict], title: str, columns: tuple[str, ...], cells) -> None:
    """Write rows as <stem>.csv and <stem>.geojson and print them as a table (``cells(row)`` -> strings)."""
    paths = write_csv(out / f"{stem}.csv", rows), write_geojson(out / f"{stem}.geojson", rows)
    table = RichTable(title=title)
    for c in columns:
        table.add_column(c, justify="right")
    for r in rows:
        table.add_row(*cells(r))
    Console().print(table)
    Console().print(f"wrote [bold]{paths[0]}[/] and [bold]{paths[1]}[/]")


TRIANGULATE_HELP = """Multi-view triangulation (M8): each target seen from two or more poses, located
without a range or a terrain model by intersecting its rays.

\b
eoloc triangulate TELEMETRY.csv DETECTIONS.csv --config CAMERA.toml [--ray-sigma-deg S]
  Groups the detections by target_id; writes triangulated.csv / .geojson with the point, its
  sigma east/north/up, the ray residuals, the widest angle between the rays and a warning when
  the baseline is too short for the range. When the rays scatter more than --ray-sigma-deg says
  (s0 > 1, from three rays on), the sigmas are scaled up by s0; they are never scaled down.
"""


@main.command(help=TRIANGULATE_HELP + CONVENTIONS)
@click.argument("telemetry", type=click.Path(dir_okay=False))
@click.argument("detections", type=click.Path(dir_okay=False))
@click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
              help="Camera/gimbal/installation TOML.")
@click.option("--ray-sigma-deg", type=click.FloatRange(0.0, min_open=True), default=0.05, show_default=True,
              help="Angular 1-sigma of each ray (attitude + gimbal + pixel).")
@click.option("--min-angle", type=click.FloatRange(0.0), default=2.0, show_default=True,
              help="Warn below this angle (deg) between the rays.")
@click.option("--time-tolerance", type=float, default=0.02, show_default=True,
              help="Max |Δt| (s) pairing a detection with a telemetry record.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Output folder.")
def triangulate(telemetry, detections, config_path, ray_sigma_deg, min_angle, time_tolerance, out_dir) -> None:
    from .io.telemetry import match_detections, telemetry_pose
    from .rules.multiview import triangulate as tri

    cfg = load_config_or_fail(config_path)
    sensor = cfg.sensor()
    tel, det, issues = read_inputs(telemetry, detections, cfg)
    matched = match_detections(tel, det, time_tolerance_s=time_tolerance)
    report_issues(issues + matched.issues)
    has = matched.record >= 0
    pose = telemetry_pose(tel, np.where(has, matched.record, 0))
    rays = sensor.rays(pose, (det.columns["u_px"], det.columns["v_px"]))
    ids = np.asarray(det.columns["target_id"]).astype(str)
    rows = []
    for tid in sorted(set(ids.tolist())):
        sel = np.flatnonzero((ids == tid) & has)
        row = {"target_id": tid, "rays": int(sel.size)}
        try:
            r = tri(rays.take(sel), np.radians(ray_sigma_deg), min_angle_deg=min_angle)
        except ValueError as exc:
            rows.append({**row, "status": "TOO_FEW_RAYS", "warning": str(exc)})
            continue
        if not r.ok:
            rows.append({**row, "max_angle_deg": r.max_angle_deg, "status": r.status.name, "warning": r.warning})
            continue
        s = r.sigma_enu * max(1.0, r.s0)
        rows.append({**row, "lat_deg": r.lat_deg, "lon_deg": r.lon_deg, "h_m": r.h_m, "sigma_e_m": s[0],
                     "sigma_n_m": s[1], "sigma_u_m": s[2], "s0": r.s0,
                     "rms_residual_m": float(np.sqrt(np.mean(r.residuals_m**2))),
                     "max_angle_deg": r.max_angle_deg, "status": "OK", "warning": r.warning})

    def cells(r):
        if r["status"] != "OK":
            return [r["target_id"], str(r["rays"]), "", "", "", "", ""]
        return [r["target_id"], str(r["rays"]), f"{r['lat_deg']:.7f}", f"{r['lon_deg']:.7f}", f"{r['h_m']:.1f}",
                f"{r['sigma_e_m']:.1f}/{r['sigma_n_m']:.1f}/{r['sigma_u_m']:.1f}", f"{r['max_angle_deg']:.1f}"]

    _emit(Path(out_dir), "triangulated", rows, "triangulated targets (M8)",
          ("target", "rays", "lat (°)", "lon (°)", "h (m)", "σ e/n/u (m)", "angle (°)"), cells)
    for r in rows:
        if r.get("warning"):
            err_console.print(f"[yellow]warning:[/] target {escape(r['target_id'])}: {escape(r['warning'])}")


CALIBRATE_HELP = """Boresight / mounting calibration from ground control points seen in frames.

\b
eoloc calibrate TELEMETRY.csv GCPS.csv --config CAMERA.toml [--estimate mount,heading,time] [--write]
  GCPS.csv columns: time_s or frame, gcp_id, u_px, v_px (where the GCP is in that image), and the
  GCP's surveyed lat_deg, lon_deg, h_m (ellipsoidal). Each observation's pose is the matching
  telemetry record, or interpolated (--interpolate; always when the time offset is estimated).
  --estimate: any of mount (3 angles, gimbal base vs INS), boresight (3 angles, optical axis vs
  gimbal), heading (INS heading bias), time (telemetry minus video clock). Least squares on the
  pixel residuals; prints the values with their sigma, correlations that the geometry cannot
  separate, outliers, and the residuals before/after in pixels and metres on the ground.
  --write puts the result into the config file ([installation] / [telemetry]), comments kept;
  every later eoloc command then uses it.
"""


@main.command(help=CALIBRATE_HELP)
@click.argument("telemetry", type=click.Path(dir_okay=False))
@click.argument("gcps", type=click.Path(dir_okay=False))
@click.option("--config", "config_path", required=True, type=click.Path(dir_okay=False),
              help="Camera/gimbal/installation TOML (the starting values).")
@click.option("--estimate", default="mount", show_default=True,
              help="Comma-separated: mount, boresight, heading, time.")
@click.option("--pixel-sigma", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True,
              help="1-sigma of a GCP's pixel position (px).")
@click.option("--robust", is_flag=True, help="Soft-L1 loss: misidentified GCPs pull less.")
@click.option("--interpolate", is_flag=True, help="Interpolate the pose to each observation's time.")
@click.option("--max-gap", type=float, default=0.5, show_default=True, help="Longest telemetry gap (s) to bridge.")
@click.option("--time-tolerance", type=float, default=0.02, show_default=True,
              help="Max |Δt| (s) pairing an observation with a record (without --interpolate).")
@click.option("--write", "write_back", is_flag=True, help="Write the result into the config file.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Folder for calibration.json and gcp_residuals.csv.")
def calibrate(telemetry, gcps, config_path, estimate, pixel_sigma, robust, interpolate, max_gap, time_tolerance,
              write_back, out_dir) -> None:
    from .calibration import GROUPS, TelemetryTrack
    from .calibration import calibrate as solve
    from .io.telemetry import match_detections, read_gcps, telemetry_pose

    groups = tuple(e.strip() for e in estimate.split(",") if e.strip())
    bad = [g for g in groups if g not in GROUPS]
    if bad or not groups:
        fail(f"--estimate: unknown {bad or groups}; choose from {', '.join(GROUPS)}")
    cfg = load_config_or_fail(config_path)
    sensor = cfg.sensor()
    # the raw telemetry: the config's heading bias is the starting value, not a correction here
    tel, obs, issues = read_inputs(telemetry, gcps, cfg.model_copy(update={"telemetry": type(cfg.telemetry)()}),
                                    reader=read_gcps)
    hb0, dt0 = cfg.telemetry.heading_bias_deg, cfg.telemetry.time_offset_s
    kw = {}
    keep = np.ones(len(obs), dtype=bool)
    if interpolate or "time" in groups:
        tt, to = tel.columns["time_s"], obs.columns["time_s"]
        if not (np.isfinite(tt).any() and np.isfinite(to).all()):
            fail("interpolation / the time offset needs time_s in both the telemetry and the GCP file")
        kw = {"telemetry": TelemetryTrack(tt, telemetry_pose(tel), max_gap), "time_s": to}
    else:
        m = match_detections(tel, obs, time_tolerance_s=time_tolerance)
        issues += m.issues
        keep = m.record >= 0
        kw = {"pose": telemetry_pose(tel, m.record[keep])}
    report_issues(issues)
    c = obs.columns
    uv = np.c_[c["u_px"], c["v_px"]][keep]
    llh = np.c_[c["lat_deg"], c["lon_deg"], c["h_m"]][keep]
    try:
        with err_console.status(f"solving for {', '.join(groups)} from {int(keep.sum())} GCP observations..."):
            cal = solve(sensor, uv, llh, estimate=groups, pixel_sigma_px=pixel_sigma, heading_bias_deg=hb0,
                        time_offset_s=dt0, robust=robust, **kw)
    except ValueError as exc:
        fail(str(exc))
    _print_calibration(cal, sensor, hb0, dt0)
    gid = np.asarray(c["gcp_id"])[keep]
    lines = np.asarray(obs.line)[keep]
    rows = [{"line": int(lines[i]), "gcp_id": str(gid[i]), "used": bool(cal.used[i]),
             "du_before_px": cal.residual_px_before[i, 0], "dv_before_px": cal.residual_px_before[i, 1],
             "du_after_px": cal.residual_px_after[i, 0], "dv_after_px": cal.residual_px_after[i, 1],
             "ground_error_before_m": cal.ground_error_before_m[i],
             "ground_error_after_m": cal.ground_error_after_m[i]} for i in range(gid.size)]
    out = Path(out_dir)
    csv_path = write_csv(out / "gcp_residuals.csv", [{k: _plain(v) for k, v in r.items()} for r in rows])
    js = out / "calibration.json"
    report = {"parameters": cal.as_dict(), "sigma": dict(zip(cal.names, cal.sigma.tolist(), strict=True)),
              "correlation": cal.correlation.tolist(), "s0": cal.s0, "undetermined": cal.undetermined,
              "rms_px_before": cal.rms(cal.residual_px_before), "rms_px_after": cal.rms(cal.residual_px_after),
              "rms_ground_m_before": cal.rms(cal.ground_error_before_m),
              "rms_ground_m_after": cal.rms(cal.ground_error_after_m), "warnings": cal.warnings}
    # JSON has no NaN or Infinity: an unknown sigma or correlation is null
    js.write_text(json.dumps(_json_safe(report), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    if write_back and cal.undetermined:
        fail(f"not writing {config_path}: these observations do not determine {', '.join(cal.undetermined)} "
              f"(see {js}); add GCPs seen from other attitudes or look directions, or leave them out of --estimate")
    if write_back:
        from .io.config import ConfigError, write_calibration

        try:
            write_calibration(config_path,
                              mount_misalignment_deg=cal.sensor.mount_misalignment_deg if "mount" in groups else None,
                              boresight_misalignment_deg=cal.sensor.boresight_misalignment_deg
                              if "boresight" in groups else None,
                              heading_bias_deg=cal.heading_bias_deg if "heading" in groups else None,
                              time_offset_s=cal.time_offset_s if "time" in groups else None)
        except ConfigError as exc:
            fail(str(exc))
        Console().print(f"updated [bold]{config_path}[/]")
    Console().print(f"wrote [bold]{js}[/] and [bold]{csv_path}[/]")


def _json_safe(v):
    """Floats that are not finite -> None, through dicts and lists."""
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    return v


def _plain(v):
    return None if isinstance(v, float) and np.isnan(v) else (float(v) if isinstance(v, np.floating) else v)


def _print_calibration(cal, sensor, hb0: float, dt0: float) -> None:
    start = {**dict(zip(("mount_x_deg", "mount_y_deg", "mount_z_deg"), sensor.mount_misalignment_deg, strict=True)),
             **dict(zip(("boresight_x_deg", "boresight_y_deg", "boresight_z_deg"), sensor.boresight_misalignment_deg,
                        strict=True)), "heading_bias_deg": hb0, "time_offset_s": dt0}
    t = RichTable(title=f"calibration from {int(cal.used.sum())} GCP observations (s0 = {cal.s0:.2f})")
    for col in ("parameter", "was", "estimate", "± 1σ"):
        t.add_column(col, justify="right")
    for name, v, s in zip(cal.names, cal.values, cal.sigma, strict=True):
        t.add_row(name, f"{start[name]:.4f}", f"{v:.4f}", f"{s:.4f}")
    Console().print(t)
    r = RichTable(title="residuals (RMS)")
    for col in ("", "before", "after"):
        r.add_column(col, justify="right")
    r.add_row("pixels", f"{cal.rms(cal.residual_px_before):.2f}", f"{cal.rms(cal.residual_px_after):.2f}")
    r.add_row("ground (m)", f"{cal.rms(cal.ground_error_before_m):.2f}", f"{cal.rms(cal.ground_error_after_m):.2f}")
    Console().print(r)
    if cal.s0 > 1.5:
        err_console.print(f"[yellow]note:[/] s0 = {cal.s0:.2f}: the residuals are larger than --pixel-sigma says "
                          "(telemetry noise shows in pixels too); the sigmas above are scaled by s0")
    for w in cal.warnings:
        err_console.print(f"[yellow]warning:[/] {escape(w)}")

