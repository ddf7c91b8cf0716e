"""`eoloc evaluate`: the statistics against hand computation, matching, the TLE model against
statsmodels, the coverage of an honest and a dishonest uncertainty, every reader against eoloc's
own writers, and the command on other tools' column names.

References: fixes are built from chosen east/north/up errors by pymap3d's ``enu2geodetic`` (not
eoloc's geodesy); the statistics of the small set are computed by hand in the comments; Cook's
distance and the OLS standard errors come from statsmodels; bootstrap intervals from
scipy.stats.bootstrap.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from where import ROOT

from eoloc.accuracy import evaluation as E
from eoloc.cli import main
from eoloc.io.points import read_points
from eoloc.io.records import Records
from eoloc.io.writers import write_layer
from eoloc.jobs.evaluate import evaluate_job

# Five fixes of five GCPs with these errors (east, north, up) in metres:
ERRORS = np.array([[3.0, 4.0, 1.0], [0.0, 5.0, -2.0], [6.0, 8.0, 0.5], [-1.0, 0.0, 3.0], [2.0, -2.0, -1.0]])
# by hand: horizontal errors 5, 5, 10, 1, 2.8284 -> sorted 1, 2.8284, 5, 5, 10
#   CEP (median) = 5; CE90: position 0.9 * (5 - 1) = 3.6 -> 5 + 0.6 * (10 - 5) = 8
#   |up| sorted 0.5, 1, 1, 2, 3: LE90 at 3.6 -> 2 + 0.6 * (3 - 2) = 2.6
#   MAE h = (5 + 5 + 10 + 1 + 2.8284) / 5 = 4.76569; RMSE h = sqrt((25 + 25 + 100 + 1 + 8) / 5) = sqrt(31.8)
#   MAE v = 7.5 / 5 = 1.5; RMSE v = sqrt((1 + 4 + 0.25 + 9 + 1) / 5) = sqrt(3.05)
#   bias E = 10 / 5 = 2, N = 15 / 5 = 3, U = 1.5 / 5 = 0.3; max = 10
HAND = {"cep50_m": 5.0, "ce90_m": 8.0, "le90_m": 2.6, "mae_h_m": (21 + math.sqrt(8)) / 5, "rmse_h_m": math.sqrt(31.8),
        "mae_v_m": 1.5, "rmse_v_m": math.sqrt(3.05), "bias_e_m": 2.0, "bias_n_m": 3.0, "bias_u_m": 0.3,
        "max_h_m": 10.0}
GCPS = [("G1", 46.52, 7.41, 1210.0), ("G2", 46.5213, 7.4125, 1234.5), ("G3", 46.519, 7.409, 1195.2),
        ("G4", 46.5231, 7.4071, 1250.0), ("G5", 46.5177, 7.4142, 1188.8)]


def _fix(gcp, enu):
    lat, lon, h = pymap3d.enu2geodetic(*enu, gcp[1], gcp[2], gcp[3])
    return float(lat), float(lon), float(h)


def _write_csv(path: Path, header: list[str], rows) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


@pytest.fixture
def other_tool(tmp_path):
    """The five fixes as another tool writes them (its own column names, ids in 'Name') and the GCPs
    as a surveyor's CSV (Point, Lat, Long, Ellips_H)."""
    fixes = _write_csv(tmp_path / "tool.csv", ["Name", "Latitude", "Longitude", "Altitude_HAE", "Sensor"],
                       [(g[0], f"{lat:.10f}", f"{lon:.10f}", f"{h:.4f}", "A" if i < 3 else "B")
                        for i, (g, e) in enumerate(zip(GCPS, ERRORS, strict=True)) for lat, lon, h in [_fix(g, e)]])
    truth = _write_csv(tmp_path / "survey.csv", ["Point", "Lat", "Long", "Ellips_H"], GCPS)
    return fixes, truth


