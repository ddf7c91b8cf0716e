"""A transport stream's KLV as each PID's bytes with their PES times: read whole (the reader), or
a chunk at a time into files set aside (the archive's streaming reader, :mod:`.segments`).

Both read the same way: the vectorised :class:`.demux.CleanTransport` over the chunks while the
stream stays clean; where it is not, :class:`.demux.KLVDemux` from the stream's start (damage and
all, every damage reported), as the whole reading does. What is kept per KLV PID: its PES payloads
joined (synchronous metadata's access-unit cells unwrapped) and a mark per PES: (byte offset in
them, PTS seconds or None). A transport stream sends its PIDs' packets interleaved, and the reader
numbers them PID after PID; so a reader a chunk at a time sets each PID's bytes aside
(:class:`SpooledPayloads`: temporary files, in ``TMPDIR``) and decodes them after, PID by PID.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable, Iterable

import numpy as np

MARK = np.dtype([("o", "<i8"), ("t", "<f8")])  # a PES's mark set aside: byte offset, PTS s (NaN: none)
Chunks = Callable[[], Iterable[tuple[bytes, bool]]]  # the stream's bytes from its start: (bytes, the last)


class MemoryPayloads:
    """Each PID's payloads and marks in memory (the whole reading)."""

    def __init__(self) -> None:
        self.parts: dict[int, list[bytes]] = {}
        self.marks: dict[int, list[tuple[int, float | None]]] = {}
        self.size: dict[int, int] = {}

    def add(self, pid: int, body: bytes, marks: list[tuple[int, float | None]]) -> None:
        """``body`` after the PID's bytes so far, with its ``marks`` (offsets in ``body``)."""
        at = self.size.get(pid, 0)
        self.parts.setdefault(pid, []).append(body)
        self.marks.setdefault(pid, []).extend([(o + at, t) for o, t in marks] if at else marks)
        self.size[pid] = at + len(body)

    def pids(self) -> list[int]:
        return sorted(self.parts)

    def payload(self, pid: int) -> bytes:
        parts = self.parts[pid]
        return parts[0] if len(parts) == 1 else b"".join(parts)

    def close(self) -> None:
        self.parts, self.marks, self.size = {}, {}, {}


class SpooledPayloads:
    """Each PID's payloads in a temporary file and its marks in another (offset int64, PTS
    float64 with NaN for none): memory bounded whatever the stream's length. A context manager:
    the files go at :meth:`close`."""

    def __init__(self) -> None:
        self.bodies: dict[int, object] = {}
        self.mark_files: dict[int, object] = {}
        self.size: dict[int, int] = {}

    def add(self, pid: int, body: bytes, marks: list[tuple[int, float | None]]) -> None:
        if pid not in self.bodies:
            self.bodies[pid] = tempfile.TemporaryFile(prefix=f"eoloc-pid{pid}-")
            self.mark_files[pid] = tempfile.TemporaryFile(prefix=f"eoloc-pid{pid}-marks-")
        at = self.size.get(pid, 0)
        self.bodies[pid].write(body)
        np.array([(o + at, math.nan if t is None else t) for o, t in marks], MARK).tofile(self.mark_files[pid])
        self.size[pid] = at + len(body)

    def pids(self) -> list[int]:
        return sorted(self.bodies)

    def stream(self, pid: int):
        """The PID's bytes (a file, at its start) and its marks' offsets and PTS (arrays read from
        their file as needed)."""
        body, marks = self.bodies[pid], self.mark_files[pid]
        body.flush()
        body.seek(0)
        marks.flush()
        n = marks.seek(0, 2) // 16
        if not n:
            return body, np.zeros(0, np.int64), np.zeros(0)
        rec = np.memmap(marks, dtype=MARK, mode="r", shape=(n,))
        return body, rec["o"], rec["t"]

    def close(self) -> None:
        for f in [*self.bodies.values(), *self.mark_files.values()]:
            f.close()
        self.bodies, self.mark_files, self.size = {}, {}, {}

    def __enter__(self) -> SpooledPayloads:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def transport_payloads(chunks: Chunks, make_sink: Callable[[], MemoryPayloads | SpooledPayloads], *,
                       fast: bool = True) -> tuple[list[tuple[int, str]], MemoryPayloads | SpooledPayloads,
                                                   dict[int, int]]:
    """Every KLV PID's payloads and PES marks put in a sink made by ``make_sink``, read from the
    stream ``chunks()`` gives (whole 188-byte packets in every chunk but the last for the
    vectorised path; any bytes for the other); the problems met (byte offset in the stream,
    message: transport damage first, then metadata access units that cannot be read); per PID
    the PES timed by arrival. ``fast=False``: :class:`.demux.KLVDemux` only."""
    from .demux import CleanTransport

    if fast:
        sink, clean = make_sink(), CleanTransport()
        for data, final in chunks():
            out = clean.feed(data, final=final)
            if out is None:
                break
            for pid, (body, marks) in out.items():
                sink.add(pid, body, marks)
        else:
            if clean.whole:
                return [], sink, clean.by_arrival
        sink.close()
    return _demuxed(chunks, make_sink())


def _demuxed(chunks: Chunks, sink) -> tuple[list[tuple[int, str]], object, dict[int, int]]:
    """:func:`transport_payloads` by :class:`.demux.KLVDemux`, packet by packet."""
    from stanag4609.transport.demux import PESStreamEvent, StreamKind
    from stanag4609.transport.metadata import parse_metadata_au_cells

    from ...errors import one_line
    from .demux import PTS_HZ, KLVDemux

    demux = KLVDemux(arrival=True)
    damaged: list[tuple[int, str]] = []
    unread: list[tuple[int, str]] = []
    by_arrival: dict[int, int] = {}
    for data, final in chunks():
        events, damage = demux.feed_stream(data, final=final)
        damaged += [(d.offset, f"MPEG-TS: {d.message}") for d in damage]
        got: dict[int, list] = {}  # the chunk's PES per PID (payloads, marks, bytes): handed to the sink at once
        for ev in events:
            if not isinstance(ev, PESStreamEvent):
                continue
            video = demux.arrival_pts.pop(ev.pes.offset, None)  # (its arrival time: kept no longer)
            if ev.kind is not StreamKind.KLV:
                continue
            payload = ev.pes.payload
            if ev.stream.stream_type == 0x15:  # synchronous metadata: access-unit cells wrap the KLV
                try:
                    payload = b"".join(cell.data for cell in parse_metadata_au_cells(payload))
                except Exception as exc:
                    unread.append((int(ev.pes.offset or 0),
                                   f"PID {ev.pid}: metadata access unit cannot be read: {one_line(exc)}"))
                    continue
            t = ev.pes.pts_seconds
            if t is None and video is not None:
                t = video / PTS_HZ
                by_arrival[ev.pid] = by_arrival.get(ev.pid, 0) + 1
            pes = got.setdefault(ev.pid, [[], [], 0])
            pes[0].append(payload)
            pes[1].append((pes[2], t))
            pes[2] += len(payload)
        for pid, (parts, marks, _) in got.items():
            sink.add(pid, b"".join(parts), marks)
    return damaged + unread, sink, by_arrival
