"""The many-frames commands end to end: eoloc calibrate (and its write-back), track, triangulate."""

from __future__ import annotations

import csv
import dataclasses
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from where import ROOT

from eoloc import AzElGimbal, Camera, SensorModel, geodesy
from eoloc.cli import main
from eoloc.io.config import ConfigError, load_config, write_calibration
from eoloc.sequence import TelemetryNoise, synthetic_flight
from eoloc.sequence.simulate import gcp_flight

DEMO = ROOT / "src" / "eoloc" / "data" / "demo"
CONFIG = """# calibration test camera ([Z15] Table 1 lens)
[camera]
width = 1024
height = 768
focal_mm = 50.0   # lens
pixel_um = 5.5

[installation]
# filled in by eoloc calibrate --write
mount_misalignment_deg = [0.0, 0.0, 0.0]
"""
TEL_HEADER = ["time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "azimuth_deg",
              "elevation_deg"]


def _write_rows(path: Path, header: list[str], rows) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([x if isinstance(x, str) else f"{x:.10f}" for x in r])
    return path


def _telemetry_rows(t, pose):
    return zip(t, *(np.ravel(getattr(pose, k)) for k in ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg",
                                                          "roll_deg")), *(np.ravel(g) for g in pose.gimbal_deg),
               strict=True)


JIT = {"lat_deg": 5e-7, "lon_deg": 5e-7, "h_m": 0.1, "yaw_deg": 0.005, "pitch_deg": 0.005, "roll_deg": 0.005,
       "gimbal1_deg": 0.003, "gimbal2_deg": 0.003, "u_px": 0.5, "v_px": 0.5}


def _gcp_files(tmp_path, pick=None):
    """A GCP flight of the demo camera with a (0.3, 0.2, 0.5) deg mount misalignment: the
    telemetry CSV, the GCP observations CSV (all, or the rows ``pick`` gives) and the flight."""
    nominal = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())
    true = dataclasses.replace(nominal, mount_misalignment_deg=(0.3, 0.2, 0.5))
    g = gcp_flight(true, 20, noise=TelemetryNoise(white=JIT), seed=7, heading_bias_deg=0.0)
    tel = _write_rows(tmp_path / "tel.csv", TEL_HEADER, _telemetry_rows(g.tel_time_s, g.tel_pose))
    rows = [(t, f"G{i}", *px, *llh) for i, (t, px, llh) in enumerate(zip(g.obs_time_s, g.pixels, g.gcp_llh,
                                                                        strict=True))]
    gcps = _write_rows(tmp_path / "gcps.csv", ["time_s", "gcp_id", "u_px", "v_px", "lat_deg", "lon_deg", "h_m"],
                       rows if pick is None else pick(rows))
    return tel, gcps, g


