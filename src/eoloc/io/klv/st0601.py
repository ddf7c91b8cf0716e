"""MISB ST 0601 (UAS Datalink Local Set) values, decoded item by item.

The table below holds the ST 0601.19 items eoloc uses (time, platform and sensor pose, fields of
view, frame centre and corners, target location, flags, heights) with the standard's mappings;
``tests/unit/io/klv/test_klv_tolerant.py`` checks every entry against stanag4609's definition of the same tag
and every decoded value against stanag4609's decoder. Items eoloc does not use are kept as their
raw bytes. An item that cannot be decoded (wrong length, reserved value, bad text) is left out
with a note; the rest of the packet is used. ST 0903 VMTI (tag 74) is decoded by
:mod:`.st0903`; ST 1607 segment and amend sets (tags 100, 101) are decoded here, as far as they
are valid, into :class:`Nested` values.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from .localset import FieldError, Note, Text, UInt, decode_table, misb_time, parse_items
from .st0903 import decode_vmti

MULTIPLE = frozenset({100, 101})  # ST 1607 segment and amend sets may repeat


class Special(enum.Enum):
    """ST 0601 special values of mapped items (read as NaN by the telemetry columns)."""

    OUT_OF_RANGE = "out of range"
    OFF_EARTH = "off earth"
    RESERVED = "reserved"
    UNKNOWN = "unknown"  # a zero-length item: the value is no longer known


@dataclass(frozen=True)
class Mapped:
    """A fixed-length integer mapped linearly onto [lo, hi] (ST 0601 §6.5), with an optional special raw value."""

    length: int
    lo: Fraction
    hi: Fraction
    signed: bool = False
    special: Special | None = None

    def domain(self) -> tuple[int, int, int | None]:
        bits = 8 * self.length
        if not self.signed:
            return 0, (1 << bits) - 1, None
        low, high = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        return (low + 1, high, low) if self.special is not None else (low, high, None)

    def decoder(self):
        rmin, rmax, special_raw = self.domain()
        span = self.hi - self.lo
        # value = lo + (r - rmin) span / (rmax - rmin), as one correctly rounded int / int division
        den = self.lo.denominator * span.denominator * (rmax - rmin)
        a = self.lo.numerator * span.denominator * (rmax - rmin)
        b = span.numerator * self.lo.denominator
        length, signed, special = self.length, self.signed, self.special

        def decode(raw: bytes):
            if len(raw) != length:
                raise FieldError(f"{length} byte(s) expected, {len(raw)} sent")
            r = int.from_bytes(raw, "big", signed=signed)
            if r == special_raw:
                return special
            return (a + (r - rmin) * b) / den
        return decode


_text = Text(strict=True)
F = Fraction
_LAT = Mapped(4, F(-90), F(90), True, Special.RESERVED)
_LON = Mapped(4, F(-180), F(180), True, Special.RESERVED)
_LAT_FC = Mapped(4, F(-90), F(90), True, Special.OFF_EARTH)
_LON_FC = Mapped(4, F(-180), F(180), True, Special.OFF_EARTH)
_ALT = Mapped(2, F(-900), F(19000))
_OFFSET = Mapped(2, F(-3, 40), F(3, 40), True, Special.OFF_EARTH)
_FULL_ANGLE = Mapped(4, F(-90), F(90), True, Special.OUT_OF_RANGE)

#: tag -> (name, mapping or decoder): the ST 0601.19 items eoloc reads
FIELDS: dict[int, tuple[str, Any]] = {
    2: ("Precision Time Stamp", misb_time),
    3: ("Mission ID", _text), 4: ("Platform Tail Number", _text),
    5: ("Platform Heading Angle", Mapped(2, F(0), F(360))),
    6: ("Platform Pitch Angle", Mapped(2, F(-20), F(20), True, Special.OUT_OF_RANGE)),
    7: ("Platform Roll Angle", Mapped(2, F(-50), F(50), True, Special.OUT_OF_RANGE)),
    10: ("Platform Designation", _text), 11: ("Image Source Sensor", _text), 12: ("Image Coordinate System", _text),
    13: ("Sensor Latitude", _LAT), 14: ("Sensor Longitude", _LON), 15: ("Sensor True Altitude", _ALT),
    16: ("Sensor Horizontal Field of View", Mapped(2, F(0), F(180))),
    17: ("Sensor Vertical Field of View", Mapped(2, F(0), F(180))),
    18: ("Sensor Relative Azimuth Angle", Mapped(4, F(0), F(360))),
    19: ("Sensor Relative Elevation Angle", Mapped(4, F(-180), F(180), True, Special.RESERVED)),
    20: ("Sensor Relative Roll Angle", Mapped(4, F(0), F(360))),
    21: ("Slant Range", Mapped(4, F(0), F(5_000_000))),
    22: ("Target Width", Mapped(2, F(0), F(10_000))),
    23: ("Frame Center Latitude", _LAT_FC), 24: ("Frame Center Longitude", _LON_FC),
    25: ("Frame Center Elevation", _ALT),
    **{t: (f"Offset Corner {'Latitude' if t % 2 == 0 else 'Longitude'} Point {(t - 24) // 2}", _OFFSET)
       for t in range(26, 34)},
    40: ("Target Location Latitude", _LAT_FC), 41: ("Target Location Longitude", _LON_FC),
    42: ("Target Location Elevation", _ALT),
    45: ("Target Error Estimate - CE90", Mapped(2, F(0), F(4095))),
    46: ("Target Error Estimate - LE90", Mapped(2, F(0), F(4095))),
    47: ("Generic Flag Data", UInt(0, 63)),
    65: ("UAS Datalink LS Version Number", UInt()),
    75: ("Sensor Ellipsoid Height", _ALT), 78: ("Frame Center Height Above Ellipsoid", _ALT),
    **{t: (f"Corner {'Latitude' if t % 2 == 0 else 'Longitude'} Point {(t - 80) // 2} (Full)",
           _LAT_FC if t % 2 == 0 else _LON_FC) for t in range(82, 90)},
    90: ("Platform Pitch Angle (Full)", _FULL_ANGLE), 91: ("Platform Roll Angle (Full)", _FULL_ANGLE),
}


class Tag(enum.IntEnum):
    """The ST 0601 items eoloc reads or writes, by the standard's names (ST 0601.19 Table 1;
    every name is the :data:`FIELDS` name of its tag, tested). Use these, not raw numbers."""

    PRECISION_TIME_STAMP = 2
    MISSION_ID = 3
    PLATFORM_TAIL_NUMBER = 4
    PLATFORM_HEADING_ANGLE = 5
    PLATFORM_PITCH_ANGLE = 6
    PLATFORM_ROLL_ANGLE = 7
    PLATFORM_DESIGNATION = 10
    IMAGE_SOURCE_SENSOR = 11
    IMAGE_COORDINATE_SYSTEM = 12
    SENSOR_LATITUDE = 13
    SENSOR_LONGITUDE = 14
    SENSOR_TRUE_ALTITUDE = 15
    SENSOR_HORIZONTAL_FIELD_OF_VIEW = 16
    SENSOR_VERTICAL_FIELD_OF_VIEW = 17
    SENSOR_RELATIVE_AZIMUTH_ANGLE = 18
    SENSOR_RELATIVE_ELEVATION_ANGLE = 19
    SENSOR_RELATIVE_ROLL_ANGLE = 20
    SLANT_RANGE = 21
    TARGET_WIDTH = 22
    FRAME_CENTER_LATITUDE = 23
    FRAME_CENTER_LONGITUDE = 24
    FRAME_CENTER_ELEVATION = 25
    OFFSET_CORNER_LATITUDE_POINT_1 = 26
    OFFSET_CORNER_LONGITUDE_POINT_1 = 27
    OFFSET_CORNER_LATITUDE_POINT_2 = 28
    OFFSET_CORNER_LONGITUDE_POINT_2 = 29
    OFFSET_CORNER_LATITUDE_POINT_3 = 30
    OFFSET_CORNER_LONGITUDE_POINT_3 = 31
    OFFSET_CORNER_LATITUDE_POINT_4 = 32
    OFFSET_CORNER_LONGITUDE_POINT_4 = 33
    TARGET_LOCATION_LATITUDE = 40
    TARGET_LOCATION_LONGITUDE = 41
    TARGET_LOCATION_ELEVATION = 42
    TARGET_ERROR_ESTIMATE_CE90 = 45
    TARGET_ERROR_ESTIMATE_LE90 = 46
    GENERIC_FLAG_DATA = 47
    UAS_DATALINK_LS_VERSION_NUMBER = 65
    VMTI_LOCAL_SET = 74
    SENSOR_ELLIPSOID_HEIGHT = 75
    FRAME_CENTER_HEIGHT_ABOVE_ELLIPSOID = 78
    CORNER_LATITUDE_POINT_1_FULL = 82
    CORNER_LONGITUDE_POINT_1_FULL = 83
    CORNER_LATITUDE_POINT_2_FULL = 84
    CORNER_LONGITUDE_POINT_2_FULL = 85
    CORNER_LATITUDE_POINT_3_FULL = 86
    CORNER_LONGITUDE_POINT_3_FULL = 87
    CORNER_LATITUDE_POINT_4_FULL = 88
    CORNER_LONGITUDE_POINT_4_FULL = 89
    PLATFORM_PITCH_ANGLE_FULL = 90
    PLATFORM_ROLL_ANGLE_FULL = 91


def _known_or_unknown(decode):
    """A zero-length item means the value is no longer known (ST 0601 §6.2)."""
    return lambda raw: decode(raw) if raw else Special.UNKNOWN


#: tag -> (name, decoder) for :func:`.localset.decode_table`
TABLE = {tag: (name, _known_or_unknown(spec.decoder() if isinstance(spec, Mapped) else spec))
         for tag, (name, spec) in FIELDS.items()}


@dataclass
class Nested:
    """An ST 1607 segment (tag 100) or amend (tag 101) set: its decoded values by tag (metadata
    substream id 143 as raw bytes) and nested children."""

    kind: str  # "segment" | "amend"
    values: dict[int, Any] = field(default_factory=dict)
    children: list[Nested] = field(default_factory=list)


def decode_values(items: list[tuple[int, bytes]], prefix: str = "", *, depth: int = 0
                  ) -> tuple[dict[int, Any], list[Note]]:
    """tag -> value for the items of one ST 0601 set (the last of a repeated tag), and notes."""
    values, notes = decode_table([(t, v) for t, v in items if t not in MULTIPLE], TABLE, prefix)
    version = [v for t, v in items if t == 65]
    if version and len(version[-1]) > 1 and 65 in values:  # jMISB refuses it; the value is plain, so it is kept
        notes.append(Note("field", f"{prefix}65", f"UAS Datalink LS Version Number sent in {len(version[-1])} bytes "
                                                  f"(ST 0601: 1); read as {values[65]}"))
    if 74 in values:  # kept raw by the table: the VMTI set is read item by item too
        values[74], more = decode_vmti(values[74], prefix=f"{prefix}74.")
        notes += more
    nested = [(t, v) for t, v in items if t in MULTIPLE]
    for tag, raw in nested:
        child, child_notes = decode_nested(raw, "segment" if tag == 100 else "amend", f"{prefix}{tag}.", depth + 1)
        notes += child_notes
        values.setdefault(tag, []).append(child)
    return values, notes


def decode_nested(raw: bytes, kind: str, prefix: str, depth: int) -> tuple[Nested, list[Note]]:
    """An ST 1607 child set, as far as it is valid: every decodable item is kept and every
    departure (both segment and amend children, a segment inside an amend, no substream id,
    a checksum item, too deep) is a note, never an error for the packet."""
    items, notes = parse_items(raw, prefix=prefix)
    if depth > 16:
        return Nested(kind), [*notes, Note("field", prefix.rstrip("."), "ST 1607 sets nested deeper than 16; "
                                                                          "not read")]
    tags = [t for t, _ in items]
    where = prefix.rstrip(".")
    if tags.count(143) != 1:
        notes.append(Note("field", where, f"ST 1607 {kind} set has {tags.count(143)} metadata substream ids "
                                          "(143), 1 expected; read anyway"))
    if 100 in tags and 101 in tags:
        notes.append(Note("field", where, f"ST 1607 {kind} set holds both segment and amend children; both "
                                          "read"))
    if kind == "amend" and 100 in tags:
        notes.append(Note("field", where, "ST 1607 amend set holds a segment child; read anyway"))
    if 1 in tags:
        notes.append(Note("field", where, "ST 1607 child set carries a checksum item (1); ignored"))
    values, more = decode_values([(t, v) for t, v in items if t != 1], prefix, depth=depth)
    children = [*values.pop(100, []), *values.pop(101, [])]
    return Nested(kind, values, children), notes + more
