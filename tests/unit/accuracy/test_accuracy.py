"""Accuracy analysis: CEP against large samples, Monte Carlo through the real chain, the sources' scenarios."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eoloc import geodetic_to_ecef
from eoloc.accuracy import (
    ErrorBudget,
    ErrorSource,
    cep_bivariate,
    cep_empirical,
    drms,
    error_ellipse,
    monte_carlo,
    q_dem,
    q_ellipsoid,
    s13,
    sensitivity,
)
from eoloc.accuracy.montecarlo import chunk_sizes
from eoloc.accuracy.scenarios import Q_SOURCE_ELLIPSOID


@pytest.mark.parametrize("mx, my, sx, sy, rho", [
    (0.0, 0.0, 10.0, 10.0, 0.0),
    (5.0, -3.0, 10.0, 4.0, 0.0),
    (17.41, 20.34, 7.77, 10.05, 0.3),  # [Z15]'s systematic and random parts
    (0.0, 0.0, 20.0, 1.0, -0.8),
    (30.0, 0.0, 3.0, 3.0, 0.0),  # bias dominates
])
def test_parametric_cep_matches_ten_million_samples(mx, my, sx, sy, rho):
    rng = np.random.default_rng(7)
    cov = [[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]]
    xy = rng.multivariate_normal([mx, my], cov, size=10_000_000)
    emp = cep_empirical(xy[:, 0], xy[:, 1])
    par = cep_bivariate(mx, my, sx, sy, rho)
    assert abs(par - emp) / emp < 0.005  # sampling error of the median radius at 1e7: ~0.05 %


def test_cep_closed_forms_and_drms():
    # zero-mean circular normal: Rayleigh, CEP = sigma sqrt(2 ln 2)
    assert cep_bivariate(0, 0, 3.0, 3.0) == pytest.approx(3.0 * math.sqrt(2 * math.log(2)), rel=1e-9)
    # all the spread on one axis: CEP = 0.67449 sigma (the normal's 75 % quantile)
    assert cep_bivariate(0, 0, 2.0, 0.0) == pytest.approx(2.0 * 0.6744897501960817, rel=1e-9)
    assert cep_bivariate(3.0, 4.0, 0.0, 0.0) == pytest.approx(5.0)
    assert drms(3.0, 4.0) == 5.0  # [Q] eq. 18 computes this and calls it CEP: it is 1.18x larger here
    assert drms(3.0, 3.0) / cep_bivariate(0, 0, 3.0, 3.0) == pytest.approx(math.sqrt(2) / math.sqrt(2 * math.log(2)))
    a, b, az = error_ellipse([[4.0, 0.0], [0.0, 1.0]])  # east-west major axis, 1-sigma
    assert (a, b, az) == pytest.approx((2.0, 1.0, 90.0))


def test_s13_sensitivities_position_rows_are_one():
    """[S13] Table 1 budget, each source alone: the aircraft position moves the target one for one."""
    rows = {r.source: r for r in sensitivity(s13(), 100_000, seed=3)}
    assert rows["lat_deg"].mu_lat == pytest.approx(1.0, abs=0.01)
    assert rows["lon_deg"].mu_lon == pytest.approx(1.0, abs=0.01)
    assert rows["lat_deg"].mu_lon < 0.01 and rows["lon_deg"].mu_lat < 0.01
    # an angle error of sigma rad at 10.2 km slant range moves the point ~ range x sigma sideways
    for name in ("yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg"):
        r = rows[name]
        assert 0.05 * 10_200 * math.radians(1) < r.sigma_horizontal_m / r.sigma_in < 1.5 * 10_200 * math.radians(1)


def test_range_error_alone_moves_the_fix_along_the_ray_by_exactly_its_sigma():
    scn = s13().with_budget(ErrorBudget((ErrorSource("range_m", "normal", 5.0),)))
    r = monte_carlo(scn, 50_000, seed=4, keep_samples=True)
    e = r.enu[:, 0]
    # every sample is the truth moved along the (fixed) ray: a line through the truth
    d = e / np.linalg.norm(e, axis=1, keepdims=True)
    assert np.min(np.abs(d @ d[0])) > 1 - 1e-9
    assert np.std(np.linalg.norm(e, axis=1) * np.sign(d @ d[0]), ddof=1) == pytest.approx(5.0, rel=0.02)


def test_no_error_gives_exactly_the_truth():
    scn = s13().with_budget(ErrorBudget((ErrorSource("yaw_deg", "normal", 0.0),)))
    r = monte_carlo(scn, 1000, seed=0, keep_samples=True)
    assert np.max(np.abs(r.enu)) < 1e-6
    assert r.stats[0].truth == pytest.approx((42.02058646, 125.03195512, 419.58), abs=0.005)  # [S13] Table 3


def test_q_ellipsoid_scenario_reproduces_the_source():
    """[Q] Table 1 on the ellipsoid with the relief as a height error: sigma lat/lon/h within 5 %
    of the paper's 0.00048 deg, 0.00060 deg, 62.3 m (n = 20 000, seeded)."""
    st = monte_carlo(q_ellipsoid(), 20_000, seed=5).stats[0]
    for got, want in zip((st.sigma_lat_deg, st.sigma_lon_deg, st.sigma_h_m), Q_SOURCE_ELLIPSOID, strict=True):
        assert got == pytest.approx(want, rel=0.05)
    assert st.n_failed == 0


