"""Rich renderings the commands share: the fix summary table and number cells. (Renderings the
demo shares with the commands live in :mod:`eoloc.render`, outside the CLI package.)"""

from __future__ import annotations

import numpy as np
from rich.table import Table as RichTable

from ..io.records import Records


def number_cell(key: str, v) -> str:
    """A table cell: coordinates with 8 decimals (1 mm), other floats with 3, '-' for none."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.8f}" if key in ("lat", "lon") or key.endswith("_deg") else f"{v:.3f}"
    return str(v)


def fix_summary_table(records: Records, counts: dict[str, int], limit: int = 12) -> RichTable:
    """The first ``limit`` fix records, with the status counts in the title; empty columns dropped."""
    n = len(records)
    table = RichTable(title=f"{n} targets: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    cols = ("time_s", "frame", "target_id", "lat_deg", "lon_deg", "h_m", "range_m", "status")
    cols = tuple(c for c in cols if c in records.columns and _has_values(records[c]))
    for c in cols:
        # coordinates never wrap or get cut to "44.9999…" at 80 columns
        table.add_column(c, no_wrap=True, overflow="fold" if not c.endswith("_deg") else "ignore",
                         min_width=13 if c.endswith("_deg") else None)
    for row in records.rows(0, limit):
        table.add_row(*(number_cell(c, row.get(c)) for c in cols))
    if n > limit:
        table.caption = f"first {limit} of {n} rows"
    return table


def _has_values(v: np.ndarray) -> bool:
    return bool((~np.isnan(v)).any()) if v.dtype.kind == "f" else any(x is not None for x in v)
