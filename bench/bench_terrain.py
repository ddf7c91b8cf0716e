"""M4 ray ∩ DEM throughput on a 30 m DEM (obliques 0-80°), and one frame of 50 targets by M2
with distortion correction.

The 30 m DEM is real terrain: the 3" SRTM tile of eastern Anatolia (tests/data/dem/srtm_ref.tif,
1111-3270 m) resampled bilinearly to 1" posts. Peers in the same run: the straightforward march
one sample per half cell (vectorised numpy, the usual peer implementation), and eoloc's own numpy path.

    python bench/bench_terrain.py [--n 200000]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.ndimage import zoom

import eoloc
from _common import best_time, row, script
from eoloc import DEM, Camera, DistortionRatio, OnDEM, Pose, SensorModel

ROOT = Path(__file__).resolve().parents[1]


def dem_30m() -> DEM:
    src = eoloc.open_dem(ROOT / "tests" / "data" / "dem" / "srtm_ref.tif")
    z = zoom(src.grid.z, 3, order=1)
    g = src.grid
    # zoom keeps the end posts: the new spacing is the old span over (new posts - 1)
    return DEM.from_array(z, lat0=g.lat0, lon0=g.lon0, dlat=g.dlat * (g.z.shape[0] - 1) / (z.shape[0] - 1),
                          dlon=g.dlon * (g.z.shape[1] - 1) / (z.shape[1] - 1), source="srtm_ref x3 (1\")")


def rays(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    sensor = SensorModel(Camera.from_hfov(20.0, 1000, 800))
    pose = Pose(39.58 + rng.uniform(-0.2, 0.2, n), 40.42 + rng.uniform(-0.2, 0.2, n), 5500.0, 0.0, 0.0, 0.0,
                (rng.uniform(-180, 180, n), -90.0 + rng.uniform(0, 80, n)))
    return sensor, sensor.rays(pose)


def naive_march(r, dem, step_m):
    """The usual peer: sample every half cell from the camera until below the DEM (no guarantee)."""
    t = np.zeros(r.shape)
    done = np.zeros(r.shape, dtype=bool)
    lo, hi = dem.height_range
    for _ in range(100_000):
        p = r.origin_ecef + t[:, None] * r.dir_ecef
        lat, lon, h = eoloc.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
        below = (h - dem.height(lat, lon) <= 0) | (h < lo)
        done |= below
        if done.all():
            break
        t = np.where(done, t, t + step_m)
    return t


def main(n: int) -> list[str]:
    dem = dem_30m()
    sensor, r = rays(n)
    lines = []
    with eoloc.use_backend("numba"):
        t_nb = best_time(lambda: eoloc.stop_at_dem(r, dem, sensor=sensor), repeat=3)
        f = eoloc.stop_at_dem(r, dem, sensor=sensor)
        with eoloc.use_threads(1):
            t_nb1 = best_time(lambda: eoloc.stop_at_dem(r, dem, sensor=sensor), repeat=3)
    k = min(n, 20_000)
    _, rk = rays(k)
    with eoloc.use_backend("numpy"):
        t_np = best_time(lambda: eoloc.stop_at_dem(rk, dem, sensor=sensor), repeat=1)
    kn = 2000
    _, rn = rays(kn)
    t_naive = best_time(lambda: naive_march(rn, dem, dem.spacing_m / 2), repeat=1)
    naive_rate = kn / t_naive
    lines.append(row(f"M4 ray-DEM, 30 m DEM, obliques 0-80 deg, numba, n={n:,} ({f.ok.mean():.0%} OK), one thread",
                     f"{n / t_nb1 / 1e3:.0f} k rays/s", f"naive half-cell march (numpy) {naive_rate / 1e3:.1f} k/s",
                     n / t_nb1 / naive_rate))
    lines.append(row(f"M4 ray-DEM, same, numba on {eoloc.threads()} threads (eoloc.kernels.backend.in_chunks)",
                     f"{n / t_nb / 1e3:.0f} k rays/s", f"one thread {n / t_nb1 / 1e3:.0f} k rays/s", t_nb1 / t_nb))
    lines.append(row(f"M4 ray-DEM, same, numpy lockstep, n={k:,}", f"{k / t_np / 1e3:.0f} k rays/s",
                     f"naive half-cell march (numpy) {naive_rate / 1e3:.1f} k/s", k / t_np / naive_rate))
    cam = Camera.from_focal_mm(50, 5.5, 1024, 768)
    s = SensorModel(cam.with_distortion(DistortionRatio.for_camera(cam)))
    pose = Pose(35.125225, 112.680649, 1140.0, 290.5, 2.1, 0.0, (89.9, -35.0))
    rng = np.random.default_rng(1)
    u, v = rng.uniform(0, 1023, 50), rng.uniform(0, 767, 50)
    t_frame = best_time(lambda: eoloc.locate_flat(s, pose, 965.0, (u, v)), repeat=5, number=200)
    lines.append(row("one frame, 50 targets, M2 + [Z15] distortion correction", f"{t_frame * 1e3:.3f} ms/frame",
                     "[Z15] Matlab 20 ms (0.4 ms/target)", 20e-3 / t_frame))
    from eoloc.ground.footprint import footprints

    fp_pose = Pose(39.58, 40.42, 5500.0, 0.0, 0.0, 0.0, (0.0, -8.0))  # the top of the image sees past the DEM
    t_fp = best_time(lambda: footprints(sensor, fp_pose, OnDEM(dem), edge_samples=16), repeat=3)
    n_clip = int(footprints(sensor, fp_pose, OnDEM(dem), edge_samples=16)[0].clipped.sum())
    lines.append(row(f"footprint of one frame on the 30 m DEM, 64 border rays ({n_clip} clipped by bisection)",
                     f"{t_fp * 1e3:.1f} ms/frame", "", None))
    return lines


if __name__ == "__main__":
    script(main, __doc__, default=200_000, help_text="elements per batch (default 200000)")
