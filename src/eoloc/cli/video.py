"""`eoloc video`: a video's frames with their metadata, orthorectified, mosaicked and tiled."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import click

from .common import ground, load_config, open_dem, progress
from .main import NOTHING_LOCATED, console, err_console, report_issues, warn
from .options import (
    CONVENTIONS,
    config_option,
    detect_options,
    detect_settings,
    flight_log_option,
    ortho_options,
    out_option,
    refine_option,
    with_flight_log,
)
from .render import titled_table

VIDEO_HELP = """Orthorectify the frames of a video with their metadata: each frame a Cloud-Optimised
GeoTIFF, a mosaic of the pass, XYZ map tiles.

\b
  eoloc video FLIGHT.ts --dem DEM.tif --every 10 --out out/
  eoloc video FLIGHT.mp4 --klv FLIGHT.klv --target-height 1650
  eoloc video FLIGHT.mp4 --telemetry TEL.csv --config CAMERA.toml --dem DEM.tif

\b
Metadata, and how each frame finds its pose:
  in the video   MPEG-TS with an ST 0601 KLV stream (synchronous or asynchronous carriage): paired
                 by presentation time (PTS), the pose interpolated between packets (position by a
                 spline in ECEF, attitude by slerp, gimbal angles and FOV linearly). Several KLV
                 streams: the first that carries a position, or --stream "PID n".
  --klv FILE     KLV beside the video: paired by its time stamps (tag 2), the first packet at the
                 first frame unless --time-offset T (the UNIX time of the first frame).
  --telemetry    a telemetry CSV with --config (the camera): its time_s is seconds since the
                 first frame, minus --time-offset (default: the config's [telemetry] time_offset_s).
A frame outside the metadata, or in a gap longer than --max-gap, is not rectified (frames.csv
says why). With KLV the camera is a pinhole whose fields of view (tags 16, 17) span the frame.

\b
Ground: --dem (terrain, with occlusion) or --target-height H; with KLV and neither, each frame's
own frame-centre elevation (tag 78, or 25 + geoid).

\b
--refine: the telemetry is first refined from the video's own pixels (eoloc refine with its
defaults, into OUT/refine/: the installation, heading bias and clock offset, each keyframe's own
attitude), then everything below is made with the refined telemetry and config, or, for a video
with its own KLV, with OUT/refine/NAME_refined.ts (its packets corrected in place).

\b
Written into --out:
  frames/frame_NNNNNN.tif  each rectified frame: its bands plus a visibility band (0 unseen,
                           1 hidden by terrain, 2 seen), the seen cells as the internal mask
  mosaic.tif               the pass: per cell the frame with the finest ground sample
  mosaic_source.tif        per cell the source frame index (-1 none) and its GSD (m)
  tiles/{z}/{x}/{y}.png    the mosaic as XYZ tiles (Web Mercator) for Leaflet, QGIS, ...
  player.html, player/     the video beside the map, synced (open it in a browser; works offline):
                           footprint, frame centre, aircraft, VMTI boxes and points, the current
                           frame draped (opacity slider), the mosaic; click in the video -> the
                           ground point (exact through `eoloc serve --player OUT`, offline from
                           per-frame ground grids)
  vmti.csv, vmti.geojson   the VMTI targets (ST 0903 in the KLV), each located with its packet's pose
  detections.csv, .geojson with --detect motion: every detection of a mover (frame, time_s,
                           track_id, u_px, v_px, box, ground area, point, speed and its sigma, heading;
                           with a --config [accuracy.budget]: sigma_e/n/u_m, CEP50, CE90, LE90 of the
                           point: the telemetry's errors and the blob's centroid on the ground)
  movers.geojson           with --detect motion: one LineString per mover (its Kalman track)
  movers.cot.zip           with --detect motion: a TAK data package, each mover where it was last seen
                           (course and speed in <track>; ce/le from the budget, unknown without one)
  --klv-out OUT.ts         with --detect motion: the video again (MPEG-TS, its metadata kept), with the
                           movers as ST 0903 VMTI (id, centroid, box, location) in a KLV stream of its own,
                           one packet at each frame's PTS where movers were found
  frames.csv, footprints.geojson, video.json
