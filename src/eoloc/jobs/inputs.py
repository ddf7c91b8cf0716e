"""Reading a job's tables: telemetry (the config's heading bias removed) and the second file."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import InputError
from ..io.table import Issue, Table
from ..io.telemetry import read_detections, with_heading_bias


@dataclass
class Inputs:
    """The telemetry, the second table (detections, GCPs) or None, every issue met reading them,
    and what the telemetry's source knows beside the poses (:class:`eoloc.io.sources.SourceData`)."""

    telemetry: Table
    other: Table | None
    issues: list[Issue] = field(default_factory=list)
    source: Any = None  # SourceData

    def sensor(self, cfg=None):
        """The sensor to locate with: the config's (``cfg``; None: the camera the telemetry
        carries), with an az-el gimbal at zero when the telemetry gives the camera's own attitude
        (drones) rather than the aircraft's and the gimbal's."""
        from dataclasses import replace

        from ..sensor import AzElGimbal, SensorModel

        src = self.source
        if cfg is not None:
            sensor = cfg.sensor()
        elif src is not None and src.camera is not None:
            sensor = SensorModel(src.camera)
        else:
            raise InputError(f"{self.telemetry.path} does not say which camera took it: give --config CAMERA.toml")
        if src is not None and src.camera_attitude and not isinstance(sensor.gimbal, AzElGimbal):
            sensor = replace(sensor, gimbal=AzElGimbal())
        return sensor


class Prefetch:
    """A file being read on a thread of its own while the caller does other work (loading the
    configuration: Python, which holds the GIL, where reading the file and pyarrow's parse
    release it). :func:`read_inputs` takes it in place of the second file's path and waits for
    it after the telemetry, so errors come in the same order as when read in turn; a caller
    that fails before then leaves the thread to finish and its error unseen."""

    def __init__(self, reader: Callable[[Any], Table], path) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.path = path
        pool = ThreadPoolExecutor(1, thread_name_prefix="eoloc-read")
        self._future = pool.submit(reader, path)
        pool.shutdown(wait=False)  # the thread ends with its one task

    def result(self) -> Table:
        """The table (waits for it), or what reading it raised."""
        return self._future.result()


def read_inputs(telemetry, other=None, *, heading_bias_deg: float = 0.0, reader=read_detections,
                msl_geoid: str | None = None, dem=None) -> Inputs:
    """Both tables; an InputError (with the issues that explain it) when either has no usable record.
    ``telemetry``: any file or folder a telemetry source reads (:mod:`eoloc.io.sources`), or a
    :class:`~eoloc.jobs.flightlog.WithFlightLog` (a video's telemetry and its flight log);
    ``other``: the second file's path, or a :class:`Prefetch` of it; ``msl_geoid``: the geoid
    grid for telemetry heights given above mean sea level (default EGM96); ``dem``: for drone
    heights given above the take-off point, and their plausibility check."""
    from ..io.sources import read_source

    geoid = None
    if msl_geoid is not None:
        from ..terrain.geoid import Geoid

        geoid = Geoid(msl_geoid)
    from .flightlog import WithFlightLog, with_flight_log

    if isinstance(telemetry, WithFlightLog):
        src = with_flight_log(read_source(telemetry.path, geoid=geoid, dem=dem),
                              read_source(telemetry.log, geoid=geoid, dem=dem))
    else:
        src = read_source(telemetry, geoid=geoid, dem=dem)
    tel = with_heading_bias(src.telemetry, heading_bias_deg)
    det = other.result() if isinstance(other, Prefetch) else reader(other) if other else None
    notes = [Issue(tel.path, int(tel.line[0]) if len(tel) else 0, note) for note in src.notes]
    issues = notes + list(tel.issues) + (list(det.issues) if det is not None else [])
    if len(tel) == 0:
        raise InputError(f"telemetry file {str(telemetry)!r} has no usable record", issues)
    if det is not None and len(det) == 0:
        raise InputError(f"file {det.path!r} has no usable record (only a header?): nothing to locate", issues)
    return Inputs(tel, det, issues, src)


def job_inputs(cfg, telemetry, other=None, *, reader=read_detections, dem=None, heading_bias: bool = True) -> Inputs:
    """:func:`read_inputs` with the config's [telemetry] settings (``cfg`` None: a source that
    carries its camera, read as it is); ``dem``: the stop rule's terrain (a DEM: drone photos
    read the take-off's ground height from it), or None."""
    tel_cfg = cfg.telemetry if cfg is not None else None
    return read_inputs(telemetry, other, reader=reader,
                       heading_bias_deg=tel_cfg.heading_bias_deg if tel_cfg is not None and heading_bias else 0.0,
                       msl_geoid=tel_cfg.msl_geoid if tel_cfg is not None else None,
                       dem=dem)
