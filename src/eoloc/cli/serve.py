"""`eoloc serve`: the HTTP JSON API on uvicorn."""

from __future__ import annotations

from pathlib import Path

import click

from ..service.http import REQUEST_TIMEOUT_S, SEND_TIMEOUT_S
from .common import load_config, working
from .main import err_console, fail
from .options import allow_host_option, config_option, dem_options

SERVE_HELP = """Serve eoloc's HTTP JSON API (OpenAPI docs at http://HOST:PORT/docs).

\b
eoloc serve [--host 127.0.0.1] [--port 8000] [--config C] [--dem NAME=PATH ...]
  POST /v1/locate  one observation or {"observations": [...]}:
    {"pose": {"lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal_deg": [a, b]},
     "gimbal": "az-el" | "roll-pitch", "pixels": [[u, v], ...] (default: the image centre),
     "stop": {"range_m": R} | {"target_height_m": H} | {"dem": NAME},
     "camera": {"width", "height", "hfov_deg" | "fx", ...} (default: --config's), "covariance": false}
    -> {"fixes": [{"lat_deg", "lon_deg", "h_m", "range_m", "status", "u_px", "v_px"}, ...]}
    Degrees WGS-84, heights ellipsoidal metres, angles as in the README's conventions; a fix that
    failed has its status and no coordinates. Errors: JSON naming the field (HTTP 422); bodies
    over --max-body-mb: 413.
  POST /v1/locate/arrow  the same observation with its pixels as Arrow columns: an Arrow IPC
    stream (content-type application/vnd.apache.arrow.stream) of u_px, v_px whose schema
    metadata 'eoloc' holds the observation's JSON without pixels -> an Arrow IPC stream of the
    fixes (null coordinates where a fix failed): big batches with no JSON to parse.
  POST /v1/photo?pixel=U,V&target_height_m=H&dem=NAME&covariance=true  a drone photo as it was
    taken (content-type image/jpeg or image/tiff; its pose from its own EXIF/XMP, as eoloc photo
    reads it) -> {"photo": {...}, "fixes": [rows as eoloc photo --json]}: the image centre (by
    its laser range when it has one) or each pixel=U,V (repeatable). Full-size photos can exceed
    the 8 MB default: start with --max-body-mb 32.
  GET /v1/health   alive, uptime, requests served, the config and DEM names.
  Limits: bodies over --max-body-mb: 413; Arrow streams declaring more than 10^5 rows or 64 MB
  once decompressed: 413 (checked before decoding); a request that has not arrived whole after
  --request-timeout: 408 and cut; an answer left unread for --send-timeout: cut; Host headers
  other than this server's names (loopback, --host, --allow-host): 400.
  --dem PATH (repeatable) as on every command: the tiles of one DEM, named by the first file's
  name without the extension; --dem NAME=PATH names the DEM, so that several can be served (the
  same NAME repeated joins tiles into one DEM); requests ask for it as {"dem": NAME}.
  --player DIR     serves `eoloc video`'s output folder DIR at /video/ (/ leads to its
                   player.html): the page then locates a click in the video through /v1/locate,
                   exactly. `eoloc video` prints the serve line that matches its own DEM and config.
"""


@click.command(help=SERVE_HELP)
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on (0.0.0.0: every one).")
@click.option("--port", type=click.IntRange(0, 65535), default=8000, show_default=True, help="TCP port (0: any free).")
@config_option(required=False, help_text="TOML: the default camera, gimbal, installation and [accuracy.budget].")
@dem_options("DEM tiles the requests can stop on: PATH (repeat for tiles of one DEM) or NAME=PATH (several DEMs).")
@click.option("--max-body-mb", type=click.FloatRange(0.001), default=8.0, show_default=True,
              help="Largest request body accepted, MB.")
@click.option("--player", "player_dir", type=click.Path(file_okay=False, exists=True), default=None,
              help="`eoloc video`'s output folder to serve at /video/ (its player.html).")
@allow_host_option
@click.option("--request-timeout", "request_timeout_s", type=click.FloatRange(0.1), default=REQUEST_TIMEOUT_S,
              show_default=True, help="Seconds a request (headers and body) may take to arrive whole; then 408.")
@click.option("--send-timeout", "send_timeout_s", type=click.FloatRange(0.1), default=SEND_TIMEOUT_S,
              show_default=True, help="Seconds a client may leave its answer unread before it is cut.")
def serve(host, port, config_path, dem_paths, vertical, geoid, dem_crs, max_body_mb, player_dir, allow_hosts,
          request_timeout_s, send_timeout_s) -> None:
    import uvicorn

    from ..service.api import ServiceState, create_app
    from ..service.http import allowed_hosts, server_config
    from ..terrain import open_dem

    tiles: dict[str, list[str]] = {}
    plain = [item for item in dem_paths if "=" not in item]  # as everywhere: tiles of one DEM
    for item in dem_paths:
        name, _, path = item.rpartition("=") if "=" in item else (Path(plain[0]).stem, "", item)
        if not name:
            fail(f"--dem {item!r}: give the DEM a name (NAME=PATH)")
        tiles.setdefault(name, []).append(path)
    dems = {}
    for name, paths in tiles.items():
        with working(f"reading DEM {name}..."):
            dems[name] = open_dem(paths, vertical=vertical, geoid=geoid, assume_crs=dem_crs)
    if player_dir is not None and not (Path(player_dir) / "player.html").is_file():
        fail(f"--player {player_dir}: no player.html in it (write one with `eoloc video ... --out {player_dir}`)")
    state = ServiceState(load_config(config_path) if config_path else None, dems)
    app = create_app(state, max_body_bytes=int(max_body_mb * 1024 * 1024), player_dir=player_dir,
                     hosts=allowed_hosts(host, allow_hosts))
    err_console.print(f"eoloc serve: http://{host}:{port}/docs (Ctrl-C stops)")
    if player_dir is not None:
        err_console.print(f"the player: http://{host}:{port}/video/player.html")
    uvicorn.Server(server_config(app, host, port, request_timeout_s=request_timeout_s, send_timeout_s=send_timeout_s,
                                 log_level="info")).run()
