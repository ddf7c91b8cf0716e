"""MISB ST 0903 VMTI (Video Moving Target Indicator) local sets, decoded from what is there.

Real encoders leave out items ST 0903.6 makes mandatory (the LS version, the number of targets
reported) and send the frame size only in some packets; stanag4609 (a validator) then refuses
the whole set and every target in it is lost. This decoder keeps every target pack and every item
that can be read, with a note for what could not (a truncated pack, an item of the wrong length).
The tag table is ST 0903.6's (Tables 2 and 5); ``tests/unit/io/klv/test_klv_tolerant.py`` decodes sets built
by stanag4609's encoder and compares every value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from .localset import (
    FieldError,
    Note,
    SetError,
    Text,
    UInt,
    ber_length,
    ber_oid,
    decode_table,
    encode_items,
    encode_length,
    encode_oid,
    misb_time,
    parse_items,
)


class IMAPB:
    """ST 1201 IMAPB decoder for [lo, hi] in ``length`` bytes; special code words give NaN.
    Its constants (``s_r``, ``z``, ``top``, ``exact_top``) are read by the columnar decoder too."""

    def __init__(self, lo: float, hi: float, length: int) -> None:
        b_pow = math.ceil(math.log2(hi - lo))
        d_pow = 8 * length - 1
        s_f = 2.0 ** (d_pow - b_pow)
        self.lo, self.length = lo, length
        self.s_r = 2.0 ** (b_pow - d_pow)
        self.z = s_f * lo - math.floor(s_f * lo) if lo < 0 < hi else 0.0
        self.top = 1 << d_pow
        self.exact_top = (hi - lo) == 2.0 ** b_pow  # interval a power of two: the MSB-only word is the maximum

    def __call__(self, raw: bytes) -> float:
        if len(raw) != self.length:
            raise FieldError(f"{self.length} bytes expected, {len(raw)} sent")
        y = int.from_bytes(raw, "big")
        if y >= self.top and not (self.exact_top and y == self.top):
            return math.nan
        return self.s_r * (y - self.z) + self.lo


_FOV = IMAPB(0.0, 180.0, 2)
_OFFSET = IMAPB(-19.2, 19.2, 3)
LOCATION_HAE = IMAPB(-900.0, 19000.0, 2)  # (the VTarget's own HAE, tag 12, too)
LOCATION_LAT, LOCATION_LON, _SIGMA = IMAPB(-90.0, 90.0, 4), IMAPB(-180.0, 180.0, 4), IMAPB(0.0, 650.0, 2)


_uint, _text = UInt(), Text(strict=False)


@dataclass(frozen=True)
class Location:
    """ST 0903 Location pack (target location, tag 17): degrees, metres HAE (as the standard
    says; some encoders write MSL: the KLV check reports which)."""

    lat_deg: float
    lon_deg: float
    h_m: float
    sigma_east_m: float = math.nan
    sigma_north_m: float = math.nan
    sigma_up_m: float = math.nan


def decode_location(raw: bytes) -> Location:
    if len(raw) not in (10, 16, 22):
        raise FieldError(f"10, 16 or 22 bytes expected, {len(raw)} sent")
    sig = [_SIGMA(raw[i:i + 2]) for i in range(10, 16, 2)] if len(raw) >= 16 else []
    return Location(LOCATION_LAT(raw[0:4]), LOCATION_LON(raw[4:8]), LOCATION_HAE(raw[8:10]), *sig)


# -- ST 0903.3 and older (VMTI LS version <= 3): linear mappings, not ST 1201 IMAPB -------------------

def _linear(lo: float, hi: float, length: int, *, signed: bool = False):
    """ST 0903.3's mappings: an unsigned integer over [lo, hi], or a signed one over +-hi."""
    top = (1 << (8 * length)) - 1

    def decode(raw: bytes) -> float:
        if len(raw) != length:
            raise FieldError(f"{length} bytes expected, {len(raw)} sent")
        if signed:
            return int.from_bytes(raw, "big", signed=True) * hi / ((1 << (8 * length - 1)) - 1)
        return lo + int.from_bytes(raw, "big") * (hi - lo) / top
    return decode


