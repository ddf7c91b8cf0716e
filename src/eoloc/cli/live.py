"""`eoloc live`: a KLV stream as it arrives -> located VMTI targets, frame centre and footprint,
as NDJSON and Cursor-on-Target."""

from __future__ import annotations

import json
import signal
import sys

import click

from .common import open_dem
from .main import err_console, fail, warn
from .options import (
    allow_host_option,
    config_option,
    dem_options,
    detect_options,
    detect_settings,
    tak_connection,
    tak_options,
)

LIVE_HELP = """Locate the VMTI targets of a live MISB ST 0601 stream, packet by packet, as it arrives,
and send them on as NDJSON and Cursor-on-Target (TAK).

\b
eoloc live SOURCE [--dem F] [--config C] [--ndjson FILE|-] [--cot URL ...]
  SOURCE: udp://HOST:PORT (a multicast HOST such as 239.1.1.1 is joined): datagrams of MPEG-TS
  (ST 1402, any number of KLV PIDs, each its own stream) or raw KLV (whole packets), told apart
  as they come; a raw KLV or MPEG-TS file (--realtime: at the stream's own clock, from the
  ST 0601 time stamps, or the TS PCR, else PTS); - for stdin (a pipe of TS or raw KLV bytes);
  rtsp://HOST:PORT/PATH or rtmp://... (through FFmpeg: each KLV data stream of the session,
  MPEG-TS over RTP included, RTSP over TCP); tcp://HOST:PORT or http(s)://... (a byte stream
  of MPEG-TS or raw KLV, through FFmpeg); srt://HOST:PORT (caller; srt://:PORT listens),
  bridged by srt-live-transmit (apt install srt-tools) since PyAV's FFmpeg has no SRT. RTSP,
  RTMP and TCP sessions that end or break off (an encoder restarting) are opened again, with
  back-off (0.5 s doubling to 8 s); the first connection must succeed.
  Each packet is decoded as `eoloc klv` decodes files (checksums, report-on-change values carried
  from packet to packet); its frame centre, footprint (the four corners; on --dem the image
  border traced on the terrain) and VMTI targets are located on --dem, else on the packet's
  frame-centre elevation; heights ellipsoidal (WGS-84), angles in degrees; with the config's
  [accuracy.budget] each target gets its uncertainty. Across packets each target id is refined
  (--track): by recursive least squares (static targets), or by a constant-velocity Kalman filter
  (moving ones), the same steps as eoloc track --static and eoloc track.
\b
Outputs (any combination, at least one):
  --ndjson FILE|-   one GeoJSON Feature per line (lon, lat, ellipsoidal h), property "what":
                    aircraft, footprint, frame centre, target (a failed target keeps its
                    status with a null geometry), estimate (the refined target: model,
                    n_fixes, cep50_m, speed_mps); flushed per packet.
  --cot URL         Cursor-on-Target, repeatable: udp://239.2.3.1:6969 (ATAK's SA multicast;
                    ?ttl=N), udp://HOST:PORT, tcp://HOST:8087 (a TAK server's CoT port;
                    reconnects with back-off, never holds up the rest) or tls://HOST:8089
                    (its TLS port: --tak-cert CLIENT.p12 [--tak-ca CA.pem] or --tak-package
                    CONNECTION.zip, the data package its admin hands out; a certificate
                    problem ends the run with one line). --tak-protocol 1: protobuf. Per
                    packet: the aircraft with its sensor's field of view, the frame centre
                    (sensor point of interest), the footprint as a shape, and each located
                    target with ce/le (1 sigma) from its covariance; stale after 10 packet intervals.
                    --cot-targets estimates: each target's refined estimate (--track)
                    under the same uid instead, ce = its CEP50/1.1774; both: the two.
  --klv-out URL|FILE  the stream re-sent (udp://HOST:PORT, multicast ?ttl=N) or recorded (FILE)
                    with each packet's first located target (lowest VMTI id) in ST 0601 tags
                    40-42 and its CE90/LE90 in 45/46 (tag 42 in the stream's datum); TS in, TS
                    out: video, audio and tables passed on untouched, the metadata PES rebuilt.
  --map HOST:PORT   a live map in the browser at http://HOST:PORT/live (offline Leaflet, updated
                    over a WebSocket): aircraft and trail, footprint, frame centre, targets with
                    their CEP50 circles and tracks, movers (--detect) with their tracks, and the
                    stream's state (live, SILENT, STOPPED).
                    The same server answers eoloc serve's API (POST /v1/locate, /docs). Port 0:
                    any free one (printed). With --map the page stays up after the source ends,
                    until Ctrl-C or --duration.
\b
Targets from the video itself (--detect motion|MODEL.onnx, with --dem): the stream's own video
(MPEG-TS sources: udp, srt, tcp, a file, stdin; not RTSP/RTMP, whose KLV FFmpeg hands over alone)
is decoded as it arrives, each frame posed by the KLV packets around it (PTS), and searched as
`eoloc video --detect` searches it (motion: each frame against frames up to --detect-window
seconds before and after it, the camera's motion taken out through the poses and the DEM; a
model: its boxes). A track is sent once it is a mover (confirmed, 1 s long, moving at least
--min-speed), then with every frame it is found in: "mover" features in --ndjson and --map (id,
speed, heading, box; with [accuracy.budget] its CE90/LE90) and CoT markers <platform>-mover-<id>
with course, speed and ce/le. Movers trail the video by --detect-window plus the work (the
summary's movers.latency_ms); frames are skipped, not queued, when the work falls behind a live
source by --detect-lag seconds (movers.frames_skipped); a file is searched whole.
\b
Faults are counted, never fatal: corrupt or non-KLV datagrams, duplicated packets (dropped),
late ones (located all the same), encoder restarts (time back > 2 s), silence (--silence S: a
warning on stderr, and the aircraft sent to TAK as stale).
Ctrl-C (SIGINT) or SIGTERM, --packets N or --duration S stop it with a summary on stderr:
datagrams, packets, detections, fixes, faults, what each output sent and the latency from a
datagram's arrival to its outputs sent.
"""