def test_q_dem_scenario_removes_the_terrain_term():
    """With a DEM the relief is no longer an error: sigmas drop by > 3x. [Q] reports 0.00015 deg,
    0.00013 deg, 3.58 m on its real DEM; ours (a synthetic relief of the same sigma) gives the same
    order; the height sigma depends on the local slope at the target, which differs."""
    ell = monte_carlo(q_ellipsoid(), 5000, seed=6).stats[0]
    dem = monte_carlo(q_dem(), 5000, seed=6).stats[0]
    assert dem.sigma_lat_deg < ell.sigma_lat_deg / 3 and dem.sigma_lon_deg < ell.sigma_lon_deg / 3
    assert dem.sigma_h_m < 10.0 and 0.00005 < dem.sigma_lat_deg < 0.0003 and 0.00005 < dem.sigma_lon_deg < 0.0003


def test_seeded_and_chunk_placement_independent():
    """Same seed, same statistics; computing the chunks elsewhere and in another order (what Dask
    does) gives identical samples, because chunk i always draws from the i-th child seed."""
    scn = s13()
    a = monte_carlo(scn, 30_000, seed=9, chunk=7000)
    b = monte_carlo(scn, 30_000, seed=9, chunk=7000)

    def reversed_mapper(fn, args_list, on_done=None):
        done = {i: fn(*args_list[i]) for i in reversed(range(len(args_list)))}
        return [done[i] for i in range(len(args_list))]

    c = monte_carlo(scn, 30_000, seed=9, chunk=7000, mapper=reversed_mapper)
    assert a.stats == b.stats == c.stats
    assert monte_carlo(scn, 30_000, seed=10, chunk=7000).stats != a.stats
    assert chunk_sizes(30_000, 7000) == [7000, 7000, 7000, 7000, 2000]


@pytest.mark.parametrize("law, value", [("normal", 0.02), ("normal", 8e-8), ("uniform", 0.0015), ("uniform", 3.0)])
def test_draws_are_numpys_normal_and_uniform_bit_for_bit(law, value):
    """Draws scaled in place are numpy's own rng.normal(0, sigma) / rng.uniform(-max, max), number
    for number: a seed gives the samples it always gave."""
    got = ErrorSource("yaw_deg", law, value).draw(np.random.default_rng(5), 50_000)
    rng = np.random.default_rng(5)
    ref = rng.normal(0.0, value, 50_000) if law == "normal" else rng.uniform(-value, value, 50_000)
    np.testing.assert_array_equal(got, ref)
    if law == "uniform":
        assert np.all(np.abs(got) <= value)


def test_budget_errors_name_the_fix():
    with pytest.raises(ValueError, match="unknown error source 'yaw'"):
        ErrorSource("yaw", "normal", 0.1)
    with pytest.raises(ValueError, match="law must be 'normal' or 'uniform'"):
        ErrorSource("yaw_deg", "gauss", 0.1)
    with pytest.raises(ValueError, match="give exactly one law"):
        ErrorBudget.from_mapping({"yaw_deg": {"normal": 0.1, "uniform": 0.2}})
    b = ErrorBudget.from_mapping({"yaw_deg": {"normal": 0.1}, "gimbal1_deg": {"uniform": 0.3}})
    assert [s.sigma for s in b] == pytest.approx([0.1, 0.3 / math.sqrt(3)])