def test_statistics_reproduce_the_hand_computation_to_a_centimetre(other_tool, tmp_path):
    fixes, truth = other_tool
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["evaluate", str(fixes), "--truth", str(truth), "--fix-columns",
                                  "Latitude,Longitude,Altitude_HAE", "--truth-columns", "Lat,Long,Ellips_H",
                                  "--fix-id", "Name", "--truth-id", "Point", "--group", "Sensor", "--json",
                                  "--out", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    assert doc["match"] == "id" and doc["matched"] == 5 and doc["unmatched"] == 0
    overall = doc["summary"][0]
    assert overall["group"] == "all"
    for k, v in HAND.items():
        assert overall[k] == pytest.approx(v, abs=0.01), k
    # by group: A holds the first three errors (horizontal 5, 5, 10: CEP 5, bias E 3)
    a = next(row for row in doc["summary"] if row["group"] == "A")
    assert a["n"] == 3 and a["cep50_m"] == pytest.approx(5.0, abs=0.01)
    assert a["bias_e_m"] == pytest.approx(3.0, abs=0.01)
    with (out / "evaluation_points.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [row["truth"] for row in rows] == [g[0] for g in GCPS]
    for row, e in zip(rows, ERRORS, strict=True):
        assert [float(row[k]) for k in ("err_e_m", "err_n_m", "err_u_m")] == pytest.approx(e, abs=0.005)


def test_nearest_matching_with_truth_points_30_m_apart():
    """A 6 x 6 grid of GCPs 30 m apart; fixes within 12 m of their GCP find it; a fix 40 m from every
    GCP stays unmatched at --max-distance 20; one half-way between two is flagged ambiguous, none
    within 9 m of its GCP is."""
    rng = np.random.default_rng(3)
    lat0, lon0 = 35.13, 112.67
    grid = [(i, j) for i in range(6) for j in range(6)]
    gcps = [pymap3d.enu2geodetic(30.0 * i, 30.0 * j, 0.0, lat0, lon0, 600.0) for i, j in grid]
    t_lat, t_lon = np.array([g[0] for g in gcps]), np.array([g[1] for g in gcps])
    truth_of, f_lat, f_lon = [], [], []
    for k, (i, j) in enumerate(grid):
        for _ in range(3):
            r, a = rng.uniform(0, 12), rng.uniform(0, 2 * np.pi)
            lat, lon, _ = pymap3d.enu2geodetic(30.0 * i + r * np.sin(a), 30.0 * j + r * np.cos(a), 0.0, lat0, lon0,
                                               600.0)
            f_lat.append(lat)
            f_lon.append(lon)
            truth_of.append(k)
    lat, lon, _ = pymap3d.enu2geodetic(-40.0, -40.0, 0.0, lat0, lon0, 600.0)  # outside the grid
    mid = pymap3d.enu2geodetic(15.0, 0.5, 0.0, lat0, lon0, 600.0)  # between (0, 0) and (1, 0)
    m = E.match_nearest(np.r_[f_lat, lat, mid[0]], np.r_[f_lon, lon, mid[1]], t_lat, t_lon, max_distance_m=20.0)
    assert m.index[:-2].tolist() == truth_of
    assert m.index[-2] == -1
    assert m.ambiguous[-1]
    close = m.distance_m[:-2] < 9.0  # 9 m from one, >= 21 m from the next: not ambiguous
    assert close.sum() > 50 and not m.ambiguous[:-2][close].any()


def test_auto_matching_falls_back_to_nearest_when_no_id_agrees(tmp_path):
    fixes = _write_csv(tmp_path / "f.csv", ["target_id", "lat_deg", "lon_deg", "h_m"],
                       [(str(k), *_fix(g, e)) for k, (g, e) in enumerate(zip(GCPS, ERRORS, strict=True))])
    truth = _write_csv(tmp_path / "t.csv", ["gcp_id", "lat_deg", "lon_deg", "h_m"], GCPS)
    ev = evaluate_job(fixes, truth, n_boot=0)
    assert ev.match == "nearest" and ev.overall.n == 5 and "nearest" in ev.notes[0]
    assert ev.overall.value["cep50_m"] == pytest.approx(5.0, abs=0.01)


def test_bootstrap_intervals_are_seeded_and_agree_with_scipy():
    from scipy import stats as sps

    rng = np.random.default_rng(0)
    enu = np.c_[rng.normal(2, 5, 400), rng.normal(-1, 3, 400), rng.normal(0, 4, 400)]
    a = E.summarize(enu, n_boot=3000, seed=7)
    b = E.summarize(enu, n_boot=3000, seed=7)
    assert a.low == b.low and a.high == b.high
    r = np.hypot(enu[:, 0], enu[:, 1])
    ref = sps.bootstrap((r,), np.median, n_resamples=3000, method="percentile", random_state=1).confidence_interval
    width = ref.high - ref.low
    assert abs(a.low["cep50_m"] - ref.low) < 0.15 * width and abs(a.high["cep50_m"] - ref.high) < 0.15 * width
    ref = sps.bootstrap((enu[:, 0],), np.mean, n_resamples=3000, method="percentile", random_state=1)
    ci = ref.confidence_interval
    assert abs(a.low["bias_e_m"] - ci.low) < 0.1 * (ci.high - ci.low)
    for k in E.STATISTICS:
        if k != "max_h_m":
            assert a.low[k] <= a.value[k] <= a.high[k], k
    # the bivariate-normal CEP of a well-sampled normal cloud is near the empirical one
    assert a.cep_parametric_m == pytest.approx(a.value["cep50_m"], rel=0.1)


def test_cooks_distance_and_the_tle_fit_agree_with_statsmodels():
    import statsmodels.api as sm  # the independent reference (test extras)

    rng = np.random.default_rng(5)
    x = rng.uniform(500, 5000, 60)
    y = 2.0 + 0.004 * x + rng.normal(0, 1.5, 60)
    y[[3, 17]] += 40.0  # two blunders
    ols = sm.OLS(y, sm.add_constant(x)).fit()
    np.testing.assert_allclose(E.cooks_distance(x, y), ols.get_influence().cooks_distance[0], rtol=1e-9)
    fit = E.tle_fit(x, y)
    assert not fit.kept[3] and not fit.kept[17] and fit.n_removed >= 2
    keep = fit.kept
    ref = sm.OLS(y[keep], sm.add_constant(x[keep])).fit()
    assert fit.intercept == pytest.approx(ref.params[0], rel=1e-9)
    assert fit.slope == pytest.approx(ref.params[1], rel=1e-9)
    assert fit.intercept_se == pytest.approx(ref.bse[0], rel=1e-6)
    assert fit.slope_se == pytest.approx(ref.bse[1], rel=1e-6)
    assert fit.r2 == pytest.approx(ref.rsquared, rel=1e-9)
    assert fit.p_slope == pytest.approx(ref.pvalues[1], rel=1e-6, abs=1e-300)
    assert fit.slope == pytest.approx(0.004, abs=0.0006)
    assert E.tle_fit([1000.0, 1000.0, 1000.0], [1.0, 2.0, 3.0]) is None  # one range: no slope


def test_coverage_says_honest_for_honest_sigmas_and_optimistic_for_halved_ones():
    rng = np.random.default_rng(11)
    n = 4000
    se, sn, rho, su = rng.uniform(2, 8, n), rng.uniform(2, 8, n), rng.uniform(-0.6, 0.6, n), rng.uniform(1, 5, n)
    z1, z2 = rng.standard_normal((2, n))
    e = se * z1
    nn = sn * (rho * z1 + np.sqrt(1 - rho**2) * z2)
    enu = np.c_[e, nn, su * rng.standard_normal(n)]
    c = E.coverage(enu, se, sn, rho, su)
    for name, (p, obs, lo, hi, _) in c.circles.items():
        assert c.verdict(obs, lo, hi, p) == "honest", (name, obs)
    assert np.all(np.abs(c.observed - c.nominal) < 0.03)
    assert c.scale == pytest.approx(1.0, abs=0.03)
    d = E.coverage(enu, se / 2, sn / 2, rho, su / 2)
    p, obs, lo, hi, _ = d.circles["CE90"]
    assert obs < 0.6 and d.verdict(obs, lo, hi, p).startswith("optimistic") and d.scale == pytest.approx(2, rel=0.05)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-500, 500), st.floats(-500, 500), st.floats(-100, 100)), min_size=2,
                max_size=40), st.floats(0, 2 * np.pi))