STREAM_SCHEMES = ("udp", "srt", "rtsp", "rtsps", "rtp", "rtmp", "http", "https")  # a SOURCE a TAK user could open too


@click.command(help=LIVE_HELP)
@click.argument("source")
@dem_options("Terrain: DEM file(s) for the targets (default: each packet's frame-centre elevation).")
@config_option(required=False, help_text="TOML with [installation] (calibrated misalignments) and "
                                         "[accuracy.budget] (uncertainty).")
@click.option("--ndjson", "ndjson", default=None, metavar="FILE|-",
              help="Write one GeoJSON feature per line ('-': stdout).")
@tak_options
@click.option("--video-url", "video_url", default=None, metavar="URL",
              help="The video TAK users open from the aircraft's marker (a <__video> link in its CoT): the stream's "
                   "URL as they reach it (rtsp://, srt://, udp://...). Default: SOURCE when it is a stream URL.")
@click.option("--video-package", "video_package", type=click.Path(dir_okay=False), default=None,
              metavar="FILE.zip",
              help="Write a TAK data package with the video connection (--video-url) for this mission: imported "
                   "in ATAK/WinTAK, the stream appears in the video list.")
@click.option("--klv-out", "klv_out", default=None, metavar="URL|FILE",
              help="Re-send the stream with the target locations in ST 0601 tags 40-42, 45, 46: udp://HOST:PORT or "
                   "a file.")
@click.option("--map", "map_at", default=None, metavar="HOST:PORT",
              help="Serve a live map at http://HOST:PORT/live (e.g. 127.0.0.1:8080; 0.0.0.0:8080 for other machines).")
@click.option("--cot-targets", "cot_targets", type=click.Choice(["fixes", "estimates", "both"]), default="fixes",
              show_default=True,
              help="What each target's CoT marker carries: every packet's fix, the target refined across packets "
                   "(--track; the same uid, so one marker converges), or both (the estimate as '<uid>-refined').")
@click.option("--cot-interval", type=click.FloatRange(0.0), default=0.0, show_default=True, metavar="S",
              help="At most one CoT event per target (and per aircraft, footprint) every S seconds; 0: all.")
