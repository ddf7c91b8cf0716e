"""Telemetry/detection readers, the config file, writers and the `eoloc` command, end to end."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from where import DATA

import eoloc
from eoloc.cli import main
from eoloc.io.config import ConfigError, load_config
from eoloc.io.table import TableError
from eoloc.io.telemetry import match_detections, read_detections, read_telemetry
from eoloc.jobs.tables import locate_tables

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
S13_ARGS = ["--lat", "42", "--lon", "125", "--aircraft-height", "10000", "--yaw", "10", "--pitch", "5", "--roll", "-2",
            "--gimbal", "az-el", "--gimbal-angles", "45", "-75"]


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture
def camera_toml(tmp_path):
    return _write(tmp_path / "cam.toml", '[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 50\npixel_um = 5.5\n'
                                         '[gimbal]\nmodel = "az-el"\n')


# ---------------------------------------------------------------- readers


def test_malformed_lines_are_reported_with_line_numbers_and_the_rest_kept(tmp_path):
    p = _write(tmp_path / "t.csv",
               "# comment line\n"
               "time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg\n"
               "0,42,125,10000,10,5,-2,45,-75\n"
               "1,42,125,10000,10,abc,-2,45,-75\n"      # line 4: bad number -> NaN, kept
               "2,42,125,10000\n"                       # line 5: short -> skipped
               "3,95,125,10000,10,5,-2,45,-75\n"         # line 6: latitude out of range -> NaN, kept
               ",42,125,10000,10,5,-2,45,-75\n"          # line 7: no time -> skipped
               "5,42,125,10000,10,5,-2,45,nan\n"         # line 8: explicit NaN -> reported
               "\n"
               "6,42,125,10000,10,5,-2,45,-75\n")
    t = read_telemetry(p)
    assert t.line.tolist() == [3, 4, 6, 8, 10]
    msgs = {i.line: i.message for i in t.issues}
    assert set(msgs) == {4, 5, 6, 7, 8}
    assert "'abc' is not a number" in msgs[4] and "pitch_deg" in msgs[4]
    assert "fields where the header has" in msgs[5]
    assert "outside [-90, 90]" in msgs[6]
    assert "no usable time_s or frame" in msgs[7]
    assert str(t.issues[0]).startswith(str(p) + ":4: ")
    located = locate_tables(eoloc.SensorModel(eoloc.Camera(1, 1, 1, 1, 0, 0)), t, None, eoloc.AtRange(10_200.0))
    assert located.fixes.status.tolist() == [0, 4, 4, 4, 0]  # bad records end INVALID_INPUT, never a point
    assert np.isnan(located.fixes.lat_deg[1:4]).all()


def test_missing_columns_and_files_are_clear_errors(tmp_path):
    with pytest.raises(TableError, match="does not exist"):
        read_telemetry(tmp_path / "nope.csv")
    p = _write(tmp_path / "t.csv", "time_s,lat_deg,lon_deg\n0,1,2\n")
    with pytest.raises(TableError, match=r"has no height column: give h_m \(ellipsoidal, m\) or h_msl_m"):
        read_telemetry(p)
    with pytest.raises(TableError, match="empty"):
        read_telemetry(_write(tmp_path / "e.csv", "# nothing\n"))


def test_detections_match_by_time_within_tolerance_and_by_frame(tmp_path):
    tel = _write(tmp_path / "t.csv", "time_s,frame,lat,lon,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n"
                 + "".join(f"{i * 0.1:.1f},{i},42,125,1000,0,0,0,0,-90\n" for i in range(10)))
    det = _write(tmp_path / "d.csv", "time_s,target_id,u_px,v_px\n0.31,a,1,1\n0.34,b,1,1\n5.0,c,1,1\n")
    m = match_detections(read_telemetry(tel), read_detections(det), time_tolerance_s=0.02)
    assert m.record.tolist() == [3, -1, -1]
    assert [i.line for i in m.issues] == [3, 4] and "widen --time-tolerance" in m.issues[0].message
    detf = _write(tmp_path / "f.csv", "frame,target_id,u_px,v_px\n7,a,1,1\n42,b,1,1\n")
    m = match_detections(read_telemetry(tel), read_detections(detf))
    assert m.record.tolist() == [7, -1]


# ---------------------------------------------------------------- config


def test_config_validation_names_the_key(tmp_path):
    bad = _write(tmp_path / "c.toml", "[camera]\nwidth = 100\nheight = 0\nfocal_mm = 3\npixel_um = 2\nfoo = 1\n")
    with pytest.raises(ConfigError) as exc:
        load_config(bad)
    assert "camera.height" in str(exc.value) and "camera.foo" in str(exc.value) and str(bad) in str(exc.value)
    with pytest.raises(ConfigError, match="one way"):
        load_config(_write(tmp_path / "d.toml", "[camera]\nwidth = 1\nheight = 1\nfocal_mm = 3\npixel_um = 2\n"
                                                "hfov_deg = 5\n"))
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(_write(tmp_path / "e.toml", "[camera\n"))
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "none.toml")


def test_config_builds_the_sensor(tmp_path):
    cfg = load_config(_write(tmp_path / "c.toml",
                             "[camera]\nwidth = 640\nheight = 512\nhfov_deg = 30\n"
                             '[gimbal]\nmodel = "fixed"\nquaternion = [1, 0, 0, 0]\n'
                             "[installation]\nlever_arm_m = [1, 2, 3]\n"))
    s = cfg.sensor()
    assert s.gimbal.name == "fixed" and s.lever_arm_m == (1.0, 2.0, 3.0)
    assert s.camera.hfov_deg == pytest.approx(30.0)
    assert s.camera.cx == 319.5 and s.camera.cy == 255.5


def test_config_without_a_camera(tmp_path):
    """A config with only [accuracy.budget] (for inputs that bring their camera: KLV, drone photos)
    reads; a command that needs the camera's geometry says so, naming the file; through the CLI
    (eoloc locate) one line, exit 2."""
    path = _write(tmp_path / "b.toml", "[accuracy.budget]\nyaw_deg = {normal = 1.0}\n")
    cfg = load_config(path)
    assert cfg.camera is None and cfg.accuracy.budget == {"yaw_deg": {"normal": 1.0}}
    with pytest.raises(ConfigError, match=r"b\.toml' has no \[camera\] section"):
        cfg.sensor()
    r = CliRunner().invoke(main, ["locate", *S13_ARGS, "--target-height", "400", "--pixel", "100", "700",
                                  "--config", str(path), "--json"])
    assert r.exit_code == 2 and "has no [camera] section" in r.output and "Traceback" not in r.output, r.output


def test_config_distortion_models(tmp_path):
    base = "[camera]\nwidth = 640\nheight = 512\nhfov_deg = 30\n"
    bc = load_config(_write(tmp_path / "b.toml", base + '[camera.distortion]\nmodel = "brown-conrady"\n'
                                                        "k1 = -0.2\np2 = 0.001\n")).sensor().camera.distortion
    assert isinstance(bc, eoloc.BrownConrady) and (bc.k1, bc.p2) == (-0.2, 0.001)
    ratio = load_config(_write(tmp_path / "r.toml", base + '[camera.distortion]\nmodel = "ratio"\n')).sensor()
    cam = ratio.camera
    assert cam.distortion == eoloc.DistortionRatio.for_camera(cam)
    with pytest.raises(ConfigError, match="k1, k2, p1, p2, k3 belong to model = 'brown-conrady'"):
        load_config(_write(tmp_path / "x.toml", base + '[camera.distortion]\nmodel = "ratio"\nk1 = 0.1\n'))
    with pytest.raises(ConfigError, match=r"camera\.distortion\.model"):
        load_config(_write(tmp_path / "y.toml", base + '[camera.distortion]\nmodel = "fisheye"\n'))


# ---------------------------------------------------------------- CLI


def test_cli_one_observation_json_S13():
    r = CliRunner().invoke(main, ["locate", *S13_ARGS, "--range", "10200", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert out["status"] == "OK"
    assert out["lat"] == pytest.approx(42.02058646, abs=1e-7)
    assert out["lon"] == pytest.approx(125.03195512, abs=1e-7)
    assert out["h"] == pytest.approx(419.58, abs=0.01)


def test_cli_one_observation_above_horizon_is_no_intersection():
    args = [a if a != "-75" else "10" for a in S13_ARGS]
    r = CliRunner().invoke(main, ["locate", *args, "--target-height", "0", "--json"])
    assert r.exit_code == 3  # ran, located nothing (`eoloc --help`: exit status)
    assert json.loads(r.stdout) == {"lat": None, "lon": None, "h": None, "range": None, "status": "NO_INTERSECTION"}
    assert "check the pointing" in r.stderr  # the reason and what to do


def test_cli_one_observation_pixel_with_config(camera_toml):
    r = CliRunner().invoke(main, ["locate", *S13_ARGS, "--target-height", "400", "--pixel", "100", "700",
                                  "--config", str(camera_toml), "--json"])
    assert r.exit_code == 0, r.output
    got = json.loads(r.output)
    sensor = load_config(camera_toml).sensor()
    ref = eoloc.locate_ellipsoid(sensor, eoloc.Pose(42, 125, 10000, 10, 5, -2, (45, -75)), 400.0, (100.0, 700.0))
    assert got["lat"] == pytest.approx(float(ref.lat_deg), abs=1e-12)


def test_cli_errors_name_the_fix(camera_toml):
    runner = CliRunner()
    r = runner.invoke(main, ["locate", *S13_ARGS, "--json"])
    assert r.exit_code == 2 and "choose one stop rule" in r.output
    r = runner.invoke(main, ["locate", *S13_ARGS, "--range", "1", "--pixel", "1", "2"])
    assert r.exit_code == 2 and "--pixel needs --config" in r.output
    r = runner.invoke(main, ["locate", "missing.csv", "--config", str(camera_toml), "--range"])
    assert r.exit_code == 2 and "does not exist" in r.output


def test_cli_file_mode_writes_csv_and_geojson(tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"),
                                  "--config", str(DEMO / "camera.toml"), "--target-height", "600", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "telemetry.csv:16" in r.output and "not a number" in r.output  # the demo's malformed line
    with (out / "fixes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 91  # every detection has a row, located or not
    statuses = [row["status"] for row in rows]
    assert statuses.count("OK") == 87 and statuses.count("NO_TELEMETRY") == 1
    gj = json.loads((out / "fixes.geojson").read_text())
    assert gj["type"] == "FeatureCollection" and len(gj["features"]) == 91
    ok = [f for f in gj["features"] if f["properties"]["status"] == "OK"]
    assert all(f["geometry"]["type"] == "Point" and len(f["geometry"]["coordinates"]) == 3 for f in ok)
    assert all(f["geometry"] is None for f in gj["features"] if f["properties"]["status"] != "OK")
    lon, lat, h = ok[0]["geometry"]["coordinates"]
    assert 112.6 < lon < 112.7 and 35.1 < lat < 35.2 and h == pytest.approx(600.0, abs=1e-3)


def test_cli_demo_runs_and_matches_truth_statistically(tmp_path):
    r = CliRunner().invoke(main, ["demo", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    assert "[S13] reference case" in r.output
    with (tmp_path / "fixes_ellipsoid.csv").open() as fh:
        errs = [float(row["error_vs_truth_m"]) for row in csv.DictReader(fh) if row["status"] == "OK"]
    # the demo flight carries [Z15]'s telemetry noise: CEP of the same order as its 28.7 m
    assert 10.0 < float(np.median(errs)) < 50.0
    # the mountain flight: M4 on real SRTM terrain. Off the summits, errors are at the level of the
    # telemetry noise (2 m, 0.03 deg at ~9 km: ~5-10 m); the far hill beyond the DEM has no point.
    with (tmp_path / "fixes_dem.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    lake = [float(r["error_vs_truth_m"]) for r in rows if r["target_id"] == "CHASM_LAKE" and r["status"] == "OK"]
    assert len(lake) == 40 and float(np.median(lake)) < 15.0
    far = [r for r in rows if r["target_id"] == "FAR_HILL"]
    assert len(far) == 5 and all(r["status"] == "OUT_OF_COVERAGE" and r["lat_deg"] == "" for r in far)
    doc = json.loads((tmp_path / "footprints_dem.geojson").read_text())
    assert len(doc["features"]) == 8 and all(f["geometry"]["type"] == "Polygon" for f in doc["features"])


def test_help_explains_units_and_conventions():
    r = CliRunner().invoke(main, ["--help"])
    assert r.exit_code == 0
    for words in ("ellipsoidal", "clockwise from true north", "right wing down", "top-left pixel"):
        assert words in r.output


def test_cli_dem_stop_rule_one_observation_and_errors(tmp_path):
    dem_file = DATA / "dem" / "srtm_ref.tif"
    args = ["locate", "--lat", "39.6", "--lon", "40.4", "--aircraft-height", "6000", "--gimbal", "az-el",
            "--gimbal-angles", "0", "-90", "--dem", str(dem_file), "--json"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    got = json.loads(r.output)
    dem = eoloc.open_dem(dem_file)
    assert got["status"] == "OK" and got["lat"] == pytest.approx(39.6, abs=1e-9)
    assert got["h"] == pytest.approx(float(dem.height(39.6, 40.4)), abs=0.01)  # straight down onto the DEM
    r = CliRunner().invoke(main, [*args[:-1], "--range", "5", "--json"])
    assert r.exit_code == 2 and "choose one stop rule" in r.output
    asc = DATA / "dem" / "SRTMGL3_boulder_front_range.asc"
    r = CliRunner().invoke(main, [*args[:-3], "--dem", str(asc), "--json"])
    assert r.exit_code == 2 and "--dem-crs EPSG:4326" in r.output


def test_cli_file_mode_with_dem(tmp_path):
    # the demo flight over a flat DEM at the targets' height gives the ellipsoid answer
    flat = tmp_path / "flat.tif"
    import rasterio
    from rasterio.transform import from_origin

    with rasterio.open(flat, "w", driver="GTiff", width=50, height=50, count=1, dtype="float64", crs="EPSG:4326",
                       transform=from_origin(112.6, 35.2, 0.004, 0.004)) as out:
        out.write(np.full((50, 50), 600.0), 1)
    out_dir = tmp_path / "out"
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config",
                                  str(DEMO / "camera.toml"), "--dem", str(flat), "--vertical", "ellipsoid",
                                  "--out", str(out_dir)])
    assert r.exit_code == 0, r.output
    with (out_dir / "fixes.csv").open() as fh:
        rows = [row for row in csv.DictReader(fh) if row["status"] == "OK"]
    assert len(rows) == 87 and all(abs(float(row["h_m"]) - 600.0) < 0.01 for row in rows)


def test_cli_footprint_writes_polygons_that_map_back_to_the_image_border(tmp_path):
    out = tmp_path / "fp"
    r = CliRunner().invoke(main, ["footprint", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"),
                                  "--target-height", "600", "--edge-samples", "4", "--out", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "footprints.geojson").read_text())
    tel = read_telemetry(DEMO / "telemetry.csv")
    assert len(doc["features"]) == len(tel)
    statuses = [f["properties"]["status"] for f in doc["features"]]
    assert statuses.count("INVALID_INPUT") == 1 and statuses.count("OK") == len(tel) - 1
    # the first frame's ring, projected back into its camera, is the image border (4 points a side)
    from eoloc.ground.footprint import border_pixels
    from eoloc.io.telemetry import telemetry_pose

    sensor = load_config(DEMO / "camera.toml").sensor()
    ring = np.array(doc["features"][0]["geometry"]["coordinates"][0][:-1])
    p = np.stack(eoloc.geodetic_to_ecef(ring[:, 1], ring[:, 0], ring[:, 2]), -1)
    u, v = sensor.ground_to_image(telemetry_pose(tel, 0), p)
    px = {(round(a, 4), round(b, 4)) for a, b in zip(u, v, strict=True)}
    assert px == {(round(a, 4), round(b, 4)) for a, b in border_pixels(sensor.camera, 4)}
    rows = list(csv.DictReader((out / "footprints.csv").open()))
    assert len(rows) == len(tel) and float(rows[0]["area_m2"]) > 0
    bad = CliRunner().invoke(main, ["footprint", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml")])
    assert bad.exit_code == 2 and "--target-height H" in bad.output


def test_cli_unwritable_output_is_a_message_naming_the_path_not_a_traceback(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder", encoding="utf-8")
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"),
                                  "--target-height", "0", "--out", str(blocker / "out")])
    assert r.exit_code == 2 and str(blocker) in r.output and "Traceback" not in r.output


def test_cli_a_real_bug_keeps_its_traceback_and_asks_for_a_report(monkeypatch):
    def broken(self, sensor, pose, pixels=None):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(eoloc.AtHeight, "locate", broken)
    r = CliRunner().invoke(main, ["locate", "--lat", "45", "--lon", "7", "--aircraft-height", "3000",
                                  "--gimbal-angles", "0", "-45", "--target-height", "100", "--json"])
    assert isinstance(r.exception, ZeroDivisionError) and "bug in eoloc" in r.output


def test_encodings_cost_a_line_or_name_the_fix_never_a_traceback(tmp_path):
    header = "time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg\n"
    good = "0,45,7,3000,0,0,0,0,-45\n"
    latin = tmp_path / "latin1.csv"
    latin.write_bytes((header + "# caf\xe9 in a comment\n" + good + "1,45,7,3000,0,0,0,0,-45 caf\xe9\n"
                       + good.replace("0,", "2,", 1)).encode("latin-1"))
    tel = read_telemetry(latin)
    assert len(tel) == 2 and tel.line.tolist() == [3, 5]  # every good record kept, physical line numbers
    assert [i.line for i in tel.issues] == [4] and "0xE9 is not UTF-8" in tel.issues[0].message
    u16 = tmp_path / "u16.csv"
    u16.write_text(header + good, encoding="utf-16")
    with pytest.raises(TableError, match=r"UTF-16.*save it as UTF-8"):
        read_telemetry(u16)
    huge = tmp_path / "huge.csv"
    huge.write_text(header + good + "1," + "9" * 200_000 + ",7,3000,0,0,0,0,-45\n", encoding="utf-8")
    t = read_telemetry(huge)  # a 200 000-digit latitude costs its cell, not the file
    assert t.line.tolist() == [2, 3] and np.isnan(t.columns["lat_deg"][1])
    assert [(i.line, "is not a finite number" in i.message) for i in t.issues] == [(3, True)]
    conf = tmp_path / "latin1.toml"
    conf.write_bytes("[camera]\nwidth = 10  # caf\xe9\n".encode("latin-1"))
    r = CliRunner().invoke(main, ["locate", str(latin), "--config", str(conf), "--target-height", "0"])
    assert r.exit_code == 2 and "not UTF-8" in r.output and "Traceback" not in r.output


def test_klv_stream_with_nothing_to_draw_writes_no_map_and_says_so(tmp_path):
    # the one-packet ST 0902 example: no aircraft track, footprint or fix a map could show
    packet = DATA / "klv" / "DynamicOnlyMISMMSPacketData.bin"
    r = CliRunner().invoke(main, ["klv", str(packet), "--out", str(tmp_path)])
    assert r.exit_code == 0 and "no map" in r.output and "Traceback" not in r.output
    assert (tmp_path / "telemetry.csv").exists() and not (tmp_path / "map.html").exists()


@pytest.mark.parametrize("bad", [["--angles", "10:5:1"], ["--terrain-sigmas", ""], ["--angles", "nan"]])
def test_sweep_with_an_empty_or_non_finite_list_is_refused(bad):
    r = CliRunner().invoke(main, ["sweep", "--scenario", "q-ellipsoid", *bad])
    assert r.exit_code == 2 and "start:stop:step" in r.output and "Traceback" not in r.output


@pytest.mark.parametrize(("section", "key"), [("[camera.distortion]\nmodel = \"ratio\"\nfield = [0, 0.5, 1]\n",
                                               "d_percent = [0, nan, 2]"),
                                              ("[telemetry]\n", "heading_bias_deg = nan"),
                                              ("[installation]\n", "lever_arm_m = [0, inf, 0]")])
def test_config_refuses_non_finite_numbers_naming_the_key(tmp_path, section, key):
    p = _write(tmp_path / "c.toml", "[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 50\npixel_um = 5.5\n"
               + section + key + "\n")
    with pytest.raises(ConfigError, match="finite number"):
        load_config(p)


def test_a_picture_as_dem_is_named_as_such_with_no_warning_leaked(tmp_path):
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pic = tmp_path / "photo.png"
    plt.imsave(pic, np.random.default_rng(0).random((20, 20)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # rasterio's NotGeoreferencedWarning must not reach the user
        with pytest.raises(eoloc.terrain.DEMError, match="no georeferencing at all: it is not a terrain model"):
            eoloc.open_dem(pic)
    r = CliRunner().invoke(main, ["locate", "--lat", "40", "--lon", "-105", "--aircraft-height", "6000",
                                  "--gimbal-angles", "0", "-45", "--dem", str(pic)])
    assert r.exit_code == 2 and "not a terrain model" in r.output and "assume_crs" not in r.output


def test_a_dem_that_misses_the_flight_is_summed_up_in_one_line(tmp_path):
    dem = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"  # Colorado
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), "--config", str(DEMO / "camera.toml"),
                                  "--dem", str(dem), "--out", str(tmp_path)])  # the demo flight is in Shanxi
    text = " ".join(r.output.split())
    assert r.exit_code == 3 and "nothing was located" in text and "OUT_OF_COVERAGE" in text
    assert "covering lat 40.2008..40.3100" in text


def test_repeated_telemetry_times_are_reported_never_chosen_silently(tmp_path):
    p = _write(tmp_path / "t.csv",
               "time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg\n"
               "0,45,7,3000,0,0,0,0,-45\n"
               "1,45,7,3000,0,0,0,0,-45\n"
               "1,46.26,7,3000,0,0,0,0,-45\n"  # the same time, 140 km north
               "2,45,7,3000,0,0,0,0,-45\n"
               "2,45,7,3000,0,0,0,0,-45\n")  # an exact copy
    t = read_telemetry(p)
    assert t.line.tolist() == [2, 5]  # time 0 and the first time-2 record
    msgs = {i.line: i.message for i in t.issues}
    assert "also at line 3 with another pose: neither record is used" in msgs[4]
    assert "repeats line 5 exactly" in msgs[6]


def test_detections_that_cannot_be_paired_or_are_empty_are_named(tmp_path):
    det_frames = _write(tmp_path / "d.csv", "frame,target_id,u_px,v_px\n1,A,10,10\n")
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(det_frames), "--config",
                                  str(DEMO / "camera.toml"), "--target-height", "0", "--out", str(tmp_path / "o")])
    text = " ".join(r.output.split())
    assert r.exit_code == 2 and "frame only" in text and "time_s only" in text and "nothing to pair" in text
    header_only = _write(tmp_path / "h.csv", "time_s,target_id,u_px,v_px\n")
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(header_only), "--config",
                                  str(DEMO / "camera.toml"), "--target-height", "0", "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2 and "no usable record" in r.output and not (tmp_path / "o2").exists()


def test_many_targets_per_image_share_its_camera_frame_and_get_the_same_fixes(tmp_path):
    """With more detections than telemetry records, each record's camera frame is computed once
    and shared by its targets (pose_index): the fixes are the per-target path's, number for number,
    with a zoomed record, an unusable pose (INVALID_INPUT), an unmatched detection (NO_TELEMETRY)
    and a pixel outside the image (OUT_OF_IMAGE) among them."""
    from eoloc.io.telemetry import telemetry_pose

    rng = np.random.default_rng(5)
    tel_lines = ["time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg,hfov_deg"]
    for k in range(40):
        pitch = "nan" if k == 7 else f"{rng.normal(0, 2):.3f}"
        tel_lines.append(f"{k * 0.1:.1f},{45 + k * 1e-4:.6f},7.0,3000,{rng.uniform(0, 360):.3f},{pitch},"
                         f"{rng.normal(0, 2):.3f},{rng.uniform(-180, 180):.3f},{rng.uniform(-80, -30):.3f},"
                         f"{20 if k == 3 else 40}")
    det_lines = ["time_s,target_id,u_px,v_px"]
    for j in range(400):
        t = 99.0 if j == 11 else rng.integers(0, 40) * 0.1
        u = 5000.0 if j == 12 else rng.uniform(0, 1023)
        det_lines.append(f"{t:.1f},T{j % 9},{u:.3f},{rng.uniform(0, 767):.3f}")
    tel = read_telemetry(_write(tmp_path / "t.csv", "\n".join(tel_lines) + "\n"))
    det = read_detections(_write(tmp_path / "d.csv", "\n".join(det_lines) + "\n"))
    sensor = eoloc.SensorModel(eoloc.Camera(1024, 768, 1200.0, 1200.0, 511.5, 383.5))
    rule = eoloc.AtHeight(250.0)
    shared = locate_tables(sensor, tel, det, rule).fixes
    record = match_detections(tel, det).record
    pose = telemetry_pose(tel, np.where(record >= 0, record, 0), sensor.camera)
    alone = rule.locate(sensor, pose, (det.columns["u_px"], det.columns["v_px"]))
    Status = eoloc.Status
    assert set(shared.status.tolist()) == {Status.OK, Status.INVALID_INPUT, Status.NO_TELEMETRY,
                                           Status.OUT_OF_IMAGE}
    own = record >= 0
    np.testing.assert_array_equal(shared.status[own], alone.status[own])
    for name in ("lat_deg", "lon_deg", "h_m", "range_m"):
        np.testing.assert_array_equal(getattr(shared, name)[own], getattr(alone, name)[own])


@settings(max_examples=150, deadline=None)
@given(tel_frames=st.lists(st.one_of(st.integers(-5, 30).map(float), st.just(np.nan)), min_size=1, max_size=25),
       det_frames=st.lists(st.one_of(st.integers(-8, 35).map(float), st.just(np.nan)), min_size=1, max_size=40))
def test_frame_matching_agrees_with_a_dict_of_frame_numbers(tel_frames, det_frames):
    """Pairing by frame number (vectorised) is what a dict {frame: last record with it} gives:
    duplicated frames go to their last record, unknown and missing frames to -1."""
    from eoloc.io.table import Table

    def table(frames):
        n = len(frames)
        return Table("x.csv", {"frame": np.array(frames, dtype=float), "time_s": np.full(n, np.nan)},
                     np.arange(2, n + 2))

    lookup = {int(f): i for i, f in enumerate(tel_frames) if np.isfinite(f)}
    expected = [lookup.get(int(f), -1) if np.isfinite(f) else -1 for f in det_frames]
    assume(lookup and np.isfinite(det_frames).any())  # else nothing to pair by (a TableError, tested elsewhere)
    got = match_detections(table(tel_frames), table(det_frames))
    assert got.record.tolist() == expected
    assert sorted(i.line for i in got.issues) == [j + 2 for j, r in enumerate(expected) if r < 0]
