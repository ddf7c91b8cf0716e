"""MISB KLV decoded straight into column arrays: the archive's reader (`eoloc batch`, tables).

The same packets, issues and notes as the tolerant reader (:mod:`.reader`), at compiled speed:
runs of clean ST 0601 packets (their VMTI sets included) are framed, checksummed and decoded by
:mod:`eoloc.kernels.klvscan` in one pass over the bytes, straight into arrays; every packet the
scanner does not call clean (a departure the tolerant reader would note, a value it would refuse)
and every stretch that is not a clean run (damage, other keys, stray bytes) goes through the
tolerant reader's own code, one packet at a time (:class:`.reader.Framer`), so its values, notes
and issues are the tolerant reader's by construction. The scanner's tag tables are built here
from the tolerant decoders' tables (:data:`.st0601.FIELDS`, :data:`.st0903.VMTI_FIELDS`,
:data:`.st0903.VTARGET_FIELDS`): one declaration of each tag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from fractions import Fraction
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from .localset import EPOCH, MAX_TIME_US, Text, UInt, misb_time, num
from .reader import (
    UAS_KEY,
    Framer,
    KLVIssue,
    KLVPacket,
    KLVStream,
    StreamNote,
    decode_klv_bytes,
    decode_packet,
    packet_pts,
    read_klv_file,
    ts_klv_parts,
    with_repaired_keys,
)
from .st0601 import FIELDS, Mapped
from .st0903 import (
    IMAPB,
    LEGACY_VERSION,
    LOCATION_HAE,
    LOCATION_LAT,
    LOCATION_LON,
    VMTI_FIELDS,
    VTARGET_FIELDS,
    decode_location,
)

#: ST 0601 tags with a numeric column (every mapped or integer item of :data:`.st0601.FIELDS`)
COLUMN_TAGS: tuple[int, ...] = tuple(t for t, (_, spec) in FIELDS.items() if isinstance(spec, (Mapped, UInt)))
COLUMN = {tag: i for i, tag in enumerate(COLUMN_TAGS)}
#: ST 0903 output columns: set level (integers after "has a set"; floats), target level
VMTI_COLUMNS = {11: 0, 12: 1, 8: 2, 9: 3}  # fields of view, frame width and height
TARGET_INT_COLUMNS = {1: 2, 2: 3, 3: 4, 19: 5, 20: 6}  # after (row, target id); then 7: 1 where a location is sent
TARGET_FLOAT_COLUMNS = {10: 0, 11: 1, 12: 2, 17: 3}  # 17: location lat, lon, HAE in 3, 4, 5
RUN = 1 << 16  # packets framed per call of the scanner (bounds its arrays)
MAX_INT = (1 << 63) - 1
_US = timedelta(microseconds=1)


@cache
def scan_tables() -> tuple[np.ndarray, ...]:
    """The scanner's tables (integer and float rows per tag) for ST 0601, the VMTI set, the
    VTarget pack and the location pack, from the tolerant decoders' own tables."""
    from ...kernels import klvscan as S

    def table(fields: dict[int, tuple[str, Any]], int_cols: dict[int, int], float_cols: dict[int, int],
              extra: dict[int, int]) -> tuple[np.ndarray, np.ndarray]:
        spec_i = np.zeros((S.N_TAGS, S.N_SPEC_I), np.int64)
        spec_f = np.zeros((S.N_TAGS, S.N_SPEC_F), np.float64)
        spec_i[:, S.SPEC_COL] = -1
        spec_i[:, S.SPEC_UHI] = -1
        for tag, kind in extra.items():
            spec_i[tag, S.SPEC_KIND] = kind
        for tag, (_, dec) in fields.items():
            row = spec_i[tag]
            row[S.SPEC_COL] = int_cols.get(tag, float_cols.get(tag, -1))
            if dec is misb_time:
                row[S.SPEC_KIND] = S.K_TIME
            elif isinstance(dec, Text):
                row[S.SPEC_KIND] = S.K_TEXT_UTF8 if dec.strict else S.K_TEXT_ANY
            elif isinstance(dec, UInt):
                row[S.SPEC_KIND] = S.K_VERSION if tag in extra else S.K_UINT
                row[S.SPEC_ULO] = dec.lo or 0
                row[S.SPEC_UHI] = -1 if dec.hi is None else dec.hi
            elif isinstance(dec, Mapped):
                rmin, rmax, special = dec.domain()
                row[S.SPEC_KIND], row[S.SPEC_LENGTH], row[S.SPEC_SIGNED] = S.K_MAPPED, dec.length, dec.signed
                row[S.SPEC_HAS_SPECIAL], row[S.SPEC_SPECIAL] = special is not None, special or 0
                row[S.SPEC_RMIN] = rmin
                spec_f[tag, S.SPEC_LO] = float(dec.lo)
                spec_f[tag, S.SPEC_STEP] = float((dec.hi - dec.lo) / Fraction(rmax - rmin))
            elif isinstance(dec, IMAPB):
                imapb_row(S, spec_i, spec_f, tag, dec)
            elif dec is decode_location:
                row[S.SPEC_KIND] = S.K_LOCATION
            else:
                raise TypeError(f"tag {tag}: no scanner kind for decoder {dec!r}")
        return spec_i, spec_f

    st0601 = table(FIELDS, {}, COLUMN, {74: S.K_VMTI, 100: S.K_IRREGULAR, 101: S.K_IRREGULAR, 65: S.K_VERSION})
    vmti = table(VMTI_FIELDS, {}, VMTI_COLUMNS, {101: S.K_SERIES, 1: S.K_IGNORE})
    target = table(VTARGET_FIELDS, TARGET_INT_COLUMNS, TARGET_FLOAT_COLUMNS, {})
    loc_i = np.zeros((3, S.N_SPEC_I), np.int64)
    loc_f = np.zeros((3, S.N_SPEC_F), np.float64)
    for k, dec in enumerate((LOCATION_LAT, LOCATION_LON, LOCATION_HAE)):
        imapb_row(S, loc_i, loc_f, k, dec)
    return (*st0601, *vmti, *target, loc_i, loc_f)


