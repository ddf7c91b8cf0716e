"""The columnar KLV reader (issue 54) against the tolerant one: the same packets, values (to a
fraction of one LSB), VMTI targets, issues and notes, on clean streams, the mutated-item corpus,
damaged framing, transport streams and the bundled samples; and the compiled scanner really
decodes the clean packets (so that a silent fall-back to the slow path would fail here too).

The reference is the tolerant reader (itself checked item by item against stanag4609 and jMISB's
vectors in test_klv_tolerant.py / test_conformance.py), put in columns by
``columns_from_stream``, which only copies each decoded value into its cell."""

from __future__ import annotations

import random
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from klvfuzz import mutated_packets
from where import DATA

import eoloc
from eoloc.io.klv import build_uas_packet, encode_eg0104, encode_uas_packet, encode_vmti, frame_uas_packet, uas_items
from eoloc.io.klv.columnar import (
    COLUMN,
    COLUMN_TAGS,
    KLVColumns,
    columns_from_stream,
    decode_klv_columns,
    read_klv_columns,
)
from eoloc.io.klv.localset import encode_items
from eoloc.io.klv.mux import write_klv_ts
from eoloc.io.klv.reader import VMTI_KEY, decode_klv_bytes, read_klv, split_klv
from eoloc.io.klv.st0601 import FIELDS, Mapped

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
SAMPLES = DATA / "klv"


def lsb(tag: int) -> float:
    """One LSB of an ST 0601 item's mapping (1 for an integer item)."""
    spec = FIELDS[tag][1]
    if isinstance(spec, Mapped):
        rmin, rmax, _ = spec.domain()
        return float((spec.hi - spec.lo) / (rmax - rmin))
    return 1.0


def assert_same(fast: KLVColumns, ref: KLVColumns) -> None:
    """Every column, issue and note equal; floats to 1e-6 of an LSB (the mapped values are
    computed in float64 by the scanner, exactly rounded from fractions by the reader)."""
    assert len(fast) == len(ref)
    for name in ("index", "offset", "stream", "standard", "time_us", "present", "has_vmti", "target_i"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(ref, name), err_msg=name)
    np.testing.assert_array_equal(np.isnan(fast.pts_s), np.isnan(ref.pts_s))
    np.testing.assert_array_equal(np.nan_to_num(fast.pts_s), np.nan_to_num(ref.pts_s))
    tol = 1e-6 * np.array([lsb(t) for t in COLUMN_TAGS])
    for name, atol in (("values", tol), ("vmti_f", 1e-9), ("target_f", 1e-9)):
        a, b = getattr(fast, name), getattr(ref, name)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
        assert np.all(np.abs(np.nan_to_num(a) - np.nan_to_num(b)) <= atol), name
    assert fast.issues == ref.issues
    assert fast.notes == ref.notes


def check(data: bytes, **kw) -> KLVColumns:
    fast = decode_klv_columns(data, "x.klv", **kw)
    assert_same(fast, columns_from_stream(decode_klv_bytes(data, "x.klv", **kw)))
    return fast


def pose_packets(n: int, *, vmti: int = 0, seed: int = 0) -> list[bytes]:
    """Packets as an encoder sends them (stanag4609's encoder), ``vmti`` targets each."""
    rng = np.random.default_rng(seed)
    t0 = datetime(2026, 1, 1, tzinfo=UTC)
    out = []
    for k in range(n):
        v = {2: t0 + timedelta(seconds=k / 30), 3: "COLUMNS", 5: float(rng.uniform(0, 360)),
             6: float(rng.uniform(-10, 10)), 7: float(rng.uniform(-30, 30)), 13: float(rng.uniform(-89, 89)),
             14: float(rng.uniform(-179, 179)), 15: float(rng.uniform(0, 9000)), 16: 2.5, 17: 1.4,
             18: float(rng.uniform(0, 360)), 19: float(rng.uniform(-170, 170)), 20: float(rng.uniform(0, 360)),
             21: float(rng.uniform(0, 20000)), 23: float(rng.uniform(-89, 89)), 24: float(rng.uniform(-179, 179)),
             25: 1890.0, **{t: float(rng.uniform(-0.07, 0.07)) for t in range(26, 34)}, 47: int(rng.integers(64)),
             65: 19, 75: float(rng.uniform(-800, 18000)), 90: float(rng.uniform(-89, 89)),
             91: float(rng.uniform(-89, 89))}
        if vmti:
            v[74] = encode_vmti([(j + 1, float(rng.uniform(0, 1279)), float(rng.uniform(0, 719)))
                                 for j in range(vmti)], 1280, 720)
        out.append(encode_uas_packet(v))
    return out


