"""Rich renderings of job results shared by the CLI and the demo (both present jobs; neither
imports the other): the compensation band table, the KLV packet summary and frame check."""

from __future__ import annotations

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table as RichTable


def band_table(rows, title: str) -> RichTable:
    """CEP50 by oblique band, located and after each correction, with the change."""
    t = RichTable(title=title, caption="CEP50 in metres; Δ: change against 'located'")
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
    """What `eoloc klv` says about a stream: packets, issues, field notes, the span, the frame
    check against the encoder and the VMTI summary."""
    stream, tel, check = job.stream, job.telemetry, job.check
    console.print(escape(stream.summary()))
    print_issues(stream.issues, err_console)
    for w in stream.field_warnings:
        err_console.print(f"[yellow]note:[/] {escape(w)}", highlight=False)
    c = tel.columns
    t = c["time_s"][np.isfinite(c["time_s"])]
    if t.size and np.isfinite(c["h_m"]).any() and np.isfinite(c["hfov_deg"]).any():
        console.print(f"{len(tel)} packets over {t[-1] - t[0]:.1f} s; sensor at {np.nanmin(c['h_m']):.0f}-"
                      f"{np.nanmax(c['h_m']):.0f} m ellipsoidal; HFOV {np.nanmin(c['hfov_deg']):.2f}-"
                      f"{np.nanmax(c['hfov_deg']):.2f}°")
    surface = "the DEM" if job.dem is not None else "the ellipsoid at the encoder's frame-centre elevation"
    table = RichTable(title=f"eoloc vs the encoder: horizontal distance (m), ours on {surface}")
    for col in ("", "packets", "median", "p90", "max"):
        table.add_column(col, justify="right")
    for name, n, med, p90, mx in check.stats():
        table.add_row(name, str(n), *(f"{x:.1f}" if np.isfinite(x) else "-" for x in (med, p90, mx)))
    console.print(table)
    if job.dem is not None:
        console.print("[dim]On a DEM the corners are compared with the encoder's own surface for them (often a level "
                      "plane through the frame centre, or a coarser terrain model): far corners of an oblique view "
                      "differ by the terrain, not the pointing. Leave out --dem to compare the pointing alone.[/]")
    print_issues(job.issues, err_console)
    if job.vmti is not None:
        det = job.detections
        console.print(f"VMTI: {len(det)} detections of {len(set(det.columns['target_id']))} targets located on "
                      f"{job.surface}: {job.vmti.fixes.status_counts()}"
                      + ("" if "ce90_m" in job.vmti.uncertainty else
                         escape(" (no [accuracy.budget] given: no uncertainty)")))
    else:
        console.print("no VMTI detections (tag 74) in this stream: frame centres and footprints only")
