"""Where live KLV comes from: a UDP socket (unicast, or a multicast group joined), a raw KLV or
MPEG-TS file replayed (at its own clock with ``realtime``), a byte stream such as stdin, and the
network sources FFmpeg opens (through PyAV): RTSP/RTMP (its demultiplexer's KLV data streams),
TCP/HTTP (a byte stream of MPEG-TS or raw KLV) and SRT (PyAV's FFmpeg has no libsrt: Haivision's
``srt-live-transmit`` bridges it to a loopback UDP port when it is installed).
Each source yields (datagram bytes, arrival time) or (KLV bytes, arrival time, stream name) and
ends when ``stop()`` says so; silence is reported through ``on_silence(seconds)`` once per silent
spell. :func:`open_source` picks the source for a SOURCE argument."""

from __future__ import annotations

import ipaddress
import queue
import shutil
import socket
import struct
import subprocess
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


def watch_silence(receive: Callable[[], object], stop: Callable[[], bool], *, silence_s: float = 3.0,
                  on_silence: Callable[[float], None] | None = None) -> Iterator:
    """What ``receive()`` returns, until ``stop()`` or it returns END. ``receive`` waits a short
    while (0.2 s) and returns None when nothing came: after ``silence_s`` of that,
    ``on_silence(seconds)`` is called once per silent spell."""
    last = time.monotonic()
    silent = False
    while not stop():
        item = receive()
        if item is END:
            return
        if item is None:
            quiet = time.monotonic() - last
            if quiet > silence_s and not silent:
                silent = True
                if on_silence is not None:
                    on_silence(quiet)
            continue
        last, silent = time.monotonic(), False
        yield item


END = object()  # a source's end, as ``receive`` returns it to watch_silence


def udp_datagrams(sock: socket.socket, stop: Callable[[], bool], *, silence_s: float = 3.0,
                  on_silence: Callable[[float], None] | None = None,
                  ended: Callable[[], bool] = lambda: False) -> Iterator[tuple[bytes, float]]:
    """The datagrams of ``sock`` with their arrival times, until ``stop()``, or ``ended()`` in a
    quiet moment (whoever feeds the socket is gone)."""
    sock.settimeout(0.2)

    def receive():
        try:
            return sock.recv(MAX_DATAGRAM), time.perf_counter()
        except TimeoutError:
            return END if ended() else None

    return watch_silence(receive, stop, silence_s=silence_s, on_silence=on_silence)


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


FFMPEG_DEMUX = ("rtsp", "rtsps", "rtmp", "rtmps")  # FFmpeg opens these as containers: their KLV data streams
FFMPEG_BYTES = ("tcp", "http", "https")  # byte streams of MPEG-TS or raw KLV, read through FFmpeg's protocols
RECONNECTING = ("rtsp", "rtsps", "rtmp", "rtmps", "tcp")  # live sessions: opened again when they end or break
OPEN_TIMEOUT_S = 10.0
RECONNECT_S = (0.5, 8.0)  # the wait before the first attempt to reconnect, doubled per failure up to the second


def scheme_of(source: str) -> str:
    return urlparse(source).scheme.lower() if "://" in source else ""


def in_thread(produce: Callable[[Callable[[], bool]], Iterator], stop: Callable[[], bool], *, silence_s: float,
              on_silence: Callable[[float], None] | None, name: str) -> Iterator:
    """The items of ``produce(halted)``, which blocks on the network, read in a background thread
    and handed over through a queue, so that silence is noticed and ``stop()`` obeyed while a read
    waits. An error in the reader ends the source with an InputError naming ``name``."""
    items: queue.Queue = queue.Queue(maxsize=100_000)
    halted = threading.Event()
    failure: list[BaseException] = []

    def run() -> None:
        try:
            for item in produce(halted.is_set):
                items.put(item)
        except Exception as exc:  # the network source's verdict (a dropped connection, a refused read)
            failure.append(exc)
        finally:
            items.put(END)

    threading.Thread(target=run, daemon=True, name=f"eoloc source {name}").start()

    def receive():
        try:
            return items.get(timeout=0.2)
        except queue.Empty:
            return None

    try:
        yield from watch_silence(receive, stop, silence_s=silence_s, on_silence=on_silence)
    finally:
        halted.set()
    if failure:
        raise InputError(f"{name}: the stream broke off: {failure[0]}") from None


