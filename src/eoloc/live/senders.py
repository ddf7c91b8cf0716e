"""Where live CoT events go: UDP (unicast, or a multicast group such as ATAK's situational-
awareness default ``udp://239.2.3.1:6969``), a TCP stream to a TAK server (``tcp://HOST:8087``,
the plain-text CoT port) or a TLS one (``tls://HOST:8089`` with a client certificate:
:mod:`eoloc.live.tls`). Each event is one XML document (TAK protocol 0) unless TAK protocol 1
was asked for (:mod:`eoloc.live.takwire`): protobuf mesh datagrams on UDP; on a stream, protobuf
once the server has offered and agreed to it, XML otherwise.

Nothing here ever makes the pipeline wait. A UDP event is sent at once (a refused send is
counted). A stream sender keeps its own thread and a bounded queue: while the server is down or
restarting the thread reconnects with back-off (0.5 s doubling to 8 s) and the queue keeps the
newest events, the oldest dropped and counted. A certificate problem is not retried: the sender
stops with ``fatal`` set to a one-line description with the fix (the live job ends on it).

On a stream the events go without their ``<?xml ...?>`` declaration, one ``<event>`` after
another: TAK servers split a stream at ``</event>`` and parse each event alone, and
FreeTAKServer's TLS reader (2.2) deletes everything from the first declaration of what it read
at once to the last one (a greedy pattern), which loses every event but the last of a burst
(measured: 24 of 220 arrived with declarations, all without).
"""

from __future__ import annotations

import ipaddress
import select
import socket
import ssl
import threading
import time
from collections import deque
from urllib.parse import parse_qs, urlparse

from ..errors import InputError
from . import takwire
from .tls import TlsCredentials, handshake_problem

QUEUE_EVENTS = 10_000
BACKOFF_S = (0.5, 8.0)
HANDSHAKE_S = 15.0  # a TLS handshake's limit: slow links and busy servers (a single-threaded one under load)
PROBE_S = 1.0  # after a TLS handshake: how long to listen for the server refusing our certificate
NEGOTIATE_S = 3.0  # TAK protocol 1: how long to wait for the server's offer, then for its answer


def parse_cot_url(url: str) -> tuple[str, str, int, dict[str, str]]:
    """(scheme, host, port, query) of a CoT destination; an InputError naming the URL otherwise."""
    u = urlparse(url)
    try:
        port = u.port
    except ValueError:
        port = None
    if u.scheme not in ("udp", "tcp", "tls") or not u.hostname or not port:
        raise InputError(f"--cot {url!r}: give udp://HOST:PORT (unicast or a multicast group, e.g. ATAK's "
                         "udp://239.2.3.1:6969; ?ttl=N sets the multicast TTL), tcp://HOST:PORT (a TAK "
                         "server's plain CoT port, e.g. tcp://takserver:8087) or tls://HOST:PORT (its TLS port, "
                         "e.g. tls://takserver:8089, with --tak-cert or --tak-package)")
    return u.scheme, u.hostname, u.port, {k: v[-1] for k, v in parse_qs(u.query).items()}


class UdpSender:
    """Each event one datagram to ``udp://HOST:PORT`` (multicast TTL from ``?ttl=N``, default 1)."""

    def __init__(self, url: str, option: str = "--cot", protocol: str = "xml") -> None:
        _, host, port, q = parse_cot_url(url)
        self.url, self.sent, self.errors = url, 0, 0
        self.encode = takwire.mesh if protocol == "1" else bytes
        self.fatal: str | None = None
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
            self.sock.sendto(self.encode(event), self.addr)
            self.sent += 1
        except OSError:
            self.errors += 1

    def close(self, timeout_s: float = 0.0) -> None:
        self.sock.close()

    def summary(self) -> dict:
        return {"url": self.url, "sent": self.sent, "errors": self.errors}


