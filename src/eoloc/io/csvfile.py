"""The CSV writer: records (columns) to a CSV file with a header, fast enough for a million fixes.

Each column becomes its cells as text, every cell followed by its separator (a comma; a line
break after the last column), and pyarrow joins the cells of each row (``binary_join_element_wise``,
GIL released). Numbers get their text from orjson's Ryu code (the shortest text that reads back
as the same double, 3x faster than pyarrow's float cast) in one call per column and chunk; the
commas orjson puts between them are the cells' separators already, so a cell is only an offset
into orjson's output. Chunks of rows are rendered on two threads and written in order.

Compared with rendering every cell on its own and handing pyarrow's CSV writer the columns, this
takes 25 % less processor time on a million fixes (bench/RESULTS.md, session 41).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .records import Coded, Records

CSV_CHUNK = 1 << 15  # rows rendered per pyarrow call (two at a time, one per core)

_QUOTED = '[,"\r\n]'  # a cell with one of these is quoted (RFC 4180)


def write_csv(path: str | Path, records: Records | Sequence[Mapping], *, columns: Sequence[str] = ()) -> Path:
    """CSV with a header (``columns`` when there are no records); empty cells where there is no
    value; angles (``*_deg``) rounded to 9 decimals (< 0.1 mm), other numbers to 4, written in
    their shortest form (a column of whole numbers as integers: ``17``, not ``17.0``); booleans
    True/False; a text cell quoted only when it holds a comma, quote or line break (as Python's
    csv module does); numbers never quoted. Coded text columns (:class:`Coded`) render each of
    their names once."""
    recs = Records.of(records)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = recs.names or list(columns)
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow(names)
    with path.open("wb") as fh:
        fh.write(header.getvalue().encode("utf-8"))
        if len(recs) and names:
            cells = [_Cells.of(k, recs.columns[k], recs.coded.get(k), last=i == len(names) - 1, lone=len(names) == 1)
                     for i, k in enumerate(names)]

            def render(start: int):
                stop = min(start + CSV_CHUNK, len(recs))
                return _join([c.render(start, stop) for c in cells], stop - start)

            with ThreadPoolExecutor(2) as pool:
                for chunk in pool.map(render, range(0, len(recs), CSV_CHUNK)):
                    fh.write(chunk)
    return path


def decimals(name: str) -> int:
    """The decimals a number column is written with: 9 for angles (``*_deg``), else 4."""
    return 9 if name.endswith("_deg") else 4


class _Cells:
    """How one column renders its cells, decided once for the whole column: each cell's text and
    then its separator; no value: the separator alone."""

    def __init__(self, name: str, v: np.ndarray, coded: Coded | None, sep: str, lone: bool) -> None:
        import pyarrow as pa

        self.name, self.v, self.sep, self.lone = name, v, sep, lone
        self.empty = ('""' if lone else "") + sep  # a row of one empty cell is not a blank line
        self.kind = "text"
        if coded is not None:
            self.kind, self.codes = "coded", coded.codes
            self.names = _finish(pa.array(coded.names.tolist(), type=pa.string()), sep, self.empty, lone)
        elif v.dtype.kind == "b":
            self.kind, self.codes = "coded", v.view(np.int8)
            self.names = pa.array(["False" + sep, "True" + sep])
        elif v.dtype.kind in "iu":
            self.kind = "numbers"
        elif v.dtype.kind == "f":
            self.kind = "cast" if np.isinf(v).any() else "numbers"  # orjson has no infinity: pyarrow writes it
            self.whole = self.kind == "numbers" and _whole(v[:CSV_CHUNK], decimals(name)) and _whole(v, decimals(name))
            self.big = bool(np.fmax.reduce(v, initial=-np.inf) >= _INTEGRAL or  # (NaN skipped)
                            np.fmin.reduce(v, initial=np.inf) <= -_INTEGRAL)
        else:
            self.text = _finish(_text_array(name, v), sep, self.empty, lone)

    @classmethod
    def of(cls, name: str, v: np.ndarray, coded: Coded | None, *, last: bool, lone: bool) -> _Cells:
        return cls(name, v, coded, "\n" if last else ",", lone)

    def render(self, start: int, stop: int):
        """Rows ``start:stop`` as a pyarrow string array (or one scalar for all of them)."""
        import pyarrow as pa

        from . import arrowfn

        if self.kind == "coded":
            return arrowfn.take(self.names, arrow_ints(self.codes[start:stop]))
        if self.kind == "text":
            return self.text.slice(start, stop - start)
        v = self.v[start:stop]
        if v.dtype.kind in "iu":
            return number_cells(v, self.sep)
        missing = np.isnan(v)
        if missing.all():
            return pa.scalar(self.empty)
        rounded = rounded_to(v, decimals(self.name), self.big)
        if self.kind == "cast":  # pyarrow's text for the numbers, "inf" and "-inf" included
            return _finish(arrowfn.cast(pa.array(rounded, mask=missing), pa.string()), self.sep, self.empty, False)
        if self.whole:
            rounded = np.where(missing, 0.0, rounded).astype(np.int64)
        cells = number_cells(rounded, self.sep, missing if missing.any() else None)
        return cells if self.sep == "," else arrowfn.fill_null(cells, self.empty)


_INTEGRAL = 2.0**52  # a double this large or larger is a whole number: rounding leaves it as it is


def rounded_to(v: np.ndarray, decimals: int, big: bool = True) -> np.ndarray:
    """``v`` rounded to ``decimals`` as numpy rounds (half to even); numbers of 2^52 or more are
    whole already and are kept as they are (numpy scales by 10^decimals first, which turns 1e306
    into infinity). ``big=False``: the caller knows there are none (one pass less)."""
    with np.errstate(over="ignore"):  # those numbers' scaled copies: replaced below
        r = np.round(v, decimals)
    return np.where(np.abs(v) >= _INTEGRAL, v, r) if big else r


def _whole(v: np.ndarray, decimals: int) -> bool:
    """Whether a float column, rounded as written, holds only whole numbers (or no value) that
    int64 writes exactly."""
    r = rounded_to(v[~np.isnan(v)], decimals)
    return bool((np.abs(r) < 2.0**53).all() and (r == np.trunc(r)).all())  # an infinity is not whole


def number_cells(v: np.ndarray, sep: str = ",", missing: np.ndarray | None = None):
    """Finite numbers (float or int) as a pyarrow string array of their shortest round-trip text,
    each cell followed by ``sep`` (``missing``: null cells). One value throughout (a height
    surface's h_m): one scalar. orjson writes ``[a,b,c]``; each cell is its number and the comma
    after it (made ``sep``), the last one's ``]`` made ``sep`` too: no cutting, no copying of cells."""
    import orjson
    import pyarrow as pa

    v = np.ascontiguousarray(v, dtype=np.float64 if v.dtype.kind == "f" and v.itemsize < 4 else None)  # orjson's
    if len(v) == 0:
        return pa.array([], type=pa.string())
    if missing is None and len(v) > 1 and v[0] == v[-1] and bool((v == v[0]).all()):
        return pa.scalar(orjson.dumps(v[:1], option=orjson.OPT_SERIALIZE_NUMPY).decode()[1:-1] + sep)
    raw = bytearray(orjson.dumps(v, option=orjson.OPT_SERIALIZE_NUMPY))  # b"[a,b,c]": ASCII, no comma in a number
    text = np.frombuffer(raw, dtype=np.uint8)
    commas = np.flatnonzero(text == ord(","))
    if sep != ",":  # the last column: each of its cells ends a row
        text[commas] = ord(sep)
    raw[-1] = ord(sep)
    offsets = np.empty(len(v) + 1, dtype=np.int32)  # a chunk's text is far below 2 GB
    offsets[0], offsets[1:-1], offsets[-1] = 1, commas + 1, len(raw)
    valid = None if missing is None else pa.py_buffer(np.packbits(~missing, bitorder="little"))
    return pa.StringArray.from_buffers(len(v), pa.py_buffer(offsets), pa.py_buffer(raw), valid)


def arrow_ints(codes: np.ndarray):
    """A 1-D numpy integer array as a pyarrow array, sharing its memory (``pa.array`` on numpy
    input imports numpy.ma to look for masks: 25 ms)."""
    import pyarrow as pa

    codes = np.ascontiguousarray(codes)
    return pa.Array.from_buffers(pa.from_numpy_dtype(codes.dtype), len(codes), [None, pa.py_buffer(codes)])


def _text_array(name: str, v: np.ndarray):
    """Text and None (ids, statuses, ISO times) as a pyarrow string array; other objects (numbers
    among text) by their Python text, numbers rounded as their column would be."""
    import pyarrow as pa

    try:
        return pa.array(v, type=pa.string(), from_pandas=True)
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        pass
    cells = [None if x is None or (isinstance(x, float) and math.isnan(x)) else
             (_fmt(name, x) if isinstance(x, (float, bool, np.generic)) else str(x)) for x in v.tolist()]
    return pa.array(cells, type=pa.string())


def _fmt(key: str, v) -> str:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return f"{v:.{decimals(key)}f}"
    return str(v)


def _finish(text, sep: str, empty: str, lone: bool):
    """Text cells quoted where they must be (a lone column's empty cells too), then ``sep``
    after each; no value: ``empty``."""
    import pyarrow as pa

    from . import arrowfn

    quote = arrowfn.matches(text, _QUOTED)
    if lone:
        quote = arrowfn.or_(quote, arrowfn.equal(text, ""))
    if arrowfn.any_true(quote):
        text = arrowfn.if_else(quote, arrowfn.join_cells('"', arrowfn.replace_all(text, '"', '""'), '"', ""), text)
    return arrowfn.fill_null(arrowfn.join_cells(text, pa.scalar(sep), ""), empty)


def _join(cells: list, n: int):
    """The bytes of ``n`` rows: each row's cells (with their separators) one after the other."""
    import pyarrow as pa

    from . import arrowfn

    if not any(isinstance(c, pa.Array) for c in cells):  # every column one value: the same row n times
        return "".join(c.as_py() for c in cells).encode("utf-8") * n
    rows = arrowfn.join_cells(*cells, "", null_replacement=",")
    _, offsets, data = rows.buffers()
    o = np.frombuffer(offsets, dtype=np.int32)
    return data[o[rows.offset]:o[rows.offset + len(rows)]]