def test_calibrate_cli_writes_the_config_and_locate_uses_it(tmp_path):
    tel, gcps, g = _gcp_files(tmp_path)
    cfg = tmp_path / "camera.toml"
    cfg.write_text(CONFIG)
    r = CliRunner().invoke(main, ["calibrate", str(tel), str(gcps), "--config", str(cfg), "--pixel-sigma", "0.5",
                                  "--write", "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert "mount_z_deg" in r.output and "residuals" in r.output
    text = cfg.read_text()
    assert "# filled in by eoloc calibrate --write" in text and "focal_mm = 50.0   # lens" in text  # comments kept
    mount = tomllib.loads(text)["installation"]["mount_misalignment_deg"]
    np.testing.assert_allclose(mount, [0.3, 0.2, 0.5], atol=0.01)
    report = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert report["rms_ground_m_after"] < report["rms_ground_m_before"] / 10
    with (tmp_path / "out" / "gcp_residuals.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 20
    # the calibrated config is what every later command uses: the GCPs located by M3 now land on them
    errs = {}
    for name, conf in (("before", tmp_path / "nominal.toml"), ("after", cfg)):
        if name == "before":
            conf.write_text(CONFIG)
        out = tmp_path / name
        errs[name] = []
        for i in range(20):  # each GCP at its own height
            one = _write_rows(tmp_path / "one.csv", ["time_s", "target_id", "u_px", "v_px"],
                              [(g.obs_time_s[i], f"G{i}", *g.pixels[i])])
            r = CliRunner().invoke(main, ["locate", str(tel), str(one), "--config", str(conf), "--target-height",
                                          str(g.gcp_llh[i, 2]), "--out", str(out)])
            assert r.exit_code == 0, r.output
            with (out / "fixes.csv").open() as fh:
                row = next(csv.DictReader(fh))
            assert row["status"] == "OK", (row, r.output)
            p = np.array(geodesy.geodetic_to_ecef(float(row["lat_deg"]), float(row["lon_deg"]), float(row["h_m"])))
            q = np.array(geodesy.geodetic_to_ecef(*g.gcp_llh[i]))
            errs[name].append(np.linalg.norm(p - q))
    assert np.sqrt(np.mean(np.square(errs["before"]))) > 10.0
    assert np.sqrt(np.mean(np.square(errs["after"]))) < 1.0


def test_write_calibration_refuses_an_invalid_result_and_adds_a_telemetry_section(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(CONFIG)
    write_calibration(cfg, heading_bias_deg=0.25, time_offset_s=-0.04)
    c = load_config(cfg)
    assert c.telemetry.heading_bias_deg == 0.25 and c.telemetry.time_offset_s == -0.04
    with pytest.raises(ConfigError, match="left unchanged"):
        write_calibration(cfg, mount_misalignment_deg=[0.1, float("nan"), 0.0])
    assert load_config(cfg).telemetry.heading_bias_deg == 0.25


def test_track_cli_associates_moving_targets_into_geojson_linestrings(tmp_path):
    sensor = SensorModel(Camera.from_focal_mm(73.6, 5.5, 1024, 768), AzElGimbal())
    vel = [(8.0, 3.0), (-12.0, 5.0), (0.0, -20.0)]
    fl = synthetic_flight(sensor, centre=(42.6, 120.9, 226.0), targets_px=[(453, 342), (476, 251), (504, 213)],
                          velocity_enu_mps=vel, height_agl_m=2279.0, ground_range_m=2300.0, bearing_deg=190.0,
                          heading_deg=350.2, pitch_deg=2.0, roll_deg=-1.8, speed_mps=50.0, duration_s=6.0, fps=10.0,
                          noise=TelemetryNoise(white={**JIT, "u_px": 1.0, "v_px": 1.0}), seed=3)
    tel = _write_rows(tmp_path / "tel.csv", TEL_HEADER, _telemetry_rows(fl.time_s, fl.pose_measured))
    rows = [(t, "?", *fl.pixels_measured[k, j]) for k, t in enumerate(fl.time_s) for j in range(3)]
    det = _write_rows(tmp_path / "det.csv", ["time_s", "target_id", "u_px", "v_px"], rows)
    cam = tmp_path / "cam.toml"
    cam.write_text("[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 73.6\npixel_um = 5.5\n")
    r = CliRunner().invoke(main, ["track", str(tel), str(det), "--config", str(cam), "--target-height", "226",
                                  "--associate", "--meas-sigma", "3", "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert "3 tracks" in r.output
    feats = json.loads((tmp_path / "out" / "tracks.geojson").read_text())["features"]
    assert len(feats) == 3 and all(f["geometry"]["type"] == "LineString" for f in feats)
    speeds = sorted(f["properties"]["speed_mps"] for f in feats)
    np.testing.assert_allclose(speeds, sorted(np.hypot(*np.array(vel).T)), atol=0.5)
    with (tmp_path / "out" / "track_fixes.csv").open() as fh:
        got = list(csv.DictReader(fh))
    assert len(got) == len(rows) and all(row["track_id"].startswith("T") for row in got)
    # each track's first row: position only; its speed and its sigma are unknown (empty), not 0
    for tid in {row["track_id"] for row in got}:
        first = next(row for row in got if row["track_id"] == tid)
        assert first["speed_sigma_mps"] in ("", "nan") and first["speed_mps"] in ("", "nan")
    later = [row for row in got if row["speed_sigma_mps"] not in ("", "nan")]
    assert later and all(float(row["speed_sigma_mps"]) > 0 for row in later)


def test_track_static_and_triangulate_on_the_demo(tmp_path):
    truth = {r["target_id"]: r for r in csv.DictReader((DEMO / "truth.csv").open())}
    args = [str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config", str(DEMO / "camera.toml")]
    r = CliRunner().invoke(main, ["track", *args, "--target-height", "600", "--static", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    r2 = CliRunner().invoke(main, ["triangulate", *args, "--ray-sigma-deg", "1", "--out", str(tmp_path)])
    assert r2.exit_code == 0, r2.output
    for name, limit in (("static_targets.csv", 20.0), ("triangulated.csv", 20.0)):
        with (tmp_path / name).open() as fh:
            rows = list(csv.DictReader(fh))
        assert [row["target_id"] for row in rows] == ["T1", "T2", "T3"]
        for row in rows:
            t = truth[row["target_id"]]
            d = np.hypot((float(row["lat_deg"]) - float(t["lat_deg"])) * 111_000,
                         (float(row["lon_deg"]) - float(t["lon_deg"])) * 91_000)
            assert d < limit  # single frames: ~28 m CEP50
            assert d < 3.5 * np.hypot(float(row["sigma_e_m"]), float(row["sigma_n_m"]))
    r3 = CliRunner().invoke(main, ["track", *args, "--range", "--out", str(tmp_path)])
    assert r3.exit_code == 2 and "nothing was located" in r3.output and "--range R" in r3.output


def test_calibrate_with_undetermined_parameters_names_them_and_refuses_to_write(tmp_path):
    # one GCP observed three times from the same pose: six equations, but only two independent ones
    # for three mount angles
    tel, gcps, _ = _gcp_files(tmp_path, lambda rows: [(rows[0][0], f"G{k}", *rows[0][2:]) for k in range(3)])
    cfg = tmp_path / "camera.toml"
    cfg.write_text(CONFIG)
    r = CliRunner().invoke(main, ["calibrate", str(tel), str(gcps), "--config", str(cfg), "--write",
                                  "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "do not determine" in r.output and "Traceback" not in r.output
    assert cfg.read_text() == CONFIG  # nothing written
    text = (tmp_path / "out" / "calibration.json").read_text()

    def no_constants(name):
        raise AssertionError(f"{name} in calibration.json is not JSON")

    report = json.loads(text, parse_constant=no_constants)  # NaN / Infinity would be refused
    assert report["undetermined"] and set(report["undetermined"]) <= {"mount_x_deg", "mount_y_deg", "mount_z_deg"}
    assert all(report["sigma"][k] is None for k in report["undetermined"])


def test_track_static_on_moving_targets_flags_them_and_inflates_the_uncertainty(tmp_path):
    sensor = SensorModel(Camera.from_focal_mm(73.6, 5.5, 1024, 768), AzElGimbal())
    vel = [(0.0, 0.0), (-12.0, 5.0)]  # T0 stands still, T1 drives at 13 m/s
    fl = synthetic_flight(sensor, centre=(42.6, 120.9, 226.0), targets_px=[(453, 342), (476, 251)],
                          velocity_enu_mps=vel, height_agl_m=2279.0, ground_range_m=2300.0, bearing_deg=190.0,
                          heading_deg=350.2, pitch_deg=2.0, roll_deg=-1.8, speed_mps=50.0, duration_s=6.0, fps=10.0,
                          noise=TelemetryNoise(white={**JIT, "u_px": 1.0, "v_px": 1.0}), seed=3)
    tel = _write_rows(tmp_path / "tel.csv", TEL_HEADER, _telemetry_rows(fl.time_s, fl.pose_measured))
    rows = [(t, f"T{j}", *fl.pixels_measured[k, j]) for k, t in enumerate(fl.time_s) for j in range(2)]
    det = _write_rows(tmp_path / "det.csv", ["time_s", "target_id", "u_px", "v_px"], rows)
    cam = tmp_path / "cam.toml"
    cam.write_text("[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 73.6\npixel_um = 5.5\n")
    r = CliRunner().invoke(main, ["track", str(tel), str(det), "--config", str(cam), "--target-height", "226",
                                  "--static", "--meas-sigma", "3", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    got = {row["target_id"]: row for row in csv.DictReader((tmp_path / "static_targets.csv").open())}
    assert not got["T0"]["warning"] and float(got["T0"]["scatter_ratio"]) < 3
    moving = got["T1"]
    assert float(moving["scatter_ratio"]) > 3 and "target moves" in moving["warning"]
    # the inflated CEP50 is of the size of the path it drove (13 m/s over 6 s ~ 78 m), not a few metres
    assert float(moving["cep50_m"]) > 10.0 and "target T1" in " ".join(r.output.split())
