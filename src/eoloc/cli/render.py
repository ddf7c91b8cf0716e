"""Rich renderings the commands share: the fix summary table and number cells. (Renderings the
demo shares with the commands live in :mod:`eoloc.render`, outside the CLI package.)"""

from __future__ import annotations

from rich.table import Table as RichTable


def number_cell(key: str, v) -> str:
    """A table cell: coordinates with 8 decimals (1 mm), other floats with 3, '-' for none."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.8f}" if key in ("lat", "lon") or key.endswith("_deg") else f"{v:.3f}"
    return str(v)


def fix_summary_table(rows: list[dict], counts: dict[str, int], limit: int = 12) -> RichTable:
    """The first ``limit`` fix rows, with the status counts in the title; empty columns dropped."""
    table = RichTable(title=f"{len(rows)} targets: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    cols = ("time_s", "frame", "target_id", "lat_deg", "lon_deg", "h_m", "range_m", "status")
    cols = tuple(c for c in cols if any(r.get(c) is not None for r in rows))
    for c in cols:
        # coordinates never wrap or get cut to "44.9999…" at 80 columns
        table.add_column(c, no_wrap=True, overflow="fold" if not c.endswith("_deg") else "ignore",
                         min_width=13 if c.endswith("_deg") else None)
    for row in rows[:limit]:
        table.add_row(*(number_cell(c, row.get(c)) for c in cols))
    if len(rows) > limit:
        table.caption = f"first {limit} of {len(rows)} rows"
    return table
