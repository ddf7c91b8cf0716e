"""The options every command shares, declared once: the stop rule (one option per rule of
:data:`eoloc.rules.spec.SPECS`: --range [R], --target-height H, --dem and its datum options), the
config, the output folder and formats, pose matching, Dask,
--json; and the conventions text. A command module takes what it needs from here."""

from __future__ import annotations

import functools

import click

from ..rules.spec import FROM_RECORDS, SPECS, RuleSpec

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
  exit status  0 done; 2 a usage mistake or an input that cannot be used (one line says which);
               3 ran and wrote its outputs but located nothing (a warning says why); 1 a bug in eoloc
"""

MINUS = "\u2212"  # a negative --range value travels as U+2212 past click's "looks like an option" test


RECORDS_FLAGS = tuple(s.flag for s in SPECS if s.records)  # the optional-value options


def negative_values_kept(args: list[str], options: tuple[str, ...] = RECORDS_FLAGS) -> list[str]:
    """``--range -5`` / ``--range=-5``: click reads an optional-value option's "-5" as an option
    ("No such option '-5'"); the value is passed on with a Unicode minus so the option's own type
    refuses it by name."""
    out = list(args)
    for i, a in enumerate(out):
        for opt in options:
            if a.startswith(opt + "=-"):
                out[i] = opt + "=" + MINUS + a[len(opt) + 2:]
            elif a == opt and i + 1 < len(out) and _is_number(out[i + 1]):
                out[i + 1] = out[i + 1].replace("-", MINUS, 1)
    return out


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return text.startswith("-")


class RuleValue(click.ParamType):
    """A stop rule's number in metres, checked against the rule's domain (:class:`RuleSpec`), or
    (a rule with ``records``) no value: each target's own from the files."""

    name = "metres"

    def __init__(self, spec: RuleSpec) -> None:
        self.spec = spec

    def convert(self, value, param, ctx):
        if value == FROM_RECORDS or isinstance(value, float):
            return value
        s = self.spec
        try:
            x = float(str(value).replace(MINUS, "-"))
        except ValueError:
            alone = f" or nothing (then {s.records_help})" if s.records else ""
            self.fail(f"takes metres (e.g. {s.flag} 1200){alone}, got {value!r}", param, ctx)
        why = s.check(x)
        if why is not None:
            self.fail(why.replace(s.key, s.flag, 1), param, ctx)
        return x


def _apply(opts):
    def apply(fn):
        for o in reversed(opts):
            fn = o(fn)
        return fn

    return apply


def dem_options(dem_help: str):
    """--dem (repeatable), --vertical, --geoid and --dem-crs: the same DEM options on every command."""
    return _apply([
        click.option("--dem", "dem_paths", multiple=True, type=click.Path(dir_okay=False), help=dem_help),
        click.option("--vertical", type=click.Choice(["egm96", "egm2008", "ellipsoid"]), default="egm96",
                     show_default=True, help="Vertical datum of the DEM heights (converted to ellipsoidal)."),
        click.option("--geoid", type=click.Path(dir_okay=False), default=None,
                     help="Geoid grid for --vertical (default: the bundled EGM96 15')."),
        click.option("--dem-crs", default=None, help="CRS of a DEM that carries none (ESRI ASCII), e.g. EPSG:4326."),
    ])


def detect_options(fn):
    """--detect and its settings: the same options on `eoloc video` and `eoloc live`
    (:func:`detect_settings` turns them into the detector's and the tracker's settings)."""
    return _apply([
        click.option("--detect", default=None, metavar="motion|MODEL.onnx",
                     help="Find the targets in the frames: 'motion' = what moves on the ground, or the boxes of an "
                          "ONNX object detector (YOLO outputs) you give (see above)."),
        click.option("--detect-score", type=click.FloatRange(0.0, 1.0), default=0.35, show_default=True,
                     help="--detect MODEL.onnx: the least score of a box kept."),
        click.option("--detect-classes", default=None, metavar="NAME,NAME",
                     help="--detect MODEL.onnx: keep only these classes (the model's names)."),
        click.option("--detect-point", type=click.Choice(["bottom", "centre"]), default="bottom", show_default=True,
                     help="--detect MODEL.onnx: a box's point on the ground: its bottom centre (upright objects) or "
                          "centre (objects lying flat)."),
        click.option("--detect-window", type=click.FloatRange(0.0, min_open=True), default=2.0, show_default=True,
                     help="--detect: seconds before and after a frame to compare it with."),
        click.option("--detect-threshold", type=click.FloatRange(1.0, 255.0), default=40.0, show_default=True,
                     help="--detect: colour difference (0-255) that counts as a change."),
        click.option("--min-area", type=click.FloatRange(0.0, min_open=True), default=6.0, show_default=True,
                     help="--detect: smallest target, square metres on the ground."),
        click.option("--max-area", type=click.FloatRange(0.0, min_open=True), default=5000.0, show_default=True,
                     help="--detect: largest target, square metres on the ground."),
        click.option("--min-speed", type=click.FloatRange(0.0), default=None,
                     help="--detect: slowest target kept, m/s over the ground [default: 2 for motion, 0 for a model]."),
    ])(fn)


