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
and the stretch's skipped bytes are reported in two issues rather than one.

An MPEG-TS file is read in two passes: its transport a chunk at a time (:mod:`.transport`: the
program tables, the PES packets still open and the rest carried across each chunk's end), each KLV
PID's bytes and PES times set aside in temporary files; then each PID's bytes decoded as raw KLV
is, a segment at a time, PID after PID, as the whole reading numbers them. Its packets, values,
issues and notes are the whole reading's (the PID's bytes carry no key to repair: the caveats
above on cuts hold for them too).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Generator, Iterator
from pathlib import Path

import numpy as np

from ...errors import KLVError
from .columnar import KLVColumns, decode_klv_columns
from .eg0104 import EG0104_KEY
from .reader import (
    TS_PACKET,
    UAS_KEY,
    VMTI_KEY,
    StreamNote,
    arrival_note,
    check_found,
    checksum_problem,
    looks_like_ts,
    no_klv_stream,
    packet_end,
    torn_issue,
    transport_issues,
)
from .transport import SpooledPayloads, transport_payloads

#: bytes of KLV per segment (about 5 000 packets with 5 VMTI targets, some 40 MB at work; `eoloc batch
#: --segment-mb`)
SEGMENT_BYTES = 1_000_000
_CUT_TRIES = 256  # keys looked at, from the end of a block back, for a place to cut
TS_CHUNK_BYTES = 8_000_000  # of an MPEG-TS file's transport read at a time, at least
MAX_BLOCKS = 16  # a block is read on to find a cut up to this many segments (at least 1 MB each), then cut anyway


