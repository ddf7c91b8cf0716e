"""Geodetic <-> ECEF throughput against pyproj (PROJ, C), measured side by side.

    python bench/bench_geodesy.py [--n 1000000]
"""

from __future__ import annotations

import numpy as np
import pyproj

import eoloc
from _common import best_time, row, script


def main(n: int) -> list[str]:
    rng = np.random.default_rng(0)
    lat, lon, h = rng.uniform(-90, 90, n), rng.uniform(-180, 180, n), rng.uniform(-500, 20_000, n)
    fwd = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    inv = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
    x, y, z = fwd.transform(lon, lat, h)
    t_pf = best_time(lambda: fwd.transform(lon, lat, h))
    t_pi = best_time(lambda: inv.transform(x, y, z))
    lines = []
    for backend in eoloc.available_backends():  # "auto" is numba where installed
        with eoloc.use_backend(backend), eoloc.use_threads(1):  # one core, as PROJ
            t_f = best_time(lambda: eoloc.geodetic_to_ecef(lat, lon, h))
            t_i = best_time(lambda: eoloc.ecef_to_geodetic(x, y, z))
        lines.append(row(f"geodetic -> ECEF, {backend}, n={n:,}", f"{n / t_f / 1e6:.1f} M/s",
                         f"pyproj {n / t_pf / 1e6:.1f} M/s", t_pf / t_f))
        lines.append(row(f"ECEF -> geodetic, {backend}, n={n:,}", f"{n / t_i / 1e6:.1f} M/s",
                         f"pyproj {n / t_pi / 1e6:.1f} M/s", t_pi / t_i))
    return lines


if __name__ == "__main__":
    script(main, __doc__)
