"""`eoloc serve`: the HTTP JSON API on uvicorn."""

from __future__ import annotations

from pathlib import Path

import click

from .common import load_config
from .main import err_console, fail
from .options import config_option, dem_options

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
  GET /v1/health   alive, uptime, requests served, the config and DEM names.
  --dem NAME=PATH (repeatable) makes the DEM usable as {"dem": NAME}; --dem PATH names it by its
  file name without the extension.
"""


@click.command(help=SERVE_HELP)
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on (0.0.0.0: every one).")
@click.option("--port", type=click.IntRange(0, 65535), default=8000, show_default=True, help="TCP port (0: any free).")
@config_option(required=False, help_text="TOML: the default camera, gimbal, installation and [accuracy.budget].")
@dem_options("A DEM the requests can name: NAME=PATH or PATH; repeat for several.")
@click.option("--max-body-mb", type=click.FloatRange(0.001), default=8.0, show_default=True,
              help="Largest request body accepted, MB.")
def serve(host, port, config_path, dem_paths, vertical, geoid, dem_crs, max_body_mb) -> None:
    import uvicorn

    from ..service.api import ServiceState, create_app
    from ..terrain import open_dem

    dems = {}
    for item in dem_paths:
        name, _, path = item.rpartition("=") if "=" in item else (Path(item).stem, "", item)
        if not name or name in dems:
            fail(f"--dem {item!r}: give each DEM a name of its own (NAME=PATH)")
        with err_console.status(f"reading DEM {name}..."):
            dems[name] = open_dem([path], vertical=vertical, geoid=geoid, assume_crs=dem_crs)
    state = ServiceState(load_config(config_path) if config_path else None, dems)
    app = create_app(state, max_body_bytes=int(max_body_mb * 1024 * 1024))
    err_console.print(f"eoloc serve: http://{host}:{port}/docs (Ctrl-C stops)")
    uvicorn.run(app, host=host, port=port, log_level="info")
