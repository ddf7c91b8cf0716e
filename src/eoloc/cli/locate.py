"""`eoloc locate`: geolocate targets from files, or one observation given as options."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from ..result import Status
from .common import load_config, open_dem, stop_rule, working
from .main import console, err_console, exit_if_nothing_located, fail, report_issues, warn
from .options import (
    CONVENTIONS,
    config_option,
    flight_log_option,
    formats_option,
    grid_option,
    json_option,
    out_option,
    pairing_options,
    poses_option,
    refine_option,
    stop_rule_options,
    with_flight_log,
)
from .render import fix_summary_table, number_cell, titled_table

LOCATE_HELP = """Geolocate targets: from files, or one observation given as options.

\b
FILE MODE:  eoloc locate TELEMETRY.csv [DETECTIONS.csv] --config CAMERA.toml
              (--range [R] | --target-height H | --dem F)
  TELEMETRY.csv columns: time_s and/or frame, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg,
    roll_deg, gimbal1_deg, gimbal2_deg (or azimuth_deg, elevation_deg / frame_roll_deg,
    frame_pitch_deg), optional sensor_roll_deg, optional range_m (laser slant range).
    Instead of h_m: h_msl_m (EGM96). Instead of yaw/pitch/roll: qw,qx,qy,qz (body->NED,
    scalar first) or dcm_11..dcm_33 (R_ned_body). A zoom lens: hfov_deg, focal_px or
    focal_mm per record. (README: Input formats.)
  TELEMETRY may also be any other source eoloc reads, told apart by its content: MISB ST 0601
    KLV (raw or MPEG-TS), a DJI .SRT, an Airdata flight log, a drone photo or a folder of them
    (their camera comes from the photos: --config optional). Drones give the camera's own
    attitude (DJI gimbal yaw/pitch/roll, earth-referenced): the config's gimbal is not used;
    heights above the take-off point need --dem (README: Telemetry sources).
  DETECTIONS.csv columns: time_s or frame, target_id, u_px, v_px, optional range_m.
  Without DETECTIONS the image centre of every record is located.
  --range alone takes each target's range_m from the files; --range R uses R metres for all;
  --target-height H stops at ellipsoidal height H; --dem FILE (repeat for
  tiles: GeoTIFF, DTED, SRTM .hgt/.zip, ESRI ASCII) stops at the first hit on the terrain
  (heights taken as EGM96 and converted with the bundled geoid unless --vertical says otherwise).
  Writes fixes.csv and fixes.geojson into --out (--format adds kml, cot). Bad lines are
  reported (file:line) and skipped; every good record is kept. --json prints the rows as JSON.
  --interpolate: each detection's pose is interpolated to its time_s (position by a spline in
  ECEF, attitude by slerp, gimbal angles unwrapped) instead of the nearest record; --time-offset
  S is the telemetry clock minus the video clock; detections in a gap longer than --max-gap are
  reported and get NO_TELEMETRY, never a bridged pose.
  --covariance adds each fix's first-order uncertainty from the config's [accuracy.budget]:
  sigma east/north/up, CEP50/CE90, LE90, the error ellipse, and a nonlinearity figure (> 0.1:
  the linearisation does not hold there, e.g. a ray grazing a ridge; use eoloc accuracy).
  --refine: TELEMETRY refined from its own images first (eoloc refine into OUT/refine/, --dem
  needed): an MPEG-TS with its video is located from its refined copy (NAME_refined.ts; with
  --config, NAME_refined.toml: no installation left to apply, the budget what refinement left
  unknown); drone photos with their refined poses. --poses FILE: photos with eoloc refine's poses.

\b
ONE OBSERVATION:  eoloc locate --lat 42 --lon 125 --aircraft-height 10000 --yaw 10 --pitch 5
                  --roll -2 --gimbal az-el --gimbal-angles 45 -75 --range 10200 [--json]
  --aircraft-height is the aircraft's ellipsoidal height (m); the stop rule as in file mode;
  --pixel U V needs --config for the camera (image centre when omitted).
