"""The movers eoloc found in a video, written back into it as MISB ST 0903 VMTI: the video and
its metadata streams copied packet for packet (PyAV, nothing decoded) into an MPEG-TS with one
more KLV stream (a PID of its own; asynchronous 'KLVA' carriage as FFmpeg writes it, each packet
a PES with the PTS of its frame), an ST 0601 packet for each frame where movers were found, its
tag 74 a VMTI set with one VTarget per mover: its track id, centroid pixel, bounding box and
ground location (Location pack, tag 17), tag 2 the frame's time from the metadata (the frame's
presentation time where it has none)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..errors import InputError


def write_movers_klv(video: str | Path, dest: str | Path, rows: list[dict], frame_pts_s: np.ndarray, width: int,
                     height: int) -> Path:
    """``video`` (any container PyAV reads) copied to the MPEG-TS ``dest`` with the movers
    ``rows`` (detections.csv's) as VMTI; ``frame_pts_s``: every frame's presentation time (s, the
    container's clock, as :func:`eoloc.io.videofile.frame_times` gives them)."""
    from fractions import Fraction

    import av

    from ..io.klv.demux import PTS_HZ
    from ..io.klv.encode import encode_uas_packet, encode_vmti

    if not rows:
        raise InputError("no mover to write: --klv-out needs movers found by --detect")
    by_frame: dict[int, list[dict]] = {}
    for r in rows:
        by_frame.setdefault(int(r["frame"]), []).append(r)
    frame_of = {round(float(t) * PTS_HZ): i for i, t in enumerate(frame_pts_s)}

    def packet_for(pts_s: float) -> bytes | None:
        i = frame_of.get(round(pts_s * PTS_HZ))
        here = by_frame.get(i, []) if i is not None else []
        if not here:
            return None
        targets = [(int(r["track_id"]), float(r["u_px"]), float(r["v_px"])) for r in here]
        boxes = {int(r["track_id"]): (r["bbox_u0"], r["bbox_v0"], r["bbox_u1"], r["bbox_v1"]) for r in here}
        where = {int(r["track_id"]): (r["lat_deg"], r["lon_deg"], r["h_m"]) for r in here if r["status"] == "OK"}
        utc = here[0].get("time_utc")
        when = datetime.fromisoformat(utc) if utc else datetime.fromtimestamp(pts_s, UTC)
        return encode_uas_packet({2: when, 74: encode_vmti(targets, width, height, boxes=boxes, locations=where)})

    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(video)) as src, av.open(str(dest), "w", format="mpegts") as out:
        vin = src.streams.video[0]
        copied = {vin.index: out.add_stream_from_template(vin)}
        for d in src.streams.data:
            copied[d.index] = out.add_data_stream(codec_name="klv")
        movers = out.add_data_stream(codec_name="klv")
        for pkt in src.demux(vin, *src.streams.data):
            if pkt.dts is None and pkt.pts is None:
                continue
            is_video = pkt.stream.index == vin.index
            pts = pkt.pts
            pkt.stream = copied[pkt.stream.index]
            out.mux(pkt)
            if is_video and pts is not None:
                raw = packet_for(float(pts * vin.time_base))
                if raw is not None:
                    mine = av.Packet(raw)
                    mine.stream = movers
                    mine.pts = mine.dts = round(float(pts * vin.time_base) * PTS_HZ)
                    mine.time_base = Fraction(1, PTS_HZ)
                    out.mux(mine)
    return dest
