"""The faults of a live session, counted and reported at a bounded rate in bounded memory.

A ground station can receive thousands of bad datagrams a second (a noisy link, a scanner, a
replay of a damaged file): a line on stderr per fault would be the session's main cost, and a
list of them its memory. So each fault is counted under its kind ("checksum", "not KLV", "field
2: ..."); the first of a kind is reported at once, whole; after that a kind is reported at most
once every ``every_s`` seconds, as the number since its last report with the latest message.
The counts go in the session's summary. Memory: the counts, and one message per kind, for at
most ``max_kinds`` kinds (further kinds are counted as "other").
"""

from __future__ import annotations

import time
from collections.abc import Callable


class FaultLog:
    """Faults by kind: :meth:`add` as they happen, :meth:`due` for the lines to print now,
    :meth:`flush` for what is left at the end, :meth:`counts` for the summary."""

    def __init__(self, every_s: float = 5.0, max_kinds: int = 64, clock: Callable[[], float] = time.monotonic) -> None:
        self.every_s, self.max_kinds, self.clock = every_s, max_kinds, clock
        self.total: dict[str, int] = {}
        self.unreported: dict[str, tuple[int, str]] = {}  # kind -> (faults since its last report, the latest)
        self.reported_at: dict[str, float] = {}

    def add(self, kind: str, message: str, count: int = 1) -> None:
        if kind not in self.total and len(self.total) >= self.max_kinds:
            kind = "other"
        self.total[kind] = self.total.get(kind, 0) + count
        n, _ = self.unreported.get(kind, (0, ""))
        self.unreported[kind] = (n + count, message)

    def due(self) -> list[str]:
        """The lines to print now: a kind's first fault, and each kind's faults since its last
        report once ``every_s`` has passed since then."""
        now = self.clock()
        lines = []
        for kind, (n, message) in list(self.unreported.items()):
            last = self.reported_at.get(kind)
            if last is None:
                lines.append(message + ("" if n == 1 else f" (and {n - 1} more {kind} faults)"))
            elif now - last >= self.every_s:
                lines.append(f"{n} more {kind} fault{'s' if n > 1 else ''} in the last {now - last:.0f} s; "
                             f"the latest: {message}")
            else:
                continue
            self.reported_at[kind] = now
            del self.unreported[kind]
        return lines

    def flush(self) -> list[str]:
        """Every fault not reported yet (at the end of a session)."""
        lines = []
        for kind, (n, message) in self.unreported.items():
            lines.append(message if n == 1 and kind not in self.reported_at else
                         f"{n} more {kind} fault{'s' if n > 1 else ''}; the latest: {message}")
        self.unreported.clear()
        return lines

    def counts(self) -> dict[str, int]:
        return dict(self.total)
