"""`eoloc refine`: what the telemetry gets wrong, estimated from the video's own pixels."""

from __future__ import annotations

import click

from .common import load_config, open_dem
from .main import console, err_console, report_issues, warn
from .options import config_option, dem_options, out_option
from .render import titled_table

REFINE_HELP = """Refine the telemetry of a video, or the poses of a photo set, from the pixels themselves:
tie points and a bundle adjustment, no ground control needed.

\b
  eoloc refine FLIGHT.mp4 --telemetry TEL.csv --config CAMERA.toml --dem DEM.tif --out out/
  eoloc video FLIGHT.mp4 --telemetry out/telemetry_refined.csv --config out/config_refined.toml --dem DEM.tif
  eoloc refine FLIGHT.ts --dem DEM.tif --out out/      (the ST 0601 KLV in the video's own TS)
  eoloc refine PHOTO|FOLDER... --dem DEM.tif [--json]
  (or --refine on eoloc video, photo, klv and locate: refined first into OUT/refine/, then run)

\b
Photos (no --telemetry): overlapping drone photos (any vendor eoloc photo reads; a folder stands
for its photos). Estimated by default: a mounting error and a heading bias (the gimbal yaw's)
shared by the set; no time offset. --json prints one object per photo with its refined pose under
eoloc photo --json's keys (file, camera_lat, camera_lon, camera_h, camera_yaw, camera_pitch,
camera_roll), their 1-sigma (sigma_camera_yaw ...; the position is not estimated: null) and the
attitude as given (given_camera_yaw ...); photos_refined.csv, refine.json, residuals.png, geo.txt
(OpenDroneMap's) and xmp/NAME.xmp go into --out: each photo's own XMP packet with the refined
attitude in its vendor's tags (and a position refined with --reference, where the XMP has it), a
sidecar for exiftool -tagsfromfile NAME.xmp -xmp:all NAME.JPG.

\b
What it estimates (--estimate, comma-separated): mount (the turret base's three small angles to the
INS body axes, deg), boresight (the optical axis' three angles to the gimbal, deg), heading (the INS
heading bias, deg: measured = true + bias), time (the telemetry clock minus the video clock, s),
position (the GPS position's bias east, north, up, m: measured = true + bias; needs --reference or
strong relief), each around the config's value with a prior 1-sigma (--prior-mount, --prior-heading,
--prior-time, --prior-position; by default what the config's [accuracy.budget] says of them).
Keyframes every --every-s seconds; the frames that overlap are predicted from the poses and the DEM
(no all-pairs matching); SIFT tie points matched between them (ratio test, RANSAC), joined into
tracks; then the biases and every tie point's ground position adjusted so that each tie point
projects onto its pixels (1-sigma --pixel-sigma px) and lies on the DEM (1-sigma --dem-sigma m),
each keyframe's attitude free to differ from its records by a little of its own (1-sigma
--frame-sigma deg per axis: refine.json's frame_attitude_deg). No ground control needed: the images
and the DEM tell the biases apart when the geometry varies (turns, gimbal motion, relief).
Parameters the pass cannot separate are said (correlations above 0.95, and any whose sigma stays
above half its prior's), not guessed. Without a reference the solution is relative (the frames agree
with each other) and held to the ground by the DEM only, and says so. --reference ORTHO.tif (any
georeferenced image of the ground: an orthophoto, a hillshade of the DEM): each keyframe is matched
to the reference drawn as the frame would see it (its pose and the DEM), each match a control point
(the frame's pixel sees the reference's ground there, 1-sigma --reference-sigma m): the solution
becomes absolute.

\b
Written into --out:
  refine.json            estimates, 1-sigma, correlations, undetermined parameters, residuals, timings
  telemetry_refined.csv  the telemetry with the heading bias out of yaw_deg, the time offset out of
                         time_s, a position bias out of lat/lon/h_m (heights ellipsoidal, gimbal
                         angles as gimbal1/gimbal2_deg)
  config_refined.toml    the config with the installation estimated (use it with the CSV above); its
                         [accuracy.budget] with what refinement left unknown in place of what it
                         estimated (mount_*_deg, boresight_x/y_deg, yaw_deg, time_s, lat/lon/h:
                         the estimate's 1-sigma, with a time-varying source's wander over the pass)
  NAME_refined.ts        a video with its own KLV: the video again with every ST 0601 packet's pose
                         corrected in place (platform, sensor position, sensor angles carrying the
                         installation, frame centre and corners on the DEM): no config needed
  NAME_refined.toml      ... and with --config, the config for that TS (installation, heading bias,
                         clock offset zero: the packets carry them; the refined [accuracy.budget])
  tiepoints.csv          every tie-point observation with its residual before and after (px)
  residuals.png          the residuals' distribution and per-keyframe RMS, before and after
"""


