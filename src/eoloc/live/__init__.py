"""eoloc live: KLV streams as they arrive. :func:`run` drives a :class:`LiveSession` (demultiplex,
decode, locate, refine; with :class:`LiveMovers` the movers found in the stream's own video) on a
source (:mod:`.sources`) into sinks (:mod:`.sinks`)."""

from typing import TYPE_CHECKING

from ..util.lazy import lazy_attributes

if TYPE_CHECKING:  # the same names as _WHERE, for type checkers and the API reference (read statically)
    from .klvout import KlvOut
    from .loop import RunResult, run
    from .movers import LiveMovers
    from .session import LiveSession
    from .sinks import BaseSink, CotSink, NdjsonSink, Sink
    from .update import PacketUpdate

_WHERE = {"run": "loop", "RunResult": "loop", "LiveSession": "session", "Sink": "sinks", "BaseSink": "sinks",
          "NdjsonSink": "sinks", "CotSink": "sinks", "KlvOut": "klvout", "PacketUpdate": "update",
          "LiveMovers": "movers"}

__getattr__ = lazy_attributes(__name__, _WHERE)

__all__ = ["BaseSink", "CotSink", "KlvOut", "LiveMovers", "LiveSession", "NdjsonSink", "PacketUpdate", "RunResult",
           "Sink", "run"]
