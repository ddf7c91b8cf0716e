"""Monte Carlo throughput: 10^6 samples of the full chain ([S13] budget, M1; [Q] on the
ellipsoid, M3), the statistics, the DEM chain ([Q] with a DEM, M4), first-order covariance per
frame, and a Dask LocalCluster (2 worker processes) against the same run in one process.

Peers in the same run: the usual hand-written vectorised Monte Carlo of the same chain (scipy
Rotation for attitude and turret, pyproj for geodetic <-> ECEF) with the same draws; for the
covariance, the 5 000-sample Monte Carlo it replaces; for Dask, one local process.

    python bench/bench_accuracy.py [--n 1000000]
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pyproj
from scipy.spatial.transform import Rotation

from _common import best_time, row, script
from eoloc.accuracy import locate_with_covariance, monte_carlo, q_dem, q_ellipsoid, s13
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
    t_loc = best_time(lambda: perturbed_fixes(scn, d, n), repeat=3)
    t_peer_loc = best_time(lambda: peer_chain(d, n), repeat=3)
    lines.append(row(f"  the locate chain alone (draws made beforehand), n={n:,}", f"{t_loc:.3f} s",
                     f"scipy Rotation + pyproj {t_peer_loc:.3f} s", t_peer_loc / t_loc))
    qe = q_ellipsoid()
    t_q = best_time(lambda: perturbed_fixes(qe, qe.budget.draw(np.random.default_rng(0), n), n), repeat=3)
    lines.append(row(f"Monte Carlo, [Q] on the ellipsoid (M3, 9 sources), draws + locate, n={n:,}",
                     f"{t_q:.3f} s ({n / t_q / 1e6:.2f} M samples/s)", "", None))
    t_all = best_time(lambda: monte_carlo(scn, n, seed=0), repeat=3)
    lines.append(row(f"Monte Carlo with statistics (ENU errors, CEP empirical + parametric, CE90, LE90), n={n:,}",
                     f"{t_all:.3f} s", "", None))
    k = min(n, 100_000)
    qd = q_dem()
    t_dem = best_time(lambda: monte_carlo(qd, k, seed=0), repeat=1)
    lines.append(row(f"Monte Carlo, DEM chain ([Q] with a 3\" DEM, M4), n={k:,}",
                     f"{t_dem:.3f} s ({k / t_dem / 1e6:.2f} M samples/s)", "", None))
    px = np.stack(np.meshgrid(np.linspace(0, 999, 10), np.linspace(0, 999, 5)), -1).reshape(-1, 2)
    t_cov = best_time(lambda: locate_with_covariance(qd.sensor, qd.pose, qd.budget, px, qd.rule), repeat=5)
    t_mc5k = best_time(lambda: monte_carlo(replace(qd, pixels=px), 5000, seed=0), repeat=1)
    lines.append(row("First-order covariance, one 50-target frame on the DEM ([Q] budget, with the linearity check)",
                     f"{t_cov * 1e3:.2f} ms", f"Monte Carlo n=5,000 of the same frame {t_mc5k * 1e3:.0f} ms",
                     t_mc5k / t_cov))
    if DASK:
        lines += dask_rows(scn, max(n, 2_000_000) * 2)
    return lines


def dask_rows(scn, n: int) -> list[str]:
    """The same Monte Carlo (statistics included) in one process and on a 2-worker LocalCluster."""
    import time

    from distributed import Client, LocalCluster

    from eoloc.accuracy import DaskMapper

    t_local = best_time(lambda: monte_carlo(scn, n, seed=0), repeat=1)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        mapper = DaskMapper(client)
        monte_carlo(scn, 400_000, seed=1, mapper=mapper)  # workers import eoloc and load the compiled kernels
        t0 = time.perf_counter()
        remote = monte_carlo(scn, n, seed=0, mapper=mapper)
        t_dask = time.perf_counter() - t0
    same = remote.stats == monte_carlo(scn, n, seed=0).stats
    return [row(f"Monte Carlo with statistics on a Dask LocalCluster, 2 workers x 1 thread, n={n:,} "
                f"(identical statistics: {same})", f"{t_dask:.2f} s ({n / t_dask / 1e6:.2f} M samples/s)",
                f"one process {t_local:.2f} s ({n / t_local / 1e6:.2f} M samples/s)", t_local / t_dask)]


DASK = True

if __name__ == "__main__":
    import sys

    if "--no-dask" in sys.argv:
        sys.argv.remove("--no-dask")
        DASK = False
    script(main, __doc__)
