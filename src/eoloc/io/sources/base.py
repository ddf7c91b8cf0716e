"""What every telemetry source shares: the data it returns, the protocol it follows, and the
sniffing helpers (the registry is :mod:`eoloc.io.sources`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from ..table import Table

HEAD_BYTES = 65536  # what a sniffer sees of a file


@dataclass
class SourceData:
    """What a source read: the telemetry table, the source's name, the camera when the file says
    which one (drone photos), whether yaw/pitch/roll are the camera's own earth-referenced attitude
    (then the gimbal angles are zero and the config's gimbal is not used), and whole-file notes."""

    telemetry: Table
    source: str
    camera: object | None = None  # eoloc.sensor.Camera
    camera_attitude: bool = False
    notes: list[str] = field(default_factory=list)


class TelemetrySource(Protocol):
    """One kind of telemetry file."""

    name: str
    summary: str

    def sniff(self, path: Path, head: bytes) -> bool:
        """Whether this source reads the file, from its first :data:`HEAD_BYTES` bytes (a folder:
        ``head`` is empty and ``path`` is the folder)."""
        ...

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        """The file's telemetry; ``dem`` (optional) for heights given above the take-off point."""
        ...


def is_text(head: bytes) -> bool:
    """Whether a file's first bytes look like text (UTF-8 or Latin-1, no NUL)."""
    return bool(head) and b"\x00" not in head
