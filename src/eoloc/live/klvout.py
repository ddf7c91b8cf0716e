"""KLV out: the live stream re-sent with eoloc's answer in it. Each ST 0601 packet gets its
first located target (the lowest VMTI target id with status OK, as `eoloc klv --klv-out`) in the
target location tags 40-42 (tag 42 in the datum the stream uses: HAE when it sends tag 78, else
MSL through the geoid) with CE90 and LE90 in tags 45 and 46; every other item is kept byte for
byte and the checksum recomputed (:func:`eoloc.io.klv.encode.with_target_location`, item by
item: a packet that departs from the standard elsewhere takes its fix all the same). A packet
without a located target, or whose fix no tag can hold (a height outside tag 42's range), goes on
as it came.

The output keeps the input's form. Raw KLV in: each datagram out carries the same packets.
MPEG-TS in: every transport packet that is not metadata (video, audio, PAT, PMT, PCR) is passed
on untouched, in its place; the metadata PIDs' PES packets are rebuilt around the new KLV (same
stream id, PTS, DTS and alignment; synchronous metadata keeps its access-unit cells) and split
into transport packets with their own continuity counters. Datagrams carry 7 transport packets
(1316 bytes), as ST 1402 and most encoders send them.

Destinations: ``udp://HOST:PORT`` (a multicast group too, ``?ttl=N``), or a file (raw KLV or
.ts, appended datagram by datagram).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from .sinks import BaseSink
from .update import PacketUpdate

TS_PACKET = 188
TS_PER_DATAGRAM = 7
METADATA_STREAM_TYPES = (0x06, 0x15)  # asynchronous (private data) and synchronous metadata (ST 1402)


def first_located(update: PacketUpdate) -> dict | None:
    """The fix that goes into the packet's target location tags: the lowest target id located."""
    ok = [r for r in update.fixes if r.get("status") == "OK"]
    return min(ok, key=lambda r: str(r.get("target_id"))) if ok else None


class KlvOut(BaseSink):
    """Collects, per datagram, what the session decoded and located (:meth:`mark`), then sends the
    datagram on rewritten (:meth:`raw_datagram`, :meth:`transport`). Given to the session
    (``LiveSession(klv_out=)``), which rewrites as it demultiplexes, and to :func:`eoloc.live.run`
    as a sink (closed and counted with the others)."""

    name = "klv-out"

    def __init__(self, destination: str) -> None:
        from urllib.parse import urlparse

        self.destination = destination
        scheme = urlparse(destination).scheme
        if scheme == "udp":
            from .senders import UdpSender

            self.sender = UdpSender(destination, option="--klv-out")
            self._send: Callable[[bytes], None] = self.sender.send
            self.file = None
        elif scheme:
            raise InputError(f"--klv-out {destination!r}: give udp://HOST:PORT (multicast too, ?ttl=N) or a file")
        else:
            try:
                self.file = open(Path(destination), "wb")  # kept open for the session
            except OSError as exc:
                raise InputError(f"--klv-out {destination!r}: cannot write there: {exc.strerror}") from None
            self.sender = None
            self._send = self.file.write
        self.replace: dict[bytes, bytes] = {}
        self.cc: dict[int, int] = {}
        self.held: dict[int, int] = {}  # metadata PID -> transport packets held until its PES completes
        self.counts = {"packets": 0, "with_target": 0, "unchanged": 0, "datagrams": 0, "bytes": 0}

    def mark(self, raw: bytes, update: PacketUpdate | None, hae: bool) -> None:
        """The packet ``raw`` (as it arrived) located as ``update``: its rewritten bytes are
        kept for the datagram being built. ``hae``: the stream gives tag 42 as HAE."""
        from ..io.klv.encode import with_fix

        self.counts["packets"] += 1
        fix = first_located(update) if update is not None else None
        if fix is None:
            return
        ce, le = fix.get("ce90_m"), fix.get("le90_m")
        new = with_fix(raw, fix["lat_deg"], fix["lon_deg"], fix["h_m"], ce90_m=ce, le90_m=le, tag42_hae=hae)
        if new is None:
            self.counts["unchanged"] += 1
            return
        self.replace[raw] = new
        self.counts["with_target"] += 1

    def payload(self, data: bytes) -> bytes:
        """``data`` (KLV bytes) with each packet marked so far replaced by its rewritten bytes."""
        for old, new in self.replace.items():
            data = data.replace(old, new, 1)
        return data

    def raw_datagram(self, datagram: bytes) -> None:
        self._out(self.payload(datagram))
        self.replace.clear()

    def transport(self, items: list) -> None:
        """Send one TS datagram's worth: ``items`` in arrival order, each a transport packet's
        bytes to pass on, or a completed metadata PES event (stanag4609 ``PESStreamEvent``) to
        rebuild."""
        from stanag4609.transport.metadata import encode_metadata_au_cell, parse_metadata_au_cells
        from stanag4609.transport.mux import encode_pes_packet, packetize_pes

        out: list[bytes] = []
        for item in items:
            if isinstance(item, bytes):
                out.append(item)
                continue
            ev = item
            pes = ev.pes
            as_it_came = [bytes(tp) for tp in pes.transport_packets]
            try:
                if ev.stream.stream_type == 0x15:  # synchronous metadata: the KLV inside its cells
                    payload = b"".join(encode_metadata_au_cell(
                        self.payload(c.data), metadata_service_id=c.metadata_service_id,
                        sequence_number=c.sequence_number, fragmentation=c.fragmentation,
                        decoder_config=c.decoder_config, random_access=c.random_access)
                        for c in parse_metadata_au_cells(pes.payload))
                else:
                    payload = self.payload(pes.payload)
                if payload == pes.payload and ev.pid not in self.cc:
                    out += as_it_came  # unchanged, and the PID's counters still the encoder's
                    continue
                new_pes = encode_pes_packet(payload, stream_id=pes.stream_id, pts=pes.pts, dts=pes.dts,
                                            data_alignment_indicator=pes.data_alignment_indicator)
                packets, self.cc[ev.pid] = packetize_pes(new_pes, pid=ev.pid,
                                                         continuity_counter=self.cc.get(ev.pid, 0))
            except ValueError:  # damaged access-unit cells (stanag4609's DecodeError), or a PES grown past 64 KB
                self.counts["unchanged"] += 1
                out += as_it_came
                continue
            out += packets
        self.replace.clear()
        for k in range(0, len(out), TS_PER_DATAGRAM):
            self._out(b"".join(out[k:k + TS_PER_DATAGRAM]))

    def _out(self, data: bytes) -> None:
        if data:
            self._send(data)
            self.counts["datagrams"] += 1
            self.counts["bytes"] += len(data)

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
        if self.sender is not None:
            self.sender.close()

    def summary(self) -> dict:
        return {"klv_out": {"to": self.destination, **self.counts,
                            **({"errors": self.sender.errors} if self.sender is not None else {})}}