def detect_settings(detect: str | None, rule, *, detect_score: float, detect_classes: str | None, detect_point: str,
                    detect_window: float, detect_threshold: float, min_area: float, max_area: float,
                    min_speed: float | None):
    """(the motion detector's settings or the learned detector, the movers' settings) of
    :func:`detect_options`' values; (None, None) without --detect. ``rule``: the ground."""
    if min_area >= max_area:
        raise click.UsageError(f"--min-area {min_area:g} must be below --max-area {max_area:g}")
    if not detect:
        return None, None
    if detect != "motion" and not detect.lower().endswith(".onnx"):
        raise click.UsageError(f"--detect {detect!r}: 'motion', or an ONNX model file (MODEL.onnx)")
    from ..detect.movers import MoverSettings

    if detect == "motion":
        from ..detect.motion import MotionSettings

        finder = MotionSettings(window_s=detect_window, threshold=detect_threshold, min_area_m2=min_area,
                                max_area_m2=max_area)
    else:
        from ..detect.learned import LearnedDetector

        classes = {c.strip() for c in detect_classes.split(",") if c.strip()} if detect_classes else None
        finder = LearnedDetector(detect, rule, score=detect_score, classes=classes, point=detect_point)
    movers = MoverSettings(min_speed_mps=(2.0 if detect == "motion" else 0.0) if min_speed is None else min_speed)
    return finder, movers


def basemap_options(fn):
    """--basemap PATH, --world/--no-world and --tiles NAME: what lies under a map, the same on
    every command that draws one."""
    return _apply([
        click.option("--basemap", type=click.Path(exists=True), default=None,
                     help="Offline basemap under the map: an MBTiles file or a folder of {z}/{x}/{y}.png XYZ tiles "
                          "(raster; the tiles over the map's area are embedded in the page)."),
        click.option("--world/--no-world", default=True, show_default=True,
                     help="The bundled world layer (Natural Earth countries, public domain) at the bottom."),
        click.option("--tiles", default=None, help="Web map tiles too (e.g. OpenStreetMap; needs a network)."),
    ])(fn)


def rule_options(*, ground: bool = False, role: str = "Stop rule", records: bool = True,
                 dem_help: str = "DEM file(s) (GeoTIFF, DTED, SRTM .hgt/.zip, ESRI ASCII); repeat for tiles."):
    """One option per stop rule of :data:`eoloc.rules.spec.SPECS` (``ground``: only the rules that
    stop rays on a surface), read from the table: the command receives their values as one
    argument, ``rule_values`` (key -> value or None; :func:`eoloc.cli.common.stop_rule` makes the
    rule), and the DEM's files with their datum options as ``dem_paths, vertical, geoid, dem_crs``
    (the command may use the DEM for more than the rule). ``records``: a rule's flag may be given
    without a value (each target's value from the files). The old --height is refused by name."""
    opts, keys = [], []
    for s in SPECS:
        if ground and not s.ground:
            continue
        if s.value == "dem":
            opts.append(dem_options(f"{role} {s.method}: {dem_help}"))
            continue
        keys.append(s.key)
        text = f"{role} {s.method}: {s.help}."
        alone = {}
        if records and s.records:
            alone = {"is_flag": False, "flag_value": FROM_RECORDS}
            text += f" {s.flag} alone: {s.records_help}."
        metavar = f"[{s.metavar}]" if alone else s.metavar
        opts.append(click.option(s.flag, s.key, type=RuleValue(s), default=None, metavar=metavar, help=text, **alone))
    opts.append(click.option("--height", "old_height", type=float, default=None, hidden=True, expose_value=False,
                             callback=_refuse_height))

    def apply(fn):
        @functools.wraps(fn)
        def command(*args, **kwargs):
            return fn(*args, rule_values={k: kwargs.pop(k) for k in keys}, **kwargs)

        return _apply(opts)(command)

    return apply


