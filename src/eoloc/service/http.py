"""The HTTP server under eoloc's services (`eoloc serve`, `eoloc live --map`): uvicorn with limits
and time-outs that keep it up and its memory bounded under slow or hostile clients.

- **A request must arrive whole** (headers and body) within ``request_timeout_s`` of the
  connection, or of the previous answer on a kept-alive connection: a client that trickles its
  headers or its body (slowloris) is answered 408 and cut, instead of holding a connection and a
  worker for as long as it likes. uvicorn itself has no such time-out (only the keep-alive one,
  which any byte resets).
- **An answer must be read**: a client that reads nothing of it for ``send_timeout_s`` (the
  socket's write buffer stays full) is cut, and the answer's bytes are freed. Thirty clients that
  never read their 15 MB answers would otherwise hold 450 MB for as long as they stay connected.
- **At most ``limit_concurrency`` connections and tasks** (uvicorn's own limit: 503 beyond it),
  headers of at most 16 KiB (h11's), keep-alive 5 s; request bodies are limited by
  :class:`eoloc.service.api.SizeLimit` (413), and what an Arrow body declares is checked before it
  is decoded (:mod:`eoloc.service.arrowcheck`).
- **Host names**: only requests whose ``Host`` header names this server are served (starlette's
  ``TrustedHostMiddleware``, 400 otherwise), so that a web page on another site cannot reach a
  server on loopback by rebinding a DNS name to 127.0.0.1 (:func:`allowed_hosts`).
"""

from __future__ import annotations

import socket
import struct

REQUEST_TIMEOUT_S = 20.0
SEND_TIMEOUT_S = 30.0
KEEP_ALIVE_S = 5.0
LIMIT_CONCURRENCY = 1024
LOOPBACK = ("localhost", "127.0.0.1", "[::1]")


def allowed_hosts(bind: str, extra: tuple[str, ...] = ()) -> list[str]:
    """The host names a server bound to ``bind`` answers to (as ``Host`` headers give them, IPv6
    addresses in brackets): loopback's, the bound address, and on a wildcard address (0.0.0.0, ::)
    this machine's names and addresses; plus ``extra`` (``*``: any)."""
    names = {*LOOPBACK, bind, *extra}
    if bind in ("", "0.0.0.0", "::"):
        names |= {socket.gethostname(), socket.getfqdn()}
        try:
            names |= {info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None)}
        except OSError:
            pass
    return sorted(f"[{n}]" if ":" in n and not n.startswith("[") else n for n in names if n not in ("", "::"))


def give_back_memory() -> None:
    """Return freed heap memory to the system (glibc's ``malloc_trim``): after a big answer is
    dropped, the freed pages would otherwise stay in the process (glibc keeps them in its arenas,
    one per thread that allocated them). Nothing where the C library has no such call."""
    global _trim
    if _trim is None:
        import ctypes
        import ctypes.util

        try:
            _trim = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _trim = False
    if _trim:
        _trim(0)


_trim = None
_trimmer: dict = {}


def give_back_memory_soon(delay_s: float = 0.5) -> None:
    """:func:`give_back_memory` on a thread of its own, once, ``delay_s`` after the first call of a
    burst: what asks for it (a big answer just computed, a connection just cut) is not held up by
    it (it can take milliseconds on a big heap), and a burst of big requests trims once."""
    import threading

    with _trimmer.setdefault("lock", threading.Lock()):
        if _trimmer.get("due"):
            return
        _trimmer["due"] = True

    def trim() -> None:
        _trimmer["due"] = False
        give_back_memory()

    timer = threading.Timer(delay_s, trim)
    timer.daemon = True
    timer.start()


def protocol(request_timeout_s: float = REQUEST_TIMEOUT_S, send_timeout_s: float = SEND_TIMEOUT_S):
    """uvicorn's HTTP/1.1 protocol (h11) with the two time-outs of the module notes."""
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    waiting = (h11.IDLE, h11.SEND_BODY)  # the client's side of a request not yet whole

    class TimedH11Protocol(H11Protocol):
        read_timer = write_timer = None

        def connection_made(self, transport) -> None:
            super().connection_made(transport)
            self._arm_read()

        def _arm_read(self) -> None:
            self._cancel("read_timer")
            self.read_timer = self.loop.call_later(request_timeout_s, self._read_timed_out)

        def _cancel(self, name: str) -> None:
            timer = getattr(self, name)
            if timer is not None:
                timer.cancel()
                setattr(self, name, None)

        def _read_timed_out(self) -> None:
            self.read_timer = None
            if self.transport.is_closing() or self.conn.their_state not in waiting:
                return
            if self.conn.their_state is h11.IDLE and self.conn.our_state is h11.IDLE:  # headers never came whole
                self.transport.write(b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain\r\n"
                                     b"content-length: 35\r\nconnection: close\r\n\r\n"
                                     b"the request did not arrive in time\n")
            self.transport.close()

        def handle_events(self) -> None:
            super().handle_events()
            if self.conn.their_state not in waiting:  # the request is here whole (or the connection ends)
                self._cancel("read_timer")

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing():
                self._arm_read()

        def handle_websocket_upgrade(self, event) -> None:
            self._cancel("read_timer")
            super().handle_websocket_upgrade(event)

        def pause_writing(self) -> None:  # the client is not reading: its answer waits in our buffer
            super().pause_writing()
            if self.write_timer is None:
                self.write_timer = self.loop.call_later(send_timeout_s, self._write_timed_out)

        def resume_writing(self) -> None:
            super().resume_writing()
            self._cancel("write_timer")

        def _write_timed_out(self) -> None:
            self.write_timer = None
            sock = self.transport.get_extra_info("socket")
            if sock is not None:  # a reset, not a close: the kernel drops what it still holds for the client too
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            self.transport.abort()  # the buffered answer is dropped with the connection
            give_back_memory_soon()

        def connection_lost(self, exc) -> None:
            self._cancel("read_timer")
            self._cancel("write_timer")
            super().connection_lost(exc)

    return TimedH11Protocol


def server_config(app, host: str, port: int, *, request_timeout_s: float = REQUEST_TIMEOUT_S,
                  send_timeout_s: float = SEND_TIMEOUT_S, **kwargs):
    """The uvicorn configuration of an eoloc server: the protocol above, its limits; ``kwargs`` go
    to ``uvicorn.Config`` (log level, websockets, lifespan)."""
    import uvicorn

    return uvicorn.Config(app, host=host, port=port, http=protocol(request_timeout_s, send_timeout_s),
                          timeout_keep_alive=KEEP_ALIVE_S, limit_concurrency=LIMIT_CONCURRENCY, **kwargs)
