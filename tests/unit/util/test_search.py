"""eoloc.util.search.searchsorted against numpy's own searchsorted: the same position for every query,
whatever the keys' spacing (steady, bunched, repeated, integers, huge magnitudes) and the queries
(the keys themselves, between them, outside their range, non-finite)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from eoloc.util import search


def _keys(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    if kind == "steady":  # telemetry at a fixed rate, with jitter
        return np.sort(np.arange(n) * 0.04 + rng.normal(0, 0.002, n))
    if kind == "bunched":  # most keys in a few bursts
        return np.sort(np.concatenate([rng.normal(c, 0.01, n // 4) for c in rng.uniform(0, 100, 4)]
                                      + [rng.uniform(0, 100, n - 4 * (n // 4))]))
    if kind == "repeated":  # many equal keys (frames carried by several records)
        return np.sort(rng.integers(0, max(n // 8, 2), n)).astype(np.float64)
    if kind == "ints":
        return np.sort(rng.integers(-10**6, 10**6, n))
    if kind == "huge":  # integers where float64 cannot resolve the buckets
        return np.sort(rng.integers(2**62, 2**62 + 10 * n, n))
    return np.sort(rng.exponential(1.0, n))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["steady", "bunched", "repeated", "ints", "huge", "exp"]),
       n=st.integers(2, 3000), m=st.integers(4096, 20000), side=st.sampled_from(["left", "right"]))
def test_searchsorted_equals_numpy(seed: int, kind: str, n: int, m: int, side: str) -> None:
    rng = np.random.default_rng(seed)
    keys = _keys(rng, kind, n)
    span = float(keys[-1] - keys[0]) or 1.0
    if keys.dtype.kind == "i":
        q = np.concatenate([keys[rng.integers(0, n, m // 2)],
                            rng.integers(int(keys[0]) - 5, int(keys[-1]) + 6, m - m // 2)])
    else:
        q = np.concatenate([keys[rng.integers(0, n, m // 3)],  # exact hits: where left and right differ
                            rng.uniform(keys[0] - 0.1 * span, keys[-1] + 0.1 * span, m // 3),
                            np.nextafter(keys[rng.integers(0, n, m - 2 * (m // 3) - 6)], np.inf),
                            [np.nan, np.inf, -np.inf, keys[0], keys[-1], -0.0]])
    rng.shuffle(q)
    got = search.searchsorted(keys, q, side=side)
    want = np.searchsorted(keys, q, side=side)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_few_queries_and_degenerate_keys_take_numpy() -> None:
    keys = np.array([3.0, 3.0, 3.0])
    q = np.linspace(2, 4, 5000)
    np.testing.assert_array_equal(search.searchsorted(keys, q), np.searchsorted(keys, q))
    np.testing.assert_array_equal(search.searchsorted(np.arange(5.0), [2.0, 2.5]), [2, 3])


def test_steady_keys_answer_without_numpy_binary_search_per_query(monkeypatch) -> None:
    """The fast path really runs for telemetry at a steady rate: numpy's search only places the
    bucket starts (n + 1 sorted values), never the 10^5 queries."""
    rng = np.random.default_rng(3)
    keys = _keys(rng, "steady", 2000)
    q = rng.uniform(keys[0], keys[-1], 100_000)
    want = np.searchsorted(keys, q)
    sizes = []
    real = np.searchsorted

    def counting(a, v, *args, **kwargs):
        sizes.append(np.size(v))
        return real(a, v, *args, **kwargs)

    monkeypatch.setattr(search.np, "searchsorted", counting)
    np.testing.assert_array_equal(search.searchsorted(keys, q), want)
    assert sizes == [keys.size + 1]


def test_pairing_on_threads_is_the_nearest_record_by_brute_force():
    """match_detections splits 20 000 detections over the threads: each gets the record nearest
    in time within the tolerance (ties to the earlier), as a brute-force search over every record
    says; by frame, the last record of its frame; the same on one thread."""
    from eoloc import use_threads
    from eoloc.io.table import Table
    from eoloc.io.telemetry import match_detections

    rng = np.random.default_rng(3)
    m, n = 500, 20_000
    t_tel = np.sort(rng.uniform(0, 100, m))
    frames = rng.integers(0, 300, m).astype(np.float64)
    tel = Table("tel.csv", {"time_s": t_tel, "frame": np.full(m, np.nan)}, np.arange(2, m + 2))
    t_det = np.concatenate([rng.uniform(-1, 101, n - 3), [np.nan, t_tel[7], t_tel[8] + 0.5]])
    det = Table("det.csv", {"time_s": t_det, "frame": np.full(n, np.nan)}, np.arange(2, n + 2))
    gap = np.abs(t_det[:, None] - t_tel[None, :])  # 20 000 x 500
    nearest = np.argmin(np.where(np.isnan(gap), np.inf, gap), axis=1)  # the first of equal gaps
    expect = np.where(np.nan_to_num(gap[np.arange(n), nearest], nan=np.inf) <= 0.05, nearest, -1)
    with use_threads(2):
        got = match_detections(tel, det, time_tolerance_s=0.05).record
    with use_threads(1):
        one = match_detections(tel, det, time_tolerance_s=0.05).record
    assert np.array_equal(got, expect) and np.array_equal(one, got) and 0 < (got < 0).sum() < n
    tel_f = Table("tel.csv", {"time_s": np.full(m, np.nan), "frame": frames}, np.arange(2, m + 2))
    f_det = rng.integers(-5, 310, n).astype(np.float64)
    det_f = Table("det.csv", {"time_s": np.full(n, np.nan), "frame": f_det}, np.arange(2, n + 2))
    last = {f: i for i, f in enumerate(frames)}  # the last record of each frame, as a dict keeps it
    with use_threads(2):
        got = match_detections(tel_f, det_f).record
    assert got.tolist() == [last.get(f, -1) for f in f_det]
