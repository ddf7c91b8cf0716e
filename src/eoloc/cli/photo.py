"""`eoloc photo`: drone photos located from their own EXIF/XMP."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .common import ground, open_dem, working
from .main import NOTHING_LOCATED, console, err_console, warn
from .options import (
    CONVENTIONS,
    config_option,
    formats_option,
    ortho_options,
    out_option,
    poses_option,
    refine_option,
    tak_connection,
    tak_options,
)
from .render import titled_table

PHOTO_HELP = """Drone photos: the camera's pose read from each photo's own EXIF/XMP, the target located.

\b
eoloc photo PHOTO|FOLDER... [--pixel U V]... [--dem FILE | --target-height H] [--ortho] [--json] [--out DIR]
  A FOLDER stands for every photo in it (JPEG/TIFF by content, sorted by name).
  Writes photo_fixes.* and, with a ground (--dem or --target-height), photo_footprints.* (each
  photo's footprint); --ortho: every photo orthorectified onto that ground, ortho/<photo>.tif.
  Each photo's position, camera attitude (earth-referenced: DJI's gimbal angles are the camera's,
  not relative to the aircraft) and intrinsics (its own calibration, else the bundled drone camera
  database, else EXIF's 35 mm focal length) are read and shown. Without --pixel the image centre
  is located — by the laser range finder's distance when the photo has one (DJI H20/M30/M3T:
  LRFTargetDistance; DJI's own LRFTarget answer is shown beside eoloc's), else on the DEM or the
  target height; with --pixel U V (repeatable) every pixel given, on the DEM or the height.
  --poses FILE: the camera poses of eoloc refine (photos_refined.csv, or its --json lines) instead
  of the photos' own, by file name; --refine: refined first from the set's own overlap (eoloc
  refine into OUT/refine/, needs --dem), then located with them.
  Vendors: DJI (drone-dji:), Skydio (drone-skydio:), Parrot (drone-parrot:), Autel (drone-dji:
  or Pix4D Camera:), Teal (exif:Platform*/Camera*). Heights are ellipsoidal (converted from EGM96
  where the vendor's tag is MSL: README, Input formats).
  --json: one object per line (file, u, v, lat, lon, h, status, source, camera_lat, camera_lon,
  camera_h, camera_yaw, camera_pitch, camera_roll: the optical axis' azimuth from true north, its
  elevation, negative below the horizon, and the image's roll). A photo that
  cannot be read is named with the tag and the fix; the others are still located.
  --config C.toml with [accuracy.budget] (the camera comes from the photos): each fix's
  first-order uncertainty (sigma_e_m, sigma_n_m, sigma_u_m, cep50_m, ce90_m, le90_m; yaw_deg,
  pitch_deg, roll_deg are the camera attitude's errors, lat_deg, lon_deg, h_m the position's,
  range_m the laser's).
  --cot URL: each located point sent to TAK as it is sent by eoloc live (udp://, tcp://, tls://
  with --tak-cert or --tak-package), uid eoloc-<photo name>[-<pixel>], ce/le its 1-sigma
  errors from the budget (unknown, 9999999, without one).
"""


@click.command(help=PHOTO_HELP + CONVENTIONS)
@click.argument("photos", nargs=-1, required=True, type=click.Path())
@click.option("--pixel", "pixels", type=(float, float), multiple=True, metavar="U V",
              help="A pixel to locate (column, row; 0,0 the centre of the top-left pixel); repeat for several.")
@ortho_options(gsd_default="each photo's native GSD at its centre")
@click.option("--ortho", "write_orthos", is_flag=True,
              help="Also orthorectify every photo onto the ground (--dem or --target-height): ortho/<photo>.tif, "
                   "Cloud-Optimised GeoTIFFs (--crs, --gsd, --resampling, --nodata, --occlusion as eoloc rectify).")
@config_option(required=False, help_text="TOML with [accuracy.budget]: each fix's uncertainty (the camera comes "
                                         "from the photos).")
@poses_option("With a --config budget, give refine's refined one (its config_refined.toml).")
@refine_option("the set's camera poses from the photos' own overlap (eoloc refine, its defaults, into OUT/refine/; "
               "needs --dem and three or more overlapping photos), then locate with them (and with --config, its "
               "refined budget).")
@click.option("--json", "as_json", is_flag=True, help="One JSON object per fix on stdout.")
@out_option("photo_fixes.*")
@formats_option()
@tak_options
def photo(photos, pixels, rule_values, dem_paths, vertical, geoid, dem_crs, crs, gsd, resampling, nodata, occlusion,
          write_orthos, config_path, poses_path, refine_first, as_json, out_dir, formats, cot_urls, tak_cert,
          tak_cert_password, tak_ca, tak_package, tak_protocol) -> None:
    import orjson

    from ..jobs.photo import OrthoSettings, photo_job

    cot_urls, tak_tls = tak_connection(cot_urls, tak_cert, tak_cert_password, tak_ca, tak_package)
    budget = None
    if config_path is not None:
        from ..jobs.setup import error_budget
        from .common import load_config

        budget = error_budget(load_config(config_path), config_path)
    dem = open_dem(dem_paths, vertical, geoid, dem_crs)
    rule = ground(rule_values, dem, required=False)
    if write_orthos and rule is None:
        raise click.UsageError("--ortho needs the ground to rectify onto: give --dem FILE or --target-height H")
    settings = OrthoSettings(crs, gsd, resampling, nodata, occlusion)
    poses = None
    if refine_first:
        from .refined import refine_photos_first

        if poses_path is not None:
            raise click.UsageError("give --refine or --poses FILE, not both")
        poses, poses_path, refined_config = refine_photos_first(photos, dem, Path(out_dir) / "refine", config_path)
        if budget is not None:  # what refinement left unknown
            from ..jobs.setup import error_budget
            from .common import load_config

            budget = error_budget(load_config(refined_config), refined_config)
    elif poses_path is not None:
        from ..io.photo import read_photo_poses

        poses = read_photo_poses(poses_path)
    with working("orthorectifying the photos..." if write_orthos else "reading the photos..."):
        job = photo_job(photos, pixels=pixels, ground=rule, budget=budget,
                        ortho_dir=Path(out_dir) / "ortho" if write_orthos else None, ortho=settings, poses=poses,
                        poses_from=str(poses_path or ""))
    for msg in job.failed:
        warn(msg)
    if as_json:
        out = sys.stdout.buffer
        for row in job.rows:
            out.write(orjson.dumps(row, option=orjson.OPT_SERIALIZE_NUMPY) + b"\n")
        out.flush()
    else:
        for p in job.photos:
            err_console.print(f"[bold]{p.path}[/]: {p.make} {p.model} {p.width}x{p.height}"
                              f"{' thermal' if p.thermal else ''}; camera at {p.lat_deg:.7f}, {p.lon_deg:.7f}, "
                              f"h {p.h_m:.2f} m ({p.height_rule}); yaw {p.yaw_deg:.2f}° pitch {p.pitch_deg:.2f}° "
                              f"roll {p.roll_deg:.2f}°; intrinsics: {p.camera_source}"
                              + (f"; laser range {p.lrf_range_m:g} m" if p.lrf_range_m else "")
                              + "".join(f"; {n}" for n in p.notes))
        table = titled_table("photo fixes (heights ellipsoidal)")
        for c in ("photo", "pixel", "lat, lon (°)", "h (m)", "by", "status", "vs the drone's own"):
            table.add_column(c, justify="right", overflow="fold")
        for r in job.rows:
            if "lat" not in r:
                continue
            vs = (f"{r['vendor_offset_h_m']:.2f} m horiz., {r['vendor_offset_v_m']:+.2f} m vert."
                  if "vendor_offset_h_m" in r else "")
            where = f"{r['lat']:.7f}, {r['lon']:.7f}" if r["lat"] is not None else ""
            table.add_row(click.format_filename(r["file"], shorten=True), f"{r['u']:g}, {r['v']:g}", where,
                          f"{r['h']:.2f}" if r["h"] is not None else "", r["source"], r["status"], vs)
        console.print(table)
    from ..io.writers import write_layer

    # the files in eoloc's column vocabulary (lat_deg, lon_deg, h_m: every format, KML and CoT too);
    # --json keeps its documented short keys
    names = {"lat": "lat_deg", "lon": "lon_deg", "h": "h_m", "u": "u_px", "v": "v_px"}
    rows = [{names.get(k, k): v for k, v in r.items()} for r in job.rows if "lat" in r]
    written = write_layer(out_dir, "photo_fixes", rows, formats)
    if job.footprints:  # each photo's footprint on the ground given (formats without polygons skip it)
        written += write_layer(out_dir, "photo_footprints", [f["properties"] for f in job.footprints],
                               [f for f in formats if f not in ("csv", "cot")] or ["geojson"], features=job.footprints)
    written += job.orthos
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
    if cot_urls:
        send_photo_fixes(job.rows, cot_urls, tak_tls, tak_protocol, pixels_given=bool(pixels))
    if not any(r.get("status") == "OK" for r in job.rows):
        warn("nothing was located: no photo could be located" +
             (f" ({len(job.failed)} named above)" if job.failed else ""))
        sys.exit(NOTHING_LOCATED)


def send_photo_fixes(rows: list[dict], urls: list[str], tls, protocol: str, *, pixels_given: bool) -> None:
    """Each located point as a CoT event to every URL (one summary line; a certificate problem
    ends the command with its one-line error)."""
    import json
    from pathlib import Path

    from ..io.cot import cot_event_bytes
    from ..live.cotfeed import CotFeed
    from ..live.senders import send_events
    from .main import fail

    events, per_photo = [], {}
    for r in rows:
        if r.get("status") != "OK":
            continue
        k = per_photo[r["file"]] = per_photo.get(r["file"], -1) + 1
        name = Path(r["file"]).stem + (f"-{k}" if pixels_given else "")
        events.append(cot_event_bytes({**r, "lat_deg": r["lat"], "lon_deg": r["lon"], "h_m": r["h"],
                                       "target_id": name}, stale_s=3600.0))
    feed = CotFeed()
    summaries, fatal = send_events(urls, events, tls=tls, protocol=protocol, hello=feed.presence,
                                   uid=feed.presence_uid(), on_state=lambda m: warn(m, "cot"))
    if fatal:
        fail(fatal)
    err_console.print(f"CoT: {len(events)} events -> " + json.dumps(summaries), soft_wrap=True, highlight=False)
