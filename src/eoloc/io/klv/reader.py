"""MISB KLV in: ST 0601 (and the older EG 0104) packets from raw KLV files or MPEG-TS, one stream
per KLV PID, every decodable value kept.

What is ours and what is not:

- **MPEG-TS demultiplexing** is stanag4609's transport layer (README: why it), made to survive damage
  (:class:`.demux.KLVDemux`); a clean stream is read in vectorised passes to the same result
  (:func:`.demux.clean_klv_payloads`).
- **Framing** is ours: the bytes are scanned for the ST 0601 and EG 0104 keys, every packet is
  decoded on its own, and after a corrupt or truncated packet the scan resumes at the next key
  *inside* the bad bytes, so a truncated packet never swallows the good packet that follows it.
  A packet is refused only for its framing (a length that runs past the data) or its ST 0601
  checksum; every bad packet and every skipped run of bytes is reported with its byte offset.
- **Item decoding** is ours and tolerant (:mod:`.localset`, :mod:`.st0601`, :mod:`.st0903`):
  duplicated tags, long-form lengths, items out of order, ST 1607 sets that break its rules, VMTI
  sets missing mandatory items — decoded, and each departure counted per stream and tag with the
  first packet it was seen in. ``strict=True`` has stanag4609 enforce the standard instead: a
  packet it refuses is dropped and named.
- **Streams**: each KLV PID of a transport stream is its own stream (``"PID 497"``); a raw KLV
  file is one stream (``""``). :mod:`.tables` keeps report-on-change state per stream.
"""

from __future__ import annotations

import itertools
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import KLVError, one_line
from .eg0104 import EG0104_KEY, decode_eg0104
from .localset import Note, SetError, ber_length, parse_items
from .st0601 import decode_values

UAS_KEY = bytes.fromhex("060E2B34020B01010E01030101000000")
VMTI_KEY = bytes.fromhex("060E2B34020B01010E01030306000000")  # a stand-alone ST 0903 VMTI local set
TS_PACKET = 188
KEY_HEAD, KEY_TAIL = UAS_KEY[:5], UAS_KEY[5:]  # 06 0E 2B 34 02 | 0B 01 01 0E 01 03 01 01 00 00 00


def restore_key_heads(data: bytes) -> tuple[bytes, int]:
    """The bytes with the first 5 bytes of the ST 0601 key (06 0E 2B 34 02) put back before every
    occurrence of its last 11 that lacks them (streams cut that way: sitrec's day/night samples),
    and how many were put back (0: the bytes unchanged)."""
    if data.count(KEY_TAIL) == data.count(UAS_KEY):  # (neither overlaps itself: every tail has its head)
        return data, 0
    at, pos = [], data.find(KEY_TAIL)
    while pos >= 0:
        if data[max(pos - 5, 0):pos] != KEY_HEAD:
            at.append(pos)
        pos = data.find(KEY_TAIL, pos + 1)
    if not at:
        return data, 0
    parts, prev = [], 0
    for a in at:
        parts += [data[prev:a], KEY_HEAD]
        prev = a
    parts.append(data[prev:])
    return b"".join(parts), len(at)


@dataclass(frozen=True)
class KLVIssue:
    """A packet (or run of bytes) that could not be used, with its place in the file."""

    path: str
    packet: int | None  # packet number in the file (good and bad counted), None for skipped bytes
    offset: int  # byte offset in the file (raw KLV) or in the PID's KLV stream (MPEG-TS)
    kind: str  # "checksum" | "truncated" | "malformed" | "non-standard" | "skipped bytes"
    message: str

    def __str__(self) -> str:
        where = f"packet {self.packet} at byte {self.offset}" if self.packet is not None else f"byte {self.offset}"
        return f"{self.path}: {where}: {self.kind}: {self.message}"


@dataclass(frozen=True)
class KLVPacket:
    """One good packet: its number in the file, byte offset, transport PTS (s, MPEG-TS only), raw
    bytes, decoded values (ST 0601 tag -> value), stream and standard."""

    index: int
    offset: int
    pts_s: float | None
    raw: bytes
    fields: dict[int, Any]
    stream: str = ""
    standard: str = "ST 0601"


@dataclass(frozen=True)
class StreamNote:
    """A departure from the standard, counted over a stream: kind, item tag, the first message,
    how many packets showed it and the first of them."""

    stream: str
    kind: str
    tag: str
    message: str
    count: int
    first_packet: int

    def __str__(self) -> str:
        where = f"{self.stream}: " if self.stream else ""
        return (f"{where}tag {self.tag}: {self.kind}: {self.message} ({self.count} packet(s), first packet "
                f"{self.first_packet})")


