"""Start-up of the command line: each command against `python -c "import numpy"`, run alternately
in fresh processes, median wall time and the median of the paired ratios (goal <= 3x).

    python bench/bench_startup.py [--n 15]   (paired runs per command)
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

from _common import HEADER, machine, row

BIN = Path(sys.executable).parent
BASELINE = [sys.executable, "-c", "import numpy"]
COMMANDS = {
    "eoloc --help": [str(BIN / "eoloc"), "--help"],
    "eoloc locate (one observation, --json)": [str(BIN / "eoloc"), "locate", "--lat", "45", "--lon", "7",
                                               "--aircraft-height", "3000", "--gimbal-angles", "0", "-45",
                                               "--target-height", "100", "--json"],
}


def wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(runs: int = 15) -> list[str]:
    lines = []
    for name, cmd in COMMANDS.items():
        wall(cmd)  # warm the file cache (and numba's, were it used)
        pairs = [(wall(BASELINE), wall(cmd)) for _ in range(runs)]
        base = statistics.median(b for b, _ in pairs)
        took = statistics.median(c for _, c in pairs)
        ratio = statistics.median(c / b for b, c in pairs)
        lines.append(row(f"start-up: {name}, median of {runs} paired runs", f"{took * 1e3:.0f} ms ({ratio:.1f}x)",
                         f"python -c 'import numpy' {base * 1e3:.0f} ms", base / took))
    return lines


if __name__ == "__main__":
    n = int(sys.argv[sys.argv.index("--n") + 1]) if "--n" in sys.argv else 15
    print(machine())
    print(HEADER)
    print("\n".join(main(n)))