def test_cli_accuracy_from_a_config_file_and_builtin(tmp_path):
    import csv

    from click.testing import CliRunner

    from eoloc.cli import main

    cfg = tmp_path / "acc.toml"
    cfg.write_text(
        "[camera]\nwidth = 1000\nheight = 800\nhfov_deg = 20\n[gimbal]\nmodel = \"az-el\"\n"
        "[accuracy]\nstop = {range_m = 10200}\nsamples = 20000\nseed = 1\n"
        "pixels = [[499.5, 399.5], [100, 700]]\n"
        "pose = {lat_deg = 42, lon_deg = 125, h_m = 10000, yaw_deg = 10, pitch_deg = 5, roll_deg = -2, "
        "gimbal_deg = [45, -75]}\n"
        "[accuracy.budget]\nlat_deg = {normal = 0.8e-7}\nlon_deg = {normal = 0.8e-7}\nyaw_deg = {normal = 0.02}\n"
        "gimbal1_deg = {uniform = 0.0015}\n")
    r = CliRunner().invoke(main, ["accuracy", str(cfg), "--sensitivity-samples", "5000", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    assert "CEP50, bivariate normal" in r.output and "DRMS (m; not a CEP)" in r.output
    rows = list(csv.DictReader((tmp_path / "accuracy.csv").open()))
    assert len(rows) == 2 and float(rows[0]["truth_lat_deg"]) == pytest.approx(42.02058646, abs=1e-7)
    sens = {row["source"]: row for row in csv.DictReader((tmp_path / "sensitivity.csv").open())}
    assert float(sens["lat_deg"]["mu_lat"]) == pytest.approx(1.0, abs=0.03)
    bad = tmp_path / "bad.toml"
    bad.write_text(cfg.read_text().replace("yaw_deg = {normal", "yaw = {normal"))
    r = CliRunner().invoke(main, ["accuracy", str(bad)])
    assert r.exit_code == 2 and "unknown error source 'yaw'" in r.output
    r = CliRunner().invoke(main, ["accuracy", "--scenario", "s13", "-n", "5000", "--no-sensitivity", "--out",
                                  str(tmp_path / "b")])
    assert r.exit_code == 0 and "s13: 5,000 samples" in r.output


def test_perturbed_chain_matches_an_independent_scipy_pyproj_chain():
    """The Monte Carlo samples ([S13] budget) equal the same chain written independently with scipy
    Rotation (attitude ZYX, turret ZY) and pyproj (geodetic <-> ECEF): < 1 mm for every sample."""
    import pyproj
    from scipy.spatial.transform import Rotation

    from eoloc.accuracy.montecarlo import perturbed_fixes

    scn = s13()
    n = 20_000
    d = scn.budget.draw(np.random.default_rng(11), n)
    f = perturbed_fixes(scn, d, n)
    lat, lon = 42.0 + d["lat_deg"], 125.0 + d["lon_deg"]
    att = Rotation.from_euler("ZYX", np.c_[10.0 + d["yaw_deg"], 5.0 + d["pitch_deg"], -2.0 + d["roll_deg"]],
                              degrees=True)
    turret = Rotation.from_euler("ZY", np.c_[45.0 + d["gimbal1_deg"], -75.0 + d["gimbal2_deg"]], degrees=True)
    los_ned = (att * turret).apply([1.0, 0.0, 0.0])
    la, lo = np.radians(lat), np.radians(lon)
    north = np.c_[-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)]
    east = np.c_[-np.sin(lo), np.cos(lo), np.zeros(n)]
    down = -np.c_[np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)]
    to_ecef = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    p0 = np.stack(to_ecef.transform(lon, lat, np.full(n, 10_000.0)), -1)
    p = p0 + 10_200.0 * (los_ned[:, :1] * north + los_ned[:, 1:2] * east + los_ned[:, 2:] * down)
    mine = np.stack(geodetic_to_ecef(np.ravel(f.lat_deg), np.ravel(f.lon_deg), np.ravel(f.h_m)), -1)
    assert np.max(np.linalg.norm(mine - p, axis=1)) < 1e-3
