"""A live KLV session: datagrams in, one :class:`~eoloc.live.update.PacketUpdate` per packet out.

A datagram is either MPEG-TS (whole 188-byte transport packets starting with 0x47, as ST 1402
sends them, usually seven per datagram) or raw KLV (one or more whole packets); each is told
apart on arrival. Transport streams go through one demultiplexer kept for the whole session
(stanag4609's, as for files), so a KLV packet split over several datagrams is put back
together; each KLV PID is its own stream ("PID 497"). Packets are framed and decoded with the
same tolerant reader as files (:func:`eoloc.io.klv.reader.decode_klv_bytes`) and worked out by
:class:`eoloc.live.update.PacketLocator`. What ST 0601 sends only when it changes
(report-on-change) is carried from packet to packet per stream. With ``refine`` (a
:class:`eoloc.live.refine.TargetFilters`) each target id is also refined across packets.

Faults are counted, never fatal: a datagram that is neither (``not_klv``), a packet that fails
its checksum or framing, or a transport packet the demultiplexer refuses (``corrupt``), the same
packet twice (``duplicates``: dropped), a packet older than the last of its stream (``late``:
located all the same, its values not carried), an encoder restart (its time back by more than
``restart_s``: ``restarts``). Each fault's message goes to :attr:`LiveSession.faults`
(:class:`eoloc.live.faults.FaultLog`: counted by kind, reported at a bounded rate, in bounded
memory), never to a list that grows with the stream.
"""

from __future__ import annotations

import time
from collections import OrderedDict, deque
from dataclasses import dataclass, field, replace

import numpy as np

from ..io.klv.st0601 import Tag
from .faults import FaultLog
from .update import PacketLocator, PacketUpdate

RESTART_S = 2.0  # a time stamp this far behind the newest one: the encoder restarted its clock
TS_PACKET = 188


@dataclass
class Counters:
    datagrams: int = 0
    packets: int = 0
    corrupt: int = 0
    duplicates: int = 0
    late: int = 0
    restarts: int = 0
    detections: int = 0
    fixes_ok: int = 0
    not_klv: int = 0
    latency_s: deque = field(default_factory=lambda: deque(maxlen=100_000))  # the latest (memory stays bounded)
    latency_max_s: float = 0.0

    def counts(self) -> dict:
        """The counts so far (cheap: no latency statistics)."""
        return {"datagrams": self.datagrams, "packets": self.packets, "corrupt": self.corrupt,
                "duplicates": self.duplicates, "late": self.late, "restarts": self.restarts,
                "not_klv": self.not_klv, "detections": self.detections, "fixes_ok": self.fixes_ok}

    def summary(self) -> dict:
        """The counts and the latency from a datagram's arrival to its outputs sent (ms)."""
        lat = np.asarray(self.latency_s) * 1e3
        return self.counts() | {
                "latency_ms_median": float(np.median(lat)) if lat.size else None,
                "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else None,
                "latency_ms_max": self.latency_max_s * 1e3 if lat.size else None}


def is_transport(datagram: bytes) -> bool:
    """Whether a datagram is whole MPEG-TS packets (ST 1402) rather than raw KLV."""
    n = len(datagram)
    return n >= TS_PACKET and n % TS_PACKET == 0 and datagram[0] == 0x47 and datagram[n - TS_PACKET] == 0x47


