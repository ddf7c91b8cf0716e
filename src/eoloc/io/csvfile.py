"""The CSV writer: records (columns) to a CSV file with a header, fast enough for a million fixes.

How each column writes its cells is decided once for the whole column (:class:`_Cells`). Chunks
of rows are rendered on two threads and written in order. A chunk's rows come from the compiled
row renderer :mod:`eoloc.io.csvrows` (built with the package; it writes numbers, codes and
pre-rendered cells with the GIL released) or, where it was not built, from pyarrow: each column's
cells as a string array, every cell followed by its separator, joined row by row
(``binary_join_element_wise``). Both give the same bytes (tested). Numbers are written as orjson
writes them (Ryu: the shortest text that reads back as the same double); csvrows does that itself
for a column whose rounded numbers have at most 15 digits and hands the others to orjson.

Against orjson + pyarrow's join, csvrows takes the writer of 10^6 fixes from 0.29 to ~0.1 s
(bench/RESULTS.md, session 43).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from . import rows
from .records import Coded, Records

CSV_CHUNK = rows.CHUNK

_QUOTED = '[,"\r\n]'  # a cell with one of these is quoted (RFC 4180)
# a spreadsheet takes a cell that starts with one of these for a formula (CSV injection, OWASP): a
# text cell that does and is not a plain number is written after an apostrophe, which spreadsheets
# show as text and eoloc's reader takes off again (:func:`eoloc.io.table.unguarded`); a cell that
# already starts with apostrophes before such a character gets one more, so every cell reads back
FORMULA = "^'*[=+\\-@\t\r]"
PLAIN_NUMBER = "^[+-]?([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][+-]?[0-9]+)?$"


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

            compiled = rows.compiled()

            def render(start: int, stop: int) -> bytes:
                if compiled is not None:
                    return compiled.render(start, stop - start, tuple(c.spec(start, stop) for c in cells))
                return _join([c.render(start, stop) for c in cells], stop - start)

            rows.write_chunks(fh, len(recs), render, CSV_CHUNK)
    return path


ANGLE_WORDS = ("lat", "lon", "yaw", "pitch", "roll")  # eoloc photo's keys: camera_lat, camera_yaw, sigma_camera_roll


def decimals(name: str) -> int:
    """The decimals a number column is written with: 9 for angles (``*_deg``, and the photo
    vocabulary's ``*lat``, ``*_yaw`` ... in degrees: 1e-4 deg would be 11 m of latitude), else 4."""
    return 9 if name.endswith("_deg") or name.rsplit("_", 1)[-1] in ANGLE_WORDS else 4


class _Cells:
    """How one column renders its cells, decided once for the whole column: each cell's text and
    then its separator; no value: the separator alone."""

    def __init__(self, name: str, v: np.ndarray, coded: Coded | None, sep: str, lone: bool) -> None:
        import pyarrow as pa

        self.name, self.v, self.sep, self.lone = name, v, sep, lone
        self.empty = ('""' if lone else "") + sep  # a row of one empty cell is not a blank line
        self.kind = "text"
        if coded is not None:
            codes = np.ascontiguousarray(coded.codes)
            self.kind, self.codes = "coded", codes if codes.dtype.kind == "i" else codes.astype(np.int64)
            self.names = _finish(pa.array(coded.names.tolist(), type=pa.string()), sep, self.empty, lone)
        elif v.dtype.kind == "b":
            self.kind, self.codes = "coded", np.ascontiguousarray(v).view(np.int8)
            self.names = pa.array(["False" + sep, "True" + sep])
        if self.kind == "coded":  # the names' offsets and text, for csvrows
            _, offsets, data = self.names.buffers()
            at = self.names.offset
            self.name_buffers = (np.frombuffer(offsets, dtype=np.int32)[at:at + len(self.names) + 1], data)
        elif v.dtype.kind in "iu":
            self.kind = "numbers"
            self.ints = np.ascontiguousarray(v, dtype=np.int64) if fits_int64(v) else None
        elif v.dtype.kind == "f":
            self.kind = "cast" if np.isinf(v).any() else "numbers"  # orjson has no infinity: pyarrow writes it
            self.whole = self.kind == "numbers" and whole_column(v, decimals(name))
            top, bottom = np.fmax.reduce(v, initial=-np.inf), np.fmin.reduce(v, initial=np.inf)  # (NaN skipped)
            self.big = bool(top >= _INTEGRAL or bottom <= -_INTEGRAL)
            self.floats = compiled_floats(v, decimals(name), top, bottom) if self.kind == "numbers" else None
        else:
            self.text = _finish(_text_array(name, v), sep, self.empty, lone)

    @classmethod
    def of(cls, name: str, v: np.ndarray, coded: Coded | None, *, last: bool, lone: bool) -> _Cells:
        return cls(name, v, coded, "\n" if last else ",", lone)

    def spec(self, start: int, stop: int) -> tuple:
        """Rows ``start:stop`` as :func:`eoloc.io.csvrows.render` takes them (see csvrows.c)."""
        sep = self.sep.encode()
        if self.kind == "coded":
            return 3, self.codes, *self.name_buffers
        if self.kind == "numbers" and self.v.dtype.kind == "f" and self.floats is not None:
            return 1, self.floats, decimals(self.name), self.whole, b"", sep, self.empty.encode()
        if self.kind == "numbers" and self.v.dtype.kind in "iu" and self.ints is not None:
            return 2, self.ints, b"", sep
        import pyarrow as pa

        cells = self.render(start, stop)
        if not isinstance(cells, pa.Array):
            return 0, cells.as_py().encode("utf-8")
        if cells.type != pa.string():  # csvrows reads int32 offsets
            raise TypeError(f"CSV column {self.name!r}: cells of type {cells.type}, not string")
        validity, offsets, data = cells.buffers()
        return 4, offsets, b"" if data is None else data, validity, cells.offset

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
            return _finish(arrowfn.cast(pa.array(rounded, mask=missing), pa.string()), self.sep, self.empty, False,
                           numbers=True)
        if self.whole:
            rounded = np.where(missing, 0.0, rounded).astype(np.int64)
        cells = number_cells(rounded, self.sep, missing if missing.any() else None)
        return cells if self.sep == "," else arrowfn.fill_null(cells, self.empty)


def fits_int64(v: np.ndarray) -> bool:
    """Whether an integer column's values all fit int64 (a uint64 column's may not)."""
    return v.size == 0 or (int(v.min()) >= -2**63 and int(v.max()) < 2**63)


_INTEGRAL = 2.0**52  # a double this large or larger is a whole number: rounding leaves it as it is


def rounded_to(v: np.ndarray, decimals: int, big: bool = True) -> np.ndarray:
    """``v`` rounded to ``decimals`` as numpy rounds (half to even); numbers of 2^52 or more are
    whole already and are kept as they are (numpy scales by 10^decimals first, which turns 1e306
    into infinity). ``big=False``: the caller knows there are none (one pass less)."""
    with np.errstate(over="ignore"):  # those numbers' scaled copies: replaced below
        r = np.round(v, decimals)
    return np.where(np.abs(v) >= _INTEGRAL, v, r) if big else r


def whole_column(v: np.ndarray, decimals: int) -> bool:
    """Whether a float column, rounded as written, holds only whole numbers (or no value) that
    int64 writes exactly (its first chunk looked at first: most columns are not)."""
    return _whole(v[:CSV_CHUNK], decimals) and _whole(v, decimals)


def compiled_floats(v: np.ndarray, decimals: int, top: float | None = None, bottom: float | None = None):
    """The float column as csvrows takes it (contiguous float64), or None where csvrows does not
    write it: a float32 column (numpy rounds it in float32), or a rounded number with more than
    15 digits (csvrows.c says why). Infinities: the caller's (csvrows refuses them). ``top``,
    ``bottom``: the column's largest and smallest number if known."""
    if v.dtype != np.float64:
        return None
    top = np.fmax.reduce(v, initial=-np.inf) if top is None else top  # (NaN skipped)
    bottom = np.fmin.reduce(v, initial=np.inf) if bottom is None else bottom
    return np.ascontiguousarray(v) if max(top, -bottom) < 10.0 ** (15 - decimals) else None


def _whole(v: np.ndarray, decimals: int) -> bool:
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
    bits = v.view(f"u{v.itemsize}")  # one value throughout, bit for bit: 0.0 and -0.0 are two
    if missing is None and len(v) > 1 and bits[0] == bits[-1] and bool((bits == bits[0]).all()):
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


def _finish(text, sep: str, empty: str, lone: bool, *, numbers: bool = False):
    """Text cells guarded against formulas (:data:`FORMULA`; not ``numbers``' text, such as
    "-inf"), quoted where they must be (a lone column's empty cells too), then ``sep`` after each;
    no value: ``empty``."""
    import pyarrow as pa

    from . import arrowfn

    formula = None if numbers else arrowfn.matches(text, FORMULA)
    if formula is not None and arrowfn.any_true(formula):
        formula = arrowfn.and_not(formula, arrowfn.matches(text, PLAIN_NUMBER))
        text = arrowfn.if_else(formula, arrowfn.join_cells("'", text, ""), text)
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
