"""A CSV reader that keeps every good record and says exactly what was wrong with the others.

Columns are declared once (:class:`Column`: name, aliases, required or not, valid range). A line
with the wrong number of fields, or whose key column cannot be read, is dropped; a bad value in
another column becomes NaN and the record is kept (it ends as INVALID_INPUT downstream). Every
problem is reported as ``file:line: column 'x': what, and what would fix it``. Lines starting
with ``#`` and blank lines are comments.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import TableError


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

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.message}"


@dataclass
class Table:
    """Columns as arrays (float, NaN where bad; str for text columns), source line numbers, issues."""

    path: str
    columns: dict[str, np.ndarray]
    line: np.ndarray
    issues: list[Issue] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.line.size)

    def has(self, name: str) -> bool:
        return name in self.columns

    def keep(self, mask: np.ndarray) -> Table:
        """The records where ``mask`` holds (issues kept)."""
        return Table(self.path, {k: v[mask] for k, v in self.columns.items()}, self.line[mask], self.issues)


def read_table(path: str | Path, columns: list[Column], *, what: str, key: tuple[str, ...]) -> Table:
    """Read a CSV with a header into a :class:`Table`.

    ``key``: the columns of which at least one must parse for a record to be kept (e.g. time or
    frame) — without it the record cannot be matched to anything.
    """
    path = Path(path)
    if not path.is_file():
        raise TableError(f"{what} file {str(path)!r} does not exist (check the path)")
    issues: list[Issue] = []
    rows: list[tuple[int, list[str]]] = []
    header: list[str] | None = None
    with path.open("rb") as fb:
        head = fb.read(4)
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise TableError(f"{what} file {str(path)!r} is UTF-16 text: save it as UTF-8 (with or without a BOM)")
    # bytes that are not UTF-8 are kept as surrogates, so that one bad byte costs its own line
    # (reported below), not the file
    with path.open(newline="", encoding="utf-8-sig", errors="surrogateescape") as fh:
        reader = csv.reader(fh)
        try:
            for raw in reader:
                lineno = reader.line_num
                if not raw or not "".join(raw).strip() or raw[0].lstrip().startswith("#"):
                    continue
                bad = next((c for c in "".join(raw) if "\udc80" <= c <= "\udcff"), None)
                if bad is not None:
                    issues.append(Issue(str(path), lineno, f"byte 0x{ord(bad) - 0xDC00:02X} is not UTF-8 (the file "
                                                           "looks Latin-1 or similar; save it as UTF-8); line skipped"))
                    continue
                if header is None:
                    header = [h.strip().lower() for h in raw]
                    continue
                rows.append((lineno, raw))
        except csv.Error as exc:
            raise TableError(f"{what} file {str(path)!r}, line {reader.line_num}: {exc} (a field far too long, or an "
                             "unterminated quote: check the file around that line)") from None
    if header is None:
        raise TableError(f"{what} file {str(path)!r} is empty: it needs a header line naming its columns")
    index = _map_columns(header, columns, str(path), what)
    data: dict[str, list] = {c.name: [] for c in columns if c.name in index}
    kept_lines: list[int] = []
    for lineno, raw in rows:
        if len(raw) != len(header):
            issues.append(Issue(str(path), lineno, f"{len(raw)} fields where the header has {len(header)}; "
                                                   "line skipped"))
            continue
        values: dict[str, object] = {}
        line_issues: list[str] = []
        for col in columns:
            if col.name not in index:
                continue
            cell = raw[index[col.name]].strip()
            if col.text:
                values[col.name] = cell
                continue
            values[col.name] = _parse(cell, col, line_issues)
        key_ok = any(k in values and not (isinstance(values[k], float) and math.isnan(values[k])) for k in key)
        if not key_ok:
            issues.append(Issue(str(path), lineno, f"no usable {' or '.join(key)}; line skipped"
                                + (f" ({'; '.join(line_issues)})" if line_issues else "")))
            continue
        issues.extend(Issue(str(path), lineno, m) for m in line_issues)
        for name, value in values.items():
            data[name].append(value)
        kept_lines.append(lineno)
    arrays = {
        c.name: np.array(data[c.name], dtype=object if c.text else np.float64)
        for c in columns if c.name in data
    }
    return Table(str(path), arrays, np.array(kept_lines, dtype=np.int64), issues)


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


def _parse(cell: str, col: Column, issues: list[str]) -> float:
    if cell == "":
        if col.required:
            issues.append(f"column {col.name!r} is empty")
        return math.nan
    try:
        value = float(cell)
    except ValueError:
        issues.append(f"column {col.name!r}: {cell!r} is not a number")
        return math.nan
    if math.isnan(value):
        issues.append(f"column {col.name!r} is NaN")
        return math.nan
    if not col.lo <= value <= col.hi:
        unit = f" {col.unit}" if col.unit else ""
        issues.append(f"column {col.name!r}: {value:g}{unit} is outside [{col.lo:g}, {col.hi:g}]")
        return math.nan
    return value
