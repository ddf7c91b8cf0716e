"""A CSV reader that keeps every good record and says exactly what was wrong with the others.

Columns are declared once (:class:`Column`: name, aliases, required or not, valid range). A line
with the wrong number of fields, or whose key column cannot be read, is dropped; a bad value in
another column becomes NaN and the record is kept (it ends as INVALID_INPUT downstream). Every
problem is reported as ``file:line: column 'x': what, and what would fix it``. Lines starting
with ``#`` and blank lines are comments.
"""

from __future__ import annotations

import csv
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import TableError
from .records import Coded


@dataclass(frozen=True)
class Column:
    """One column: its canonical name, accepted aliases, whether required, and valid range."""

    name: str
    aliases: tuple[str, ...] = ()
    required: bool = True
    lo: float = -math.inf
    hi: float = math.inf
    text: bool = False  # kept as a string (ids)
    unit: str = ""


@dataclass(frozen=True)
class Issue:
    """A problem found in an input file, with its place."""

    path: str
    line: int
    message: str

    def __str__(self) -> str:  # line 0: about the whole file (a note, a photo)
        return f"{self.path}:{self.line}: {self.message}" if self.line > 0 else f"{self.path}: {self.message}"


@dataclass
class Table:
    """Columns as arrays (float, NaN where bad; str for text columns), source line numbers, issues;
    ``coded``: text columns also as codes into their distinct values (see
    :class:`eoloc.io.records.Coded`)."""

    path: str
    columns: dict[str, np.ndarray]
    line: np.ndarray
    issues: list[Issue] = field(default_factory=list)
    coded: dict[str, Coded] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.line.size)

    def has(self, name: str) -> bool:
        return name in self.columns

    def add_missing(self, names, fill=np.nan, dtype=np.float64) -> None:
        """The columns among ``names`` that the file did not have, as ``fill``: a read-only view
        of the one value (a million detections without range_m or frame: no 8 MB column made
        and filled for each)."""
        for name in names:
            if name not in self.columns:
                self.columns[name] = np.broadcast_to(np.array(fill, dtype=dtype), (len(self),))

    def keep(self, mask: np.ndarray) -> Table:
        """The records where ``mask`` holds (issues kept)."""
        return Table(self.path, {k: v[mask] for k, v in self.columns.items()}, self.line[mask], self.issues,
                     {k: c[mask] for k, c in self.coded.items()})


