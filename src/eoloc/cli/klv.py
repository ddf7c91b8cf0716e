"""`eoloc klv`: MISB ST 0601/0903 in: check, geolocate, export."""

from __future__ import annotations

import sys
import textwrap

import click

from ..io.klv.conventions import CONVENTIONS
from .common import load_config, open_dem, working
from .main import NOTHING_LOCATED, console, err_console, warn
from .options import (
    basemap_options,
    config_option,
    dem_options,
    formats_option,
    grid_option,
    out_option,
    refine_option,
)

KLV_HELP = """Read MISB ST 0601 metadata (raw .klv/.bin, or MPEG-TS with a KLV data stream), check it,
geolocate its VMTI targets and write everything out.

\b
eoloc klv FILE [--dem F ...] [--config C.toml] [--out DIR] [--basemap TILES] [--tiles OpenStreetMap] [--klv-out OUT.klv]
eoloc klv FLIGHT.ts --refine --dem F [--config C.toml]   (the KLV refined from the video's pixels first)
  Flags as elsewhere: --dem stops the VMTI rays on the terrain instead of at the frame-centre
  elevation; --format picks the fix formats (default csv, geojson, cot).
  1. Decodes every packet: MISB ST 0601 (and the older EG 0104), with ST 0903 VMTI and ST 1607
     sets. A packet is refused only for a bad checksum or a length that runs past the data
     (named with its byte offset); items that depart from the standard (a duplicated tag, a
     long-form length, items out of order, a VMTI set missing mandatory items, a bad nested
     set) are decoded and counted per stream and tag. Each KLV PID of an MPEG-TS is its own
     stream, with its own report-on-change state, in its own time order (a stream column in
     every table; out-of-order packets and time jumps reported).
  2. Recomputes each packet's frame centre and four corners with eoloc's model and prints how far
     they are from what the encoder wrote (median, p90, max): on the ellipsoid at the encoder's
     own frame-centre elevation (so only the pointing model is compared), or on --dem.
  3. Geolocates the ST 0903 VMTI detections (tag 74) with their packet's pose and field of view,
     on --dem or the frame-centre elevation; with a config that has [accuracy.budget], each fix
     gets its uncertainty (sigma, CEP50, CE90, LE90). [installation] angles are applied.
  4. Writes into --out: telemetry.csv (every packet in eoloc's conventions, heights
     ellipsoidal), frames.csv (ours vs the encoder's per packet), footprints.geojson, fixes.csv,
     fixes.geojson, eoloc.kml (all layers), fixes.cot.zip (Cursor-on-Target: a TAK data
     package, one event per fix), map.html
     (self-contained, works offline). --klv-out re-encodes the stream with each packet's first
     fix in the target location tags 40-42, 45, 46 (only those items and the checksum change).
  5. Convention check: when eoloc's frame centres or VMTI locations disagree with the
     encoder's, tries the alternative readings below and says which one the encoder follows,
     with the agreement under each (also in conventions.csv); --assume NAME applies one.

\b
--assume NAME (encoders seen in the field):
{assume_list}

\b
ST 0601 conventions: platform heading/pitch/roll (5, 90|6, 91|7) are eoloc's yaw/pitch/roll; the
sensor relative azimuth/elevation/roll (18, 19, 20) are the az-el turret's angles, applied after
the platform's: R_ned_cam = Rz(5) Ry(6) Rx(7) . Rz(18) Ry(19) Rx(20). Heights: HAE tags (75, 78)
when sent, else MSL (15, 25) + EGM96 undulation. A tag missing from a packet keeps its last value.
"""


KLV_HELP = KLV_HELP.replace("{assume_list}", "\n".join(
    textwrap.fill(text, 100, initial_indent=f"  {name:22s}", subsequent_indent=" " * 24)
    for name, text in CONVENTIONS.items()))


@click.command(help=KLV_HELP)
@click.argument("path", type=click.Path(dir_okay=False))
@dem_options("DEM file(s) for the frame check and the targets (default: the frame-centre elevation).")
@config_option(required=False, help_text="TOML with [installation] (calibrated misalignments) and [accuracy.budget] "
                                         "(uncertainty).")
@out_option("the products")
@formats_option(default=("csv", "geojson", "cot"))
@grid_option()
@click.option("--map/--no-map", "make_map", default=True, show_default=True, help="Write map.html.")
@basemap_options
@click.option("--klv-out", "--write-klv", "write_klv", type=click.Path(dir_okay=False), default=None,
              help="Write the stream back with the fixes in tags 40-42, 45, 46 (as eoloc live --klv-out).")
@click.option("--footprint-every", type=click.IntRange(1), default=1, show_default=True,
              help="Draw one footprint every N packets.")
@click.option("--strict", is_flag=True, help="Enforce MISB ST 0601 as written (stanag4609 validates each packet): "
                                             "packets that break it are dropped and named. Default: decode what is "
                                             "there and note every departure.")
@click.option("--assume", "assume", multiple=True, type=click.Choice(list(CONVENTIONS)),
              help="Read the stream under an encoder's own convention (repeatable); the convention check prints "
                   "which one the encoder follows. See the list below.")
@refine_option("the KLV of an MPEG-TS from its video's own pixels (eoloc refine, its defaults, into OUT/refine/; "
               "needs --dem), then read OUT/refine/NAME_refined.ts (and, with --config, NAME_refined.toml: the "
               "refined budget).")
def klv(path, dem_paths, vertical, geoid, dem_crs, config_path, out_dir, formats, grid, make_map, basemap, world,
        tiles, write_klv, footprint_every, strict, assume, refine_first) -> None:
    from ..jobs.klv import klv_job, write_klv_products
    from .render import print_klv_job

    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    if refine_first:
        from pathlib import Path

        from .refined import refine_video_first

        if assume:
            raise click.UsageError("--refine reads the KLV as ST 0601 writes it: leave out --assume (refine a stream "
                                   "that follows the standard)")
        path, _, config_path = refine_video_first(path, None, config_path, dem, Path(out_dir) / "refine")
    from ..jobs.setup import misb_setup

    sensor, budget = misb_setup(load_config(config_path) if config_path else None)
    with working("decoding and locating..."):
        job = klv_job(path, dem=dem, sensor=sensor, budget=budget, footprint_every=footprint_every, strict=strict,
                      assume=assume)
    print_klv_job(job, console, err_console)
    written, notes = write_klv_products(job, out_dir, formats=formats, grid=grid, make_map=make_map, tiles=tiles,
                                        klv_out=write_klv, basemap=basemap, world=world)
    for note in notes:
        warn(note, "note")
    for i, note in enumerate(job.notes):
        warn(("nothing was located: " if job.located_nothing and i == 0 else "") + note)
    err_console.print("wrote " + ", ".join(str(p) for p in written))
    if job.located_nothing:
        sys.exit(NOTHING_LOCATED)
