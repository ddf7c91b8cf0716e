"""What the commands share beyond options: reading the config and the DEM with a status line,
parsing the stop rule once into a rule object, and progress that shows on a terminal (a bar) and
off it (a line every few seconds, so logs of long jobs show they are alive)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import click

from .main import err_console

if TYPE_CHECKING:  # the rules load the sensor model and the kernels: imported when a command runs
    from ..rules import StopRule


def load_config(config_path):
    """The TOML configuration (pydantic is imported only by the commands that read one)."""
    from ..io.config import load_config as load

    return load(config_path)


def open_dem(paths, vertical, geoid, dem_crs):
    """The DEM of --dem (None when not given); a DEMError names the file and the fix."""
    if not paths:
        return None
    from ..terrain import open_dem as open_

    with working("reading the DEM..."):
        return open_(list(paths), vertical=vertical, geoid=geoid, assume_crs=dem_crs)


def stop_rule(rule_values: dict, dem=None, *, required: bool = True, what: str = "one stop rule") -> StopRule | None:
    """The command line's stop rule (:func:`eoloc.cli.options.rule_options`), parsed once into a
    rule object: the one rule given a value, or the DEM; a flag given without a value takes each
    target's value from the files (:class:`eoloc.rules.RangeFromRecords`). None when nothing is
    given and the rule is not ``required``; a usage error naming the flags otherwise."""
    from ..errors import InputError
    from ..rules.spec import FROM_RECORDS, SPECS, chosen

    values = {**rule_values, "dem": dem}
    if not required and all(v is None for v in values.values()):
        return None
    specs = [s for s in SPECS if s.key in values]
    try:
        spec, value = chosen(values, specs)
    except InputError:
        flags = [f"{s.flag} {s.metavar} ({s.help})" for s in specs]
        raise click.UsageError(f"choose {what}: {', '.join(flags[:-1])} or {flags[-1]}") from None
    # (the option's own type checked the number against the rule's domain)
    return spec.records_rule() if isinstance(value, str) and value == FROM_RECORDS else spec.rule(value)


def ground(rule_values: dict, dem=None, *, required: bool = True) -> StopRule | None:
    """The ground of the commands that need a surface (footprint, rectify, video, mux, photo):
    the one surface rule given (:func:`eoloc.cli.options.rule_options` with ``ground=True``)."""
    return stop_rule(rule_values, dem, required=required, what="the ground")


class LineProgress:
    """rich.progress's API (add_task, advance, update) for a stream that is not a terminal: one line
    on stderr when a task starts (at its first report: its inputs are checked by then), then at most
    every ``every_s`` seconds, and when it ends."""

    def __init__(self, every_s: float = 5.0) -> None:
        self.every_s = every_s
        self.tasks: dict[int, dict] = {}

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc) -> None:
        for t in self.tasks.values():
            if not exc[0] and t["total"] and t["done"] < t["total"]:
                self._line(t, force=True)

    def add_task(self, description: str, total=None, **_) -> int:
        k = len(self.tasks)
        self.tasks[k] = {"description": description, "total": total, "done": 0, "shown": time.monotonic(),
                         "start": time.monotonic(), "announced": False}
        return k

    def _announce(self, t: dict) -> None:
        """"started" once the job reports its first progress: its inputs have been checked by then,
        so a mistake in them is the only line printed, never after a "started"."""
        if not t["announced"]:
            t["announced"] = True
            err_console.print(f"{t['description']}: started" + (f" ({t['total']:,} to do)" if t["total"] else ""),
                              highlight=False)

    def advance(self, task: int, advance: float = 1) -> None:
        t = self.tasks[task]
        self._announce(t)
        t["done"] += advance
        self._line(t)

    def update(self, task: int, completed=None, total=None, description: str | None = None, **_) -> None:
        t = self.tasks[task]
        if total is not None:
            t["total"] = total
        self._announce(t)
        if completed is not None:
            t["done"] = completed
        if description is not None and description != t["description"]:  # a new step: said at once
            t["description"] = description
            err_console.print(f"{description}...", highlight=False)
            return
        self._line(t)

    def _line(self, t: dict, force: bool = False) -> None:
        now = time.monotonic()
        finished = bool(t["total"]) and t["done"] >= t["total"]
        if not (force or finished or now - t["shown"] >= self.every_s) or t.get("ended"):
            return
        t["shown"] = now
        t["ended"] = finished
        of = f"/{t['total']:,}" if t["total"] else ""
        pct = f" ({100 * t['done'] / t['total']:.0f} %)" if t["total"] else ""
        err_console.print(f"{t['description']}: {t['done']:,.0f}{of}{pct}, {now - t['start']:.0f} s",
                          highlight=False)


def working(message: str):
    """A step under way: a spinner with ``message`` on a terminal. Elsewhere (CI logs, pipes)
    nothing, as rich's spinner writes nothing there either; but its display is then not even
    imported (~10 ms of start-up)."""
    if err_console.is_terminal:
        return err_console.status(message)
    import contextlib

    return contextlib.nullcontext()


def progress():
    """A progress display: a bar on a terminal, progress lines elsewhere (CI logs, pipes)."""
    if not err_console.is_terminal:
        return LineProgress()
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                    console=err_console, transient=True)
