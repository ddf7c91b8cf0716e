"""A KLV file read and located in bounded segments (issue 54, the streaming batch): the segments
together are the whole file's reading, packet for packet, issue for issue (the reference: the
tolerant reader on the whole file); report-on-change, the VMTI frame size and every-n-th
footprints carry across the cuts; an MPEG-TS is read a chunk of its transport at a time, then PID by PID;
`eoloc batch` in small segments writes the same rows as in one (row groups of one GeoParquet file
per layer, read back by pyarrow and geopandas)."""

from __future__ import annotations

import random
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from klvsegments import assert_segments_are_the_file, job_tables, same_columns, sparse_flight, transport_stream

import eoloc
from eoloc.io.klv.columnar import read_klv_columns
from eoloc.io.klv.reader import packet_end, read_klv
from eoloc.io.klv.segments import klv_segments
from eoloc.io.klv.synthetic import circling_flight_klv
from eoloc.jobs.batch import LAYERS, BatchSettings, batch_job
from eoloc.jobs.klv import klv_segment_jobs, stream_job

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"


def damaged(data: bytes, seed: int) -> bytes:
    """Bytes flipped, cut out and put in at a few places."""
    rng = random.Random(seed)
    b = bytearray(data)
    for _ in range(8):
        at = rng.randrange(len(b))
        op = rng.choice(["flip", "cut", "insert"])
        if op == "flip":
            b[at] ^= rng.randrange(1, 256)
        elif op == "cut":
            del b[at:at + rng.randrange(1, 300)]
        else:
            b[at:at] = rng.randbytes(rng.randrange(1, 60))
    return bytes(b)


@pytest.mark.parametrize("segment_bytes", [3_000, 40_000, 10 ** 9])
def test_the_segments_are_the_whole_files_packets_issues_and_notes(tmp_path, segment_bytes):
    path = tmp_path / "f.klv"
    path.write_bytes(circling_flight_klv(700, seed=3) + b"\x00trailing")
    segs = assert_segments_are_the_file(path, segment_bytes)
    assert (len(segs) > 10) == (segment_bytes == 3_000)
    assert max(len(s) for s in segs) <= (20 if segment_bytes == 3_000 else 700)  # (~200 bytes a packet)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10 ** 6), segment_bytes=st.sampled_from([700, 2_500, 9_000]))
@example(seed=429, segment_bytes=700)  # a corrupt length past the end: its message once counted the segment's bytes
def test_damage_anywhere_gives_the_whole_files_reading(tmp_path_factory, seed, segment_bytes):
    """Cuts come only after a good packet, so a damaged packet is judged as in one reading:
    flipped, cut and inserted bytes give the same packets, issues (kinds, byte offsets) and notes.
    (Not where the whole file's reading put back the lost heads of keys: each segment decides that
    for itself, as the module says.)"""
    path = tmp_path_factory.mktemp("d") / "d.klv"
    data = damaged(sparse_flight(150, seed % 7), seed)
    path.write_bytes(data)
    whole = read_klv(path)
    assume(not any(n.kind == "damaged key" for n in whole.notes))
    # nor where a corrupt length ends inside the file past a cut (the module says so: "truncated" in
    # the segment, "checksum" in the whole reading)
    cuts = [int(s.offset[0]) for s in list(klv_segments(path, segment_bytes=segment_bytes))[1:] if len(s)]
    ends = [packet_end(data, i.offset)[0] for i in whole.issues if i.kind == "checksum"]
    assume(not any(e is not None and any(i.offset < c < e for c in cuts)
                   for i, e in zip([i for i in whole.issues if i.kind == "checksum"], ends, strict=True)))
    assert_segments_are_the_file(path, segment_bytes)


@pytest.mark.parametrize("chunk", [188, 188 * 7, 188 * 300, 10 ** 9])
@pytest.mark.parametrize("torn", [b"", b"\x47\x01\x02 cut off"])
def test_a_transport_stream_is_read_a_chunk_at_a_time(tmp_path, torn, chunk):
    """An MPEG-TS (two KLV PIDs, video, maybe ending mid-packet) read a chunk of its transport at a
    time (down to one transport packet: every PES and table then runs across cuts), each PID's
    bytes set aside, then given in segments: together the whole reading of the tolerant reader,
    the cut-off tail named in the first segment."""
    data = circling_flight_klv(90, seed=4)
    from eoloc.io.klv.reader import split_klv

    path = transport_stream(tmp_path / "two.ts", [p for p, _ in split_klv(data)], torn)
    segs = assert_segments_are_the_file(path, 2_000, ts_chunk_bytes=chunk)
    assert len(segs) > 5 and {s.container for s in segs} == {"mpegts"}
    streams = [str(x) for s in segs for x in dict.fromkeys(s.stream.tolist())]
    assert list(dict.fromkeys(streams)) == ["PID 257", "PID 258"]  # one PID after the other
    assert any("cut short" in i.message for i in segs[0].issues) == bool(torn)
    assert not any(s.issues for s in segs[1:])


