"""KLV local sets read the way receivers in the field read them: item by item, keeping every item
that can be read and noting every departure from the standard instead of refusing the set.

A local set is a run of (BER-OID tag, BER length, value) items (SMPTE ST 336). What a strict
decoder rejects and this one keeps, with a :class:`Note`: a length in long form where the short
form would do, a tag sent twice (the last one counts, as report-on-change receivers do), items out
of the standard's order. What cannot be kept is named too: an item whose length runs past the end
of its set ends the set there (the items before it are kept).

Written here rather than taken from stanag4609, whose parser is (rightly, for a validator) strict:
it refuses the whole set on any of the above (README: "Real KLV").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

EPOCH = datetime(1970, 1, 1, tzinfo=UTC)  # MISB time stamps: microseconds since (ST 0603)
MAX_TIME_US = (datetime.max.replace(tzinfo=UTC) - EPOCH) // timedelta(microseconds=1)  # 9999-12-31 23:59:59.999999


@dataclass(frozen=True, slots=True)
class Note:
    """A departure from the standard met while decoding, kept with the item it concerns.

    kind: "long-form length" | "duplicate tag" | "out of order" | "truncated item" | "field";
    tag: the item's tag, dotted for nested sets ("74.101.3" is item 3 of a VMTI target).
    """

    kind: str
    tag: str
    message: str


class FieldError(ValueError):
    """An item's value cannot be decoded (message says why); the item is left out with a note."""


class SetError(Exception):
    """The bytes cannot be read as a local set at all (raised only by :func:`ber_length`)."""


def num(v: Any) -> float:
    """A decoded value as a float; special values ('off earth', 'reserved', ...) become NaN."""
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        return float(v) if math.isfinite(v) else math.nan
    return math.nan


def misb_time(raw: bytes) -> datetime:
    """A MISB precision time stamp (ST 0603: an 8-byte count of microseconds since 1970-01-01 UTC)
    as a UTC datetime. Every item time stamp (ST 0601 tag 2, ST 0903 tag 2, EG 0104's) is read
    here. A value it cannot be (a wrong length, or past the year 9999, such as all bits set) is a
    :class:`FieldError`: the item is left out with a note and the rest of the packet kept."""
    if len(raw) != 8:
        raise FieldError(f"8 bytes expected, {len(raw)} sent")
    us = int.from_bytes(raw, "big")
    if us > MAX_TIME_US:
        raise FieldError(f"time stamp {us} µs (0x{raw.hex().upper()}) is past the year 9999: not a time")
    return EPOCH + timedelta(microseconds=us)


@dataclass(frozen=True, slots=True)
class UInt:
    """Decoder of an unsigned integer item of 1 to 8 bytes, within [lo, hi] where given."""

    lo: int | None = None
    hi: int | None = None

    def __call__(self, raw: bytes) -> int:
        if not raw or len(raw) > 8:
            raise FieldError(f"1 to 8 bytes expected, {len(raw)} sent")
        v = int.from_bytes(raw, "big")
        if (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi):
            raise FieldError(f"value {v} outside {self.lo}..{self.hi}")
        return v


@dataclass(frozen=True, slots=True)
class Text:
    """Decoder of a text item: UTF-8 with trailing NULs cut; ``strict``: bytes that are not UTF-8
    are a :class:`FieldError` (ST 0601), else replaced (ST 0903, which keeps the set)."""

    strict: bool = True

    def __call__(self, raw: bytes) -> str:
        try:
            return raw.decode("utf-8", errors="strict" if self.strict else "replace").rstrip("\x00")
        except UnicodeDecodeError:
            raise FieldError("not UTF-8 text") from None


def ber_length(data: bytes, pos: int, end: int) -> tuple[int, int, bool]:
    """(length, position after it, long form where short would do) of the BER length at ``pos``."""
    if pos >= end:
        raise SetError("the set ends before an item's length")
    first = data[pos]
    if first < 0x80:
        return first, pos + 1, False
    n = first & 0x7F
    if n == 0 or n > 8:
        raise SetError(f"invalid BER length byte 0x{first:02X}")
    if pos + 1 + n > end:
        raise SetError("the set ends inside an item's BER length")
    length = int.from_bytes(data[pos + 1:pos + 1 + n], "big")
    return length, pos + 1 + n, length < 0x80 or data[pos + 1] == 0