def imapb_row(S, spec_i: np.ndarray, spec_f: np.ndarray, tag: int, dec: IMAPB) -> None:
    spec_i[tag, S.SPEC_KIND], spec_i[tag, S.SPEC_LENGTH] = S.K_IMAPB, dec.length
    spec_i[tag, S.SPEC_TOP], spec_i[tag, S.SPEC_EXACT_TOP] = dec.top, dec.exact_top
    spec_f[tag, S.SPEC_LO], spec_f[tag, S.SPEC_STEP], spec_f[tag, S.SPEC_ZERO] = dec.lo, dec.s_r, dec.z


@dataclass(eq=False)
class KLVColumns:
    """The packets of a KLV file as columns, one row per good packet in file order (what
    :class:`.reader.KLVStream` holds as objects, with the same issues and notes).

    ``values[:, COLUMN[tag]]``: ST 0601 item ``tag`` as a float (NaN where absent or a special
    value), ``present``: the packet carries the item; ``time_us``: tag 2 in µs since 1970 (-1:
    none); ``has_vmti``: the packet carries a VMTI set, ``vmti_f``: its horizontal and vertical
    field of view (deg), frame width and height (px; NaN absent); ``target_i``: one row per VMTI
    target (packet row, target id, centroid, box top-left and bottom-right pixel numbers, centroid
    row and column, 1 where a location pack is sent; -1 absent), ``target_f``: (location offsets
    lat, lon, HAE; location lat, lon, HAE; NaN absent)."""

    path: str
    container: str
    index: np.ndarray
    offset: np.ndarray
    pts_s: np.ndarray
    stream: np.ndarray
    standard: np.ndarray
    time_us: np.ndarray
    values: np.ndarray
    present: np.ndarray
    has_vmti: np.ndarray
    vmti_f: np.ndarray
    target_i: np.ndarray
    target_f: np.ndarray
    issues: list[KLVIssue] = field(default_factory=list)
    notes: list[StreamNote] = field(default_factory=list)
    scanned: int = 0  # packets decoded by the compiled scanner (the others by the tolerant reader)

    def __len__(self) -> int:
        return int(self.index.size)

    @property
    def n_bad(self) -> int:
        """Packets that could not be used (counted in the file's packet numbers, not in the rows)."""
        return sum(1 for i in self.issues if i.packet is not None)

    @property
    def first_packet(self) -> int:
        return int(self.index[0])

    def col(self, tag: int) -> np.ndarray:
        return self.values[:, COLUMN[tag]]

    def has(self, tag: int) -> np.ndarray:
        return self.present[:, COLUMN[tag]]

    @property
    def time_s(self) -> np.ndarray:
        return np.where(self.time_us >= 0, self.time_us / 1e6, np.nan)


def empty_chunk(n: int = 0) -> dict[str, np.ndarray]:
    return {"index": np.zeros(n, np.int64), "offset": np.zeros(n, np.int64), "standard": np.full(n, "ST 0601"),
            "time_us": np.full(n, -1, np.int64), "values": np.full((n, len(COLUMN_TAGS)), np.nan),
            "present": np.zeros((n, len(COLUMN_TAGS)), bool), "has_vmti": np.zeros(n, bool),
            "vmti_f": np.full((n, 4), np.nan), "target_i": np.zeros((0, 8), np.int64),
            "target_f": np.zeros((0, 6))}