def forced_cut(block: bytes) -> int:
    """Where to cut a block that has no :func:`safe_cut`: at the last packet key in its second half
    (the packet there then starts the next segment), else where no key can be split (16 bytes
    before the end)."""
    last = max(block.rfind(k, len(block) // 2) for k in (UAS_KEY, EG0104_KEY, VMTI_KEY))
    return last if last > 0 else len(block) - 16


def good_packet(block: bytes, a: int, b: int) -> bool:
    """Whether the packet whose key is at ``a`` ends at ``b`` (its length) and passes its checksum."""
    end, _, _ = packet_end(block, a)
    return end == b and checksum_problem(block[a:b]) is None


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
        if good_packet(block, p, c):
            return c
        c = p
    return None


def klv_segments(path: str | Path, *, segment_bytes: int = SEGMENT_BYTES, strict: bool = False,
                 ts_chunk_bytes: int | None = None, span: tuple[int, int] | None = None,
                 first_index: int = 0) -> Iterator[KLVColumns]:
    """The packets of a KLV file (raw KLV, or MPEG-TS: its transport read ``ts_chunk_bytes`` at a
    time, by default 8 segments' worth and at least :data:`TS_CHUNK_BYTES`, each KLV PID's bytes set
    aside, then decoded PID after PID) as columns, a segment of
    about ``segment_bytes`` at a time, in file order: packet numbers and byte offsets are the
    file's; issues are each segment's, notes count each segment's packets (see the module notes).
    Raises :class:`KLVError` as :func:`.reader.read_klv` does (the last only after the segments
    read). ``span``: bytes ``start`` to ``end`` of a raw KLV file only (each from :func:`range_cut`),
    its packets numbered from ``first_index`` (those before it), not checked for having any."""
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
            if span is not None:
                raise KLVError(f"{path}: an MPEG-TS file is read from its start (streamed), not by byte ranges "
                               "(its PIDs' packets are numbered one PID after the other)")
            chunk = ts_chunk_bytes if ts_chunk_bytes is not None else max(TS_CHUNK_BYTES, 8 * int(segment_bytes))
            yield from _ts_segments(f, str(path), segment_bytes, strict, chunk)
            return
        start, end = span if span is not None else (0, os.fstat(f.fileno()).st_size)
        f.seek(start)
        counts = yield from _segments(f, str(path), segment_bytes=segment_bytes, strict=strict, first_index=first_index,
                                      start=start, end=end)
        if span is None:
            check_found(path, counts[1], counts[2])


def range_cut(f, at: int, *, window: int = 1 << 20) -> int:
    """Where the byte range of a raw KLV file (``f``, open) that begins near byte ``at`` begins: at
    the first ST 0601 key at or after ``at`` that a good packet starting at the key before it (at
    or after ``at``) ends on; there the reader stands at a packet start with nothing pending (as at
    :func:`safe_cut`). The file's end where there is none (a packet is looked for within ``window``
    bytes of the key before it). The ranges on either side of ``at`` find the same place."""
    size = os.fstat(f.fileno()).st_size
    if at <= 0 or at >= size:
        return min(max(at, 0), size)
    pos = at
    while pos < size:
        f.seek(pos)
        block = f.read(window)
        k = block.find(UAS_KEY)
        while k >= 0:
            nxt = block.find(UAS_KEY, k + 1)
            if nxt < 0:
                break
            if good_packet(block, k, nxt):
                return pos + nxt
            k = nxt
        if len(block) < window:
            return size
        pos += k if k > 0 else len(block) - len(UAS_KEY) + 1  # (from the last key, or on without splitting one)
    return size


def _segments(f, path: str, *, segment_bytes: int, strict: bool, first_index: int = 0, marks=None,
              container: str = "klv", stream: str = "", start: int = 0, end: int | None = None
              ) -> Generator[KLVColumns, None, tuple[int, int, int]]:
    """The KLV bytes of ``f`` from where it stands (byte ``start``) to byte ``end`` (default: its
    end) decoded a segment at a time (the module notes), packets numbered from ``first_index``;
    ``marks``: (byte offsets, PTS s with NaN for none) of a transport stream's PES in these bytes.
    Returns the packets numbered, the good and the bad ones."""
    block, base, n, good, bad = b"", start, first_index, 0, 0
    want = max(int(segment_bytes), 1)
    limit = MAX_BLOCKS * max(want, 1 << 20)
    end = os.fstat(f.fileno()).st_size if end is None else end
    while True:
        ask = want - len(block) if want > len(block) else want
        ask = min(ask, max(end - f.tell(), 0))
        more = f.read(ask)
        block += more
        eof = len(more) < ask or f.tell() >= end
        cut = len(block) if eof else safe_cut(block, len(block) // 2)
        if cut is None and len(block) >= limit:
            cut = forced_cut(block)  # (a long stretch without a good packet: memory stays bounded)
        if cut is None:  # no place to cut in the second half: read on (twice as much, to the limit)
            want = min(2 * len(block), limit)
            continue
        pts = None if marks is None else segment_marks(marks, base, base + cut)
        seg = shifted(decode_klv_columns(block[:cut], path, pts=pts, container=container, stream=stream,
                                         first_index=n, strict=strict), base)
        bad_here = seg.n_bad
        n += len(seg) + bad_here
        good, bad = good + len(seg), bad + bad_here
        yield seg
        base, block = base + cut, block[cut:]
        want = max(int(segment_bytes), 1)
        if eof:
            return n, good, bad


def segment_marks(marks, a: int, b: int) -> list[tuple[int, float | None]]:
    """The PES marks (offsets, PTS s) that time bytes ``a`` to ``b`` of a PID's stream, as offsets
    from ``a``: those in it, after the last one before it (moved to ``a``)."""
    offsets, times = marks
    i = max(int(np.searchsorted(offsets, a, side="right")) - 1, 0)
    j = int(np.searchsorted(offsets, b, side="left"))
    o = np.maximum(np.asarray(offsets[i:j], np.int64) - a, 0).tolist()
    return [(x, None if math.isnan(t) else t) for x, t in zip(o, np.asarray(times[i:j]).tolist(), strict=True)]


def _ts_segments(f, path: str, segment_bytes: int, strict: bool, chunk_bytes: int) -> Iterator[KLVColumns]:
    """An MPEG-TS file's packets: its transport read ``chunk_bytes`` at a time, each KLV PID's
    bytes and PES marks set aside in temporary files (:class:`.transport.SpooledPayloads`), then
    each PID decoded a segment at a time as raw KLV is, PID after PID (the reader's numbering);
    the transport's issues with the first segment, a PID's note on timing by arrival with its
    first. Memory is bounded by the chunk and segment sizes, whatever the file's."""
    size = os.fstat(f.fileno()).st_size
    torn = size % TS_PACKET
    step = max(int(chunk_bytes) // TS_PACKET, 1) * TS_PACKET

    def chunks():
        f.seek(0)
        left = size - torn
        while True:
            data = f.read(min(step, left))
            left -= len(data)
            yield data, left <= 0 or not data
            if left <= 0 or not data:
                return

    problems, sink, by_arrival = transport_payloads(chunks, SpooledPayloads)
    with sink:
        if not sink.pids():
            raise KLVError(no_klv_stream(path))
        issues = ([torn_issue(path, size)] if torn else []) + transport_issues(path, problems)
        n = good = bad = 0
        for pid in sink.pids():
            body, offsets, times = sink.stream(pid)
            note = arrival_note(pid, by_arrival, n)
            parts = _segments(body, f"{path} [PID {pid}]", segment_bytes=segment_bytes, strict=strict, first_index=n,
                              marks=(offsets, times), container="mpegts", stream=f"PID {pid}")
            while True:
                try:
                    seg = next(parts)
                except StopIteration as done:
                    n, g, b = done.value
                    good, bad = good + g, bad + b
                    break
                seg.path = path
                seg.issues, issues = [*issues, *seg.issues], []
                if note is not None:
                    seg.notes, note = [note, *seg.notes], None
                yield seg
            del offsets, times
    check_found(path, good, bad)


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