def _refuse_height(ctx: click.Context, param: click.Parameter, value) -> None:
    if value is not None:
        raise click.UsageError("--height is no longer accepted: it meant two things. Give --target-height H for the "
                               "surface the rays stop on (ellipsoidal m), or --aircraft-height H for the aircraft of "
                               "one observation.", ctx)


stop_rule_options = rule_options()
"""--range [R] | --target-height H | --dem FILE...: one of them chooses the stop rule."""


def ortho_options(crs_note: str = "", gsd_default: str = "the native GSD at the centre"):
    """The orthorectification options of `rectify` and `video`, declared once: the ground
    (the rules that stop on a surface: --target-height H | --dem ...), --crs, --gsd, --resampling,
    --nodata, --occlusion."""
    return _apply([
        rule_options(ground=True, role="Ground"),
        click.option("--crs", default="utm", show_default=True,
                     help="Output grid: utm, gk6, gk3 (Gauss-Krüger zones on WGS-84), or EPSG:xxxx / a PROJ string"
                          f"{crs_note}."),
        click.option("--gsd", type=click.FloatRange(0.0, min_open=True), default=None,
                     help=f"Output cell size (m); default: {gsd_default}."),
        click.option("--resampling", type=click.Choice(["nearest", "bilinear", "cubic"]), default="bilinear",
                     show_default=True, help="How a cell's value is read from the frame."),
        click.option("--nodata", type=float, default=0, show_default=True, help="Value of cells with no image."),
        click.option("--occlusion/--no-occlusion", default=True, show_default=True,
                     help="On a DEM: blank cells hidden by terrain."),
    ])


def allow_host_option(fn):
    """--allow-host: a host name (as browsers send it in the Host header) a server also answers to."""
    return click.option("--allow-host", "allow_hosts", multiple=True, metavar="NAME",
                        help="Also answer requests for this host name (the server's own names and loopback's "
                             "always; '*': any, which lets a page on another site reach it by DNS "
                             "rebinding). Repeatable.")(fn)


def config_option(required: bool = True, help_text: str = "Camera/gimbal/installation TOML (see the README)."):
    return click.option("--config", "config_path", required=required, type=click.Path(dir_okay=False),
                        metavar="CONFIG.toml", help=help_text)


def refine_option(help_text: str):
    """--refine: refine the command's input from its own images first (eoloc refine, its defaults,
    into OUT/refine/), then run on what it wrote; ``help_text`` says what that is for the command."""
    return click.option("--refine", "refine_first", is_flag=True,
                        help="First refine " + help_text)


def poses_option(help_text: str = ""):
    """--poses FILE: drone photos' camera poses (eoloc refine's) in place of their own."""
    return click.option("--poses", "poses_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
                        help="Camera poses that replace the photos' own, by file name: eoloc refine's "
                             "photos_refined.csv (or its --json lines)." + (" " + help_text if help_text else ""))


def flight_log_option(f):
    """--flight-log LOG: the flight log that completes a video's telemetry (a DJI .SRT without
    attitude): synced by the tracks they share, it gives every record's pose."""
    return click.option("--flight-log", "flight_log", type=click.Path(dir_okay=False), default=None,
                        metavar="LOG.csv",
                        help="Flight log (Airdata CSV) of the same flight: synced to the telemetry by their tracks, "
                             "it gives each record's pose (a DJI .SRT carries no attitude on most models).")(f)


def with_flight_log(telemetry, flight_log):
    """The telemetry argument as the jobs take it: the path, or the path with its flight log."""
    if flight_log is None or telemetry is None:
        return telemetry
    from ..jobs.flightlog import WithFlightLog

    return WithFlightLog(str(telemetry), str(flight_log))


