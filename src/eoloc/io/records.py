"""Records: a layer's rows held as columns, which is how every writer takes them.

A million fixes are a dozen arrays, not a million dicts: the CSV writer renders them with
pyarrow, the GeoJSON writer streams them in chunks, and rows (plain Python values, None where
there is no value) are made only where a format needs them one by one (JSON, KML, CoT, a table on
screen).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Coded:
    """A text column drawn from a few names, as codes into them: ``names[codes]`` are its values
    (statuses, target ids). A writer that knows it renders each name once instead of every cell."""

    codes: np.ndarray
    names: np.ndarray

    def __len__(self) -> int:
        return len(self.codes)

    def __getitem__(self, index) -> Coded:
        return Coded(self.codes[index], self.names)


@dataclass
class Records:
    """Columns in output order: name -> 1-D array of one length (float64 with NaN where there is
    no value, int, bool, or objects: strings and None). ``coded``: text columns that are also
    held as :class:`Coded` (the column itself stays the reference)."""

    columns: dict[str, np.ndarray]
    coded: dict[str, Coded] = field(default_factory=dict)

    def __post_init__(self) -> None:
        sizes = {len(v) for v in self.columns.values()}
        if len(sizes) > 1:
            raise ValueError(f"Records: columns of different lengths {sorted(sizes)}")
        self.coded = {k: c for k, c in self.coded.items() if k in self.columns}  # dropped columns lose theirs
        if any(len(c.codes) != len(self.columns[k]) for k, c in self.coded.items()):
            raise ValueError("Records: a coded column's codes differ in length from the column")

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    @property
    def names(self) -> list[str]:
        return list(self.columns)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @classmethod
    def of(cls, records: Records | Sequence[Mapping]) -> Records:
        """Records as they are, or the columns of dict rows (:meth:`from_rows`)."""
        return records if isinstance(records, Records) else cls.from_rows(records)

    @property
    def has_points(self) -> bool:
        """Whether the records carry coordinates (a point layer) rather than a plain table."""
        return "lat_deg" in self.columns and "lon_deg" in self.columns

    @classmethod
    def from_rows(cls, rows: Sequence[Mapping]) -> Records:
        """Columns of dict rows (the union of their keys, in first-seen order; a missing key is
        no value)."""
        names: dict[str, None] = {}
        for row in rows:
            names.update(dict.fromkeys(row))
        return cls({k: column_of([row.get(k) for row in rows]) for k in names})

    def slice(self, start: int, stop: int) -> Records:
        return Records({k: v[start:stop] for k, v in self.columns.items()},
                       {k: c[start:stop] for k, c in self.coded.items()})

    def rows(self, start: int = 0, stop: int | None = None) -> list[dict]:
        """Rows ``start:stop`` as dicts of plain Python values (None where there is no value)."""
        names = list(self.columns)
        lists = [plain_list(v[start:stop]) for v in self.columns.values()]
        return [dict(zip(names, vals, strict=True)) for vals in zip(*lists, strict=True)]

    def chunks(self, size: int = 65536) -> Iterator[Records]:
        for start in range(0, len(self), size):
            yield self.slice(start, start + size)


def column_of(values: Sequence) -> np.ndarray:
    """One column from Python values: float64 (None as NaN) when all are numbers, int64 or bool
    when all are, else objects (strings, None)."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, (bool, np.bool_)) for v in present) and len(present) == len(values):
        return np.array(values, dtype=bool)
    if present and all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in present) \
            and len(present) == len(values):
        return np.array(values, dtype=np.int64)
    if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
           for v in present):
        return np.array([math.nan if v is None else v for v in values], dtype=np.float64)
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


def plain_list(v: np.ndarray) -> list:
    """A column as a list of plain Python values (:func:`plain_value`), numbers without a call each."""
    if v.dtype.kind == "f":
        return [None if x != x else x for x in v.tolist()]  # x != x: NaN
    if v.dtype.kind in "biu":
        return v.tolist()
    return [plain_value(x) for x in v.tolist()]


def plain_value(v):
    """A numpy scalar as a plain Python value; NaN as None (an empty cell / JSON null)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v
