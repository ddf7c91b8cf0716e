"""KLV out: ST 0601 packets for synthetic streams (stanag4609's encoder, which writes the standard
strictly), fixes written into real packets item by item (stanag4609's item encoder for the
values, everything else kept as it came), and a raw builder for test streams that break the
standard on purpose."""

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


def frame_uas_packet(body: bytes, *, length_bytes: int = 0) -> bytes:
    """Key, length, the given item bytes and a checksum item with a valid bcc-16. ``length_bytes``
    > 0: the packet length in BER long form with that many bytes where it fits (as a packet being
    rewritten had it), else the shortest form."""
    n = len(body) + 4
    if 0 < length_bytes <= 8 and n < 1 << 8 * length_bytes:
        length = bytes((0x80 | length_bytes,)) + n.to_bytes(length_bytes, "big")
    else:
        length = encode_length(n)
    pkt = UAS_KEY + length + body + b"\x01\x02"
    return pkt + bcc16(pkt).to_bytes(2, "big")


def encode_vmti(targets: Iterable[tuple[int, float, float]], width: int, height: int, *,
                hfov_deg: float | None = None, vfov_deg: float | None = None,
                boxes: dict[int, tuple[float, float, float, float]] | None = None,
                locations: dict[int, tuple[float, float, float]] | None = None) -> bytes:
    """An ST 0903 VMTI local set (for ST 0601 tag 74) with one VTarget per (id, u_px, v_px)
    (eoloc pixel convention; written as 1-based centroid pixel number and row/column); ``boxes``:
    a bounding box (u0, v0, u1, v1) per target id (tags 2 and 3, clipped to the frame);
    ``locations``: the target's (lat deg, lon deg, HAE m) per id (tag 17, the Location pack)."""
    from stanag4609.st0903 import Location, VTargetData, encode_vmti_local_set

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
        if locations and tid in locations:
            lat, lon, hae = locations[tid]
            items[17] = Location(float(lat), float(lon), float(hae))
        packs.append(VTargetData(int(tid), items))
    values: dict[int, Any] = {4: 5, 8: int(width), 9: int(height)}
    if hfov_deg is not None:
        values[11] = float(hfov_deg)
    if vfov_deg is not None:
        values[12] = float(vfov_deg)
    return encode_vmti_local_set(values, targets=packs)


TARGET_TAGS = (40, 41, 42, 45, 46)  # target latitude, longitude, elevation, CE90, LE90


def with_target_location(packet: bytes, lat_deg: float, lon_deg: float, h_m: float, *, ce90_m: float | None = None,
                         le90_m: float | None = None) -> bytes:
    """The packet with a fix in the target location tags: 40 lat, 41 lon, 42 elevation (``h_m``
    must be in tag 42's datum: HAE when the packet stream sends tag 78, else MSL), 45 CE90 and 46
    LE90 (m, at most 4095). Re-encoded item by item, as eoloc reads: only those items and the
    checksum change. Every other item stays byte for byte in its place (a set that departs from
    the standard, such as an ST 0102 set missing a required item, stays as it came); a target tag
    the packet already sends is replaced where it stood (a repeated one once, where its last copy
    stood, which is the one receivers keep); one it lacks goes before the checksum; a CE90 or
    LE90 the packet sends and the fix has none for is left out (it was another fix's); the packet's
    length keeps its BER form. Each value is encoded by stanag4609's ST 0601 item encoder.
    ValueError when a value lies outside its tag's range (tag 42: -900 to 19 000 m) or the
    packet cannot be read item by item."""
    from stanag4609.st0601 import encode_field_value


    values: dict[int, float] = {40: float(lat_deg), 41: float(lon_deg), 42: float(h_m)}
    for tag, v in ((45, ce90_m), (46, le90_m)):
        if v is not None and np.isfinite(v):
            values[tag] = float(min(v, 4095.0))
    if not all(np.isfinite(v) for v in values.values()):
        raise ValueError("the fix has a NaN or infinite coordinate")
    new = {tag: encode_items([(tag, encode_field_value(tag, v))]) for tag, v in values.items()}
    items, _, start, _ = packet_items(packet)
    last = {tag: i for i, (tag, _) in enumerate(items)}
    body = bytearray()
    for i, (tag, raw) in enumerate(items):
        if tag == 1:
            continue  # the checksum: computed again, last
        body += (new.pop(tag, b"") if last[tag] == i else b"") if tag in TARGET_TAGS else raw
    body += b"".join(new.values())
    return frame_uas_packet(bytes(body), length_bytes=start - 17)  # the length's form as sent (0: short)


