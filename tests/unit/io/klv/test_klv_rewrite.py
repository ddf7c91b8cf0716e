"""KLV rewritten in place (the refined video's metadata, issue 52): an item re-encoded without
moving a byte of anything else, checked by stanag4609's decoder (checksum, values to one LSB), and
packets rewritten inside a transport stream in every carriage eoloc writes, the other cells byte
for byte."""

from __future__ import annotations

from datetime import UTC, datetime
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stanag4609.st0601 import FIELD_DEFINITIONS, SpecialValue, decode_uas_local_set

from eoloc.io.klv import read_klv
from eoloc.io.klv.encode import build_uas_packet, encode_uas_packet, replace_items, uas_items
from eoloc.io.klv.mux import add_klv, rewrite_klv_in_ts, write_klv_ts
from eoloc.io.klv.reader import split_klv
from eoloc.io.klv.synthetic import circling_flight_klv

RANGES = {5: (0.0, 360.0), 6: (-20.0, 20.0), 13: (-90.0, 90.0), 14: (-180.0, 180.0), 15: (-900.0, 19000.0),
          18: (0.0, 360.0), 19: (-180.0, 180.0), 20: (0.0, 360.0), 23: (-90.0, 90.0), 24: (-180.0, 180.0)}


def lsb(tag: int) -> float:
    d = FIELD_DEFINITIONS[tag]
    return float((d.physical_max - d.physical_min) / Fraction((1 << 8 * d.length) - 2))


def base_packet() -> bytes:
    return encode_uas_packet({2: datetime(2026, 11, 27, 12, 0, tzinfo=UTC), 3: "MISSION-7", 5: 10.0, 6: 1.0,
                              13: 40.0, 14: -105.0, 15: 2500.0, 18: 30.0, 19: -40.0, 20: 0.0, 23: 40.01,
                              24: -105.01})


@settings(max_examples=60, deadline=None)
@given(st.fixed_dictionaries({t: st.floats(lo, hi, allow_nan=False) for t, (lo, hi) in RANGES.items()}))
def test_replaced_items_decode_to_the_values_and_nothing_else_moves(values):
    old = base_packet()
    new = replace_items(old, {**values, 82: 40.0})  # tag 82 is not sent: not added
    assert len(new) == len(old)
    got = decode_uas_local_set(new)  # raises on a bad checksum
    for tag, v in values.items():
        x = float(got.value(tag))
        span = RANGES[tag][1] - RANGES[tag][0]
        d = abs(x - v) % span if tag in (5, 18, 20) else abs(x - v)  # 360 and 0 are one azimuth
        assert min(d, span - d if tag in (5, 18, 20) else d) <= lsb(tag), (tag, v, x)
    before, after = dict(uas_items(old)), dict(uas_items(new))
    assert set(before) == set(after)
    assert all(before[t] == after[t] for t in before if t not in values)


def test_an_error_value_and_what_cannot_be_rewritten_in_place():
    new = replace_items(base_packet(), {13: SpecialValue.RESERVED, 23: SpecialValue.OFF_EARTH})
    got = decode_uas_local_set(new)
    assert got.value(13) is SpecialValue.RESERVED and got.value(23) is SpecialValue.OFF_EARTH
    short = build_uas_packet([(2, (1_795_000_000_000_000).to_bytes(8, "big")), (13, b"\x10\x00")])  # 2-byte latitude
    with pytest.raises(ValueError, match="tag 13 is sent with 2 byte"):
        replace_items(short, {13: 41.0})
    with pytest.raises(ValueError):
        replace_items(base_packet()[:-10], {13: 41.0})  # cut short


def test_packets_rewritten_inside_a_transport_stream_in_every_carriage(tmp_path):
    """FFmpeg-style (0xFC with PTS), ST 1402 asynchronous (0xBD, timed by arrival) and synchronous
    (metadata access units) carriage, packets of ~250 bytes spread over two cells: each rewritten
    with a new latitude, every cell of every other PID byte for byte, every packet's time as it
    was (eoloc's reader) and valid for stanag4609."""
    packets = split_klv(circling_flight_klv(20))
    assert min(len(p) for p, _ in packets) > 184  # each spans two cells or more
    t0 = packets[0][1]
    plain = write_klv_ts(tmp_path / "ffmpeg.ts", [[(p, t - t0) for p, t in packets]], video_fps=10.0)
    sources = {"ffmpeg": plain}
    video = write_klv_ts(tmp_path / "video.ts", [], video_fps=10.0, duration_s=2.0)
    for carriage in ("async", "sync"):
        sources[carriage] = add_klv(video, tmp_path / f"{carriage}.ts",
                                    lambda n, _t: packets[n][0] if n < len(packets) else None, carriage=carriage)
    for name, path in sources.items():
        data = path.read_bytes()
        seen = []

        def rewrite(pid: int, raw: bytes, seen=seen) -> bytes:
            seen.append(raw)
            return replace_items(raw, {13: 10.0 + len(seen)})

        out, changed = rewrite_klv_in_ts(data, rewrite)
        assert changed == len(packets) == len(seen), name
        assert len(out) == len(data)
        a = np.frombuffer(data, np.uint8).reshape(-1, 188)
        b = np.frombuffer(out, np.uint8).reshape(-1, 188)
        pid = ((a[:, 1].astype(np.int64) & 0x1F) << 8) | a[:, 2]
        klv_pid = int(read_klv(path).packets[0].stream.removeprefix("PID "))
        assert np.array_equal(a[pid != klv_pid], b[pid != klv_pid]), name
        (tmp_path / f"{name}_new.ts").write_bytes(out)
        was, now = read_klv(path), read_klv(tmp_path / f"{name}_new.ts")
        assert len(now.packets) == len(packets) and not now.issues, (name, now.issues)
        assert [p.pts_s for p in now.packets] == [p.pts_s for p in was.packets]
        lat = [float(decode_uas_local_set(p.raw).value(13)) for p in now.packets]
        assert np.allclose(lat, 11.0 + np.arange(len(packets)), atol=lsb(13)), name


def test_what_is_not_a_transport_stream_is_refused(tmp_path):
    with pytest.raises(ValueError, match="188-byte cells"):
        rewrite_klv_in_ts(b"\x47" + bytes(200), lambda pid, raw: None)
