"""A large raw KLV file in byte ranges, a task each, so that Dask workers share one recording
(issue 54): the ranges read on their own, then located from what the ranges before them leave, are
the whole file's reading and job; `eoloc batch` with ranges writes the same files on Dask as on
one process, with the rows of the batch without ranges. The reference: the tolerant reader and
the job on the whole file."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from klvsegments import job_tables, same_columns, sparse_flight, transport_stream

import eoloc
from eoloc.io.klv.columnar import columns_from_stream, read_klv_columns
from eoloc.io.klv.reader import read_klv
from eoloc.io.klv.segments import klv_segments
from eoloc.io.klv.synthetic import circling_flight_klv
from eoloc.jobs.batch import LAYERS, BatchSettings, batch_job
from eoloc.jobs.klv import klv_segment_jobs, stream_job

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"

def _ranges(path: Path, range_bytes: int) -> list[tuple[int, int]]:
    from eoloc.jobs.batch import Task, file_spans

    return file_spans(Task(str(path), None, "k"), range_bytes) or [(0, path.stat().st_size)]


@pytest.mark.parametrize("range_bytes", [5_000, 23_000, 10 ** 9])
def test_byte_ranges_read_on_their_own_are_the_whole_files_reading(tmp_path, range_bytes):
    """A raw KLV file (report-on-change, with garbage between packets and at the end) cut in byte
    ranges: each range starts where the tolerant reader, on the whole file, has just ended a good
    packet and starts the next; each range read on its own (first for its packet count and what a
    receiver knows at its end, then from what the ranges before it leave) gives together the
    whole reading's packets, numbers, offsets, values and issues, and the whole file's job."""
    from eoloc.io.klv.reader import split_klv
    from eoloc.jobs.klv import range_starts, range_summary

    packets = [p for p, _ in split_klv(sparse_flight(500, seed=4, slow=350))]  # height and FOV: packets 0, 350
    packets[320] = packets[320][:40] + bytes([packets[320][40] ^ 0x5A]) + packets[320][41:]  # a bad checksum
    path = tmp_path / "r.klv"
    path.write_bytes(b"".join(packets[:200]) + b"\x06\x0e\x2b\x34 noise " * 40 + b"".join(packets[200:]) + b"tail")
    ref = read_klv(path)
    ends = {p.offset + len(p.raw) for p in ref.packets} & {p.offset for p in ref.packets}
    spans = _ranges(path, range_bytes)
    assert (len(spans) > 10) == (range_bytes == 5_000)
    assert all(a in ends for a, _ in spans[1:]) and spans[-1][1] == path.stat().st_size
    summaries = [range_summary(path, sp, segment_bytes=3_000) for sp in spans]
    starts = range_starts(summaries)
    segs = [s for sp, st in zip(spans, starts, strict=True)
            for s in klv_segments(path, segment_bytes=3_000, span=sp, first_index=st.first_index)]
    ref_cols = columns_from_stream(ref)
    for name in ("index", "offset", "time_us", "present", "has_vmti"):
        np.testing.assert_array_equal(np.concatenate([getattr(s, name) for s in segs]), getattr(ref_cols, name), name)
    np.testing.assert_allclose(np.concatenate([s.values for s in segs]), ref_cols.values, rtol=0, atol=1e-9,
                               equal_nan=True)  # (the compiled decoder and the tolerant one: to ~1e-13)
    assert [i for s in segs for i in s.issues] == ref.issues
    assert sum(s[0] for s in summaries) == ref.n_good + ref.n_bad and ref.n_bad == 1
    whole = stream_job(path, read_klv_columns(path), map_layers=False, footprint_every=3)
    parts = [job for sp, st in zip(spans, starts, strict=True)
             for _, job in klv_segment_jobs(path, segment_bytes=3_000, footprint_every=3, span=sp, start=st) if job]
    for name, want in job_tables(whole).items():
        got = [job_tables(job)[name] for job in parts]
        same_columns({k: np.concatenate([g[k] for g in got]) for k in want}, want, name)


def _files(out: Path, layer: str) -> dict[str, pa.Table]:
    return {f"{p.parent.name}/{p.name}": pq.read_table(p) for p in sorted((out / layer).glob("file=*/*.parquet"))}


def test_a_large_file_in_byte_ranges_is_the_same_dataset_on_dask_and_in_one_process(tmp_path):
    """`eoloc batch` with files longer than the range size cut in byte ranges, a task each: on a
    2-worker Dask LocalCluster the same partition files as on one process, byte ranges and all;
    every layer's rows those of the batch without ranges; a transport stream and a short file stay
    whole; a second run skips the files (their manifests)."""
    from eoloc.accuracy.runners import dask_mapper
    from eoloc.io.klv.reader import split_klv

    src = tmp_path / "in"
    src.mkdir()
    (src / "sparse.klv").write_bytes(sparse_flight(700, seed=2))
    (src / "circling.klv").write_bytes(circling_flight_klv(500, seed=5) + b"\x00" * 3000)
    shutil.copy(MOUNTAIN / "flight.klv", src / "mountain.klv")
    transport_stream(src / "two.ts", [p for p, _ in split_klv(sparse_flight(120, seed=3))])
    noise = np.random.default_rng(3).integers(0, 256, 30_000, dtype=np.uint8).tobytes()
    flight = circling_flight_klv(200, seed=7)
    (src / "gap.klv").write_bytes(flight[:20_000] + noise + flight[20_000:])  # ranges of noise alone among them
    (src / "noise.klv").write_bytes(noise)  # no packet: failed, as without ranges
    size = (src / "mountain.klv").stat().st_size
    kw = {"footprint_every": 3, "segment_bytes": 8_000}
    whole = batch_job([str(src)], BatchSettings(str(tmp_path / "whole"), range_bytes=0, **kw))
    progress = []
    one = batch_job([str(src)], BatchSettings(str(tmp_path / "one"), range_bytes=6_000, **kw),
                    on_done=lambda part=1.0: progress.append(part))
    assert len(progress) > 20 and sum(progress) == pytest.approx(6)  # a range: its part of a file
    with dask_mapper("local:2") as m:
        dask = batch_job([str(src)], BatchSettings(str(tmp_path / "dask"), range_bytes=6_000, **kw), mapper=m)
    assert size > 6_000  # (the demo's flight is cut too)
    assert [r.status for r in whole.results] == ["done"] * 3 + ["failed"] + ["done"] * 2
    rows = [(r.key, r.status, r.packets, r.fixes, r.fixes_ok, r.issues, r.message) for r in whole.results]
    assert [(r.key, r.status, r.packets, r.fixes, r.fixes_ok, r.issues, r.message) for r in one.results] == rows
    assert [(r.key, r.status, r.packets, r.fixes, r.fixes_ok, r.issues, r.message) for r in dask.results] == rows
    for layer in LAYERS:
        a, b = _files(tmp_path / "one", layer), _files(tmp_path / "dask", layer)
        assert a.keys() == b.keys() and all(a[k].equals(b[k]) for k in a), layer
        ranged = {k.split("/")[0] for k in a if "/range-" in k}
        if layer != "issues":
            assert {k.split("-")[0] for k in ranged} == {"file=sparse", "file=circling", "file=mountain", "file=gap"}
        for key in {k.split("/")[0] for k in a}:  # the ranges' rows, in order, are the file's
            got = pa.concat_tables([a[k] for k in sorted(a) if k.startswith(key + "/")])
            want = pa.concat_tables([t for k, t in sorted(_files(tmp_path / "whole", layer).items())
                                     if k.startswith(key + "/")])
            assert got.equals(want), (layer, key)
    again = batch_job([str(src)], BatchSettings(str(tmp_path / "one"), range_bytes=6_000, **kw))
    assert [r.status for r in again.results] == ["skipped"] * 3 + ["failed"] + ["skipped"] * 2
