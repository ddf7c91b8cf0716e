"""Sweeps ([Q] Fig. 10), the accuracy plots ([Z15] Fig. 7) and the same runs on a Dask cluster."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from eoloc.accuracy import locate_with_covariance, monte_carlo, q_dem, q_ellipsoid, s13, sensitivity
from eoloc.accuracy.plots import plot_scatter, plot_sweep
from eoloc.accuracy.runners import DaskMapper, local_map
from eoloc.accuracy.sweep import sweep_point, terrain_sweep
from eoloc.cli import main


@pytest.fixture(scope="module")
def q_sweep():
    return terrain_sweep(q_ellipsoid(), [10.0, 50.0, 74.0], [10.0, 100.0], n=4000, seed=5)


def _cep(points, method, angle, sigma):
    (p,) = [p for p in points if p.method == method and p.angle_deg == angle and p.terrain_sigma_m == sigma]
    return p


def test_q_sweep_shape_matches_the_source_figure(q_sweep):
    """[Q] Fig. 10: on the ellipsoid the CEP grows with the relief sigma and with the roll angle;
    with a DEM it hardly depends on the relief and stays far below the ellipsoid's."""
    assert all(p.failed == 0 and not p.note for p in q_sweep)
    for a in (10.0, 50.0, 74.0):
        assert _cep(q_sweep, "ellipsoid", a, 100.0).cep50_m > 1.3 * _cep(q_sweep, "ellipsoid", a, 10.0).cep50_m
    for s in (10.0, 100.0):
        c = [_cep(q_sweep, "ellipsoid", a, s).cep50_m for a in (10.0, 50.0, 74.0)]
        assert c[0] < c[1] < c[2]
    for a in (10.0, 50.0):
        dem10, dem100 = _cep(q_sweep, "dem", a, 10.0).cep50_m, _cep(q_sweep, "dem", a, 100.0).cep50_m
        assert abs(dem100 / dem10 - 1.0) < 0.1
    assert _cep(q_sweep, "dem", 50.0, 100.0).cep50_m < _cep(q_sweep, "ellipsoid", 50.0, 100.0).cep50_m / 3


def test_sweep_points_agree_with_first_order_propagation(q_sweep):
    """Cross-check by a different method: each ellipsoid point's CEP50 and DRMS vs the first-order
    covariance of the same pose and budget (within 5 %; n = 4000 gives ~1.5 % sampling error)."""
    scn = q_ellipsoid()
    for a in (10.0, 50.0, 74.0):
        p = _cep(q_sweep, "ellipsoid", a, 100.0)
        pose = replace(scn.pose, gimbal_deg=(a, scn.pose.gimbal_deg[1]))
        budget = replace(scn.budget, sources=tuple(s if s.name != "terrain_m" else replace(s, value=100.0)
                                                   for s in scn.budget))
        _, cov = locate_with_covariance(scn.sensor, pose, budget, None, scn.rule)
        assert p.cep50_m == pytest.approx(float(cov.cep()), rel=0.05)
        assert p.drms_m == pytest.approx(float(cov.drms), rel=0.05)


def test_sweep_input_errors():
    with pytest.raises(ValueError, match="stops on the ellipsoid"):
        terrain_sweep(s13(), [10.0], [10.0])
    with pytest.raises(ValueError, match="angle must be one of"):
        terrain_sweep(q_ellipsoid(), [10.0], [10.0], angle="yaw")
    # a pose whose ray does not reach the ground: reported per point, the sweep goes on
    p = sweep_point(q_ellipsoid(), "ellipsoid", "gimbal1", 95.0, 10.0, 100, 0, 62)
    assert p.failed == 100 and "cannot be located" in p.note and np.isnan(p.cep50_m)


def test_plots_are_written_and_show_something(tmp_path, q_sweep):
    from matplotlib.image import imread

    r = monte_carlo(q_ellipsoid(), 5000, seed=1, keep_samples=True)
    for path in (plot_scatter(r, tmp_path / "s.png"), plot_sweep(q_sweep, tmp_path / "w.png", title="Q")):
        img = imread(path)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 300
        assert img[..., :3].std() > 0.05  # not a blank canvas
    with pytest.raises(ValueError, match="keep_samples"):
        plot_scatter(monte_carlo(q_ellipsoid(), 100), tmp_path / "x.png")


def test_cli_sweep_writes_csv_and_png(tmp_path):
    r = CliRunner().invoke(main, ["sweep", "--scenario", "q-ellipsoid", "--angles", "20,60", "--terrain-sigmas",
                                  "25", "-n", "1000", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert [(row["method"], float(row["angle_deg"])) for row in rows] == [
        ("ellipsoid", 20.0), ("ellipsoid", 60.0), ("dem", 20.0), ("dem", 60.0)]
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
    r = CliRunner().invoke(main, ["sweep", "--scenario", "q-ellipsoid", "--angles", "10:80:-5"])
    assert r.exit_code == 2 and "start:stop:step" in r.output


# ---------------------------------------------------------------- Dask


@pytest.fixture(scope="module")
def dask_client():
    import distributed

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        yield client


def test_dask_monte_carlo_sensitivity_and_sweep_identical_to_local(dask_client):
    """Same seed, same statistics, on a 2-worker LocalCluster: chunks of a DEM Monte Carlo, the
    sensitivity runs and the sweep points (the DEM travels to the workers once, by scatter)."""
    mapper = DaskMapper(dask_client)
    scn = q_dem()
    local = monte_carlo(scn, 30_000, seed=4, chunk=8000)
    seen = []
    remote = monte_carlo(scn, 30_000, seed=4, chunk=8000, mapper=mapper, progress=seen.append)
    assert remote.stats == local.stats
    assert sorted(seen) == [6000, 8000, 8000, 8000]
    assert sensitivity(s13(), 4000, seed=2, mapper=mapper) == sensitivity(s13(), 4000, seed=2)
    args = dict(n=1000, seed=3)
    assert (terrain_sweep(q_ellipsoid(), [20.0, 60.0], [30.0], mapper=mapper, **args)
            == terrain_sweep(q_ellipsoid(), [20.0, 60.0], [30.0], mapper=local_map, **args))
    workers = {w for w in dask_client.run(lambda: 1)}
    assert len(workers) == 2


def test_dask_task_errors_surface(dask_client):
    def boom(x):
        raise RuntimeError(f"bad item {x}")

    with pytest.raises(RuntimeError, match="bad item"):
        DaskMapper(dask_client)(boom, [(1,), (2,)])


def test_one_mapper_maps_the_same_shared_argument_twice(dask_client):
    """Two calls scattering the same shared value back to back: each keeps its own copy (the
    first call's release once took the second call's dependency away: 'lost dependencies')."""
    mapper = DaskMapper(dask_client)
    shared = {"offset": 10.0, "table": list(range(1000))}
    for _ in range(3):
        assert mapper(lambda k, s: k + s["offset"], [(k, shared) for k in range(8)]) == [k + 10.0 for k in range(8)]