#: Where a command writes when --out is not given: one folder per command under this one, so
#: that `eoloc locate` and `eoloc klv` (both write fixes.csv) never overwrite each other.
OUT_ROOT = "eoloc-out"


def default_out(ctx: click.Context) -> str:
    """The default --out of the command ``ctx`` runs: eoloc-out/COMMAND (eoloc-out/compensate-train
    for a subcommand)."""
    return f"{OUT_ROOT}/" + "-".join(ctx.command_path.split()[1:] or [ctx.info_name or "eoloc"])


def _out_default(ctx: click.Context, param: click.Parameter, value):
    return default_out(ctx) if value is None else value


class OutOption(click.Option):
    """--out: its help shows the command's own default folder (eoloc-out/locate, ...)."""

    def get_help_record(self, ctx: click.Context):
        self.default = default_out(ctx)  # for the help only: the value still comes from the callback
        try:
            return super().get_help_record(ctx)
        finally:
            self.default = None


def out_option(what: str):
    """--out DIR, the same on every command: a folder (created if needed), by default eoloc-out/COMMAND."""
    return click.option("--out", "out_dir", cls=OutOption, type=click.Path(file_okay=False), default=None,
                        callback=_out_default, show_default=True, metavar="DIR",
                        help=f"Folder for {what} (created if needed).")


def formats_option(default=("csv", "geojson")):
    from ..io.writers import FORMATS

    return click.option("--format", "-f", "formats", type=click.Choice(FORMATS), multiple=True, default=default,
                        show_default=True,
                        help="Output format of every layer; repeat for several: csv, geojson (RFC 7946), kml "
                             "(heights as MSL for Google Earth), cot (a TAK data package, one event per located "
                             "point), geoparquet (GeoParquet 1.1, EPSG:4979), gpkg (GeoPackage).")


def grid_option():
    """--grid mgrs|utm (repeatable): grid-reference columns beside lat/lon in every point layer."""
    from ..io.gridref import GRIDS

    return click.option("--grid", "grid", type=click.Choice(GRIDS), multiple=True,
                        help="Add grid references to every point layer; repeat for both: mgrs (1 m MGRS string), "
                             "utm (utm_zone, utm_easting_m, utm_northing_m).")


def json_option(help_text: str = "Print the result as one JSON document on stdout (tables and notes go to "
                                 "stderr)."):
    return click.option("--json", "as_json", is_flag=True, help=help_text)


def pairing_options(fn):
    """How a detection finds its pose: the nearest record within --time-tolerance, or --interpolate."""
    return _apply([
        click.option("--time-tolerance", type=click.FloatRange(0.0), default=0.02, show_default=True,
                     help="Max |Δt| (s) pairing a detection with a telemetry record."),
        click.option("--interpolate", is_flag=True,
                     help="Interpolate the pose to each detection's time_s (position by a spline in ECEF, attitude "
                          "by slerp) instead of the nearest record."),
        click.option("--max-gap", type=click.FloatRange(0.0, min_open=True), default=0.5, show_default=True,
                     help="With --interpolate: longest telemetry gap (s) to interpolate across."),
        click.option("--time-offset", type=float, default=None,
                     help="With --interpolate: telemetry clock minus video clock (s); default: the config's "
                          "[telemetry] time_offset_s, else 0."),
    ])(fn)


DASK_HELP = ("Run on dask.distributed: a scheduler address (tcp://host:8786), or local[:N] for a local cluster of N "
             "worker processes. Same seed, same figures.")


def dask_option(fn):
    return click.option("--dask", "dask_address", default=None, metavar="ADDRESS", help=DASK_HELP)(fn)


def float_list(text: str) -> list[float]:
    """'10,25,50' or 'start:stop:step' (stop included) -> finite floats; a click error otherwise."""
    import numpy as np

    try:
        if ":" in text:
            a, b, c = (float(x) for x in text.split(":"))
            if c <= 0:
                raise ValueError
            values = [float(x) for x in np.arange(a, b + 0.5 * c, c)]
        else:
            values = [float(x) for x in text.split(",") if x.strip()]
        if not values or not all(np.isfinite(values)):
            raise ValueError
        return values
    except ValueError:
        raise click.BadParameter(f"give finite numbers like 10,25,50 or start:stop:step (step > 0, stop >= start), "
                                 f"got {text!r}") from None


