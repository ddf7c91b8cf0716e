"""A KLV file read in bounded segments: the archive's streaming reader (`eoloc batch`).

A raw KLV file is read a block at a time and cut only where the tolerant reader itself would stand
at the start of a packet with nothing pending: at an ST 0601 key that a good packet (framed,
checksum passed) ends on. Each segment is then decoded on its own (:func:`.columnar.decode_klv_columns`)
with the file's packet numbering and byte offsets, so that its packets, values and issues are those of
the whole file's reading; its notes count that segment's packets (:func:`merge_notes` sums them to the
whole file's). Memory is bounded by the segment size, whatever the file's size.

What a segment cannot know: whether keys that lost their first 5 bytes are repaired is decided per
segment (the whole file's reading decides once); a damaged packet whose corrupt length ends inside
the file but past the segment's cut is "truncated" there, where the whole reading reads that far
and finds its checksum wrong ("checksum", the same offset); and a block with no such cut in its second half
(a long stretch of damage, or a file of EG 0104 packets only) is read on until one comes, up to
16 segments (at least 16 MB): then it is cut at its last packet key, or anywhere that splits no key,
and the stretch's skipped bytes are reported in two issues rather than one. An MPEG-TS
file is demultiplexed whole (its tables and PES packets run across any cut) from the file mapped
into memory, and its packets given in slices.
"""

from __future__ import annotations

import dataclasses
import mmap
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ...errors import KLVError
from .columnar import KLVColumns, decode_klv_columns, ts_columns
from .eg0104 import EG0104_KEY
from .reader import (
    TS_PACKET,
    UAS_KEY,
    VMTI_KEY,
    StreamNote,
    check_found,
    checksum_problem,
    looks_like_ts,
    packet_end,
    torn_issue,
)

#: bytes of KLV per segment (about 5 000 packets with 5 VMTI targets, some 40 MB at work; `eoloc batch
#: --segment-mb`)
SEGMENT_BYTES = 1_000_000
_CUT_TRIES = 256  # keys looked at, from the end of a block back, for a place to cut
MAX_BLOCKS = 16  # a block is read on to find a cut up to this many segments (at least 1 MB each), then cut anyway


