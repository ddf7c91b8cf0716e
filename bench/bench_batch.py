"""`eoloc batch` throughput: files/s and packets/s for one process and for a 2-worker Dask
LocalCluster on the same generated archive (circling flights, 5 VMTI targets per packet, located on
the frame-centre elevation), each writing the five GeoParquet layers; the two runs must give the
same partitions (checked). The baseline is the same work file by file in one process.

One long file (5n packets) on one process: the rate where the per-file costs are amortised.
Memory: `eoloc batch` on one long file in a child process (its own peak resident size, VmHWM):
a file of n/2 packets and one 10x longer, read in segments of 1 MB of KLV (the default) and, for
the baseline, whole (one segment as large as the file: what the batch did before it streamed);
the same for an MPEG-TS of those packets (libavformat's muxer; the longer one the shorter 10 times
over), its transport read 8 MB at a time (the default) or whole.

    python bench/bench_batch.py [--n 12000]     # n: packets in the archive (600 per file)
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

from _common import row, script

PACKETS_PER_FILE = 600


def _run(folder: Path, out: Path, mapper) -> tuple[float, list]:
    from eoloc.jobs.batch import BatchSettings, batch_job

    t0 = time.perf_counter()
    job = batch_job([str(folder)], BatchSettings(str(out)), mapper=mapper, redo=True)
    return time.perf_counter() - t0, job.results


_PEAK = """
import sys, time
from pathlib import Path
from eoloc.jobs.batch import BatchSettings, batch_job
t0 = time.perf_counter()
job = batch_job([sys.argv[1]], BatchSettings(sys.argv[2], segment_bytes=int(sys.argv[3])), redo=True)
assert [r.status for r in job.results] == ["done"], job.results
seconds = time.perf_counter() - t0
peak = [int(x.split()[1]) for x in Path("/proc/self/status").read_text().splitlines() if x.startswith("VmHWM:")][0]
print(peak / 1024, seconds, job.results[0].packets)
"""


def long_flight(path: Path, packets: int) -> Path:
    """One long recording: circling flights of 6 000 packets one after the other in time."""
    from eoloc.io.klv.synthetic import START_UNIX_S, circling_flight_klv

    with path.open("wb") as fh:
        for k in range(0, packets, 6_000):
            fh.write(circling_flight_klv(min(6_000, packets - k), seed=k, start_unix_s=START_UNIX_S + k / 10.0))
    return path


def peak_mb(path: Path, out: Path, segment_bytes: int) -> tuple[float, float, int]:
    """(peak resident MB, seconds, packets) of a child process running the batch on ``path``."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _PEAK, str(path), str(out), str(segment_bytes)], check=True,
                          capture_output=True, text=True)
    mb, seconds, packets = done.stdout.split()
    return float(mb), float(seconds), int(packets)


def long_ts(path: Path, short: Path, times: int) -> tuple[Path, Path]:
    """The packets of ``short`` (raw KLV) in an MPEG-TS at 30 Hz, and that TS ``times`` over (``path``)."""
    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.io.klv.reader import split_klv

    packets = [p for p, _ in split_klv(short.read_bytes())]
    one = write_klv_ts(path.with_name("one.ts"), [[(p, k / 30) for k, p in enumerate(packets)]])
    data = one.read_bytes()
    with path.open("wb") as fh:
        for _ in range(times):
            fh.write(data)
    return one, path


def memory_rows(n: int) -> list[str]:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        short, long = long_flight(root / "short.klv", n // 2), long_flight(root / "long.klv", 5 * n)
        short_ts, ts = long_ts(root / "long.ts", short, 10)
        _run_file(long, root / "warm")
        t = min(_run_file(long, root / f"o{k}") for k in range(3))
        rows = [row(f"`eoloc batch`, one recording of {5 * n:,} packets (a long file: the per-file costs "
                    "amortised), one process, best of 3", f"{5 * n / t:,.0f} packets/s ({t:.2f} s)",
                    "(target >= 50,000 per process)", None)]
        for path in (short, long, short_ts, ts):
            whole = peak_mb(path, root / "whole", 1 << 40)
            seg = peak_mb(path, root / "seg", 1_000_000)
            size = path.stat().st_size / 1e6
            what = "MPEG-TS (transport read 8 MB at a time)" if path.suffix == ".ts" else "file"
            rows.append(row(f"`eoloc batch`, one {what} of {seg[2]:,} packets ({size:.0f} MB), peak memory, "
                            "segments of 1 MB", f"{seg[0]:.0f} MB ({seg[1]:.1f} s)",
                            f"read whole: {whole[0]:.0f} MB ({whole[1]:.1f} s)", whole[0] / seg[0]))
    return rows


def _run_file(path: Path, out: Path) -> float:
    from eoloc.jobs.batch import BatchSettings, batch_job

    t0 = time.perf_counter()
    job = batch_job([str(path)], BatchSettings(str(out)), redo=True)
    assert job.results[0].status == "done"
    return time.perf_counter() - t0


def main(n: int = 12_000) -> list[str]:
    import pyarrow.parquet as pq

    from eoloc.accuracy.runners import dask_mapper
    from eoloc.io.klv.synthetic import write_circling_flights

    files = max(2, n // PACKETS_PER_FILE)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        write_circling_flights(root / "in", files, PACKETS_PER_FILE)
        _run(root / "in", root / "warm", None)  # compile and import once, as a long batch would
        shutil.rmtree(root / "warm")
        t_one, res = _run(root / "in", root / "one", None)
        with dask_mapper("local:2") as m:
            _run(root / "in", root / "warm", m)  # the workers import and load the kernels before the clock starts
            t_dask, res_d = _run(root / "in", root / "dask", m)
        assert all(r.status == "done" for r in res + res_d)
        parts = sorted(p.relative_to(root / "one") for p in (root / "one").rglob("*.parquet"))
        same = all(pq.read_table(root / "one" / p).equals(pq.read_table(root / "dask" / p)) for p in parts)
        assert same and len(parts) >= 4 * files  # a file without issues has no issues partition
        packets = sum(r.packets for r in res)
        fixes = sum(r.fixes for r in res)
    return [row(f"`eoloc batch`, {files} KLV files, {packets:,} packets, {fixes:,} VMTI fixes, 5 GeoParquet layers, "
                "one process", f"{files / t_one:.1f} files/s, {packets / t_one:,.0f} packets/s ({t_one:.1f} s)",
                "", None),
            row("the same on a Dask LocalCluster, 2 workers x 1 thread (same partitions: True)",
                f"{files / t_dask:.1f} files/s, {packets / t_dask:,.0f} packets/s ({t_dask:.1f} s)",
                f"one process {t_one:.1f} s", t_one / t_dask),
            *memory_rows(n)]


if __name__ == "__main__":
    script(main, __doc__, default=12_000, help_text="packets in the archive, 600 per file (default 12000)")
