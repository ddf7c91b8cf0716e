"""The telemetry-source seam: every file (or folder) that can give poses, told apart by its content.

A *source* turns one input into the same thing: a telemetry :class:`~eoloc.io.table.Table` (one row
per image or record; the columns of :mod:`eoloc.io.telemetry`: time_s and/or frame, lat_deg,
lon_deg, h_m ellipsoidal, yaw/pitch/roll_deg, gimbal1/2_deg, sensor_roll_deg, range_m, optional
zoom), plus what the file itself knows: the camera, and whether its angles are the *camera's* own
attitude (drones: the gimbal's earth-referenced yaw/pitch/roll) rather than the aircraft's attitude
and gimbal angles relative to it. Commands never ask which kind of file they were given.

The registry is :data:`SOURCES`, in the order they are asked: the first whose ``sniff`` accepts the
file's first bytes reads it (the file's name and extension are not looked at). A new source is one
module with a class that has ``name``, ``summary``, ``sniff`` and ``read`` (see
:class:`TelemetrySource`), and one line in :data:`SOURCES`::

    class MyLog:
        name = "mylog"
        summary = "MyCompany flight log (CSV with a '#MYLOG' first line)"

        def sniff(self, path, head: bytes) -> bool:
            return head.startswith(b"#MYLOG")

        def read(self, path, *, geoid=None, dem=None) -> SourceData:
            table = ...  # a Table with the telemetry columns
            return SourceData(table, self.name)

    # in eoloc/io/sources/__init__.py, _registry(): before EolocCsv(), which takes any text
    return [KlvStream(), DronePhotos(), DjiSrt(), Airdata(), MyLog(), EolocCsv()]
"""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError
from .base import HEAD_BYTES, SourceData, TelemetrySource, is_text

__all__ = ["HEAD_BYTES", "SOURCES", "SourceData", "TelemetrySource", "identify", "is_text", "read_source"]

def _registry() -> list[TelemetrySource]:
    from .airdata import Airdata
    from .dji_srt import DjiSrt
    from .eoloc_csv import EolocCsv
    from .klv import KlvStream
    from .photos import DronePhotos

    return [KlvStream(), DronePhotos(), DjiSrt(), Airdata(), EolocCsv()]


#: Every telemetry source, in the order they are asked (the eoloc CSV last: it takes any text).
SOURCES: list[TelemetrySource] = _registry()


def identify(path: str | Path) -> TelemetrySource:
    """The source that reads ``path`` (by content); an InputError naming the file when none does."""
    path = Path(path)
    if path.is_dir():
        head = b""
    else:
        try:
            with open(path, "rb") as f:
                head = f.read(HEAD_BYTES)
        except FileNotFoundError:
            raise InputError(f"telemetry file {str(path)!r} does not exist (check the path)") from None
        except OSError as exc:
            raise InputError(f"telemetry file {str(path)!r} cannot be read: {exc.strerror or exc}") from None
        if not head:
            raise InputError(f"telemetry file {str(path)!r} is empty (0 bytes): nothing to read; was it copied "
                             "before the recording ended?")
    for source in SOURCES:
        if source.sniff(path, head):
            return source
    if path.is_dir():
        raise InputError(f"{str(path)!r} is a folder with no drone photo in it: give a telemetry file, or a folder "
                         "of photos")
    kinds = "; ".join(s.summary for s in SOURCES)
    raise InputError(f"{str(path)!r} is no telemetry eoloc knows (it reads: {kinds})")


def read_source(path: str | Path, *, geoid=None, dem=None) -> SourceData:
    """Read any telemetry file or folder through the source that recognises it."""
    return identify(path).read(Path(path), geoid=geoid, dem=dem)