def test_statistics_invariants(errors, angle):
    """Turning the errors about the vertical changes no radial statistic; CEP <= CE90 <= max;
    MAE <= RMSE; the bias is the mean."""
    enu = np.array(errors, dtype=np.float64)
    s = E.statistics(enu[:, :2], enu[:, 2])
    c, si = np.cos(angle), np.sin(angle)
    turned = np.c_[c * enu[:, 0] - si * enu[:, 1], si * enu[:, 0] + c * enu[:, 1]]
    t = E.statistics(turned, enu[:, 2])
    for k in ("cep50_m", "ce90_m", "mae_h_m", "rmse_h_m", "max_h_m"):
        assert t[k] == pytest.approx(s[k], abs=1e-9, rel=1e-9)
    assert s["cep50_m"] <= s["ce90_m"] + 1e-9 <= s["max_h_m"] + 2e-9
    assert s["mae_h_m"] <= s["rmse_h_m"] + 1e-9 and s["mae_v_m"] <= s["rmse_v_m"] + 1e-9
    assert s["bias_e_m"] == pytest.approx(enu[:, 0].mean(), abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-500, 500), st.floats(-500, 500), st.floats(-100, 100)), min_size=1,
                max_size=40), st.integers(0, 2**32 - 1), st.integers(1, 9))
