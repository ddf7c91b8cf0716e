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

import eoloc
from eoloc.cli import main
from eoloc.io.klv.synthetic import circling_flight_klv, write_circling_flights
from eoloc.jobs.batch import LAYERS

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
KLV = Path(__file__).parent / "data" / "klv"


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
