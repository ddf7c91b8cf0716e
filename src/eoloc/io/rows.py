"""Text rows from columns, for the CSV and GeoJSON writers: the row specs both speak, the renderer
that turns them into bytes, and the chunked, ordered write.

A row is its columns' cells one after the other; each column is a spec tuple (see
``csvrows.c``): a constant text, float64 numbers rounded to a number of decimals between a
prefix and a suffix (NaN: an "empty" text instead), int64 numbers likewise, coded text (names
pre-rendered with whatever surrounds them) or pre-rendered cells (a pyarrow string array). The
compiled renderer :mod:`eoloc.io.csvrows` writes them with the GIL released; where it was not
built (an install without a C compiler), :func:`render_reference` does, cell by cell in Python:
slow, and the reference the compiled one is tested against.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import BinaryIO

import numpy as np

CHUNK = 1 << 15  # rows rendered per call (two at a time, one per core)
AHEAD = 4  # chunks rendered ahead of the file: rendering outruns the writes, memory should not
USE_COMPILED = True  # False: never the compiled renderer (the tests compare the two)


def compiled():
    """The compiled row renderer (:mod:`eoloc.io.csvrows`), or None where it was not built."""
    if not USE_COMPILED:
        return None
    try:
        from . import csvrows
    except ImportError:
        return None
    return csvrows


def write_chunks(fh: BinaryIO, n: int, render: Callable[[int, int], bytes], chunk: int = CHUNK) -> None:
    """Rows 0..n rendered chunk by chunk on two threads (``render(start, stop)`` -> bytes) and
    written in order, at most :data:`AHEAD` chunks ahead of the file."""
    with ThreadPoolExecutor(2) as pool:
        pending: deque = deque()
        for start in range(0, n, chunk):
            if len(pending) == AHEAD:
                fh.write(pending.popleft().result())
            pending.append(pool.submit(render, start, min(start + chunk, n)))
        while pending:
            fh.write(pending.popleft().result())


def render_reference(start: int, n: int, specs: Sequence[tuple]) -> bytes:
    """What :func:`eoloc.io.csvrows.render` writes, cell by cell in Python: numbers through
    numpy's rounding and orjson's text, whole ones through ``int``."""
    import orjson

    def cells(spec: tuple) -> list[bytes]:
        kind = spec[0]
        if kind == 0:
            return [spec[1]] * n
        if kind in (1, 2):
            values = np.asarray(spec[1])[start:start + n]
            prefix, suffix = spec[-3:-1] if kind == 1 else spec[2:4]
            out = []
            for x in values.tolist():
                if kind == 2:
                    out.append(prefix + str(x).encode() + suffix)
                elif x != x:  # NaN
                    out.append(spec[6])
                else:
                    r = np.round(np.float64(x), spec[2])
                    text = str(int(r)).encode() if spec[3] else orjson.dumps(float(r))
                    out.append(prefix + text + suffix)
            return out
        if kind == 3:
            codes, offsets, data = spec[1], np.asarray(spec[2]), bytes(spec[3])
            return [data[offsets[c]:offsets[c + 1]] for c in np.asarray(codes)[start:start + n].tolist()]
        offsets, data, validity, at = spec[1:]
        offsets, data = np.frombuffer(offsets, dtype=np.int32), bytes(data)
        bits = None if validity is None else np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        return [b"," if bits is not None and not bits[i] else data[offsets[i]:offsets[i + 1]]
                for i in range(at, at + n)]

    columns = [cells(s) for s in specs]
    return b"".join(b"".join(row) for row in zip(*columns, strict=True)) if columns else b""


def render(start: int, n: int, specs: Sequence[tuple]) -> bytes:
    """Rows ``start .. start+n`` of the specs: compiled where built, else the reference."""
    rows = compiled()
    return (rows.render if rows is not None else render_reference)(start, n, tuple(specs))