def test_a_file_of_nothing_is_refused_as_the_reader_refuses_it(tmp_path):
    from eoloc.errors import KLVError

    (tmp_path / "e.klv").write_bytes(b"")
    (tmp_path / "n.klv").write_bytes(b"no key here " * 1000)
    for name in ("e.klv", "n.klv"):
        with pytest.raises(KLVError) as want:
            read_klv(tmp_path / name)
        with pytest.raises(KLVError) as got:
            list(klv_segments(tmp_path / name, segment_bytes=500))
        assert str(got.value) == str(want.value)


@pytest.mark.parametrize("every", [1, 3])
def test_the_segment_jobs_are_the_whole_files_job(tmp_path, every):
    """Report-on-change items sent every 7th/11th packet, VMTI frame sizes every 5th: the rows,
    fixes (located on the frame-centre elevation carried from packets of earlier segments) and
    every-3rd footprints of 29 segments are those of the job on the whole file."""
    path = tmp_path / "sparse.klv"
    path.write_bytes(sparse_flight(900))
    whole = stream_job(path, read_klv_columns(path), map_layers=False, footprint_every=every)
    parts = list(klv_segment_jobs(path, segment_bytes=4_000, footprint_every=every))
    assert len(parts) > 25 and all(job is not None for _, job in parts)
    for name, ref in job_tables(whole).items():
        got = [job_tables(job)[name] for _, job in parts]
        same_columns({k: np.concatenate([g[k] for g in got]) for k in ref}, ref, name)
    assert whole.records["status"].tolist().count("OK") > 2000  # (the carried frame centre and size at work)
    assert [str(i) for _, j in parts for i in j.issues] == [str(i) for i in whole.issues]


def _dataset(out: Path, layer: str) -> dict[str, pa.Table]:
    return {p.parent.name: pq.read_table(p) for p in sorted((out / layer).glob("file=*/part-*.parquet"))}


def test_the_batch_in_small_segments_writes_the_same_rows_as_in_one(tmp_path):
    import geopandas

    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(MOUNTAIN / "flight.klv", src / "mountain.klv")
    (src / "sparse.klv").write_bytes(sparse_flight(600, seed=2))
    (src / "circling.klv").write_bytes(circling_flight_klv(500, seed=5))
    (src / "damaged.klv").write_bytes(damaged(circling_flight_klv(400, seed=6), 11))
    from eoloc.io.klv.reader import split_klv

    transport_stream(src / "two.ts", [p for p, _ in split_klv(sparse_flight(120, seed=3))], b"\x47 cut")
    one = batch_job([str(src)], BatchSettings(str(tmp_path / "one"), footprint_every=2))
    small = batch_job([str(src)], BatchSettings(str(tmp_path / "small"), footprint_every=2, segment_bytes=5_000))
    assert [r.status for r in one.results] == ["done"] * 5
    assert [(r.packets, r.fixes, r.fixes_ok, r.issues) for r in small.results] == \
        [(r.packets, r.fixes, r.fixes_ok, r.issues) for r in one.results]
    for layer in LAYERS:
        a, b = _dataset(tmp_path / "one", layer), _dataset(tmp_path / "small", layer)
        assert a.keys() == b.keys()
        for key in a:
            assert a[key].equals(b[key]), (layer, key)
    many = next((tmp_path / "small" / "fixes").glob("file=sparse-*/part-0.parquet"))
    meta = pq.read_metadata(many)
    assert meta.num_row_groups > 5  # written as the segments came
    frame = geopandas.read_parquet(many)
    ref = geopandas.read_parquet(next((tmp_path / "one" / "fixes").glob("file=sparse-*/part-0.parquet")))
    assert frame.crs == ref.crs and frame.crs.to_epsg() == 4979
    np.testing.assert_allclose(frame.total_bounds, ref.total_bounds, rtol=0, atol=0)
    assert frame.geometry.equals(ref.geometry)
    for layer in ("fixes", "packets", "frames", "footprints"):  # types, CRS, bbox over every row group
        for key in _dataset(tmp_path / "one", layer):
            geo = [pq.read_schema(next((tmp_path / run / layer / key).glob("part-0.parquet"))).metadata[b"geo"]
                   for run in ("one", "small")]
            assert geo[0] == geo[1], (layer, key)


