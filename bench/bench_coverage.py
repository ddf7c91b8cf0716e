"""Coverage of every uncertainty eoloc gives, big: the README's table (issue 47).

    python bench/bench_coverage.py -n 10000 [--seed 1] [--frames 40] [--mc-samples 1000]

For each path that emits an uncertainty — covariance per fix (height and range rules), the CoT
ce/le a receiver parses, RLS static over a pass, Kalman tracks of moving targets, Monte Carlo,
triangulation — n simulated targets whose truth is made without eoloc (tests/helpers/coverage_lib.py: the
oracle's geometry, pyproj, scipy) and whose telemetry carries biases, noise and Gauss–Markov errors
drawn from the budget; the share of truths inside the predicted 50 % and 90 % circles and 90 %
vertical interval, with the binomial 99 % band. Targets flagged non-linear or INCONSISTENT are
counted apart ("apart"). Prints a Markdown table and the time each path took.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "helpers"))

import coverage_lib as C


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=10_000, help="targets per path")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames", type=int, default=40, help="frames per pass (RLS, Kalman)")
    ap.add_argument("--mc-samples", type=int, default=1000, help="Monte Carlo samples per target")
    a = ap.parse_args()
    rows = []
    times = {}

    def run(name, fn):
        t = time.perf_counter()
        out = fn()
        times[name] = time.perf_counter() - t
        rows.append(out)
        print(out.row(), f"  ({times[name]:.0f} s)", file=sys.stderr, flush=True)
        return out

    for rule in ("height", "range"):
        rng = np.random.default_rng([a.seed, 1, rule == "range"])
        p = C.simulate(rng, a.n, 1, rule)
        fixes, cov, cv = C.per_fix(p, rule)
        rows.append(cv)
        print(cv.row(), file=sys.stderr, flush=True)
        run(f"cot {rule}", lambda: C.cot(fixes, cov, p, rule))  # noqa: B023
        chunks = []
        for i in range(0, a.n, 2000):  # 2 000 passes a call: bounded memory
            q = C.simulate(np.random.default_rng([a.seed, 2, rule == "range", i]), min(2000, a.n - i), a.frames,
                           rule, spread_deg=0.5)
            chunks.append(C.rls(q, rule)[1])
        rows.append(_merge(chunks))
        print(rows[-1].row(), file=sys.stderr, flush=True)
        chunks = []
        for i in range(0, a.n, 2000):
            q = C.simulate(np.random.default_rng([a.seed, 3, rule == "range", i]), min(2000, a.n - i), a.frames,
                           rule, spread_deg=0.5, speed_mps=15.0)
            chunks.append(C.kalman(q, rule))
        rows.append(_merge(chunks))
        print(rows[-1].row(), file=sys.stderr, flush=True)
        q = C.simulate(np.random.default_rng([a.seed, 4, rule == "range"]), a.n, 1, rule)
        run(f"mc {rule}", lambda: C.monte_carlo(q, rule, n=a.mc_samples))  # noqa: B023
    run("triangulation", lambda: C.triangulation(np.random.default_rng([a.seed, 5]), a.n))
    print(f"\ncoverage, {a.n:,} targets per path, seed {a.seed}, {date.today()}, {platform.node()} "
          f"({platform.processor() or platform.machine()})\n")
    print("| path | targets | apart | inside CE50 (99 % band) | inside CE90 (99 % band) | inside LE90 |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(r.row())
    bad = [r.path for r in rows if not all(r.within().values()) and not r.path.startswith("CoT")]
    print("\nall within their bands" if not bad else f"\noutside the band: {', '.join(bad)}")


def _merge(parts: list) -> C.Coverage:
    n = sum(p.n for p in parts)
    w = [p.n / n for p in parts]
    le = [p.in_le90 for p in parts]
    in50 = sum(x.in50 * k for x, k in zip(parts, w, strict=True))
    return C.Coverage(parts[0].path, n, sum(p.apart for p in parts), in50,
                      sum(x.in90 * k for x, k in zip(parts, w, strict=True)),
                      float("nan") if np.isnan(le[0]) else sum(x * k for x, k in zip(le, w, strict=True)))


if __name__ == "__main__":
    main()
