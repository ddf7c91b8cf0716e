"""Asynchronous KLV in MPEG-TS (ST 1402: stream_type 0x06 'KLVA', PES stream_id 0xBD, no PTS)
timed by the video frame it follows, on both of the reader's paths: the vectorised demultiplexer
of clean streams and the tolerant reader of damaged ones (issue 55: the reader's own test). The
transport stream is written here by hand from ISO/IEC 13818-1 (PAT, PMT with the registration
descriptor, PES headers, adaptation-field stuffing, the MPEG-2 CRC-32), not by eoloc or FFmpeg."""

from __future__ import annotations

import numpy as np
from klvfuzz import with_reserved_null_cell

from eoloc.io.klv import read_klv

# a real-shaped ST 0601 packet (time stamp, angles, position, a VMTI set), bytes as found by the
# live tests' property search
ST0601 = bytes.fromhex(
    "060e2b34020b01010e0103010100000065020800060a24181e40000502000006020000070200000d04000000000e0402"
    "d82d830f020b941002000011020000120400b60b611304c0000000140400000000170400000000180402d82d8319020a"
    "4b4101134a0c04010506010008010109010101023444")
VIDEO_PID, KLV_PID, PMT_PID = 0x101, 0x102, 0x100


def crc32_mpeg2(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for b in data:
        crc ^= b << 24
        for _ in range(8):
            crc = ((crc << 1) ^ 0x04C11DB7) if crc & 0x80000000 else crc << 1
            crc &= 0xFFFFFFFF
    return crc


def ts_packets(pid: int, payload: bytes, counters: dict) -> bytes:
    """The payload (a PES packet or a pointer field + section) cut into 188-byte TS packets, the
    first with payload_unit_start_indicator, the last filled by adaptation-field stuffing."""
    out = b""
    first = True
    while payload:
        chunk, payload = payload[:184], payload[184:]
        cc = counters.get(pid, 0)
        counters[pid] = (cc + 1) % 16
        head = bytes([0x47, (0x40 if first else 0) | pid >> 8, pid & 0xFF])
        if len(chunk) == 184:
            out += head + bytes([0x10 | cc]) + chunk
        else:
            n = 183 - len(chunk)  # the adaptation field's length byte counts what follows it
            field = bytes([n]) + (bytes([0x00]) + b"\xff" * (n - 1) if n else b"")
            out += head + bytes([0x30 | cc]) + field + chunk
        first = False
    return out


def section(table_id: int, ext: int, body: bytes) -> bytes:
    length = 5 + len(body) + 4
    sec = bytes([table_id, 0xB0 | length >> 8, length & 0xFF, ext >> 8, ext & 0xFF, 0xC1, 0, 0]) + body
    return b"\x00" + sec + crc32_mpeg2(sec).to_bytes(4, "big")


def pes(stream_id: int, payload: bytes, pts: int | None) -> bytes:
    if pts is None:
        header = bytes([0x80, 0x00, 0x00])
    else:
        header = bytes([0x80, 0x80, 0x05, 0x21 | (pts >> 29) & 0x0E, (pts >> 22) & 0xFF, 0x01 | (pts >> 14) & 0xFE,
                        (pts >> 7) & 0xFF, 0x01 | (pts << 1) & 0xFE])
    n = len(header) + len(payload)
    return bytes([0, 0, 1, stream_id]) + (n.to_bytes(2, "big") if stream_id != 0xE0 else b"\x00\x00") + header + payload


def transport_stream(frames: int = 12, fps: float = 10.0, start_pts: int = 90_000) -> tuple[bytes, np.ndarray]:
    """frames video PES (an H.264 access unit delimiter each) at fps, each followed by one KLV PES
    without PTS; (the bytes, each frame's PTS in seconds)."""
    cc: dict = {}
    pat = section(0x00, 1, (1).to_bytes(2, "big") + bytes([0xE0 | PMT_PID >> 8, PMT_PID & 0xFF]))
    streams = (bytes([0x1B, 0xE0 | VIDEO_PID >> 8, VIDEO_PID & 0xFF, 0xF0, 0x00])
               + bytes([0x06, 0xE0 | KLV_PID >> 8, KLV_PID & 0xFF, 0xF0, 0x06, 0x05, 0x04]) + b"KLVA")
    pmt = section(0x02, 1, bytes([0xE0 | VIDEO_PID >> 8, VIDEO_PID & 0xFF, 0xF0, 0x00]) + streams)
    out = ts_packets(0, pat, cc) + ts_packets(PMT_PID, pmt, cc)
    pts = start_pts + np.round(np.arange(frames) * 90_000 / fps).astype(np.int64)
    for p in pts:
        out += ts_packets(VIDEO_PID, pes(0xE0, b"\x00\x00\x00\x01\x09\xf0", int(p)), cc)
        out += ts_packets(KLV_PID, pes(0xBD, ST0601, None), cc)
    return out, pts / 90_000


def test_crc32_mpeg2_check_value():
    assert crc32_mpeg2(b"123456789") == 0x0376E6E7  # the CRC-32/MPEG-2 catalogue's check value


def test_asynchronous_klv_is_timed_by_the_frame_it_follows_on_both_paths(tmp_path):
    data, times = transport_stream()
    clean = tmp_path / "clean.ts"
    clean.write_bytes(data)
    back = read_klv(clean)
    assert len(back.packets) == times.size and all(p.raw == ST0601 for p in back.packets)
    np.testing.assert_allclose([p.pts_s for p in back.packets], times, atol=1.2e-5)
    assert any(n.kind == "timed by arrival" and n.count == times.size for n in back.notes)
    # a null packet with the reserved adaptation_field_control (00) halfway: the tolerant path
    damaged = tmp_path / "damaged.ts"
    damaged.write_bytes(with_reserved_null_cell(data))
    again = read_klv(damaged)
    assert [p.raw for p in again.packets] == [p.raw for p in back.packets]
    np.testing.assert_allclose([p.pts_s for p in again.packets], times, atol=1.2e-5)
