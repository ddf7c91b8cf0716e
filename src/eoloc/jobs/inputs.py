"""Reading a job's tables: telemetry (the config's heading bias removed) and the second file."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import InputError
from ..io.table import Issue, Table
from ..io.telemetry import read_detections, read_telemetry, with_heading_bias


@dataclass
class Inputs:
    """The telemetry, the second table (detections, GCPs) or None, and every issue met reading them."""

    telemetry: Table
    other: Table | None
    issues: list[Issue] = field(default_factory=list)


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
                msl_geoid: str | None = None) -> Inputs:
    """Both tables; an InputError (with the issues that explain it) when either has no usable record.
    ``other``: the second file's path, or a :class:`Prefetch` of it; ``msl_geoid``: the geoid
    grid for telemetry heights given as h_msl_m (default EGM96)."""
    geoid = None
    if msl_geoid is not None:
        from ..terrain.geoid import Geoid

        geoid = Geoid(msl_geoid)
    tel = with_heading_bias(read_telemetry(telemetry, geoid=geoid), heading_bias_deg)
    det = other.result() if isinstance(other, Prefetch) else reader(other) if other else None
    issues = list(tel.issues) + (list(det.issues) if det is not None else [])
    if len(tel) == 0:
        raise InputError(f"telemetry file {str(telemetry)!r} has no usable record", issues)
    if det is not None and len(det) == 0:
        raise InputError(f"file {det.path!r} has no usable record (only a header?): nothing to locate", issues)
    return Inputs(tel, det, issues)