def ber_oid(data: bytes, pos: int, end: int) -> tuple[int, int]:
    """(value, position after it) of the BER-OID integer at ``pos`` (at most 4 bytes)."""
    value = 0
    for i in range(pos, min(pos + 4, end)):
        b = data[i]
        value = (value << 7) | (b & 0x7F)
        if not b & 0x80:
            return value, i + 1
    raise SetError("an item's tag is unterminated or longer than 4 bytes")


def encode_length(n: int) -> bytes:
    """Minimal definite-form BER length."""
    if n < 0x80:
        return bytes((n,))
    width = (n.bit_length() + 7) // 8
    return bytes((0x80 | width,)) + n.to_bytes(width, "big")


def encode_oid(tag: int) -> bytes:
    """BER-OID encoding of a tag."""
    groups = [tag & 0x7F]
    tag >>= 7
    while tag:
        groups.append(0x80 | (tag & 0x7F))
        tag >>= 7
    return bytes(reversed(groups))


def encode_items(items, *, long_form: bool = False) -> bytes:
    """A local set from (tag, value bytes) pairs, in the given order (duplicates allowed: tests
    build non-standard sets with it). long_form: every length in 4-byte long form."""
    out = bytearray()
    for tag, value in items:
        out += encode_oid(tag)
        out += (b"\x84" + len(value).to_bytes(4, "big")) if long_form else encode_length(len(value))
        out += value
    return bytes(out)


def parse_items(data: bytes, start: int = 0, end: int | None = None, *, prefix: str = "", whole: bool = False
                ) -> tuple[list[tuple[int, bytes]], list[Note]]:
    """Every readable (tag, value) item of the set data[start:end], in order, and the notes.

    Duplicates are returned as sent (the caller keeps the last); a long-form length is noted once
    per tag; an item running past the end stops the parse with a "truncated item" note.
    ``whole``: (tag, the item's bytes as sent: tag, length and value) instead, for re-encoding a
    set item by item.
    """
    end = len(data) if end is None else end
    items: list[tuple[int, bytes]] = []
    notes: list[Note] = []
    pos = start
    while pos < end:
        try:
            tag, p = ber_oid(data, pos, end)
            length, p, needless = ber_length(data, p, end)
        except SetError as exc:
            notes.append(Note("truncated item", prefix.rstrip(".") or "set",
                              f"{exc} at byte {pos - start} of the set; the rest of the set is not read"))
            break
        if p + length > end:
            notes.append(Note("truncated item", f"{prefix}{tag}",
                              f"declares {length} bytes but only {end - p} remain in the set; the rest of the "
                              "set is not read"))
            break
        if needless:
            notes.append(Note("long-form length", f"{prefix}{tag}", "length in BER long form where the short form "
                              "would do (read as is)"))
        items.append((tag, data[pos if whole else p:p + length]))
        pos = p + length
    return items, notes


def last_of_each(items: list[tuple[int, bytes]], prefix: str = "") -> tuple[dict[int, bytes], list[Note]]:
    """tag -> value with the last of a repeated tag kept, and a note per repeated tag."""
    out: dict[int, bytes] = {}
    notes: list[Note] = []
    for tag, value in items:
        if tag in out:
            notes.append(Note("duplicate tag", f"{prefix}{tag}", "sent more than once in a set; the last one is "
                              "used"))
        out[tag] = value
    return out, notes


def decode_table(items: list[tuple[int, bytes]], table: dict, prefix: str = "") -> tuple[dict[int, Any], list[Note]]:
    """tag -> value of a set's items, the last of a repeated tag kept: decoded by ``table[tag] =
    (name, decoder)``, kept as raw bytes where the table has no entry; an item its decoder refuses
    (:class:`FieldError`) is left out with a note. The one item loop of ST 0601, ST 0903 and EG 0104."""
    last, notes = last_of_each(items, prefix)
    values: dict[int, Any] = {}
    for tag, raw in last.items():
        spec = table.get(tag)
        if spec is None:
            values[tag] = raw
            continue
        try:
            values[tag] = spec[1](raw)
        except FieldError as exc:
            notes.append(Note("field", f"{prefix}{tag}", f"{spec[0]}: {exc}; left out"))
    return values, notes