def forced_cut(block: bytes) -> int:
    """Where to cut a block that has no :func:`safe_cut`: at the last packet key in its second half
    (the packet there then starts the next segment), else where no key can be split (16 bytes
    before the end)."""
    last = max(block.rfind(k, len(block) // 2) for k in (UAS_KEY, EG0104_KEY, VMTI_KEY))
    return last if last > 0 else len(block) - 16


def safe_cut(block: bytes, lo: int) -> int | None:
    """The last position at or after ``lo`` where an ST 0601 key starts right after a good packet
    (its key, length and checksum in ``block``, ending there), or None."""
    c = block.rfind(UAS_KEY, lo)
    for _ in range(_CUT_TRIES):
        if c <= lo:
            return None
        p = block.rfind(UAS_KEY, 0, c)
        if p < 0:
            return None
        end, _, _ = packet_end(block, p)
        if end == c and checksum_problem(block[p:c]) is None:
            return c
        c = p
    return None


def klv_segments(path: str | Path, *, segment_bytes: int = SEGMENT_BYTES, strict: bool = False
                 ) -> Iterator[KLVColumns]:
    """The packets of a KLV file (raw KLV, or MPEG-TS: demultiplexed whole, then given in slices)
    as columns, a segment of about ``segment_bytes`` at a time, in file order: packet numbers and
    byte offsets are the file's; issues are each segment's, notes count each segment's packets (see
    the module notes). Raises :class:`KLVError` as :func:`.reader.read_klv` does (the last only
    after the segments read)."""
    p = Path(path)
    try:
        f = p.open("rb")
    except OSError as exc:
        raise KLVError(f"cannot read {path}: {exc.strerror or exc}") from None
    with f:
        head = f.read(5 * TS_PACKET)
        if not head:
            raise KLVError(f"{path} is empty")
        if looks_like_ts(head):
            yield from _ts_segments(f, str(path), segment_bytes, strict)
            return
        block, base, n, good, bad = head, 0, 0, 0, 0
        want = max(int(segment_bytes), 1)
        limit = MAX_BLOCKS * max(want, 1 << 20)
        while True:
            ask = want - len(block) if want > len(block) else want
            ask = min(ask, max(os.fstat(f.fileno()).st_size - f.tell(), 0) + 1)  # (no buffer past the file's end)
            more = f.read(ask)
            block += more
            eof = len(more) < ask  # (a file: a short read is its end)
            cut = len(block) if eof else safe_cut(block, len(block) // 2)
            if cut is None and len(block) >= limit:
                cut = forced_cut(block)  # (a long stretch without a good packet: memory stays bounded)
            if cut is None:  # no place to cut in the second half: read on (twice as much, to the limit)
                want = min(2 * len(block), limit)
                continue
            seg = shifted(decode_klv_columns(block[:cut], str(path), first_index=n, strict=strict), base)
            bad_here = seg.n_bad
            n += len(seg) + bad_here
            good, bad = good + len(seg), bad + bad_here
            yield seg
            base, block = base + cut, block[cut:]
            want = max(int(segment_bytes), 1)
            if eof:
                break
        check_found(path, good, bad)


def _ts_segments(f, path: str, segment_bytes: int, strict: bool) -> Iterator[KLVColumns]:
    """An MPEG-TS file's packets: the file mapped into memory rather than copied into it (its
    pages are the system's file cache, which it can drop and read again; the demultiplexer's own
    arrays take some 25 bytes per transport packet, and the KLV streams are copied out), read
    whole, then given in slices of about ``segment_bytes`` of KLV (the transport's issues and the
    notes with the first), so that the job's memory is bounded as for raw KLV."""
    size = os.fstat(f.fileno()).st_size
    torn = size % TS_PACKET
    with mmap.mmap(f.fileno(), size - torn, access=mmap.ACCESS_READ) as whole:
        cols = ts_columns(whole, path, strict=strict)
    if torn:
        cols.issues.insert(0, torn_issue(path, size))
    check_found(path, len(cols), cols.n_bad)
    per = max(int(segment_bytes) // 200, 1)  # (rows: ~200 bytes of KLV a packet)
    for a in range(0, max(len(cols), 1), per):
        yield row_slice(cols, a, min(a + per, len(cols)), first=a == 0)


def row_slice(cols: KLVColumns, a: int, b: int, *, first: bool) -> KLVColumns:
    """Rows ``a`` to ``b`` of ``cols`` (their VMTI targets with them); its issues and notes only
    where ``first``."""
    t = (cols.target_i[:, 0] >= a) & (cols.target_i[:, 0] < b)
    target_i = cols.target_i[t].copy()
    target_i[:, 0] -= a
    return KLVColumns(cols.path, cols.container, cols.index[a:b], cols.offset[a:b], cols.pts_s[a:b],
                      cols.stream[a:b], cols.standard[a:b], cols.time_us[a:b], cols.values[a:b], cols.present[a:b],
                      cols.has_vmti[a:b], cols.vmti_f[a:b], target_i, cols.target_f[t],
                      list(cols.issues) if first else [], list(cols.notes) if first else [],
                      cols.scanned if first else 0)


def shifted(cols: KLVColumns, base: int) -> KLVColumns:
    """A segment's columns with its byte offsets (and its issues') moved on by ``base``: the file's."""
    if not base:
        return cols
    cols.offset = cols.offset + np.int64(base)
    cols.issues = [dataclasses.replace(i, offset=i.offset + base) for i in cols.issues]
    return cols


def merge_notes(parts: list[list[StreamNote]]) -> list[StreamNote]:
    """The segments' notes as the whole file's: counts summed per (stream, kind, tag), the first
    message and packet kept, in order of first appearance."""
    seen: dict[tuple[str, str, str], StreamNote] = {}
    for notes in parts:
        for n in notes:
            k = (n.stream, n.kind, n.tag)
            seen[k] = n if k not in seen else dataclasses.replace(seen[k], count=seen[k].count + n.count)
    return list(seen.values())
