"""Timing helpers shared by the benchmarks: best-of-N wall time, machine description."""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable


def best_time(fn: Callable[[], object], repeat: int = 5, number: int = 1) -> float:
    """Best wall time (s) of ``number`` calls, over ``repeat`` tries, after one warm-up call."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}"


def row(work: str, figure: str, peer: str, ratio: float | None) -> str:
    """One table row; ``ratio`` is the peer's time over eoloc's (above 1: eoloc is faster)."""
    r = "" if ratio is None else (f"{ratio:.1f}x" if ratio >= 1 else f"{ratio:.2g}x")
    return f"| {work} | {figure} | {peer} | {r} |"


HEADER = "| work | eoloc | peer (same run) | peer time / eoloc time |\n|---|---|---|---|"


def script(main: Callable[[float], list[str]], doc: str | None, *, flag: str = "--n", kind: type = int,
           default: float = 1_000_000, help_text: str = "elements per batch (default 10^6)") -> None:
    """Command-line entry of one benchmark script: one argument (``flag``, default ``--n``
    elements) handed to ``main``; prints the machine and a table."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(flag, dest="value", type=kind, default=default, help=help_text)
    print(machine())
    print(HEADER)
    print("\n".join(main(ap.parse_args().value)))