def open_ffmpeg(url: str, *, as_bytes: bool):
    """The PyAV container of a network URL (an InputError naming the URL and FFmpeg's reason when
    it cannot be opened)."""
    import av

    options = {"rtsp_transport": "tcp"} if scheme_of(url).startswith("rtsp") else {}
    try:
        return av.open(url, format="data" if as_bytes else None, options=options,
                       timeout=(OPEN_TIMEOUT_S, None))
    except av.error.FFmpegError as exc:
        raise InputError(f"{url}: FFmpeg cannot open it: {exc.strerror or exc} (is the sender running, and the "
                         "address right?)") from None


def ffmpeg_klv_packets(container, halted: Callable[[], bool]) -> Iterator[tuple[bytes, float, str]]:
    """Each KLV data packet an FFmpeg demultiplexer gives (RTSP/RTMP, MPEG-TS over RTP inside),
    with its arrival time and its stream's name ("PID n" as the transport stream's reader names it)."""
    data = list(container.streams.data)
    names = {s.index: f"PID {s.id}" if s.id else f"stream {s.index}" for s in data}
    for packet in container.demux(*data):
        if halted():
            return
        if packet.size:
            yield bytes(packet), time.perf_counter(), names[packet.stream.index]


def ffmpeg_byte_chunks(container, halted: Callable[[], bool]) -> Iterator[tuple[bytes, float]]:
    """An FFmpeg byte stream (TCP, HTTP) cut as :func:`byte_stream_chunks` cuts stdin."""
    packets = container.demux()

    def read(_n: int) -> bytes:
        for packet in packets:
            if packet.size:
                return bytes(packet)
        return b""

    return byte_stream_chunks(read, halted)