def read_table(path: str | Path, columns: list[Column], *, what: str, key: tuple[str, ...],
               keep_other: bool = False, name_unknown: bool = True) -> Table:
    """Read a CSV with a header into a :class:`Table`.

    ``key``: the columns of which at least one must parse for a record to be kept (e.g. time or
    frame) — without it the record cannot be matched to anything; an empty ``key`` keeps every
    record (the caller judges them). ``keep_other``: the columns not declared are kept too, as
    text, under their header names (lower case). ``name_unknown``: every other column is named in
    an issue with the closest declared name (a ``gimbal_az`` column is not silently ignored); off
    for files that carry many columns by design (a flight log).

    The lines are sorted out first, vectorised over the file's bytes (comments, blank lines, lines
    of only commas, wrong field counts, bytes that are not UTF-8: each bad line reported with its
    physical number); the good ones are parsed by pyarrow's CSV reader; values are then checked
    column by column (numbers, finite, in range, whole frames). Files with quoted fields go
    through Python's csv module line by line instead, so that a quoted newline keeps the line
    numbers right and an unterminated quote costs its own line only.
    """
    path = Path(path)
    if not path.is_file():
        raise TableError(f"{what} file {str(path)!r} does not exist (check the path)")
    data = path.read_bytes()
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise TableError(f"{what} file {str(path)!r} is UTF-16 text: save it as UTF-8 (with or without a BOM)")
    if b"\x00" in data[:65536]:
        raise TableError(f"{what} file {str(path)!r} is not text (it holds NUL bytes: a binary file?): give the CSV "
                         "file, saved as UTF-8")
    if data[:3] == b"\xef\xbb\xbf":
        data = b" " * 3 + data[3:]  # same byte offsets; the header's names are stripped anyway
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        # line ends of old Macs (CR alone), or mixed: each lone CR is a line end (same byte offsets)
        data = _LONE_CR.sub(b"\n", data)
    src = str(path)
    fast = _clean_file(data)
    lines = None if fast is not None else _Lines(data, src)
    header = fast[0] if fast is not None else lines.header
    if header is None:
        raise TableError(f"{what} file {src!r} is empty: it needs a header line naming its columns")
    if keep_other:  # every column the declared ones do not claim, as text
        claimed = {n for c in columns for n in (c.name, *c.aliases)}
        columns = [*columns, *(Column(h, text=True, required=False) for h in dict.fromkeys(header)
                               if h and h not in claimed)]
    index = _map_columns(header, columns, src, what)
    unknown = unknown_columns(header, columns, index, what) if name_unknown and not keep_other else []
    wanted = [c for c in columns if c.name in index]
    cols = {c.name: index[c.name] for c in wanted}
    text = {c.name for c in wanted if c.text}
    raw = _arrow_clean(data, fast[1], len(header), cols, text) if fast is not None else None
    if raw is None:  # not clean after all: sort the lines out one by one
        lines = lines or _Lines(data, src)
        raw = lines.parse(header, cols, text)
        numbers, issues = lines.numbers, lines.issues
    else:
        numbers, issues = np.arange(2, 2 + _size(raw), dtype=np.int64), []
    issues = [Issue(src, 0, m) for m in unknown] + issues
    n = numbers.size
    arrays: dict[str, np.ndarray] = {}
    coded: dict[str, Coded] = {}
    cell_issues: list[tuple[int, int, str]] = []  # (record, column order, message)
    for order, col in enumerate(wanted):
        values = raw[col.name]
        if col.text:
            if isinstance(values, Coded):
                coded[col.name], values = values, values.names[values.codes]
            arrays[col.name] = values
            continue
        arrays[col.name] = _check_column(values, col, order, cell_issues)
    present = [k for k in key if k in arrays]
    key_ok = np.zeros(n, dtype=bool) if key else np.ones(n, dtype=bool)  # no key: every record kept
    for k in present:
        key_ok |= ~np.isnan(arrays[k])
    by_record: dict[int, list[str]] = {}
    for rec, _order, msg in sorted(cell_issues):
        by_record.setdefault(rec, []).append(msg)
    for rec in np.flatnonzero(~key_ok):
        more = by_record.pop(int(rec), [])
        issues.append(Issue(src, int(numbers[rec]), f"no usable {' or '.join(key)}; line skipped"
                            + (f" ({'; '.join(more)})" if more else "")))
    for rec, msgs in by_record.items():
        issues.extend(Issue(src, int(numbers[rec]), m) for m in msgs)
    issues.sort(key=lambda i: i.line)
    table = Table(src, arrays, numbers, issues, coded)
    return table if key_ok.all() else table.keep(key_ok)  # the usual case: no copies


_LONE_CR = re.compile(rb"\r(?!\n)")


def _fields(line: str, *, strict: bool = False) -> list[str]:
    """The fields of one CSV record (Python's csv module), however long a field is: the module's
    own limit (128 KiB a field, process-wide) is raised to the record's length first. ``strict``:
    text after a closing quote is an error (csv.Error), not part of the field."""
    if len(line) > csv.field_size_limit():
        csv.field_size_limit(len(line))
    return next(csv.reader([line], strict=strict), [])


def _clean_file(data: bytes) -> tuple[list[str], int] | None:
    """The header and the offset of the first data line when the file can be read in one go:
    ASCII or UTF-8, the header on line 1, no comment, no quote; else None (the lines are then
    sorted out one by one). Blank, comma-only and short lines are caught after the parse."""
    nl = data.find(b"\n")
    first = data[: nl if nl >= 0 else len(data)].rstrip(b"\r")
    if not first.strip() or first.lstrip().startswith(b"#") or b"#" in data or data.find(b'"', len(first)) >= 0:
        return None
    if not data.isascii():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            return None
    header = [x.strip().lower() for x in _fields(first.decode("utf-8"))]
    return header, (nl + 1 if nl >= 0 else len(data))


def _size(raw: dict) -> int:
    v = next(iter(raw.values()))
    return len(v[0] if isinstance(v, tuple) else v)