def test_a_layer_whose_columns_change_goes_on_in_a_second_file(tmp_path):
    import geopandas

    from eoloc.io.geotable import ParquetLayer
    from eoloc.io.records import Records

    layer = ParquetLayer(tmp_path / "fixes")
    layer.write(Records({"lat_deg": np.array([1.0, 2.0]), "lon_deg": np.array([3.0, 4.0]), "h_m": np.array([5.0, 6])}))
    layer.write(Records({"lat_deg": np.array([7.0]), "lon_deg": np.array([8.0]), "h_m": np.array([np.nan])}))
    layer.write(Records({"lat_deg": np.array([9.0]), "lon_deg": np.array([10.0]), "h_m": np.array([11.0]),
                         "id": np.array(["a"], dtype=object)}))
    parts = layer.close()
    assert [p.name for p in parts] == ["part-0.parquet", "part-1.parquet"]
    first = geopandas.read_parquet(parts[0])
    assert first["lat_deg"].tolist() == [1.0, 2.0, 7.0]
    assert [g.has_z for g in first.geometry] == [True, True, False]
    assert first.crs.to_epsg() == 4979 and list(first.total_bounds) == [3.0, 1.0, 8.0, 7.0]
    assert geopandas.read_parquet(parts[1])["id"].tolist() == ["a"]
    assert not list(tmp_path.glob("fixes/.*"))  # no temporary file left


def test_a_long_stretch_without_a_packet_is_cut_anyway_and_every_good_packet_kept(tmp_path):
    """20 MB of noise between good packets, read in 1 kB segments: the block is read on for a cut
    up to 16 MB, then cut anyway (memory bounded); every good packet kept with its file offset, the
    noise reported as skipped bytes, every byte of it, in more than one issue."""
    import numpy as np

    rng = np.random.default_rng(9)
    flight = circling_flight_klv(40, seed=8)
    noise = rng.integers(0, 256, 20_000_000, dtype=np.uint8).tobytes().replace(b"\x06\x0e", b"\x00\x00")
    path = tmp_path / "noisy.klv"
    path.write_bytes(flight + noise + flight)
    segs = list(klv_segments(path, segment_bytes=1_000))
    ref = read_klv(path)
    assert sum(len(s) for s in segs) == len(ref) == 80
    np.testing.assert_array_equal(np.concatenate([s.offset for s in segs]), [p.offset for p in ref.packets])
    skipped = [i for s in segs for i in s.issues if i.kind == "skipped bytes"]
    assert len(skipped) >= 2 and sum(int(i.message.split()[0]) for i in skipped) == len(noise)


def test_the_forced_cut_splits_no_key():
    from eoloc.io.klv.reader import UAS_KEY
    from eoloc.io.klv.segments import forced_cut

    block = b"\x00" * 1000 + UAS_KEY + b"\x01" * 500
    assert forced_cut(block) == 1000
    assert forced_cut(b"\x00" * 100) == 84  # (no key in it: 16 bytes before the end)


@pytest.mark.parametrize("range_bytes", [3_000, 17_000])
def test_a_byte_range_begins_where_a_good_packet_ends(tmp_path, range_bytes):
    """range_cut (where a byte range of a raw KLV file begins, for a task of its own): at a packet
    that the tolerant reader, on the whole file, reads right after a good one ending there; the
    same place whichever range asks; the file's end where no such place follows."""
    from eoloc.io.klv.reader import split_klv
    from eoloc.io.klv.segments import range_cut

    packets = [p for p, _ in split_klv(sparse_flight(300, seed=9))]
    for k in range(120, 220, 2):  # a stretch where every other packet fails its checksum
        packets[k] = packets[k][:30] + bytes([packets[k][30] ^ 0x11]) + packets[k][31:]
    path = tmp_path / "c.klv"
    path.write_bytes(b"".join(packets[:100]) + b"\x06\x0e\x2b\x34\x02 junk " * 300 + b"".join(packets[100:])
                     + b"\x06\x0e\x2b\x34 tail without a packet" * 50)
    ref = read_klv(path)
    data = path.read_bytes()
    ends = {p.offset + len(p.raw) for p in ref.packets}  # where a good packet ends ...
    ends = {e for e in ends if data[e:e + 16] == bytes.fromhex("060E2B34020B01010E01030101000000")}  # ... a key starts
    assert sum(i.kind == "checksum" for i in ref.issues) == 50
    size = path.stat().st_size
    with path.open("rb") as f:
        cuts = [range_cut(f, k) for k in range(0, size + range_bytes, range_bytes)]
        again = [range_cut(f, k, window=4_096) for k in range(0, size + range_bytes, range_bytes)]
    assert cuts == again and cuts[0] == 0 and cuts[-1] == size
    assert all(c in ends or c == size for c in cuts[1:])
    assert cuts == sorted(cuts) and len(set(cuts)) > 3
    last_good = max(ends)
    assert all(c == size for k, c in zip(range(0, size + range_bytes, range_bytes), cuts, strict=True)
               if k > last_good)
