"""The hostile-input oracle at scale: every answer of every stop rule on both backends, checked
against ``tests/helpers/oracle_lib.py`` (scipy Rotation + pyproj + pymap3d, no eoloc code).

    python bench/oracle.py [-n 1000000] [--m4 100000] [--multiview 100000] [--seed 0]

Prints, per rule, the cases, the statuses and what was found wrong (crashes, OK-but-wrong,
non-OK with finite coordinates, statuses the inputs do not justify, backend disagreements);
exits 1 if anything was. Progress goes to stderr. The README's reliability section quotes it.
"""

from __future__ import annotations

import argparse
import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "helpers"))

import oracle_lib as O

import eoloc
from eoloc.rules.multiview import triangulate

TILE = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"
CHUNK = 20_000


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", type=int, default=1_000_000, help="cases per rule for M1, M2, M3 and the tangent family")
    ap.add_argument("--m4", type=int, default=100_000, help="cases for M4 (each checked by a dense search)")
    ap.add_argument("--multiview", type=int, default=100_000, help="targets for multi-view (2-5 rays each)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    runner = O.Runner(eoloc)
    crashes = 0
    z, lat0, lon0, dlat, dlon = O.real_tile(TILE, voids=12, seed=args.seed)
    dem = eoloc.DEM.from_array(z, lat0=lat0, lon0=lon0, dlat=dlat, dlon=dlon)
    grid = O.Grid(z, lat0, lon0, dlat, dlon)
    # per call: M1, M3 and M2 run n cases for each of the 3 gimbal kinds, so n / 3 per call
    plan = [("m1", args.n // 3, ()), ("m3", args.n // 3, ()), ("m3_tangent", args.n, ()), ("m2", args.n // 3, ()),
            ("m4", args.m4, (dem, grid)), ("multiview", args.multiview, (triangulate,))]
    t0 = time.perf_counter()
    for method, total, extra in plan:
        chunk = 2_000 if method == "multiview" else (5_000 if method == "m4" else CHUNK)
        done = 0
        while done < total:
            n = min(chunk, total - done)
            try:
                getattr(runner, method)(rng, n, *extra)
            except Exception:  # a crash is a finding, counted and shown, not the end of the run
                crashes += 1
                traceback.print_exc()
            done += n
            print(f"{method}: {done}/{total} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    print(f"eoloc {eoloc.__version__}, backends {', '.join(runner.backends)} (counts over both), seed {args.seed}, "
          f"{time.perf_counter() - t0:.0f} s")
    for line in runner.lines():
        print(line)
    for case in runner.cases:
        print("wrong case:", *case)
    print(f"crashes: {crashes}; wrong: {runner.n_wrong}")
    return 1 if crashes or runner.n_wrong else 0


if __name__ == "__main__":
    sys.exit(main())
