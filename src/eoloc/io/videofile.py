"""Video in (PyAV / FFmpeg): a file's video stream described and decoded frame by frame, each
frame with its presentation time on the transport's 90 kHz clock, so it can be paired with the
KLV packets of the same file (whose PES carry times on that clock, :mod:`eoloc.io.klv.reader`).

A frame's time is ``pts × time_base`` as FFmpeg gives it (for MPEG-TS the raw PTS / 90 000, the
same number the KLV reader gives a metadata PES). Frames come in presentation order with their
index in the file (0, 1, ...). Colour video decodes to RGB, grey formats (IR) to one band at their
own depth (8 or 16 bits). The decoder recovers from damaged packets as FFmpeg does; what it cannot
decode is counted, never raised, unless no frame at all can be read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import VideoError


@dataclass(frozen=True)
class VideoInfo:
    """A video stream: size (pixels), nominal frame rate (frames/s, 0 when the container does not
    say), frame count when the container says (else 0), duration (s, 0 when unknown), codec name,
    the first frame's time (s, on the stream's clock) and the container's format name."""

    path: str
    width: int
    height: int
    fps: float
    n_frames: int
    duration_s: float
    codec: str
    start_s: float
    container: str


@dataclass(frozen=True)
class VideoFrame:
    """One decoded frame: its index in the file, presentation time (s, stream clock) and pixels
    (H, W, 3) uint8 RGB or (H, W) grey (uint8 or uint16), or None when not asked for."""

    index: int
    pts_s: float
    image: np.ndarray | None


def _open(path: str | Path):
    import av

    p = Path(path)
    if not p.is_file():
        raise VideoError(f"video {str(path)!r} does not exist (or is not a file)")
    try:
        container = av.open(str(p))
    except (av.FFmpegError, OSError, UnicodeDecodeError) as exc:
        raise VideoError(f"video {str(path)!r} cannot be opened by FFmpeg: {exc}") from None
    if not container.streams.video:
        container.close()
        raise VideoError(f"{path}: no video stream in it (FFmpeg sees: "
                         f"{', '.join(s.type for s in container.streams) or 'nothing'})")
    return container


def probe_video(path: str | Path) -> VideoInfo:
    """The first video stream of ``path`` as the container describes it (nothing decoded)."""
    with _open(path) as c:
        v = c.streams.video[0]
        tb = float(v.time_base) if v.time_base else 0.0
        rate = v.average_rate or v.base_rate or v.guessed_rate
        dur = float(v.duration * tb) if v.duration else (c.duration / 1e6 if c.duration else 0.0)
        return VideoInfo(str(path), int(v.codec_context.width), int(v.codec_context.height),
                         float(rate) if rate else 0.0, int(v.frames or 0), dur, v.codec_context.name,
                         float(v.start_time * tb) if v.start_time is not None else 0.0, c.format.name)


def frame_times(path: str | Path) -> np.ndarray:
    """Presentation times (s) of every frame of the first video stream, in order, read from the
    container's packets without decoding (packets without a time are left out)."""
    with _open(path) as c:
        v = c.streams.video[0]
        tb = v.time_base
        pts = [p.pts for p in c.demux(v) if p.pts is not None and p.size]
    # pts x num / den: the same correctly rounded seconds as the KLV reader's PTS / 90 000
    return np.sort(np.array(pts, dtype=np.float64)) * tb.numerator / tb.denominator


def _pixel_format(frame) -> str:
    name = frame.format.name
    if name.startswith("gray"):
        return "gray16le" if "16" in name or "10" in name or "12" in name or "14" in name else "gray"
    return "rgb24"


def iter_frames(path: str | Path, *, want: Callable[[int, float], bool] | None = None,
                errors: list[str] | None = None) -> Iterator[VideoFrame]:
    """Every frame of the first video stream in presentation order. ``want(index, pts_s)``: decode
    pixels only for the frames it accepts (the others come with ``image`` None, their time only).
    Packets the decoder refuses are noted in ``errors`` (when given) and skipped."""
    import av

    with _open(path) as c:
        v = c.streams.video[0]
        v.thread_type = "AUTO"
        tb = v.time_base
        index = 0
        last_pts = None
        for packet in c.demux(v):
            try:
                frames = packet.decode()
            except av.FFmpegError as exc:
                if errors is not None:
                    errors.append(f"{path}: a video packet at {_when(packet, tb)} cannot be decoded ({exc}); "
                                  "skipped")
                continue
            for frame in frames:
                pts = frame.pts if frame.pts is not None else (last_pts + 1 if last_pts is not None else 0)
                last_pts = pts
                t = float(pts * tb)
                image = None
                if want is None or want(index, t):
                    image = frame.to_ndarray(format=_pixel_format(frame))
                yield VideoFrame(index, t, image)
                index += 1
        if index == 0:
            raise VideoError(f"{path}: not one video frame could be decoded")


def _when(packet, tb) -> str:
    return f"{float(packet.pts * tb):.3f} s" if packet.pts is not None else f"byte {packet.pos}"


BROWSER_CODECS = ("h264",)  # what every browser's <video> plays inside MP4


def browser_video(path: str | Path, dest: str | Path, *, first_pts_s: float | None = None) -> tuple[Path, str]:
    """The first video stream of ``path`` as an MP4 a browser plays, its first frame at time 0:
    H.264 is remuxed (packets copied, nothing re-encoded), anything else (MPEG-2, HEVC, ...) is
    transcoded with x264 (no B-frames, every frame at its own time). ``first_pts_s``: the time
    that becomes 0 (default: the first frame's). Returns (dest, "remuxed" | "transcoded")."""
    import av

    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    if first_pts_s is None:
        times = frame_times(path)
        first_pts_s = float(times[0]) if times.size else 0.0
    with _open(path) as src:
        v = src.streams.video[0]
        remux = v.codec_context.name in BROWSER_CODECS
        with av.open(str(dest), "w", format="mp4", options={"movflags": "+faststart"}) as out:
            if remux:
                o = out.add_stream_from_template(v)
                shift = round(first_pts_s / v.time_base)
                for packet in src.demux(v):
                    if packet.dts is None and packet.pts is None:
                        continue  # the demuxer's flush packet
                    if packet.pts is not None:
                        packet.pts -= shift
                    if packet.dts is not None:
                        packet.dts -= shift
                    packet.stream = o
                    out.mux(packet)
            else:
                o = out.add_stream("libx264", rate=v.average_rate or v.guessed_rate or 25)
                o.width, o.height, o.pix_fmt = v.codec_context.width, v.codec_context.height, "yuv420p"
                o.time_base = v.time_base
                o.options = {"crf": "18", "preset": "veryfast", "bf": "0"}
                o.codec_context.time_base = v.time_base
                shift = round(first_pts_s / v.time_base)
                for packet in src.demux(v):
                    try:
                        frames = packet.decode()
                    except av.FFmpegError:
                        continue  # eoloc video names undecodable packets; the player shows what decodes
                    for frame in frames:
                        if frame.pts is None:
                            continue
                        out_frame = frame.reformat(format="yuv420p")
                        out_frame.pts = frame.pts - shift
                        out_frame.time_base = v.time_base
                        out.mux(o.encode(out_frame))
                out.mux(o.encode(None))
    return dest, "remuxed" if remux else "transcoded"
