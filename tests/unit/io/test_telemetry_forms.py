"""Telemetry as users have it: heights above mean sea level, the attitude as a quaternion or a
direction-cosine matrix, a zoom lens's focal length per record.

Each form is written from the mountain demo's HAE/Euler telemetry with independent tools (scipy's
Rotation for the quaternion and the matrix, PROJ's EGM96 grid through the bundled file read by
rasterio for the geoid) and must locate every detection on the real DEM where the original does,
to < 1 mm. The zoom is checked both ways against a camera built with that record's field of view.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import eoloc
from eoloc.cli import main
from eoloc.io.config import load_config
from eoloc.io.table import TableError
from eoloc.io.telemetry import read_telemetry, telemetry_pose
from eoloc.jobs.locate import locate_files
from eoloc.rules import OnDEM
from eoloc.sensor import Camera, Pose
from eoloc.terrain import open_dem
from eoloc.terrain.geoid import default_geoid

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
EULER = ("yaw_deg", "pitch_deg", "roll_deg")


def _table(path: Path) -> tuple[list[str], list[list[str]]]:
    lines = [x for x in path.read_text(encoding="utf-8").splitlines() if x and not x.startswith("#")]
    rows = list(csv.reader(lines))
    return rows[0], rows[1:]


def _write(path: Path, header: list[str], columns: dict[str, np.ndarray | list]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        n = len(next(iter(columns.values())))
        for i in range(n):
            w.writerow([repr(float(columns[h][i])) if not isinstance(columns[h][i], str) else columns[h][i]
                        for h in header])
    return path


@pytest.fixture(scope="module")
def original():
    header, rows = _table(MOUNTAIN / "telemetry.csv")
    cols = {h: np.array([float(r[i]) for r in rows]) for i, h in enumerate(header)}
    return header, cols


@pytest.fixture(scope="module")
def setup():
    cfg = load_config(MOUNTAIN / "camera.toml")
    return cfg, OnDEM(open_dem(MOUNTAIN / "longs_peak_srtmgl3.tif"))


def _ecef(fixes) -> np.ndarray:
    return np.stack(pymap3d.geodetic2ecef(fixes.lat_deg, fixes.lon_deg, fixes.h_m), -1)


def _same_fixes(a, b, tol_m: float = 1e-3) -> None:
    assert (a.status == b.status).all()
    ok = a.ok
    assert ok.sum() > 50
    gap = np.linalg.norm(_ecef(a)[ok] - _ecef(b)[ok], axis=-1)
    assert gap.max() < tol_m, gap.max()


def _locate(cfg, rule, tel: Path):
    return locate_files(cfg, tel, MOUNTAIN / "detections.csv", rule).located.fixes


def test_msl_heights_locate_as_the_ellipsoidal_ones(original, setup, tmp_path):
    header, cols = original
    cfg, rule = setup
    n = default_geoid().undulation(cols["lat_deg"], cols["lon_deg"])
    assert np.all(np.abs(n + 15) < 5)  # EGM96 over the Colorado Front Range is about -15 m
    msl = {**cols, "h_msl_m": cols["h_m"] - n}
    path = _write(tmp_path / "msl.csv", [("h_msl_m" if h == "h_m" else h) for h in header], msl)
    t = read_telemetry(path)
    np.testing.assert_allclose(t.columns["h_m"], cols["h_m"], atol=1e-9)
    _same_fixes(_locate(cfg, rule, MOUNTAIN / "telemetry.csv"), _locate(cfg, rule, path))


@pytest.mark.parametrize("form", ["quaternion", "quaternion, sign flipped", "dcm"])
def test_quaternion_and_dcm_locate_as_the_euler_angles(original, setup, tmp_path, form):
    header, cols = original
    cfg, rule = setup
    rot = Rotation.from_euler("ZYX", np.c_[cols["yaw_deg"], cols["pitch_deg"], cols["roll_deg"]], degrees=True)
    rest = [h for h in header if h not in EULER]
    if form.startswith("quaternion"):
        q = rot.as_quat(scalar_first=True)
        if "flipped" in form:  # q and -q are the same rotation
            q[::2] *= -1
        new = dict(zip(("qw", "qx", "qy", "qz"), q.T, strict=True))
    else:
        R = rot.as_matrix()
        new = {f"dcm_{r + 1}{c + 1}": R[:, r, c] for r in range(3) for c in range(3)}
    path = _write(tmp_path / "att.csv", rest + list(new), {**cols, **new})
    t = read_telemetry(path)
    assert not t.issues
    R_back = Rotation.from_euler("ZYX", np.c_[t.columns["yaw_deg"], t.columns["pitch_deg"], t.columns["roll_deg"]],
                                 degrees=True)
    assert np.degrees((R_back.inv() * rot).magnitude()).max() < 1e-9
    _same_fixes(_locate(cfg, rule, MOUNTAIN / "telemetry.csv"), _locate(cfg, rule, path))


@settings(max_examples=80, deadline=None)
@given(yaw=st.floats(0, 360), pitch=st.floats(-89.9, 89.9), roll=st.floats(-179.9, 179.9))
def test_quaternion_reading_is_the_rotation_scipy_builds(yaw, pitch, roll, tmp_path_factory):
    """Any attitude: the quaternion scipy makes of it is read back as the same rotation."""
    q = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_quat(scalar_first=True)
    path = tmp_path_factory.mktemp("q") / "t.csv"
    path.write_text("time_s,lat_deg,lon_deg,h_m,qw,qx,qy,qz,azimuth_deg,elevation_deg\n"
                    "0,40,-105,3000," + ",".join(repr(float(x)) for x in q) + ",0,-45\n", encoding="utf-8")
    c = read_telemetry(path).columns
    back = Rotation.from_euler("ZYX", [c["yaw_deg"][0], c["pitch_deg"][0], c["roll_deg"][0]], degrees=True)
    assert np.degrees((back.inv() * Rotation.from_quat(q, scalar_first=True)).magnitude()) < 1e-9


@pytest.mark.parametrize("column", ["hfov_deg", "focal_px", "focal_mm"])
def test_a_zoom_lens_per_record_is_the_camera_of_that_field_of_view(original, setup, tmp_path, column, backend):
    """Each record's zoom (field of view, focal px or mm) locates its detections as a camera
    configured with that record's field of view does; the fix projects back onto its pixel."""
    header, cols = original
    cfg, rule = setup
    n = cols["time_s"].size
    hfov = np.linspace(4.0, 40.0, n)  # zooming out through the flight
    cam = cfg.sensor().camera
    fx = (cam.width / 2) / np.tan(np.radians(hfov) / 2)
    pixel_um = 3.45
    values = {"hfov_deg": hfov, "focal_px": fx, "focal_mm": fx * pixel_um / 1e3}[column]
    path = _write(tmp_path / "zoom.csv", [*header, column], {**cols, column: values})
    if column == "focal_mm":
        toml = tmp_path / "camera.toml"
        toml.write_text((MOUNTAIN / "camera.toml").read_text(encoding="utf-8").replace(
            "hfov_deg = 25.0", f"focal_mm = {cam.fx * pixel_um / 1e3!r}\npixel_um = {pixel_um}"), encoding="utf-8")
        cfg = load_config(toml)
    fixes = _locate(cfg, rule, path)
    tel = read_telemetry(path)
    det_header, det_rows = _table(MOUNTAIN / "detections.csv")
    t_det = np.array([float(r[0]) for r in det_rows])
    uv = np.array([[float(r[2]), float(r[3])] for r in det_rows])
    k = np.searchsorted(cols["time_s"], t_det)
    assert np.allclose(cols["time_s"][k], t_det)
    sensor = cfg.sensor()
    ok = fixes.ok
    assert ok.sum() > 50
    for j in np.flatnonzero(ok)[:: max(1, ok.sum() // 25)]:
        zoomed = replace(sensor, camera=Camera.from_hfov(hfov[k[j]], cam.width, cam.height))
        pose = telemetry_pose(tel, k[j], sensor.camera)
        plain = Pose(pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg, pose.roll_deg,
                     pose.gimbal_deg)
        ref = rule.locate(zoomed, plain, uv[j])
        assert np.linalg.norm(_ecef(ref) - _ecef(fixes)[j]) < 1e-3
        u, v = zoomed.ground_to_image(plain, _ecef(fixes)[j])
        assert abs(u - uv[j, 0]) < 1e-6 and abs(v - uv[j, 1]) < 1e-6


def test_bad_attitude_and_zoom_cells_are_named_and_the_rest_kept(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time_s,lat_deg,lon_deg,h_m,qw,qx,qy,qz,hfov_deg,azimuth_deg,elevation_deg\n"
                    "0,40,-105,3000,1,0,0,0,20,0,-45\n"
                    "1,40,-105,3000,2,0,0,0,20,0,-45\n"  # not a unit quaternion
                    "2,40,-105,3000,0.7071,0,0,0.7071,,0,-45\n"  # no zoom value
                    "3,40,-105,3000,0.7071,0,0,0.70711,20,0,-45\n", encoding="utf-8")
    t = read_telemetry(path)
    text = "\n".join(map(str, t.issues))
    assert f"{path}:3: quaternion (qw, qx, qy, qz) has length 2" in text
    assert f"{path}:4:" in text and "hfov_deg" in text
    assert len(t) == 4 and np.isnan(t.columns["yaw_deg"][1]) and t.columns["yaw_deg"][3] == pytest.approx(90, abs=1e-3)
    cam = Camera.from_hfov(20.0, 640, 480)
    pose = telemetry_pose(t, slice(None), cam)
    assert list(pose.invalid()) == [False, True, True, False]


@pytest.mark.parametrize(("body", "says"), [
    ("time_s,lat_deg,lon_deg,h_m,qw,qx,qy\n0,40,-105,3000,1,0,0\n", "quaternion: qz missing"),
    ("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,qw,qx,qy,qz\n0,40,-105,3000,0,0,0,1,0,0,0\n",
     "gives the attitude 2 ways (Euler angles, quaternion)"),
    ("time_s,lat_deg,lon_deg,h_m\n0,40,-105,3000\n", "has no attitude: give exactly one of Euler angles"),
    ("time_s,lat_deg,lon_deg,yaw_deg,pitch_deg,roll_deg\n0,40,-105,0,0,0\n", "no height column: give h_m"),
    ("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,hfov_deg,focal_px\n0,40,-105,3000,0,0,0,20,900\n",
     "gives the focal length twice (hfov_deg, focal_px)"),
])
def test_an_unusable_set_of_columns_is_refused_with_the_fix(tmp_path, body, says):
    path = tmp_path / "t.csv"
    path.write_text(body, encoding="utf-8")
    with pytest.raises(TableError, match=says.replace("(", r"\(").replace(")", r"\)")):
        read_telemetry(path)


def test_dcm_that_is_not_a_rotation_and_msl_that_disagrees_are_named(tmp_path):
    R = Rotation.from_euler("ZYX", [30, 5, -2], degrees=True).as_matrix()
    mirror = R @ np.diag([1, 1, -1])
    head = "time_s,lat_deg,lon_deg,h_m,h_msl_m," + ",".join(f"dcm_{r}{c}" for r in (1, 2, 3) for c in (1, 2, 3))
    n = float(default_geoid().undulation(40.0, -105.0))
    body = [head] + [f"{i},40,-105,3000,{float(3000 - n + (50 if i == 1 else 0))!r},"
                     + ",".join(repr(float(x)) for x in m.ravel()) for i, m in enumerate([R, R, mirror])]
    path = tmp_path / "t.csv"
    path.write_text("\n".join(body) + "\n", encoding="utf-8")
    t = read_telemetry(path)
    text = "\n".join(map(str, t.issues))
    assert f"{path}:4: dcm_11 ... dcm_33 is not a rotation" in text
    assert f"{path}:3: h_m and h_msl_m + geoid (EGM96) differ by 50.0 m" in text
    assert np.isfinite(t.columns["yaw_deg"][:2]).all() and np.isnan(t.columns["yaw_deg"][2])


def test_the_cli_locates_quaternion_msl_zoom_telemetry(original, tmp_path):
    """Through `eoloc locate` as a user runs it: the same OK rows as the original file."""
    header, cols = original
    rot = Rotation.from_euler("ZYX", np.c_[cols["yaw_deg"], cols["pitch_deg"], cols["roll_deg"]], degrees=True)
    q = dict(zip(("qw", "qx", "qy", "qz"), rot.as_quat(scalar_first=True).T, strict=True))
    n = default_geoid().undulation(cols["lat_deg"], cols["lon_deg"])
    new = {**cols, **q, "h_msl_m": cols["h_m"] - n, "hfov_deg": np.full(cols["time_s"].size, 25.0)}
    keep = [h for h in header if h not in (*EULER, "h_m")]
    path = _write(tmp_path / "t.csv", [*keep, "h_msl_m", *q, "hfov_deg"], new)
    outs = []
    for tel in (MOUNTAIN / "telemetry.csv", path):
        out = tmp_path / f"out_{len(outs)}"
        r = CliRunner().invoke(main, ["locate", str(tel), str(MOUNTAIN / "detections.csv"), "--config",
                                      str(MOUNTAIN / "camera.toml"), "--dem", str(MOUNTAIN / "longs_peak_srtmgl3.tif"),
                                      "--out", str(out)])
        assert r.exit_code == 0, r.output
        with (out / "fixes.csv").open(encoding="utf-8") as fh:
            outs.append(list(csv.DictReader(fh)))
    a, b = outs
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert x["status"] == y["status"]
        if x["status"] == "OK":
            pa = pymap3d.geodetic2ecef(float(x["lat_deg"]), float(x["lon_deg"]), float(x["h_m"]))
            pb = pymap3d.geodetic2ecef(float(y["lat_deg"]), float(y["lon_deg"]), float(y["h_m"]))
            assert np.linalg.norm(np.subtract(pa, pb)) < 2e-3  # the CSV's printed precision


def test_a_geoid_named_in_the_config_converts_msl_telemetry(original, tmp_path):
    """[telemetry] msl_geoid (relative to the config file): a grid of N = +30 m everywhere moves
    every located point's aircraft up by exactly the difference to EGM96 there."""
    import rasterio
    from rasterio.transform import from_origin

    header, cols = original
    grid = tmp_path / "grids" / "flat30.tif"
    grid.parent.mkdir()
    with rasterio.open(grid, "w", driver="GTiff", width=360, height=180, count=1, dtype="float32", crs="EPSG:4326",
                       transform=from_origin(-180, 90, 1, 1)) as ds:
        ds.write(np.full((1, 180, 360), 30.0, dtype=np.float32))
    cfg_path = tmp_path / "camera.toml"
    cfg_path.write_text((MOUNTAIN / "camera.toml").read_text(encoding="utf-8")
                        + '\n[telemetry]\nmsl_geoid = "grids/flat30.tif"\n', encoding="utf-8")
    cfg = load_config(cfg_path)
    assert Path(cfg.telemetry.msl_geoid) == grid
    path = _write(tmp_path / "msl.csv", [("h_msl_m" if h == "h_m" else h) for h in header],
                  {**cols, "h_msl_m": cols["h_m"]})
    job = locate_files(cfg, path, MOUNTAIN / "detections.csv", OnDEM(open_dem(MOUNTAIN / "longs_peak_srtmgl3.tif")))
    np.testing.assert_allclose(job.telemetry.columns["h_m"], cols["h_m"] + 30.0, atol=1e-4)
