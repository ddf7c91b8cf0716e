"""`eoloc batch` throughput: files/s and packets/s for one process and for a 2-worker Dask
LocalCluster on the same generated archive (circling flights, 5 VMTI targets per packet, located on
the frame-centre elevation), each writing the five GeoParquet layers; the two runs must give the
same partitions (checked). The baseline is the same work file by file in one process.

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
                f"one process {t_one:.1f} s", t_one / t_dask)]


if __name__ == "__main__":
    script(main, __doc__, default=12_000, help_text="packets in the archive, 600 per file (default 12000)")
