"""Rich renderings of job results, shared by the commands and the demo: the fix summary table and
number cells, the compensation band table, the KLV packet summary and frame check, issue lists,
the batch table. Presentation only: the jobs return data, this turns it into tables."""

from __future__ import annotations

import numpy as np
from rich.cells import cell_len
from rich.console import Console
from rich.markup import escape
from rich.table import Table as RichTable
from rich.text import Text

from ..io.records import Records


class TitledTable(RichTable):
    """A rich table whose title, when wider than the table, is a line of its own above it (wrapped
    at the console's width, not the table's): rich would wrap it at the table's width ("91
    targets: INVALID_INPUT 90," over "NO_TELEMETRY 1")."""

    def __rich_console__(self, console, options):
        title = self.title
        if not isinstance(title, str) or cell_len(title) <= self.__rich_measure__(console, options).maximum:
            yield from super().__rich_console__(console, options)
            return
        yield Text(title, style="table.title")
        self.title = None
        try:
            yield from super().__rich_console__(console, options)
        finally:
            self.title = title


def titled_table(title: str, **kwargs) -> RichTable:
    """A table with a title that is never wrapped at the table's width (:class:`TitledTable`)."""
    return TitledTable(title=title, **kwargs)


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
    table = titled_table(f"{n} targets: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
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


def band_table(rows, title: str) -> RichTable:
    """CEP50 by oblique band, located and after each correction, with the change."""
    t = titled_table(title, caption="CEP50 in metres; Δ: change against 'located'")
    t.add_column("oblique")
    t.add_column("n", justify="right")
    t.add_column("located", justify="right")
    names = list(rows[0].cep_after_m) if rows else []
    for n in names:
        t.add_column(n, justify="right")
        t.add_column("Δ", justify="right")
    for r in rows:
        cells = [("> " if r.summary else "") + (f"{r.lo_deg:.0f}°" if r.summary else f"{r.lo_deg:.0f}–{r.hi_deg:.0f}°"),
                 str(r.n), f"{r.cep_before_m:.2f}"]
        for n in names:
            cells += [f"{r.cep_after_m[n]:.2f}", f"{-100 * r.reduction(n):+.0f}%"]
        t.add_row(*cells)
    return t


def print_bands(rows, title: str, console: Console | None = None) -> None:
    (console or Console()).print(band_table(rows, title))


def print_issues(issues, err_console: Console, limit: int = 15) -> None:
    """The per-line problems of the inputs (file:line: message), the first ``limit`` of them."""
    issues = list(issues)
    for issue in issues[:limit]:
        # one line each, never wrapped: a file:line reference stays whole for the eye, grep and editors
        err_console.print(f"[yellow]warning:[/] {escape(str(issue))}", highlight=False, soft_wrap=True)
    if len(issues) > limit:
        err_console.print(f"[yellow]... and {len(issues) - limit} more issues[/]")


def print_klv_job(job, console: Console, err_console: Console) -> None:
    """What `eoloc klv` says about a stream: packets, issues, departures from the standard, then per
    stream its span and the frame check against the encoder, the VMTI summary and the convention
    check."""
    stream, tel, check = job.stream, job.telemetry, job.check
    console.print(escape(stream.summary()))
    print_issues(stream.issues, err_console)
    for w in stream.notes:
        err_console.print(f"[yellow]note:[/] {escape(str(w))}", highlight=False, soft_wrap=True)
    print_issues(job.issues, err_console)
    if job.assume:
        console.print(f"read under: {', '.join(job.assume)} (--assume)")
    c = tel.columns
    names = list(dict.fromkeys(c["stream"]))
    surface = "the DEM" if job.dem is not None else "the ellipsoid at the encoder's frame-centre elevation"
    for name in names:
        rows = c["stream"] == name
        label = f"{name}: " if name else ""
        t = c["time_s"][rows & np.isfinite(c["time_s"])]
        h, fov = c["h_m"][rows], c["hfov_deg"][rows]
        span = f" over {t[-1] - t[0]:.1f} s" if t.size > 1 else ""
        if not np.isfinite(h).any():
            console.print(f"{label}{_packets(int(rows.sum()))}{span}; no sensor position or height: nothing to locate "
                          "from this stream")
            continue
        fovs = (f"; HFOV {np.nanmin(fov):.2f}-{np.nanmax(fov):.2f}°" if np.isfinite(fov).any() else
                "; no field of view (tag 16)")
        console.print(f"{label}{_packets(int(rows.sum()))}{span}; sensor at {np.nanmin(h):.0f}-{np.nanmax(h):.0f} m "
                      f"ellipsoidal{fovs}")
        stats = check.stats(rows)
        if not any(n for _, n, *_ in stats):
            console.print(f"{label}nothing to compare with the encoder (no frame centre, corner or slant range sent)")
            continue
        table = titled_table(f"{label}eoloc vs the encoder: horizontal distance (m), ours on {surface}")
        for col in ("", "packets", "median", "p90", "max"):
            table.add_column(col, justify="right")
        for what, n, med, p90, mx in stats:
            table.add_row(what, str(n), *(f"{x:.1f}" if np.isfinite(x) else "-" for x in (med, p90, mx)))
        console.print(table)
    if job.dem is not None:
        console.print("[dim]On a DEM the corners are compared with the encoder's own surface for them (often a level "
                      "plane through the frame centre, or a coarser terrain model): far corners of an oblique view "
                      "differ by the terrain, not the pointing. Leave out --dem to compare the pointing alone.[/]")
    if job.vmti is not None:
        det = job.detections
        console.print(f"VMTI: {len(det)} detections of {len(set(det.columns['target_id']))} targets located on "
                      f"{job.surface}: {job.vmti.fixes.status_counts()}"
                      + ("" if "ce90_m" in job.vmti.uncertainty else
                         escape(" (no [accuracy.budget] given: no uncertainty)")))
    else:
        console.print("no VMTI detections (tag 74) in this stream: frame centres and footprints only")
    print_diagnoses(job.diagnoses, console)


def _packets(n: int) -> str:
    return f"{n} packet{'s' if n != 1 else ''}"


def print_diagnoses(diagnoses, console: Console) -> None:
    """The convention check: one sentence per quantity, and the trials when the encoder departs."""
    for dg in diagnoses:
        console.print(escape("convention check: " + dg.sentence()))
        if dg.follows is None and not dg.disagrees:
            continue
        table = titled_table(f"{dg.what}: eoloc vs the encoder under each reading (m)")
        for col in ("reading", "stop", "n", "median", "p90"):
            table.add_column(col, justify="right" if col in ("n", "median", "p90") else "left")
        for t in dg.trials:
            mark = " <" if t is dg.follows else ""
            table.add_row(t.label + mark, t.stop, str(t.n),
                          *(f"{x:.1f}" if np.isfinite(x) else "-" for x in (t.median_m, t.p90_m)))
        console.print(table)



def rich_table(t) -> RichTable:
    """A table given as data (title, header, rows of strings, caption, alignment()) as a rich
    table: the jobs say what a table holds, the CLI and the HTML report how it looks."""
    r = titled_table(t.title, caption=t.caption or None)
    for h, a in zip(t.header, t.alignment(), strict=True):
        r.add_column(h, justify="left" if a == "l" else "right")
    for row in t.rows:
        r.add_row(*(escape(str(c)) for c in row))
    return r


BATCH_STYLE = {"done": "green", "skipped": "dim", "failed": "red", "bug": "bold red"}


def batch_table(job, limit: int = 40) -> RichTable:
    """`eoloc batch`'s per-file status: the first ``limit`` files, failures first, and the totals."""
    import os

    results = sorted(job.results, key=lambda r: (r.status not in ("bug", "failed"), r.path))
    counts = job.counts()
    paths = [os.path.abspath(r.path) for r in results]
    base = os.path.dirname(os.path.commonpath(paths)) if len(paths) == 1 else os.path.commonpath(paths) if paths else ""
    t = titled_table(f"{len(job.results)} files under {base}: " + ", ".join(f"{k} {v}" for k, v in counts.items()),
                  caption=None if len(results) <= limit else f"first {limit} of {len(results)} (all in "
                                                             "batch_status.csv)")
    for col in ("file", "status", "packets", "fixes", "OK", "issues", "s", "message"):
        t.add_column(col, justify="right" if col in ("packets", "fixes", "OK", "issues", "s") else "left",
                     overflow="fold")
    for r, path in list(zip(results, paths, strict=True))[:limit]:
        t.add_row(escape(os.path.relpath(path, base)), f"[{BATCH_STYLE.get(r.status, '')}]{r.status}[/]",
                  str(r.packets), str(r.fixes), str(r.fixes_ok), str(r.issues), f"{r.seconds:.2f}", escape(r.message))
    return t
