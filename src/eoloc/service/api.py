"""eoloc's HTTP JSON API (FastAPI on uvicorn; OpenAPI docs at /docs): ``POST /v1/locate`` and
``GET /v1/health``.

A request is one observation or a batch (``{"observations": [...]}``). An observation: the pose
(WGS-84 degrees, ellipsoidal metres, yaw/pitch/roll and the gimbal angles in degrees, SPEC §2),
the pixels to locate (default: the image centre), the stop rule (exactly one of ``range_m``,
``target_height_m`` or ``dem``: the name of a DEM given at start-up), and the camera: in the
request, or the config named at start-up. Every fix comes back with its status; a fix that
failed has no coordinates (null), never a plausible point. ``"covariance": true`` adds each fix's
first-order uncertainty from the start-up config's ``[accuracy.budget]``.

Bad requests are answered as JSON naming the field (``observations.0.pose.lat_deg``) with HTTP
422; bodies over the size limit with 413; too many pixels or observations with 422.

``POST /v1/photo`` takes a drone photo as it was taken (``image/jpeg`` or ``image/tiff``: its pose,
camera and laser range from its own EXIF/XMP, as ``eoloc photo`` reads them) and answers the rows
``eoloc photo --json`` prints: the image centre, or each ``pixel=U,V`` query parameter, on the DEM
``dem=NAME`` or at ``target_height_m``.

``POST /v1/locate/arrow`` takes the same observation with its pixels as columns: an Apache Arrow
IPC stream (``application/vnd.apache.arrow.stream``) of ``u_px`` and ``v_px`` whose schema
metadata ``eoloc`` holds the observation's JSON without ``pixels``, and answers an Arrow stream of
the fixes (``lat_deg``, ``lon_deg``, ``h_m``, ``range_m``: null where the fix failed; ``status``;
``u_px``, ``v_px``; the uncertainty columns with ``"covariance": true``). No text to parse or
write: what a batch of 10^5 targets needs to be served at the library's speed.
"""

from __future__ import annotations

import contextlib
import os
import re
import threading
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import Query  # these two at module level: FastAPI resolves the routes' annotations here
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.requests import Request

from ..errors import EolocError
from ..io.config import CameraConfig, stop_model
from ..kernels.backend import load_compiled
from .docs import add_offline_docs

MAX_BODY_BYTES = 8 * 1024 * 1024
MAX_PIXELS = 100_000  # per request, over all observations
MAX_OBSERVATIONS = 10_000
MAX_DECODED_BYTES = 64 * 1024 * 1024  # an Arrow request's buffers, decompressed (10^5 pixels: 1.6 MB)

Deg = Annotated[float, Field(allow_inf_nan=False)]


class _Strict(BaseModel):
    # strict, as the config files are: `"lat_deg": true`, `"42"` or `"1e4"` is not a number, and
    # nothing is coerced (requests are validated as JSON, where arrays are tuples and 42 is a float)
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class PoseIn(_Strict):
    lat_deg: float = Field(ge=-90, le=90, description="WGS-84 latitude of the INS reference point, degrees")
    lon_deg: float = Field(ge=-180, le=360, description="WGS-84 longitude, degrees")
    h_m: float = Field(ge=-12_000, le=1e7, description="ellipsoidal height, metres")
    yaw_deg: float = Field(0.0, ge=-360, le=360, description="heading, clockwise from true north")
    pitch_deg: float = Field(0.0, ge=-90, le=90, description="nose up positive")
    roll_deg: float = Field(0.0, ge=-180, le=180, description="right wing down positive")
    gimbal_deg: list[Deg] = Field(default_factory=list, max_length=3,
                                  description="the gimbal model's angles in its order (az-el: azimuth, elevation[, "
                                              "sensor roll]; roll-pitch: frame roll, frame pitch[, sensor roll])")


StopIn = stop_model("StopIn", _Strict, (str | None, Field(None, description="M4: the name of a DEM given to "
                                                                           "`eoloc serve --dem NAME=PATH`")))


