"""The archive's streaming reader (:func:`eoloc.io.klv.segments.klv_segments`) checked against the
tolerant reader on the whole file (the reference): the segments together are its packets, values,
VMTI targets, issues and notes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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