def test_clean_packets_are_decoded_by_the_scanner_to_the_tolerant_readers_values():
    for vmti in (0, 20):
        data = b"".join(pose_packets(400, vmti=vmti, seed=vmti))
        fast = check(data)
        assert len(fast) == 400 and fast.scanned == 400  # every packet on the fast path
        assert fast.present[:, [COLUMN[t] for t in (5, 13, 14, 90, 91)]].all()
        assert np.isfinite(fast.col(13)).all() and (fast.time_us > 0).all()
        assert len(fast.target_i) == 400 * vmti


def test_the_mutated_item_corpus_gives_the_same_values_issues_and_notes():
    """1 500 mutated packets (tests/helpers/klvfuzz.py: items replaced, cut, repeated, dropped,
    unknown tags added, VMTI sets mutated; checksums valid) among the mountain flight's packets:
    the scanner takes the packets it can vouch for, the tolerant reader the rest, and together
    they are the tolerant reader to the last note."""
    good = [raw for raw, _ in split_klv((MOUNTAIN / "flight.klv").read_bytes()) if decode_klv_bytes(raw).packets]
    bad = mutated_packets(good, 1_500, seed=54)
    rng = random.Random(54)
    mixed = good + bad
    rng.shuffle(mixed)
    fast = check(b"".join(mixed))
    assert len(fast) == len(mixed)
    assert len(good) <= fast.scanned < len(mixed)  # the clean ones fast, the mutated ones mostly not
    assert len(fast.notes) > 20


