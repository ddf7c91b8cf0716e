"""The live map as a sink of :func:`eoloc.live.run`: eoloc serve's app with the map's routes on
its own server, fed every update (:class:`eoloc.service.livemap.LiveHub`)."""

from __future__ import annotations

from collections.abc import Callable

from ..live.sinks import BaseSink
from .livemap import LiveHub, MapServer


class MapSink(BaseSink):
    """Serves the live map at ``host:port`` (port 0: any free one; ``url`` once started) while
    the run lasts, and after the source ends until the run is stopped (:meth:`holds`).
    ``session``: its counters show on the page; ``dem``/``config``: what the page's clicks are
    located with; ``report(message, kind)``: where the page is, and that it stays up."""

    name = "map"

    def __init__(self, host: str, port: int, session, source: str, *, silence_s: float = 3.0, dem=None, config=None,
                 allow_hosts: tuple[str, ...] = (), report: Callable[[str, str], None] = lambda m, k: None) -> None:
        from .api import ServiceState, create_app
        from .http import allowed_hosts

        self.report = report
        self.hub = LiveHub(silence_s=silence_s, title=f"eoloc live: {source}",
                           counters=lambda: session.counters.counts() | {"streams": dict(session.streams)})
        state = ServiceState(config, {"dem": dem} if dem is not None else {})
        self.server = MapServer(create_app(state, hub=self.hub, hosts=allowed_hosts(host, tuple(allow_hosts))), host,
                                port)
        self.server.start()  # OSError when it cannot serve there
        self.url = self.server.url
        report(f"map at {self.url}", "map")

    def send(self, updates) -> None:
        for u in updates:
            self.hub.publish(u, u.features())

    def end(self, why: str | None) -> None:
        self.hub.stop(why or "end of the source")
        if why is None:
            self.report(f"the source ended; the map stays up at {self.url} (Ctrl-C stops)", "map")

    def holds(self) -> bool:
        return True

    def close(self) -> None:
        self.server.close()

    def summary(self) -> dict:
        return {"map": self.hub.summary()}
