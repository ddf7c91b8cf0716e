"""`eoloc klv` (MISB ST 0601/0903 in: check, geolocate, export) and `eoloc map` (HTML map)."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table as RichTable

from .cli_common import dem_options, err_console, fail, load_config_or_fail, main, open_dem_or_fail, report_issues
from .io.export import fix_rows, write_csv, write_feature_collection, write_geojson

KLV_HELP = """Read MISB ST 0601 metadata (raw .klv/.bin, or MPEG-TS with a KLV data stream), check it,
geolocate its VMTI targets and write everything out.

\b
eoloc klv FILE [--dem F ...] [--config C.toml] [--out DIR] [--tiles OpenStreetMap] [--write-klv OUT.klv]
  1. Decodes every packet (checksums verified). Corrupt and truncated packets are counted,
     named with their byte offset and skipped; every good packet is kept.
  2. Recomputes each packet's frame centre and four corners with eoloc's model and prints how far
     they are from what the encoder wrote (median, p90, max): on the ellipsoid at the encoder's
     own frame-centre elevation (so only the pointing model is compared), or on --dem.
  3. Geolocates the ST 0903 VMTI detections (tag 74) with their packet's pose and field of view,
     on --dem or the frame-centre elevation; with a config that has [accuracy.budget], each fix
     gets its uncertainty (sigma, CEP50, CE90, LE90). [installation] angles are applied.
  4. Writes into --out: telemetry.csv (every packet in eoloc's conventions, heights
     ellipsoidal), frames.csv (ours vs the encoder's per packet), footprints.geojson, fixes.csv,
     fixes.geojson, eoloc.kml (all layers), fixes.cot.xml (Cursor-on-Target for TAK), map.html
     (self-contained, works offline). --write-klv re-encodes the stream with each packet's first
     fix in the target location tags 40-42, 45, 46.

\b
ST 0601 conventions: platform heading/pitch/roll (5, 90|6, 91|7) are eoloc's yaw/pitch/roll; the
sensor relative azimuth/elevation/roll (18, 19, 20) are the az-el turret's angles, applied after
the platform's: R_ned_cam = Rz(5) Ry(6) Rx(7) . Rz(18) Ry(19) Rx(20). Heights: HAE tags (75, 78)
when sent, else MSL (15, 25) + EGM96 undulation. A tag missing from a packet keeps its last value.
"""


@main.command(help=KLV_HELP)
@click.argument("path", type=click.Path(dir_okay=False))
@dem_options("DEM file(s) for the frame check and the targets (default: the frame-centre elevation).")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="TOML with [installation] (calibrated misalignments) and [accuracy.budget] (uncertainty).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="eoloc-out", show_default=True,
              help="Output folder.")
@click.option("--map/--no-map", "make_map", default=True, show_default=True, help="Write map.html.")
@click.option("--tiles", default=None, help="Web map tiles under the map (e.g. OpenStreetMap; needs a network).")
@click.option("--write-klv", "write_klv", type=click.Path(dir_okay=False), default=None,
              help="Write the stream back with the fixes in tags 40-46.")
@click.option("--footprint-every", type=click.IntRange(1), default=1, show_default=True,
              help="Draw one footprint every N packets.")
def klv(path, dem_paths, vertical, geoid, dem_crs, config_path, out_dir, make_map, tiles, write_klv,
        footprint_every) -> None:
    console = Console()
    dem = open_dem_or_fail(dem_paths, vertical, geoid, dem_crs) if dem_paths else None
    sensor, budget = None, None
    if config_path:
        from .accuracy.budget import ErrorBudget
        from .misb import misb_sensor

        cfg = load_config_or_fail(config_path)
        inst = cfg.installation
        sensor = misb_sensor(inst.mount_misalignment_deg, inst.boresight_misalignment_deg, inst.lever_arm_m)
        budget = ErrorBudget.from_mapping(cfg.accuracy.budget) if cfg.accuracy is not None else None
    klv_job(path, Path(out_dir), console=console, dem=dem, sensor=sensor, budget=budget, make_map=make_map,
            tiles=tiles, write_klv=write_klv, footprint_every=footprint_every)


def klv_job(path, out: Path, *, console: Console, dem=None, sensor=None, budget=None, make_map: bool = True,
            tiles: str | None = None, write_klv=None, footprint_every: int = 1) -> dict:
    """The whole `eoloc klv` job (also run by `eoloc demo`): returns {"check": FrameCheck, "fixes":
    VMTIFixes | None, "written": [paths]}."""
    from .io.klv import KLVError, klv_telemetry, read_klv, vmti_detections
    from .misb import misb_sensor
    from .video import aircraft_feature, check_frames, dem_footprint_features, footprint_features, locate_vmti

    try:
        stream = read_klv(path)
    except KLVError as exc:
        fail(str(exc))
    _print_packets(console, stream)
    if not stream.packets:
        fail(f"{path}: no packet could be decoded, so there is nothing to locate")
    sensor = sensor or misb_sensor()
    tel = klv_telemetry(stream)
    c = tel.columns
    t = c["time_s"][np.isfinite(c["time_s"])]
    if t.size:
        console.print(f"{len(tel)} packets over {t[-1] - t[0]:.1f} s; sensor at {np.nanmin(c['h_m']):.0f}-"
                      f"{np.nanmax(c['h_m']):.0f} m ellipsoidal; HFOV {np.nanmin(c['hfov_deg']):.2f}-"
                      f"{np.nanmax(c['hfov_deg']):.2f}°")
    out.mkdir(parents=True, exist_ok=True)
    check = check_frames(tel, dem, sensor=sensor)
    _print_check(console, check, "the DEM" if dem is not None else "the ellipsoid at the encoder's frame-centre "
                 "elevation")
    if dem is not None:
        console.print("[dim]On a DEM the corners are compared with the encoder's own surface for them (often a level "
                      "plane through the frame centre, or a coarser terrain model): far corners of an oblique view "
                      "differ by the terrain, not the pointing. Leave out --dem to compare the pointing alone.[/]")
    det = vmti_detections(stream)
    report_issues(det.issues)
    written = [write_csv(out / "telemetry.csv", _table_rows(tel)),
               write_csv(out / "frames.csv", _frame_rows(tel, check))]
    prints = (dem_footprint_features(tel, dem, sensor, every=footprint_every) if dem is not None else
              footprint_features(tel, check.geometry, every=footprint_every))
    encoder_prints = footprint_features(tel, None, every=footprint_every)
    track = aircraft_feature(tel)
    written.append(write_feature_collection(out / "footprints.geojson", prints))
    layers = {"aircraft": [track], "footprints": prints, "encoder footprints": encoder_prints}
    rows: list[dict] = []
    v = None
    if len(det):
        v = locate_vmti(tel, det, dem, budget=budget, base=sensor)
        rows = fix_rows(v.fixes, v.extra, v.uncertainty)
        counts = v.fixes.status_counts()
        console.print(f"VMTI: {len(det)} detections of {len(set(det.columns['target_id']))} targets located on "
                      f"{'the DEM' if dem is not None else 'the frame-centre elevation'}: {counts}"
                      + ("" if budget else " (no [accuracy.budget] given: no uncertainty)"))
        from .io.cot import write_cot

        written += [write_csv(out / "fixes.csv", rows), write_geojson(out / "fixes.geojson", rows)]
        cot_path, n_cot = write_cot(out / "fixes.cot.xml", rows)
        written.append(cot_path)
        from .io.export import fix_features

        layers["fixes"] = fix_features(rows)
        if write_klv:
            written.append(_write_klv(Path(write_klv), stream, tel, v))
    else:
        console.print("no VMTI detections (tag 74) in this stream: frame centres and footprints only")
    from .io.kml import write_kml

    written.append(write_kml(out / "eoloc.kml", layers, name=Path(path).name))
    from .io.mapview import drawable, write_map

    if make_map and not drawable([track], prints, encoder_prints, layers.get("fixes")):
        console.print("no map: the stream has no aircraft position, footprint or fix to draw")
    elif make_map:
        written.append(write_map(out / "map.html", aircraft=[track], footprints=prints,
                                 encoder_footprints=encoder_prints, targets=layers.get("fixes"), dem=dem, tiles=tiles,
                                 title=f"eoloc: {Path(path).name}"))
    console.print("wrote " + ", ".join(str(p) for p in written))
    return {"check": check, "fixes": v, "written": written}




def _print_packets(console: Console, stream) -> None:
    console.print(escape(stream.summary()))
    report_issues([str(i) for i in stream.issues])
    for w in stream.field_warnings:
        err_console.print(f"[yellow]note:[/] {escape(w)}", highlight=False)


def _print_check(console: Console, check, surface: str) -> None:
    table = RichTable(title=f"eoloc vs the encoder: horizontal distance (m), ours on {surface}")
    for col in ("", "packets", "median", "p90", "max"):
        table.add_column(col, justify="right")
    for name, n, med, p90, mx in check.stats():
        table.add_row(name, str(n), *(f"{x:.1f}" if np.isfinite(x) else "-" for x in (med, p90, mx)))
    console.print(table)


def _table_rows(tel) -> list[dict]:
    from .io.export import plain_value

    keys = list(tel.columns)
    return [{"packet": int(tel.line[i]), **{k: plain_value(tel.columns[k][i]) for k in keys if k != "frame"}}
            for i in range(len(tel))]


def _frame_rows(tel, check) -> list[dict]:
    from .io.export import plain_value

    g, c = check.geometry, tel.columns
    rows = []
    for i in range(len(tel)):
        row = {"packet": int(tel.line[i]), "time_s": plain_value(c["time_s"][i]),
               "encoder_lat_deg": plain_value(c["fc_lat_deg"][i]), "encoder_lon_deg": plain_value(c["fc_lon_deg"][i]),
               "encoder_h_m": plain_value(c["fc_h_m"][i]), "eoloc_lat_deg": plain_value(g.centre.lat_deg[i]),
               "eoloc_lon_deg": plain_value(g.centre.lon_deg[i]), "eoloc_h_m": plain_value(g.centre.h_m[i]),
               "centre_distance_m": plain_value(check.centre_m[i]), "range_difference_m": plain_value(check.range_m[i])}
        row.update({f"corner{k + 1}_distance_m": plain_value(check.corners_m[i, k]) for k in range(4)})
        rows.append(row)
    return rows


def _write_klv(path: Path, stream, tel, v) -> Path:
    """The stream with each packet's first OK fix (lowest target id) in tags 40-42, 45, 46."""
    from .io.klv import with_target_location

    f = v.fixes
    first: dict[int, int] = {}
    for j in np.flatnonzero(f.ok):
        frame = int(v.extra["frame"][j])
        if frame not in first or v.extra["target_id"][j] < v.extra["target_id"][first[frame]]:
            first[frame] = j
    ce = v.uncertainty.get("ce90_m", np.full(len(f), np.nan))
    le = v.uncertainty.get("le90_m", np.full(len(f), np.nan))
    hae = tel.columns["target_elevation_hae"] > 0  # the datum the reader gives tag 42 in each packet
    from .terrain.geoid import default_geoid

    geoid = default_geoid()
    out = bytearray()
    for i, p in enumerate(stream.packets):
        raw = p.uas.packet.raw
        j = first.get(p.index)
        if j is not None:
            h = float(f.h_m[j]) if hae[i] else float(f.h_m[j] - geoid.undulation(f.lat_deg[j], f.lon_deg[j]))
            raw = with_target_location(raw, float(f.lat_deg[j]), float(f.lon_deg[j]), h, ce90_m=ce[j], le90_m=le[j])
        out += raw
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(out))
    return path