class ObservationIn(_Strict):
    pose: PoseIn
    gimbal: Literal["az-el", "roll-pitch", "fixed"] | None = Field(
        None, description="the gimbal model (default: the start-up config's, else az-el)")
    pixels: list[tuple[Deg, Deg]] | None = Field(None, description="[[u, v], ...] (column, row; the centre of the "
                                                                  "top-left pixel is (0, 0)); default: the image "
                                                                  "centre")
    stop: StopIn
    camera: CameraConfig | None = Field(None, description="the camera (as the config's [camera]); default: the "
                                                          "start-up config's")
    covariance: bool = Field(False, description="add each fix's first-order uncertainty (start-up config's "
                                                "[accuracy.budget])")


class BatchIn(_Strict):
    observations: list[ObservationIn] = Field(max_length=MAX_OBSERVATIONS)


class FixOut(BaseModel):
    lat_deg: float | None
    lon_deg: float | None
    h_m: float | None
    range_m: float | None
    status: str
    u_px: float | None = None
    v_px: float | None = None
    uncertainty: dict[str, float | None] | None = None


class LocateOut(BaseModel):
    fixes: list[FixOut]


class BatchOut(BaseModel):
    results: list[LocateOut]


class RequestError(EolocError):
    """A request the API cannot serve, with the field it is about (HTTP ``status``)."""

    status = 422

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(message)
        self.field = field_name


class TooLargeError(RequestError):
    """A request that declares more than the server takes (rows, decompressed bytes): 413."""

    status = 413


@dataclass
class ServiceState:
    """What the server was started with: the config (camera, gimbal, installation, budget) and the
    DEMs by name."""

    config: Any = None
    dems: dict[str, Any] = field(default_factory=dict)
    started: float = 0.0
    served: int = 0

    def dem(self, name: str | None, where: str):
        """The DEM served as ``name`` (None for None); RequestError at ``where`` for an unknown name."""
        if name is None:
            return None
        if name not in self.dems:
            known = ", ".join(sorted(self.dems)) or "none (start the server with --dem NAME=PATH)"
            raise RequestError(where, f"no DEM named {name!r}; this server has: {known}")
        return self.dems[name]

    def rule(self, stop, where: str):
        """The stop rule of a request's ``stop`` object (:data:`StopIn`; a DEM by its served name)."""
        from ..rules.spec import rule_from_table

        return rule_from_table(stop, lambda name: self.dem(name, f"{where}.dem" if where else "dem"))

    def budget(self, wanted: bool, where: str):
        """The config's error budget when ``wanted`` (else None); RequestError at ``where`` when the
        server was started without one."""
        if not wanted:
            return None
        cfg = self.config
        if cfg is None or cfg.accuracy is None or not cfg.accuracy.budget:
            raise RequestError(where, "covariance needs the server started with a --config that has an "
                                      "[accuracy.budget]")
        from ..accuracy.budget import ErrorBudget

        return ErrorBudget.from_mapping(cfg.accuracy.budget)


def locate_observation(obs: ObservationIn, state: ServiceState, where: str) -> dict:
    """One observation through eoloc's chain, as the API's rows; RequestError naming the field for
    what cannot be served."""
    f, u, v, unc = solve_observation(obs, state, where)
    return {"fixes": fix_rows(f, u, v, unc)}


