"""Where live KLV comes from: a UDP socket (unicast, or a multicast group joined), or a file
replayed packet by packet (at its own clock with ``realtime``). Each source yields
(datagram bytes, arrival time) and ends when ``stop()`` says so; silence is reported through
``on_silence(seconds)`` once per silent spell."""

from __future__ import annotations

import ipaddress
import itertools
import socket
import struct
import time
from collections.abc import Callable, Iterator
from urllib.parse import urlparse

from ..errors import InputError

MAX_DATAGRAM = 65_535


def parse_udp(url: str) -> tuple[str, int]:
    """(host, port) of ``udp://HOST:PORT``; an InputError naming the URL otherwise."""
    u = urlparse(url)
    if u.scheme != "udp" or not u.hostname or not u.port:
        raise InputError(f"{url!r}: give a UDP source as udp://HOST:PORT (e.g. udp://0.0.0.0:15000, or a "
                         "multicast group udp://239.1.1.1:15000)")
    return u.hostname, u.port


def udp_socket(url: str) -> socket.socket:
    """A bound UDP socket for ``udp://HOST:PORT`` (a multicast HOST is joined on every interface)."""
    host, port = parse_udp(url)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 1024 * 1024)
    multicast = ipaddress.ip_address(socket.gethostbyname(host)).is_multicast
    sock.bind(("" if multicast else host, port))
    if multicast:
        mreq = struct.pack("4s4s", socket.inet_aton(socket.gethostbyname(host)), socket.inet_aton("0.0.0.0"))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
    return sock


def udp_datagrams(sock: socket.socket, stop: Callable[[], bool], *, silence_s: float = 3.0,
                  on_silence: Callable[[float], None] | None = None) -> Iterator[tuple[bytes, float]]:
    sock.settimeout(0.2)
    last = time.monotonic()
    silent = False
    while not stop():
        try:
            data = sock.recv(MAX_DATAGRAM)
        except TimeoutError:
            quiet = time.monotonic() - last
            if quiet > silence_s and not silent:
                silent = True
                if on_silence is not None:
                    on_silence(quiet)
            continue
        last, silent = time.monotonic(), False
        yield data, time.perf_counter()


def file_packets(path: str, stop: Callable[[], bool], *, realtime: bool = False) -> Iterator[tuple[bytes, float]]:
    """The packets of a KLV file one by one (bad ones too: the session counts them), spaced by
    their time stamps when ``realtime``."""
    from ..io.klv import read_klv

    with open(path, "rb") as fh:
        data = fh.read()
    stream = read_klv(path)
    if stream.container != "klv":
        raise InputError(f"{path}: eoloc live replays raw KLV files; for MPEG-TS use eoloc klv (or a raw KLV stream)")
    starts = sorted({p.offset for p in stream.packets} | {i.offset for i in stream.issues if i.offset is not None})
    bounds = [*starts, len(data)]
    t0_wall = t0_stream = None
    times = {p.offset: p.fields.get(2) for p in stream.packets}
    for a, b in itertools.pairwise(bounds):
        if stop():
            return
        t = times.get(a)
        if realtime and t is not None and hasattr(t, "timestamp"):
            if t0_wall is None:
                t0_wall, t0_stream = time.monotonic(), t.timestamp()
            wait = (t.timestamp() - t0_stream) - (time.monotonic() - t0_wall)
            if wait > 0:
                time.sleep(min(wait, 5.0))
        yield data[a:b], time.perf_counter()
