"""`eoloc batch` on a folder of recordings: the bundled KLV files, generated ones, a telemetry CSV
pair and a broken file; here and on a 2-worker Dask LocalCluster (the same partitions, byte for
byte in content); resumed (done files skipped, a changed file redone); the GeoParquet datasets
read back by geopandas and DuckDB."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from where import DATA

import eoloc
from eoloc.cli import main
from eoloc.io.klv.synthetic import circling_flight_klv, write_circling_flights
from eoloc.jobs.batch import LAYERS

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
KLV = DATA / "klv"


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    root = tmp_path_factory.mktemp("archive")
    shutil.copy(MOUNTAIN / "flight.klv", root / "mountain.klv")
    for name in ("realflight.bin", "eg0104_jmisb_example.bin"):
        shutil.copy(KLV / name, root / name)
    write_circling_flights(root / "generated", 3, 40, seed=7)
    shutil.copy(MOUNTAIN / "telemetry.csv", root / "generated" / "m_telemetry.csv")
    shutil.copy(MOUNTAIN / "detections.csv", root / "generated" / "m_detections.csv")
    (root / "broken.ts").write_bytes(b"not a transport stream at all" * 10)
    return root


def _run(args):
    r = CliRunner().invoke(main, ["batch", *map(str, args)])
    assert "Traceback" not in r.output, r.output
    return r


def _status(out: Path) -> dict[str, dict]:
    with (out / "batch_status.csv").open(encoding="utf-8") as fh:
        return {Path(r["path"]).name: r for r in csv.DictReader(fh)}


def _common(archive, out):
    return [archive, "--out", out, "--config", MOUNTAIN / "camera.toml", "--target-height", "3600"]


@pytest.fixture(scope="module")
def local_run(archive, tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    r = _run(_common(archive, out))
    assert r.exit_code == 2, r.output  # the broken file failed; every other one done
    return out, r


def test_every_good_file_is_done_and_the_bad_one_named(local_run):
    out, r = local_run
    st = _status(out)
    assert st["broken.ts"]["status"] == "failed" and "no MISB ST 0601 packet found" in st["broken.ts"]["message"]
    done = {k for k, v in st.items() if v["status"] == "done"}
    assert done == {"mountain.klv", "realflight.bin", "eg0104_jmisb_example.bin", "flight_000.klv",
                    "flight_001.klv", "flight_002.klv", "m_telemetry.csv"}
    assert int(st["flight_000.klv"]["packets"]) == 40 and int(st["flight_000.klv"]["fixes_ok"]) == 200
    assert int(st["mountain.klv"]["issues"]) >= 1  # its corrupted packet, named
    issues = pq.read_table(next((out / "issues").glob("file=mountain-*/part-0.parquet"))).to_pylist()
    assert any("packet 17" in x["message"] or "checksum" in x["message"] for x in issues), issues


def test_the_datasets_read_back_in_geopandas_and_duckdb(local_run):
    import duckdb
    import duckdb_extensions
    import geopandas as gpd

    out, _ = local_run
    st = _status(out)
    fixes = gpd.read_parquet(out / "fixes")
    assert fixes.crs.to_epsg() == 4979
    assert len(fixes) == sum(int(v["fixes"]) for v in st.values())
    ok = fixes[fixes["status"] == "OK"]
    np.testing.assert_allclose(ok.geometry.x, ok["lon_deg"], atol=0)
    np.testing.assert_allclose(ok.geometry.z, ok["h_m"], atol=0)
    prints = gpd.read_parquet(out / "footprints")
    assert set(prints.geometry.dropna().geom_type) == {"Polygon"}
    con = duckdb.connect()
    duckdb_extensions.import_extension("spatial", con=con)
    con.sql("LOAD spatial")
    got = dict(con.sql(f"SELECT source_file, count(*) FROM read_parquet('{out}/fixes/*/*.parquet', "
                       "hive_partitioning = true) WHERE ST_GeometryType(geometry) = 'POINT' GROUP BY source_file"
                       ).fetchall())
    assert {Path(k).name: v for k, v in got.items()} == {k: int(v["fixes_ok"]) for k, v in st.items()
                                                         if int(v["fixes_ok"])}


def test_a_2_worker_dask_cluster_gives_the_same_partitions(archive, local_run, tmp_path):
    out, _ = local_run
    r = _run([*_common(archive, tmp_path), "--dask", "local:2"])
    assert r.exit_code == 2, r.output
    a = sorted(p.relative_to(out) for layer in LAYERS for p in (out / layer).rglob("*.parquet"))
    b = sorted(p.relative_to(tmp_path) for layer in LAYERS for p in (tmp_path / layer).rglob("*.parquet"))
    assert a == b and len(a) >= 20
    for rel in a:
        assert pq.read_table(out / rel).equals(pq.read_table(tmp_path / rel)), rel


def test_resume_skips_what_is_done_and_redoes_a_changed_file(archive, tmp_path):
    work = tmp_path / "a"
    shutil.copytree(archive, work)
    out = tmp_path / "out"
    _run(_common(work, out))
    r = _run(_common(work, out))
    st = _status(out)
    assert {v["status"] for k, v in st.items() if k != "broken.ts"} == {"skipped"}
    assert st["broken.ts"]["status"] == "failed"  # failures are tried again
    assert "already done with these settings were skipped" in r.output
    changed = work / "generated" / "flight_001.klv"
    changed.write_bytes(circling_flight_klv(25, seed=99))
    _run(_common(work, out))
    st = _status(out)
    assert st["flight_001.klv"]["status"] == "done" and int(st["flight_001.klv"]["packets"]) == 25
    assert st["flight_000.klv"]["status"] == "skipped"
    part = next((out / "packets").glob("file=flight_001-*/part-0.parquet"))
    assert pq.read_table(part).num_rows == 25
    r = _run([*_common(work, out), "--redo"])
    assert {v["status"] for k, v in _status(out).items() if k != "broken.ts"} == {"done"}


def test_nothing_to_do_is_a_clear_message(tmp_path):
    r = _run([tmp_path / "nothing-here", "--out", tmp_path / "o"])
    assert r.exit_code == 2 and "no KLV stream" in r.output and "nothing-here" in r.output


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_the_archives_footprint_table_is_the_footprint_features(data):
    """`eoloc batch` builds the corner footprints as a table in vectorised calls
    (`corner_footprint_table`); they are the GeoJSON features `eoloc klv` writes, polygon for
    polygon (the same vertices, counter-clockwise by pyproj's geodesic area, cut at the
    antimeridian), for footprints anywhere: small and large, across +-180, near the poles,
    degenerate, with missing corners; and the properties are the same columns."""
    import shapely
    from pyproj import Geod
    from shapely.geometry import shape

    from eoloc.io.records import Records
    from eoloc.io.table import Table
    from eoloc.jobs.klvframes import corner_footprint_features, corner_footprint_table

    n = data.draw(st.integers(1, 30))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    lat0 = rng.choice([rng.uniform(-60, 60, n), rng.uniform(-89.9, 89.9, n)])
    lon0 = rng.choice([rng.uniform(-180, 180, n), rng.choice([-179.99, 179.99], n)])
    size = rng.choice([1e-4, 0.01, 0.5, 5.0, 30.0])
    c = {"time_s": np.where(rng.random(n) < 0.2, np.nan, 1.7e9 + np.arange(n)),
         "fc_h_m": np.where(rng.random(n) < 0.2, np.nan, rng.uniform(-100, 4000, n)),
         "stream": rng.choice(["", "PID 497", "PID 498"], n).astype(str)}
    turn = rng.choice([-1.0, 1.0], n) * np.pi / 2  # corners round the centre, either way (image borders run
    start = rng.uniform(0, 2 * np.pi, n)              # clockwise on the ground seen from above, or not)
    for k in range(4):
        a = start + k * turn + rng.uniform(-0.3, 0.3, n)
        r = size * rng.uniform(0.5, 1.5, n)
        c[f"corner{k + 1}_lat_deg"] = np.clip(lat0 + r * np.sin(a), -90, 90)
        c[f"corner{k + 1}_lon_deg"] = (lon0 + r * np.cos(a) + 180) % 360 - 180
    c["corner2_lat_deg"] = np.where(rng.random(n) < 0.1, c["corner1_lat_deg"], c["corner2_lat_deg"])  # degenerate
    c["corner3_lon_deg"] = np.where(rng.random(n) < 0.1, np.nan, c["corner3_lon_deg"])  # a corner missing
    tel = Table("t", c, np.arange(n) * 3)
    every = data.draw(st.integers(1, 3))
    feats = corner_footprint_features(tel, None, every=every)
    props, column = corner_footprint_table(tel, None, every=every)
    geoms = column.geometries()
    want = Records.from_rows([f["properties"] for f in feats])
    assert list(props.columns) == list(want.columns)
    for k in want.columns:
        assert props[k].tolist() == want[k].tolist() or np.array_equal(props[k], want[k], equal_nan=True), k
    geod = Geod(ellps="WGS84")
    for i, f, g in zip(range(0, n, every), feats, geoms, strict=True):
        assert (f["geometry"] is None) == (g is None)
        if g is None:
            continue
        assert shapely.equals_exact(g, shape(f["geometry"]), tolerance=1e-9), (f["geometry"], g)
        lon = np.array([c[f"corner{k + 1}_lon_deg"][i] for k in range(4)])
        lat = np.array([c[f"corner{k + 1}_lat_deg"][i] for k in range(4)])
        lon = lon[0] + (lon - lon[0] + 180) % 360 - 180  # (unwrapped across the antimeridian)
        if not shapely.LinearRing(np.column_stack([lon, lat])).is_simple:
            continue  # a ring that crosses itself (a bow-tie) has no orientation to check
        for poly in getattr(g, "geoms", [g]):
            x, y = poly.exterior.coords.xy
            if max(x) - min(x) < 90:  # (a ring round a pole has no inside to point to)
                area, perimeter = geod.polygon_area_perimeter(x, y)  # counter-clockwise (or degenerate: a ring
                assert area >= -1e-3 - 1e-12 * perimeter ** 2            # whose corners meet at a pole: ~0 m^2)
