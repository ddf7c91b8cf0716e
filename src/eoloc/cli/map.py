"""`eoloc map`: a self-contained HTML map of eoloc outputs."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ..errors import InputError
from .common import open_dem
from .main import err_console, warn
from .options import basemap_options, dem_options, out_option

MAP_HELP = """Write a self-contained HTML map (works offline) from eoloc outputs.

\b
eoloc map [--telemetry T.csv] [--fixes F.geojson ...] [--footprints P.geojson] [--tracks K.geojson]
          [--dem D.tif ...] [--basemap TILES] [--out DIR | -o FILE.html]
  --telemetry draws the aircraft path (an eoloc telemetry CSV: lat_deg, lon_deg, h_m);
  --fixes draws targets, with their CEP50 as a circle in metres where the file has cep50_m;
  --footprints draws frame outlines; --tracks draws track LineStrings (eoloc track);
  Underneath, offline: the bundled world layer (Natural Earth countries; --no-world leaves it
  out), --basemap TILES (an MBTiles file or a folder of {z}/{x}/{y}.png XYZ tiles, e.g. from
  QGIS's "Generate XYZ tiles" or gdal2tiles --xyz: the tiles over the map's area are embedded,
  coarse zooms first, up to 24 MB), --dem's hillshade (tiles, --vertical, --geoid, --dem-crs as
  on every command); --tiles adds web tiles (needs a network). Footprints and fixes with a time
  get a time slider (everything up to a time, or that time only); over 8 footprints are drawn
  as outlines coloured from early (blue) to late (yellow).
  Writes DIR/map.html (--out, as every command: default eoloc-out/map), or the file -o names.
"""


@click.command(name="map", help=MAP_HELP)
@click.option("--telemetry", type=click.Path(dir_okay=False), default=None, help="Telemetry CSV (aircraft path).")
@click.option("--fixes", multiple=True, type=click.Path(dir_okay=False), help="Fixes GeoJSON (repeatable).")
@click.option("--footprints", multiple=True, type=click.Path(dir_okay=False), help="Footprints GeoJSON.")
@click.option("--tracks", multiple=True, type=click.Path(dir_okay=False), help="Tracks GeoJSON.")
@dem_options("DEM file(s) for a hillshade; repeat for tiles.")
@basemap_options
@out_option("map.html")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              help="The HTML file to write, instead of DIR/map.html.")
@click.option("--title", default="eoloc", show_default=True, help="Title of the page.")
def map_command(telemetry, fixes, footprints, tracks, dem_paths, vertical, geoid, dem_crs, basemap, world, tiles,
                out_dir, output, title) -> None:
    from ..io.mapview import drawable, write_map

    aircraft = None
    if telemetry:
        from ..io.telemetry import read_telemetry
        from ..jobs.klvframes import aircraft_feature

        aircraft = [aircraft_feature(read_telemetry(telemetry))]
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    if output is None:
        output = Path(out_dir) / "map.html"
        output.parent.mkdir(parents=True, exist_ok=True)
    layers = dict(targets=_features(fixes), footprints=_features(footprints), tracks=_features(tracks))
    if not drawable(aircraft, *layers.values()):
        raise InputError("nothing to draw: give --telemetry, --fixes, --footprints or --tracks files that have located "
                         "points")
    notes: list[str] = []
    path = write_map(output, aircraft=aircraft, **layers, dem=dem, tiles=tiles, title=title, basemap=basemap,
                     world=world, notes=notes)
    for note in notes:
        warn(note, "note")
    err_console.print(f"wrote [bold]{path}[/]")


def _features(paths) -> list[dict]:
    feats: list[dict] = []
    for p in paths:
        try:
            doc = json.loads(Path(p).read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{p}: not a readable GeoJSON file ({exc})") from None
        if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
            kind = doc.get("type") if isinstance(doc, dict) else type(doc).__name__
            raise InputError(f"{p}: expected a GeoJSON FeatureCollection, found {kind!r}")
        feats += doc["features"]
    return feats
