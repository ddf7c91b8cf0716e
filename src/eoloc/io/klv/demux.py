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
from dataclasses import dataclass

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
        self.video_pids |= {s.elementary_pid for s in pmt.streams if s.stream_type in VIDEO_STREAM_TYPES}
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