def test_bootstrap_counts_give_the_statistics_of_the_resampled_copies(errors, seed, b):
    """The bootstrap holds each resample as counts per value; its quantiles, means and maximum are
    those of :func:`statistics` on the same resample written out value by value (np.repeat)."""
    enu = np.array(errors, dtype=np.float64)
    en, up = enu[:, :2], enu[:, 2]
    reps = E.bootstrap_statistics(en, up, n_boot=b, seed=seed, max_elements=len(en) * 3)
    rng = np.random.default_rng(seed)
    order_h, order_v = np.argsort(np.hypot(en[:, 0], en[:, 1])), np.argsort(np.abs(up))
    for start in range(0, b, 3):  # the batches the function drew, in its order: horizontal, then vertical
        k = min(3, b - start)
        ch, cv = E.resample_counts(rng, len(en), k), E.resample_counts(rng, len(up), k)
        for i in range(k):
            copy_en = np.repeat(en[order_h], ch[i].astype(int), axis=0)
            copy_up = np.repeat(up[order_v], cv[i].astype(int))
            ref = E.statistics(copy_en, copy_up)
            for name, value in ref.items():
                assert reps[name][start + i] == pytest.approx(value, abs=1e-9, rel=1e-12), name


def test_every_format_eoloc_writes_reads_back(tmp_path):
    """Fixes written as CSV, GeoJSON, KML (MSL heights) and a CoT data package come back with the
    same positions: < 1e-8° and < 1 cm (CoT carries hae to the centimetre), ids and sigmas intact."""
    lat = np.array([40.2549, 40.2537, 40.2483])
    lon = np.array([-105.616, -105.5927, -105.6053])
    h = np.array([4298.38, 3895.58, 4194.15])
    rec = Records({"target_id": np.array(["A", "B", "C"], dtype=object), "lat_deg": lat, "lon_deg": lon, "h_m": h,
                   "range_m": np.array([9000.0, 8500.0, 8700.0]), "status": np.array(["OK"] * 3, dtype=object),
                   "sigma_e_m": np.array([3.0, 4.0, 5.0]), "sigma_n_m": np.array([3.0, 4.0, 5.0]),
                   "sigma_u_m": np.array([1.0, 2.0, 3.0])})
    paths = write_layer(tmp_path, "fixes", rec, ["csv", "geojson", "kml", "cot"])
    assert len(paths) == 4
    for p in paths:
        pts = read_points(p)
        assert len(pts) == 3, p
        np.testing.assert_allclose(pts.lat_deg, lat, atol=1e-8)
        np.testing.assert_allclose(pts.lon_deg, lon, atol=1e-8)
        np.testing.assert_allclose(pts.h_m, h, atol=0.006 if p.suffix == ".zip" else 1e-3)
        ids = pts.column("callsign") if p.suffix == ".zip" else pts.column("target_id")
        assert list(ids) == ["A", "B", "C"], p
        np.testing.assert_allclose(pts.numeric("sigma_u_m"), [1.0, 2.0, 3.0], atol=0.01)