def solve_observation(obs: ObservationIn, state: ServiceState, where: str, pixels=None):
    """(fixes, u, v, uncertainty columns or None) of one observation; ``pixels``: (u, v) arrays that
    replace the observation's own (the Arrow route's columns)."""
    from ..jobs.tables import locate_by_rule
    from ..sensor import Camera, Pose, SensorModel, gimbal_from_name

    cfg = state.config
    if obs.camera is not None:
        sensor = SensorModel(obs.camera.build(), gimbal_from_name(obs.gimbal or (cfg.gimbal.model if cfg else "az-el")))
    elif cfg is not None:
        sensor = cfg.sensor()
        if obs.gimbal is not None and obs.gimbal != sensor.gimbal.name:
            raise RequestError(f"{where}.gimbal", f"gimbal {obs.gimbal!r} contradicts the server config's "
                                                    f"{sensor.gimbal.name!r}")
    elif obs.pixels is not None or pixels is not None:
        raise RequestError(f"{where}.camera", "pixels need a camera: give one in the request or start the "
                                                "server with --config")
    else:  # the image centre's ray is the boresight whatever the intrinsics
        sensor = SensorModel(Camera(1, 1, 1.0, 1.0, 0.0, 0.0), gimbal_from_name(obs.gimbal or "az-el"))
    names = sensor.gimbal.angle_names
    g = list(obs.pose.gimbal_deg)
    need = len(names)
    if sensor.gimbal.name != "fixed" and len(g) not in (need, need + 1):
        raise RequestError(f"{where}.pose.gimbal_deg", f"the {sensor.gimbal.name} gimbal needs {need} angles "
                                                         f"({', '.join(names)}[, sensor roll]), got {len(g)}")
    angles = tuple(g) if sensor.gimbal.name == "fixed" else (*g, *([0.0] if len(g) == need else []))
    p = obs.pose
    pose = Pose(p.lat_deg, p.lon_deg, p.h_m, p.yaw_deg, p.pitch_deg, p.roll_deg, angles)
    rule = state.rule(obs.stop, f"{where}.stop")
    budget = state.budget(obs.covariance, f"{where}.covariance")
    if pixels is not None:
        u, v = pixels
    elif obs.pixels is None:
        u = np.array([sensor.camera.cx])
        v = np.array([sensor.camera.cy])
    else:
        px = np.asarray(obs.pixels, dtype=np.float64).reshape(-1, 2)
        u, v = px[:, 0], px[:, 1]
    f, cov = locate_by_rule(sensor, pose, (u, v), rule, budget=budget)
    unc = None
    if cov is not None:
        from ..accuracy.covariance import covariance_columns

        unc = covariance_columns(cov, f.ok)
    return f, u, v, unc


def fix_rows(f, u: np.ndarray, v: np.ndarray, unc: dict | None) -> list[dict]:
    """The fixes as the API's rows (:class:`FixOut`), built column by column: a failed fix has no
    coordinates (null), never a plausible point."""
    from ..io.export import STATUS_NAMES, json_column

    ok = np.ravel(f.ok)
    cols = {"lat_deg": json_column(f.lat_deg, ok), "lon_deg": json_column(f.lon_deg, ok),
            "h_m": json_column(f.h_m, ok), "range_m": json_column(f.range_m, ok),
            "status": STATUS_NAMES[np.ravel(f.status).astype(np.intp)].tolist(),
            "u_px": json_column(u), "v_px": json_column(v)}
    rows = [dict(zip(cols, vals, strict=True)) for vals in zip(*cols.values(), strict=True)]
    if unc is not None:
        names, values = list(unc), [json_column(c) for c in unc.values()]
        for row, vals in zip(rows, zip(*values, strict=True), strict=True):
            row["uncertainty"] = dict(zip(names, vals, strict=True))
    return rows


ARROW_STREAM = "application/vnd.apache.arrow.stream"
ARROW_METADATA_KEY = b"eoloc"