def _damaged_stream(rng: random.Random) -> bytes:
    """Clean packets with damage between and inside them: stray bytes, a cut packet, a wrong
    checksum, a lost key head, an EG 0104 packet, a stand-alone VMTI packet."""
    packets = pose_packets(60, vmti=3, seed=rng.randrange(1000))
    cut = packets[10][: len(packets[10]) // 2]
    wrong = bytearray(packets[20])
    wrong[-1] ^= 0x5A
    lost_head = packets[30][5:]
    eg = encode_eg0104({"User Defined Time Stamp": datetime(2026, 1, 1, tzinfo=UTC), "Platform Heading Angle": 12.5})
    vset = encode_items([(4, b"\x05"), (101, b"")])
    standalone = VMTI_KEY + bytes([len(vset)]) + vset
    parts = [*packets[:10], b"\x00garbage\xff", cut, *packets[11:20], bytes(wrong), *packets[21:30], lost_head,
             *packets[31:40], eg, standalone, *packets[40:], b"\x06\x0e\x2b"]
    return b"".join(parts)


def test_damaged_framing_gives_the_same_issues_and_keeps_every_good_packet():
    fast = check(_damaged_stream(random.Random(1)))
    kinds = {i.kind for i in fast.issues}
    assert {"skipped bytes", "checksum"} <= kinds
    assert fast.scanned >= 50 and set(fast.standard) >= {"ST 0601", "EG 0104", "ST 0903"}
    assert any(n.kind == "damaged key" for n in fast.notes)  # the lost key head put back, as the reader does


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_any_byte_level_damage_gives_what_the_tolerant_reader_gives(data):
    """Bytes flipped, cut out or put in anywhere in a clean stream with VMTI (checksums then
    fail, lengths run over, keys break): the same packets, values, issues and notes."""
    stream = bytearray(b"".join(pose_packets(12, vmti=2, seed=data.draw(st.integers(0, 50)))))
    for _ in range(data.draw(st.integers(1, 6))):
        at = data.draw(st.integers(0, len(stream) - 1))
        op = data.draw(st.sampled_from(["flip", "cut", "insert"]))
        if op == "flip":
            stream[at] ^= data.draw(st.integers(1, 255))
        elif op == "cut":
            del stream[at:at + data.draw(st.integers(1, 40))]
        else:
            stream[at:at] = data.draw(st.binary(min_size=1, max_size=40))
    check(bytes(stream))


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_any_item_level_change_with_a_valid_checksum_gives_the_same(data):
    """Items of a packet changed with the checksum made valid again (what reaches the item
    decoders): a value's length, its bytes, a repeated or missing item, the VMTI version and
    target count: the scanner declines or agrees, never differs."""
    packets = pose_packets(6, vmti=3, seed=data.draw(st.integers(0, 50)))
    k = data.draw(st.integers(0, 5))
    items = [(t, v) for t, v in uas_items(packets[k]) if t != 1]
    j = data.draw(st.integers(0, len(items) - 1))
    tag, value = items[j]
    op = data.draw(st.sampled_from(["bytes", "length", "repeat", "drop", "move", "long form"]))
    if op == "bytes":
        items[j] = (tag, data.draw(st.binary(min_size=len(value), max_size=len(value))))
    elif op == "length":
        items[j] = (tag, data.draw(st.binary(max_size=12)))
    elif op == "repeat":
        items.insert(data.draw(st.integers(0, len(items))), (tag, value))
    elif op == "drop":
        del items[j]
    elif op == "move":
        items.insert(data.draw(st.integers(0, len(items))), items.pop(j))
    if op == "long form":  # one item's length in 4-byte long form
        packets[k] = frame_uas_packet(encode_items(items[:j]) + encode_items(items[j:j + 1], long_form=True)
                                      + encode_items(items[j + 1:]))
    else:
        packets[k] = build_uas_packet(items)
    check(b"".join(packets))


def _vmti(version: bytes | None = b"\x05", *, count: bytes | None = None, target_items=None, long_pack=False) -> bytes:
    items = [] if version is None else [(4, version)]
    if count is not None:
        items.append((6, count))
    pack_items = target_items if target_items is not None else [(1, (641).to_bytes(3, "big")), (19, b"\x02")]
    body = b"\x01" + encode_items(pack_items, long_form=long_pack)  # target id 1, then its items
    pack = bytes([len(body)]) + body
    return encode_items([*items, (8, b"\x05\x00"), (101, pack)])


@pytest.mark.parametrize("what, items", [
    ("text in UTF-8 beyond ASCII", [(3, "Zürich".encode())]),
    ("text that is not UTF-8", [(3, b"\xff\xfeabc")]),
    ("a long-form length where short would do", "long"),
    ("VMTI LS version 3 (ST 0903.3's mappings)", [(74, _vmti(b"\x03"))]),
    ("VMTI without its LS version", [(74, _vmti(None))]),
    ("VMTI target count that disagrees", [(74, _vmti(count=b"\x02"))]),
    ("VMTI target pack with a long-form length", [(74, _vmti(long_pack=True))]),
    ("VMTI target item of the wrong length", [(74, _vmti(target_items=[(10, b"\x01\x02")]))]),
    ("VMTI location of 11 bytes", [(74, _vmti(target_items=[(17, bytes(11))]))]),
    ("an 8-byte pixel number past int64", [(74, _vmti(target_items=[(1, b"\xff" * 8)]))]),
    ("ST 1607 segment set", [(100, encode_items([(143, b"\x01"), (13, bytes(4))]))]),
    ("UAS LS version in 2 bytes", [(65, b"\x00\x13")]),
    ("generic flags past 63", [(47, b"\x80")]),
    ("time stamp past the year 9999", [(2, b"\xff" * 8)]),
    ("a tag of 3 BER-OID bytes", [(1 << 15, b"\x00")]),
])
def test_each_departure_goes_to_the_tolerant_reader(what, items):
    """Each departure the scanner must not decode itself (the reader notes it, or reads it its
    own way): that packet is declined, the clean ones around it still scanned, and the result is
    the reader's."""
    packets = pose_packets(3, seed=7)
    base = [(t, v) for t, v in uas_items(packets[1]) if t != 1]
    if items == "long":
        odd = frame_uas_packet(encode_items(base[:3]) + encode_items(base[3:4], long_form=True)
                               + encode_items(base[4:]))
    else:
        odd = build_uas_packet([*base, *items] if items[0][0] not in (2, 3) else
                               [*(it for it in items if it[0] == 2), *(x for x in base if x[0] != items[0][0]),
                                *(it for it in items if it[0] != 2)])
    fast = check(packets[0] + odd + packets[2])
    assert len(fast) == 3 and fast.scanned == 2, what


@pytest.mark.parametrize("name", sorted(p.name for p in SAMPLES.glob("*") if p.suffix in (".bin", ".klv")))
def test_the_bundled_samples_read_the_same(name):
    assert_same(read_klv_columns(SAMPLES / name), columns_from_stream(read_klv(SAMPLES / name)))


def test_a_transport_stream_reads_the_same_with_its_pts(tmp_path):
    """Two KLV PIDs in an MPEG-TS (libavformat): the same packets, PTS, streams and notes."""
    a = pose_packets(50, vmti=2, seed=3)
    b = pose_packets(30, seed=4)
    ts = write_klv_ts(tmp_path / "two.ts", [[(p, k / 10) for k, p in enumerate(a)],
                                            [(p, k / 10) for k, p in enumerate(b)]], video_fps=10)
    fast = read_klv_columns(ts)
    assert_same(fast, columns_from_stream(read_klv(ts)))
    assert len(fast) == 80 and fast.scanned == 80 and len(set(fast.stream)) == 2
    assert np.isfinite(fast.pts_s).all()


def test_the_control_packets_of_the_departures_are_scanned():
    """The departures' control: the same packets with a clean VMTI set (version 5, a target with
    a centroid pixel and row) are all taken by the scanner, their values the reader's."""
    packets = pose_packets(3, seed=7)
    base = [(t, v) for t, v in uas_items(packets[1]) if t != 1]
    fast = check(packets[0] + build_uas_packet([*base, (74, _vmti())]) + packets[2])
    assert fast.scanned == 3 and fast.target_i[:, [1, 2, 5]].tolist() == [[1, 641, 2]]


# -- a clean transport stream read in vectorised passes (demux.clean_klv_payloads) ------------------


def _same_ts_reading(data: bytes, path: str = "x.ts", chunks=(1, 5, 64)) -> bool:
    """Read the transport both ways (the vectorised path where it is clean, KLVDemux always):
    the same packets, values, issues and notes (or the same error); and a chunk of ``chunks``
    transport packets at a time: the vectorised path takes a chunked stream where it takes it
    whole, to the same bytes and marks, and the archive's streaming reader (the transport a chunk
    at a time, each PID set aside, then decoded in segments) is the whole reading. Returns whether
    the vectorised path was taken."""
    import tempfile

    from klvsegments import assert_segments_are_the_file

    from eoloc.errors import KLVError
    from eoloc.io.klv.demux import CleanTransport, clean_klv_payloads
    from eoloc.io.klv.reader import ts_klv_parts
    from eoloc.io.klv.segments import klv_segments

    def read(fast: bool):
        try:
            issues, parts = ts_klv_parts(data, path, strict=False, decode=decode_klv_bytes, fast=fast)
        except KLVError as exc:
            return str(exc)
        return issues, [(s.packets, s.issues, s.notes, arrival) for s, arrival in parts]

    whole_read = read(True)
    assert whole_read == read(False)
    whole = data[:len(data) - len(data) % 188]
    clean = clean_klv_payloads(whole)
    for n in chunks:
        t, got, step = CleanTransport(), {}, 188 * n
        for a in range(0, max(len(whole), 1), step):
            out = t.feed(whole[a:a + step], final=a + step >= len(whole))
            if out is None:
                break
            for p, (body, marks) in out.items():
                b, m = got.setdefault(p, (bytearray(), []))
                m += [(o + len(b), x) for o, x in marks]
                b += body
        else:
            assert clean is not None, f"{n}-packet chunks read as clean, the whole stream not"
            assert {p: (bytes(b), m) for p, (b, m) in got.items()} == clean[0] and t.by_arrival == clean[1]
            continue
        assert clean is None, f"{n}-packet chunks declined a stream read whole as clean"
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / path
        f.write_bytes(data)
        for n in chunks:
            if isinstance(whole_read, str):
                with pytest.raises(KLVError) as want:
                    read_klv(f)
                with pytest.raises(KLVError) as got:
                    list(klv_segments(f, segment_bytes=1_500, ts_chunk_bytes=188 * n))
                assert str(got.value) == str(want.value)
            else:
                assert_segments_are_the_file(f, 1_500, ts_chunk_bytes=188 * n)
    return clean is not None


@pytest.fixture(scope="module")
def transport_streams(tmp_path_factory):
    """A video TS with two KLV PIDs (PTS, libavformat), ST 1402 asynchronous carriage without PTS
    and synchronous carriage added by stanag4609's transformer (`eoloc mux`'s way)."""
    from eoloc.io.klv.mux import add_klv

    d = tmp_path_factory.mktemp("ts")
    a, b = pose_packets(40, vmti=2, seed=11), pose_packets(25, seed=12)
    two = write_klv_ts(d / "two.ts", [[(p, k / 10) for k, p in enumerate(a)], [(p, k / 5) for k, p in enumerate(b)]],
                       video_fps=10)
    plain = write_klv_ts(d / "plain.ts", [], video_fps=10, duration_s=3.0)
    made = {"two": two}
    for carriage in ("async", "sync"):
        made[carriage] = add_klv(plain, d / f"{carriage}.ts", lambda n, t: a[n % len(a)], carriage=carriage)
    return {k: v.read_bytes() for k, v in made.items()}


def test_a_clean_transport_stream_is_read_in_vectorised_passes_to_the_same_packets(transport_streams):
    assert _same_ts_reading(transport_streams["two"])  # PTS on every PES: the vectorised path
    assert _same_ts_reading(transport_streams["async"])  # ST 1402 without PTS: timed by arrival, the same
    assert not _same_ts_reading(transport_streams["sync"])  # synchronous carriage: KLVDemux's, as before
    cols = read_klv_columns_bytes(transport_streams["async"])
    assert any(n.kind == "timed by arrival" for n in cols.notes) and np.isfinite(cols.pts_s).all()


def read_klv_columns_bytes(data: bytes) -> KLVColumns:
    import tempfile

    with tempfile.NamedTemporaryFile(suffix=".ts") as f:
        f.write(data)
        f.flush()
        return read_klv_columns(f.name)


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_a_damaged_transport_stream_reads_the_same_either_way(data):
    """Bytes changed, cut or put in anywhere in a TS (a header, a table, a PES, a KLV packet, the
    video): the vectorised path declines what it cannot vouch for, and the result is KLVDemux's."""
    which = data.draw(st.sampled_from(["two", "async", "sync"]))
    ts = bytearray(_TS_CACHE.setdefault(which, _ts_bytes(which)))
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(ts) - 1))
        op = data.draw(st.sampled_from(["flip", "flip", "cut", "insert", "cell"]))
        if op == "flip":
            ts[at] ^= data.draw(st.integers(1, 255))
        elif op == "cut":
            del ts[at:at + data.draw(st.integers(1, 400))]
        elif op == "insert":
            ts[at:at] = data.draw(st.binary(min_size=1, max_size=200))
        else:  # a whole cell lost
            k = at // 188 * 188
            del ts[k:k + 188]
    _same_ts_reading(bytes(ts))