@click.command(help=REFINE_HELP)
@click.argument("sources", nargs=-1, required=True, type=click.Path())
@click.option("--telemetry", type=click.Path(),
              help="The video's telemetry (CSV, DJI SRT, flight log): time_s is seconds since the first frame "
                   "minus the config's time_offset_s. Without it: the video's own KLV (MPEG-TS), or photos.")
@config_option(required=False, help_text="Camera/gimbal/installation TOML (the starting values; a video's); its "
                                         "[accuracy.budget] gives the priors and comes back refined.")
@dem_options("The terrain (GeoTIFF, DTED, SRTM .hgt): the tie points' heights are held to it.")
@click.option("--estimate", default=None,
              help="Comma-separated: mount, boresight, heading, time (default: mount,heading,time for a video; "
                   "mount,heading for photos).")
@click.option("--every-s", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True,
              help="Keyframes at least this many seconds apart.")
@click.option("--pixel-sigma", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True,
              help="1-sigma of a tie point's pixel (px).")
@click.option("--dem-sigma", type=click.FloatRange(0.0, min_open=True), default=10.0, show_default=True,
              help="1-sigma of the DEM's heights (m; SRTM about 10).")
@click.option("--prior-mount", type=click.FloatRange(0.0, min_open=True), default=None,
              help="Prior 1-sigma of each mount / boresight angle (deg). Default: the config's [accuracy.budget] "
                   "(its largest mount_*_deg), else 1.")
@click.option("--prior-heading", type=click.FloatRange(0.0, min_open=True), default=None,
              help="Prior 1-sigma of the heading bias (deg). Default: the budget's yaw_deg, else 2.")
@click.option("--prior-time", type=click.FloatRange(0.0, min_open=True), default=None,
              help="Prior 1-sigma of the time offset (s). Default: the budget's time_s, else 0.5.")
@click.option("--frame-sigma", type=click.FloatRange(0.0), default=None,
              help="1-sigma (deg) of each keyframe's own attitude error about each body axis, which the records "
                   "do not show (INS noise, vibration): estimated per keyframe, so the shared biases' sigma "
                   "allow for it. 0: none. Default: the budget's largest vibration_*_deg, else 0.01.")
@click.option("--reference", "reference_path", type=click.Path(dir_okay=False), default=None,
              help="A georeferenced image of the ground (orthophoto or DEM hillshade, GeoTIFF): every keyframe or "
                   "photo matched to it gives control points; the solution becomes absolute and the GPS position "
                   "bias (position, m) is estimated too.")
@click.option("--reference-sigma", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True,
              help="1-sigma of the reference's georeferencing, horizontal (m).")
@click.option("--prior-position", type=click.FloatRange(0.0, min_open=True), default=None,
              help="Prior 1-sigma of each axis of the GPS position bias (east, north, up; m). Default: the "
                   "budget's largest of lat_deg, lon_deg (in m), h_m, else 5.")
@click.option("--max-gap", type=click.FloatRange(0.0, min_open=True), default=0.5, show_default=True,
              help="Longest telemetry gap (s) to bridge.")