def read_arrow_request(body: bytes) -> tuple[ObservationIn, np.ndarray, np.ndarray]:
    """The observation (schema metadata ``eoloc``) and the u_px, v_px columns of an Arrow IPC
    stream; RequestError naming what is wrong."""
    import orjson
    import pyarrow as pa
    from pydantic import ValidationError

    from .arrowcheck import MalformedMessageError, declared

    try:  # what the stream declares, before pyarrow allocates or decompresses any of it
        size = declared(body)
    except (ValueError, MalformedMessageError, OSError) as exc:
        raise RequestError("(body)", f"not an Arrow IPC stream ({ARROW_STREAM}): {exc}") from None
    if size.rows > MAX_PIXELS:
        raise TooLargeError("u_px", f"the stream declares {size.rows} rows; at most {MAX_PIXELS} pixels a request: "
                                    "split the batch")
    if size.bytes > MAX_DECODED_BYTES:
        raise TooLargeError("(body)", f"the stream's buffers hold {size.bytes} bytes once decompressed; at most "
                                      f"{MAX_DECODED_BYTES}")
    try:
        table = pa.ipc.open_stream(body).read_all()
    except (pa.ArrowInvalid, pa.ArrowTypeError, OSError) as exc:
        raise RequestError("(body)", f"not an Arrow IPC stream ({ARROW_STREAM}): {exc}") from None
    meta = (table.schema.metadata or {}).get(ARROW_METADATA_KEY)
    if meta is None:
        raise RequestError("(schema metadata)", "the stream's schema metadata has no 'eoloc' key: put the "
                                                "observation's JSON (pose, stop, camera, ...; no pixels) there")
    try:
        orjson.loads(meta)
        obs = ObservationIn.model_validate_json(meta)
    except orjson.JSONDecodeError as exc:
        raise RequestError("(schema metadata).eoloc", f"not JSON: {exc}") from None
    except ValidationError as exc:
        e = exc.errors()[0]
        raise RequestError(".".join(["eoloc", *(str(x) for x in e["loc"])]), e["msg"]) from None
    if obs.pixels is not None:
        raise RequestError("eoloc.pixels", "give the pixels as the u_px and v_px columns, not in the metadata")
    if table.num_rows > MAX_PIXELS:
        raise RequestError("u_px", f"{table.num_rows} pixels in one request; at most {MAX_PIXELS}: split the batch")
    cols = []
    for name in ("u_px", "v_px"):
        if name not in table.column_names:
            raise RequestError(name, f"no column {name!r}; the stream has {table.column_names}")
        col = table.column(name)
        if col.null_count or not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)):
            raise RequestError(name, f"{name} must be numbers with no nulls (float64), not {col.type}"
                               + (f" with {col.null_count} nulls" if col.null_count else ""))
        x = col.to_numpy().astype(np.float64, copy=False)
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise RequestError(name, f"{name} row {bad[0]} is {x[bad[0]]}: pixels must be finite")
        cols.append(x)
    return obs, cols[0], cols[1]


def arrow_fixes(f, u: np.ndarray, v: np.ndarray, unc: dict | None) -> bytes:
    """The fixes as an Arrow IPC stream: the columns eoloc's GeoParquet has (``fix_records`` as
    ``arrow_table`` makes them: coordinates null where the fix failed, never a plausible point),
    then u_px, v_px and the uncertainty columns."""
    import pyarrow as pa

    from .. import __version__
    from ..io.export import STATUS_NAMES, fix_records
    from ..io.geotable import arrow_table

    records = fix_records(f, after={"u_px": u, "v_px": v, **(unc or {})}, status_codes=True)
    table = arrow_table(records, labels={"status": STATUS_NAMES})
    table = table.replace_schema_metadata({"eoloc": __version__, "crs": "EPSG:4979 (WGS-84 lat, lon, ellipsoidal h)"})
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue().to_pybytes()


JSON_TYPES = ("application/json",)
_BATCH = re.compile(rb'\s*\{\s*"observations"\s*:')


def media_type(request) -> str:
    """The request's media type, lower case, without parameters ("" when none is given)."""
    return request.headers.get("content-type", "").split(";", 1)[0].strip().lower()


def read_json_request(body: bytes) -> ObservationIn | BatchIn:
    """One observation or a batch, validated strictly from the JSON text (no type coerced); a
    RequestError naming the first field that is wrong."""
    from pydantic import ValidationError

    # a batch is an object whose one key is "observations" (an observation has no such key): told
    # apart by its first key, so that the body is parsed once, by the model, strictly
    model = BatchIn if _BATCH.match(body) else ObservationIn
    try:
        return model.model_validate_json(body)
    except ValidationError as exc:
        raise ValidationProblemsError(exc.errors()) from None


class ValidationProblemsError(EolocError):
    """Every problem pydantic found in a request, each with its field."""

    def __init__(self, errors: list[dict]) -> None:
        super().__init__("invalid request")
        self.problems = [{"field": ".".join(str(x) for x in e["loc"]) or "(body)", "message": e["msg"]}
                         for e in errors]


COMPUTING = threading.BoundedSemaphore(max(2, os.cpu_count() or 2))  # requests worked out at once
BIG_BODY_BYTES = 256 * 1024  # a request this big leaves megabytes of garbage behind it


@contextlib.contextmanager
def computing(body_bytes: int):
    """A request being worked out: at most one per core at a time (the work holds the GIL for much
    of it; more at once would only hold more memory), and after a big one its garbage given back
    to the system (:func:`eoloc.service.http.give_back_memory_soon`, off the request's time)."""
    with COMPUTING:
        try:
            yield
        finally:
            if body_bytes >= BIG_BODY_BYTES:
                from .http import give_back_memory_soon

                give_back_memory_soon()