@dataclass
class KLVStream:
    """Everything read from one file: the good packets (of every stream), the bad ones, and the
    departures from the standard counted per stream and tag."""

    path: str
    container: str  # "klv" or "mpegts"
    packets: list[KLVPacket]
    issues: list[KLVIssue] = field(default_factory=list)
    notes: list[StreamNote] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.packets)

    @property
    def first_packet(self) -> int:
        return self.packets[0].index

    @property
    def n_good(self) -> int:
        return len(self.packets)

    @property
    def n_bad(self) -> int:
        return sum(1 for i in self.issues if i.packet is not None)

    @property
    def streams(self) -> list[str]:
        """Stream names in order of first packet."""
        return list(dict.fromkeys(p.stream for p in self.packets))

    def counts(self) -> dict[str, int]:
        """How many packets or byte runs of each problem kind, plus the good packets."""
        c = Counter(i.kind for i in self.issues)
        return {"good": self.n_good, **c}

    def summary(self) -> str:
        bad = ", ".join(f"{n} {k}" for k, n in self.counts().items() if k != "good") or "none bad"
        kinds = Counter(p.standard for p in self.packets)
        what = (f"{self.n_good} good {next(iter(kinds), 'ST 0601')} packet{'s' if self.n_good != 1 else ''}"
                if len(kinds) < 2 else
                f"{self.n_good} good packets ({', '.join(f'{n} {k}' for k, n in kinds.items())})")
        return f"{self.path} ({self.container}): {what}; {bad}"


# -- reading ------------------------------------------------------------------------------------


def read_klv(path: str | Path, *, strict: bool = False) -> KLVStream:
    """Read every ST 0601 / EG 0104 packet of a raw KLV file (.klv/.bin) or an MPEG-TS file.

    The container is recognised from the content (0x47 sync bytes every 188 bytes), not the name.
    Raises :class:`KLVError` only when nothing can be read; bad packets are reported in
    ``issues``, departures from the standard in ``notes``, and every good packet kept.
    """
    return read_klv_file(path, strict=strict, from_ts=read_ts_bytes, from_klv=decode_klv_bytes)


def read_klv_file(path: str | Path, *, strict: bool, from_ts, from_klv):
    """A KLV file read by ``from_ts`` (an MPEG-TS, told by its content) or ``from_klv`` (raw KLV),
    readers of (bytes, path, strict=) giving objects or columns; :class:`KLVError` when the file
    cannot be read or holds no packet, good or bad."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise KLVError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not data:
        raise KLVError(f"{path} is empty")
    result = (from_ts if looks_like_ts(data) else from_klv)(data, str(path), strict=strict)
    check_found(path, len(result), result.n_bad)
    return result


def check_found(path, good: int, bad: int) -> None:
    """:class:`KLVError` for a file in which no packet, good or bad, was found."""
    if not good and not bad:
        raise KLVError(f"{path}: no MISB ST 0601 packet found (key {UAS_KEY.hex(' ')}), nor an EG 0104 one; is this "
                       "a KLV stream or an MPEG-TS file with a KLV data stream?")


class _Notes:
    """Departures counted per (stream, kind, tag), with the first message and packet."""

    def __init__(self) -> None:
        self.seen: dict[tuple[str, str, str], list] = {}

    def add(self, stream: str, packet: int, notes: list[Note]) -> None:
        for n in notes:
            rec = self.seen.setdefault((stream, n.kind, n.tag), [n.message, 0, packet])
            rec[1] += 1

    def result(self) -> list[StreamNote]:
        return [StreamNote(s, k, t, m, c, f) for (s, k, t), (m, c, f) in self.seen.items()]


def bcc16(data: bytes) -> int:
    """ST 0601 bcc-16: the bytes as big-endian 16-bit words, summed modulo 2^16."""
    return ((sum(data[0::2]) << 8) + sum(data[1::2])) & 0xFFFF


def checksum_problem(raw: bytes) -> str | None:
    """Why an ST 0601 packet fails its checksum (the item 01 02 hi lo ending the packet, over every
    byte before its value), or None."""
    if len(raw) < 20 or raw[-4:-2] != b"\x01\x02":
        return "no checksum item (tag 1, 2 bytes) at the end of the packet"
    expected, total = int.from_bytes(raw[-2:], "big"), bcc16(raw[:-2])
    if total != expected:
        return f"ST 0601 checksum mismatch: expected 0x{expected:04X}, computed 0x{total:04X}"
    return None


def decode_packet(raw: bytes, value_start: int) -> tuple[str, dict[int, Any], list[Note]]:
    """(standard, tag -> value, notes) of one framed packet whose checksum (ST 0601) was checked."""
    if raw[:16] == EG0104_KEY:
        values, notes = decode_eg0104(raw[value_start:])
        return "EG 0104", values, notes
    if raw[:16] == VMTI_KEY:  # its targets under tag 74, as when it rides in an ST 0601 packet
        from .st0903 import decode_vmti

        vset, notes = decode_vmti(raw[value_start:], prefix="74.")
        return "ST 0903", {74: vset}, notes
    items, notes = parse_items(raw, value_start, len(raw) - 4)
    if items and items[0][0] != 2 and any(t == 2 for t, _ in items):
        notes.append(Note("out of order", "2", "Precision Time Stamp is not the first item (read anyway)"))
    values, more = decode_values(items)
    return "ST 0601", values, notes + more


def _strict_check(raw: bytes) -> str | None:
    """Why stanag4609 refuses the packet under the standard's rules, or None."""
    from stanag4609.st0601 import decode_uas_local_set

    if raw[:16] == EG0104_KEY:
        return "EG 0104 is not ST 0601 (obsolete; read only without --strict)"
    if raw[:16] == VMTI_KEY:
        return None  # a stand-alone ST 0903 set: its own standard, checked by its checksum
    try:
        decode_uas_local_set(raw)
    except Exception as exc:  # stanag4609's verdict, whatever its exception type
        return one_line(exc)
    return None


