"""KLV into MPEG-TS. :func:`add_klv` adds a KLV stream to a video's transport stream (one that
:func:`remux_video` brought into MPEG-TS) the way MISB ST 1402 specifies, asynchronous or
synchronous carriage (`eoloc mux`). :func:`write_klv_ts` writes what FFmpeg's muxer (libavformat,
through PyAV) writes, as most encoders in the field do: a 'KLVA' data stream (stream_type 0x06)
whose PES packets have stream_id 0xFC and a PTS each; for demos, tests and benchmarks that need a
stream as such an encoder sends it. eoloc reads all three (:func:`eoloc.io.klv.reader.read_ts_bytes`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path

import numpy as np

from .demux import PTS_HZ, TS_PACKET


def write_klv_ts(path: str | Path, streams: Sequence[Sequence[tuple[bytes, float]]], *, video_fps: float = 0.0,
                 video_size: tuple[int, int] = (160, 96), duration_s: float = 0.0,
                 frame_source: Callable[[int], np.ndarray] | None = None) -> Path:
    """Write ``streams`` as the KLV PIDs of one transport stream; each stream is a list of
    (raw packet, time s) pairs as :func:`eoloc.io.klv.reader.split_klv` gives them (its ST 0601
    time stamps) or as the caller chooses. Presentation times are those times relative to the
    earliest over all streams; a packet without one (NaN) takes the last time before it.
    ``video_fps`` > 0 adds an H.264 video stream over the same span whose frames show their own
    index (:func:`index_frame`), as an encoder's video beside its metadata, over the packets'
    span or ``duration_s``, whichever is longer (no streams and a duration: video alone).
    ``frame_source(i)``: the picture of frame i instead ((H, W) grey or (H, W, 3) RGB uint8)."""
    import av

    stamps = [np.array([t for _, t in s], dtype=np.float64) for s in streams]
    t0 = min((np.nanmin(t) for t in stamps if np.isfinite(t).any()), default=0.0)
    times = [np.nan_to_num(_hold(t - t0)) for t in stamps]
    order = sorted((float(t), k, i) for k, ts in enumerate(times) for i, t in enumerate(ts))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w", format="mpegts") as out:
        video = None
        if video_fps > 0:
            video = out.add_stream("libx264", rate=Fraction(video_fps).limit_denominator(1001))
            video.width, video.height = video_size
            video.pix_fmt = "yuv420p"
            video.options = {"preset": "ultrafast", "tune": "zerolatency", "crf": "16"}
            end = max(max((float(ts.max()) for ts in times if ts.size), default=0.0), duration_s - 1.0 / video_fps)
            order += [(j / video_fps, -1, j) for j in range(int(end * video_fps) + 1)]
            order.sort()
        pids = [out.add_data_stream(codec_name="klv") for _ in streams]
        for t, k, i in order:
            if k < 0:
                pic = frame_source(i) if frame_source is not None else index_frame(i, video_size)
                frame = av.VideoFrame.from_ndarray(pic, format="gray" if pic.ndim == 2 else "rgb24")
                frame.pts = i
                for vp in video.encode(frame.reformat(format="yuv420p")):
                    out.mux(vp)
                continue
            pkt = av.Packet(streams[k][i][0])
            pkt.stream = pids[k]
            pkt.pts = pkt.dts = round(t * PTS_HZ)
            pkt.time_base = Fraction(1, PTS_HZ)
            out.mux(pkt)
        if video is not None:
            for vp in video.encode(None):
                out.mux(vp)
    return path


def ts_cells(data: bytes) -> tuple[np.ndarray, np.ndarray, object]:
    """A transport stream's whole 188-byte cells (C, 188), each one's PID (C,) and a
    :class:`.demux.KLVDemux` that has read the program tables (PAT, then the PMTs): its
    ``video_pids`` and ``streams`` (the metadata PIDs)."""
    from .demux import KLVDemux

    cells = np.frombuffer(data, np.uint8)[:len(data) // TS_PACKET * TS_PACKET].reshape(-1, TS_PACKET)
    pids = (cells[:, 1].astype(np.int32) & 0x1F) << 8 | cells[:, 2]
    tables = KLVDemux()
    tables.feed_cells(cells[pids == 0].tobytes())
    tables.feed_cells(cells[np.isin(pids, list(tables.pmt_pids))].tobytes())
    return cells, pids, tables


def rewrite_klv_in_ts(data: bytes, rewrite: Callable[[int, bytes], bytes | None]) -> tuple[bytes, int]:
    """The transport stream ``data`` with its KLV packets rewritten in place: ``rewrite(pid, raw)``
    is called with each ST 0601 packet found whole in a metadata PID's payload bytes, in stream
    order, and gives the packet's new bytes (the same length) or None to leave it. Every other
    byte of the file stays as it was (video, tables, PES headers, timing), so the result plays
    and demultiplexes exactly as the input did. Returns the new bytes and how many packets changed.
    ValueError when the file is not a transport stream of whole 188-byte cells from its first byte."""
    from .reader import UAS_KEY, packet_end

    cells, pids, tables = ts_cells(data)
    if len(data) % TS_PACKET or not cells.size or not np.all(cells[:, 0] == 0x47):
        raise ValueError("not an MPEG-TS of whole 188-byte cells, each with its sync byte, from the first byte")
    out = np.frombuffer(bytearray(data), np.uint8)
    changed = 0
    for pid in sorted(tables.streams):
        idx = np.flatnonzero(pids == pid)
        sel = cells[idx]
        control = (sel[:, 3] >> 4) & 3  # adaptation_field_control: 1 payload, 2 adaptation, 3 both
        start = np.where(control == 3, 5 + sel[:, 4].astype(np.int64), 4)
        keep = ((control & 1) == 1) & (start < TS_PACKET) & ((sel[:, 1] & 0x80) == 0)  # no transport error
        idx, start = idx[keep], start[keep]
        sizes = TS_PACKET - start
        first = np.cumsum(sizes) - sizes
        offs = np.repeat(idx * TS_PACKET + start - first, sizes) + np.arange(int(sizes.sum()))
        buf = out[offs].tobytes()  # the PID's payload bytes; offs[i]: where byte i sits in the file
        k = buf.find(UAS_KEY)
        while k >= 0:
            end, _, _ = packet_end(buf, k)
            if end is None:
                k = buf.find(UAS_KEY, k + 1)
                continue
            new = rewrite(int(pid), buf[k:end])
            if new is not None and len(new) == end - k and new != buf[k:end]:
                out[offs[k:end]] = np.frombuffer(new, np.uint8)
                changed += 1
            k = buf.find(UAS_KEY, end)
    return out.tobytes(), changed


def add_klv(video_ts: str | Path, dest: str | Path, packet_for: Callable[[int, float], bytes | None], *,
            carriage: str = "async", pid: int = 0x1F1) -> Path:
    """Copy the transport stream ``video_ts`` to ``dest`` with a KLV metadata stream on ``pid``
    carried as MISB ST 1402 says: for each video access unit (n counts the video PES from 0,
    pts_s is its presentation time), ``packet_for(n, pts_s)`` gives the ST 0601 packet that goes
    with it, or None for none. Each packet is placed right after its frame's video data, before
    the next frame's begins.

    carriage "async": asynchronous carriage, stream_type 0x06 with the 'KLVA' registration
    descriptor, each packet a PES of stream_id 0xBD (private_stream_1) without PTS (a receiver
    times it by where it arrives: the video frame before it). "sync": synchronous carriage,
    stream_type 0x15 with the metadata and metadata STD descriptors, metadata access units of
    stream_id 0xFC with the frame's PTS. Video passes through byte for byte (stanag4609's
    transformer writes the new PMT and re-packetises around the new PID)."""
    from stanag4609.transport.metadata import asynchronous_klv_stream, synchronous_klv_stream
    from stanag4609.transport.processor import TimedKLVPacket
    from stanag4609.transport.psi import KLVCarriage
    from stanag4609.transport.transformer import LiveTransportTransformer

    from .demux import cell_pes_pts

    if carriage == "async":
        info, kind = asynchronous_klv_stream(pid), KLVCarriage.ASYNCHRONOUS
    elif carriage == "sync":
        info = synchronous_klv_stream(pid, metadata_input_leak_rate=1_000, metadata_buffer_size=200_000)
        kind = KLVCarriage.SYNCHRONOUS
    else:
        raise ValueError(f"carriage {carriage!r}: async or sync")
    transformer = LiveTransportTransformer(additional_metadata_stream=info)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    data = Path(video_ts).read_bytes()
    # where each frame begins (a cell starting a PES on a video PID), found over all cells at once:
    # the transformer is then fed a frame at a time, not a cell at a time
    cells, pids, tables = ts_cells(data)
    starts = np.flatnonzero((cells[:, 1] & 0x40).astype(bool) & np.isin(pids, list(tables.video_pids)))
    frame: tuple[int, int] | None = None  # (n, PTS) of the video PES being copied
    n = 0
    next_cc = 0  # the KLV PID's next continuity counter
    with dest.open("wb") as out:
        def packet() -> object | None:
            raw = packet_for(frame[0], frame[1] / PTS_HZ) if frame is not None else None
            if raw is None:
                return None
            sync = kind is KLVCarriage.SYNCHRONOUS
            return TimedKLVPacket.from_bytes(raw, program_number=transformer.program.program_number, pid=pid,
                                             carriage=kind, pts=frame[1] if sync else None,
                                             metadata_service_id=0 if sync else None, random_access=True)

        def emit() -> None:
            nonlocal next_cc
            pkt = packet()
            if pkt is not None:
                cells = transformer.emit_metadata(pkt).transport
                out.write(cells)
                next_cc = (cells[-TS_PACKET + 3] + 1) & 0x0F if cells else next_cc

        ends = [*starts[1:].tolist(), len(cells)]
        out.write(transformer.feed(data[:int(starts[0]) * TS_PACKET if starts.size else len(data)]).transport)
        for s, e in zip(starts.tolist(), ends, strict=True):
            cell = data[s * TS_PACKET:(s + 1) * TS_PACKET]
            # the transformer hands a PES on once it is complete: when the next one begins
            out.write(transformer.feed(cell).transport)
            emit()  # the previous frame's packet, after its video and before this frame's
            pts = cell_pes_pts(cell)
            frame = (n, pts) if pts is not None else None
            n += 1
            out.write(transformer.feed(data[(s + 1) * TS_PACKET:e * TS_PACKET]).transport)
        if kind is KLVCarriage.SYNCHRONOUS:  # timed by its PTS: before the last frame's video will do
            emit()
            out.write(transformer.finish().transport)
        else:  # after the last frame's video, which only finishing hands on: the PES written here
            from stanag4609.transport.mux import encode_pes_packet, packetize_pes

            out.write(transformer.finish().transport)
            last = packet()
            if last is not None:
                pes = encode_pes_packet(bytes(last.packet), stream_id=0xBD, data_alignment_indicator=True)
                out.write(b"".join(packetize_pes(pes, pid=pid, continuity_counter=next_cc)[0]))
    return dest


def remux_video(video_in: str | Path, dest: str | Path) -> Path:
    """The video of ``video_in`` (any container PyAV reads: MP4, MOV, TS) copied packet for packet
    into the MPEG-TS ``dest``, its presentation times kept, for :func:`add_klv`. H.264/HEVC from
    MP4/MOV is turned to Annex B on the way (the ``h264_mp4toannexb`` / ``hevc_mp4toannexb``
    bitstream filters); nothing is decoded."""
    import av
    from av.bitstream import BitStreamFilterContext

    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(video_in)) as src, av.open(str(dest), "w", format="mpegts") as out:
        vin = src.streams.video[0]
        vout = out.add_stream_from_template(vin)
        codec = vin.codec_context.name
        bsf = None
        if codec in ("h264", "hevc") and (vin.codec_context.extradata or b"")[:1] == b"\x01":  # avcC/hvcC: MP4 style
            bsf = BitStreamFilterContext(f"{codec}_mp4toannexb", vin, vout)
        for pkt in src.demux(vin):
            if pkt.dts is None and pkt.pts is None:
                continue
            for p2 in (bsf.filter(pkt) if bsf is not None else [pkt]):
                p2.stream = vout
                out.mux(p2)
        if bsf is not None:
            for p2 in bsf.filter(None):
                p2.stream = vout
                out.mux(p2)
    return dest


def index_frame(i: int, size: tuple[int, int] = (160, 96)) -> np.ndarray:
    """A grey frame (height, width) that shows its index ``i``: 16 bits as black/white blocks
    across the top row of blocks, most significant first, readable after lossy coding."""
    w, h = size
    img = np.full((h, w), 128, dtype=np.uint8)
    bw = w // 16
    for b in range(16):
        img[: h // 4, b * bw:(b + 1) * bw] = 255 if (i >> (15 - b)) & 1 else 0
    return img


def _hold(t: np.ndarray) -> np.ndarray:
    """NaN replaced by the last finite value before it (the first finite one at the start)."""
    t = np.asarray(t, dtype=np.float64).copy()
    ok = np.isfinite(t)
    if not ok.any():
        return np.zeros_like(t)
    idx = np.where(ok, np.arange(t.size), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(ok))
    idx[:first] = first
    return t[idx]