_TS_CACHE: dict[str, bytes] = {}


def _ts_bytes(which: str) -> bytes:
    import tempfile

    from eoloc.io.klv.mux import add_klv

    a = pose_packets(12, vmti=2, seed=21)
    with tempfile.TemporaryDirectory() as d:
        if which == "two":
            p = write_klv_ts(Path(d) / "two.ts", [[(x, k / 10) for k, x in enumerate(a)], [(x, k / 5) for k, x in
                                                                                        enumerate(a[:5])]],
                             video_fps=10)
        else:
            plain = write_klv_ts(Path(d) / "plain.ts", [], video_fps=10, duration_s=1.2)
            p = add_klv(plain, Path(d) / f"{which}.ts", lambda n, t: a[n % len(a)], carriage=which)
        return p.read_bytes()


def _klv_cells(ts: bytes) -> list[int]:
    """Offsets of the transport packets that start a KLV PES (PUSI set, PES start code, private
    stream 1 or metadata stream 0xFC), read from the bytes by hand."""
    out = []
    for k in range(0, len(ts) - 187, 188):
        c = ts[k:k + 188]
        start = 4 + (1 + c[4] if (c[3] >> 4) & 3 == 3 else 0)
        if c[1] & 0x40 and c[start:start + 3] == b"\x00\x00\x01" and c[start + 3] in (0xBD, 0xFC):
            out.append(k)
    return out


