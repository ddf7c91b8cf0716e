"""eoloc._search.searchsorted against numpy's own searchsorted: the same position for every query,
whatever the keys' spacing (steady, bunched, repeated, integers, huge magnitudes) and the queries
(the keys themselves, between them, outside their range, non-finite)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from eoloc import _search


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
    got = _search.searchsorted(keys, q, side=side)
    want = np.searchsorted(keys, q, side=side)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_few_queries_and_degenerate_keys_take_numpy() -> None:
    keys = np.array([3.0, 3.0, 3.0])
    q = np.linspace(2, 4, 5000)
    np.testing.assert_array_equal(_search.searchsorted(keys, q), np.searchsorted(keys, q))
    np.testing.assert_array_equal(_search.searchsorted(np.arange(5.0), [2.0, 2.5]), [2, 3])


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

    monkeypatch.setattr(_search.np, "searchsorted", counting)
    np.testing.assert_array_equal(_search.searchsorted(keys, q), want)
    assert sizes == [keys.size + 1]
