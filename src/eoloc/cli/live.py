"""`eoloc live`: a KLV stream as it arrives -> located VMTI targets as NDJSON."""

from __future__ import annotations

import json
import signal
import sys
import time

import click

from .common import open_dem
from .main import err_console, fail, warn
from .options import config_option, dem_options

LIVE_HELP = """Locate the VMTI targets of a live MISB ST 0601 stream, packet by packet, as it arrives.

\b
eoloc live SOURCE [--dem F] [--config C] --ndjson FILE|-
  SOURCE: udp://HOST:PORT (raw KLV datagrams, one or more whole packets each; a multicast
  HOST such as 239.1.1.1 is joined), or a raw KLV file replayed packet by packet (--realtime:
  at the stream's own clock).
  Each packet is decoded as `eoloc klv` decodes files (checksums, report-on-change values carried
  from packet to packet) and its targets located on --dem, else on the packet's frame-centre
  elevation; with the config's [accuracy.budget] each fix gets its uncertainty.
  --ndjson FILE|-: one GeoJSON Feature per located target per line (lon, lat, ellipsoidal h;
  a failed fix keeps its status with a null geometry), flushed as it is written.
  Faults are counted, never fatal: corrupt or non-KLV datagrams, duplicated packets (dropped),
  late ones (located all the same), encoder restarts (time back > 2 s), silence (--silence S:
  a warning on stderr).
  Ctrl-C (SIGINT) or SIGTERM, --packets N or --duration S stop it with a summary on stderr:
  datagrams, packets, detections, fixes, faults and the latency from arrival to output.
"""


@click.command(help=LIVE_HELP)
@click.argument("source")
@dem_options("Terrain: DEM file(s) for the targets (default: each packet's frame-centre elevation).")
@config_option(required=False, help_text="TOML with [installation] (calibrated misalignments) and "
                                         "[accuracy.budget] (uncertainty).")
@click.option("--ndjson", "ndjson", required=True, metavar="FILE|-",
              help="Write one GeoJSON feature per located target per line ('-': stdout).")
@click.option("--realtime", is_flag=True, help="A file SOURCE: replay at the stream's own clock.")
@click.option("--packets", "max_packets", type=click.IntRange(1), default=None, help="Stop after N good packets.")
@click.option("--duration", type=click.FloatRange(0.0, min_open=True), default=None, metavar="S",
              help="Stop after S seconds.")
@click.option("--silence", type=click.FloatRange(0.0, min_open=True), default=3.0, show_default=True, metavar="S",
              help="Warn when nothing arrives for S seconds.")
def live(source, dem_paths, vertical, geoid, dem_crs, config_path, ndjson, realtime, max_packets, duration,
         silence) -> None:
    from ..live.session import LiveSession
    from ..live.sources import file_packets, udp_datagrams, udp_socket

    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    from ..jobs.setup import misb_setup
    from .common import load_config

    sensor, budget = misb_setup(load_config(config_path) if config_path else None)
    session = LiveSession(source, dem=dem, sensor=sensor, budget=budget)
    stopping = {"why": None}
    started = time.monotonic()

    def stop() -> bool:
        if duration is not None and time.monotonic() - started > duration:
            stopping["why"] = stopping["why"] or f"--duration {duration:g} s"
        if max_packets is not None and session.counters.packets >= max_packets:
            stopping["why"] = stopping["why"] or f"--packets {max_packets}"
        return stopping["why"] is not None

    def on_signal(signum, _frame) -> None:
        stopping["why"] = signal.Signals(signum).name

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    if source.startswith("udp://"):
        sock = udp_socket(source)
        err_console.print(f"eoloc live: listening on {source} (Ctrl-C stops)")
        feed = udp_datagrams(sock, stop, silence_s=silence,
                             on_silence=lambda s: warn(f"{source}: nothing received for {s:.0f} s", "silence"))
    elif source.startswith(("rtsp://", "srt://", "tcp://")) or source == "-":
        fail(f"{source!r}: eoloc live reads udp://HOST:PORT and raw KLV files for now")
    else:
        feed = file_packets(source, stop, realtime=realtime)
    out = sys.stdout if ndjson == "-" else open(ndjson, "w", encoding="utf-8")
    seen_issues = 0
    try:
        for datagram, arrived in feed:
            for feature in session.feed(datagram, arrived):
                out.write(json.dumps(feature, allow_nan=False) + "\n")
            out.flush()
            for issue in session.issues[seen_issues:]:
                warn(issue, "packet")
            seen_issues = len(session.issues)
            if stop():
                break
    finally:
        if out is not sys.stdout:
            out.close()
    summary = session.counters.summary()
    err_console.print(f"eoloc live stopped ({stopping['why'] or 'end of the source'}): "
                      + json.dumps(summary), soft_wrap=True, highlight=False)