def evaluation_options(fn):
    """The statistics options of `eoloc evaluate` and `eoloc report`: bootstrap, level, seed and the
    TLE model's Cook's-distance threshold."""
    return _apply([
        click.option("--bootstrap", "n_boot", type=click.IntRange(0, 1_000_000), default=2000, show_default=True,
                     metavar="N", help="Bootstrap resamples for the intervals (0: none)."),
        click.option("--level", type=click.FloatRange(0.5, 0.999), default=0.95, show_default=True,
                     help="Confidence level of the intervals."),
        click.option("--seed", type=int, default=0, show_default=True, help="Seed of the bootstrap."),
        click.option("--cooks-threshold", type=click.FloatRange(0.0, min_open=True), default=None, metavar="D",
                     help="Cook's distance above which a point is left out of the TLE model [default: 4/n]."),
    ])(fn)


def tak_options(fn):
    """How eoloc reaches a TAK server: --cot URL(s), and for TLS the client certificate (or a
    connection data package), and the TAK protocol version."""
    return _apply([
        click.option("--cot", "cot_urls", multiple=True, metavar="URL",
                     help="Send Cursor-on-Target to udp://HOST:PORT (multicast too, e.g. ATAK's udp://239.2.3.1:6969), "
                          "tcp://HOST:PORT (a TAK server's plain port, 8087) or tls://HOST:PORT (its TLS port, 8089: "
                          "needs --tak-cert or --tak-package); repeatable."),
        click.option("--tak-cert", "tak_cert", type=click.Path(dir_okay=False), default=None, metavar="CLIENT.p12",
                     help="eoloc's client certificate for tls:// (the .p12 the TAK server's admin made, or a PEM with "
                          "its key); its CA certificates check the server unless --tak-ca is given."),
        click.option("--tak-cert-password", "tak_cert_password", default=None, metavar="PASSWORD",
                     envvar="EOLOC_TAK_CERT_PASSWORD", show_envvar=True,
                     help="The .p12's password (default: none, then TAK Server's atakatak and FreeTAKServer's "
                          "supersecret are tried). The environment variable keeps it out of the process list."),
        click.option("--tak-ca", "tak_ca", type=click.Path(dir_okay=False), default=None, metavar="CA.pem",
                     help="The TAK server's CA (PEM, DER, or a truststore .p12 opened with --tak-cert-password): "
                          "the server is trusted when its certificate chains to it, as ATAK does (its host name is "
                          "not compared unless the URL ends ?check_hostname=1)."),
        click.option("--tak-package", "tak_package", type=click.Path(dir_okay=False), default=None,
                     metavar="CONNECTION.zip",
                     help="A TAK connection data package (the zip with a .pref and the certificates an admin hands "
                          "out for ATAK): its server is added to --cot, its certificates and passwords used."),
        click.option("--tak-protocol", "tak_protocol", type=click.Choice(["xml", "1"]), default="xml",
                     show_default=True,
                     help="TAK protocol: xml (version 0, what every TAK speaks) or 1 (protobuf: mesh datagrams on "
                          "udp://; on tcp:// and tls:// when the server offers it, else XML)."),
    ])(fn)


def tak_connection(cot_urls, tak_cert, tak_cert_password, tak_ca, tak_package):
    """(the --cot URLs, the TLS credentials or None) of the TAK options; the package's server is
    added to the URLs. Certificate problems raise InputError here, before anything starts."""
    from ..live.tls import credentials_from_files, read_connection_package

    urls, creds = list(cot_urls), None
    if tak_package is not None:
        if tak_cert is not None or tak_ca is not None:
            raise click.UsageError("--tak-package brings its own certificates: give it without --tak-cert/--tak-ca")
        package = read_connection_package(tak_package)
        creds = package.credentials
        if package.url not in urls:
            urls.append(package.url)
    elif tak_cert is not None:
        if not any(u.startswith("tls://") for u in urls):
            raise click.UsageError("--tak-cert is for a TLS connection: give --cot tls://HOST:PORT")
        creds = credentials_from_files(tak_cert, tak_cert_password, tak_ca)
    elif tak_ca is not None:
        raise click.UsageError("--tak-ca checks the server for eoloc's client certificate: give --tak-cert too")
    return urls, creds