@pytest.mark.parametrize("which", ["two", "async"])
@pytest.mark.parametrize("damage", ["sync byte", "error flag", "PES length", "PTS marker"])
def test_each_transport_damage_reads_the_same_either_way(which, damage):
    """Each kind of damage the vectorised path must leave to KLVDemux, on a KLV PES's first cell."""
    ts = bytearray(_TS_CACHE.setdefault(which, _ts_bytes(which)))
    k = _klv_cells(bytes(ts))[3]
    start = k + 4 + (1 + ts[k + 4] if (ts[k + 3] >> 4) & 3 == 3 else 0)
    if damage == "sync byte":
        ts[k] = 0x46
    elif damage == "error flag":
        ts[k + 1] |= 0x80
    elif damage == "PES length":
        ts[start + 5] ^= 0x01
    elif which == "two":  # the PTS's first marker bit
        ts[start + 9] &= 0xFE
    else:  # (no PTS in asynchronous carriage: its header's marker bits '10' instead)
        ts[start + 6] &= 0x7F
    assert not _same_ts_reading(bytes(ts))


@pytest.mark.parametrize("which", ["two", "async"])
def test_pes_of_unbounded_length_run_to_the_next_one_in_chunks_too(which):
    """KLV PES that declare no length (0: the packet runs to the next PES start) are read the same
    whole, a chunk at a time (each held open across the cuts until the next one begins) and by
    KLVDemux; a stream ends the last one."""
    ts = bytearray(_TS_CACHE.setdefault(which, _ts_bytes(which)))
    for k in _klv_cells(bytes(ts)):
        start = k + 4 + (1 + ts[k + 4] if (ts[k + 3] >> 4) & 3 == 3 else 0)
        ts[start + 4:start + 6] = b"\x00\x00"
    assert _same_ts_reading(bytes(ts), chunks=(1, 2, 7, 64))


