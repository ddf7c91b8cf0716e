"""KLV out: ST 0601 packets for synthetic streams and re-encoded fixes (stanag4609's encoder, which
writes the standard strictly), and a raw builder for test streams that break it on purpose."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from .localset import encode_items, encode_length
from .reader import UAS_KEY, bcc16


def encode_uas_packet(values: dict[int, Any]) -> bytes:
    """One ST 0601 packet from {tag: value} in the standard's units (degrees, metres, datetime
    for tag 2); the checksum is computed. Tag 65 (LS version) defaults to 19."""
    from stanag4609.st0601 import encode_uas_local_set

    return encode_uas_local_set({65: 19, **values})


def uas_items(packet: bytes) -> list[tuple[int, bytes]]:
    """The (tag, value) items of a well-formed ST 0601 packet, checksum item left out."""
    from .localset import parse_items
    from .reader import packet_end

    end, start, why = packet_end(packet, 0)
    if end is None:
        raise ValueError(why)
    items, _ = parse_items(packet, start, end)
    return [(t, v) for t, v in items if t != 1]


def build_uas_packet(items: Iterable[tuple[int, bytes]], *, long_form: bool = False) -> bytes:
    """An ST 0601 packet from raw (tag, value) items exactly as given (order, duplicates, long-form
    lengths: for test streams that depart from the standard), with a valid checksum."""
    return frame_uas_packet(encode_items(items, long_form=long_form))


def frame_uas_packet(body: bytes) -> bytes:
    """Key, length, the given item bytes and a checksum item with a valid bcc-16."""
    pkt = UAS_KEY + encode_length(len(body) + 4) + body + b"\x01\x02"
    return pkt + bcc16(pkt).to_bytes(2, "big")


def encode_vmti(targets: Iterable[tuple[int, float, float]], width: int, height: int, *,
                hfov_deg: float | None = None, vfov_deg: float | None = None,
                boxes: dict[int, tuple[float, float, float, float]] | None = None) -> bytes:
    """An ST 0903 VMTI local set (for ST 0601 tag 74) with one VTarget per (id, u_px, v_px)
    (eoloc pixel convention; written as 1-based centroid pixel number and row/column); ``boxes``:
    a bounding box (u0, v0, u1, v1) per target id (tags 2 and 3, clipped to the frame)."""
    from stanag4609.st0903 import VTargetData, encode_vmti_local_set

    def number(u: float, v: float) -> int:
        col, row = min(max(round(u), 0), width - 1) + 1, min(max(round(v), 0), height - 1) + 1
        return (row - 1) * width + col

    packs = []
    for tid, u, v in targets:
        col, row = round(u) + 1, round(v) + 1
        if not (1 <= col <= width and 1 <= row <= height):
            continue
        items = {1: (row - 1) * width + col, 19: row, 20: col}
        if boxes and tid in boxes:
            u0, v0, u1, v1 = boxes[tid]
            items |= {2: number(u0, v0), 3: number(u1, v1)}
        packs.append(VTargetData(int(tid), items))
    values: dict[int, Any] = {4: 5, 8: int(width), 9: int(height)}
    if hfov_deg is not None:
        values[11] = float(hfov_deg)
    if vfov_deg is not None:
        values[12] = float(vfov_deg)
    return encode_vmti_local_set(values, targets=packs)


def with_target_location(packet: bytes, lat_deg: float, lon_deg: float, h_m: float, *, ce90_m: float | None = None,
                         le90_m: float | None = None) -> bytes:
    """The packet re-encoded with a fix in the target location tags: 40 lat, 41 lon, 42 elevation
    (``h_m`` must be in tag 42's datum: HAE when the packet stream sends tag 78, else MSL), 45
    CE90 and 46 LE90 (m). Every other item is kept byte for byte; the checksum is recomputed."""
    from stanag4609.st0601 import update_uas_local_set

    upd: dict[int, Any] = {40: float(lat_deg), 41: float(lon_deg), 42: float(h_m)}
    if ce90_m is not None and np.isfinite(ce90_m):
        upd[45] = float(min(ce90_m, 4095.0))
    if le90_m is not None and np.isfinite(le90_m):
        upd[46] = float(min(le90_m, 4095.0))
    return update_uas_local_set(packet, upd)


def with_fix(packet: bytes, lat_deg: float, lon_deg: float, h_hae_m: float, *, ce90_m: float | None = None,
             le90_m: float | None = None, tag42_hae: bool) -> bytes | None:
    """The packet with a fix (ellipsoidal height) in its target location tags, tag 42 in the
    datum the stream gives it: HAE when ``tag42_hae`` (the stream sends tag 78), else MSL through
    the geoid. None when stanag4609 cannot re-encode the packet (it breaks ST 0601 in a way its
    encoder refuses); the caller passes such a packet on as it came. Used by `eoloc klv --klv-out`
    and `eoloc live --klv-out`."""
    from stanag4609.errors import Stanag4609Error

    h = float(h_hae_m)
    if not tag42_hae:
        from ...terrain.geoid import default_geoid

        h -= float(default_geoid().undulation(lat_deg, lon_deg))
    try:
        return with_target_location(packet, float(lat_deg), float(lon_deg), h, ce90_m=ce90_m, le90_m=le90_m)
    except Stanag4609Error:
        return None
