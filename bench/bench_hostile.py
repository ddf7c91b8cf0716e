"""Hostile input and load, big (issue 46): the suites of tests/integration/test_hostile_input.py at
the sizes of the README's reliability section, and the floods that need a real process and time.

    python bench/bench_hostile.py live  [--seconds 60] [--rate 5000]   eoloc live under a mixed UDP flood
    python bench/bench_hostile.py serve [--seconds 30] [--clients 200] load, a bomb, slow and unread clients
    python bench/bench_hostile.py klv   [--n 100000]  mutated KLV through the decoder and a live session
    python bench/bench_hostile.py csv   [--n 4000]    fuzzed CSV files, every good line kept
    python bench/bench_hostile.py http  [--n 2000]    hostile HTTP bodies

Each prints a markdown table (the docs/reliability.md's "Reliability" and bench/RESULTS.md take it).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1] / "tests" / "helpers"))
sys.path.insert(0, str(Path(__file__).parents[1] / "tests" / "integration"))

from _common import HEADER, machine, row

EOLOC = str(Path(sys.executable).parent / "eoloc")


def _rss_mb(pid: int) -> float:
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS:")).split()[1]) / 1024


def _free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# -- live --------------------------------------------------------------------------------------------


def live(seconds: float, rate: float) -> list[str]:
    """A 30 Hz MPEG-TS stream (7 transport packets a datagram, as ST 1402 sends) with ``rate`` hostile
    datagrams a second mixed in (random bytes, bad checksums, all-ones time stamps with valid
    checksums, random transport packets), for ``seconds``, to `eoloc live` on loopback."""
    from test_hostile_input import _flood

    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.io.klv.reader import decode_klv_bytes, split_klv
    from eoloc.io.klv.synthetic import circling_flight_klv

    warm_s = 5.0  # the first seconds: the stream with a light flood (500/s), as a session already running
    n_good = int((seconds + warm_s) * 30) + 90
    good = [raw for raw, _ in split_klv(circling_flight_klv(n_good, seed=5, rate_hz=30.0, n_targets=5))]
    with tempfile.TemporaryDirectory() as tmp:
        ts = Path(tmp) / "good.ts"
        write_klv_ts(ts, [[(raw, k / 30.0) for k, raw in enumerate(good)]])
        cells = ts.read_bytes()
    datagrams = [cells[k:k + 7 * 188] for k in range(0, len(cells), 7 * 188)]
    rng = np.random.default_rng(7)
    pool = [d for _, d in _flood(rng, [p for p in good[:200] if decode_klv_bytes(p).packets], 20_000)]
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "fixes.ndjson"
        proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--ndjson", str(out)],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        head = []
        while "listening on" not in (line := proc.stdout.readline()):
            assert proc.poll() is None, "".join(head)
            head.append(line)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 22)
        per_good = len(datagrams) / (n_good / 30.0)  # good datagrams a second
        t0 = time.perf_counter()
        sent_bad = sent_good = 0
        rss, warm_rss = [], None
        next_sample = t0 + 1.0
        while sent_good < len(datagrams):
            now = time.perf_counter() - t0
            while sent_good < len(datagrams) and sent_good <= now * per_good:
                tx.sendto(datagrams[sent_good], ("127.0.0.1", port))
                sent_good += 1
            while sent_bad < (now * 500.0 if now < warm_s else warm_s * 500.0 + (now - warm_s) * rate):
                tx.sendto(pool[sent_bad % len(pool)], ("127.0.0.1", port))
                sent_bad += 1
            if time.perf_counter() >= next_sample:
                rss.append(_rss_mb(proc.pid))
                if warm_rss is None and now > warm_s + 10.0:
                    warm_rss = rss[-1]
                next_sample += 1.0
            time.sleep(0.0005)
        wall = time.perf_counter() - t0
        time.sleep(3.0)
        proc.send_signal(signal.SIGINT)
        log, _ = proc.communicate(timeout=120)
        log = "".join(head) + log
        summary = json.loads(log[log.index("{", log.index("eoloc live stopped")):].splitlines()[0])
        fault_lines = sum("fault:" in x for x in log.splitlines())
        feats = [json.loads(x)["properties"] for x in out.read_text().splitlines() if '"aircraft"' in x]
        ts_times = {p["time_utc"] for p in feats if p["stream"].startswith("PID")}  # the TS stream's packets
        t_first = min(ts_times)
        from datetime import datetime

        def since(t: str) -> float:
            return (datetime.fromisoformat(t) - datetime.fromisoformat(t_first)).total_seconds()

        measured = [since(t) for t in ts_times if since(t) >= warm_s]
        written = len(measured)
        expected = len(good) - int(warm_s * 30)
        if os.environ.get("EOLOC_DEBUG"):
            got = sorted(p["time_utc"] for p in feats if p["stream"].startswith("PID"))
            secs = sorted(int(t[17:19]) for t in got)
            print("located per second", np.bincount(secs).tolist(), file=sys.stderr)
    counts = summary["faults"]
    return [
        row(f"`eoloc live`, {wall - warm_s:.0f} s after {warm_s:.0f} s of warm-up: a 30 Hz MPEG-TS stream + "
            f"{rate:.0f} hostile datagrams/s ({sent_bad:,} in all: random bytes, bad checksums, all-ones time "
            "stamps, random TS)",
            f"good packets located {written} of {expected}; datagrams received {summary['datagrams']:,} of "
            f"{sent_bad + sent_good:,}; Traceback: {'Traceback' in log}", "", None),
        row("memory of the eoloc process", f"RSS {warm_rss:.0f} MB after 10 s, {max(rss):.0f} MB at most, "
            f"{rss[-1]:.0f} MB at the end: growth {rss[-1] - warm_rss:+.1f} MB (goal < 20)", "", None),
        row("faults in the summary", ", ".join(f"{k} {v:,}" for k, v in counts.items()) +
            f"; corrupt {summary['corrupt']:,}, not KLV {summary['not_klv']:,}, duplicates {summary['duplicates']:,}",
            "", None),
        row("stderr", f"{fault_lines} fault lines for {sum(counts.values()):,} faults (first of each kind, then one "
            "a kind every 5 s)", "", None),
    ]


# -- serve -------------------------------------------------------------------------------------------


def serve(seconds: float, clients: int) -> list[str]:
    """`eoloc serve` under ``clients`` concurrent keep-alive clients for ``seconds`` (single
    observations), then a compressed Arrow bomb, slow clients and clients that never read."""
    import httpx
    from test_hostile_input import S13_POSE, _arrow_stream

    port = _free_port(socket.SOCK_STREAM)
    mountain = Path(__file__).parents[1] / "src" / "eoloc" / "data" / "demo" / "mountain"
    proc = subprocess.Popen([EOLOC, "serve", "--port", str(port), "--config", str(mountain / "camera.toml"),
                             "--request-timeout", "5", "--send-timeout", "5"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    for _ in range(300):
        try:
            if httpx.get(url + "/v1/health", timeout=1).status_code == 200:
                break
        except httpx.TransportError:
            time.sleep(0.1)
    lines = []
    try:
        body = json.dumps({"pose": S13_POSE, "stop": {"target_height_m": 100.0}}).encode()

        async def load():
            limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
            async with httpx.AsyncClient(base_url=url, limits=limits, timeout=60) as client:
                lat, codes = [], {}
                end = time.perf_counter() + seconds

                async def one():
                    while time.perf_counter() < end:
                        t = time.perf_counter()
                        try:
                            r = await client.post("/v1/locate", content=body,
                                                  headers={"content-type": "application/json"})
                        except httpx.TransportError as exc:  # counted: e.g. a kept-alive connection closed
                            name = type(exc).__name__  # by the server as the client reused it (a race)
                            codes[name] = codes.get(name, 0) + 1
                            continue
                        lat.append(time.perf_counter() - t)
                        codes[r.status_code] = codes.get(r.status_code, 0) + 1

                await asyncio.gather(*(one() for _ in range(clients)))
                return np.array(lat) * 1e3, codes

        rss0 = _rss_mb(proc.pid)
        lat, codes = asyncio.run(load())
        five = sum(v for k, v in codes.items() if isinstance(k, int) and k >= 500)
        lines.append(row(f"`eoloc serve`: {clients} concurrent clients for {seconds:.0f} s, single observations",
                         f"{len(lat):,} requests, {len(lat) / seconds:.0f}/s; p50 {np.percentile(lat, 50):.1f} ms, "
                         f"p99 {np.percentile(lat, 99):.1f} ms; 5xx: {five}; statuses {codes}", "", None))
        bomb = _arrow_stream(10**8, compression="zstd")
        before = _rss_mb(proc.pid)
        r = httpx.post(url + "/v1/locate/arrow", content=bomb,
                       headers={"content-type": "application/vnd.apache.arrow.stream"}, timeout=120)
        lines.append(row(f"compressed Arrow bomb ({len(bomb) / 1024:.1f} KB declaring 10^8 rows, 1.6 GB inflated)",
                         f"HTTP {r.status_code}; RSS {before:.0f} -> {_rss_mb(proc.pid):.0f} MB (goal growth < 50)",
                         "", None))
        t = time.perf_counter()
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.sendall(b"POST /v1/locate HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            s.settimeout(60)
            try:
                while True:
                    s.sendall(b"X: 1\r\n")
                    time.sleep(0.5)
            except OSError:
                pass
        lines.append(row("slow headers (a header line every 0.5 s), --request-timeout 5",
                         f"cut after {time.perf_counter() - t:.1f} s (408)", "", None))
        big = json.dumps({"pose": {**S13_POSE, "gimbal_deg": [45.0, -30.0]}, "stop": {"target_height_m": 100.0},
                          "pixels": [[float(k % 1280), float(k // 1280)] for k in range(100_000)]}).encode()
        socks = []
        for _ in range(30):
            s = socket.socket()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(("127.0.0.1", port))
            s.sendall(b"POST /v1/locate HTTP/1.1\r\nHost: 127.0.0.1\r\ncontent-type: application/json\r\n"
                      + f"content-length: {len(big)}\r\n\r\n".encode() + big)
            socks.append(s)
        peak, t = 0.0, time.perf_counter()
        while any(s.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 8)[0] == 1 for s in socks):
            peak = max(peak, _rss_mb(proc.pid))
            time.sleep(0.2)
        for s in socks:
            s.close()
        lines.append(row("30 clients that never read their ~15 MB answers, --send-timeout 5",
                         f"all cut after {time.perf_counter() - t:.1f} s; RSS {rss0:.0f} MB before the load, "
                         f"{peak:.0f} MB at most, {_rss_mb(proc.pid):.0f} MB after", "", None))
    finally:
        proc.terminate()
        proc.wait(30)
    return lines


# -- suites ------------------------------------------------------------------------------------------


def klv(n: int) -> list[str]:
    from klvfuzz import mutated_packets

    import eoloc
    from eoloc.io.klv.reader import decode_klv_bytes, split_klv
    from eoloc.live.session import LiveSession

    flight = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "flight.klv"
    good = [raw for raw, _ in split_klv(flight.read_bytes()) if decode_klv_bytes(raw).packets]
    bad = mutated_packets(good, n, seed=100)
    t = time.perf_counter()
    kept = errors = 0
    for p in bad:
        try:
            kept += len(decode_klv_bytes(p).packets)
        except Exception:
            errors += 1
    decode_s = time.perf_counter() - t
    session = LiveSession("udp://mutated")  # (no DEM: each packet located on its frame-centre height)
    live_errors = 0
    t = time.perf_counter()
    m = min(n, 5_000)
    for p in bad[:m]:
        try:
            session.feed(p)
        except Exception:
            live_errors += 1
    return [row(f"{n:,} mutated ST 0601 packets with valid checksums (tests/helpers/klvfuzz.py) through the "
                "tolerant decoder", f"{kept:,} kept, exceptions {errors}, {decode_s / n * 1e6:.0f} µs a packet", "",
                None),
            row(f"the first {m:,} through a live session (located, faults counted)",
                f"exceptions {live_errors}; {session.counters.packets:,} packets, "
                f"{time.perf_counter() - t:.1f} s", "", None)]


def csv_files(n: int) -> list[str]:
    from csvfuzz import fuzzed_csv

    from eoloc.io.telemetry import read_detections

    lost = extra = errors = lines = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(n):
            f = fuzzed_csv(10_000 + seed)
            path = Path(tmp) / "f.csv"
            path.write_bytes(f.data)
            try:
                t = read_detections(path)
            except Exception:
                errors += 1
                continue
            lines += len(f.expected)
            got = len(t)
            lost += max(0, len(f.expected) - got)
            extra += max(0, got - len(f.expected))
    return [row(f"{n:,} fuzzed CSV files (line ends, BOM, quotes, 100-300 KiB fields, bad lines)",
                f"exceptions {errors}; {lines:,} good lines, {lost} lost, {extra} invented", "", None)]


def http(n: int) -> list[str]:
    import httpx
    from served import eoloc_serve, stop_and_log
    from test_hostile_input import MOUNTAIN, _hostile_bodies

    rng = np.random.default_rng(1)
    codes: dict[int, int] = {}
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml")) as url:
        with httpx.Client(base_url=url, timeout=60) as client:
            for ctype, body in _hostile_bodies(rng, n):
                route = "/v1/locate/arrow" if "arrow" in ctype else "/v1/locate"
                r = client.post(route, content=body, headers={"content-type": ctype})
                codes[r.status_code] = codes.get(r.status_code, 0) + 1
        log = stop_and_log(url)
    return [row(f"{n:,} hostile HTTP bodies (JSON with wrong types, broken JSON, deep nesting, random bytes, "
                "damaged Arrow streams)", f"statuses {dict(sorted(codes.items()))}; 5xx "
                f"{sum(v for k, v in codes.items() if k >= 500)}; tracebacks in the log {log.count('Traceback')}",
                "", None)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("live")
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--rate", type=float, default=5000.0)
    p = sub.add_parser("serve")
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--clients", type=int, default=200)
    for name, default in (("klv", 100_000), ("csv", 4_000), ("http", 2_000)):
        sub.add_parser(name).add_argument("--n", type=int, default=default)
    a = ap.parse_args()
    os.environ.setdefault("PYTHONHASHSEED", "0")
    print(machine())
    print(HEADER)
    rows = {"live": lambda: live(a.seconds, a.rate), "serve": lambda: serve(a.seconds, a.clients),
            "klv": lambda: klv(a.n), "csv": lambda: csv_files(a.n), "http": lambda: http(a.n)}[a.what]()
    print("\n".join(rows))


if __name__ == "__main__":
    main()