def srt_bridge(url: str, sock: socket.socket) -> subprocess.Popen:
    """``srt-live-transmit URL udp://127.0.0.1:PORT`` (Haivision's SRT tools) feeding ``sock``."""
    tool = shutil.which("srt-live-transmit")
    if tool is None:
        raise InputError(f"{url}: PyAV's FFmpeg has no SRT, and srt-live-transmit (SRT's own bridge) is not installed: "
                         "install it (Debian/Ubuntu: apt install srt-tools) and eoloc runs it, or relay the stream "
                         f"yourself: srt-live-transmit {url} udp://127.0.0.1:15000, then eoloc live "
                         "udp://127.0.0.1:15000")
    port = sock.getsockname()[1]
    return subprocess.Popen([tool, "-q", url, f"udp://127.0.0.1:{port}"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def srt_datagrams(url: str, stop: Callable[[], bool], *, silence_s: float,
                  on_silence: Callable[[float], None] | None) -> Iterator[tuple[bytes, float]]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 1024 * 1024)
    sock.bind(("127.0.0.1", 0))
    bridge = srt_bridge(url, sock)
    try:
        yield from udp_datagrams(sock, stop, silence_s=silence_s, on_silence=on_silence,
                                 ended=lambda: bridge.poll() is not None)
        if bridge.poll() not in (None, 0):
            why = (bridge.stderr.read() or b"").decode("utf-8", "replace").strip().splitlines()
            raise InputError(f"{url}: srt-live-transmit stopped (exit {bridge.returncode})"
                             + (f": {why[-1]}" if why else ""))
    finally:
        if bridge.poll() is None:
            bridge.terminate()
            try:
                bridge.wait(timeout=5)
            except subprocess.TimeoutExpired:
                bridge.kill()
        sock.close()


class SourceState:
    """What a source did besides its chunks, for the summary: ``reconnects`` (network sessions
    opened again after they ended or broke off)."""

    def __init__(self) -> None:
        self.reconnects = 0

    def summary(self) -> dict:
        return {"reconnects": self.reconnects}


def session_reader(url: str, first, produce: Callable, *, as_bytes: bool, again: bool, state: SourceState,
                   on_event: Callable[[str], None]) -> Callable[[Callable[[], bool]], Iterator]:
    """``produce(container, halted)`` over the FFmpeg session of ``url`` (``first``: the container
    already open). With ``again`` the session is opened again whenever it ends or breaks off (an
    encoder or server restarting), with back-off between the attempts (RECONNECT_S), until
    ``halted()``; without, its end is the source's end and its error the source's error."""
    import av

    def read(halted: Callable[[], bool]) -> Iterator:
        container = first
        while True:
            try:
                yield from produce(container, halted)
                why = "the stream ended"
            except (av.error.FFmpegError, OSError) as exc:
                if not again:
                    raise
                why = f"the stream broke off ({exc})"
            finally:
                container.close()
            if not again:
                return
            delay = RECONNECT_S[0]
            while not halted():
                on_event(f"{url}: {why}; reconnecting in {delay:g} s")
                until = time.monotonic() + delay
                while time.monotonic() < until and not halted():
                    time.sleep(0.05)
                if halted():
                    break
                try:
                    container = open_ffmpeg(url, as_bytes=as_bytes)
                    break
                except InputError as exc:
                    why = str(exc).removeprefix(f"{url}: ")
                    delay = min(2.0 * delay, RECONNECT_S[1])
            if halted():
                return
            state.reconnects += 1
            on_event(f"{url}: reconnected")

    return read


def open_source(source: str, stop: Callable[[], bool], *, realtime: bool = False, silence_s: float = 3.0,
                on_silence: Callable[[float], None] | None = None, on_event: Callable[[str], None] | None = None,
                stdin=None) -> tuple[Iterator, str, SourceState]:
    """The chunks of SOURCE (see the module), a line saying where they come from, and its state.
    RTSP, RTMP and TCP sessions are opened again when they end or break off (``on_event`` hears
    of it); the first opening must succeed (a wrong address is an InputError at once)."""
    scheme = scheme_of(source)
    watch = {"silence_s": silence_s, "on_silence": on_silence}
    state = SourceState()
    if scheme == "udp":
        return udp_datagrams(udp_socket(source), stop, **watch), f"listening on {source}", state
    if source == "-":
        return byte_stream_chunks(stdin.read1, stop), "reading stdin", state
    if scheme == "srt":
        return srt_datagrams(source, stop, **watch), f"receiving {source} (through srt-live-transmit)", state
    if scheme in FFMPEG_DEMUX or scheme in FFMPEG_BYTES:
        as_bytes = scheme in FFMPEG_BYTES
        container = open_ffmpeg(source, as_bytes=as_bytes)
        produce = ffmpeg_byte_chunks if as_bytes else ffmpeg_klv_packets
        if not as_bytes and not container.streams.data:
            container.close()
            raise InputError(f"{source}: FFmpeg finds no data stream in it (KLV carried as MPEG-TS over RTP is "
                             "read; KLV in its own RTP payload, RFC 6597, FFmpeg does not read: ask the encoder for "
                             "MPEG-TS, or relay it to UDP with a tool that does)")
        read = session_reader(source, container, produce, as_bytes=as_bytes, again=scheme in RECONNECTING, state=state,
                              on_event=on_event or (lambda message: None))
        return in_thread(read, stop, name=source, **watch), f"receiving {source} (FFmpeg)", state
    if scheme:
        raise InputError(f"{source!r}: eoloc live reads udp://, rtsp://, rtmp://, srt://, tcp://, http(s):// URLs, "
                         "raw KLV or MPEG-TS files, and - (stdin)")
    return file_datagrams(source, stop, realtime=realtime), f"reading {source}", state