class _Lines:
    """The physical lines of a CSV file sorted out: the header, the numbers of the data lines that
    have the header's field count, and an issue for every other line that is not a comment or
    blank. ``parse`` gives the data lines' cells, column by column."""

    def __init__(self, data: bytes, path: str) -> None:
        self.data, self.path = data, path
        self.issues: list[Issue] = []
        self.header: list[str] | None = None
        self.quoted = False
        buf = np.frombuffer(data, dtype=np.uint8)
        ends = np.flatnonzero(buf == 10)
        if not data.endswith(b"\n"):
            ends = np.append(ends, len(data))
        starts = np.concatenate(([0], ends[:-1] + 1)).astype(np.int64)
        self.starts, self.ends = starts, ends
        def per_line(mask: np.ndarray) -> np.ndarray:  # how many bytes of each line the mask marks
            at = np.flatnonzero(mask)
            return np.searchsorted(at, ends) - np.searchsorted(at, starts)

        self.n_commas = per_line(buf == 44)
        self.n_nonspace = (ends - starts) - per_line((buf == 32) | (buf == 9) | (buf == 13))
        first = np.full(starts.size, 0, dtype=np.uint8)
        has = starts < ends
        first[has] = buf[starts[has]]
        self.comment = first == ord("#")
        odd = np.flatnonzero((self.n_nonspace > 0) & ~self.comment & np.isin(first, (9, 32)))
        for i in odd:  # a comment indented by spaces
            self.comment[i] = self.line(i).lstrip().startswith(b"#")
        blank = (self.n_nonspace == 0) | self.comment
        self.bad_utf8 = np.zeros(starts.size, dtype=bool)
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            for i in np.flatnonzero(~blank):
                try:
                    self.line(i).decode("utf-8")
                except UnicodeDecodeError as exc:
                    self.bad_utf8[i] = True
                    self.issues.append(Issue(path, int(i) + 1, f"byte 0x{exc.object[exc.start]:02X} is not UTF-8 (the "
                                             "file looks Latin-1 or similar; save it as UTF-8); line skipped"))
        content = np.flatnonzero(~blank & ~self.bad_utf8)
        if content.size == 0:
            self.numbers = np.zeros(0, dtype=np.int64)
            return
        h = int(content[0])
        try:
            self.header = [x.strip().lower() for x in _fields(self.line(h).decode("utf-8"))]
        except csv.Error as exc:
            raise TableError(f"{path}:{h + 1}: the header line is not a CSV record ({exc})") from None
        self.data_lines = content[1:]
        self.quoted = b'"' in data[self.ends[h]:]  # quotes in the header alone do not need the slow path

    def line(self, i: int) -> bytes:
        return self.data[self.starts[i]:self.ends[i]].rstrip(b"\r")

    def parse(self, header: list[str], index: dict[str, int], text: set[str]) -> dict[str, np.ndarray]:
        """The cells of the good data lines: float64 arrays (NaN empty) or, where a column is not
        all numbers, arrays of strings; text columns as stripped strings."""
        if self.quoted:
            return self._parse_quoted(header, index, text)
        lines = self.data_lines
        width = len(header)
        comma_only = self.n_nonspace[lines] == self.n_commas[lines]
        wrong = self.n_commas[lines] != width - 1
        for i in lines[comma_only]:
            self.issues.append(Issue(self.path, int(i) + 1, "a line of only commas (no values); line skipped"))
        for i in lines[wrong & ~comma_only]:
            self.issues.append(Issue(self.path, int(i) + 1, f"{int(self.n_commas[i]) + 1} fields where the header "
                                                            f"has {width}; line skipped"))
        good = lines[~comma_only & ~wrong]
        self.numbers = good.astype(np.int64) + 1
        if good.size == 0:
            return {name: np.zeros(0, dtype=object) if name in text else (np.zeros(0), np.zeros(0, dtype=bool))
                    for name in index}
        buf = np.frombuffer(self.data, dtype=np.uint8)
        keep = np.zeros(self.starts.size, dtype=bool)
        keep[good] = True
        length = np.diff(np.append(self.starts, len(self.data)))
        clean = buf[np.repeat(keep, length)].tobytes()
        if not clean.endswith(b"\n"):
            clean += b"\n"
        return _arrow_columns(clean, width, index, text, int((self.ends - self.starts).max()))

    def _parse_quoted(self, header: list[str], index: dict[str, int], text: set[str]) -> dict[str, np.ndarray]:
        width = len(header)
        rows: list[list[str]] = []
        numbers: list[int] = []
        lines = [int(i) for i in self.data_lines]
        k = 0
        while k < len(lines):
            i = lines[k]
            record = self.line(i).decode("utf-8")
            span = 1
            # a record continues past the line end only inside a quote, and only when the joined
            # record is then strictly CSV with the header's field count (else: an unterminated
            # quote on this line, and the lines after it are records of their own)
            while record.count('"') % 2 and k + span < len(lines) and lines[k + span] == i + span and span < 64:
                record += "\n" + self.line(i + span).decode("utf-8")
                span += 1
            try:
                fields = _fields(record, strict=span > 1)
            except csv.Error as exc:
                if span == 1:  # one line the csv module refuses
                    self.issues.append(Issue(self.path, i + 1, f"not a CSV record ({exc}); line skipped"))
                    k += 1
                    continue
                fields = []  # the joined lines are not one record
            if record.count('"') % 2 or (span > 1 and len(fields) != width):
                self.issues.append(Issue(self.path, i + 1, "an unterminated quote (a field opened with \" and never "
                                                           "closed); line skipped"))
                k += 1  # the lines it swallowed are read again on their own
                continue
            k += span
            if all(not f.strip() for f in fields):
                self.issues.append(Issue(self.path, i + 1, "a line of only commas (no values); line skipped"))
                continue
            if len(fields) != width:
                self.issues.append(Issue(self.path, i + 1, f"{len(fields)} fields where the header has {width}; "
                                                           "line skipped"))
                continue
            rows.append(fields)
            numbers.append(i + 1)
        self.numbers = np.array(numbers, dtype=np.int64)
        out = {}
        for name, j in index.items():
            cells = np.array([r[j].strip() for r in rows], dtype=object)
            if name in text and cells.size:
                import pyarrow as pa

                cells = np.array(unguarded(pa.array(cells.tolist(), type=pa.string())).to_pylist(), dtype=object)
            out[name] = cells if name in text else _numbers(cells)
        return out


