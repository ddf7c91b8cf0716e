"""Run every benchmark and print one markdown table (paste into bench/RESULTS.md)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import bench_accuracy
import bench_batch
import bench_compensation
import bench_csv
import bench_detect
import bench_evaluate
import bench_geodesy
import bench_klv
import bench_live
import bench_locate
import bench_ortho
import bench_refine
import bench_serve
import bench_startup
import bench_terrain
from _common import HEADER, machine

if __name__ == "__main__":
    print(f"Machine: {machine()}\n")
    print(HEADER)
    for line in (bench_locate.main(1_000_000) + bench_geodesy.main(1_000_000) + bench_terrain.main(200_000)
                 + bench_accuracy.main(1_000_000) + bench_compensation.main(1_000_000) + bench_ortho.main(2.25)
                 + bench_startup.main(15)
                 + bench_csv.main() + bench_klv.main(3000) + bench_evaluate.main(1_000_000)
                 + bench_batch.main(12_000) + bench_live.main(1.0) + bench_serve.main(20.0) + bench_detect.main(60)
                 + bench_refine.main(60.0)):
        print(line, flush=True)