All frames share one grid (--crs, cell --gsd: default the first frame's native GSD, rounded).

\b
Movers (--detect motion): every frame is compared with frames up to --detect-window seconds
before and after it, each warped onto its view through the poses and the ground (--dem: terrain
parallax removed; --target-height: flat), the residual shift between frames measured from the
images. What differs from a frame before AND one after it, by more than --detect-threshold
(0-255 colour scale), covering --min-area..--max-area square metres on the ground, is a blob; its
centroid is located and tracked on the ground (Kalman). A track is a mover when it lasts 1 s and
moves at least --min-speed m/s. Not seen: targets standing still, or moving less than half their
length in --detect-window (slowest: length / (2 x window)). False alarms: tall things not in the
DEM (parallax), moving shadows, water.

\b
A learned detector (--detect MODEL.onnx): your ONNX object detector (YOLOv5/v7/v8/v11 outputs,
class names from its metadata) run by onnxruntime on every frame (letterboxed to its input);
boxes scoring --detect-score or more (--detect-classes: only those), overlaps reduced (NMS); each
box's --detect-point located and tracked the same way, standing targets kept (--min-speed 0).
Nothing is downloaded. detections.csv adds the class and score.
"""


@click.command(help=VIDEO_HELP + CONVENTIONS)
@click.argument("video", type=click.Path(dir_okay=False))
@click.option("--klv", "klv_path", type=click.Path(dir_okay=False), default=None,
              help="KLV file (raw .klv/.bin or MPEG-TS) beside the video, paired by its time stamps.")
@click.option("--telemetry", type=click.Path(dir_okay=False), default=None,
              help="Telemetry beside the video (needs --config), paired by time_s: an eoloc CSV, a DJI .SRT "
                   "(its time codes are the video's clock) or a flight log.")
@config_option(required=False, help_text="Camera/gimbal/installation TOML (with --telemetry); its [accuracy.budget] "
                                         "gives --detect's fixes their uncertainty (any source).")
@click.option("--stream", "klv_stream", default=None, metavar="NAME",
              help='The KLV stream to use when there are several, as eoloc klv names them ("PID 497").')
@click.option("--time-offset", type=float, default=None,
              help="Metadata clock minus video clock (s); see above for each source's default.")
@click.option("--max-gap", type=click.FloatRange(0.0, min_open=True), default=0.5, show_default=True,
              help="Longest metadata gap (s) to interpolate a frame's pose across.")
@ortho_options("; the zone of the first rectified frame holds for the pass",
               "the first rectified frame's native GSD, rounded")
@click.option("--every", type=click.IntRange(1), default=1, show_default=True, help="Rectify every N-th frame.")
@click.option("--start", "start_s", type=click.FloatRange(0.0), default=0.0, show_default=True,
              help="First frame time to rectify (s since the first frame).")
@click.option("--end", "end_s", type=click.FloatRange(0.0), default=None,
              help="Last frame time to rectify (s since the first frame); default: the end.")
@click.option("--frames/--no-frames", "write_frames", default=True, show_default=True,
              help="Write each rectified frame as a COG.")
@click.option("--mosaic/--no-mosaic", default=True, show_default=True, help="Build the mosaic of the pass.")
@click.option("--tiles/--no-tiles", default=True, show_default=True, help="Cut the mosaic into XYZ tiles.")
@click.option("--player/--no-player", default=True, show_default=True,
              help="Write player.html: the video beside the map (the video remuxed or transcoded to MP4).")
@detect_options
@refine_option("the telemetry from the video's own pixels (eoloc refine, its defaults, into OUT/refine/; needs "
               "--dem), then run on the refined telemetry and config (or the video's own KLV refined: "
               "OUT/refine/NAME_refined.ts).")
@click.option("--klv-out", "klv_out", type=click.Path(dir_okay=False), default=None, metavar="OUT.ts",
              help="--detect: the video written again as MPEG-TS, its metadata kept, with the movers as ST 0903 "
                   "VMTI in a KLV stream of its own (ids, centroid, box, location).")
@out_option("frames/, mosaic.tif, mosaic_source.tif, tiles/, frames.csv, footprints.geojson and video.json")
@flight_log_option
def video(video, klv_path, telemetry, config_path, klv_stream, time_offset, max_gap, rule_values, dem_paths,
          vertical, geoid, dem_crs, crs, gsd, resampling, nodata, occlusion, every, start_s, end_s, write_frames,
          mosaic, tiles, player, detect, detect_score, detect_classes, detect_point, detect_window, detect_threshold,
          min_area, max_area, min_speed, refine_first, klv_out, out_dir, flight_log) -> None:
    telemetry = with_flight_log(telemetry, flight_log)
    from ..io.writers import write_layer
    from ..jobs.video import FrameSelection, video_job

    if klv_path and telemetry:
        raise click.UsageError("choose one metadata source beside the video: --klv FILE or --telemetry CSV")
    if telemetry and not config_path:
        raise click.UsageError("--telemetry needs --config (the camera: size, focal length, distortion)")
    if end_s is not None and end_s < start_s:
        raise click.UsageError(f"--end {end_s:g} is before --start {start_s:g}")
    if klv_out and not detect:
        raise click.UsageError("--klv-out writes the targets --detect finds: add --detect motion (or MODEL.onnx)")
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    rule = ground(rule_values, dem, required=False)  # None: each frame's metadata frame-centre elevation
    if detect and rule is None:
        raise click.UsageError("--detect needs the ground as one surface: --dem FILE or --target-height H")
    finder, movers = detect_settings(detect, rule, detect_score=detect_score, detect_classes=detect_classes,
                                     detect_point=detect_point, detect_window=detect_window,
                                     detect_threshold=detect_threshold, min_area=min_area, max_area=max_area,
                                     min_speed=min_speed)
    if refine_first:
        video, telemetry, config_path = refined_inputs(video, klv_path, telemetry, config_path, time_offset, dem,
                                                       max_gap, Path(out_dir))
    dem_name = Path(dem_paths[0]).stem if dem_paths else "dem"
    serve_line = serve_command(Path(out_dir), dem_name, dem_paths, vertical, geoid, dem_crs, config_path)
    cfg = load_config(config_path) if config_path else None
    out = Path(out_dir)
    select = FrameSelection(every, start_s, math.inf if end_s is None else end_s)
    with progress() as bar:
        task = bar.add_task("rectifying frames", total=None)
        searching = bar.add_task("finding targets", total=None, visible=False)

        def searched(done: int, total: int) -> None:
            bar.update(searching, completed=done, total=total, visible=True)

        job = video_job(video, out=out, klv=klv_path, telemetry=telemetry, cfg=cfg, ground=rule, crs=crs,
                        gsd_m=gsd, resampling=resampling, nodata=nodata, occlusion=occlusion, select=select,
                        klv_stream=klv_stream, time_offset_s=time_offset, max_gap_s=max_gap,
                        write_frames=write_frames, mosaic=mosaic, tiles=tiles, player=player,
                        dem_name=dem_name, serve_command=serve_line, detect=finder, movers=movers,
                        progress=lambda done, total: bar.update(task, completed=done, total=total),
                        detect_progress=searched)
    report_issues(job.issues)
    for line in job.decode_errors:
        warn(line)
    written = list(job.written)
    written += write_layer(out, "frames", job.rows, ["csv"])
    if job.vmti:
        written += write_layer(out, "vmti", job.vmti, ["csv", "geojson"])
    if job.movers is not None:
        from ..sequence.track import track_features

        written += write_layer(out, "detections", job.movers.rows, ["csv", "geojson"])
        feats = track_features(job.movers.track_set())
        written += write_layer(out, "movers", [f["properties"] for f in feats], ["geojson"], features=feats)
        if job.movers.rows:  # TAK: one marker per mover where it was last seen, with its course and speed
            from ..io.cot import write_cot

            last = {r["track_id"]: r for r in job.movers.rows}
            rows = [{k: v for k, v in r.items() if k != "frame"} | {"target_id": f"mover-{n}"}
                    for n, r in last.items()]
            written.append(write_cot(out / "movers.cot.zip", rows, name="eoloc movers")[0])
        if klv_out:
            from ..io.videofile import frame_times
            from ..jobs.moversklv import write_movers_klv

            if job.movers.rows:
                written.append(write_movers_klv(video, klv_out, job.movers.rows, frame_times(video),
                                                job.info.width, job.info.height))
            else:
                warn(f"no mover was found: {klv_out} not written")
    if job.footprints:
        written += write_layer(out, "footprints", [f["properties"] for f in job.footprints], ["geojson"],
                               features=job.footprints)
    statuses: dict[str, int] = {}
    for r in job.rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    info = job.info
    report = {"video": str(video), "size": [info.width, info.height], "fps": info.fps, "codec": info.codec,
              "metadata": job.metadata.source, "frames_selected": len(job.rows), "statuses": statuses}
    if job.mosaic is not None:
        g = job.mosaic.grid
        report["mosaic"] = {"crs": g.crs.to_string(), "res": list(g.res), "size": list(g.shape),
                            "seen_fraction": float(job.mosaic.valid.mean()),
                            "frames_used": len(set(job.mosaic.frame[job.mosaic.valid].tolist()))}
    if job.player is not None:
        report["player"] = {"page": str(job.player), "video": job.video_for_browser, "serve": serve_line}
    if job.vmti:
        report["vmti"] = {"detections": len(job.vmti), "located": sum(r["status"] == "OK" for r in job.vmti)}
    if job.movers is not None:
        m = job.movers
        report["movers"] = {"tracks": len(m.tracks), "detections": len(m.rows), "blobs": m.blobs,
                            "blobs_not_located": m.not_located, "tracks_dropped": m.dropped_tracks,
                            "blobs_dropped": m.dropped_blobs}
    if job.tiles is not None:
        report["tiles"] = {"url": job.tiles.url, "min_zoom": job.tiles.min_zoom, "max_zoom": job.tiles.max_zoom,
                           "count": job.tiles.count}
    js = out / "video.json"
    js.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    written.append(js)
    t = titled_table(f"{Path(video).name}", show_header=False)
    t.add_row("video", f"{info.width} x {info.height} {info.codec}, {info.fps:.3g} fps, {info.container}")
    t.add_row("metadata", job.metadata.source)
    t.add_row("frames", ", ".join(f"{n} {k}" for k, n in statuses.items()) + f" (of {len(job.rows)} selected)")
    if job.mosaic is not None:
        g = job.mosaic.grid
        t.add_row("mosaic", f"{g.shape[1]} x {g.shape[0]} cells of {g.res[0]:.3g} "
                            f"{'deg' if g.crs.is_geographic else 'm'} in {g.crs.name}; "
                            f"{report['mosaic']['frames_used']} frames")
    if job.vmti:
        n_ok = sum(r["status"] == "OK" for r in job.vmti)
        t.add_row("VMTI", f"{len(job.vmti)} detections, {n_ok} located")
    if job.movers is not None:
        m = job.movers
        t.add_row("movers", f"{len(m.tracks)} tracks, {len(m.rows)} detections ({m.blobs} blobs; "
                            f"{m.dropped_tracks} tracks that did not move as a target dropped)")
    if job.player is not None:
        t.add_row("player", f"{job.player} (the video {job.video_for_browser} to MP4)")
    if job.tiles is not None:
        t.add_row("tiles", f"{job.tiles.count} tiles, zoom {job.tiles.min_zoom}-{job.tiles.max_zoom}")
    console.print(t)
    frames = [p for p in written if p.parent.name == "frames"]
    others = [p for p in written if p.parent.name != "frames"]
    if frames:
        err_console.print(f"wrote {len(frames)} frame COGs into [bold]{out / 'frames'}[/]")
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in others))
    if job.player is not None:
        err_console.print(f"open {job.player} in a browser; for exact clicks on every frame serve it:")
        err_console.print(f"  {serve_line}", soft_wrap=True, markup=False)
    if not job.n_rectified:
        warn("nothing was located: no frame was rectified: see the status and note columns of frames.csv")
        sys.exit(NOTHING_LOCATED)


def refined_inputs(video, klv_path, telemetry, config_path, time_offset, dem, max_gap: float, out: Path):
    """``--refine``: the video, telemetry and config to go on with (:func:`eoloc.cli.refined.refine_video_first`
    into OUT/refine/)."""
    from .refined import refine_video_first

    if klv_path:
        raise click.UsageError("--refine takes the video's own KLV or --telemetry with --config, not --klv FILE: "
                               "mux the KLV into the video first (eoloc mux)")
    if time_offset is not None:
        raise click.UsageError("--refine estimates the clock offset itself: leave out --time-offset (the config's "
                               "time_offset_s is its starting value)")
    return refine_video_first(video, telemetry, config_path, dem, out / "refine", max_gap_s=max_gap)


def serve_command(out: Path, dem_name: str, dem_paths, vertical: str, geoid, dem_crs, config_path) -> str:
    """The `eoloc serve` line that serves the player with what this job used (its clicks exact)."""
    import shlex

    parts = ["eoloc", "serve", "--player", str(out)]
    for p in dem_paths:
        parts += ["--dem", f"{dem_name}={Path(p).resolve()}"]
    if dem_paths and vertical != "egm96":
        parts += ["--vertical", vertical]
    if dem_paths and geoid:
        parts += ["--geoid", str(Path(geoid).resolve())]
    if dem_paths and dem_crs:
        parts += ["--dem-crs", dem_crs]
    if config_path:
        parts += ["--config", str(Path(config_path).resolve())]
    return shlex.join(parts)