PHOTO_TYPES = ("image/jpeg", "image/tiff")


def locate_photo_request(data: bytes, state: ServiceState, *, pixels: list[str], target_height_m: float | None,
                         dem: str | None, covariance: bool, name: str) -> dict:
    """``POST /v1/photo``: the photo's pose and its rows (:func:`eoloc.jobs.photo.locate_photo`);
    RequestError naming the parameter for what cannot be served."""
    import math

    from ..io.photo import read_photo
    from ..jobs.photo import locate_photo

    if target_height_m is not None and dem is not None:
        raise RequestError("target_height_m", "give dem or target_height_m, not both")
    ground = None  # the photo's ground (a laser range, where it has one, stops the centre's ray first)
    if target_height_m is not None or dem is not None:
        try:
            ground = state.rule(StopIn(target_height_m=target_height_m, dem=dem), "")
        except ValidationError as exc:
            raise RequestError("target_height_m" if target_height_m is not None else "dem",
                               exc.errors()[0]["msg"].removeprefix("Value error, ")) from None
    uv = []
    for i, text in enumerate(pixels):
        try:
            u, v = (float(x) for x in text.split(","))
        except ValueError:
            raise RequestError(f"pixel.{i}", f"{text!r}: give a pixel as U,V (column,row)") from None
        if not (math.isfinite(u) and math.isfinite(v)):
            raise RequestError(f"pixel.{i}", f"{text!r} is not a pixel")
        uv.append((u, v))
    if len(uv) > MAX_PIXELS:
        raise RequestError("pixel", f"{len(uv)} pixels; at most {MAX_PIXELS}")
    budget = state.budget(covariance, "covariance")
    p = read_photo(name, data=data)  # a PhotoError (an EolocError: 422) names the tag and the fix
    rows = locate_photo(p, pixels=uv, ground=ground, budget=budget)
    return {"photo": {"name": name, "make": p.make, "model": p.model, "width": p.width, "height": p.height,
                      "thermal": p.thermal, "intrinsics": p.camera_source, "height_rule": p.height_rule,
                      "laser_range_m": p.lrf_range_m, "notes": list(p.notes)},
            "fixes": rows}


def _pixel_count(obs: list[ObservationIn]) -> int:
    return sum(1 if o.pixels is None else len(o.pixels) for o in obs)