class PacketKeys:
    """Next position of either packet key at or after a position (each key searched once per hit)."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.next = {UAS_KEY: data.find(UAS_KEY), EG0104_KEY: data.find(EG0104_KEY), VMTI_KEY: data.find(VMTI_KEY)}

    def find(self, pos: int) -> int:
        for key, at in self.next.items():
            if 0 <= at < pos:
                self.next[key] = self.data.find(key, pos)
        hits = [a for a in self.next.values() if a >= 0]
        return min(hits) if hits else -1


def decode_klv_bytes(data: bytes, path: str = "<bytes>", *, pts: list[tuple[int, float | None]] | None = None,
                     container: str = "klv", stream: str = "", first_index: int = 0,
                     strict: bool = False) -> KLVStream:
    """Frame and decode a byte string of concatenated KLV packets (see the module notes).

    pts: optional (byte offset, PTS seconds) marks: a packet takes the PTS of the last mark at or
    before its key. first_index: the number of the first packet (streams of one file count on).
    Packets whose key lost its first 5 bytes are recovered when that gives more good packets (each
    must still pass its checksum), and a note says so.
    """
    return with_repaired_keys(data, pts, stream, first_index, lambda d, marks: _decode_klv_bytes(
        d, path, pts=marks, container=container, stream=stream, first_index=first_index, strict=strict))


def with_repaired_keys(data: bytes, pts, stream: str, first_index: int, decode):
    """``decode(data, pts)``, or ``decode`` of the bytes with the ST 0601 keys' lost heads put back
    (:func:`restore_key_heads`) where that gives more good packets, with a note saying so (the
    reader's rule for either kind of result: objects or columns)."""
    result = decode(data, pts)
    repaired, count = restore_key_heads(data)
    if count and pts is None:  # (a transport stream's PTS marks are byte offsets of the unrepaired bytes)
        again = decode(repaired, None)
        if len(again) > len(result):
            note = StreamNote(stream, "damaged key", "key", f"{count} packet key(s) lacked their first 5 bytes "
                              f"({KEY_HEAD.hex(' ')}): put back, and {len(again) - len(result)} more packet(s) "
                              "then pass their checksum; byte offsets are those of the repaired stream",
                              count, again.first_packet if len(again) else first_index)
            again.notes.insert(0, note)
            return again
    return result


def _decode_klv_bytes(data: bytes, path: str = "<bytes>", *, pts: list[tuple[int, float | None]] | None = None,
                      container: str = "klv", stream: str = "", first_index: int = 0,
                      strict: bool = False) -> KLVStream:
    framer = Framer(data, path, stream=stream, first_index=first_index, strict=strict, pts=pts)
    while framer.pos < len(data):
        framer.step()
    return KLVStream(path, container, framer.packets, framer.issues, framer.notes.result())


def packet_pts(offsets, pts: list[tuple[int, float | None]], marks: np.ndarray | None = None
               ) -> list[float | None]:
    """Each packet's PTS: that of the last (byte offset, PTS) mark at or before its key (``marks``:
    the marks' offsets as an array, where the caller keeps them)."""
    marks = np.array([m[0] for m in pts], dtype=np.int64) if marks is None else marks
    at = np.maximum(np.searchsorted(marks, np.asarray(offsets, dtype=np.int64), side="right") - 1, 0)
    return [pts[j][1] for j in at.tolist()]


class Framer:
    """The tolerant reader's framing, one step at a time (see the module notes): each
    :meth:`step` reads the next packet (or reports the bytes before it) from ``pos`` and keeps
    the good packet (with its PTS where ``pts`` marks are given), the issue and the notes. The
    columnar reader steps it over what its compiled scanner does not take."""

    def __init__(self, data: bytes, path: str, *, stream: str = "", first_index: int = 0,
                 strict: bool = False, pts: list[tuple[int, float | None]] | None = None) -> None:
        self.data, self.path, self.stream, self.strict, self.pts = data, path, stream, strict, pts
        self.marks = np.array([m[0] for m in pts], dtype=np.int64) if pts else None
        self.packets: list[KLVPacket] = []
        self.issues: list[KLVIssue] = []
        self.notes = _Notes()
        self.keys: PacketKeys | None = None  # (made on the first step: the columnar reader may need none)
        self.n = first_index  # the number of the next packet (good and bad counted)
        self.pos = 0
        self.after_bad = False  # bytes up to the next key after a bad packet belong to it: not reported twice

    def step(self) -> None:
        data, path, n, pos = self.data, self.path, self.n, self.pos
        size = len(data)
        if self.keys is None:
            self.keys = PacketKeys(data)
        k = self.keys.find(pos)
        if k < 0:
            if size - pos and not self.after_bad:
                self.issues.append(KLVIssue(path, None, pos, "skipped bytes", f"{size - pos} bytes after the last "
                                            "packet are not a KLV packet"))
            self.pos = size
            return
        if k > pos and not self.after_bad:
            self.issues.append(KLVIssue(path, None, pos, "skipped bytes",
                                        f"{k - pos} bytes before the next packet key are not a packet"))
        self.after_bad = True
        self.n += 1
        self.pos = k + 1  # after a bad packet: the next key may sit inside what its bad length claimed
        end, start, why = packet_end(data, k)
        if end is None:
            self.issues.append(KLVIssue(path, n, k, "truncated", why))
            return
        raw = data[k:end]
        vmti_sum = raw[:16] == VMTI_KEY and raw[-4:-2] == b"\x01\x02"  # ST 0903's checksum item is optional
        if (raw[:16] == UAS_KEY or vmti_sum) and (why := checksum_problem(raw)) is not None:
            self.issues.append(KLVIssue(path, n, k, "checksum", why))
            return
        standard, values, pnotes = decode_packet(raw, start - k)
        self.pos = end
        if self.strict and (why := _strict_check(raw)) is not None:
            self.issues.append(KLVIssue(path, n, k, "non-standard", why))
            self.after_bad = False
            return
        self.notes.add(self.stream, n, pnotes)
        pts_s = packet_pts([k], self.pts, self.marks)[0] if self.pts else None
        self.packets.append(KLVPacket(n, k, pts_s, raw, values, self.stream, standard))
        self.after_bad = False


def split_klv(data: bytes, path: str = "<bytes>") -> list[tuple[bytes, float]]:
    """Raw KLV bytes cut into packets as sent (bad ones and stray bytes too, each with the packet
    it precedes), with each packet's ST 0601 time stamp (UNIX s; NaN without one)."""
    import math

    stream = decode_klv_bytes(data, path)
    starts = sorted({p.offset for p in stream.packets} | {i.offset for i in stream.issues if i.offset is not None})
    times = {p.offset: p.fields.get(2) for p in stream.packets}
    bounds = [*starts, len(data)]
    return [(data[a:b], times[a].timestamp() if hasattr(times.get(a), "timestamp") else math.nan)
            for a, b in itertools.pairwise(bounds)]


def packet_end(data: bytes, k: int) -> tuple[int | None, int, str]:
    """(end offset, value start, "") of the packet whose key starts at ``k``, or (None, 0, why)."""
    try:
        length, start, _ = ber_length(data, k + 16, len(data))
    except SetError as exc:
        return None, 0, f"{exc} (the packet's own length)"
    if start + length > len(data):
        # (not how many bytes remain: a segment of the file (io.klv.segments) holds fewer than the
        # file does, and its reading must say what the whole file's says)
        return None, 0, (f"the packet declares {length} bytes of value, more than the stream holds after it "
                         "(cut short, or a corrupt length)")
    return start + length, start, ""


def looks_like_ts(data: bytes) -> bool:
    n = min(len(data) // TS_PACKET, 5)
    return n >= 2 and all(data[i * TS_PACKET] == 0x47 for i in range(n))


def read_ts_bytes(data: bytes, path: str, *, strict: bool = False) -> KLVStream:
    """KLV packets from every KLV elementary stream (PID) of an MPEG-TS file, with their PTS; each
    PID is its own stream ("PID n"); see :func:`ts_klv_parts`."""
    issues, parts = ts_klv_parts(data, path, strict=strict, decode=decode_klv_bytes)
    packets: list[KLVPacket] = []
    notes: list[StreamNote] = []
    for s, arrival in parts:
        packets += s.packets
        issues += s.issues
        notes += [arrival, *s.notes] if arrival else s.notes
    return KLVStream(path, "mpegts", packets, issues, notes)


def ts_klv_parts(data: bytes, path: str, *, strict: bool, decode, fast: bool = True
                 ) -> tuple[list[KLVIssue], list[tuple[Any, Any]]]:
    """The transport's issues, and each KLV PID's bytes decoded by ``decode`` (a reader of
    :func:`decode_klv_bytes`'s signature: objects or columns) with the note on its timing by
    arrival (or None), in PID order.

    Asynchronous carriage (stream_type 0x06, 'KLVA') and synchronous carriage (0x15, metadata
    access units) both end up as one byte stream per PID, framed like a raw KLV file. A packet's
    time is its PES's PTS; asynchronous KLV sent as ST 1402 says (stream_id 0xBD, no PTS) is timed
    by where it arrives: the PTS of the video PES begun before it (said in a note). Transport
    errors (lost sync, a damaged packet, a PES packet that does not add up) cost the packets they
    touch, and are reported with their byte offsets in the file (:class:`.demux.KLVDemux`).
    """
    from .transport import MemoryPayloads, transport_payloads

    issues: list[KLVIssue] = []
    torn = len(data) % TS_PACKET
    if torn:  # a recording cut off mid-packet: the whole packets before it are kept
        issues.append(torn_issue(path, len(data)))
        data = data[:len(data) - torn]
    problems, sink, by_arrival = transport_payloads(lambda: [(data, True)], MemoryPayloads, fast=fast)
    issues += transport_issues(path, problems)
    if not sink.pids():
        raise KLVError(no_klv_stream(path))
    parts = []
    n = 0
    for pid in sink.pids():
        s = decode(sink.payload(pid), f"{path} [PID {pid}]", pts=sink.marks[pid], container="mpegts",
                   stream=f"PID {pid}", first_index=n, strict=strict)
        arrival = arrival_note(pid, by_arrival, n)
        n += len(s) + s.n_bad
        parts.append((s, arrival))
    return issues, parts


def transport_issues(path: str, problems: list[tuple[int, str]]) -> list[KLVIssue]:
    """The transport's problems (:func:`.transport.transport_payloads`) as issues of the file."""
    return [KLVIssue(path, None, offset, "malformed", message) for offset, message in problems]


def no_klv_stream(path: str) -> str:
    return f"{path}: MPEG-TS with no KLV metadata stream (no PID with stream_type 0x06 'KLVA' or 0x15)"


def arrival_note(pid: int, by_arrival: dict[int, int], first_packet: int) -> StreamNote | None:
    """The note on a PID's PES timed by arrival (None: none was)."""
    if not by_arrival.get(pid):
        return None
    return StreamNote(f"PID {pid}", "timed by arrival", "PES", f"{by_arrival[pid]} PES packet(s) in asynchronous "
                      "carriage without PTS (ST 1402): each timed by the video frame before it in the stream",
                      by_arrival[pid], first_packet)


def torn_issue(path: str, size: int) -> KLVIssue:
    """The issue of a transport stream of ``size`` bytes that ends mid-packet."""
    torn = size % TS_PACKET
    return KLVIssue(path, None, size - torn, "skipped bytes",
                    f"the last {torn} bytes are a transport packet cut short (the file ends mid-packet)")
