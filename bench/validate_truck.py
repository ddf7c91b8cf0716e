"""The frame-centre check on a real encoder's flight: Esri's FMV sample Truck.klv (711 packets),
which may not be redistributed and so is not in this repository or its tests. Give its path:

    python bench/validate_truck.py PATH/TO/Truck.klv

Prints eoloc's frame centre, corners and slant range against the encoder's own tags (the README's
"frame centre check" row quotes the result) and exits 1 where the figures are past their bounds.
"""

from __future__ import annotations

import sys
from pathlib import Path


def main(path: Path) -> int:
    from eoloc.io.klv import klv_telemetry, read_klv
    from eoloc.jobs.klvframes import check_frames

    s = read_klv(path)
    chk = check_frames(klv_telemetry(s))
    stats = {name: (n, med, p90) for name, n, med, p90, _ in chk.stats()}
    for name, (n, med, p90) in stats.items():
        print(f"{name}: {n} packets, median {med:.1f} m, p90 {p90:.1f} m")
    ok = (s.n_good == 711 and s.n_bad == 0 and stats["frame centre"][0] == 711 and stats["frame centre"][1] < 10.0
          and stats["frame centre"][2] < 30.0 and all(stats[f"corner {k}"][1] < 25.0 for k in range(1, 5))
          and stats["slant range (|ours - tag 21|)"][1] < 5.0)
    print("within bounds" if ok else "PAST THE BOUNDS")
    return 0 if ok else 1


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    sys.exit(main(Path(sys.argv[1])))
