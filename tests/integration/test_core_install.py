"""The core install (issue 45): `pip install .` without any extra, in a fresh virtual environment,
imports eoloc and locates pixels on a DEM, runs the file commands, and has none of FastAPI, Dask,
PyAV, OpenCV, folium, matplotlib or scikit-learn; a command that needs an optional part refuses
with one line naming the extra to install (exit 2, no traceback)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from where import ROOT

import eoloc

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
OPTIONAL = ("fastapi", "uvicorn", "dask", "distributed", "av", "cv2", "folium", "matplotlib", "sklearn", "takproto",
            "mercantile", "onnxruntime")

pytestmark = pytest.mark.slow

LOCATE = """
import json, sys
from importlib.util import find_spec
from pathlib import Path
import numpy as np
import eoloc
dem = eoloc.open_dem(str(Path(eoloc.__file__).parent / "data/demo/mountain/longs_peak_srtmgl3.tif"))
sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(30.0, 1280, 720), eoloc.AzElGimbal())
pose = eoloc.Pose(40.25, -105.6, 6000.0, 10.0, 0.0, 0.0, (0.0, -60.0))
fix = eoloc.locate(sensor, pose, eoloc.OnDEM(dem), np.array([[640.0, 360.0], [100.0, 50.0]]))
print(json.dumps({"lat": fix.lat_deg.tolist(), "lon": fix.lon_deg.tolist(), "h": fix.h_m.tolist(),
                  "status": [int(s) for s in fix.status], "missing": [m for m in sys.argv[1:] if find_spec(m) is None],
                  "file": eoloc.__file__}))
"""


@pytest.fixture(scope="module")
def core(tmp_path_factory) -> Path:
    """A fresh venv with eoloc installed from a copy of the source tree, no extras: its bin folder."""
    root = tmp_path_factory.mktemp("core")
    src = root / "eoloc-src"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "src", src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.egg-info"))
    subprocess.run([sys.executable, "-m", "venv", str(root / "venv")], check=True)
    bin_dir = root / "venv" / "bin"
    done = subprocess.run([str(bin_dir / "python"), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                           str(src)], capture_output=True, text=True, timeout=1500)
    assert done.returncode == 0, done.stderr[-3000:]
    return bin_dir


def _eoloc(core: Path, *args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(core / "eoloc"), *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


def test_the_core_install_locates_on_a_dem_without_the_optional_parts(core):
    done = subprocess.run([str(core / "python"), "-c", LOCATE, *OPTIONAL], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert sorted(got["missing"]) == sorted(OPTIONAL)  # none of the optional parts came with the core
    assert not got["file"].startswith(str(ROOT))  # (the copy installed there, not this checkout)
    dem = eoloc.open_dem(str(MOUNTAIN / "longs_peak_srtmgl3.tif"))
    sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(30.0, 1280, 720), eoloc.AzElGimbal())
    pose = eoloc.Pose(40.25, -105.6, 6000.0, 10.0, 0.0, 0.0, (0.0, -60.0))
    ref = eoloc.locate(sensor, pose, eoloc.OnDEM(dem), np.array([[640.0, 360.0], [100.0, 50.0]]))
    assert got["status"] == [0, 0]  # on the ground
    np.testing.assert_allclose(got["lat"], ref.lat_deg, rtol=0, atol=1e-9)  # the full install's answer
    np.testing.assert_allclose(got["lon"], ref.lon_deg, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["h"], ref.h_m, rtol=0, atol=1e-5)
    # the point is on the DEM's surface where the DEM is sampled by rasterio itself
    import rasterio

    with rasterio.open(MOUNTAIN / "longs_peak_srtmgl3.tif") as ds:
        ground = next(ds.sample([(got["lon"][0], got["lat"][0])]))[0]
    geoid = float(eoloc.terrain.geoid.default_geoid().undulation(got["lat"][0], got["lon"][0]))
    assert abs(got["h"][0] - (ground + geoid)) < 40  # (3" SRTM, bilinear against the cell: within its relief)


def test_the_file_commands_run_on_the_core_install(core, tmp_path):
    done = _eoloc(core, "locate", MOUNTAIN / "telemetry.csv", MOUNTAIN / "detections.csv", "--config",
                  MOUNTAIN / "camera.toml", "--dem", MOUNTAIN / "longs_peak_srtmgl3.tif", "--out", tmp_path / "loc",
                  *(a for f in ("csv", "geojson", "kml", "geoparquet", "gpkg") for a in ("--format", f)), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert {"fixes.csv", "fixes.geojson", "fixes.kml", "fixes.parquet", "fixes.gpkg"} <= {
        p.name for p in (tmp_path / "loc").iterdir()}
    klv = _eoloc(core, "klv", MOUNTAIN / "flight.klv", "--out", tmp_path / "klv", cwd=tmp_path)
    assert klv.returncode == 0, klv.stderr
    assert "no map.html" in klv.stderr and "eoloc[report]" in klv.stderr and "Traceback" not in klv.stderr
    assert (tmp_path / "klv" / "fixes.csv").is_file() and not (tmp_path / "klv" / "map.html").exists()


@pytest.mark.parametrize("args, extra", [
    (["serve", "--port", "0"], "service"),
    (["video", str(MOUNTAIN / "flight.klv"), "--out", "v"], "video"),
    (["batch", str(MOUNTAIN / "flight.klv"), "--out", "b", "--dask", "local:2"], "batch"),
])
def test_a_command_that_needs_an_extra_says_which(core, tmp_path, args, extra):
    done = _eoloc(core, *args, cwd=tmp_path)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr and f"pip install 'eoloc[{extra}]'" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1  # one line
