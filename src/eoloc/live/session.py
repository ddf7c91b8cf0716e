"""A live KLV session: datagrams in, located VMTI targets out, packet by packet.

Each datagram is framed and decoded with the same tolerant reader as files
(:func:`eoloc.io.klv.reader.decode_klv_bytes`); the packet's pose, field of view and VMTI targets
go through the same code as `eoloc klv` (:func:`eoloc.io.klv.klv_telemetry`,
:func:`eoloc.io.klv.vmti_detections`, :func:`eoloc.video.locate_vmti`). What ST 0601 sends only
when it changes (report-on-change) is carried from packet to packet: each packet is decoded
after a copy of everything known so far, so a packet that leaves its field of view out still
gets the last one sent.

Faults are counted, never fatal: a datagram that is not KLV or a packet that fails its checksum
(``corrupt``), the same packet twice (``duplicates``: dropped), a packet older than the last
(``late``: located all the same), an encoder restart (time back by more than ``restart_s``:
``restarts``), and gaps (``gaps``, the longest in ``longest_gap_s``).
"""

from __future__ import annotations

import time
from collections import OrderedDict, deque
from dataclasses import dataclass, field, replace

import numpy as np

RESTART_S = 2.0  # a time stamp this far behind the newest one: the encoder restarted its clock


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

    def summary(self) -> dict:
        lat = np.asarray(self.latency_s) * 1e3
        return {"datagrams": self.datagrams, "packets": self.packets, "corrupt": self.corrupt,
                "duplicates": self.duplicates, "late": self.late, "restarts": self.restarts,
                "not_klv": self.not_klv, "detections": self.detections, "fixes_ok": self.fixes_ok,
                "latency_ms_median": float(np.median(lat)) if lat.size else None,
                "latency_ms_max": self.latency_max_s * 1e3 if lat.size else None}


class LiveSession:
    """Feed datagrams (:meth:`feed`); each returns the GeoJSON features of the targets located in it."""

    def __init__(self, source: str, *, dem=None, sensor=None, budget=None, recent: int = 512,
                 restart_s: float = RESTART_S) -> None:
        from ..misb import misb_sensor

        self.source, self.dem, self.budget = source, dem, budget
        self.sensor = sensor or misb_sensor()
        self.counters = Counters()
        self.carry: dict[str, object] = {}  # stream -> the packet holding every value known so far
        self.recent: OrderedDict[bytes, None] = OrderedDict()
        self.recent_size = recent
        self.restart_s = restart_s
        self.newest_s: float | None = None
        self.issues: list[str] = []
        self.next_index = 0

    def feed(self, datagram: bytes, arrived: float | None = None) -> list[dict]:
        """The features (GeoJSON Points, one per VMTI target; failed ones with a null geometry)
        of the packets in ``datagram``."""
        from ..io.klv.reader import KLVStream, decode_klv_bytes

        arrived = time.perf_counter() if arrived is None else arrived
        c = self.counters
        c.datagrams += 1
        stream = decode_klv_bytes(datagram, self.source, first_index=self.next_index)
        c.corrupt += stream.n_bad
        self.issues += [f"{self.source}: datagram {c.datagrams}: {i.kind}: {i.message}" for i in stream.issues]
        if not stream.packets and stream.n_bad == 0:  # no packet key at all: not KLV
            c.not_klv += 1
            return []
        features: list[dict] = []
        for pkt in stream.packets:
            self.next_index = max(self.next_index, pkt.index + 1)
            if pkt.raw in self.recent:
                c.duplicates += 1
                continue
            self.recent[pkt.raw] = None
            if len(self.recent) > self.recent_size:
                self.recent.popitem(last=False)
            c.packets += 1
            t = pkt.fields.get(2)
            t_s = t.timestamp() if hasattr(t, "timestamp") else None
            late = False
            if t_s is not None and self.newest_s is not None and t_s < self.newest_s:
                if self.newest_s - t_s > self.restart_s:
                    c.restarts += 1
                    self.newest_s = t_s
                else:
                    c.late += 1
                    late = True
            elif t_s is not None:
                self.newest_s = t_s
            carried = self.carry.get(pkt.stream)
            packets = [pkt] if carried is None else [carried, pkt]
            if not late:  # a late packet's values are older than those carried: they do not replace them
                self.carry[pkt.stream] = replace(pkt, fields={**(carried.fields if carried else {}), **pkt.fields})
            features += self._locate(KLVStream(self.source, "klv", packets), pkt.index)
        c.latency_s.append(time.perf_counter() - arrived)
        c.latency_max_s = max(c.latency_max_s, c.latency_s[-1])
        return features

    def _locate(self, stream, index: int) -> list[dict]:
        from ..io.export import fix_features, fix_records, with_utc
        from ..io.klv import klv_telemetry, vmti_detections
        from ..video import locate_vmti

        det = vmti_detections(stream)
        if not len(det):
            return []
        mine = det.columns["frame"] == index
        if not mine.any():
            return []
        det = det.keep(mine)
        tel = klv_telemetry(stream, report_on_change=True)
        v = locate_vmti(tel, det, self.dem, budget=self.budget, base=self.sensor)
        self.counters.detections += len(det)
        self.counters.fixes_ok += int(np.sum(v.fixes.ok))
        extra = with_utc({"stream": det.columns["stream"], **v.extra}, "unix")
        return fix_features(fix_records(v.fixes, extra, v.uncertainty))