_FOV3, _HAE3, _OFFSET3 = _linear(0.0, 180.0, 2), _linear(-900.0, 19000.0, 2), _linear(0, 19.2, 3, signed=True)
_LAT3, _LON3, _SIGMA3 = _linear(-90.0, 90.0, 4), _linear(-180.0, 180.0, 4), _linear(0.0, 650.0, 2)


def _location3(raw: bytes) -> Location:
    if len(raw) not in (10, 16, 22):
        raise FieldError(f"10, 16 or 22 bytes expected, {len(raw)} sent")
    sig = [_SIGMA3(raw[i:i + 2]) for i in range(10, 16, 2)] if len(raw) >= 16 else []
    return Location(_LAT3(raw[0:4]), _LON3(raw[4:8]), _HAE3(raw[8:10]), *sig)


#: What ST 0903.3 and older encode differently (jMISB's LEGACY encoding mode: the same tags)
LEGACY_VMTI = {11: ("vmtiHorizontalFov", _FOV3), 12: ("vmtiVerticalFov", _FOV3)}
LEGACY_VTARGET = {10: ("targetLocationOffsetLat", _OFFSET3), 11: ("targetLocationOffsetLon", _OFFSET3),
                  12: ("targetHae", _HAE3), 13: ("boundingBoxTopLeftLatOffset", _OFFSET3),
                  14: ("boundingBoxTopLeftLonOffset", _OFFSET3), 15: ("boundingBoxBottomRightLatOffset", _OFFSET3),
                  16: ("boundingBoxBottomRightLonOffset", _OFFSET3), 17: ("targetLocation", _location3)}
LEGACY_VERSION = 3  # sets of this LS version or older


#: ST 0903.6 VMTI local set items: tag -> (name, decoder); 101 (targets) is read separately
VMTI_FIELDS: dict[int, tuple[str, Any]] = {
    2: ("precisionTimeStamp", misb_time), 3: ("vmtiSystemName", _text), 4: ("vmtiLsVersionNum", _uint),
    5: ("totalNumTargetsDetected", _uint), 6: ("numTargetsReported", _uint), 7: ("frameNumber", _uint),
    8: ("frameWidth", _uint), 9: ("frameHeight", _uint), 10: ("vmtiSourceSensor", _text),
    11: ("vmtiHorizontalFov", _FOV), 12: ("vmtiVerticalFov", _FOV),
}
#: ST 0903.6 VTarget pack items eoloc reads
VTARGET_FIELDS: dict[int, tuple[str, Any]] = {
    1: ("targetCentroid", _uint), 2: ("boundingBoxTopLeft", _uint), 3: ("boundingBoxBottomRight", _uint),
    4: ("targetPriority", _uint), 5: ("targetConfidenceLevel", _uint), 6: ("targetHistory", _uint),
    7: ("percentageOfTargetPixels", _uint), 9: ("targetIntensity", _uint),
    10: ("targetLocationOffsetLat", _OFFSET), 11: ("targetLocationOffsetLon", _OFFSET), 12: ("targetHae", LOCATION_HAE),
    13: ("boundingBoxTopLeftLatOffset", _OFFSET), 14: ("boundingBoxTopLeftLonOffset", _OFFSET),
    15: ("boundingBoxBottomRightLatOffset", _OFFSET), 16: ("boundingBoxBottomRightLonOffset", _OFFSET),
    17: ("targetLocation", decode_location), 19: ("centroidPixRow", _uint), 20: ("centroidPixCol", _uint),
    22: ("algorithmId", _uint), 23: ("detectionStatus", _uint),
}


@dataclass
class VTarget:
    """One VTarget pack: its id and decoded items (others kept as raw bytes)."""

    target_id: int
    values: dict[int, Any] = field(default_factory=dict)

    def value(self, tag: int, default: Any = None) -> Any:
        return self.values.get(tag, default)


