"""The live map: an offline Leaflet page served over HTTP and kept up to date over a WebSocket.

:class:`LiveHub` is the bridge between the pipeline and the browsers. The pipeline (its own
thread) calls :meth:`LiveHub.publish` with each packet's GeoJSON features; that serialises the
message once and hands it to the server's event loop, which appends it to every browser's own
bounded queue. A browser that reads too slowly loses its oldest messages (counted, and told to
it in its status); neither the pipeline nor the other browsers ever wait for it.

Once a second every browser gets a status message: ``waiting`` (nothing yet), ``live``,
``silent`` (no packet for the session's silence time) or ``stopped`` (the source ended, with
why), the session's counters and the messages dropped for that browser. A browser that has not
heard from the server for a few seconds says so itself (the page shows "no contact").

Messages (JSON text frames)::

    {"type": "packet", "key", "stream", "index", "time_utc", "late", "features": [GeoJSON ...]}
    {"type": "status", "state", "quiet_s", "silence_s", "why", "counters", "streams", "dropped",
     "sent", "clients"}

A browser that connects late first gets the newest packet of every stream, so it draws the
present at once.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable

import orjson

QUEUE = 256  # messages held per browser; past this its oldest are dropped (and counted)
HEARTBEAT_S = 1.0
WS_PATH = "/v1/live/ws"


class _Client:
    def __init__(self, size: int) -> None:
        self.queue: deque[bytes] = deque(maxlen=size)
        self.ready = asyncio.Event()
        self.dropped = 0
        self.sent = 0
        self.closed = False
        self.since = 0  # the messages published before it connected came in its first snapshot

    def put(self, data: bytes) -> None:
        if len(self.queue) == self.queue.maxlen:
            self.dropped += 1  # deque(maxlen) drops the oldest itself
        self.queue.append(data)
        self.ready.set()


class LiveHub:
    """Fans the pipeline's messages out to the browsers of the live map (see the module)."""

    def __init__(self, *, silence_s: float = 3.0, queue: int = QUEUE, title: str = "eoloc live",
                 counters: Callable[[], dict] | None = None) -> None:
        self.silence_s, self.queue_size, self.title = silence_s, queue, title
        self.counters = counters or dict
        self.loop: asyncio.AbstractEventLoop | None = None
        self.clients: set[_Client] = set()
        self.newest: OrderedDict[str, bytes] = OrderedDict()  # stream -> its newest packet message
        self.lock = threading.Lock()
        self.last_packet: float | None = None  # time.monotonic() of the newest packet
        self.stopped: str | None = None
        self.published = 0
        self.connections = 0
        self.gone = {"sent": 0, "dropped": 0}  # of browsers that have left

    # the pipeline's side (any thread)
    def publish(self, update, features: list[dict] | None = None) -> None:
        """Send one :class:`~eoloc.live.update.PacketUpdate` (its features, when already made) to
        every browser."""
        self.publish_message({"type": "packet", "kind": update.kind, "key": update.key, "stream": update.stream,
                              "index": update.index, "time_utc": update.time_utc, "late": update.late,
                              "features": update.features() if features is None else features})

    def publish_message(self, message: dict) -> None:
        data = orjson.dumps(message, option=orjson.OPT_SERIALIZE_NUMPY)
        with self.lock:
            self.newest[f'{message.get("stream", "")}/{message.get("kind", "")}'] = data
            self.last_packet = time.monotonic()
            self.published += 1
            number = self.published
        loop = self.loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._fan_out, data, number)

    def stop(self, why: str) -> None:
        """The source has ended: every browser is told at once (and by each status after)."""
        self.stopped = why
        loop = self.loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._status_all)

    def summary(self) -> dict:
        """Browsers connected over the session, messages published, sent and dropped (all browsers)."""
        sent = self.gone["sent"] + sum(c.sent for c in self.clients)
        dropped = self.gone["dropped"] + sum(c.dropped for c in self.clients)
        return {"connections": self.connections, "connected": len(self.clients), "published": self.published,
                "sent": sent, "dropped": dropped}

    # the server's side (its event loop)
    def _fan_out(self, data: bytes, number: int) -> None:
        """Message ``number`` to every browser that did not have it in its first snapshot (it may
        have connected between the publishing and this call)."""
        for c in self.clients:
            if number > c.since:
                c.put(data)

    def status(self) -> dict:
        """The session's state (waiting, live, silent, stopped), its counters and the browsers."""
        now = time.monotonic()
        quiet = None if self.last_packet is None else now - self.last_packet
        state = ("stopped" if self.stopped else "waiting" if quiet is None
                 else "silent" if quiet > self.silence_s else "live")
        counters = self.counters()
        return {"type": "status", "state": state, "why": self.stopped, "quiet_s": quiet, "silence_s": self.silence_s,
                "counters": {k: v for k, v in counters.items() if k != "streams"},
                "streams": counters.get("streams", {}), "clients": len(self.clients)}

    @staticmethod
    def _for(client: _Client, status: dict) -> bytes:
        """The status as one browser gets it: with what it was sent and lost."""
        return orjson.dumps(status | {"dropped": client.dropped, "sent": client.sent})

    def _status_all(self) -> None:
        status = self.status()
        for c in self.clients:
            c.put(self._for(c, status))

    async def heartbeat(self) -> None:
        while True:
            await asyncio.sleep(HEARTBEAT_S)
            self._status_all()

    async def serve(self, websocket) -> None:
        """One browser's connection (a Starlette WebSocket), until it goes."""
        from starlette.websockets import WebSocketDisconnect

        await websocket.accept()
        client = _Client(self.queue_size)
        with self.lock:
            for data in self.newest.values():
                client.put(data)
            client.since = self.published
        client.put(self._for(client, self.status()))
        self.clients.add(client)
        self.connections += 1

        async def listen() -> None:  # a browser says nothing; this notices when it goes
            try:
                while (await websocket.receive())["type"] != "websocket.disconnect":
                    pass
            finally:
                client.closed = True
                client.ready.set()

        listener = asyncio.create_task(listen())
        try:
            while not client.closed:
                await client.ready.wait()
                client.ready.clear()
                while client.queue and not client.closed:
                    await websocket.send_text(client.queue.popleft().decode())
                    client.sent += 1
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the browser went while a message was on its way
        finally:
            listener.cancel()
            self.clients.discard(client)
            self.gone["sent"] += client.sent
            self.gone["dropped"] += client.dropped

    def page(self) -> str:
        """The live map page: Leaflet inlined (no network needed), the WebSocket at WS_PATH."""
        from ..io.mapview import offline_page

        return offline_page("livemap/live.html", {"/*LIVE_JS*/": "livemap/live.js"},
                            {"TITLE": self.title, "WS_PATH": WS_PATH})


class MapServer:
    """The HTTP server of the live map (uvicorn, in its own thread): ``app`` is eoloc's API app
    with the hub's routes (:func:`eoloc.service.api.create_app` with ``hub=``)."""

    def __init__(self, app, host: str, port: int) -> None:
        import uvicorn

        from .http import server_config

        self.server = uvicorn.Server(server_config(app, host, port, log_level="warning", ws="auto", lifespan="on"))
        self.thread = threading.Thread(target=self.server.run, name="eoloc-map", daemon=True)
        self.host = host
        self.url = ""

    def start(self, timeout_s: float = 10.0) -> str:
        """Start serving; the page's URL (also ``self.url``)."""
        self.thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise OSError(f"the live map's server did not start on {self.host}")
            time.sleep(0.01)
        port = self.server.servers[0].sockets[0].getsockname()[1]
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        self.url = f"http://{host}:{port}/live"
        return self.url

    def close(self, flush_s: float = 0.3) -> None:
        time.sleep(flush_s)  # the last status reaches the browsers
        self.server.should_exit = True
        self.thread.join(timeout=5.0)