class LiveSession:
    """Feed datagrams (:meth:`feed`); each returns the :class:`PacketUpdate` of every new packet
    completed by it. Whoever sends the outputs calls :meth:`done` after them: the latency counted
    runs from the datagram's arrival to its outputs sent."""

    def __init__(self, source: str, *, dem=None, sensor=None, budget=None, recent: int = 512,
                 restart_s: float = RESTART_S, refine=None, klv_out=None, movers=None) -> None:
        self.source, self.dem, self.budget = source, dem, budget
        self.locator = PacketLocator(dem=dem, sensor=sensor, budget=budget)
        self.sensor = self.locator.sensor
        self.counters = Counters()
        self.carry: dict[str, object] = {}  # stream -> the packet holding every value known so far
        self.recent: OrderedDict[bytes, None] = OrderedDict()
        self.recent_size = recent
        self.restart_s = restart_s
        self.newest_s: dict[str, float] = {}
        self.faults = FaultLog()  # counted by kind, reported at a bounded rate (memory bounded too)
        self.next_index = 0
        self.demux = None
        self.streams: dict[str, int] = {}  # stream -> good packets
        self.refine = refine  # a live.refine.TargetFilters: the targets refined across packets, or None
        self.klv_out = klv_out  # a live.klvout.KlvOut: the stream re-sent with the target locations, or None
        self._items: list = []  # with klv_out: the datagram's transport packets to pass on and PES to rebuild
        self.movers = movers  # a live.movers.LiveMovers: the movers found in the stream's video, or None
        self.mover_stream: str | None = None  # the KLV stream whose packets pose the video's frames

    def feed(self, datagram: bytes, stream: str = "") -> list[PacketUpdate]:
        """``stream``: the name of the KLV stream a raw (not MPEG-TS) datagram belongs to, where the
        source demultiplexed it (FFmpeg's "PID n")."""
        c = self.counters
        c.datagrams += 1
        transport = is_transport(datagram)
        chunks = self._demux(datagram) if transport else [(datagram, stream, None)]
        updates: list[PacketUpdate] = []
        for payload, stream_name, pts in chunks:
            updates += self._packets(payload, stream_name, pts)
        if self.klv_out is not None:
            if transport:
                self.klv_out.transport(self._items)
            else:
                self.klv_out.raw_datagram(datagram)
        return updates

    def mover_updates(self, *, final: bool = False, timeout_s: float = 120.0) -> list[PacketUpdate]:
        """The movers found in the video since the last call (none without ``movers``); ``final``:
        the source has ended, so the frames still waiting are searched first (up to ``timeout_s``)."""
        if self.movers is None:
            return []
        return self.movers.finish(timeout_s) if final else self.movers.updates()

    def done(self, arrived: float) -> None:
        """The outputs of the datagram that arrived at ``arrived`` are sent: its latency is counted."""
        c = self.counters
        c.latency_s.append(time.perf_counter() - arrived)
        c.latency_max_s = max(c.latency_max_s, c.latency_s[-1])

    def _demux(self, datagram: bytes) -> list[tuple[bytes, str, int | None]]:
        """KLV payloads (stream name, PES presentation time in 90 kHz ticks) completed by the
        transport packets of one datagram; with ``movers`` its video handed to them."""
        from stanag4609.transport.demux import PESStreamEvent, PMTEvent, StreamKind
        from stanag4609.transport.metadata import parse_metadata_au_cells

        from ..errors import one_line
        from ..io.klv.demux import KLVDemux

        if self.demux is None:
            self.demux = KLVDemux()
        out = []
        items = self._items = []
        metadata_pids = self._metadata_pids() if self.klv_out is not None else set()
        video_pid = min(self.demux.video_types, default=None) if self.movers is not None else None
        video = []
        for k in range(0, len(datagram), TS_PACKET):
            cell = datagram[k:k + TS_PACKET]
            pid = (cell[1] & 0x1F) << 8 | cell[2]
            if pid == video_pid:
                video.append(cell)
            if self.klv_out is not None and pid not in metadata_pids:
                items.append(cell)  # passed on untouched (video, audio, tables, clock)
            events, damage = self.demux.feed_cells(cell, k)
            for d in damage:
                self.counters.corrupt += 1
                self.faults.add("transport", f"{self.source}: datagram {self.counters.datagrams}: transport "
                                             f"packet {k // TS_PACKET}: {d.message}")
            for ev in events:
                if isinstance(ev, PMTEvent) and self.klv_out is not None:
                    metadata_pids = self._metadata_pids()
                if isinstance(ev, PMTEvent) and self.movers is not None:
                    video_pid = min(self.demux.video_types, default=None)
                if not isinstance(ev, PESStreamEvent):
                    continue
                if ev.kind is not StreamKind.KLV:
                    if self.klv_out is not None:  # held back as metadata, but not KLV: on as it came
                        items += [bytes(p) for p in ev.pes.transport_packets]
                    continue
                if self.klv_out is not None:
                    items.append(ev)
                payload = ev.pes.payload
                if ev.stream.stream_type == 0x15:  # synchronous metadata: access-unit cells wrap the KLV
                    try:
                        payload = b"".join(cell.data for cell in parse_metadata_au_cells(payload))
                    except Exception as exc:
                        self.counters.corrupt += 1
                        self.faults.add("metadata access unit",
                                        f"{self.source}: PID {ev.pid}: metadata access unit: {one_line(exc)}")
                        continue
                out.append((payload, f"PID {ev.pid}", ev.pes.pts))
        if video:
            self.movers.video(self.demux.video_types[video_pid], b"".join(video), time.perf_counter())
        return out

    def _metadata_pids(self) -> set[int]:
        """The PIDs the program tables give as metadata (their packets are held for KLV out)."""
        return set(self.demux.streams)

    def _packets(self, payload: bytes, stream_name: str, pts: int | None = None) -> list[PacketUpdate]:
        from ..io.klv.reader import decode_klv_bytes

        c = self.counters
        if payload in self.recent:  # a packet seen a moment ago, sent again whole: not decoded again
            c.duplicates += 1
            return []
        decoded = decode_klv_bytes(payload, self.source, first_index=self.next_index, stream=stream_name,
                                   container="mpegts" if stream_name else "klv")
        if not decoded.packets and decoded.n_bad == 0 and not stream_name:  # no packet key at all
            c.not_klv += 1
            self.faults.add("not KLV", f"{self.source}: datagram {c.datagrams}: not KLV ({len(payload)} bytes, no "
                                       "ST 0601 or EG 0104 key)")
            return []
        c.corrupt += decoded.n_bad
        if decoded.issues or decoded.notes:
            where = f"{self.source}{f' [{stream_name}]' if stream_name else ''}: datagram {c.datagrams}"
            for i in decoded.issues:
                self.faults.add(i.kind, f"{where}: {i.kind}: {i.message}")
            for n in decoded.notes:  # item-level departures (a field that cannot be decoded, ...)
                self.faults.add(f"tag {n.tag} {n.kind}", f"{where}: tag {n.tag}: {n.kind}: {n.message}", n.count)
        self.next_index += len(decoded.packets) + decoded.n_bad
        updates = []
        for pkt in decoded.packets:
            if pkt.raw in self.recent:
                c.duplicates += 1
                continue
            self.recent[pkt.raw] = None
            if len(self.recent) > self.recent_size:
                self.recent.popitem(last=False)
            c.packets += 1
            self.streams[pkt.stream] = self.streams.get(pkt.stream, 0) + 1
            t = pkt.fields.get(Tag.PRECISION_TIME_STAMP)
            t_s = t.timestamp() if hasattr(t, "timestamp") else None
            newest = self.newest_s.get(pkt.stream)
            late = False
            if t_s is not None and newest is not None and t_s < newest:
                if newest - t_s > self.restart_s:
                    c.restarts += 1
                    self.newest_s[pkt.stream] = t_s
                else:
                    c.late += 1
                    late = True
            elif t_s is not None:
                self.newest_s[pkt.stream] = t_s
            carried = self.carry.get(pkt.stream)
            known = replace(pkt, fields={**(carried.fields if carried else {}), **pkt.fields})
            if not late:  # a late packet's values are older than those carried: they do not replace them
                self.carry[pkt.stream] = known
            u = self.locator.locate(self.source, pkt, known, late=late)
            if self.refine is not None:
                self.refine.update(u)
            if self.klv_out is not None:
                self.klv_out.mark(pkt.raw, u, hae=Tag.FRAME_CENTER_HEIGHT_ABOVE_ELLIPSOID in known.fields)
            if self.movers is not None and not late and u.platform is not None and pts is not None:
                if self.mover_stream is None:
                    self.mover_stream = pkt.stream  # the first stream with a position poses the video
                if pkt.stream == self.mover_stream:
                    self.movers.pose(pts / 90_000.0, u.view, u.key, pkt.stream, pkt.index)
            c.detections += len(u.fixes)
            c.fixes_ok += sum(1 for r in u.fixes if r["status"] == "OK")
            updates.append(u)
        return updates