def _arrow_clean(data: bytes, offset: int, width: int, index: dict[str, int],
                 text: set[str]) -> dict[str, np.ndarray] | None:
    """The whole body (from ``offset``) through pyarrow in one go, or None when a line turns out
    not to be clean (a wrong field count, a blank or comma-only line): the caller then sorts the
    lines out one by one, with their numbers."""
    import pyarrow as pa

    if not data[offset:offset + 1]:
        return None  # a header alone
    wrong: list[int] = []
    body = pa.py_buffer(data)[offset:]

    def handler(row) -> str:
        wrong.append(1)
        return "skip"

    raw = _arrow_columns(body, width, index, text, 1 << 16, handler)
    if wrong or not raw:
        return None
    n = _size(raw)  # with empty lines kept as rows and short or long ones caught above, one row per line
    empty = np.ones(n, dtype=bool)  # a blank or comma-only line is a row with every cell empty
    for name, v in raw.items():
        empty &= (v.names == "")[v.codes] if name in text else v[1]
    return None if empty.any() else raw


def _arrow_columns(clean, width: int, index: dict[str, int], text: set[str],
                   longest: int, invalid_row=None) -> dict[str, np.ndarray]:
    """pyarrow's CSV reader on the clean lines: numeric columns as float64 (an empty cell NaN),
    falling back to strings for a column with a cell that is not a number; text columns as
    :class:`Coded` (see :func:`text_cells`)."""
    import io

    import pyarrow as pa
    from pyarrow import csv as pacsv

    from . import arrowfn

    names = [f"c{j}" for j in range(width)]
    wanted = {name: f"c{j}" for name, j in index.items()}
    read = pacsv.ReadOptions(column_names=names, block_size=max(1 << 22, 2 * longest + 64))
    parse = pacsv.ParseOptions(quote_char=False, newlines_in_values=False, ignore_empty_lines=False,
                               invalid_row_handler=invalid_row)

    def load(types):
        conv = pacsv.ConvertOptions(column_types=types, include_columns=list(wanted.values()), null_values=[""],
                                    strings_can_be_null=True, quoted_strings_can_be_null=True)
        src = pa.BufferReader(clean) if isinstance(clean, pa.Buffer) else io.BytesIO(clean)
        return pacsv.read_csv(src, read_options=read, parse_options=parse, convert_options=conv)

    types = {c: (pa.string() if name in text else pa.float64()) for name, c in wanted.items()}
    try:
        table = load(types)
        as_text: set[str] = set()
    except pa.ArrowInvalid:  # some cell is not a number: read every column as text, convert each
        table = load(dict.fromkeys(wanted.values(), pa.string()))
        as_text = {n for n in wanted if n not in text}
    out = {}
    for name, c in wanted.items():
        col = table.column(c)
        if name in text:
            out[name] = text_cells(col)
        elif name in as_text:
            try:
                out[name] = (arrowfn.cast(col, pa.float64()).to_numpy(zero_copy_only=False),
                             arrowfn.is_null(col).to_numpy(zero_copy_only=False))
            except pa.ArrowInvalid:
                cells = arrowfn.utf8_trim_whitespace(arrowfn.fill_null(col, "")).to_numpy(zero_copy_only=False) \
                    .astype(object)
                out[name] = _numbers(cells)
        else:
            out[name] = (col.to_numpy(zero_copy_only=False).astype(np.float64, copy=False),  # nulls -> NaN
                         arrowfn.is_null(col).to_numpy(zero_copy_only=False))
    return out