@click.option("--json", "as_json", is_flag=True, help="Print refine.json's content instead of the tables.")
@out_option("refine.json, telemetry_refined.csv, config_refined.toml, tiepoints.csv, residuals.png")
def refine(sources, telemetry, config_path, dem_paths, vertical, geoid, dem_crs, estimate, every_s, pixel_sigma,
           dem_sigma, prior_mount, prior_heading, prior_time, frame_sigma, reference_path, reference_sigma,
           prior_position, max_gap, as_json, out_dir) -> None:
    import json
    from pathlib import Path

    from ..errors import InputError
    from ..jobs.refine import refine_video
    from ..refine.adjust import FRAME_SIGMA_DEG, PRIOR_SIGMA, AdjustSettings
    from .refined import looks_like_video

    photos = telemetry is None and not any(Path(src).is_file() and looks_like_video(src) for src in sources)
    if estimate is None:
        estimate = ("mount,heading" if photos else "mount,heading,time") + (",position" if reference_path else "")
    groups = tuple(e.strip() for e in estimate.split(",") if e.strip())
    given = {"mount": prior_mount, "boresight": prior_mount, "heading": prior_heading, "time": prior_time,
             "position": prior_position, "frame": frame_sigma}
    settings = AdjustSettings(estimate=groups, pixel_sigma_px=pixel_sigma, dem_sigma_m=dem_sigma,
                              frame_sigma_deg=FRAME_SIGMA_DEG if frame_sigma is None else frame_sigma,
                              prior_sigma={**PRIOR_SIGMA, **{g: v for g, v in given.items()
                                                            if v is not None and g in PRIOR_SIGMA}})
    if not photos and len(sources) != 1:
        raise InputError("a video is refined one at a time: eoloc refine VIDEO [--telemetry FILE --config C.toml] "
                         "--dem F")
    if telemetry is not None and config_path is None:
        raise InputError("--telemetry needs the camera: --config C.toml")
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    if dem is None:
        raise InputError("refining needs the terrain: --dem FILE (the tie points' heights are held to it)")

    reference = None
    if reference_path is not None:
        from ..io.raster import read_reference_band
        from ..refine.register import Reference

        reference = Reference(*read_reference_band(reference_path), sigma_m=reference_sigma)

    def say(msg: str) -> None:
        err_console.print(f"{msg}...", highlight=False)

    cfg = load_config(config_path) if config_path is not None else None
    from_budget = {g for g, v in given.items() if v is None}
    if photos:
        from ..jobs.refine import refine_photos
        from ..jobs.setup import optional_budget

        pjob = refine_photos(sources, dem, settings=settings, out=out_dir, reference=reference,
                             budget=optional_budget(cfg),
                             config_path=config_path, priors_from_budget=from_budget, progress=say)
        report_issues(pjob.failed)
        if as_json:
            for row in pjob.rows:
                click.echo(json.dumps(row, allow_nan=False))
        else:
            _print_table(pjob.refinement, pjob.report)
        for w in pjob.refinement.warnings:
            warn(w)
        err_console.print(f"wrote {out_dir}/photos_refined.csv, refine.json, residuals.png, geo.txt, xmp/*.xmp"
                          + (", config_refined.toml" if pjob.budget and config_path else ""), highlight=False)
        return
    job = refine_video(sources[0], telemetry, cfg, dem, config_path=config_path, out=out_dir, every_s=every_s,
                       settings=settings, max_gap_s=max_gap, reference=reference, priors_from_budget=from_budget,
                       progress=say)
    report_issues(job.issues)
    if as_json:
        click.echo(json.dumps(job.report, indent=1, allow_nan=False))
    else:
        _print_table(job.refinement, job.report)
    for w in job.refinement.warnings:
        warn(w)
    err_console.print(f"wrote {', '.join(str(p) for p in job.written)}", highlight=False)


def _print_table(r, rep) -> None:
    t = titled_table(f"refined from {rep['observations']} observations of {rep['tie_points']} tie points in "
                     f"{rep['keyframes']} keyframes (s0 = {r.s0:.2f})")
    for col in ("parameter", "estimate", "± 1σ", "prior σ", ""):
        t.add_column(col, justify="right")
    for name, v, s, p in zip(r.names, r.values, r.sigma, r.prior_sigma, strict=True):
        t.add_row(name, f"{v:+.4g}", f"{s:.2g}", f"{p:g}", "not determined" if name in r.undetermined else "")
    console.print(t)
    console.print(f"tie-point residuals RMS: {rep['rms_px_before']:.2f} px with the telemetry as given, "
                  f"{rep['rms_px_after']:.2f} px refined; {rep['timing_s']['total_s']:.1f} s")
