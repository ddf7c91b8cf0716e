"""Monte Carlo throughput: 10^6 samples of the full chain ([S13] budget, M1), the statistics, and
the DEM chain ([Q] with a DEM, M4) beside it.

Peer in the same run: the usual hand-written vectorised Monte Carlo of the same chain (scipy
Rotation for attitude and turret, pyproj for geodetic <-> ECEF), with the same draws.

    python bench/bench_accuracy.py [--n 1000000]
"""

from __future__ import annotations

import numpy as np
import pyproj
from scipy.spatial.transform import Rotation

from _common import best_time, row, script
from eoloc.accuracy import monte_carlo, q_dem, s13
from eoloc.accuracy.montecarlo import perturbed_fixes

TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


def peer_chain(d, n):
    """[S13]'s chain written the usual way: rotations from scipy, conversions from pyproj."""
    lat = 42.0 + d["lat_deg"]
    lon = 125.0 + d["lon_deg"]
    h = np.full(n, 10_000.0)
    att = Rotation.from_euler("ZYX", np.c_[10.0 + d["yaw_deg"], 5.0 + d["pitch_deg"], -2.0 + d["roll_deg"]],
                              degrees=True)
    turret = Rotation.from_euler("ZY", np.c_[45.0 + d["gimbal1_deg"], -75.0 + d["gimbal2_deg"]], degrees=True)
    los_ned = (att * turret).apply([1.0, 0.0, 0.0])
    la, lo = np.radians(lat), np.radians(lon)
    sl, cl, so, co = np.sin(la), np.cos(la), np.sin(lo), np.cos(lo)
    R = np.stack([np.stack([-sl * co, -so, -cl * co], -1), np.stack([-sl * so, co, -cl * so], -1),
                  np.stack([cl, np.zeros(n), -sl], -1)], -2)
    x, y, z = TO_ECEF.transform(lon, lat, h)
    p = np.c_[x, y, z] + 10_200.0 * np.einsum("nij,nj->ni", R, los_ned)
    return TO_ECEF.transform(p[:, 0], p[:, 1], p[:, 2], direction="INVERSE")


def main(n: int) -> list[str]:
    scn = s13()
    rng = np.random.default_rng(0)
    d = scn.budget.draw(rng, n)
    lines = []
    t_chain = best_time(lambda: perturbed_fixes(scn, scn.budget.draw(np.random.default_rng(0), n), n), repeat=3)
    t_peer = best_time(lambda: peer_chain(scn.budget.draw(np.random.default_rng(0), n), n), repeat=3)
    lon_p, lat_p, _ = peer_chain(d, n)
    f = perturbed_fixes(scn, d, n)
    agree = float(np.max(np.abs(np.ravel(f.lat_deg) - lat_p)) * 111_000)
    lines.append(row(f"Monte Carlo, full chain ([S13] budget, M1), draws + locate, n={n:,}",
                     f"{t_chain:.3f} s ({n / t_chain / 1e6:.2f} M samples/s)",
                     f"scipy Rotation + pyproj, same draws {t_peer:.3f} s (agree {agree * 1000:.2f} mm)",
                     t_peer / t_chain))
    t_all = best_time(lambda: monte_carlo(scn, n, seed=0), repeat=3)
    lines.append(row(f"Monte Carlo with statistics (ENU errors, CEP empirical + parametric, CE90, LE90), n={n:,}",
                     f"{t_all:.3f} s", "", None))
    k = min(n, 100_000)
    qd = q_dem()
    t_dem = best_time(lambda: monte_carlo(qd, k, seed=0), repeat=1)
    lines.append(row(f"Monte Carlo, DEM chain ([Q] with a 3\" DEM, M4), n={k:,}",
                     f"{t_dem:.3f} s ({k / t_dem / 1e6:.2f} M samples/s)", "", None))
    return lines


if __name__ == "__main__":
    script(main, __doc__)
