"""MPEG-TS in, KLV out: the transport demultiplexed the way a receiver on a damaged link needs it.

stanag4609 does the reading: transport packets (``parse_transport_packet``, or its
``TransportStreamParser`` for a file, which re-synchronises past garbage), the program tables (its
``TransportDemuxer``, fed only the PAT and PMT packets), which PIDs carry KLV
(``find_klv_streams``), and each PID's PES packets (its ``PESAssembler``). What is done here is the
damage: stanag4609's demultiplexer keeps a PES assembler that a damaged transport packet has
confused (a PES length the packets do not match), and that assembler then refuses every later
packet of its PID, so one bad cell lost the rest of the stream (live) or the whole file. Here an
assembler that fails is replaced by a new one, which starts again at the PID's next packet start;
the table reader is reset the same way; every failure is returned with its byte offset. Only the
PIDs the tables name as metadata (stream types 0x06 and 0x15) are assembled: video and audio
packets cost a lookup each, as do those on PIDs no table names.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

METADATA_STREAM_TYPES = (0x06, 0x15)  # asynchronous (private data, "KLVA") and synchronous metadata (ST 1402)
# MPEG-1/2 video, MPEG-4 part 2, AVC (with SVC, MVC), HEVC, AVS
VIDEO_STREAM_TYPES = frozenset({0x01, 0x02, 0x10, 0x1B, 0x20, 0x21, 0x24, 0x42})
TS_PACKET = 188
PTS_HZ = 90_000  # the MPEG system clock's PTS ticks per second
MAX_PES_BYTES = 4 * 1024 * 1024  # a KLV PES is kilobytes: a PID that never ends one costs at most this


@dataclass(frozen=True)
class Damage:
    """A transport packet, table or PES packet that could not be read: where (byte offset in the
    stream; for live, of the datagram's cells as fed) and why."""

    offset: int
    pid: int | None
    message: str


class KLVDemux:
    """Feed transport packets (:meth:`feed_cells` for whole 188-byte cells, as datagrams bring them;
    :meth:`feed_stream` for a file's bytes); each call returns stanag4609's events (PAT, PMT, and a
    ``PESStreamEvent`` per complete PES packet on a metadata PID) and the :class:`Damage` met."""

    def __init__(self, *, max_pes_bytes: int = MAX_PES_BYTES, arrival: bool = False) -> None:
        from stanag4609.transport.demux import TransportDemuxer
        from stanag4609.transport.mpegts import TransportStreamParser

        self.max_pes_bytes = max_pes_bytes
        self.tables = TransportDemuxer(max_pes_length=max_pes_bytes)
        self.parser = TransportStreamParser(recover=True)
        self.pmt_pids: set[int] = set()
        self.programs: dict[int, object] = {}  # program number -> its PMT (stanag4609's ProgramMapTable)
        self.streams: dict[int, tuple] = {}  # metadata PID -> (program number, stream info, kind, KLV carriage)
        self.assemblers: dict[int, object] = {}
        self.video_pids: set[int] = set()  # what the tables name as video
        self.video_types: dict[int, int] = {}  # video PID -> its stream type, as the tables name them
        # arrival: each metadata PES's place in the stream, as the PTS of the video PES begun before
        # it (:attr:`arrival_pts`, by the PES's byte offset), for asynchronous KLV sent without PTS
        self.arrival = arrival
        self.video_pts: int | None = None
        self.arrival_pts: dict[int, int | None] = {}

    def feed_cells(self, data: bytes, offset: int = 0) -> tuple[list, list[Damage]]:
        """Whole transport packets, each read on its own (a bad one costs itself only)."""
        from stanag4609.transport.mpegts import parse_transport_packet

        from ...errors import one_line

        events: list = []
        damage: list[Damage] = []
        for k in range(0, len(data) - TS_PACKET + 1, TS_PACKET):
            cell = data[k:k + TS_PACKET]
            pid = (cell[1] & 0x1F) << 8 | cell[2]
            if pid != 0 and pid not in self.pmt_pids and pid not in self.streams:
                continue  # video, audio, or nothing a table names: not parsed at all
            try:
                packet = parse_transport_packet(cell, offset=offset + k)
            except Exception as exc:  # stanag4609's verdict on a damaged cell
                damage.append(Damage(offset + k, pid, f"transport packet: {one_line(exc)}"))
                continue
            self._packet(packet, events, damage)
        return events, damage

    def feed_stream(self, data: bytes, *, final: bool = True) -> tuple[list, list[Damage]]:
        """A stream's bytes (any chunking; garbage between packets is skipped); ``final``: the end
        of the stream, so that the PES packets still open are completed."""
        events: list = []
        damage: list[Damage] = []
        self.feed_packets(self.parser.feed(data), events, damage)
        if final:
            self.finish(events, damage)
        return events, damage

    def feed_packets(self, packets: Iterable, events: list, damage: list[Damage]) -> None:
        for packet in packets:
            pid = packet.pid
            if pid == 0 or pid in self.pmt_pids or pid in self.streams:
                if self.arrival and packet.payload_unit_start and pid in self.streams:
                    self.arrival_pts[packet.offset] = self.video_pts
                self._packet(packet, events, damage)
            elif self.arrival and packet.payload_unit_start and pid in self.video_pids:
                self.video_pts = pes_start_pts(packet.payload)

    def finish(self, events: list, damage: list[Damage]) -> None:
        """Complete the PES packets still open (a stream that ends)."""
        from stanag4609.transport.demux import PESStreamEvent

        from ...errors import one_line

        for pid, assembler in self.assemblers.items():
            try:
                events += [PESStreamEvent(*self.streams[pid], pes) for pes in assembler.finish()]
            except Exception as exc:
                damage.append(Damage(self.parser.stream_offset, pid, f"PID {pid}: the last PES packet: "
                                                                     f"{one_line(exc)}"))

    def _packet(self, packet, events: list, damage: list[Damage]) -> None:
        from stanag4609.transport.demux import PATEvent, PESStreamEvent, PMTEvent

        from ...errors import one_line

        pid = packet.pid
        if pid == 0 or pid in self.pmt_pids:
            try:
                found = self.tables.feed(packet.raw)
            except Exception as exc:  # a damaged table: read the next one afresh
                damage.append(Damage(packet.offset, pid, f"program table on PID {pid}: {one_line(exc)}"))
                self.tables.reset()
                return
            for ev in found:
                if isinstance(ev, PATEvent):
                    self.pmt_pids = {p.program_map_pid for p in ev.programs}
                elif isinstance(ev, PMTEvent) and ev.table.current_next_indicator:
                    self._program(ev.table)
                events.append(ev)
            return
        if packet.transport_error_indicator:
            damage.append(Damage(packet.offset, pid, f"transport packet on PID {pid} has its error flag set"))
            self._restart(pid)
            return
        try:
            done = self.assemblers[pid].feed(packet)
        except Exception as exc:  # this PID's PES cannot be put together: start again at this packet
            damage.append(Damage(packet.offset, pid, f"PID {pid}: {one_line(exc)}; its PES packet dropped"))
            self._restart(pid)
            try:
                done = self.assemblers[pid].feed(packet) if packet.payload_unit_start else []
            except Exception:
                self._restart(pid)
                return
        events += [PESStreamEvent(*self.streams[pid], pes) for pes in done]

    def _restart(self, pid: int) -> None:
        from stanag4609.transport.pes import PESAssembler

        self.assemblers[pid] = PESAssembler(pid=pid, max_pes_length=self.max_pes_bytes)

    def _program(self, pmt) -> None:
        """The metadata PIDs of a program, as its PMT now says (a PMT repeated as it was changes
        nothing: the PES packets being put together go on)."""
        from stanag4609.transport.demux import StreamKind
        from stanag4609.transport.psi import find_klv_streams

        old = self.programs.get(pmt.program_number)
        if old is not None and old.raw == pmt.raw:
            return
        klv = dict(find_klv_streams(pmt))
        now = {s.elementary_pid: (pmt.program_number, s, StreamKind.KLV if s.elementary_pid in klv else StreamKind.DATA,
                                  klv.get(s.elementary_pid))
               for s in pmt.streams if s.stream_type in METADATA_STREAM_TYPES or s.elementary_pid in klv}
        self.video_types |= {s.elementary_pid: s.stream_type for s in pmt.streams
                             if s.stream_type in VIDEO_STREAM_TYPES}
        self.video_pids |= set(self.video_types)
        for pid in [p for p, s in self.streams.items() if s[0] == pmt.program_number and p not in now]:
            del self.streams[pid]
            self.assemblers.pop(pid, None)
        for pid, stream in now.items():
            if self.streams.get(pid) != stream:
                self.streams[pid] = stream
                self._restart(pid)
        self.programs[pmt.program_number] = pmt


def pes_start_pts(payload: bytes) -> int | None:
    """The PTS (90 kHz ticks) in the PES header at the start of ``payload`` (the payload of a
    transport packet that begins a PES packet), or None: no PTS, or a header too damaged to say."""
    from stanag4609.transport.pes import decode_timestamp

    if len(payload) < 14 or payload[:3] != b"\x00\x00\x01" or payload[6] & 0xC0 != 0x80 or not payload[7] & 0x80:
        return None
    try:
        return decode_timestamp(payload[9:14], expected_prefix=payload[7] >> 6)
    except ValueError:  # stanag4609's DecodeError: a marker bit or prefix wrong
        return None


def cell_pes_pts(cell: bytes) -> int | None:
    """:func:`pes_start_pts` of a whole 188-byte transport packet (its adaptation field skipped)."""
    control = cell[3] >> 4 & 0x3
    start = 4 + (1 + cell[4] if control == 0x3 else 0)
    return pes_start_pts(cell[start:]) if control & 0x1 and start < TS_PACKET else None


SPECIAL_STREAM_IDS = frozenset({0xBC, 0xBE, 0xBF, 0xF0, 0xF1, 0xF2, 0xF8, 0xFF})  # PES without the optional header


def clean_klv_payloads(data: bytes, *, max_pes_bytes: int = MAX_PES_BYTES
                       ) -> tuple[dict[int, tuple[bytes, list]], dict[int, int]] | None:
    """Each asynchronous KLV PID's PES payloads joined, with (byte offset in them, PTS seconds) per
    PES, and per PID the PES timed by arrival, read from a whole transport stream in vectorised
    passes (:class:`CleanTransport` given it in one piece); or None where the stream is not clean
    enough for that (:class:`KLVDemux` then reads it, damage and all)."""
    clean = CleanTransport(max_pes_bytes=max_pes_bytes)
    out = clean.feed(data, final=True)
    return (out, clean.by_arrival) if out else None


@dataclass
class TableCarry:
    """What :class:`TableRepeats` carries from one chunk of a stream to the next, by PID: the
    last packet handed on or left out (its index in the stream), the repeats left out, and the
    last candidate packet (index, its 188 bytes)."""

    last: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    before: dict = field(default_factory=dict)


class CleanTransport:
    """A clean transport stream's KLV read in vectorised passes, a chunk at a time: each
    :meth:`feed` takes whole 188-byte packets (any number) and returns each asynchronous KLV PID's
    PES payloads completed in them, joined, with (byte offset in them, PTS seconds) per PES; or
    None where the stream is not clean enough for that (then :class:`KLVDemux` is to read the
    stream from its start, damage and all). :attr:`by_arrival` counts per PID the PES timed by
    arrival (no PTS: the PTS of the video PES begun before it, as :class:`KLVDemux` with
    ``arrival`` times them); :attr:`whole` the KLV PIDs that gave a whole PES.

    Clean: every 188-byte packet in sync and readable, the program tables read without damage and
    unchanged once metadata has begun, every metadata PES whole (its declared length met) with the
    standard header and a PTS or none (not a DTS), no transport error flag on a metadata packet, no
    synchronous (0x15) metadata. Then :class:`KLVDemux` would give exactly this and no damage (the
    same tables, read by the same code; ``tests/unit/io/klv/test_klv_columnar.py`` compares the
    two, whole and in chunks), at the cost of a few numpy passes instead of a Python object per
    transport packet. Across a chunk's end are carried: the program tables' reader (and the PATs'
    alone), their repeats (:class:`TableCarry`), the PES still open on each metadata PID (its
    packets, until the next PES begins or the stream ends: ``final``), the last video PES's PTS,
    whether metadata has begun, every PID the tables have named."""

    def __init__(self, *, max_pes_bytes: int = MAX_PES_BYTES) -> None:
        self.max_pes_bytes = max_pes_bytes
        self.demux = KLVDemux(max_pes_bytes=max_pes_bytes)  # the program tables, as they come
        self.pats = KLVDemux(max_pes_bytes=max_pes_bytes)  # the PATs alone: every PID one names as a PMT's
        self.tables, self.pat_tables = TableCarry(), TableCarry()
        self.named: set[int] = set()
        self.ever: set[int] = set()  # every PID a metadata stream's or a video one's at some time
        self.begun = False  # a metadata packet has come
        self.video_pts: int | None = None  # the PTS of the last video PES begun before the chunk
        self.open: dict[int, tuple] = {}  # PID -> its open PES: (cells, their indices, arrival of its start)
        self.k0 = 0  # the chunk's first packet's index in the stream
        self.by_arrival: dict[int, int] = {}
        self.whole: set[int] = set()

    def feed(self, data: bytes, *, final: bool = True) -> dict[int, tuple[bytes, list]] | None:
        import numpy as np
        from stanag4609.transport.demux import StreamKind
        from stanag4609.transport.mpegts import parse_transport_packet

        n = len(data) // TS_PACKET
        if len(data) % TS_PACKET:
            return None
        if not n and not final:
            return {}
        cells = np.frombuffer(data, np.uint8).reshape(n, TS_PACKET)
        control = (cells[:, 3] >> 4) & 0x3
        if (cells[:, 0] != 0x47).any() or (control == 0).any():
            return None
        alen = cells[:, 4].astype(np.int64)
        adapted = control >= 2
        if ((control == 2) & (alen != TS_PACKET - 5)).any() or (adapted & (alen > TS_PACKET - 5)).any():
            return None
        if not _adaptation_fields_read(data, cells, adapted & (alen > 0), alen):
            return None
        pid = ((cells[:, 1].astype(np.int64) & 0x1F) << 8) | cells[:, 2]
        starts = (cells[:, 1] & 0x40) != 0
        if not self._read_pats(data, cells, pid):
            return None
        demux = self.demux
        events: list = []
        damage: list[Damage] = []
        tables = TableRepeats(data, cells, pid, np.flatnonzero((pid == 0) | np.isin(pid, list(self.named))),
                              k0=self.k0, carry=self.tables)
        states = [(-1, dict(demux.streams), frozenset(demux.video_pids))]  # from the packet after k: the
        for k, p, prev, repeat in tables:  # the program tables, in order     metadata streams, the video PIDs
            if p == 0 or p in demux.pmt_pids:
                raw = tables.fed(k, p, prev, repeat)
                if raw is None:  # the table packet before it again: nothing the program tables say changes
                    continue
                demux._packet(parse_transport_packet(raw, offset=(self.k0 + k) * TS_PACKET), events, damage)
                if damage:
                    return None
                if demux.streams != states[-1][1] or demux.video_pids != states[-1][2]:
                    states.append((k, dict(demux.streams), frozenset(demux.video_pids)))
        for _, s, v in states:
            self.ever |= set(s) | v
        if self.ever & self.named:
            return None  # (a PID both a table's and a stream's: KLVDemux's packet-by-packet way)
        ends = [k for k, _, _ in states[1:]] + [n]
        for (k0, streams, _), k1, later in zip(states, ends, [*states[1:], None], strict=True):
            self.begun = self.begun or bool(streams and np.isin(pid[k0 + 1:k1], list(streams)).any())
            if self.begun and later is not None and later[1] != streams:
                return None  # the tables changed once metadata had begun
        k_last, streams, _ = states[-1]
        arrival = ArrivalTimes(data, pid, starts, states, ends, before=self.video_pts)
        out: dict[int, tuple[bytes, list]] = {}
        for p in streams:
            ks = k_last + 1 + np.flatnonzero(pid[k_last + 1:] == p)
            carried = self.open.pop(p, None)
            if not ks.size and carried is None:
                continue
            _, info, kind, _ = demux.streams[p]
            if info.stream_type == 0x15:
                return None
            c, g = cells[ks], self.k0 + ks
            if carried is not None:
                c, g = np.concatenate([carried[0], c]), np.concatenate([carried[1], g])

            def at(k: int, carried=carried) -> int | None:
                return carried[2] if k < self.k0 else arrival.get(k - self.k0)

            read = _clean_pes(c, g, self.max_pes_bytes, at, final=final)
            if read is None:
                return None
            body, marks, timed, tail = read
            if tail is not None:
                self.open[p] = (tail[0].copy(), tail[1], at(int(tail[1][0])))
            if kind is StreamKind.KLV and marks:  # (a PID without a whole PES gives nothing, as in KLVDemux)
                out[p] = (body, marks)
                self.whole.add(p)
                if timed:
                    self.by_arrival[p] = self.by_arrival.get(p, 0) + timed
        self.video_pts = arrival.get(n)
        self.k0 += n
        return out

    def _read_pats(self, data: bytes, cells, pid) -> bool:
        """The chunk's PAT packets read alone (their reader carried): every PID they name as a
        program map's added to :attr:`named`; False where they cannot be read without damage."""
        import numpy as np
        from stanag4609.transport.mpegts import parse_transport_packet

        events: list = []
        damage: list[Damage] = []
        tables = TableRepeats(data, cells, pid, np.flatnonzero(pid == 0), k0=self.k0, carry=self.pat_tables)
        for k, p, prev, repeat in tables:
            raw = tables.fed(k, p, prev, repeat)
            if raw is not None:
                self.pats._packet(parse_transport_packet(raw, offset=(self.k0 + k) * TS_PACKET), events, damage)
                self.named |= self.pats.pmt_pids
        return not damage


class ArrivalTimes:
    """The PTS of the video PES begun last before a packet (what :class:`KLVDemux` with
    ``arrival`` times a metadata PES without a PTS by), found when asked: the video PIDs' PES
    starts as the program tables then stood (``states``: from the packet after k, the metadata
    streams and the video PIDs, until the next one's k, ``ends``); ``before``: what it was before
    the first packet (a chunk of a longer stream)."""

    def __init__(self, data: bytes, pid, starts, states, ends, *, before: int | None = None) -> None:
        import numpy as np

        self.data, self.before = data, before
        video = [k0 + 1 + np.flatnonzero(starts[k0 + 1:k1] & np.isin(pid[k0 + 1:k1], list(v - set(s))))
                 for (k0, s, v), k1 in zip(states, ends, strict=True) if v]
        self.video = np.concatenate(video) if video else np.zeros(0, np.int64)

    def get(self, k: int) -> int | None:
        import numpy as np

        j = int(np.searchsorted(self.video, k)) - 1
        if j < 0:
            return self.before
        v = int(self.video[j])
        return cell_pes_pts(self.data[v * TS_PACKET:(v + 1) * TS_PACKET])


class TableRepeats:
    """Program-table packets a clean read need not hand to the table reader: a packet that is the
    one before it on its PID again (every byte but the continuity counter), one on from it, one
    whole table section in it (stuffing after), no adaptation field. Transmitters repeat their PAT
    and PMT every ~0.1 s; read once, a repeat changes nothing the tables say. The packets that are
    read carry the continuity counter they would have had without the repeats, so that the table
    reader sees the same continuity (and any break in it) as in the whole stream (stanag4609's
    does not judge a table PID's continuity today; a repeat must also be one on from the packet
    before, in case it does). ``rows``: the
    candidate table packets, in order; the repeats are found in vectorised passes, and a repeat is
    left out only when the packet before it on its PID was itself handed on or left out. In a
    chunk of a longer stream, ``k0`` is the chunk's first packet's index in the stream and
    ``carry`` what the chunks before it left (updated here); the packets before are then
    given by those indices."""

    def __init__(self, data: bytes, cells, pid, rows, *, k0: int = 0, carry: TableCarry | None = None) -> None:
        import numpy as np

        self.data, self.k0 = data, k0
        self.carry = carry if carry is not None else TableCarry()
        p = pid[rows]
        order = np.lexsort((rows, p))  # grouped by PID, in stream order within each
        prev = np.full(rows.size, -1, np.int64)
        same_pid = p[order[1:]] == p[order[:-1]]
        prev[order[1:][same_pid]] = k0 + rows[order[:-1][same_pid]]
        c, q = cells[rows], cells[np.maximum(prev - k0, 0)]
        before = self.carry.before
        for j in np.flatnonzero(prev < 0).tolist():  # a PID's first candidate in the chunk: its last one before
            if int(p[j]) in before:
                prev[j], q[j] = before[int(p[j])]
        end = 8 + (((c[:, 6].astype(np.int64) & 0x0F) << 8) | c[:, 7])  # a section starting at byte 5 ends
        tail = c[np.arange(rows.size), np.minimum(end, TS_PACKET - 1)]
        repeat = ((prev >= 0) & (c[:, 3] >> 4 == 1) & (q[:, 3] >> 4 == 1) & ((c[:, 1] & 0x40) != 0) & (c[:, 4] == 0)
                  & ((c[:, 3] & 0x0F) == ((q[:, 3] + 1) & 0x0F)) & (c[:, :3] == q[:, :3]).all(axis=1)
                  & (c[:, 4:] == q[:, 4:]).all(axis=1) & ((end == TS_PACKET) | ((end < TS_PACKET) & (tail == 0xFF))))
        for j in order[np.append(~same_pid, True)].tolist() if rows.size else []:  # each PID's last candidate,
            before[int(p[j])] = (k0 + int(rows[j]), c[j].copy())                  # for the next chunk
        self.rows, self.pid, self.prev, self.repeat = rows.tolist(), p.tolist(), prev.tolist(), repeat.tolist()

    def __iter__(self):
        """(packet index in the chunk, PID, the packet before it on its PID (index in the stream)
        or -1, whether it repeats that one) per candidate, in order: what :meth:`fed` takes."""
        return zip(self.rows, self.pid, self.prev, self.repeat, strict=True)

    def fed(self, k: int, p: int, prev: int, repeat: bool) -> bytes | None:
        """Packet ``k`` (PID ``p``, about to be read as a table) as the table reader is to get it,
        or None to leave it out."""
        last = self.carry.last.get(p)
        self.carry.last[p] = self.k0 + k
        if repeat and last == prev:
            self.carry.skipped[p] = self.carry.skipped.get(p, 0) + 1
            return None
        raw = self.data[k * TS_PACKET:(k + 1) * TS_PACKET]
        shift = self.carry.skipped.get(p, 0)
        if not shift & 0x0F:
            return raw
        return raw[:3] + bytes([(raw[3] & 0xF0) | ((raw[3] - shift) & 0x0F)]) + raw[4:]


def _adaptation_fields_read(data: bytes, cells, rows, alen) -> bool:
    """Whether stanag4609 reads the adaptation fields of the ``rows`` (a mask) without an error:
    the common ones (flags, a PCR, 0xFF stuffing) checked in vectorised passes by its rules, the
    others (OPCR, splice countdown, private data, extension) by its own parser."""
    import numpy as np
    from stanag4609.transport.mpegts import parse_transport_packet

    idx = np.flatnonzero(rows)
    flags = cells[idx, 5]
    rare = (flags & 0x0F) != 0
    for k in idx[rare].tolist():
        try:
            parse_transport_packet(data[k * TS_PACKET:(k + 1) * TS_PACKET], offset=k * TS_PACKET)
        except Exception:
            return False
    idx, flags, n = idx[~rare], flags[~rare], alen[idx[~rare]]
    pcr = (flags & 0x10) != 0
    v = cells[idx, 6:12].astype(np.int64)
    if (pcr & ((n < 7) | ((v[:, 4] & 0x7E) != 0x7E) | ((((v[:, 4] & 1) << 8) | v[:, 5]) > 299))).any():
        return False
    first = 5 + np.where(pcr, 7, 1)  # the stuffing: every byte after the fields to the field's end is 0xFF
    some = first < 5 + n
    idx, first, n = idx[some], first[some], n[some]
    if not idx.size:
        return True
    col = np.arange(TS_PACKET)
    stuffing = (col >= first[:, None]) & (col < (5 + n)[:, None])
    return bool((cells[idx] == 0xFF)[stuffing].all())


def _clean_pes(c, g, max_pes_bytes: int, arrival, *, final: bool = True
               ) -> tuple[bytes, list, int, tuple | None] | None:
    """One metadata PID's packets (``c``: their cells, in order; ``g``: their indices in the
    stream) as its PES payloads joined, (offset, PTS s) marks, the count of PES timed by
    ``arrival`` (a packet's index -> the PTS it is timed by) and, unless ``final``, the packets of
    the last PES, still open (cells, indices; or None); or None where the PES assembler would meet
    anything but whole PES packets with the standard header and a PTS or none."""
    import numpy as np

    if (c[:, 1] & 0x80).any():  # the transport error flag
        return None
    control, alen = (c[:, 3] >> 4) & 0x3, c[:, 4].astype(np.int64)
    start = np.where(control == 1, 4, 5 + alen)
    size = np.where(control & 1, TS_PACKET - start, 0)
    pusi = (c[:, 1] & 0x40) != 0
    keep = size > 0  # (a packet without payload adds nothing)
    c, g, start, size, pusi = c[keep], g[keep], start[keep], size[keep], pusi[keep]
    first = np.flatnonzero(pusi)
    if not first.size:  # (nothing begun: the assembler drops them)
        return b"", [], 0, None
    tail = None
    if not final:  # the last PES may go on in the next chunk
        if int(size[first[-1]:].sum()) > max_pes_bytes:
            return None
        tail = (c[first[-1]:], g[first[-1]:])
    sl = slice(first[0], None if final else first[-1])
    c, g, start, size, pusi = c[sl], g[sl], start[sl], size[sl], pusi[sl]
    if not c.shape[0]:
        return b"", [], 0, tail
    total = int(size.sum())
    at = np.cumsum(size) - size  # each packet's payload's place in the joined bytes
    joined = c[np.arange(TS_PACKET) >= start[:, None]]  # each packet's payload, in order
    s = at[pusi]  # PES starts
    e = np.append(s[1:], total)
    length = e - s
    if (length < 14).any() or (length > max_pes_bytes).any():
        return None
    h = joined[s[:, None] + np.arange(14)].astype(np.int64)  # each PES's first 14 bytes
    declared = (h[:, 4] << 8) | h[:, 5]
    flags = h[:, 7] >> 6
    hdl = h[:, 8]
    timed = flags == 2
    ok = ((h[:, 0] == 0) & (h[:, 1] == 0) & (h[:, 2] == 1) & ~np.isin(h[:, 3], list(SPECIAL_STREAM_IDS))
          & ((declared == 0) | (declared + 6 == length)) & ((h[:, 6] & 0xC0) == 0x80) & (timed | (flags == 0))
          & (9 + hdl <= length)
          & (~timed | ((hdl >= 5) & ((h[:, 9] >> 4) == 2) & ((h[:, 9] & 1) == 1) & ((h[:, 11] & 1) == 1)
                       & ((h[:, 13] & 1) == 1))))
    if not ok.all():  # (a DTS too, a damaged header: the assembler's own way)
        return None
    pts = ((h[:, 9] >> 1) & 0x7) << 30 | h[:, 10] << 22 | (h[:, 11] >> 1) << 15 | h[:, 12] << 7 | h[:, 13] >> 1
    times: list[float | None] = [t if ok_t else None for t, ok_t in zip((pts / PTS_HZ).tolist(), timed.tolist(),
                                                                       strict=True)]
    by_arrival = 0
    begins = g[pusi]  # each PES's first packet
    for j in np.flatnonzero(~timed).tolist():  # no PTS: the video frame before it in the stream (ST 1402)
        video = arrival(int(begins[j]))
        if video is not None:
            times[j] = video / PTS_HZ
            by_arrival += 1
    p0 = s + 9 + hdl
    plen = e - p0
    mark = np.cumsum(plen) - plen
    runs = np.column_stack([p0 - s, plen]).ravel()  # each PES: its header [s, p0), then its payload [p0, e)
    body = joined[np.repeat(np.tile(np.array([False, True]), s.size), runs)].tobytes()  # the payloads, joined
    return body, list(zip(mark.tolist(), times, strict=True)), by_arrival, tail