@click.option("--track", "refine", type=click.Choice(["static", "moving", "auto", "off"]), default="static",
              show_default=True,
              help="Refine each VMTI target id across packets: static (RLS, as eoloc track --static; a target "
                   "whose fixes walk gets a warning and their scatter as its uncertainty), moving (Kalman, as "
                   "eoloc track), auto (Kalman once the speed is significant: a drifting attitude bias makes a "
                   "fixed target look moving too), off. The estimates go to --ndjson, --map and (--cot-targets) "
                   "CoT.")
@click.option("--refine", "refine_legacy", type=click.Choice(["static", "moving", "auto", "off"]), default=None,
              hidden=True, help="The old name of --track (--refine now means refining the telemetry from the pixels, "
                                "in eoloc video, photo, klv and locate).")
@click.option("--realtime", is_flag=True, help="A file SOURCE: replay at the stream's own clock.")
@click.option("--packets", "max_packets", type=click.IntRange(1), default=None, help="Stop after N good packets.")
@click.option("--duration", type=click.FloatRange(0.0, min_open=True), default=None, metavar="S",
              help="Stop after S seconds.")
@click.option("--silence", type=click.FloatRange(0.0, min_open=True), default=3.0, show_default=True, metavar="S",
              help="Warn (and mark the aircraft stale in TAK) when nothing arrives for S seconds.")
@detect_options
@click.option("--detect-lag", type=click.FloatRange(0.0, min_open=True), default=1.0, show_default=True, metavar="S",
              help="--detect on a live source: a frame the search reaches more than S seconds after it arrived is "
                   "skipped (the search keeps up rather than lag; a file is searched whole).")
@allow_host_option
def live(source, dem_paths, vertical, geoid, dem_crs, config_path, ndjson, cot_urls, tak_cert, tak_cert_password,
         tak_ca, tak_package, tak_protocol, video_url, video_package, klv_out, map_at, cot_targets, cot_interval,
         refine, refine_legacy, realtime, max_packets, duration, silence, detect, detect_score, detect_classes,
         detect_point, detect_window, detect_threshold, min_area, max_area, min_speed, detect_lag,
         allow_hosts) -> None:
    from ..jobs.setup import misb_setup
    from ..live.loop import run
    from ..live.session import LiveSession
    from .common import load_config

    if refine_legacy is not None:
        warn(f"--refine {refine_legacy} is now --track {refine_legacy} (--refine means refining the telemetry from "
             "the pixels in eoloc video, photo, klv and locate)", "deprecated")
        refine = refine_legacy
    cot_urls, tak_tls = tak_connection(cot_urls, tak_cert, tak_cert_password, tak_ca, tak_package)
    wanted = {"ndjson": ndjson, "cot": cot_urls, "klv_out": klv_out, "map": map_at}  # the outputs: SINKS
    if not any(wanted.values()):
        fail("eoloc live: give at least one output: --ndjson FILE|-, --cot URL, --klv-out URL|FILE and/or "
             "--map HOST:PORT")
    map_host, map_port = parse_host_port(map_at) if map_at is not None else (None, None)
    if cot_targets != "fixes" and (refine == "off" or not cot_urls):
        fail(f"--cot-targets {cot_targets}: the refined targets need --track (static, moving or auto) and a --cot URL")
    if video_url is None and source.split("://")[0].lower() in STREAM_SCHEMES:
        video_url = source
    if video_package is not None:
        from ..io.cot import write_video_package
        from ..live.cotfeed import CotFeed

        if video_url is None:
            fail("--video-package: give the stream's URL (--video-url rtsp://...; SOURCE is not a stream URL)")
        write_video_package(video_package, video_url, uid=CotFeed().video_uid(), alias="eoloc video")
    if detect and not dem_paths:
        fail("--detect needs the ground the video sees: --dem FILE")
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    config = load_config(config_path) if config_path else None
    sensor, budget = misb_setup(config)
    movers = None
    if detect:
        from ..live.movers import LiveMovers
        from ..rules import OnDEM

        rule = OnDEM(dem)
        finder, mover_settings = detect_settings(
            detect, rule, detect_score=detect_score, detect_classes=detect_classes, detect_point=detect_point,
            detect_window=detect_window, detect_threshold=detect_threshold, min_area=min_area, max_area=max_area,
            min_speed=min_speed)
        learned = None if detect == "motion" else finder
        movers = LiveMovers(rule, motion=finder if learned is None else None, learned=learned,
                            settings=mover_settings, budget=budget, sensor=sensor, max_lag_s=detect_lag,
                            wait=not realtime and "://" not in source and source != "-", source=source)
    filters = None
    if refine != "off" and (ndjson is not None or map_at is not None or cot_targets != "fixes"):  # estimates wanted
        from ..live.refine import TargetFilters

        filters = TargetFilters(refine)
    settings = {"source": source, "dem": dem, "config": config, "silence_s": silence, "allow_hosts": allow_hosts,
                "tls": tak_tls, "protocol": tak_protocol, "interval_s": cot_interval, "targets": cot_targets,
                "video_url": video_url, "map_host": map_host, "map_port": map_port}
    sinks = []
    session = None
    try:
        klv = SINKS["klv_out"](klv_out, settings) if klv_out is not None else None
        session = LiveSession(source, dem=dem, sensor=sensor, budget=budget, refine=filters, klv_out=klv,
                              movers=movers)
        settings["session"] = session
        sinks = [klv] if klv is not None else []
        sinks += [SINKS[name](value, settings) for name, value in wanted.items() if value and name != "klv_out"]
    except BaseException:
        for sink in sinks:
            sink.close()
        if movers is not None:
            movers.close()
        raise
    stopping: dict = {"why": None}

    def on_signal(signum, _frame) -> None:
        stopping["why"] = stopping["why"] or signal.Signals(signum).name

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    result = run(source, session, sinks, max_packets=max_packets, duration_s=duration, realtime=realtime,
                 silence_s=silence, should_stop=lambda: stopping["why"], report=_report, stdin=sys.stdin.buffer)
    err_console.print(f"eoloc live stopped ({result.why or 'end of the source'}): " + json.dumps(result.summary),
                      soft_wrap=True, highlight=False)
    if movers is not None and not movers.counts["video_frames"]:
        warn(f"--detect: {source} brought no video eoloc could decode (MPEG-TS with an H.264, HEVC or MPEG-2 "
             "video PID is needed), so no mover was searched for", "detect")
    if result.fatal:
        fail(result.fatal)


