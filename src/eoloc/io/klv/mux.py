"""KLV into MPEG-TS with libavformat (PyAV): one asynchronous KLV data stream (stream_type 0x06,
'KLVA') per list of packets, each packet a PES with its presentation time. For demos, tests and
benchmarks that need a transport stream as an encoder would send it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path

import numpy as np

PTS_HZ = 90_000
TS_BYTES = 188


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


def add_sync_klv(video_ts: str | Path, dest: str | Path, packet_for: Callable[[int, float], bytes | None], *,
                 pid: int = 0x1F1) -> Path:
    """Copy the transport stream ``video_ts`` to ``dest`` with a synchronous KLV metadata stream
    (ST 1402: stream_type 0x15, metadata access units) on ``pid``: after each video access unit,
    ``packet_for(n, pts_s)`` (n counts the video PES from 0, pts_s its presentation time) gives the
    ST 0601 packet carried with the same PTS, or None for none. Video passes through byte for
    byte (stanag4609's transformer re-packetises around the new PID)."""
    from stanag4609.transport.demux import PESStreamEvent, StreamKind, TransportDemuxer
    from stanag4609.transport.metadata import synchronous_klv_stream
    from stanag4609.transport.processor import TimedKLVPacket
    from stanag4609.transport.psi import KLVCarriage
    from stanag4609.transport.transformer import LiveTransportTransformer

    info = synchronous_klv_stream(pid, metadata_input_leak_rate=1_000, metadata_buffer_size=200_000)
    transformer = LiveTransportTransformer(additional_metadata_stream=info)
    observer = TransportDemuxer(max_programs=1)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    data = Path(video_ts).read_bytes()
    n = 0
    with dest.open("wb") as out:
        def emit(events) -> None:
            nonlocal n
            for ev in events:
                if not (isinstance(ev, PESStreamEvent) and ev.kind is StreamKind.VIDEO and ev.pes.pts is not None):
                    continue
                raw = packet_for(n, ev.pes.pts / PTS_HZ)
                n += 1
                if raw is None:
                    continue
                pkt = TimedKLVPacket.from_bytes(raw, program_number=transformer.program.program_number, pid=pid,
                                                carriage=KLVCarriage.SYNCHRONOUS, pts=ev.pes.pts,
                                                metadata_service_id=0, random_access=True)
                out.write(transformer.emit_metadata(pkt).transport)

        for k in range(0, len(data), 64 * TS_BYTES):
            chunk = data[k:k + 64 * TS_BYTES]
            events = observer.feed(chunk)
            out.write(transformer.feed(chunk).transport)
            emit(events)
        emit(observer.finish())
        out.write(transformer.finish().transport)
    return dest


def remux_with_klv(video_in: str | Path, dest: str | Path, packets: Sequence[tuple[bytes, float]]) -> Path:
    """The video of ``video_in`` (any container PyAV reads: MP4, MOV, TS) copied packet for packet
    into the MPEG-TS ``dest`` with one asynchronous KLV data stream (stream_type 0x06, 'KLVA'):
    each (raw ST 0601 packet, time s) at that presentation time on the video's own clock (the
    video's PTS, in seconds). H.264/HEVC from MP4/MOV is turned to Annex B on the way (the
    ``h264_mp4toannexb`` / ``hevc_mp4toannexb`` bitstream filters); nothing is decoded."""
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
        data = out.add_data_stream(codec_name="klv")
        tb = vin.time_base
        queue = sorted(((round(t / tb), raw) for raw, t in packets), key=lambda x: x[0])
        q = 0

        def klv_until(pts: int | None) -> None:
            nonlocal q
            while q < len(queue) and (pts is None or queue[q][0] <= pts):
                pkt = av.Packet(queue[q][1])
                pkt.stream = data
                pkt.pts = pkt.dts = queue[q][0]
                pkt.time_base = tb
                out.mux(pkt)
                q += 1

        for pkt in src.demux(vin):
            if pkt.dts is None and pkt.pts is None:
                continue
            klv_until(pkt.dts if pkt.dts is not None else pkt.pts)
            for p2 in (bsf.filter(pkt) if bsf is not None else [pkt]):
                p2.stream = vout
                out.mux(p2)
        if bsf is not None:
            for p2 in bsf.filter(None):
                p2.stream = vout
                out.mux(p2)
        klv_until(None)
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