def packet_items(packet: bytes) -> tuple[list[tuple[int, bytes]], list[tuple[int, bytes]], int, int]:
    """A packet read item by item: its items as sent (tag, length and value bytes), the same as
    (tag, value), where its value starts and its end. ValueError when it cannot be read so (a
    bad length, an item cut short)."""
    from .localset import parse_items
    from .reader import packet_end

    end, start, why = packet_end(packet, 0)
    if end is None:
        raise ValueError(why)
    whole, notes = parse_items(packet, start, end, whole=True)
    if any(n.kind == "truncated item" for n in notes):
        raise ValueError(next(n.message for n in notes if n.kind == "truncated item"))
    return whole, parse_items(packet, start, end)[0], start, end


def replace_items(packet: bytes, values: dict[int, Any]) -> bytes:
    """The packet with the items of ``values`` ({tag: value in the standard's units, or one of
    stanag4609's ``SpecialValue``}) re-encoded in place by stanag4609's ST 0601 item encoder: only
    tags the packet already sends are written (each copy of a repeated one), everything else stays
    byte for byte, the checksum is computed again and the packet keeps its length (ST 0601's
    mapped items have a fixed size). ValueError when a value lies outside its tag's range, an item
    would change size (an encoder that sent a non-standard length) or the packet cannot be read
    item by item."""
    from stanag4609.st0601 import encode_field_value

    whole, items, start, end = packet_items(packet)
    sent = {t for t, _ in items}
    new = {tag: encode_field_value(tag, v) for tag, v in values.items() if tag in sent}
    body = bytearray()
    for (tag, item), (_, value) in zip(whole, items, strict=True):
        if tag == 1:
            continue  # the checksum: computed again, last
        if tag in new:
            if len(new[tag]) != len(value):
                raise ValueError(f"tag {tag} is sent with {len(value)} byte(s), the standard's size is "
                                 f"{len(new[tag])}")
            item = item[:len(item) - len(value)] + new[tag]  # its tag and length as sent
        body += item
    out = frame_uas_packet(bytes(body), length_bytes=start - 17)
    if len(out) != end:
        raise ValueError(f"the packet would change size ({end} -> {len(out)} bytes)")
    return out


def with_fix(packet: bytes, lat_deg: float, lon_deg: float, h_hae_m: float, *, ce90_m: float | None = None,
             le90_m: float | None = None, tag42_hae: bool) -> bytes | None:
    """The packet with a fix (ellipsoidal height) in its target location tags, tag 42 in the
    datum the stream gives it: HAE when ``tag42_hae`` (the stream sends tag 78), else MSL through
    the geoid. None when the fix cannot be written (a height outside tag 42's range, -900 to
    19 000 m) or the packet cannot be read item by item (:func:`with_target_location`); the
    caller passes such a packet on as it came and says how many. Used by `eoloc klv --klv-out`
    and `eoloc live --klv-out`."""
    h = float(h_hae_m)
    if not tag42_hae:
        from ...terrain.geoid import default_geoid

        h -= float(default_geoid().undulation(lat_deg, lon_deg))
    try:
        return with_target_location(packet, float(lat_deg), float(lon_deg), h, ce90_m=ce90_m, le90_m=le90_m)
    except ValueError:  # a value outside its tag's range, or a packet that cannot be read item by item
        return None