def text_cells(col) -> Coded:
    """A pyarrow string column's stripped strings ("" for no value) as codes into its distinct
    values: ids repeat, and a million cells of a few dozen ids then cost a hash instead of a
    million Python strings. The cells are coded as they are and the distinct values stripped
    (" T1" and "T1" then become one name): a million cells are hashed, not also copied stripped."""
    import pyarrow as pa

    from . import arrowfn

    cells = arrowfn.fill_null(col, "")
    if isinstance(cells, pa.ChunkedArray):
        cells = cells.combine_chunks()
    coded = arrowfn.dictionary_encode(cells)
    codes = coded.indices.to_numpy(zero_copy_only=False)
    names = unguarded(arrowfn.utf8_trim_whitespace(coded.dictionary))
    if not names.equals(coded.dictionary):  # some had spaces: names equal once stripped share one code
        merged = arrowfn.dictionary_encode(names)
        codes, names = merged.indices.to_numpy(zero_copy_only=False)[codes], merged.dictionary
    return Coded(codes, names.to_numpy(zero_copy_only=False).astype(object))


GUARDED = "^'('*[=+\\-@\t\r])"  # a cell eoloc's CSV writer guarded against formulas (eoloc.io.csvfile.FORMULA)


def unguarded(names):
    """Text cells (a pyarrow string array) with the apostrophe a CSV writer puts before a cell that
    a spreadsheet would take for a formula (``'=1+2``, OWASP's CSV injection advice, which eoloc's
    writer follows) taken off again: ids read back as they were written."""
    from . import arrowfn

    if not arrowfn.any_true(arrowfn.matches(names, GUARDED)):
        return names
    return arrowfn.replace_regex(names, GUARDED, "\\1")