def _table_cells(ts: bytes, pid: int) -> list[int]:
    return [k for k in range(0, len(ts) - 187, 188) if ((ts[k + 1] & 0x1F) << 8 | ts[k + 2]) == pid]


@pytest.mark.parametrize("change", ["none", "counter jump", "duplicate", "table byte", "pmt byte", "pat dropped"])
def test_repeated_program_tables_read_once_give_the_same_either_way(change):
    """The vectorised path hands a repeated PAT/PMT packet to the table reader only once (its
    continuity counters renumbered to match): the same reading as KLVDemux's, packet by packet,
    when a table packet's counter jumps, a packet is sent twice, a table byte (CRC then wrong)
    changes, or a PAT is lost; and on a clean stream most table packets are left out."""
    import numpy as np

    from eoloc.io.klv.demux import TableRepeats

    ts = bytearray(_TS_CACHE.setdefault("two", _ts_bytes("two")))
    pats = _table_cells(bytes(ts), 0)
    pmt_pid = ((ts[pats[0] + 15] & 0x1F) << 8) | ts[pats[0] + 16]  # the first program's PMT PID in the PAT
    pmts = _table_cells(bytes(ts), pmt_pid)
    assert len(pats) > 5 and len(pmts) > 5
    if change == "counter jump":
        ts[pats[4] + 3] = (ts[pats[4] + 3] & 0xF0) | ((ts[pats[4] + 3] + 5) & 0x0F)
    elif change == "duplicate":
        k = pmts[3]
        ts[k + 188:k + 188] = ts[k:k + 188]
    elif change == "table byte":
        ts[pats[5] + 12] ^= 0x01
    elif change == "pmt byte":
        ts[pmts[4] + 20] ^= 0x10
    elif change == "pat dropped":
        del ts[pats[2]:pats[2] + 188]
    data = bytes(ts)
    fast = _same_ts_reading(data)
    if change == "none":
        assert fast
        cells = np.frombuffer(data, np.uint8).reshape(-1, 188)
        pid = ((cells[:, 1].astype(np.int64) & 0x1F) << 8) | cells[:, 2]
        rows = np.flatnonzero((pid == 0) | (pid == pmt_pid))
        repeats = TableRepeats(data, cells, pid, rows)
        assert sum(repeats.repeat) >= len(rows) - 4  # each table read once (and the rest left out)
