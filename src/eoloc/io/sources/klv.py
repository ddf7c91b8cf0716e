"""MISB ST 0601 KLV, raw or in MPEG-TS (:mod:`eoloc.io.klv`): each packet a record, ``frame`` its
packet number, ``time_s`` its UNIX time (tag 2), gimbal angles the sensor's relative azimuth and
elevation (an az-el gimbal), the zoom from the horizontal field of view (tag 16)."""

from __future__ import annotations

from pathlib import Path

from .base import SourceData

UL_PREFIX = b"\x06\x0e\x2b\x34"  # every SMPTE universal label starts so


def looks_like_klv(head: bytes) -> bool:
    """An MPEG-TS (a sync byte every 188 bytes) or bytes that hold a SMPTE key (or the ST 0601
    key's last 11 bytes: packets whose key lost its head, which the reader puts back)."""
    from ..klv.reader import KEY_TAIL, looks_like_ts

    return looks_like_ts(head) or UL_PREFIX in head or KEY_TAIL in head


class KlvStream:
    name = "klv"
    summary = "MISB ST 0601 KLV (raw, or in an MPEG-TS)"

    def sniff(self, path: Path, head: bytes) -> bool:
        return looks_like_klv(head)

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        from ..klv import klv_telemetry, read_klv

        return SourceData(klv_telemetry(read_klv(path), geoid=geoid), self.name)
