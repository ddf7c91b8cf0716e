"""MISB EG 0104 (the Predator-era "UAV Basic Universal Metadata Set"), read into ST 0601 tags.

EG 0104 items carry 16-byte SMPTE universal labels instead of ST 0601's one-byte tags; ST 0601
gives each of its tags the universal label of the same EG 0104 element, so every EG 0104 item
below lands on the ST 0601 tag with that label and the rest of eoloc reads it like ST 0601
(docs/formats.md "Real KLV" has the table). Labels are matched without their version byte (byte 8), as
SMPTE ST 336 says. Values: latitudes/longitudes are 8-byte IEEE doubles, angles, heights, ranges
and widths 4-byte IEEE floats, the user-defined time stamp 8 bytes of microseconds since 1970,
text in ASCII. Platform pitch and roll are full-range, so they go to the full-range tags 90/91.
EG 0104's heights are MSL (tags 15, 25), its sensor angles the ones ST 0601 calls relative
azimuth/elevation/roll (tags 18-20) — whether an encoder meant them relative to the platform or to
the earth is what the convention check of `eoloc klv` tells.
"""

from __future__ import annotations

import struct
from datetime import timedelta
from functools import partial
from typing import Any

from .localset import EPOCH, FieldError, Note, SetError, ber_length, decode_table, encode_length, misb_time

EG0104_KEY = bytes.fromhex("060E2B34020101010E01010201010000")
_PREFIX = bytes.fromhex("060E2B34")

# label without its first 8 bytes (06 0E 2B 34 01 01 01 vv) -> (ST 0601 tag, kind, name)
LABELS: dict[bytes, tuple[int, str, str]] = {
    bytes.fromhex(k): v for k, v in {
        "0702010101050000": (2, "time", "User Defined Time Stamp"),
        "0701100106000000": (5, "f32", "Platform Heading Angle"),
        "0701100105000000": (90, "f32", "Platform Pitch Angle"),
        "0701100104000000": (91, "f32", "Platform Roll Angle"),
        "0101200100000000": (10, "text", "Device Designation"),
        "0420010201010000": (11, "text", "Image Source Device"),
        "0701010100000000": (12, "text", "Image Coordinate System"),
        "0701020102040200": (13, "f64", "Device Latitude"),
        "0701020102060200": (14, "f64", "Device Longitude"),
        "0701020102020000": (15, "f32", "Device Altitude"),
        "0420020101080000": (16, "f32", "Field of View (Horizontal)"),
        "04200201010A0100": (17, "f32", "Field of View (Vertical)"),
        "0701100102000000": (18, "f32", "Angle to North"),
        "0701100103000000": (19, "f32", "Obliquity Angle"),
        "0701100101000000": (20, "f32", "Sensor Roll Angle"),
        "0701080101000000": (21, "f32", "Slant Range"),
        "0701090201000000": (22, "f32", "Target Width"),
        "0701020103020000": (23, "f64", "Frame Center Latitude"),
        "0701020103040000": (24, "f64", "Frame Center Longitude"),
        "0701020103160000": (25, "f32", "Frame Center Elevation"),
        "0105050000000000": (53, "text", "Episode Number"),
        **{f"07010201030{7 + k:X}0100": (82 + 2 * k, "f64", f"Corner Latitude Point {k + 1}") for k in range(4)},
        **{f"07010201030{0xB + k:X}0100": (83 + 2 * k, "f64", f"Corner Longitude Point {k + 1}") for k in range(4)},
    }.items()
}


#: The version byte (byte 8) of each element's label as the SMPTE registry gives it (RP 210; the
#: same as jMISB's and KWIVER's tables): written by :func:`encode_eg0104`, ignored when reading.
REGISTRY_VERSION: dict[bytes, int] = {
    bytes.fromhex(k): v for k, v in {
        "0702010101050000": 0x03, "0701100106000000": 0x07, "0701100105000000": 0x07, "0701100104000000": 0x07,
        "0101200100000000": 0x01, "0420010201010000": 0x01, "0701010100000000": 0x01, "0701020102040200": 0x03,
        "0701020102060200": 0x03, "0701020102020000": 0x01, "0420020101080000": 0x02, "04200201010A0100": 0x07,
        "0701100102000000": 0x01, "0701100103000000": 0x01, "0701100101000000": 0x01, "0701080101000000": 0x01,
        "0701090201000000": 0x01, "0701020103020000": 0x01, "0701020103040000": 0x01, "0701020103160000": 0x0A,
        "0105050000000000": 0x01,
        **{f"07010201030{7 + k:X}0100": 0x03 for k in range(4)},
        **{f"07010201030{0xB + k:X}0100": 0x03 for k in range(4)},
    }.items()
}


def _value(kind: str, raw: bytes) -> Any:
    if kind == "f64":
        if len(raw) != 8:
            raise FieldError(f"8 bytes expected, {len(raw)} sent")
        return struct.unpack(">d", raw)[0]
    if kind == "f32":
        if len(raw) != 4:
            raise FieldError(f"4 bytes expected, {len(raw)} sent")
        return struct.unpack(">f", raw)[0]
    if kind == "time":
        return misb_time(raw)
    return raw.decode("ascii", errors="replace").rstrip("\x00")


#: ST 0601 tag -> (EG 0104 element name, decoder) for :func:`.localset.decode_table`
TABLE = {tag: (name, partial(_value, kind)) for tag, kind, name in LABELS.values()}


def decode_eg0104(value: bytes) -> tuple[dict[int, Any], list[Note]]:
    """The items of one EG 0104 universal set (the bytes after its key and length) as ST 0601
    tag -> value, and notes (unknown labels are skipped silently, as ST 0601's unknown tags are)."""
    items: list[tuple[int, bytes]] = []
    notes: list[Note] = []
    pos, end = 0, len(value)
    while pos < end:
        label = value[pos:pos + 16]
        try:
            if len(label) < 16 or label[:4] != _PREFIX:
                raise SetError(f"no universal label at byte {pos} of the set")
            length, p, _ = ber_length(value, pos + 16, end)
            if p + length > end:
                raise SetError(f"item at byte {pos} declares {length} bytes but only {end - p} remain")
        except SetError as exc:
            notes.append(Note("truncated item", "EG 0104", f"{exc}; the rest of the set is not read"))
            break
        spec = LABELS.get(label[8:])
        if spec is not None:
            items.append((spec[0], value[p:p + length]))
        pos = p + length
    out, more = decode_table(items, TABLE, "EG 0104 ")
    if isinstance(out.get(19), float) and out[19] > 180.0:
        out[19] -= 360.0  # obliquity sent as 0-360: ST 0601's elevation is (-180, 180]
    return out, notes + more


def encode_eg0104(values: dict[str, Any]) -> bytes:
    """One EG 0104 packet from {element name: value} (names as in :data:`LABELS`; floats, text,
    datetime for the time stamp), each label with its registry version byte (:data:`REGISTRY_VERSION`)."""
    by_name = {name: (label, kind) for label, (_, kind, name) in LABELS.items()}
    body = bytearray()
    for name, v in values.items():
        label, kind = by_name[name]
        if kind == "f64":
            raw = struct.pack(">d", v)
        elif kind == "f32":
            raw = struct.pack(">f", v)
        elif kind == "time":
            raw = ((v - EPOCH) // timedelta(microseconds=1)).to_bytes(8, "big")
        else:
            raw = str(v).encode("ascii")
        head = bytes.fromhex("060E2B34010101") + bytes([REGISTRY_VERSION[label]])
        body += head + label + encode_length(len(raw)) + raw
    return EG0104_KEY + encode_length(len(body)) + bytes(body)
