"""`eoloc live` soak: a generated stream at 30 Hz with 20 VMTI targets per packet sent over loopback
UDP (raw KLV datagrams, paced on an absolute schedule) to `eoloc live` (the real command, its own
process) with Cursor-on-Target by UDP to a receiver in this process.

Measured from outside: good packets lost (sent - processed), CoT events lost (sent - received),
the latency from a datagram sent to its aircraft event received (the receiver matches the packet
number in the event), eoloc's own latency (datagram received -> outputs sent, its summary), the
CPU time of the eoloc process over the measured part (/proc), hence how many such streams one
core carries. Baseline in the same run: the same packets through the batch path (`eoloc klv`'s
job, in this process), CPU per packet.

    python bench/bench_live.py [--minutes 10]
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import row, script

RATE_HZ, TARGETS, WARMUP = 30.0, 20, 90


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Receiver:
    """CoT datagrams: counted; the arrival time of each aircraft event by its packet number."""

    def __init__(self, port: int) -> None:
        from eoloc.live.sources import DatagramSink

        self.events, self.platform_at = 0, {}
        self.pattern = re.compile(rb"packet (\d+) of")
        self.sink = DatagramSink(f"udp://127.0.0.1:{port}", self._count)

    def _count(self, data: bytes, arrival: float) -> None:
        self.events += 1
        if b'type="a-f-A-M-F-Q"' in data and (m := self.pattern.search(data)):
            self.platform_at[int(m.group(1))] = arrival


def main(minutes: float) -> list[str]:
    from eoloc.io.klv.reader import split_klv
    from eoloc.io.klv.synthetic import circling_flight_klv
    from eoloc.jobs.klv import klv_job

    n = WARMUP + int(minutes * 60 * RATE_HZ)
    data = circling_flight_klv(n, seed=7, rate_hz=RATE_HZ, n_targets=TARGETS)
    packets = [raw for raw, _ in split_klv(data)]
    with tempfile.TemporaryDirectory() as tmp:  # the baseline: the batch path on the same packets
        path = Path(tmp) / "soak.klv"
        path.write_bytes(b"".join(packets[WARMUP:WARMUP + 3000]))
        klv_job(path, map_layers=False)
        c0 = time.process_time()
        job = klv_job(path, map_layers=False)
        batch_cpu_per_packet = (time.process_time() - c0) / job.stream.n_good
    port, cot_port = _free_port(), _free_port()
    rx = Receiver(cot_port)
    eoloc = str(Path(sys.executable).parent / "eoloc")
    proc = subprocess.Popen([eoloc, "live", f"udp://127.0.0.1:{port}", "--cot", f"udp://127.0.0.1:{cot_port}"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    while "listening on" not in proc.stdout.readline():
        assert proc.poll() is None
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for raw in packets[:WARMUP]:  # imports and compiled kernels warm, as in a session already running
        tx.sendto(raw, ("127.0.0.1", port))
        time.sleep(1 / RATE_HZ)
    time.sleep(3.0)
    cpu0, sent_at = _cpu_s(proc.pid), {}
    t0 = time.perf_counter()
    for k, raw in enumerate(packets[WARMUP:]):
        due = t0 + k / RATE_HZ
        while (wait := due - time.perf_counter()) > 0:
            time.sleep(min(wait, 0.002))
        sent_at[WARMUP + k] = time.perf_counter()
        tx.sendto(raw, ("127.0.0.1", port))
    wall = time.perf_counter() - t0
    time.sleep(2.0)
    cpu = _cpu_s(proc.pid) - cpu0
    proc.send_signal(signal.SIGINT)
    log, _ = proc.communicate(timeout=60)
    rx.sink.stop()
    summary = json.loads(log[log.index("{", log.index("eoloc live stopped")):].splitlines()[0])
    lost_packets = n - summary["packets"]
    lost_events = summary["cot"][0]["sent"] - rx.events
    lat = np.array([rx.platform_at[k] - t for k, t in sent_at.items() if k in rx.platform_at]) * 1e3
    measured = n - WARMUP
    cpu_per_packet = cpu / measured
    refine_ms = _refine_cost(packets[:400])
    per_core = 1.0 / (cpu / wall)
    return [
        row(f"`eoloc live` soak: {measured:,} packets at {RATE_HZ:.0f} Hz x {TARGETS} VMTI targets "
            f"({wall / 60:.1f} min, loopback UDP in, CoT by UDP out)",
            f"good packets lost {lost_packets} (goal 0); CoT events lost {lost_events} of "
            f"{summary['cot'][0]['sent']:,}", "", None),
        row("latency, datagram sent -> its aircraft CoT event received (this process)",
            f"p50 {np.percentile(lat, 50):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms, max {lat.max():.1f} ms "
            "(goal p50 <= 2, p99 <= 10)", "", None),
        row("latency, datagram received -> all its outputs sent (eoloc's summary, warm-up included)",
            f"p50 {summary['latency_ms_median']:.2f} ms, p99 {summary['latency_ms_p99']:.2f} ms", "", None),
        row("CPU of the eoloc process per stream",
            f"{cpu / wall * 100:.0f} % of a core ({cpu_per_packet * 1e3:.2f} ms per packet); one core carries "
            f"{per_core:.1f} such streams",
            f"batch path (`eoloc klv` job) {batch_cpu_per_packet * 1e3:.2f} ms per packet",
            batch_cpu_per_packet / cpu_per_packet),
        row("`--track static` (the default: RLS per target id), CPU per packet in-process (LiveSession)",
            f"{refine_ms['static']:.2f} ms", f"--track off {refine_ms['off']:.2f} ms", refine_ms["off"] /
            refine_ms["static"]),
        row("`--track auto` (RLS + the Kalman tracker per target id), CPU per packet in-process",
            f"{refine_ms['auto']:.2f} ms", f"--track off {refine_ms['off']:.2f} ms", refine_ms["off"] /
            refine_ms["auto"]),
    ]


def _refine_cost(packets: list[bytes]) -> dict[str, float]:
    """CPU ms per packet of a LiveSession without and with the targets refined across packets
    (the first 100 packets warm it up)."""
    from eoloc.live.refine import TargetFilters
    from eoloc.live.session import LiveSession

    out = {}
    for model in ("off", "static", "auto"):
        s = LiveSession("bench", refine=None if model == "off" else TargetFilters(model))
        for raw in packets[:100]:
            s.feed(raw)
        c0 = time.process_time()
        for raw in packets[100:]:
            s.feed(raw)
        out[model] = (time.process_time() - c0) / (len(packets) - 100) * 1e3
    return out


if __name__ == "__main__":
    script(main, __doc__, flag="--minutes", kind=float, default=1.0, help_text="length of the soak (the goal's is 10)")