def _report(message: str, kind: str) -> None:
    """What the run says, as the command shows it: where it listens and the map's address plainly,
    the rest as warnings of their kind."""
    if kind == "start":
        err_console.print(f"eoloc live: {message} (Ctrl-C stops)")
    elif kind == "map":
        err_console.print(f"eoloc live: {message}")
    else:
        warn(message, kind)


def _ndjson_sink(path: str, settings: dict):
    from ..live.sinks import NdjsonSink

    return NdjsonSink(path)


def _cot_sink(urls, settings: dict):
    from ..live.sinks import CotSink

    return CotSink(urls, interval_s=settings["interval_s"], targets=settings["targets"],
                   video_url=settings["video_url"], tls=settings["tls"], protocol=settings["protocol"],
                   on_state=lambda m: warn(m, "cot"))


def _klv_out_sink(destination: str, settings: dict):
    from ..live.klvout import KlvOut

    return KlvOut(destination)


def _map_sink(at: str, settings: dict):
    from ..service.mapsink import MapSink

    host, port = settings["map_host"], settings["map_port"]
    try:
        return MapSink(host, port, settings["session"], settings["source"], silence_s=settings["silence_s"],
                       dem=settings["dem"], config=settings["config"], allow_hosts=tuple(settings["allow_hosts"]),
                       report=_report)
    except OSError as exc:
        fail(f"--map {host}:{port}: cannot serve there: {exc}")


SINKS = {"ndjson": _ndjson_sink, "cot": _cot_sink, "klv_out": _klv_out_sink, "map": _map_sink}
"""Each output of `eoloc live`: its option's value and the run's settings -> a sink of
:func:`eoloc.live.run` (a new output: its sink class, its option above and its line here)."""


def parse_host_port(text: str) -> tuple[str, int]:
    """(host, port) of --map's HOST:PORT (a bare PORT listens on 127.0.0.1)."""
    host, _, port = text.rpartition(":")
    if not port.isdigit() or int(port) > 65535:
        fail(f"--map {text!r}: give HOST:PORT, e.g. 127.0.0.1:8080 (0.0.0.0:8080 to be seen from other machines; "
             "port 0: any free one)")
    return host.strip("[]") or "127.0.0.1", int(port)
