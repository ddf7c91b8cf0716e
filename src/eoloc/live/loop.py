"""The live loop as a library: a source's datagrams through a :class:`LiveSession` into sinks.

    from eoloc.live import LiveSession, NdjsonSink, run
    source = "udp://0.0.0.0:5000"
    result = run(source, LiveSession(source), [NdjsonSink("-")], duration_s=60)

:func:`run` owns the loop: it opens the source (UDP, SRT, RTSP, a file, stdin:
:func:`eoloc.live.sources.open_source`), feeds every datagram to the session, hands each
datagram's :class:`PacketUpdate`s to every sink (:mod:`eoloc.live.sinks`), reports silence,
the source's events and the session's faults, and stops at the end of the source, after
``max_packets`` good packets or ``duration_s`` seconds, when ``should_stop()`` gives a reason, or
when a sink fails for good (its ``fatal``). ``eoloc live`` is this call with its options parsed.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .session import LiveSession
from .sinks import Sink


@dataclass
class RunResult:
    """How a run ended: ``why`` (None: the source ended), ``fatal`` (a sink's failure, else
    None) and ``summary`` (the session's, the source's and every sink's counts)."""

    why: str | None
    fatal: str | None
    summary: dict = field(default_factory=dict)


def run(source: str, session: LiveSession, sinks: Sequence[Sink], *, max_packets: int | None = None,
        duration_s: float | None = None, realtime: bool = False, silence_s: float = 3.0,
        should_stop: Callable[[], str | None] | None = None,
        report: Callable[[str, str], None] = lambda message, kind: None, stdin=None) -> RunResult:
    """Run ``session`` on ``source`` into ``sinks`` until the source ends or a stop condition
    holds (``max_packets`` good packets, ``duration_s`` seconds, ``should_stop()`` returning a
    reason, a sink's ``fatal``); then, while a sink ``holds()`` the run (the live map), until a
    stop condition. ``report(message, kind)`` hears where the source was opened ("start"),
    silence ("silence"), the source's events ("source") and the session's faults ("fault"). The
    sinks are closed on the way out, whatever happens."""
    from .sources import open_source

    started = time.monotonic()
    state: dict = {"why": None}

    def stop() -> bool:
        if state["why"] is None:
            if duration_s is not None and time.monotonic() - started > duration_s:
                state["why"] = f"duration {duration_s:g} s"
            elif max_packets is not None and session.counters.packets >= max_packets:
                state["why"] = f"{max_packets} packets"
            elif (fatal := next((s.fatal for s in sinks if s.fatal), None)) is not None:
                state["why"], state["fatal"] = f"the {_name(sinks, fatal)} output failed", fatal
            elif should_stop is not None:
                state["why"] = should_stop()
        return state["why"] is not None

    def on_silence(quiet_s: float) -> None:
        report(f"{source}: nothing received for {quiet_s:.0f} s", "silence")
        for s in sinks:
            s.silence(quiet_s)

    feed = None
    try:
        feed, where, source_state = open_source(source, stop, realtime=realtime, silence_s=silence_s,
                                                on_silence=on_silence, on_event=lambda m: report(m, "source"),
                                                stdin=stdin)
        report(where, "start")
        for datagram, arrived, *stream in feed:
            updates = session.feed(datagram, *stream) + session.mover_updates()
            if updates:
                for s in sinks:
                    s.send(updates)
            session.done(arrived)
            for line in session.faults.due():  # the first of each kind, then a count every few seconds
                report(line, "fault")
            if stop():
                break
        # the video's last frames searched (the movers trail the video by the detector's window)
        last = session.mover_updates(final=True, timeout_s=120.0 if state["why"] is None else 5.0)
        if last:
            for s in sinks:
                s.send(last)
        for s in sinks:
            s.end(state["why"])
        if state["why"] is None and any(s.holds() for s in sinks):
            while not stop():
                time.sleep(0.1)
    finally:
        if session.movers is not None:
            session.movers.close()
        if feed is not None:
            feed.close()
        for s in sinks:
            s.close()
    for line in session.faults.flush():
        report(line, "fault")
    summary = session.counters.summary() | source_state.summary() | {"faults": session.faults.counts(),
                                                                      "streams": session.streams}
    if session.movers is not None:
        summary |= session.movers.summary()
    for s in sinks:
        summary |= s.summary()
    fatal = state.get("fatal") or next((s.fatal for s in sinks if s.fatal), None)
    return RunResult(state["why"], fatal, summary)


def _name(sinks: Sequence[Sink], fatal: str) -> str:
    return next((getattr(s, "name", "an") for s in sinks if s.fatal == fatal), "an")