def _int_or_absent(v: Any) -> int:
    """An integer item for an int64 column: -1 where absent, not an integer, or past int64 (no
    pixel number or frame size is that large)."""
    return v if isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= MAX_INT else -1


def put_packet(chunk: dict[str, np.ndarray], row: int, p: KLVPacket, targets: list) -> None:
    """Row ``row`` of ``chunk`` from a packet decoded by the tolerant reader (its targets appended
    to ``targets`` as (int row, float row))."""
    f = p.fields
    chunk["index"][row], chunk["offset"][row], chunk["standard"][row] = p.index, p.offset, p.standard
    t = f.get(2)
    chunk["time_us"][row] = (t - EPOCH) // _US if isinstance(t, datetime) else -1
    vals, pres = chunk["values"][row], chunk["present"][row]
    vals.fill(math.nan)  # the row as if nothing were sent (a row the compiled scanner left is rewritten whole)
    pres.fill(False)
    for tag, v in f.items():  # the packet's own items (fewer than the columns)
        c = COLUMN.get(tag)
        if c is not None:
            pres[c] = True
            vals[c] = num(v)
    vm = f.get(74)
    if vm is None or not hasattr(vm, "targets"):
        chunk["has_vmti"][row], chunk["vmti_f"][row] = False, math.nan
        return
    chunk["has_vmti"][row] = True
    chunk["vmti_f"][row] = [num(vm.value(t)) for t in VMTI_COLUMNS]
    for tg in vm.targets:
        tv = tg.values
        loc = tv.get(17)
        sent = hasattr(loc, "lat_deg")
        where = (loc.lat_deg, loc.lon_deg, loc.h_m) if sent else (math.nan,) * 3
        targets.append(((row, _int_or_absent(tg.target_id), *[_int_or_absent(tv.get(t)) for t in TARGET_INT_COLUMNS],
                         1 if sent else -1), (num(tv.get(10)), num(tv.get(11)), num(tv.get(12)), *where)))


def chunk_from_packets(packets: list[KLVPacket]) -> dict[str, np.ndarray]:
    chunk = empty_chunk(len(packets))
    targets: list = []
    for row, p in enumerate(packets):
        put_packet(chunk, row, p, targets)
    add_targets(chunk, targets)
    return chunk


def add_targets(chunk: dict[str, np.ndarray], targets: list) -> None:
    """Append target rows (int row, float row) to a chunk's, keeping the rows in packet order."""
    if not targets:
        return
    ti = np.array([t[0] for t in targets], np.int64).reshape(-1, 8)
    tf = np.array([t[1] for t in targets], np.float64).reshape(-1, 6)
    ti_all = np.concatenate([chunk["target_i"], ti])
    order = np.argsort(ti_all[:, 0], kind="stable")
    chunk["target_i"], chunk["target_f"] = ti_all[order], np.concatenate([chunk["target_f"], tf])[order]


def columns_from_stream(stream: KLVStream) -> KLVColumns:
    """A decoded :class:`.reader.KLVStream` as columns (the reference the fast reader is held to)."""
    chunk = chunk_from_packets(stream.packets)
    pts = np.array([math.nan if p.pts_s is None else p.pts_s for p in stream.packets], np.float64)
    names = np.array([p.stream for p in stream.packets], dtype=object).astype(str)
    return _assemble(stream.path, stream.container, [chunk], pts, names, stream.issues, stream.notes)


