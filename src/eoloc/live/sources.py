"""Where live KLV comes from: a UDP socket (unicast, or a multicast group joined), a raw KLV or
MPEG-TS file replayed (at its own clock with ``realtime``), or a byte stream such as stdin.
Each source yields (datagram bytes, arrival time) and ends when ``stop()`` says so; silence is
reported through ``on_silence(seconds)`` once per silent spell."""

from __future__ import annotations

import ipaddress
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from urllib.parse import urlparse

import numpy as np

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


class DatagramSink:
    """A receiver on ``udp://HOST:PORT`` (bound before the constructor returns) in a background
    thread: every datagram goes to ``on_datagram(data, arrival_s)`` (default: kept in
    ``datagrams``) until :meth:`stop`. What a CoT or KLV-out consumer is, for demos, tests and
    benchmarks; a context manager."""

    def __init__(self, url: str, on_datagram: Callable[[bytes, float], None] | None = None) -> None:
        self.sock = udp_socket(url)
        self.datagrams: list[bytes] = []
        self._on = on_datagram or (lambda data, _t: self.datagrams.append(data))
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        for data, arrival in udp_datagrams(self.sock, self._stopped.is_set):
            self._on(data, arrival)

    def stop(self) -> None:
        self._stopped.set()
        self._thread.join()
        self.sock.close()

    def __enter__(self) -> DatagramSink:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


TS_PACKET = 188
TS_DATAGRAM = 7 * TS_PACKET  # ST 1402: seven transport packets per datagram


def ts_packet_times(data: bytes) -> np.ndarray:
    """Each 188-byte transport packet's time on the stream's clock (s): from the program clock
    references (PCR) of the first PID that carries them, else from the PES presentation times
    (PTS) of the first PID that has them (a stream of data PIDs only may carry no PCR); linear
    in between, held before the first and after the last; NaN with neither."""
    n = len(data) // TS_PACKET
    a = np.frombuffer(data, dtype=np.uint8, count=n * TS_PACKET).reshape(n, TS_PACKET)
    pid = ((a[:, 1].astype(np.int32) & 0x1F) << 8) | a[:, 2]
    adapt = (a[:, 0] == 0x47) & ((a[:, 3] & 0x20) != 0)
    has = adapt & (a[:, 4] >= 7) & ((a[:, 5] & 0x10) != 0)
    if has.any():
        at, first = 6, None  # PCR base: 33 bits from byte 6
    else:  # PES headers: 00 00 01, stream id, length, flags, PTS flag, header length, PTS from byte 9
        start = 4 + np.where(adapt, a[:, 4].astype(np.int64) + 1, 0)
        start = np.minimum(start, TS_PACKET - 14)
        rows_all = np.arange(n)
        pes = lambda k: a[rows_all, start + k]  # noqa: E731
        has = ((a[:, 1] & 0x40) != 0) & (pes(0) == 0) & (pes(1) == 0) & (pes(2) == 1) & ((pes(7) & 0x80) != 0)
        if not has.any():
            return np.full(n, np.nan)
        at, first = None, start
    has &= pid == pid[np.argmax(has)]
    rows = np.flatnonzero(has)
    if at is not None:
        b = a[rows, at:at + 5].astype(np.int64)
        ticks = (b[:, 0] << 25) | (b[:, 1] << 17) | (b[:, 2] << 9) | (b[:, 3] << 1) | (b[:, 4] >> 7)
    else:
        b = np.stack([a[rows, first[rows] + 9 + k] for k in range(5)], -1).astype(np.int64)
        ticks = ((((b[:, 0] >> 1) & 0x7) << 30) | (b[:, 1] << 22) | ((b[:, 2] >> 1) << 15) | (b[:, 3] << 7)
                 | (b[:, 4] >> 1))
    t_s = np.unwrap(ticks / 90_000.0, period=2.0**33 / 90_000.0)
    return np.interp(np.arange(n), rows, t_s)


def paced(chunks: Iterator[tuple[bytes, float]], stop: Callable[[], bool], realtime: bool
          ) -> Iterator[tuple[bytes, float]]:
    """(bytes, stream time s) -> (bytes, arrival time), spaced by the stream times when ``realtime``."""
    t0_wall = t0_stream = None
    for chunk, t in chunks:
        if stop():
            return
        if realtime and np.isfinite(t):
            if t0_wall is None or t < t0_stream:
                t0_wall, t0_stream = time.monotonic(), t
            wait = (t - t0_stream) - (time.monotonic() - t0_wall)
            if wait > 0:
                time.sleep(min(wait, 5.0))
        yield chunk, time.perf_counter()


def ts_file_datagrams(data: bytes) -> Iterator[tuple[bytes, float]]:
    """A transport stream cut into ST 1402 datagrams (seven packets), each with its PCR time."""
    times = ts_packet_times(data)
    for k in range(0, len(data) - len(data) % TS_PACKET, TS_DATAGRAM):
        yield data[k:k + TS_DATAGRAM], float(times[k // TS_PACKET])


def file_datagrams(path: str, stop: Callable[[], bool], *, realtime: bool = False) -> Iterator[tuple[bytes, float]]:
    """A raw KLV or MPEG-TS file as a live source: KLV packet by packet, TS seven transport
    packets at a time (as ST 1402 sends it); at the stream's own clock when ``realtime`` (ST 0601
    time stamps for KLV, the PCR for TS)."""
    from ..io.klv.reader import looks_like_ts, split_klv

    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    chunks = ts_file_datagrams(data) if looks_like_ts(data) else iter(split_klv(data, path))
    yield from paced(chunks, stop, realtime)


def byte_stream_chunks(read: Callable[[int], bytes], stop: Callable[[], bool]) -> Iterator[tuple[bytes, float]]:
    """A byte stream (stdin, a pipe) cut where a datagram would end: whole transport packets
    (seven at a time) when it is MPEG-TS, whole KLV packets otherwise. Ends at end of file."""
    from ..io.klv.reader import PacketKeys, packet_end

    buf = b""
    ts = None
    while not stop():
        data = read(65536)
        if not data:
            break
        buf += data
        if ts is None:
            if len(buf) < 2 * TS_PACKET and buf[:1] == b"\x47":
                continue
            ts = buf[0] == 0x47 and buf[TS_PACKET] == 0x47
        if ts:
            cut = len(buf) - len(buf) % TS_PACKET
            for k in range(0, cut, TS_DATAGRAM):
                yield buf[k:min(k + TS_DATAGRAM, cut)], time.perf_counter()
            buf = buf[cut:]
            continue
        keys, pos = PacketKeys(buf), 0
        while (k := keys.find(pos)) >= 0:
            end, _, _ = packet_end(buf, k)
            if end is None:
                break
            yield buf[pos:end], time.perf_counter()  # bytes before the key go with it: counted, not lost
            pos = end
        buf = buf[pos:]
        if len(buf) > 1 << 20:  # a megabyte with no whole packet: hand it over to be reported
            yield buf, time.perf_counter()
            buf = b""
    if buf:
        yield buf, time.perf_counter()
