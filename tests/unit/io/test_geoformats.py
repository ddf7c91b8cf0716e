"""The formats GIS people use: GeoParquet (read back by geopandas and by DuckDB's spatial
extension), GeoPackage (GDAL through geopandas/pyogrio), MGRS and UTM columns (the mgrs package's
GeoTrans conversion against pyproj's UTM, both ways)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import eoloc
from eoloc.cli import main
from eoloc.io.gridref import mgrs_column, utm_columns, utm_zone_numbers
from eoloc.io.records import Records
from eoloc.io.writers import write_layer

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"


@pytest.fixture(scope="module")
def located(tmp_path_factory):
    out = tmp_path_factory.mktemp("geo")
    r = CliRunner().invoke(main, ["locate", str(MOUNTAIN / "telemetry.csv"), str(MOUNTAIN / "detections.csv"),
                                  "--config", str(MOUNTAIN / "camera.toml"), "--target-height", "3600", "--out",
                                  str(out), "-f", "csv", "-f", "geoparquet", "-f", "gpkg", "--grid", "mgrs",
                                  "--grid", "utm"])
    assert r.exit_code == 0, r.output
    with (out / "fixes.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert {x["status"] for x in rows} >= {"OK"}
    return out, rows


def _expected(rows):
    ok = [x for x in rows if x["status"] == "OK"]
    return np.array([[float(x["lon_deg"]), float(x["lat_deg"]), float(x["h_m"])] for x in ok])


def test_geoparquet_reads_back_in_geopandas_with_points_and_crs(located):
    import geopandas as gpd

    out, rows = located
    df = gpd.read_parquet(out / "fixes.parquet")
    assert len(df) == len(rows)
    assert df.crs.to_epsg() == 4979
    ok = (df["status"] == "OK").to_numpy()
    got = np.c_[df.geometry[ok].x, df.geometry[ok].y, df.geometry[ok].z]
    np.testing.assert_allclose(got, _expected(rows), atol=1e-8)  # the CSV's 9 decimals
    assert df.geometry[~ok].isna().all()  # failed fixes: rows kept, no geometry
    assert list(df["target_id"][:2]) == [rows[0]["target_id"], rows[1]["target_id"]]
    assert df["mgrs"].iloc[0] == rows[0]["mgrs"]
    import pyarrow.parquet as pq

    geo = json.loads(pq.read_schema(out / "fixes.parquet").metadata[b"geo"])
    assert geo["version"] == "1.1.0" and geo["columns"]["geometry"]["geometry_types"] == ["Point Z"]
    bbox = geo["columns"]["geometry"]["bbox"]
    assert bbox[0] == pytest.approx(got[:, 0].min()) and bbox[3] == pytest.approx(got[:, 1].max())


def test_geoparquet_reads_back_in_duckdb_spatial(located):
    import duckdb
    import duckdb_extensions

    out, rows = located
    con = duckdb.connect()
    duckdb_extensions.import_extension("spatial", con=con)
    con.sql("LOAD spatial")
    got = con.sql(f"SELECT ST_X(geometry), ST_Y(geometry), ST_Z(geometry), status, ST_GeometryType(geometry) "
                  f"FROM read_parquet('{out / 'fixes.parquet'}')").fetchall()
    assert len(got) == len(rows)
    ok = np.array([[x, y, z] for x, y, z, s, _ in got if s == "OK"])
    np.testing.assert_allclose(ok, _expected(rows), atol=1e-8)
    assert all(t == "POINT" for *_, s, t in got if s == "OK")
    assert all(x is None for x, *_, s, _t in got if s != "OK")
    crs = con.sql(f"SELECT value FROM parquet_kv_metadata('{out / 'fixes.parquet'}') WHERE key = 'geo'").fetchone()
    assert json.loads(crs[0])["columns"]["geometry"]["crs"]["id"] == {"authority": "EPSG", "code": 4979}


def test_geopackage_reads_back_in_gdal(located):
    import geopandas as gpd
    import pyogrio

    out, rows = located
    info = pyogrio.read_info(out / "fixes.gpkg")
    assert info["geometry_type"] == "Point Z" and info["crs"] == "EPSG:4979" and info["features"] == len(rows)
    df = gpd.read_file(out / "fixes.gpkg")
    ok = (df["status"] == "OK").to_numpy()
    np.testing.assert_allclose(np.c_[df.geometry[ok].x, df.geometry[ok].y, df.geometry[ok].z], _expected(rows),
                               atol=1e-8)


def test_footprint_polygons_as_geoparquet_match_the_geojson(tmp_path):
    import geopandas as gpd
    import shapely

    r = CliRunner().invoke(main, ["footprint", str(MOUNTAIN / "telemetry.csv"), "--config",
                                  str(MOUNTAIN / "camera.toml"), "--target-height", "3600", "--out", str(tmp_path),
                                  "-f", "geojson", "-f", "geoparquet"])
    assert r.exit_code == 0, r.output
    gj = json.loads((tmp_path / "footprints.geojson").read_text(encoding="utf-8"))["features"]
    df = gpd.read_parquet(tmp_path / "footprints.parquet")
    assert len(df) == len(gj)
    for f, g in zip(gj, df.geometry, strict=True):
        if f["geometry"] is None:
            assert g is None
        else:
            assert shapely.equals_exact(shapely.from_geojson(json.dumps(f["geometry"])), g, tolerance=1e-12)


def test_mgrs_and_utm_agree_on_the_demo_fixes(located):
    _, rows = located
    for x in rows:
        if x["status"] != "OK":
            assert x["mgrs"] == "" and x["utm_zone"] == ""
            continue
        assert x["mgrs"][:2] == x["utm_zone"][:-1]
        e, n = float(x["utm_easting_m"]), float(x["utm_northing_m"])
        assert int(x["mgrs"][5:10]) == int(e % 100_000) and int(x["mgrs"][10:]) == int(n % 100_000)


@settings(max_examples=300, deadline=None)
@given(st.floats(-79.9, 83.9), st.floats(-180, 179.999))
def test_mgrs_is_the_utm_position_everywhere(lat, lon):
    """eoloc's MGRS against GeoTrans's (the mgrs package) anywhere in UTM's range, Norway's and
    Svalbard's exceptions included: the same zone, band and 100 km square, and the same metre
    except that GeoTrans rounds where MGRS truncates (eoloc's digits are GeoTrans's or one less;
    GeographicLib's GeoConvert is the exact reference in tests/integration/test_conformance.py).
    Points within 1e-7 degrees of a zone or band edge and within 2 m of a 100 km line are left
    out: there rounding may cross the line."""
    import mgrs

    edges = [*np.arange(-180, 181, 6), 3, 9, 12, 21, 33, 42]
    assume(min(abs(lon - e) for e in edges) > 1e-7 and min(abs(lat - b) for b in (0, 56, 64, 72, 84)) > 1e-7)
    m = mgrs_column(np.array([lat]), np.array([lon]))[0]
    u = utm_columns(np.array([lat]), np.array([lon]))
    e, n = u["utm_easting_m"][0], u["utm_northing_m"][0]
    assume(min(e % 100_000, 100_000 - e % 100_000, n % 100_000, 100_000 - n % 100_000) > 2.0)
    ref = mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
    assert m[:5] == ref[:5] == f"{utm_zone_numbers(np.array([lat]), np.array([lon]))[0]:02d}{m[2:5]}"
    assert int(ref[5:10]) - int(m[5:10]) in (0, 1) and int(ref[10:]) - int(m[10:]) in (0, 1)


def test_a_table_layer_and_a_point_without_height():
    recs = Records({"lat_deg": np.array([40.0, np.nan]), "lon_deg": np.array([-105.0, 1.0]),
                    "status": np.array(["OK", "NO_INTERSECTION"], dtype=object)})
    from eoloc.io.geotable import geo_table

    table, meta = geo_table(recs)
    assert meta["geometry_types"] == ["Point"] and meta["crs"]["id"]["code"] == 4326
    assert table["geometry"].null_count == 1


def test_gpkg_and_geoparquet_through_the_registry(tmp_path):
    recs = Records({"lat_deg": np.array([40.0]), "lon_deg": np.array([-105.0]), "h_m": np.array([3000.0]),
                    "status": np.array(["OK"], dtype=object)})
    paths = write_layer(tmp_path, "x", recs, ["geoparquet", "gpkg"], grid=["utm"])
    assert [p.name for p in paths] == ["x.parquet", "x.gpkg"]
    import geopandas as gpd

    df = gpd.read_file(paths[1])
    # -105° is zone 13's central meridian: the false easting exactly
    assert df["utm_zone"][0] == "13N" and df["utm_easting_m"][0] == pytest.approx(500_000, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_point_wkb_is_shapelys_byte_for_byte(data):
    """The GeoParquet writer's points, built with numpy (`point_wkb`), against shapely's `to_wkb`
    of the same points (Point Z, Point without height, no position: null), and the same metadata
    (geometry types, CRS, bbox)."""
    from eoloc.io.geotable import geo_table, point_geometries

    n = data.draw(st.integers(0, 40))
    coord = st.one_of(st.floats(-180, 180), st.just(float("nan")))
    lon = np.array(data.draw(st.lists(coord, min_size=n, max_size=n)), dtype=float)
    lat = np.array(data.draw(st.lists(st.one_of(st.floats(-90, 90), st.just(float("nan"))), min_size=n,
                                      max_size=n)), dtype=float)
    cols = {"lat_deg": lat, "lon_deg": lon}
    if data.draw(st.booleans()):
        cols["h_m"] = np.array(data.draw(st.lists(st.one_of(st.floats(-1e4, 1e5), st.just(float("nan"))),
                                                  min_size=n, max_size=n)), dtype=float)
    recs = Records(cols)
    ours, meta = geo_table(recs)
    ref, ref_meta = geo_table(recs, point_geometries(recs))  # (an array of shapely points: shapely's to_wkb)
    assert ours.column("geometry").to_pylist() == ref.column("geometry").to_pylist()
    assert meta == ref_meta


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_ring_wkb_is_shapelys_byte_for_byte(data):
    """The archive's footprint polygons, built with numpy (`ring_wkb`), against shapely's `to_wkb`
    of `shapely.polygons` of the same rings, the other rows (an antimeridian MultiPolygon, a 2-D
    polygon, none) through shapely; and the same metadata (geometry types, CRS, bbox)."""
    import shapely
    from shapely.geometry import MultiPolygon, Polygon

    from eoloc.io.geotable import geo_table, ring_wkb

    n = data.draw(st.integers(1, 30))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    ring = np.stack([rng.uniform(-180, 180, (n, 4)), rng.uniform(-90, 90, (n, 4)), rng.uniform(-500, 9000, (n, 4))], -1)
    ring = np.concatenate([ring, ring[:, :1]], axis=1)
    simple = rng.random(n) < 0.7
    pick = rng.integers(0, 3, n)
    others = np.array([None if simple[i] else
                       [None, Polygon([(0, 0), (1, 0), (1, 1)]),
                        MultiPolygon([Polygon([(179, 0, 5), (180, 0, 5), (180, 1, 5)]),
                                      Polygon([(-180, 0, 5), (-179, 0, 5), (-180, 1, 5)])])][pick[i]]
                       for i in range(n)], dtype=object)
    ours = ring_wkb(ring, simple, others)
    geoms = np.where(simple, None, others)
    geoms[simple] = shapely.polygons(ring[simple]) if simple.any() else geoms[simple]
    recs = Records({"frame": np.arange(n)})
    table, meta = geo_table(recs, ours)
    ref, ref_meta = geo_table(recs, geoms)
    assert table.column("geometry").to_pylist() == ref.column("geometry").to_pylist()
    assert meta == ref_meta
    assert ours.drawn == any(g is not None for g in geoms)
