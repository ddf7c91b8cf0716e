"""A live stream's video, as it arrives: the transport packets of its video PID put back into PES
packets (:class:`PesAssembler`) and decoded into frames with their presentation times
(:class:`VideoDecoder`, FFmpeg through PyAV), for the live motion detector
(:mod:`eoloc.live.movers`).

A PES packet is complete when the next one on its PID begins (video PES usually leave their length
at 0, "unbounded"); a transport packet lost on the way (a continuity counter that jumps) drops the
PES packet it belonged to, and the decoder picks up again at the next picture it can decode (a
lost reference frame costs the pictures that lean on it: counted, never a guess)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.klv.demux import TS_PACKET, pes_start_pts

# ISO/IEC 13818-1 stream types -> FFmpeg's decoder names
CODECS = {0x01: "mpeg1video", 0x02: "mpeg2video", 0x10: "mpeg4", 0x1B: "h264", 0x20: "h264", 0x21: "jpeg2000",
          0x24: "hevc", 0x42: "cavs"}
MAX_PES_BYTES = 8 << 20  # a PES packet larger than this is damage, not a picture


@dataclass(frozen=True)
class Pes:
    """One video PES packet: its presentation time (90 kHz ticks, None without one) and the
    elementary stream bytes it carries."""

    pts: int | None
    payload: bytes


class PesAssembler:
    """Transport packets of one PID (:meth:`feed`, whole 188-byte cells in order) -> its PES
    packets as each completes; ``dropped`` counts those lost to a gap or damage."""

    def __init__(self) -> None:
        self.parts: list[bytes] | None = None  # the PES being put together (None: waiting for a start)
        self.size = 0
        self.counter: int | None = None
        self.dropped = 0

    def feed(self, cell: bytes) -> list[Pes]:
        out: list[Pes] = []
        control = cell[3] >> 4 & 0x3
        cc = cell[3] & 0xF
        if control & 0x1:  # a payload: its counter steps by one (mod 16)
            if self.counter is not None and cc != (self.counter + 1) & 0xF and cc != self.counter:
                self._drop()  # a packet lost on the way: this PES is not whole
            elif self.counter is not None and cc == self.counter:
                return out  # a duplicate (allowed once by the standard): nothing new
        self.counter = cc
        if not control & 0x1:
            return out
        start = 4 + (1 + cell[4] if control == 0x3 else 0)
        if start >= TS_PACKET:
            return out
        data = cell[start:]
        if cell[1] & 0x40:  # payload_unit_start: the PES before is whole
            out += self.flush()
            self.parts, self.size = [data], len(data)
        elif self.parts is not None:
            self.parts.append(data)
            self.size += len(data)
            if self.size > MAX_PES_BYTES:
                self._drop()
        return out

    def flush(self) -> list[Pes]:
        """The PES packet being put together, as it is (the end of the stream)."""
        if self.parts is None:
            return []
        raw = b"".join(self.parts)
        self.parts, self.size = None, 0
        if len(raw) < 9 or raw[:3] != b"\x00\x00\x01":
            self.dropped += 1
            return []
        return [Pes(pes_start_pts(raw[:14]), raw[9 + raw[8]:])]

    def _drop(self) -> None:
        if self.parts is not None:
            self.dropped += 1
        self.parts, self.size = None, 0


@dataclass(frozen=True)
class Frame:
    """One decoded picture: presentation time (s, the transport's 90 kHz clock) and its pixels
    (H, W, 3) uint8 RGB."""

    pts_s: float
    image: np.ndarray


class VideoDecoder:
    """Video PES packets of one stream type (:meth:`decode`) -> its pictures in presentation order.
    ``errors`` counts the packets the decoder could not use (a lost reference, damage)."""

    def __init__(self, stream_type: int) -> None:
        import av

        from ..errors import InputError

        name = CODECS.get(stream_type)
        if name is None:
            raise InputError(f"video stream type 0x{stream_type:02X}: no decoder for it (eoloc decodes "
                             f"{', '.join(sorted(set(CODECS.values())))})")
        self.codec = av.CodecContext.create(name, "r")
        self.errors = 0

    def decode(self, pes: Pes) -> list[Frame]:
        import av

        packet = av.Packet(pes.payload)
        if pes.pts is not None:
            packet.pts = pes.pts
        try:
            pictures = self.codec.decode(packet)
        except av.FFmpegError:
            self.errors += 1
            return []
        return _frames(pictures)

    def flush(self) -> list[Frame]:
        """The pictures the decoder still holds (the end of the stream: B-frames' reordering)."""
        import av

        try:
            return _frames(self.codec.decode(None))
        except av.FFmpegError:
            self.errors += 1
            return []


def _frames(pictures) -> list[Frame]:
    return [Frame(p.pts / 90_000.0, p.to_ndarray(format="rgb24")) for p in pictures if p.pts is not None]
