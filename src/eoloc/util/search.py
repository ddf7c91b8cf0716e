"""Sorted search for many queries: numpy's ``searchsorted``, exactly, without its binary search's
cache misses and mispredicted branches when the queries come in random order.

``np.searchsorted`` costs ~140 ns per random query into 10^5 keys (17 dependent, unpredictable
steps), so pairing 10^6 detections with their telemetry took 0.14 s. Here the keys' range is cut
into as many equal buckets as there are keys; each bucket's first position is found once (sorted
queries: cheap), and each query's answer is then known to lie within its bucket and the two
next to it (one on each side absorbs rounding at the edges). A vectorised binary search over
those few positions finishes the job: one or two steps for keys spread evenly (telemetry at a
steady rate), more where the keys bunch up. Queries in buckets too crowded for that, and those
outside the keys' range or not finite, take ``np.searchsorted`` itself.
"""

from __future__ import annotations

import numpy as np

MIN_QUERIES = 4096  # fewer: numpy's own search is as fast
MAX_STEPS = 6  # binary-search steps taken vectorised; queries whose window needs more go to numpy


def searchsorted(keys: np.ndarray, queries: np.ndarray, side: str = "left") -> np.ndarray:
    """``np.searchsorted(keys, queries, side)`` for sorted, finite ``keys`` (int64 positions),
    the same answer for every query."""
    keys = np.asarray(keys)
    q = np.asarray(queries)
    n = keys.size
    if q.size < MIN_QUERIES or n < 2 or not keys[-1] > keys[0]:
        return np.searchsorted(keys, q, side=side).astype(np.int64, copy=False)
    lo_key, hi_key = float(keys[0]), float(keys[-1])
    width = (hi_key - lo_key) / n
    if not width > 1e3 * np.spacing(max(abs(lo_key), abs(hi_key))):  # buckets finer than floats resolve
        return np.searchsorted(keys, q, side=side).astype(np.int64, copy=False)
    # bucket b holds [lo_key + b width, lo_key + (b + 1) width); first[b] = the answer at its start
    first = np.searchsorted(keys, lo_key + np.arange(n + 1) * width, side=side)
    first = np.append(first, n)  # the window's right end for the last bucket
    qf = q.astype(np.float64, copy=False)
    with np.errstate(invalid="ignore"):
        inside = (qf >= lo_key) & (qf <= hi_key)
        b = ((qf - lo_key) * (1.0 / width)).astype(np.int64)  # outside or NaN: clipped, and not inside
    np.clip(b, 0, n - 1, out=b)
    lo = first[np.maximum(b - 1, 0)]
    hi = first[b + 2]
    easy = inside & (hi - lo < 1 << MAX_STEPS)
    if easy.all():  # the usual case: no subsets to gather
        return _narrow(keys, q, lo, hi, side)
    out = np.empty(q.shape, dtype=np.int64)
    hard = ~easy
    out[hard] = np.searchsorted(keys, q[hard], side=side)
    out[easy] = _narrow(keys, q[easy], lo[easy], hi[easy], side)
    return out


def _narrow(keys: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, side: str) -> np.ndarray:
    """The binary search of every query at once, each in its window [lo, hi] of positions."""
    for _ in range(int((hi - lo).max(initial=0)).bit_length()):
        mid = (lo + hi) >> 1
        k = keys.take(mid, mode="clip")  # mid = hi = n only where lo = hi: inactive
        active = lo < hi
        right = (k < q) if side == "left" else (k <= q)
        lo = lo + (active & right) * (mid + 1 - lo)  # arithmetic: 4x faster than np.where on int64
        hi = hi + (active & ~right) * (mid - hi)
    return lo


__all__ = ["searchsorted"]
