"""Where a live session's updates go: the :class:`Sink` protocol and the sinks of this layer.

:class:`NdjsonSink` writes GeoJSON features, one per line; :class:`CotSink` sends
Cursor-on-Target to TAK (UDP, TCP, TLS). The live map's sink is ``eoloc.service.mapsink.MapSink``
(it serves pages), KLV passed on with the targets' locations ``eoloc.live.klvout.KlvOut`` (the
session rewrites the transport as it demultiplexes it; the sink closes it and counts). A new
sink: a class with :class:`Sink`'s methods (:class:`BaseSink` gives the ones it need not
override), and its option in ``eoloc live`` (``cli/live.py``'s ``SINKS``).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Sequence
from typing import Protocol

from .update import PacketUpdate


class Sink(Protocol):
    """Where the updates of a live session go. ``fatal``: a one-line reason once the sink cannot
    go on (the run stops on it), else None."""

    fatal: str | None

    def send(self, updates: list[PacketUpdate]) -> None:
        """The updates of one datagram (one or more packets)."""

    def silence(self, quiet_s: float) -> None:
        """Nothing has arrived for ``quiet_s`` seconds."""

    def end(self, why: str | None) -> None:
        """The run is stopping (``why``), or the source ended (None)."""

    def holds(self) -> bool:
        """True to keep the run alive after the source ended (a map people are looking at)."""

    def close(self) -> None:
        """Release what it holds (sockets, files, threads)."""

    def summary(self) -> dict:
        """Its counts for the run's summary."""


class BaseSink:
    """A sink that does nothing: subclasses override what they need."""

    name = "sink"
    fatal: str | None = None

    def send(self, updates: list[PacketUpdate]) -> None:
        pass

    def silence(self, quiet_s: float) -> None:
        pass

    def end(self, why: str | None) -> None:
        pass

    def holds(self) -> bool:
        return False

    def close(self) -> None:
        pass

    def summary(self) -> dict:
        return {}


class NdjsonSink(BaseSink):
    """Every update's GeoJSON features, one JSON object per line, to ``path`` ("-": stdout)."""

    name = "ndjson"

    def __init__(self, path: str) -> None:
        self.out = sys.stdout if path == "-" else open(path, "w", encoding="utf-8")  # closed in close()
        self.lines = 0

    def send(self, updates: list[PacketUpdate]) -> None:
        lines = [json.dumps(f, allow_nan=False) + "\n" for u in updates for f in u.features()]
        self.out.write("".join(lines))
        self.out.flush()
        self.lines += len(lines)

    def close(self) -> None:
        if self.out is not sys.stdout:
            self.out.close()

    def summary(self) -> dict:
        return {"ndjson_lines": self.lines}


class CotSink(BaseSink):
    """Cursor-on-Target events of the updates (:class:`eoloc.live.cotfeed.CotFeed`) to every URL of
    ``urls`` (udp://, tcp://, tls://; :func:`eoloc.live.senders.cot_sender`); ``fatal`` once a
    connection fails for good (a certificate TAK refuses)."""

    name = "cot"

    def __init__(self, urls: Sequence[str], *, interval_s: float = 0.0, targets: str = "fixes",
                 video_url: str | None = None, tls=None, protocol: str = "xml",
                 on_state: Callable[[str], None] | None = None) -> None:
        from .cotfeed import CotFeed
        from .senders import cot_sender

        self.feed = CotFeed(interval_s=interval_s, targets=targets, video_url=video_url)
        self.senders = [cot_sender(url, on_state=on_state, hello=self.feed.presence, tls=tls, protocol=protocol,
                                   uid=self.feed.presence_uid()) for url in urls]

    @property
    def fatal(self) -> str | None:  # type: ignore[override]
        return next((s.fatal for s in self.senders if s.fatal), None)

    def _send(self, events) -> None:
        for event in events:
            for s in self.senders:
                s.send(event)

    def send(self, updates: list[PacketUpdate]) -> None:
        for u in updates:
            self._send(self.feed.events(u))

    def silence(self, quiet_s: float) -> None:
        self._send(self.feed.silence(quiet_s))

    def close(self) -> None:
        for s in self.senders:
            s.close()

    def summary(self) -> dict:
        return {"cot_events": self.feed.events_out, "cot_held": self.feed.held,
                "cot": [s.summary() for s in self.senders]}
