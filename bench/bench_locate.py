"""Batch pixel -> ground (M3 ellipsoid, M1 range) throughput and single-target latency.

Peers measured in the same run: pymap3d ``lookAtSpheroid`` (vectorised numpy, and called per
target), and a straightforward one-target-at-a-time loop over eoloc's own array API. eoloc's
figures include the whole chain (pixel, camera, gimbal, attitude, lever arm); pymap3d's start from
an azimuth/tilt already in the local frame, so the comparison flatters pymap3d.

    python bench/bench_locate.py [--n 1000000]
"""

from __future__ import annotations

import numpy as np
from pymap3d.los import lookAtSpheroid

import eoloc
from _common import best_time, row, script
from eoloc import AtHeight, AzElGimbal, Camera, Pose, SensorModel

SENSOR = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())


def scene(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    pixels = (rng.uniform(0, 1023, n), rng.uniform(0, 767, n))
    one_pose = Pose(35.0, 112.7, 3000.0, 290.5, 2.1, 0.0, (89.9, -50.0))
    many = Pose(35.0 + rng.normal(0, 1e-3, n), 112.7 + rng.normal(0, 1e-3, n), 3000 + rng.normal(0, 15, n),
                290.5 + rng.normal(0, 1.5, n), 2.1 + rng.normal(0, 0.4, n), rng.normal(0, 0.4, n),
                (89.9 + rng.normal(0, 0.2, n), -50 + rng.normal(0, 0.2, n)))
    return pixels, one_pose, many


def main(n: int) -> list[str]:
    pixels, one_pose, many = scene(n)
    lines = []
    figures = {}
    for backend in eoloc.available_backends():  # "auto" is numba where installed
        with eoloc.use_backend(backend), eoloc.use_threads(1):  # one core, as the peers and SPEC §6
            t = best_time(lambda: eoloc.locate_ellipsoid(SENSOR, one_pose, 0.0, pixels))
            figures[("M3 one pose", backend)] = n / t
            t = best_time(lambda: eoloc.locate_ellipsoid(SENSOR, many, 0.0, pixels))
            figures[("M3 pose per target", backend)] = n / t
            t = best_time(lambda: eoloc.locate_range(SENSOR, one_pose, 4000.0, pixels))
            figures[("M1 one pose", backend)] = n / t
    with eoloc.use_backend("numpy"):  # the numpy kernels split a large batch over every core
        t = best_time(lambda: eoloc.locate_ellipsoid(SENSOR, many, 0.0, pixels))
        figures[(f"M3 pose per target, {eoloc.threads()} threads", "numpy")] = n / t

    # pymap3d vectorised: the same number of rays, az/tilt given directly
    rng = np.random.default_rng(1)
    az, tilt = rng.uniform(0, 360, n), rng.uniform(0, 60, n)
    t_pm = best_time(lambda: lookAtSpheroid(35.0, 112.7, 3000.0, az, tilt), repeat=3)
    pm_rate = n / t_pm
    # one target at a time: pymap3d scalar, and eoloc's array API called per target
    k = 2000
    t_pm1 = best_time(lambda: [lookAtSpheroid(35.0, 112.7, 3000.0, float(a), float(b))
                               for a, b in zip(az[:k], tilt[:k], strict=True)], repeat=3) / k
    u, v = pixels
    t_loop = best_time(lambda: [eoloc.locate_ellipsoid(SENSOR, one_pose, 0.0, (float(u[i]), float(v[i])))
                                for i in range(k)], repeat=3) / k
    with eoloc.use_backend(eoloc.available_backends()[0]):
        ground = AtHeight(0.0)
        t_one = best_time(lambda: [SENSOR.locate_one(35.0, 112.7, 3000.0, 290.5, 2.1, 0.0, 89.9, -50.0,
                                                     float(u[i]), float(v[i]), rule=ground) for i in range(k)],
                          repeat=5) / k

    for (work, backend), rate in figures.items():
        peer = f"pymap3d lookAtSpheroid vectorised {pm_rate / 1e6:.2f} M/s" if work.startswith("M3") else ""
        lines.append(row(f"{work}, {backend}, n={n:,}", f"{rate / 1e6:.2f} M targets/s", peer,
                         rate / pm_rate if peer else None))
    best = max(r for (w, _), r in figures.items() if w == "M3 one pose")
    lines.append(row("M3 batch vs one-target-at-a-time loop (eoloc array API per target)",
                     f"{best / 1e6:.2f} M/s", f"{1 / t_loop / 1e3:.1f} k/s ({t_loop * 1e6:.0f} µs/target)",
                     best * t_loop))
    lines.append(row("one target, one call (SensorModel.locate_one, M3)", f"{t_one * 1e6:.2f} µs",
                     f"pymap3d scalar lookAtSpheroid {t_pm1 * 1e6:.1f} µs", t_pm1 / t_one))
    return lines


if __name__ == "__main__":
    script(main, __doc__)