"""


@click.command(help=LOCATE_HELP + CONVENTIONS)
@click.argument("telemetry", required=False, type=click.Path())
@click.argument("detections", required=False, type=click.Path(dir_okay=False))
@config_option(required=False)
@stop_rule_options
@click.option("--aircraft-height", "height", type=float, metavar="H",
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
@click.option("--sensor-roll", type=float, default=0.0, show_default=True,
              help="Sensor roll about the boresight, degrees.")
@click.option("--pixel", nargs=2, type=float, default=None, metavar="U V",
              help="One observation: the pixel (column, row; needs --config).")
@json_option()
@out_option("fixes.* (file mode)")
@formats_option()
@grid_option()
@pairing_options
@click.option("--covariance", is_flag=True,
              help="Add each fix's first-order uncertainty from the config's [accuracy.budget].")
@click.option("--compensate", "compensate_path", type=click.Path(dir_okay=False), default=None, metavar="MODEL",
              help="File mode: add a learned error correction (eoloc compensate train) to every fix inside the "
                   "model's trained range and report it per fix (default: the config's [compensation] model).")
@flight_log_option
@poses_option("(For TELEMETRY that is drone photos.)")
@refine_option("TELEMETRY from its own images (eoloc refine, its defaults, into OUT/refine/; needs --dem): an MPEG-TS "
               "with its video (then located from OUT/refine/NAME_refined.ts, with --config NAME_refined.toml) or "
               "overlapping drone photos (located with their refined poses).")
def locate(telemetry, detections, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, height,
           lat, lon, yaw, pitch, roll, gimbal, gimbal_angles, sensor_roll, pixel, as_json, out_dir, formats,
           grid, time_tolerance, interpolate, max_gap, time_offset, covariance, compensate_path, flight_log, poses_path,
           refine_first) -> None:
    if (refine_first or poses_path) and telemetry is None:
        fail("--refine and --poses belong to file mode: give a TELEMETRY file (an MPEG-TS with its video, or photos)")
    if refine_first and poses_path:
        fail("give --refine or --poses FILE, not both")
    if refine_first and flight_log:
        fail("--refine takes the telemetry in the video itself, not --flight-log (refine the video with its log: "
             "eoloc video VIDEO --telemetry FILE --flight-log LOG --refine)")
    telemetry = with_flight_log(telemetry, flight_log)
    budget = None
    if covariance:
        if config_path is None:
            fail("--covariance needs --config FILE with an [accuracy.budget] section (the error sources)")
        from ..jobs.setup import error_budget

        budget = error_budget(load_config(config_path), config_path)
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    if telemetry is None:
        if detections is not None or interpolate or compensate_path:
            fail("--interpolate, --compensate and a DETECTIONS file belong to file mode: give a TELEMETRY file")
        from ..kernels.backend import few_targets

        with few_targets():
            _locate_one(config_path, rule_values, height, lat, lon, yaw, pitch, roll, gimbal,
                        gimbal_angles, sensor_roll, pixel, as_json, dem, budget)
        return
    if lat is not None or lon is not None or height is not None or pixel is not None or gimbal_angles is not None:
        fail("give either a TELEMETRY file or --lat/--lon/--aircraft-height/--gimbal-angles/--pixel for one "
             "observation, not both")
    if interpolate and detections is None:
        fail("--interpolate needs a DETECTIONS file (the image centres are located at the records themselves)")
    rule = stop_rule(rule_values, dem)
    poses = None
    if refine_first:
        telemetry, config_path, poses, poses_path = _refined(telemetry, config_path, dem, time_offset, max_gap,
                                                             Path(out_dir) / "refine")
        if budget is not None:  # the refined config: what refinement left unknown
            from ..jobs.setup import error_budget

            budget = error_budget(load_config(config_path), config_path)
    elif poses_path is not None:
        from ..io.photo import read_photo_poses

        poses = read_photo_poses(poses_path)
    if detections is not None:  # read while the configuration loads (~70 ms off 10^6 detections)
        from ..io.telemetry import read_detections
        from ..jobs.inputs import Prefetch

        detections = Prefetch(read_detections, detections)
    cfg = load_config(config_path) if config_path else None  # drone photos carry their camera
    from ..io.export import json_safe
    from ..io.writers import write_layer
    from ..jobs.locate import locate_files
    from ..jobs.setup import compensation_model

    if cfg is None and compensate_path:
        fail("--compensate needs --config (the model was trained for a configured sensor)")
    model = compensation_model(cfg, config_path, compensate_path) if cfg is not None else None
    with working("locating..."):
        job = locate_files(cfg, telemetry, detections, rule, time_tolerance_s=time_tolerance, budget=budget,
                           interpolate=interpolate, max_gap_s=max_gap, time_offset_s=time_offset, compensation=model,
                           poses=poses, poses_from=str(poses_path or ""))
    report_issues(job.issues)
    written = write_layer(out_dir, "fixes", job.records, formats, grid=grid)
    if as_json:
        click.echo(json.dumps(json_safe({"status_counts": job.status_counts, "written": [str(p) for p in written],
                                         "fixes": job.records.rows()}), allow_nan=False))
    else:
        console.print(fix_summary_table(job.records, job.status_counts))
    if job.compensation_summary:
        err_console.print(job.compensation_summary, highlight=False)
    for note in job.notes:
        warn(note)
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
    exit_if_nothing_located(job.located.fixes)


def _refined(telemetry, config_path, dem, time_offset, max_gap: float, out: Path):
    """``--refine``: (telemetry, config, photo poses, their file) to locate with: a video's refined
    TS and its config, or the photos with their refined poses."""
    from ..io.sources import identify
    from ..io.sources.photos import DronePhotos
    from .refined import refine_photos_first, refine_video_first

    kind = identify(telemetry).name
    if kind == DronePhotos.name:
        poses, poses_path, config = refine_photos_first([telemetry], dem, out, config_path)
        return telemetry, config, poses, poses_path
    if kind != "klv":
        raise click.UsageError(f"--refine refines telemetry from its own images (an MPEG-TS with its video, or drone "
                               f"photos); {telemetry} is {kind} telemetry without them: refine it with its video "
                               "(eoloc refine VIDEO --telemetry FILE --config C.toml --dem F, then locate "
                               "OUT/telemetry_refined.csv with OUT/config_refined.toml)")
    if time_offset is not None:
        raise click.UsageError("--refine estimates the clock offset itself: leave out --time-offset")
    ts_path, _, ts_config = refine_video_first(telemetry, None, config_path, dem, out, max_gap_s=max_gap)
    return ts_path, ts_config, None, None


def _locate_one(config_path, rule_values, height, lat, lon, yaw, pitch, roll, gimbal, gimbal_angles,
                sensor_roll, pixel, as_json, dem=None, budget=None) -> None:
    from ..jobs.tables import locate_by_rule
    from ..sensor import Camera, GimbalKind, Pose, SensorModel, gimbal_from_name

    if lat is None or lon is None or height is None:
        fail("one observation needs --lat, --lon and --aircraft-height (ellipsoidal m), or give a TELEMETRY file")
    rule = stop_rule(rule_values, dem)
    from ..rules import RangeFromRecords

    if isinstance(rule, RangeFromRecords):
        fail("--range needs a value (metres) for one observation")
    if config_path is not None:
        sensor = load_config(config_path).sensor()
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
        from ..accuracy.covariance import covariance_columns

        out.update({k: _num(v[0]) for k, v in covariance_columns(cov, f.ok).items()})
    if as_json:
        click.echo(json.dumps(out))
    else:
        table = titled_table("eoloc fix", show_header=True)
        for k in ("lat", "lon", "h", "range", "status"):
            table.add_column(k + {"lat": " (deg)", "lon": " (deg)", "h": " (m, ellipsoidal)",
                                  "range": " (m)"}.get(k, ""))
        table.add_row(*(number_cell(k, out[k]) for k in ("lat", "lon", "h", "range", "status")))
        console.print(table)
        if cov is not None and status == Status.OK:
            _print_uncertainty(out)
    if status != Status.OK:
        from ..jobs.explain import explain_failures, telemetry_names

        names = {**telemetry_names(sensor.gimbal.angle_names, rule), "lat_deg": "--lat", "lon_deg": "--lon",
                 "h_m": "--aircraft-height", "yaw_deg": "--yaw", "pitch_deg": "--pitch", "roll_deg": "--roll",
                 "u_px": "--pixel", "v_px": "--pixel",
                 **{f"gimbal{i + 1}": f"--gimbal-angles ({a})" for i, a in enumerate(sensor.gimbal.angle_names)}}
        warn(explain_failures(f, pose=pose, pixels=pixels, rule=rule, names=names, what="observation")
             or f"{status.name}: {status.explanation}")
    exit_if_nothing_located(f)


def _print_uncertainty(u: dict) -> None:
    console.print(f"1σ east {u['sigma_e_m']:.3g} m, north {u['sigma_n_m']:.3g} m, up {u['sigma_u_m']:.3g} m; "
                  f"CEP50 {u['cep50_m']:.3g} m, CE90 {u['ce90_m']:.3g} m, LE90 {u['le90_m']:.3g} m; "
                  f"ellipse {u['ellipse_major_m']:.3g} × {u['ellipse_minor_m']:.3g} m at "
                  f"{u['ellipse_azimuth_deg']:.1f}°")
    nl = u["nonlinearity"]
    if nl is None or nl > 0.1:
        warn(f"the first-order uncertainty does not hold for this fix (nonlinearity {nl if nl is not None else 'inf'}"
             "): a ray near grazing or near an edge; run eoloc accuracy for a Monte Carlo of it")


def _num(x) -> float | None:
    x = float(x)
    return None if not np.isfinite(x) else x