def test_failed_fixes_are_counted_not_reported(tmp_path):
    p = _write_csv(tmp_path / "fixes.csv", ["target_id", "lat_deg", "lon_deg", "h_m", "status"],
                   [("A", 40.0, -105.0, 4000.0, "OK"), ("B", "", "", "", "NO_INTERSECTION"),
                    ("C", "", "", "", "OK"), ("D", "north", -105.0, 4000.0, "OK")])
    pts = read_points(p)
    assert len(pts) == 1 and pts.not_located == {"NO_INTERSECTION": 1}
    text = " | ".join(str(i) for i in pts.issues)
    assert "fixes.csv:4: no position" in text and "fixes.csv:5" in text and "'north' is not a number" in text


def test_kml_absolute_heights_are_msl_and_come_back_ellipsoidal(tmp_path):
    from eoloc.terrain.geoid import default_geoid

    n = float(default_geoid().undulation(40.25, -105.6))
    kml = tmp_path / "gcps.kml"
    kml.write_text("""<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document>
<Placemark><name>P1</name><Point><altitudeMode>absolute</altitudeMode>
<coordinates>-105.6,40.25,3000.0</coordinates></Point></Placemark>
<Placemark><name>P2</name><Point><coordinates>-105.61,40.26,0</coordinates></Point></Placemark>
<Placemark><name>path</name><LineString><coordinates>-105.6,40.25 -105.61,40.26</coordinates></LineString>
</Placemark></Document></kml>""", encoding="utf-8")
    pts = read_points(kml)
    assert list(pts.column("name")) == ["P1", "P2"]
    assert pts.h_m[0] == pytest.approx(3000.0 + n, abs=1e-6) and np.isnan(pts.h_m[1])
    assert "not a point" in str(pts.issues[0])


def test_evaluate_on_the_demo_klv_fixes_with_their_covariance(tmp_path):
    """The demo's KLV fixes (with eoloc's covariance) against the surveyed summits: matched by
    nearest, and the coverage table is there."""
    demo = ROOT / "src" / "eoloc" / "data" / "demo" / "mountain"
    out = tmp_path / "klv"
    r = CliRunner().invoke(main, ["klv", str(demo / "flight.klv"), "--dem", str(demo / "longs_peak_srtmgl3.tif"),
                                  "--config", str(demo / "klv.toml"), "--out", str(out)])
    assert r.exit_code == 0, r.output
    ev = evaluate_job(out / "fixes.csv", demo / "truth.csv", n_boot=200)
    assert ev.match == "nearest" and ev.overall.n >= 50
    assert ev.coverage is not None and ev.coverage.n == ev.overall.n
    assert "range_m" in ev.factors and ev.tle["all"] is not None


def test_named_columns_win_over_eolocs_and_blank_ids_match_nothing(tmp_path):
    """--fix-columns picks the named columns even when the file also has lat_deg/lon_deg; a fix
    without an id is unmatched, never paired with a truth point that has none either."""
    p = _write_csv(tmp_path / "both.csv", ["lat_deg", "lon_deg", "Lat2", "Lon2", "id"],
                   [(0.0, 0.0, 46.52, 7.41, "G1"), (0.0, 0.0, 46.5213, 7.4125, "")])
    pts = read_points(p, columns=("Lat2", "Lon2"))
    np.testing.assert_allclose(pts.lat_deg, [46.52, 46.5213])
    assert np.isnan(pts.h_m).all()
    m = E.match_ids(pts.column("id"), np.array(["G1", "", "G2"], dtype=object))
    assert m.index.tolist() == [0, -1]