class TcpSender:
    """Events streamed to ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` from a thread of its own (see
    the module notes). ``tls``: the client's credentials (required for tls://); ``protocol``:
    "xml" or "1" (TAK protocol 1 where the server agrees); ``uid``: eoloc's uid in the
    negotiation."""

    def __init__(self, url: str, *, queue_events: int = QUEUE_EVENTS, on_state=None, hello=None,
                 tls: TlsCredentials | None = None, protocol: str = "xml", uid: str = "eoloc") -> None:
        scheme, self.host, self.port, q = parse_cot_url(url)
        if scheme == "tls" and tls is None:
            raise InputError(f"--cot {url}: a TLS connection needs eoloc's client certificate: --tak-cert CLIENT.p12 "
                             "(with --tak-cert-password and --tak-ca CA.pem as needed) or --tak-package "
                             "CONNECTION.zip")
        self.url, self.tls, self.protocol, self.uid = url, tls if scheme == "tls" else None, protocol, uid
        self.context = None if self.tls is None else self.tls.context(check_hostname=q.get("check_hostname") == "1")
        self.queue: deque[bytes] = deque(maxlen=queue_events)
        self.cond = threading.Condition()
        self.stopping = threading.Event()
        self.sent = self.dropped = self.lost = self.connects = 0
        self.fatal: str | None = None
        self.connecting = False  # a connection attempt under way (bounded by its timeouts)
        self.attempts = 0
        self.wire = "xml"  # what the current connection carries: "xml" or "1"
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

    def _refused(self, exc: BaseException, sock: socket.socket) -> None:
        """A failed connection: fatal when it is a certificate problem, else retried."""
        sock.close()
        problem = handshake_problem(exc, self.url, self.tls)
        if problem is not None:
            self.fatal = problem  # not retried; the job reports it and ends
        else:
            self.on_state(f"{self.url}: {'TLS ' if self.tls is not None else ''}connection failed ({exc}); retrying")

    def _alert(self, sock: socket.socket) -> bool:
        """After a failed write on TLS: whether the server had refused our certificate (its alert
        read now; ``fatal`` set, the socket closed)."""
        try:
            sock.settimeout(0.5)
            sock.recv(1)
        except (ssl.SSLError, OSError) as exc:
            if handshake_problem(exc, self.url, self.tls) is not None:
                self._refused(exc, sock)
                return True
        return False

    def _listen(self, sock: socket.socket, seconds: float, negotiation: takwire.Negotiation | None) -> bool:
        """Read what the server sends for up to ``seconds`` (less once the negotiation is settled):
        False if the connection failed (the reason reported)."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            if negotiation is not None and negotiation.state == "proto":
                return True
            if not select.select([sock], [], [], min(left, 0.2))[0]:
                continue
            try:
                data = read_now(sock)
            except (ssl.SSLError, OSError) as exc:
                self._refused(exc, sock)
                return False
            if data is None:  # TLS records that carry no data (TLS 1.3 session tickets), or a partial one
                continue
            if not data:
                sock.close()
                self.on_state(f"{self.url}: the server closed the connection at once; retrying")
                return False
            if negotiation is not None and (reply := negotiation.feed(data)):
                sock.sendall(reply)
                deadline = max(deadline, time.monotonic() + NEGOTIATE_S)  # the offer came: wait for the answer
        return True

    def _connect(self) -> socket.socket | None:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=2.0)
        except OSError as exc:
            self.on_state(f"{self.url}: cannot connect ({exc.strerror or exc}); retrying")
            return None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(5.0)
        if self.context is not None:
            try:
                sock.settimeout(HANDSHAKE_S)
                sock = self.context.wrap_socket(sock, server_hostname=self.host)
                sock.settimeout(5.0)
            except (ssl.SSLError, OSError) as exc:
                self._refused(exc, sock)
                return None
        negotiation = takwire.Negotiation(self.uid) if self.protocol == "1" else None
        try:
            # TLS: the server's verdict on our certificate first (TLS 1.3 gives it after the handshake)
            if self.context is not None and not self._listen(sock, PROBE_S, negotiation):
                return None
            if self.hello is not None:
                hello = self.hello()
                agreed = negotiation is not None and negotiation.state == "proto"
                sock.sendall(takwire.stream(hello) if agreed else undeclared(hello))
            if negotiation is not None and not self._listen(sock, NEGOTIATE_S, negotiation):
                return None
        except OSError as exc:
            if self.context is not None and self._alert(sock):
                return None
            self.on_state(f"{self.url}: connection lost at once ({exc.strerror or exc}); retrying")
            sock.close()
            return None
        self.wire = "1" if negotiation is not None and negotiation.state == "proto" else "xml"
        if negotiation is not None and (negotiation.note or self.connects == 0):
            self.on_state(f"{self.url}: {negotiation.note or 'the server offers no TAK protocol 1: XML kept'}")
        self.connects += 1
        if self.connects > 1:
            self.on_state(f"{self.url}: reconnected")
        return sock

    @staticmethod
    def _closed_by_peer(sock: socket.socket) -> bool:
        """Whether the server has closed the connection (what it sends us is read and ignored)."""
        while select.select([sock], [], [], 0)[0] or (isinstance(sock, ssl.SSLSocket) and sock.pending()):
            try:
                data = read_now(sock)
            except OSError:
                return True
            if data is None:  # nothing but TLS records without data, or a partial one: still open
                return False
            if not data:
                return True
        return False

    def _run(self) -> None:
        sock, backoff = None, BACKOFF_S[0]
        while not self.stopping.is_set() or self.queue:
            if sock is None:
                self.connecting, self.attempts = True, self.attempts + 1
                try:
                    sock = self._connect()
                finally:
                    self.connecting = False
                if sock is None:
                    if self.fatal is not None or self.stopping.wait(backoff):
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
                    sock.sendall(b"".join(map(takwire.stream, batch)) if self.wire == "1"
                                 else b"".join(map(undeclared, batch)))
                    self.sent += len(batch)
            except OSError as exc:
                self.lost += len(batch)
                self.on_state(f"{self.url}: connection lost ({exc.strerror or exc}); reconnecting")
                sock.close()
                sock = None
        if sock is not None:
            sock.close()

    def close(self, timeout_s: float = 2.0) -> None:
        """Send what is queued (for up to ``timeout_s``, and through a connection attempt under way,
        and a second one if the first failed: a TLS handshake with a busy server can stall once),
        then stop."""
        deadline = time.monotonic() + timeout_s
        while self.queue and self.fatal is None and self.thread.is_alive() and (
                time.monotonic() < deadline or self.connecting or (self.connects == 0 and self.attempts < 2)):
            time.sleep(0.02)
        self.stopping.set()
        with self.cond:
            self.cond.notify()
        self.thread.join(timeout=max(deadline - time.monotonic(), 1.0))

    def summary(self) -> dict:
        out = {"url": self.url, "sent": self.sent, "queued": len(self.queue), "dropped": self.dropped,
               "lost": self.lost, "connects": self.connects}
        if self.protocol == "1":
            out["tak_protocol"] = self.wire
        return out


def read_now(sock: socket.socket) -> bytes | None:
    """What the socket holds now, without waiting: None when a readable TLS socket has no data for
    us (a TLS 1.3 session ticket, a record not complete yet), b"" when the peer has closed."""
    timeout = sock.gettimeout()
    sock.settimeout(0.0)
    try:
        return sock.recv(65536)
    except (ssl.SSLWantReadError, BlockingIOError):
        return None
    finally:
        sock.settimeout(timeout)


def undeclared(event: bytes) -> bytes:
    """An XML event without its ``<?xml ...?>`` declaration (see the module notes)."""
    if event.startswith(b"<?xml"):
        end = event.find(b"?>")
        return event[end + 2:].lstrip() if end >= 0 else event
    return event


def cot_sender(url: str, on_state=None, hello=None, tls: TlsCredentials | None = None, protocol: str = "xml",
               uid: str = "eoloc") -> UdpSender | TcpSender:
    """The sender for a --cot URL; ``hello`` (TCP/TLS): the event sent first on each connection;
    ``tls``: the client's credentials for tls:// URLs; ``protocol``: TAK protocol "xml" or "1"."""
    scheme = parse_cot_url(url)[0]
    if scheme == "udp":
        return UdpSender(url, protocol=protocol)
    return TcpSender(url, on_state=on_state, hello=hello, tls=tls, protocol=protocol, uid=uid)


def send_events(urls, events, *, tls: TlsCredentials | None = None, protocol: str = "xml", hello=None,
                uid: str = "eoloc", on_state=None, timeout_s: float = 10.0) -> tuple[list[dict], str | None]:
    """Send ``events`` (XML CoT) once to every URL, waiting up to ``timeout_s`` for the streams to
    deliver: (each sender's summary, the first certificate problem or None)."""
    senders = [cot_sender(u, on_state=on_state, hello=hello, tls=tls, protocol=protocol, uid=uid) for u in urls]
    for event in events:
        for s in senders:
            s.send(event)
    for s in senders:
        s.close(timeout_s)
    return [s.summary() for s in senders], next((s.fatal for s in senders if s.fatal), None)