def create_app(state: ServiceState | None = None, *, max_body_bytes: int = MAX_BODY_BYTES, hub=None,
               player_dir: str | None = None, hosts: list[str] | None = None):
    """The ASGI application (FastAPI), wrapped in the request-size limit and, with ``hosts``, the
    check that a request's Host header is one of them (:func:`eoloc.service.http.allowed_hosts`;
    400 otherwise). With ``hub`` (a
    :class:`eoloc.service.livemap.LiveHub`, as `eoloc live --map` gives) it also serves the live
    map: the page at ``/live`` (``/`` leads there) and its WebSocket. With ``player_dir`` (an
    `eoloc video` output folder) it serves that folder at ``/video/`` (``/`` leads to its
    player.html; byte ranges, so the video seeks)."""
    import asyncio
    import contextlib
    import time

    import orjson
    from fastapi import FastAPI
    from fastapi.exceptions import RequestValidationError
    from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
    from starlette.requests import ClientDisconnect

    from .. import __version__

    state = state or ServiceState()
    state.started = time.time()

    @contextlib.asynccontextmanager
    async def lifespan(app):
        load_compiled()  # a service runs for long: numba loaded at start, not in a request's time
        beat = None
        if hub is not None:
            hub.loop = asyncio.get_running_loop()
            beat = asyncio.create_task(hub.heartbeat())
        yield
        if beat is not None:
            beat.cancel()

    app = FastAPI(title="eoloc", version=__version__, lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Geolocation of targets seen by airborne EO/IR sensors: pose + gimbal + camera + pixel "
                              "+ a stop rule -> WGS-84 points with a status each (see the README's conventions).")

    add_offline_docs(app)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        problems = [{"field": ".".join(str(x) for x in e["loc"] if x != "body") or "(body)", "message": e["msg"]}
                    for e in exc.errors()]
        return JSONResponse(status_code=422, content={"error": "invalid request", "problems": problems})

    @app.exception_handler(RequestError)
    async def _problem(request: Request, exc: RequestError):
        return JSONResponse(status_code=exc.status, content={"error": "invalid request",
                                                      "problems": [{"field": exc.field, "message": str(exc)}]})

    @app.exception_handler(ClientDisconnect)
    async def _gone(request: Request, exc: ClientDisconnect):  # nobody to answer: no traceback in the log
        return Response(status_code=499)

    @app.exception_handler(EolocError)
    async def _eoloc(request: Request, exc: EolocError):
        return JSONResponse(status_code=422, content={"error": "invalid request",
                                                      "problems": [{"field": "(body)", "message": str(exc)}]})

    @app.get("/v1/health")
    def health() -> dict:
        """Alive, with what the server was started with."""
        return {"status": "ok", "eoloc": __version__, "uptime_s": round(time.time() - state.started, 3),
                "requests": state.served, "config": state.config is not None, "dems": sorted(state.dems)}

    @app.exception_handler(ValidationProblemsError)
    async def _problems(request: Request, exc: ValidationProblemsError):
        return JSONResponse(status_code=422, content={"error": "invalid request", "problems": exc.problems})

    body_schema = {"anyOf": [{"$ref": "#/components/schemas/ObservationIn"}, {"$ref": "#/components/schemas/BatchIn"}]}

    @app.post("/v1/locate", response_model=LocateOut | BatchOut, openapi_extra={
        "requestBody": {"required": True, "content": {"application/json": {"schema": body_schema}}}})
    async def locate(request: Request):
        """Locate one observation (its pixels, or the image centre) or a batch of them."""
        from starlette.concurrency import run_in_threadpool

        if media_type(request) not in JSON_TYPES:
            return _unsupported(request, "application/json")
        body = await request.body()
        return await run_in_threadpool(locate_json, body)  # parsed there too: the event loop stays free

    def locate_json(raw: bytes) -> Response:
        with computing(len(raw)):
            return _locate_json(raw)

    def _locate_json(raw: bytes) -> Response:
        body = read_json_request(raw)
        observations = body.observations if isinstance(body, BatchIn) else [body]
        n = _pixel_count(observations)
        if n > MAX_PIXELS:
            raise RequestError("pixels", f"{n} pixels in one request; at most {MAX_PIXELS}: split the batch")
        state.served += 1
        if isinstance(body, BatchIn):
            out = {"results": [locate_observation(o, state, f"observations.{i}") for i, o in enumerate(observations)]}
        else:
            out = locate_observation(body, state, "")
        # the rows are built to the response model's shape; orjson writes them (pydantic objects per fix
        # and the stdlib encoder cost 50x the geolocation on a batch of 10^5)
        return Response(orjson.dumps(out), media_type="application/json")

    @app.post("/v1/locate/arrow", response_class=Response, openapi_extra={
        "requestBody": {"required": True, "content": {ARROW_STREAM: {"schema": {"type": "string", "format": "binary"}}},
                        "description": "An Arrow IPC stream: columns u_px, v_px (float64); schema metadata 'eoloc': "
                                       "the observation's JSON (as POST /v1/locate takes it) without pixels."},
        "responses": {"200": {"content": {ARROW_STREAM: {}}, "description": "The fixes as an Arrow IPC stream."}}})
    async def locate_arrow(request: Request):
        """Locate one observation's pixels given as Arrow columns; the fixes come back as Arrow."""
        from starlette.concurrency import run_in_threadpool

        if media_type(request) != ARROW_STREAM:  # (a cross-site form post cannot send this type)
            return _unsupported(request, ARROW_STREAM)

        def serve(body: bytes) -> bytes:  # in the thread pool, as the JSON route: the event loop stays free
            with computing(len(body)):
                obs, u, v = read_arrow_request(body)
                state.served += 1
                return arrow_fixes(*solve_observation(obs, state, "eoloc", pixels=(u, v)))

        return Response(await run_in_threadpool(serve, await request.body()), media_type=ARROW_STREAM)

    @app.post("/v1/photo", openapi_extra={
        "requestBody": {"required": True, "content": {t: {"schema": {"type": "string", "format": "binary"}}
                                                      for t in PHOTO_TYPES},
                        "description": "A drone photo as it was taken (JPEG or TIFF with its EXIF and XMP)."}})
    async def photo(request: Request, pixel: Annotated[list[str] | None, Query()] = None,
                    target_height_m: float | None = None,
                    dem: str | None = None, covariance: bool = False, name: str = "photo"):
        """Locate in a drone photo, its pose read from its own EXIF/XMP (as `eoloc photo` does): the
        image centre (by its laser range when it has one), or each ``pixel=U,V`` given, on the DEM
        named ``dem`` or at ``target_height_m``. The rows are `eoloc photo --json`'s; ``covariance``
        adds each fix's uncertainty from the server config's [accuracy.budget]."""
        from starlette.concurrency import run_in_threadpool

        if media_type(request) not in PHOTO_TYPES:
            return _unsupported(request, " or ".join(PHOTO_TYPES))
        body = await request.body()

        def serve() -> Response:
            with computing(len(body)):
                out = locate_photo_request(body, state, pixels=pixel or [], target_height_m=target_height_m,
                                           dem=dem, covariance=covariance, name=name)
                state.served += 1
                return Response(orjson.dumps(out, option=orjson.OPT_SERIALIZE_NUMPY), media_type="application/json")

        return await run_in_threadpool(serve)

    def _unsupported(request: Request, wanted: str) -> JSONResponse:
        got = request.headers.get("content-type") or "none"
        return JSONResponse(status_code=415, content={"error": f"content-type {got!r}: send {wanted}"})

    def openapi() -> dict:  # the request models, which the routes validate themselves, in the schema
        from fastapi.openapi.utils import get_openapi
        from pydantic import TypeAdapter

        if app.openapi_schema is None:
            spec = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
            models = TypeAdapter(ObservationIn | BatchIn).json_schema(ref_template="#/components/schemas/{model}")
            spec.setdefault("components", {}).setdefault("schemas", {}).update(models.get("$defs", {}))
            app.openapi_schema = spec
        return app.openapi_schema

    app.openapi = openapi

    if player_dir is not None:
        from fastapi.staticfiles import StaticFiles

        app.mount("/video", StaticFiles(directory=str(player_dir)), name="video")
        if hub is None:
            @app.get("/", include_in_schema=False)
            def player_root():
                return RedirectResponse("/video/player.html")

    if hub is not None:
        from .livemap import WS_PATH

        page = hub.page()

        @app.get("/live", response_class=HTMLResponse)
        def live_page():
            """The live map (Leaflet, offline), updated over the WebSocket."""
            return HTMLResponse(page)

        @app.get("/", include_in_schema=False)
        def root():
            return RedirectResponse("/live")

        @app.get("/v1/live/status")
        def live_status() -> dict:
            """The live session's state (waiting, live, silent, stopped), counters and browsers."""
            return hub.status() | {"map": hub.summary()}

        from starlette.routing import WebSocketRoute

        app.router.routes.append(WebSocketRoute(WS_PATH, hub.serve))

    limited = SizeLimit(app, max_body_bytes)
    if hosts is None:
        return limited
    from starlette.middleware.trustedhost import TrustedHostMiddleware

    return TrustedHostMiddleware(limited, allowed_hosts=hosts, www_redirect=False)


class SizeLimit:
    """ASGI wrapper: a request body longer than ``limit`` bytes (by its Content-Length, or as it
    streams in, chunked) is answered 413 with a JSON message; nothing past the limit is read, the
    application then sees the client gone, and whatever it answers after is dropped."""

    def __init__(self, app, limit: int) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope.get("headers") or {}).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.limit:
            await self._too_large(send, int(length))
            return
        seen = 0
        refused = False

        async def limited():
            nonlocal seen, refused
            if refused:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    refused = True
                    await self._too_large(send, seen)
                    return {"type": "http.disconnect"}
            return message

        async def answer(message) -> None:
            if not refused:
                await send(message)

        await self.app(scope, limited, answer)

    async def _too_large(self, send, n: int) -> None:
        import json

        body = json.dumps({"error": f"request body of {n} bytes (or more) is over this server's limit of {self.limit} "
                                    "bytes: split the batch"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})