@dataclass
class VMTISet:
    """A VMTI local set: decoded items by tag and the target packs."""

    values: dict[int, Any] = field(default_factory=dict)
    targets: list[VTarget] = field(default_factory=list)

    def value(self, tag: int, default: Any = None) -> Any:
        return self.values.get(tag, default)


def decode_vmti(raw: bytes, *, prefix: str = "") -> tuple[VMTISet, list[Note]]:
    """An embedded VMTI local set (the value of ST 0601 tag 74), from what is there. A set whose LS
    version (tag 4) is 3 or older is read with ST 0903.3's mappings (fields of view, target HAE,
    location offsets, target location: linear, not IMAPB), with a note."""
    items, notes = parse_items(raw, prefix=prefix)
    series = [v for t, v in items if t == 101]
    version = next((v for t, v in items if t == 4), None)
    legacy = False
    if version is not None and 1 <= len(version) <= 8:
        legacy = int.from_bytes(version, "big") <= LEGACY_VERSION
    table = {**VMTI_FIELDS, **LEGACY_VMTI} if legacy else VMTI_FIELDS
    values, more = decode_table([(t, v) for t, v in items if t not in (1, 101)], table, prefix)
    notes += more
    if legacy:
        notes.append(Note("legacy version", f"{prefix}4", f"ST 0903 LS version {values.get(4)}: fields of view, "
                                                        "target HAE, offsets and locations read with ST 0903.3's "
                                                        "linear mappings"))
    targets: list[VTarget] = []
    if series:
        targets, more = decode_targets(series[-1], prefix=f"{prefix}101.", legacy=legacy)
        notes += more
    if len(series) > 1:
        notes.append(Note("duplicate tag", f"{prefix}101", "VTarget series sent more than once; the last is used"))
    if 4 not in values:
        notes.append(Note("field", f"{prefix}4", "vmtiLsVersionNum (mandatory in ST 0903.6) missing; set read anyway"))
    reported = values.get(6)
    if isinstance(reported, int) and reported != len(targets):
        notes.append(Note("field", f"{prefix}6", f"numTargetsReported says {reported}, the series holds "
                                                  f"{len(targets)} targets; all read"))
    return VMTISet(values, targets), notes


def decode_targets(raw: bytes, *, prefix: str = "", legacy: bool = False) -> tuple[list[VTarget], list[Note]]:
    """A VTarget series: BER-length-prefixed packs of (target id, items); ``legacy``: ST 0903.3's
    mappings."""
    table = {**VTARGET_FIELDS, **LEGACY_VTARGET} if legacy else VTARGET_FIELDS
    targets: list[VTarget] = []
    notes: list[Note] = []
    pos, end = 0, len(raw)
    while pos < end:
        try:
            length, p, _ = ber_length(raw, pos, end)
            if p + length > end:
                raise SetError(f"a VTarget pack declares {length} bytes but only {end - p} remain")
            tid, q = ber_oid(raw, p, p + length)
        except SetError as exc:
            notes.append(Note("truncated item", prefix.rstrip("."), f"{exc}; the targets before it are kept"))
            break
        items, n = parse_items(raw, q, p + length, prefix=f"{prefix}{tid}.")
        values, m = decode_table(items, table, f"{prefix}{tid}.")
        targets.append(VTarget(tid, values))
        notes += n + m
        pos = p + length
    return targets, notes


# -- encoding (test streams, any subset of items) ------------------------------------------------


def encode_target(target_id: int, items: dict[int, bytes]) -> bytes:
    """One VTarget pack from raw item values."""
    body = encode_oid(target_id) + encode_items(items.items())
    return encode_length(len(body)) + body


def encode_vmti_set(items: dict[int, bytes], targets: list[bytes]) -> bytes:
    """A VMTI local set (for ST 0601 tag 74) from raw item values and encoded target packs; the
    items are written as given, so sets without ST 0903's mandatory items can be built."""
    pairs = list(items.items())
    if targets:
        pairs.append((101, b"".join(targets)))
    return encode_items(pairs)