def _numbers(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strings to float64 where they parse, the others kept as strings (for the message); and
    which cells were empty."""
    vals: list = []
    mixed = False
    for c in cells:
        if c == "":
            vals.append(math.nan)
            continue
        try:
            vals.append(float(c))
        except ValueError:
            vals.append(c)
            mixed = True
    return np.array(vals, dtype=object if mixed else np.float64), np.array([c == "" for c in cells], dtype=bool)


#: Abbreviations expanded before a header name is compared with the declared ones.
_SPELLED_OUT = {"az": "azimuth", "el": "elevation", "elev": "elevation", "hdg": "heading", "lng": "lon",
                "long": "lon", "t": "time", "ts": "time", "timestamp": "time", "alt": "height"}
_UNITS = {"deg", "m", "s", "px", "mm", "rad", "ms"}
_ATTITUDE_WORDS = {"yaw", "pitch", "roll", "heading", "tilt", "pan"}  # (after _SPELLED_OUT: "hdg" is heading)


def _words(name: str) -> list[str]:
    return [_SPELLED_OUT.get(w, w) for w in re.split(r"[^a-z0-9]+", name.lower()) if w]


def closest_column(name: str, columns: list[Column]) -> tuple[str, str] | None:
    """The declared name (or alias) nearest to a header ``name``, with its column's canonical name:
    abbreviations spelled out (az, el, hdg, ...), a shared word (not a unit) worth more than a
    similar spelling; None when nothing is near."""
    words = _words(name)
    spelled = "_".join(words)
    best, best_score = None, 0.0
    for col in columns:
        for known in (col.name, *col.aliases):
            shared = (set(words) - _UNITS) & (set(_words(known)) - _UNITS)
            score = difflib.SequenceMatcher(None, spelled, known).ratio() + 0.5 * len(shared)
            if score > best_score:
                best, best_score = (known, col.name), score
    return best if best_score >= 0.6 else None


def unknown_columns(header: list[str], columns: list[Column], index: dict[str, int], what: str) -> list[str]:
    """One message per header name that no declared column takes: another name of a column the file
    already gives, or not one eoloc reads (with the closest name it does read)."""
    used = set(index.values())
    names = {n: c.name for c in columns for n in (c.name, *c.aliases)}
    messages = []
    for i, h in enumerate(header):
        if i in used or not h:
            continue
        if h in names:
            messages.append(f"column {h!r} is another name for {names[h]!r}, which the file also has; {h!r} ignored")
            continue
        near = closest_column(h, columns)
        hint = ""
        words = set(_words(h))
        if words & {"gimbal", "camera", "cam"} and words & _ATTITUDE_WORDS and {"gimbal1_deg", "gimbal2_deg"} & {
                c.name for c in columns}:
            # a camera's yaw/pitch/roll is not the aircraft's (the spelling is close, the meaning is not)
            hint = (" (a gimbal's angles relative to the aircraft go in 'gimbal1_deg' (azimuth) and 'gimbal2_deg' "
                    "(elevation); a camera attitude given in the earth frame, as drones give their gimbal's "
                    "yaw/pitch/roll, goes in 'yaw_deg', 'pitch_deg', 'roll_deg' with both gimbal angles 0)")
        elif near is not None:
            known, canonical = near
            hint = f" (did you mean {known!r}" + (f", i.e. {canonical!r}" if known != canonical else "") + "?)"
        messages.append(f"column {h!r} is not one eoloc reads in a {what} file; ignored{hint}. "
                        "See `eoloc locate --help` for the columns")
    return messages


def _map_columns(header: list[str], columns: list[Column], path: str, what: str) -> dict[str, int]:
    index: dict[str, int] = {}
    for col in columns:
        for name in (col.name, *col.aliases):
            if name in header:
                index[col.name] = header.index(name)
                break
    missing = [c for c in columns if c.required and c.name not in index]
    if missing:
        names = ", ".join(c.name + (f" (or {', '.join(c.aliases)})" if c.aliases else "") for c in missing)
        raise TableError(f"{what} file {path!r} lacks required column(s) {names}; its header is {header}. "
                         "See `eoloc locate --help` for the schema.")
    return index


_BIGGEST = float(np.finfo(np.float64).max)


def _all_fine(values: np.ndarray, col: Column) -> bool:
    """Whether every value is there, finite, in the column's range and (frames) whole."""
    with np.errstate(invalid="ignore"):
        if col.lo <= -_BIGGEST and col.hi >= _BIGGEST:
            fine = bool(np.isfinite(values).all())
        else:
            inside = np.greater_equal(values, max(col.lo, -_BIGGEST))  # NaN and infinities fail
            inside &= values <= min(col.hi, _BIGGEST)
            fine = bool(inside.all())
    return fine and (col.name != "frame" or bool((values == np.round(values)).all()))


def _check_column(cells: tuple[np.ndarray, np.ndarray], col: Column, order: int,
                  issues: list[tuple[int, int, str]]) -> np.ndarray:
    """A column's values as float64, NaN where a cell is empty, not a number, not finite, out of
    the column's range or (frames) not whole; an issue for each such cell (empty ones only when
    the column is required)."""
    values, empty = cells
    if values.dtype != object and _all_fine(values, col):  # the usual case: one or two passes, no copy
        return values
    if values.dtype == object:  # some cells are not numbers: they are kept as strings
        words = np.array([isinstance(v, str) for v in values], dtype=bool)
        for i in np.flatnonzero(words):
            issues.append((int(i), order, f"column {col.name!r}: {values[i]!r} is not a number"))
        values = np.where(words, np.nan, values).astype(np.float64)
    else:
        words = np.zeros(values.size, dtype=bool)
    if col.required:
        for i in np.flatnonzero(empty):
            issues.append((int(i), order, f"column {col.name!r} is empty"))
    for i in np.flatnonzero(np.isnan(values) & ~empty & ~words):
        issues.append((int(i), order, f"column {col.name!r} is NaN"))
    inf = np.isinf(values)
    for i in np.flatnonzero(inf):
        issues.append((int(i), order, f"column {col.name!r}: {values[i]:g} is not a finite number"))
    with np.errstate(invalid="ignore"):
        out = ~inf & ~np.isnan(values) & ~((values >= col.lo) & (values <= col.hi))
    unit = f" {col.unit}" if col.unit else ""
    for i in np.flatnonzero(out):
        issues.append((int(i), order, f"column {col.name!r}: {values[i]:g}{unit} is outside [{col.lo:g}, {col.hi:g}]"))
    bad = inf | out
    if col.name == "frame":
        with np.errstate(invalid="ignore"):
            frac = ~bad & ~np.isnan(values) & (values != np.round(values))
        for i in np.flatnonzero(frac):
            issues.append((int(i), order, f"column 'frame': {values[i]:g} is not a whole frame number"))
        bad |= frac
    return np.where(bad, np.nan, values)
