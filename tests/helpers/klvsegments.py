"""The archive's streaming reader (:func:`eoloc.io.klv.segments.klv_segments`) checked against the
tolerant reader on the whole file (the reference): the segments together are its packets, values,
VMTI targets, issues and notes."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from eoloc.io.klv import encode_uas_packet, encode_vmti
from eoloc.io.klv.columnar import columns_from_stream
from eoloc.io.klv.reader import read_klv
from eoloc.io.klv.segments import klv_segments, merge_notes


def assert_segments_are_the_file(path: Path, segment_bytes: int, **kw) -> list:
    """The segments of ``path`` (``kw``: more of klv_segments' arguments), checked to be the whole
    file's reading; returns them."""
    ref = columns_from_stream(read_klv(path))
    segs = list(klv_segments(path, segment_bytes=segment_bytes, **kw))
    for name in ("index", "offset", "time_us", "present", "has_vmti", "stream", "standard"):
        np.testing.assert_array_equal(np.concatenate([getattr(s, name) for s in segs]), getattr(ref, name), name)
    np.testing.assert_array_equal(np.concatenate([s.pts_s for s in segs]), ref.pts_s, "pts_s")
    for name in ("values", "vmti_f"):
        got = np.concatenate([getattr(s, name) for s in segs])
        np.testing.assert_allclose(got, getattr(ref, name), rtol=0, atol=1e-9, equal_nan=True, err_msg=name)
    rows = np.cumsum([0] + [len(s) for s in segs])
    ti = np.concatenate([s.target_i + np.array([r] + [0] * 7) for s, r in zip(segs, rows, strict=False)])
    np.testing.assert_array_equal(ti, ref.target_i)
    assert [i for s in segs for i in s.issues] == ref.issues
    assert merge_notes([s.notes for s in segs]) == ref.notes
    assert {s.path for s in segs} == {ref.path} and {s.container for s in segs} == {ref.container}
    return segs


def sparse_flight(n: int, seed: int = 0, slow: int = 7) -> bytes:
    """A circling flight as an encoder that reports on change sends it: the slow items (height,
    fields of view) only every ``slow``-th packet (default 7), the frame centre every 11th, the VMTI
    frame size every 5th, some items in no packet until late in the stream."""
    rng = np.random.default_rng(seed)
    t0 = datetime(2026, 3, 1, tzinfo=UTC)
    out = []
    for k in range(n):
        phase = k / 300
        v = {2: t0 + timedelta(seconds=k / 30), 5: float((np.degrees(phase) + 90) % 360),
             6: float(rng.normal(0, 1)), 7: -8.0, 13: 40.0 + 0.03 * np.cos(phase), 14: -105.0 + 0.04 * np.sin(phase),
             18: 270.0, 19: -45.0 + float(rng.normal(0, 0.3)), 20: 0.0}
        if k % slow == 0:
            v |= {15: 3000.0, 16: 20.0, 17: 11.3}
        if k % 11 == 0 and k > 40:
            v |= {23: 40.0 + 0.03 * np.cos(phase) - 0.02, 24: -105.0 + 0.04 * np.sin(phase), 25: 1600.0}
        targets = [(j + 1, float(rng.uniform(50, 1200)), float(rng.uniform(50, 650))) for j in range(3)]
        vset = encode_vmti(targets, 1280, 720)
        v[74] = vset if k % 5 == 0 else _without_frame_size(targets)
        out.append(encode_uas_packet(v))
    return b"".join(out)


def _without_frame_size(targets) -> bytes:
    """A VMTI set whose targets are given by row and column only (no frame width, tags 8/9)."""
    from stanag4609.st0903 import VTargetData, encode_vmti_local_set

    packs = [VTargetData(tid, {19: round(v) + 1, 20: round(u) + 1}) for tid, u, v in targets]
    return encode_vmti_local_set({4: 5}, targets=packs)


def transport_stream(path: Path, packets: list[bytes], torn: bytes = b"") -> Path:
    """A video TS with two KLV PIDs (libavformat) carrying ``packets``, and ``torn`` after it."""
    from eoloc.io.klv.mux import write_klv_ts

    write_klv_ts(path, [[(p, k / 10) for k, p in enumerate(packets)],
                        [(p, k / 5) for k, p in enumerate(packets[: len(packets) // 3])]], video_fps=10)
    path.write_bytes(path.read_bytes() + torn)
    return path


def job_tables(job) -> dict[str, dict]:
    from eoloc.jobs.klv import frame_records, telemetry_records

    props, geoms = job.footprint_table
    return {"telemetry": telemetry_records(job.telemetry).columns, "fixes": job.records.columns,
            "frames": frame_records(job.telemetry, job.check).columns,
            "footprints": {**props.columns, "wkb": np.array(geoms.column.to_pylist(), object)}}


def same_columns(a: dict, b: dict, what: str) -> None:
    assert list(a) == list(b), what
    for k in a:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        if x.dtype.kind == "f":
            np.testing.assert_array_equal(x, y, err_msg=f"{what}.{k}")  # (NaN equal to NaN)
        else:
            assert x.tolist() == y.tolist(), f"{what}.{k}"
