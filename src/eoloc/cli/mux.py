"""`eoloc mux`: a drone video and its telemetry into an MPEG-TS with a MISB ST 0601 KLV stream."""

from __future__ import annotations

from datetime import UTC, datetime

import click

from .common import ground, load_config, open_dem, working
from .main import console, err_console, report_issues, warn
from .options import CONVENTIONS, config_option, flight_log_option, rule_options, with_flight_log

MUX_HELP = """A drone video with its telemetry, as MISB: an MPEG-TS with an ST 0601 KLV stream.

\b
eoloc mux VIDEO --telemetry FILE [--flight-log LOG.csv] --config CAMERA.toml -o OUT.ts
          [--carriage async|sync] [--start-utc ISO] [--dem FILE | --target-height H]
  VIDEO: the drone's MP4/MOV (or a TS); its video is copied packet for packet, nothing decoded.
  --telemetry: the video's DJI .SRT (its subtitle times are the video's clock) or any telemetry
  eoloc reads with time_s on the video's clock; --flight-log completes an SRT without attitude.
  One ST 0601 packet per frame at the frame's presentation time: the pose interpolated there, the
  camera's attitude as platform heading + sensor relative elevation/roll (ST 0601 has no other
  way to say "the camera's own attitude"), heights MSL (tag 15, EGM96) and ellipsoidal (tag 75),
  the fields of view of the config's camera; with --dem/--target-height also the frame centre.
  --carriage (MISB ST 1402; each packet right after its frame's video):
    async (default): asynchronous, a 'KLVA' data stream (stream_type 0x06), PES stream_id 0xBD
      without PTS: a receiver times each packet by the frame before it (eoloc does, and says so);
    sync: synchronous metadata (stream_type 0x15 with the metadata descriptors), one access unit
      per frame with the frame's PTS.
  --start-utc: the UTC time of the first frame (tag 2); default: the SRT's dates, taken as UTC.
  Frames outside the telemetry get no packet (said). Read it back with eoloc klv / eoloc video.
"""


@click.command(help=MUX_HELP + CONVENTIONS)
@click.argument("video", type=click.Path(dir_okay=False))
@click.option("--telemetry", required=True, type=click.Path(),
              help="The video's telemetry (a DJI .SRT, or any source with time_s on the video's clock).")
@flight_log_option
@config_option(help_text="Camera TOML (size and focal length: the fields of view in each packet).")
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False), metavar="OUT.ts",
              help="The MPEG-TS to write.")
@click.option("--carriage", type=click.Choice(["async", "sync"]), default="async", show_default=True,
              help="KLV carriage (ST 1402): asynchronous (KLVA, no PTS) or synchronous (access units with PTS).")
@click.option("--start-utc", "start_utc", default=None, metavar="ISO",
              help="UTC time of the first frame, ISO 8601 (e.g. 2024-01-04T22:23:10.5Z); default: the SRT's dates.")
@rule_options(ground=True, role="Ground for the frame centre (tags 21, 23-25)")
def mux(video, telemetry, flight_log, config_path, output, carriage, start_utc, rule_values, dem_paths, vertical, geoid,
        dem_crs) -> None:
    from ..jobs.mux import mux_job

    start = None
    if start_utc is not None:
        try:
            start = datetime.fromisoformat(start_utc.replace("Z", "+00:00"))
        except ValueError:
            raise click.BadParameter(f"{start_utc!r} is not an ISO 8601 time (e.g. 2024-01-04T22:23:10Z)",
                                     param_hint="--start-utc") from None
        start = start if start.tzinfo else start.replace(tzinfo=UTC)
    rule = ground(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs), required=False)
    cfg = load_config(config_path)
    with working("muxing..."):
        job = mux_job(video, with_flight_log(telemetry, flight_log), cfg, output, carriage=carriage, start_utc=start,
                      ground=rule)
    report_issues(job.issues)
    for note in job.notes:
        warn(note, "note")
    console.print(f"{job.packets} ST 0601 packets for {job.frames} frames ({job.carriage} carriage)")
    err_console.print(f"wrote [bold]{job.path}[/]")
