"""What every `eoloc` command shares: the command group, the options declared once (DEM, target
height), the conventions text, and the helpers that read inputs and turn a user's mistake into
one line and exit code 2. The commands (cli.py, cli_*.py) import from here; nothing here imports
a command, so the command modules form no circle."""

from __future__ import annotations

import sys

import click
from rich.console import Console
from rich.markup import escape

from . import __version__
from .errors import ConfigError, EolocError
from .io.table import TableError
from .io.telemetry import read_detections, read_telemetry
from .pipeline import RANGE_FROM_FILES, locate_tables
from .rules import StopRule, rule_from_options

CONVENTIONS = """
\b
Units and conventions (the same everywhere in eoloc):
  lat/lon      WGS-84 geodetic degrees; heights ellipsoidal metres (not MSL)
  yaw          heading, degrees clockwise from true north
  pitch        degrees, nose up positive; roll: degrees, right wing down positive
  attitude     R_ned_body = Rz(yaw) Ry(pitch) Rx(roll); body x nose, y right wing, z down
  az-el        gimbal azimuth about body z (right of the nose +), elevation (up +, -90 = down)
  roll-pitch   framed camera: frame roll about body x (+ looks left), frame pitch (+ looks forward)
  pixels       u = column (right), v = row (down); top-left pixel centre is (0, 0)
  status       OK, NO_INTERSECTION, OUT_OF_COVERAGE, DEM_VOID, INVALID_INPUT, NO_TELEMETRY,
               BELOW_SURFACE (camera on or under the surface), OUT_OF_IMAGE (pixel outside the image),
               DEGENERATE (multi-view rays do not determine a point); coordinates are empty
               wherever the status is not OK
"""


err_console = Console(stderr=True)


def dem_options(dem_help: str):
    """--dem (repeatable), --vertical, --geoid and --dem-crs: the same DEM options on every command."""
    opts = [
        click.option("--dem", "dem_paths", multiple=True, type=click.Path(dir_okay=False), help=dem_help),
        click.option("--vertical", type=click.Choice(["egm96", "egm2008", "ellipsoid"]), default="egm96",
                     show_default=True, help="Vertical datum of the DEM heights (converted to ellipsoidal)."),
        click.option("--geoid", type=click.Path(dir_okay=False), default=None,
                     help="Geoid grid for --vertical (default: the bundled EGM96 15')."),
        click.option("--dem-crs", default=None, help="CRS of a DEM that carries none (ESRI ASCII), e.g. EPSG:4326."),
    ]

    def apply(fn):
        for o in reversed(opts):
            fn = o(fn)
        return fn

    return apply


def target_height_option(help_text: str = "Stop the rays on the surface of this ellipsoidal height (m)."):
    """--target-height H, the same flag on every command where a height surface stops the rays; the
    old --height (which meant the aircraft's height in one place and the target's in another) is
    refused with a message naming the flag to use."""
    def apply(fn):
        fn = click.option("--target-height", "target_height", type=float, default=None, help=help_text)(fn)
        return click.option("--height", "old_height", type=float, default=None, hidden=True, expose_value=False,
                            callback=_refuse_height)(fn)

    return apply


def _refuse_height(ctx: click.Context, param: click.Parameter, value) -> None:
    if value is not None:
        raise click.UsageError("--height is no longer accepted: it meant two things. Give --target-height H for the "
                               "surface the rays stop on (ellipsoidal m), or --aircraft-height H for the aircraft of "
                               "one observation.", ctx)


def fail(message: str) -> None:
    err_console.print(f"[bold red]error:[/] {escape(message)}")  # messages name config sections: [accuracy]
    sys.exit(2)


class _Main(click.Group):
    """The command group: a user's mistake (an EolocError: a file or configuration that cannot be
    used; an OSError: a path that cannot be read or written) becomes a message and exit code 2;
    anything else is a bug in eoloc and keeps its traceback, with a line asking to report it."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except EolocError as exc:
            fail(str(exc))
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            fail(f"{where}{exc.strerror or exc}")
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except Exception:
            err_console.print("[bold red]internal error:[/] this is a bug in eoloc, not in your input. Please report "
                              "it with the command line and the traceback below.")
            raise


@click.group(cls=_Main, help="eoloc - geolocate ground targets seen by airborne electro-optical sensors.\n"
             + CONVENTIONS)
@click.version_option(__version__, prog_name="eoloc")
def main() -> None:
    pass


def open_dem_or_fail(paths, vertical, geoid, dem_crs):
    from .terrain import DEMError, open_dem

    try:
        with err_console.status("reading the DEM..."):
            return open_dem(list(paths), vertical=vertical, geoid=geoid, assume_crs=dem_crs)
    except DEMError as exc:
        fail(str(exc))


def stop_rule(range_opt, target_height, dem=None) -> StopRule | str:
    """The command line's stop rule, parsed once into a rule object (or RANGE_FROM_FILES: M1 with
    each target's range_m column)."""
    if sum(x is not None for x in (range_opt, target_height, dem)) != 1:
        fail("choose one stop rule: --range [R] (laser slant range), --target-height H (ellipsoidal metres) "
              "or --dem FILE (terrain)")
    if range_opt == RANGE_FROM_FILES:
        return RANGE_FROM_FILES
    if range_opt is not None:
        try:
            range_opt = float(range_opt)
        except ValueError:
            fail(f"--range takes metres or nothing (then range_m from the files), got {range_opt!r}")
    return rule_from_options(range_m=range_opt, height_m=target_height, dem=dem)


def load_config(config_path):
    """The TOML configuration (pydantic is imported only by the commands that read one)."""
    from .io.config import load_config as load

    return load(config_path)


def load_config_or_fail(config_path):
    try:
        return load_config(config_path)
    except ConfigError as exc:
        fail(str(exc))


def read_inputs(telemetry, detections, cfg, reader=read_detections):
    """Telemetry (the config's heading bias removed) and the second file, with their issues reported;
    fails when the telemetry has no usable record."""
    from .io.telemetry import with_heading_bias

    try:
        tel = with_heading_bias(read_telemetry(telemetry), cfg.telemetry.heading_bias_deg)
        det = reader(detections) if detections else None
    except TableError as exc:
        fail(str(exc))
    issues = list(tel.issues) + (list(det.issues) if det is not None else [])
    if len(tel) == 0:
        report_issues(issues)
        fail(f"telemetry file {telemetry!r} has no usable record")
    if det is not None and len(det) == 0:
        report_issues(issues)
        fail(f"file {detections!r} has no usable record (only a header?): nothing to locate")
    return tel, det, issues


def locate_with_config(cfg, tel, det, rule, time_tolerance, budget, interp, compensation=None):
    """locate_tables with the config's sensor and time offset (unless --time-offset was given)."""
    interp = dict(interp or {})
    if interp.get("time_offset_s") is None:
        interp["time_offset_s"] = cfg.telemetry.time_offset_s
    with err_console.status("locating..."):
        try:
            return locate_tables(cfg.sensor(), tel, det, rule,
                                 time_tolerance_s=time_tolerance, budget=budget, compensation=compensation,
                                 **interp)
        except ValueError as exc:
            fail(str(exc))


def report_issues(issues, limit: int = 15) -> None:
    for issue in issues[:limit]:
        err_console.print(f"[yellow]warning:[/] {escape(str(issue))}", highlight=False)
    if len(issues) > limit:
        err_console.print(f"[yellow]... and {len(issues) - limit} more issues[/]")


def progress():
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                    console=err_console, transient=True)