MAP_HELP = """Write a self-contained HTML map (works offline) from eoloc outputs.

\b
eoloc map [--telemetry T.csv] [--fixes F.geojson ...] [--footprints P.geojson] [--tracks K.geojson]
          [--dem D.tif] [-o map.html]
  --telemetry draws the aircraft path (an eoloc telemetry CSV: lat_deg, lon_deg, h_m);
  --fixes draws targets, with their CEP50 as a circle in metres where the file has cep50_m;
  --footprints draws frame outlines; --tracks draws track LineStrings (eoloc track);
  --dem lays a hillshade of the terrain underneath; --tiles adds web tiles (needs a network).
"""


@main.command(name="map", help=MAP_HELP)
@click.option("--telemetry", type=click.Path(dir_okay=False), default=None, help="Telemetry CSV (aircraft path).")
@click.option("--fixes", multiple=True, type=click.Path(dir_okay=False), help="Fixes GeoJSON (repeatable).")
@click.option("--footprints", multiple=True, type=click.Path(dir_okay=False), help="Footprints GeoJSON.")
@click.option("--tracks", multiple=True, type=click.Path(dir_okay=False), help="Tracks GeoJSON.")
@click.option("--dem", "dem_paths", multiple=True, type=click.Path(dir_okay=False), help="DEM for a hillshade.")
@click.option("--tiles", default=None, help="Web map tiles (e.g. OpenStreetMap; needs a network).")
@click.option("-o", "--output", default="map.html", show_default=True, type=click.Path(dir_okay=False))
@click.option("--title", default="eoloc", show_default=True)
def map_command(telemetry, fixes, footprints, tracks, dem_paths, tiles, output, title) -> None:
    from .io.mapview import write_map

    aircraft = None
    if telemetry:
        from .io.table import TableError
        from .io.telemetry import read_telemetry
        from .video import aircraft_feature

        try:
            aircraft = [aircraft_feature(read_telemetry(telemetry))]
        except TableError as exc:
            fail(str(exc))
    dem = open_dem_or_fail(dem_paths, "egm96", None, None) if dem_paths else None
    try:
        path = write_map(output, aircraft=aircraft, targets=_features(fixes), footprints=_features(footprints),
                         tracks=_features(tracks), dem=dem, tiles=tiles, title=title)
    except ValueError as exc:
        fail(f"{exc}: give --telemetry, --fixes, --footprints or --tracks files that have located points")
    Console().print(f"wrote [bold]{path}[/]")


def _features(paths) -> list[dict]:
    feats: list[dict] = []
    for p in paths:
        try:
            doc = json.loads(Path(p).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            fail(f"{p}: not a readable GeoJSON file ({exc})")
        if doc.get("type") != "FeatureCollection":
            fail(f"{p}: expected a GeoJSON FeatureCollection, found type {doc.get('type')!r}")
        feats += doc["features"]
    return feats