def _assemble(path, container, chunks, pts, names, issues, notes, scanned: int = 0) -> KLVColumns:
    rows = np.cumsum([0] + [c["index"].size for c in chunks])
    for c, first in zip(chunks, rows[:-1], strict=True):
        c["target_i"] = c["target_i"].copy()
        c["target_i"][:, 0] += first
    cat = (chunks[0] if len(chunks) == 1 else {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
           if chunks else empty_chunk())
    return KLVColumns(path, container, cat["index"], cat["offset"], pts, names, cat["standard"].astype(str),
                      cat["time_us"], cat["values"], cat["present"], cat["has_vmti"], cat["vmti_f"], cat["target_i"],
                      cat["target_f"], list(issues), list(notes), scanned)


def decode_klv_columns(data: bytes, path: str = "<bytes>", *, pts: list[tuple[int, float | None]] | None = None,
                       container: str = "klv", stream: str = "", first_index: int = 0,
                       strict: bool = False) -> KLVColumns:
    """:func:`.reader.decode_klv_bytes` as columns, the clean packets decoded by the compiled
    scanner (see the module notes); the same packets, values, issues and notes."""
    if strict:  # (stanag4609 judges each packet: the reader's way)
        s = decode_klv_bytes(data, path, pts=pts, container=container, stream=stream, first_index=first_index,
                             strict=strict)
        return columns_from_stream(s)
    return with_repaired_keys(data, pts, stream, first_index, lambda d, marks: _decode_columns(
        d, path, pts=marks, container=container, stream=stream, first_index=first_index))


def _decode_columns(data: bytes, path: str, *, pts, container: str, stream: str, first_index: int) -> KLVColumns:
    from ...kernels import klvscan as S

    tables = scan_tables()
    buf = np.frombuffer(data, np.uint8)
    key = np.frombuffer(UAS_KEY, np.uint8)
    framer = Framer(data, path, stream=stream, first_index=first_index)
    chunks: list[dict[str, np.ndarray]] = []
    scanned = 0
    while framer.pos < len(data):
        count, starts, vstarts, ends = S.frame_run(buf, framer.pos, RUN, key)
        if not count:
            framer.step()  # (its packets join the columns as a chunk before the next clean run)
            continue
        if framer.packets:
            chunks.append(chunk_from_packets(framer.packets))
            framer.packets = []
        clean, values, present, time_us, has_vmti, vm_f, _, tg_i, tg_f = S.decode_run(
            buf, vstarts, ends, count, tables, len(COLUMN_TAGS), MAX_TIME_US, LEGACY_VERSION + 1, 2)
        chunk = {"index": framer.n + np.arange(count), "offset": starts[:count].copy(),
                 "standard": np.full(count, "ST 0601"), "time_us": time_us, "values": values, "present": present,
                 "has_vmti": has_vmti, "vmti_f": vm_f, "target_i": tg_i, "target_f": tg_f}
        targets: list = []
        for row in np.flatnonzero(~clean).tolist():  # the tolerant reader's decoding, notes and all
            k, end = int(starts[row]), int(ends[row])
            raw = data[k:end]
            standard, vals, pnotes = decode_packet(raw, int(vstarts[row]) - k)
            framer.notes.add(stream, framer.n + row, pnotes)
            put_packet(chunk, row, KLVPacket(framer.n + row, k, None, raw, vals, stream, standard), targets)
        add_targets(chunk, targets)
        chunks.append(chunk)
        scanned += int(clean.sum())
        framer.n += count
        framer.pos = int(ends[count - 1])
        framer.after_bad = False
    if framer.packets:
        chunks.append(chunk_from_packets(framer.packets))
    n = sum(c["index"].size for c in chunks)
    offsets = np.concatenate([c["offset"] for c in chunks]) if chunks else np.zeros(0, np.int64)
    pts_s = (np.array([math.nan if t is None else t for t in packet_pts(offsets, pts)], np.float64) if pts and n
             else np.full(n, np.nan))
    return _assemble(path, container, chunks, pts_s, np.full(n, stream), framer.issues, framer.notes.result(),
                     scanned)


def read_klv_columns(path: str | Path, *, strict: bool = False) -> KLVColumns:
    """:func:`.reader.read_klv` as columns (raw KLV or MPEG-TS; the same errors)."""
    return read_klv_file(path, strict=strict, from_ts=ts_columns, from_klv=decode_klv_columns)


def ts_columns(data: bytes, path: str, *, strict: bool = False) -> KLVColumns:
    """:func:`.reader.read_ts_bytes` as columns."""
    issues, parts = ts_klv_parts(data, path, strict=strict, decode=decode_klv_columns)
    notes = [n for s, arrival in parts for n in ([arrival, *s.notes] if arrival else s.notes)]
    return concat_columns(path, "mpegts", [s for s, _ in parts], issues, notes)


def concat_columns(path: str, container: str, parts: list[KLVColumns], issues: list[KLVIssue],
                   notes: list[StreamNote]) -> KLVColumns:
    """Columns of several streams one after the other (a transport stream's PIDs), with the
    transport's issues first and every stream's after them, as :func:`.reader.read_ts_bytes`."""
    chunks = [{"index": c.index, "offset": c.offset, "standard": c.standard, "time_us": c.time_us,
               "values": c.values, "present": c.present, "has_vmti": c.has_vmti, "vmti_f": c.vmti_f,
               "target_i": c.target_i, "target_f": c.target_f} for c in parts]
    pts = np.concatenate([c.pts_s for c in parts]) if parts else np.zeros(0)
    names = np.concatenate([c.stream for c in parts]) if parts else np.zeros(0, str)
    return _assemble(path, container, chunks, pts, names, [*issues, *(i for c in parts for i in c.issues)], notes,
                     sum(c.scanned for c in parts))
