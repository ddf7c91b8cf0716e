"""Where live CoT events go: UDP (unicast, or a multicast group such as ATAK's situational-
awareness default ``udp://239.2.3.1:6969``), or a TCP stream to a TAK server
(``tcp://HOST:8087``, the plain-text CoT port), one XML document per event.

Nothing here ever makes the pipeline wait. A UDP event is sent at once (a refused send is
counted). A TCP sender keeps its own thread and a bounded queue: while the server is down or
restarting the thread reconnects with back-off (0.5 s doubling to 8 s) and the queue keeps the
newest events, the oldest dropped and counted.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import threading
import time
from collections import deque
from urllib.parse import parse_qs, urlparse

from ..errors import InputError

QUEUE_EVENTS = 10_000
BACKOFF_S = (0.5, 8.0)


def parse_cot_url(url: str) -> tuple[str, str, int, dict[str, str]]:
    """(scheme, host, port, query) of a CoT destination; an InputError naming the URL otherwise."""
    u = urlparse(url)
    if u.scheme not in ("udp", "tcp") or not u.hostname or not u.port:
        raise InputError(f"--cot {url!r}: give udp://HOST:PORT (unicast or a multicast group, e.g. ATAK's "
                         "udp://239.2.3.1:6969; ?ttl=N sets the multicast TTL) or tcp://HOST:PORT (a TAK "
                         "server's CoT port, e.g. tcp://takserver:8087)")
    return u.scheme, u.hostname, u.port, {k: v[-1] for k, v in parse_qs(u.query).items()}


class UdpSender:
    """Each event one datagram to ``udp://HOST:PORT`` (multicast TTL from ``?ttl=N``, default 1)."""

    def __init__(self, url: str, option: str = "--cot") -> None:
        _, host, port, q = parse_cot_url(url)
        self.url, self.sent, self.errors = url, 0, 0
        self.addr = (socket.gethostbyname(host), port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        if ipaddress.ip_address(self.addr[0]).is_multicast:
            try:
                ttl = int(q.get("ttl", "1"))
            except ValueError:
                raise InputError(f"{option} {url!r}: ttl must be a whole number of hops") from None
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, ttl)
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)

    def send(self, event: bytes) -> None:
        try:
            self.sock.sendto(event, self.addr)
            self.sent += 1
        except OSError:
            self.errors += 1

    def close(self, timeout_s: float = 0.0) -> None:
        self.sock.close()

    def summary(self) -> dict:
        return {"url": self.url, "sent": self.sent, "errors": self.errors}


class TcpSender:
    """Events streamed to ``tcp://HOST:PORT`` from a thread of its own (see the module notes)."""

    def __init__(self, url: str, *, queue_events: int = QUEUE_EVENTS, on_state=None, hello=None) -> None:
        _, self.host, self.port, _ = parse_cot_url(url)
        self.url = url
        self.queue: deque[bytes] = deque(maxlen=queue_events)
        self.cond = threading.Condition()
        self.stopping = threading.Event()
        self.sent = self.dropped = self.lost = self.connects = 0
        self.on_state = on_state or (lambda message: None)
        self.hello = hello  # () -> bytes: sent first on every connection (a TAK client's presence)
        self.thread = threading.Thread(target=self._run, name=f"cot {url}", daemon=True)
        self.thread.start()

    def send(self, event: bytes) -> None:
        with self.cond:
            if len(self.queue) == self.queue.maxlen:
                self.dropped += 1
            self.queue.append(event)
            self.cond.notify()

    def _connect(self) -> socket.socket | None:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=2.0)
        except OSError as exc:
            self.on_state(f"{self.url}: cannot connect ({exc.strerror or exc}); retrying")
            return None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(5.0)
        if self.hello is not None:
            try:
                sock.sendall(self.hello())
            except OSError as exc:
                self.on_state(f"{self.url}: connection lost at once ({exc.strerror or exc}); retrying")
                sock.close()
                return None
        self.connects += 1
        if self.connects > 1:
            self.on_state(f"{self.url}: reconnected")
        return sock

    @staticmethod
    def _closed_by_peer(sock: socket.socket) -> bool:
        """Whether the server has closed the connection (what it sends us is read and ignored)."""
        while select.select([sock], [], [], 0)[0]:
            try:
                if not sock.recv(65536):
                    return True
            except OSError:
                return True
        return False

    def _run(self) -> None:
        sock, backoff = None, BACKOFF_S[0]
        while not self.stopping.is_set() or self.queue:
            if sock is None:
                sock = self._connect()
                if sock is None:
                    if self.stopping.wait(backoff):
                        return
                    backoff = min(backoff * 2, BACKOFF_S[1])
                    continue
                backoff = BACKOFF_S[0]
            with self.cond:
                while not self.queue and not self.stopping.is_set():
                    self.cond.wait(0.5)
                    if self._closed_by_peer(sock):
                        break
                batch = list(self.queue)
                self.queue.clear()
            try:
                if self._closed_by_peer(sock):
                    raise ConnectionResetError("closed by the server")
                if batch:
                    sock.sendall(b"".join(batch))
                    self.sent += len(batch)
            except OSError as exc:
                self.lost += len(batch)
                self.on_state(f"{self.url}: connection lost ({exc.strerror or exc}); reconnecting")
                sock.close()
                sock = None
        if sock is not None:
            sock.close()

    def close(self, timeout_s: float = 2.0) -> None:
        """Send what is queued (for up to ``timeout_s``), then stop."""
        deadline = time.monotonic() + timeout_s
        while self.queue and time.monotonic() < deadline and self.connects:
            time.sleep(0.02)
        self.stopping.set()
        with self.cond:
            self.cond.notify()
        self.thread.join(timeout=max(deadline - time.monotonic(), 0.1))

    def summary(self) -> dict:
        return {"url": self.url, "sent": self.sent, "queued": len(self.queue), "dropped": self.dropped,
                "lost": self.lost, "connects": self.connects}


def cot_sender(url: str, on_state=None, hello=None) -> UdpSender | TcpSender:
    """The sender for a --cot URL; ``hello`` (TCP): the event sent first on each connection."""
    scheme = parse_cot_url(url)[0]
    return UdpSender(url) if scheme == "udp" else TcpSender(url, on_state=on_state, hello=hello)
