"""Issue 50: a new user's first hour. Each item a newcomer hit is a regression test named after it,
run through the `eoloc` command in a subprocess as the user runs it (stdout and stderr are pipes,
not a terminal: what a script or a CI log sees).

Independent checks: statuses and counts are read back from the written CSVs; the KLV stream
without a frame-centre elevation is the bundled flight with tags 23-25 and 78 removed item by
item (on the DEM the same statuses as the untouched stream's).
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
from where import ROOT

import eoloc

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
MOUNTAIN = DEMO / "mountain"
NOTHING_LOCATED = 3  # `eoloc --help`: exit status


def eoloc_cli(*args, cwd=None) -> subprocess.CompletedProcess:
    """`eoloc ARGS` as a user runs it, output to pipes; COLUMNS unset (a CI log, a script)."""
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    r = subprocess.run([sys.executable, "-m", "eoloc", *map(str, args)], capture_output=True, text=True,
                       env=env, cwd=cwd, timeout=300)
    assert "Traceback" not in r.stderr, r.stderr
    return r


def _statuses(path: Path) -> list[str]:
    with path.open(newline="", encoding="utf-8") as fh:
        return [row["status"] for row in csv.DictReader(fh)]


def test_50_2_an_unknown_column_is_named_and_an_all_invalid_run_says_why_and_fails(tmp_path):
    """The demo telemetry with its gimbal columns called gimbal_az, gimbal_el: each is named with
    the column it probably means, the run says once that every target lacks the gimbal angles,
    writes every row, and exits 3; the same file with the right names locates (exit 0)."""
    text = (DEMO / "telemetry.csv").read_text(encoding="utf-8")
    assert "azimuth_deg,elevation_deg" in text
    bad = tmp_path / "renamed.csv"
    bad.write_text(text.replace("azimuth_deg,elevation_deg", "gimbal_az,gimbal_el"), encoding="utf-8")
    args = ["--config", DEMO / "camera.toml", "--target-height", 600]
    r = eoloc_cli("locate", bad, DEMO / "detections.csv", *args, "--out", tmp_path / "bad")
    assert r.returncode == NOTHING_LOCATED, r.stderr
    err = " ".join(r.stderr.split())
    assert "column 'gimbal_az' is not one eoloc reads" in err and "'azimuth_deg', i.e. 'gimbal1_deg'" in err
    assert "column 'gimbal_el' is not one eoloc reads" in err and "'elevation_deg', i.e. 'gimbal2_deg'" in err
    assert "nothing was located" in err
    assert "gimbal1_deg (the gimbal's azimuth) is missing or out of range in all of them" in err
    assert err.count("nothing was located") == 1  # said once, not per row
    statuses = _statuses(tmp_path / "bad" / "fixes.csv")
    assert len(statuses) == 91 and "OK" not in statuses  # every record kept, each with its status
    assert statuses.count("INVALID_INPUT") == 90 and statuses.count("NO_TELEMETRY") == 1
    good = eoloc_cli("locate", DEMO / "telemetry.csv", DEMO / "detections.csv", *args, "--out", tmp_path / "good")
    assert good.returncode == 0, good.stderr
    assert "is not one eoloc reads" not in good.stderr and "nothing was located" not in good.stderr
    assert _statuses(tmp_path / "good" / "fixes.csv").count("OK") >= 80


def test_50_2_a_column_given_twice_under_two_names_is_named(tmp_path):
    text = (DEMO / "telemetry.csv").read_text(encoding="utf-8").splitlines()
    header = next(i for i, line in enumerate(text) if line.startswith("time_s"))
    text = [line + (",lat" if i == header else "," + line.split(",")[1] if i > header and line else "")
            for i, line in enumerate(text)]
    path = tmp_path / "twice.csv"
    path.write_text("\n".join(text) + "\n", encoding="utf-8")
    r = eoloc_cli("locate", path, "--config", DEMO / "camera.toml", "--target-height", 600, "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    assert "column 'lat' is another name for 'lat_deg', which the file also has; 'lat' ignored" in r.stderr


def _without_frame_centre(src: Path, dst: Path) -> Path:
    """The stream with the frame-centre items (tags 23, 24, 25, 78) taken out of every packet."""
    from eoloc.io.klv.encode import build_uas_packet, uas_items
    from eoloc.io.klv.reader import split_klv

    def checksum_ok(packet: bytes) -> bool:  # ST 0601 §6.5.3's 16-bit sum, restated
        s = sum(b << (8 * ((i + 1) % 2)) for i, b in enumerate(packet[:-2])) & 0xFFFF
        return s == int.from_bytes(packet[-2:], "big")

    out = bytearray()
    for packet, _ in split_klv(src.read_bytes(), str(src)):
        if not checksum_ok(packet):  # the flight's one spoilt packet stays out, as the reader leaves it out
            continue
        out += build_uas_packet([(t, v) for t, v in uas_items(packet) if t not in (1, 23, 24, 25, 78)])
    dst.write_bytes(bytes(out))
    return dst


def test_50_2_klv_targets_without_a_frame_centre_elevation_say_why_and_fail(tmp_path):
    """VMTI targets with no frame-centre elevation to stop at (no --dem): the run names the missing
    tags and the fix (--dem), says why no footprint was drawn, and exits 3; with --dem every
    target is located (exit 0)."""
    stream = _without_frame_centre(MOUNTAIN / "flight.klv", tmp_path / "no_centre.klv")
    r = eoloc_cli("klv", stream, "--out", tmp_path / "a")
    assert r.returncode == NOTHING_LOCATED, r.stderr
    err = " ".join(r.stderr.split())
    statuses = _statuses(tmp_path / "a" / "fixes.csv")
    assert statuses and set(statuses) == {"INVALID_INPUT"}
    assert f"{len(statuses)} of {len(statuses)} VMTI detections are INVALID_INPUT" in err
    assert "the frame-centre elevation (tag 78, or 25 + geoid) is missing or out of range in all of them" in err
    assert "give --dem" in err and "no footprint could be drawn" in err
    dem = MOUNTAIN / "longs_peak_srtmgl3.tif"
    r = eoloc_cli("klv", stream, "--dem", dem, "--out", tmp_path / "b")
    assert r.returncode == 0, r.stderr
    on_dem = _statuses(tmp_path / "b" / "fixes.csv")
    assert len(on_dem) == len(statuses) and on_dem.count("OK") > 0.9 * len(on_dem)
    # the DEM does not need the frame centre: the same statuses as the untouched stream's on the DEM
    r = eoloc_cli("klv", MOUNTAIN / "flight.klv", "--dem", dem, "--out", tmp_path / "c")
    assert r.returncode == 0 and _statuses(tmp_path / "c" / "fixes.csv") == on_dem


def test_50_2_one_observation_that_fails_says_why_and_exits_3():
    r = eoloc_cli("locate", "--lat", 42, "--lon", 125, "--aircraft-height", 1000, "--gimbal-angles", 0, "nan",
                  "--target-height", 0, "--json")
    assert r.returncode == NOTHING_LOCATED
    assert '"status": "INVALID_INPUT"' in r.stdout
    assert "--gimbal-angles (elevation) is missing or out of range" in r.stderr


def test_50_9_tables_and_paths_are_whole_off_a_terminal(tmp_path):
    """Off a terminal no cell is cut ("statu"), no title or file name is wrapped: every table row
    is one line that starts and ends with its border, and the long names appear whole."""
    deep = tmp_path / ("a_folder_with_a_long_name_" * 3) / "recordings"
    deep.mkdir(parents=True)
    names = [f"sortie_2026_11_27_platform_ALPHA_{i}_with_a_long_descriptive_name.klv" for i in range(2)]
    for n in names:
        (deep / n).write_bytes((MOUNTAIN / "flight.klv").read_bytes())
    r = eoloc_cli("batch", deep, "--out", tmp_path / "archive", "--config", MOUNTAIN / "camera.toml",
                  "--target-height", 3600)
    assert r.returncode == 0, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("│")]
    assert len(rows) == 2 and all(line.endswith("│") for line in rows)
    for n in names:
        assert sum(n in line for line in rows) == 1  # whole, on its row
    assert f"files under {deep}" in r.stdout  # the title's path whole
    assert f"{tmp_path / 'archive'}" in r.stderr.splitlines()[-1]  # the "wrote" line whole
    bad = tmp_path / "renamed.csv"
    bad.write_text((DEMO / "telemetry.csv").read_text(encoding="utf-8").replace("azimuth_deg", "gimbal_az"),
                   encoding="utf-8")
    r = eoloc_cli("locate", bad, DEMO / "detections.csv", "--config", DEMO / "camera.toml", "--target-height", 600,
                  "--out", tmp_path / "fixes")
    assert "91 targets: INVALID_INPUT 90, NO_TELEMETRY 1" in r.stdout.splitlines()  # the title on one line
    cells = [c.strip() for line in r.stdout.splitlines() if line.startswith("│") for c in line.strip("│").split("│")]
    assert "INVALID_INPUT" in cells and not any(c.endswith("…") for c in cells)


def test_50_9_no_progress_line_before_a_mistake_is_reported(tmp_path):
    """A mistake the job finds in its inputs is the only thing said: no "rectifying frames: started"
    before it; a good run still says when it starts (off a terminal too)."""
    from datetime import UTC, datetime

    from eoloc.io.klv.encode import encode_uas_packet
    from eoloc.io.klv.mux import write_klv_ts

    def packet(t: float) -> bytes:  # 3 km up near Boulder, the turret 45° down
        return encode_uas_packet({2: datetime.fromtimestamp(1.7e9 + t, UTC), 5: 90.0, 6: 0.0, 7: 0.0, 13: 40.0,
                                  14: -105.0, 15: 3000.0, 16: 20.0, 17: 12.0, 18: 0.0, 19: -45.0, 20: 0.0,
                                  25: 0.0, 78: 0.0})

    video = write_klv_ts(tmp_path / "pass.ts", [[(packet(k / 10), k / 10) for k in range(21)]], video_fps=10.0)
    r = eoloc_cli("video", video, "--out", tmp_path / "v", "--start", 50)
    assert r.returncode == 2 and "no frame of" in r.stderr and "--start" in r.stderr
    assert "started" not in r.stderr
    r = eoloc_cli("video", video, "--out", tmp_path / "v", "--every", 5)
    assert r.returncode == 0, r.stderr
    assert "rectifying frames: started" in r.stderr


def _commands():
    """Every command and subcommand of `eoloc`, as (name, click command)."""
    import click

    from eoloc.cli import main

    ctx = click.Context(main)
    for name in main.list_commands(ctx):
        cmd = main.get_command(ctx, name)
        if isinstance(cmd, click.Group):
            yield from ((f"{name} {n}", cmd.get_command(ctx, n)) for n in cmd.list_commands(ctx))
        else:
            yield name, cmd


def _options(cmd) -> dict:
    return {o: p for p in cmd.params for o in getattr(p, "opts", [])}


def _front_range_asc(folder: Path) -> Path:
    """The bundled Front Range DEM as an ESRI ASCII grid without a .prj (no CRS), as SRTM's
    .asc grids come."""
    import rasterio

    with rasterio.open(MOUNTAIN / "longs_peak_srtmgl3.tif") as src:
        z, transform = src.read(1), src.transform
    path = folder / "front.asc"
    with rasterio.open(path, "w", driver="AAIGrid", height=z.shape[0], width=z.shape[1], count=1, dtype="int16",
                       transform=transform, nodata=0) as dst:
        dst.write(z, 1)
    for other in folder.glob("front.*"):
        if other != path:
            other.unlink()
    return path


ACCURACY_TOML = """[camera]
width = 1280
height = 720
hfov_deg = 25.0

[accuracy]
samples = 500

[accuracy.stop]
dem = ["front.asc"]
{extra}
[accuracy.pose]
lat_deg = 40.25
lon_deg = -105.56
h_m = 6000
gimbal_deg = [270, -45]

[accuracy.budget]
yaw_deg = {{normal = 0.1}}
"""


def test_50_4_the_dem_options_are_declared_once_and_offered_by_every_command_with_a_dem(tmp_path):
    """Every command that takes --dem takes --vertical, --geoid and --dem-crs, the same options
    (same help, type, default); `eoloc accuracy` takes a CRS-less DEM of its config through
    --dem-crs or the config's dem_crs (the config refused dem_crs before), `eoloc map` too."""
    seen = {}
    for name, cmd in _commands():
        opts = _options(cmd)
        if "--dem" not in opts:
            continue
        assert {"--vertical", "--geoid", "--dem-crs"} <= set(opts), name
        for flag in ("--dem", "--vertical", "--geoid", "--dem-crs"):
            p = opts[flag]
            shape = (p.name, type(p.type).__name__, p.default, p.multiple, flag == "--dem" or p.help)
            assert seen.setdefault(flag, shape) == shape, (name, flag)
    assert {"accuracy", "map", "locate", "serve", "live"} <= {n for n, c in _commands() if "--dem" in _options(c)}

    dem = _front_range_asc(tmp_path)
    config = tmp_path / "acc.toml"
    config.write_text(ACCURACY_TOML.format(extra=""), encoding="utf-8")
    r = eoloc_cli("accuracy", config, "--no-sensitivity", "--no-plots", "--out", tmp_path / "a")
    assert r.returncode == 2 and "--dem-crs EPSG:4326" in r.stderr and "dem_crs" in r.stderr
    r = eoloc_cli("accuracy", config, "--no-sensitivity", "--no-plots", "--dem-crs", "EPSG:4326",
                  "--out", tmp_path / "b")
    assert r.returncode == 0, r.stderr
    config.write_text(ACCURACY_TOML.format(extra='dem_crs = "EPSG:4326"\n'), encoding="utf-8")
    r = eoloc_cli("accuracy", config, "--no-sensitivity", "--no-plots", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    # the same Monte Carlo (seeded) on the same terrain: the same figures whichever way the CRS came
    assert (tmp_path / "b" / "accuracy.csv").read_text() == (tmp_path / "c" / "accuracy.csv").read_text()
    rows = list(csv.DictReader((tmp_path / "c" / "accuracy.csv").open(encoding="utf-8")))
    assert rows and all(float(row["cep50_m"]) > 0 for row in rows)

    args = ["map", "--telemetry", MOUNTAIN / "telemetry.csv", "--dem", dem, "--out", tmp_path / "m"]
    r = eoloc_cli(*args)
    assert r.returncode == 2 and "--dem-crs EPSG:4326" in r.stderr
    r = eoloc_cli(*args, "--dem-crs", "EPSG:4326")
    assert r.returncode == 0 and (tmp_path / "m" / "map.html").is_file(), r.stderr


def test_50_5_out_is_one_folder_per_command_by_default_and_means_a_folder_everywhere(tmp_path):
    """--out is the same option on every command that writes files (a folder, default
    eoloc-out/COMMAND): `eoloc locate` and `eoloc klv`, which both write fixes.csv, no longer
    overwrite each other; `eoloc map` writes eoloc-out/map/map.html."""
    for name, cmd in _commands():
        opts = _options(cmd)
        if "--out" in opts:
            p = opts["--out"]
            assert p.default is None and p.callback is not None and p.metavar == "DIR", name
            assert not p.type.file_okay, name
    r = eoloc_cli("locate", DEMO / "telemetry.csv", DEMO / "detections.csv", "--config", DEMO / "camera.toml",
                  "--target-height", 600, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = eoloc_cli("klv", MOUNTAIN / "flight.klv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = eoloc_cli("map", "--fixes", tmp_path / "eoloc-out" / "klv" / "fixes.geojson", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = eoloc_cli("compensate", "simulate", "--help")
    assert "[default:eoloc-out/compensate-simulate]" in "".join(r.stdout.split())  # click wraps the help
    out = tmp_path / "eoloc-out"
    assert (out / "map" / "map.html").is_file()
    located = _statuses(out / "locate" / "fixes.csv")
    vmti = _statuses(out / "klv" / "fixes.csv")
    assert len(located) == 91 and len(vmti) == 108  # each command's own fixes, neither overwritten


def test_50_5_a_repeated_dem_is_tiles_of_one_dem_in_serve_too(tmp_path):
    """`eoloc serve --dem WEST --dem EAST` (two tiles) serves one DEM, named after the first file,
    as --dem means on every command; a ray that lands on the second tile is located on it, to the
    library's answer on the whole DEM."""
    import httpx
    import numpy as np
    import rasterio
    from rasterio.windows import Window
    from served import eoloc_serve

    from eoloc import OnDEM, Pose
    from eoloc.io.config import load_config
    from eoloc.terrain import open_dem

    whole = MOUNTAIN / "longs_peak_srtmgl3.tif"
    with rasterio.open(whole) as src:
        half = src.width // 2
        parts = {}
        for name, win in (("west", Window(0, 0, half + 1, src.height)),
                          ("east", Window(half, 0, src.width - half, src.height))):
            profile = {**src.profile, "width": win.width, "height": win.height,
                       "transform": src.window_transform(win)}
            parts[name] = tmp_path / f"{name}.tif"
            with rasterio.open(parts[name], "w", **profile) as dst:
                dst.write(src.read(1, window=win), 1)
    cfg = load_config(MOUNTAIN / "camera.toml")
    pose = {"lat_deg": 40.25, "lon_deg": -105.56, "h_m": 6000.0, "yaw_deg": 0.0, "pitch_deg": 0.0,
            "roll_deg": 0.0, "gimbal_deg": [270.0, -60.0]}  # over the east half, looking down to the west
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml"), "--dem", str(parts["west"]),
                     "--dem", str(parts["east"])) as url:
        health = httpx.get(url + "/v1/health").json()
        assert health["dems"] == ["west"]
        fix = httpx.post(url + "/v1/locate", json={"pose": pose, "stop": {"dem": "west"}}).json()["fixes"][0]
    ref = OnDEM(open_dem(whole)).locate(cfg.sensor(), Pose(**{**pose, "gimbal_deg": tuple(pose["gimbal_deg"])}))
    assert fix["status"] == "OK" and int(ref.status) == 0
    assert fix["lon_deg"] > -105.6254  # on the east tile
    assert np.hypot((fix["lat_deg"] - float(ref.lat_deg)) * 111e3, (fix["lon_deg"] - float(ref.lon_deg)) * 85e3) < 0.01


@pytest.mark.browser
def test_50_3_the_api_docs_render_their_operations_offline(tmp_path):
    """/docs (Swagger UI) in headless Chromium with no network beyond loopback: every
    operation of the API is drawn, every file the pages load comes from the eoloc server itself,
    and the browser logs no error."""
    from browser import chromium
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
    from served import eoloc_serve

    operations = {("post", "/v1/locate"), ("post", "/v1/locate/arrow"), ("get", "/v1/health")}
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml")) as url:
        page = httpx_get(url + "/docs")
        assert "cdn" not in page.lower() and "https://" not in page  # nothing to fetch from elsewhere
        d = chromium(offline=True)
        try:
            d.get(url + "/docs")
            WebDriverWait(d, 60).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, ".opblock")) >= 3)
            drawn = {(e.find_element(By.CSS_SELECTOR, ".opblock-summary-method").text.lower(),
                      e.find_element(By.CSS_SELECTOR, ".opblock-summary-path").get_attribute("data-path"))
                     for e in d.find_elements(By.CSS_SELECTOR, ".opblock")}
            assert operations <= drawn, drawn
            loaded = d.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
            assert loaded and all(u.startswith(url) for u in loaded), loaded
            errors = [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
            assert not errors, errors
            assert httpx_get(url + "/redoc", 404) is not None  # no ReDoc: its page fetches a badge from a CDN
        finally:
            d.quit()


def httpx_get(url: str, status: int = 200) -> str:
    import httpx

    r = httpx.get(url)
    assert r.status_code == status, (url, r.status_code)
    return r.text


def test_50_8_a_bad_request_gets_one_problem_per_mistake_with_its_path():
    """HTTP 422 bodies name what the client got wrong and where, once: a single observation
    without its stop rule is "stop: Field required" (not the batch form's complaint about its
    pose), invalid JSON is the body with the line and column, a batch's bad pixel its full path;
    two mistakes, two problems; no model name of eoloc's in any of them."""
    import httpx
    from served import eoloc_serve

    pose = {"lat_deg": 40.25, "lon_deg": -105.56, "h_m": 6000.0, "yaw_deg": 0.0, "pitch_deg": 0.0, "roll_deg": 0.0,
            "gimbal_deg": [270.0, -60.0]}
    stop = {"target_height_m": 3000.0}
    cases = [
        ({"pose": pose}, [("stop", "Field required")]),
        ({"pose": {**pose, "lat_deg": "north"}, "stop": stop}, [("pose.lat_deg", "valid number")]),
        ({"pose": {**pose, "h_m": None}, "pixels": [[1, 2, 3]]},
         [("stop", "Field required"), ("pose.h_m", "valid number"), ("pixels.0", "")]),
        ({"observations": [{"pose": pose, "stop": stop}, {"pose": pose, "stop": stop, "pixels": [[10, "x"]]}]},
         [("observations.1.pixels.0.1", "valid number")]),
        ({"pose": pose, "stop": {"target_height_m": 0, "range_m": 5}}, [("stop", "exactly one of")]),
    ]
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml")) as url:
        for body, expected in cases:
            r = httpx.post(url + "/v1/locate", json=body)
            assert r.status_code == 422, body
            problems = r.json()["problems"]
            assert sorted(p["field"] for p in problems) == sorted(f for f, _ in expected), problems
            for field, words in expected:
                assert any(p["field"] == field and words in p["message"] for p in problems), (field, problems)
            assert not any(name in str(problems) for name in ("BatchIn", "ObservationIn", "LocateIn")), problems
        r = httpx.post(url + "/v1/locate", content=b'{"pose": {"lat_deg": 40,', headers={"content-type":
                                                                                         "application/json"})
        (p,) = r.json()["problems"]
        assert r.status_code == 422 and p["field"] == "(body)" and "Invalid JSON" in p["message"]
        assert "line 1 column 24" in p["message"]  # the body is 24 bytes: it ends there


def test_50_6_training_on_fixes_of_one_oblique_band_trains_and_says_what_it_cannot_check(tmp_path):
    """`compensate train` on fixes that all lie in one oblique band (here: one band 0–90°) trained
    nothing before ("0 usable training fixes: at least 20 are needed", on 1 800 located fixes):
    now the model is trained, the held-out-band check is skipped with the reason and what to do,
    and the model is written into --out; the held-out-flights table is still there."""
    from eoloc.accuracy.compensation import CompensationModel
    from eoloc.io.telemetry import read_observations

    cal = tmp_path / "cal"
    r = eoloc_cli("compensate", "simulate", "--config", DEMO / "camera.toml", "--flights", 3, "--test-flights", 1,
                  "--looks", 200, "--out", cal)
    assert r.returncode == 0, r.stderr
    n = len(read_observations(cal / "train.csv"))
    args = ["compensate", "train", cal / "train.csv", "--config", DEMO / "camera.toml", "--dem", cal / "dem.tif",
            "--vertical", "ellipsoid", "--out", tmp_path / "out"]
    r = eoloc_cli(*args, "--bands", "0,90")
    assert r.returncode == 0, r.stderr
    err = " ".join(r.stderr.split())
    assert "held-out oblique bands: not computed" in err and "lie in one band (oblique" in err
    assert "band edges 0, 90" in err and "leaves 0 fixes to train on" in err
    assert "wider spread of oblique angles" in err and "usable training fixes" not in err
    assert "held-out flights" in r.stdout
    model = CompensationModel.load(tmp_path / "out" / "compensation.json")  # into --out, not the working folder
    assert model.info["n_samples"] <= n and model.info["cv_by_band"] == []
    r = eoloc_cli(*args)  # the default bands: both checks
    assert r.returncode == 0 and "held-out oblique bands (each band" in r.stdout


def test_50_7_telemetry_and_gcps_join_into_the_observations_report_and_compensate_take(tmp_path):
    """The two vocabularies meet: a simulated calibration flight's observations split (here, with
    the csv module) into what a user has for `eoloc calibrate` — a telemetry file and a GCP file
    per flight — and joined back by `eoloc join`: every row, pose and point equal to the original
    ones, flights named; the joined file then feeds `eoloc report`, and a sighting with no
    telemetry record is named by file and line."""
    cal = tmp_path / "cal"
    r = eoloc_cli("compensate", "simulate", "--config", DEMO / "camera.toml", "--flights", 2, "--test-flights", 1,
                  "--looks", 60, "--out", cal)
    assert r.returncode == 0, r.stderr
    with (cal / "train.csv").open(newline="", encoding="utf-8") as fh:
        original = list(csv.DictReader(fh))
    pose = ["lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg"]
    args = []
    for flight in sorted({row["flight"] for row in original}):
        rows = [row for row in original if row["flight"] == flight]
        tel, gcp = tmp_path / f"{flight}.csv", tmp_path / f"{flight}_gcps.csv"
        with tel.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", *pose])
            w.writerows([i, *(row[k] for k in pose)] for i, row in enumerate(rows))
        with gcp.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "gcp_id", "u_px", "v_px", "lat_deg", "lon_deg", "h_m"])
            w.writerows([i, row["gcp_id"] or f"P{i}", row["u_px"], row["v_px"], row["gcp_lat_deg"],
                         row["gcp_lon_deg"], row["gcp_h_m"]] for i, row in enumerate(rows))
            w.writerow([len(rows) + 5, "LOST", 1, 1, 0, 0, 0])  # a sighting no record belongs to
        args += [tel, gcp]
    r = eoloc_cli("join", *args, "--out", tmp_path / "joined")
    assert r.returncode == 0, r.stderr
    assert "no telemetry record for frame" in r.stderr and "_gcps.csv:" in r.stderr
    with (tmp_path / "joined" / "observations.csv").open(newline="", encoding="utf-8") as fh:
        joined = list(csv.DictReader(fh))
    assert len(joined) == len(original)
    for a, b in zip(original, joined, strict=True):
        assert a["flight"] == b["flight"]
        for k in pose:
            assert abs(float(a[k]) - float(b[k])) < 1e-6, (k, a[k], b[k])
        for k in ("u_px", "v_px", "gcp_lat_deg", "gcp_lon_deg", "gcp_h_m"):
            assert abs(float(a[k]) - float(b[k])) < 1e-6, (k, a[k], b[k])
    r = eoloc_cli("report", tmp_path / "joined" / "observations.csv", "--config", DEMO / "camera.toml",
                  "--dem", cal / "dem.tif", "--vertical", "ellipsoid", "--out", tmp_path / "report")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "report" / "report.html").is_file()


def _tile_colour(x: int, y: int) -> tuple[int, int, int]:
    """The test basemap's colour of tile (x, y): neighbours differ by far more than any blending."""
    return (40 + (x * 67) % 180, 40 + (y * 97) % 180, 200 - (x + y) % 2 * 120)


def _write_tiles(folder: Path, bounds, zooms) -> None:
    """A tile folder {z}/{x}/{y}.png over ``bounds`` (west, south, east, north): each tile one
    flat colour of its own, drawn with Pillow (nothing of eoloc's)."""
    import mercantile
    from PIL import Image

    for t in mercantile.tiles(*bounds, zooms=zooms):
        p = folder / str(t.z) / str(t.x) / f"{t.y}.png"
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (256, 256), _tile_colour(t.x, t.y)).save(p)


def _mbtiles(folder: Path, path: Path) -> Path:
    """The same tiles as an MBTiles file (TMS rows, as the format says), written with sqlite3."""
    import sqlite3

    db = sqlite3.connect(path)
    db.executescript("CREATE TABLE metadata (name text, value text);"
                     "CREATE TABLE tiles (zoom_level integer, tile_column integer, tile_row integer, tile_data blob);")
    db.executemany("INSERT INTO metadata VALUES (?, ?)", [("name", "test"), ("format", "png"),
                                                          ("attribution", "<b onmouseover=alert(1)>test tiles</b>")])
    for p in folder.glob("*/*/*.png"):
        z, x, y = int(p.parent.parent.name), int(p.parent.name), int(p.stem)
        db.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x, (1 << z) - 1 - y, p.read_bytes()))
    db.commit()
    db.close()
    return path


def _screen(page: Path, wait_tiles: bool):
    """The page in headless Chromium with no network: (screenshot as an RGB array, the map's zoom,
    a function giving the container pixel of a lat/lon, the driver)."""
    import io

    import numpy as np
    from browser import chromium
    from PIL import Image
    from selenium.webdriver.support.ui import WebDriverWait

    d = chromium(offline=True)
    d.set_window_size(1200, 900)
    d.get(page.as_uri())
    find = "var m = Object.values(window).find(v => v instanceof L.Map);"
    WebDriverWait(d, 60).until(lambda d: d.execute_script(find + "return !!m;"))
    if wait_tiles:
        WebDriverWait(d, 60).until(lambda d: d.execute_script(
            "var t = document.querySelectorAll('img.leaflet-tile');"
            "return t.length > 0 && [...t].every(i => i.complete && i.classList.contains('leaflet-tile-loaded'));"))
    d.execute_script("return new Promise(r => setTimeout(r, 500));")  # fade-in of the tiles (Leaflet: 200 ms)
    zoom = d.execute_script(find + "return m.getZoom();")
    img = np.asarray(Image.open(io.BytesIO(d.get_screenshot_as_png())).convert("RGB")).astype(int)

    def pixel(lat: float, lon: float):
        return d.execute_script(find + "var p = m.latLngToContainerPoint([arguments[0], arguments[1]]);"
                                "var r = m.getContainer().getBoundingClientRect(); return [p.x + r.left, p.y + r.top];",
                                lat, lon)

    return img, zoom, pixel, d


@pytest.mark.browser
@pytest.mark.parametrize("kind", ["folder", "mbtiles"])
def test_50_10_an_offline_basemap_shows_its_land_under_the_footprints(tmp_path, kind):
    """`eoloc map --basemap TILES` (a tile folder, or the same tiles as MBTiles) opened with no
    network: the screenshot shows, under the flight's footprints, the colour of the tile that
    covers each place (tile by tile, as mercantile places them) wherever no footprint outline
    passes (39 footprints: outlines, no fill hiding the land); the MBTiles attribution is shown as
    text, not run as HTML."""
    import json

    import mercantile
    import numpy as np
    import shapely

    r = eoloc_cli("klv", MOUNTAIN / "flight.klv", "--dem", MOUNTAIN / "longs_peak_srtmgl3.tif", "--no-map",
                  "--out", tmp_path / "klv")
    assert r.returncode == 0, r.stderr
    prints = json.loads((tmp_path / "klv" / "footprints.geojson").read_text())["features"]
    polys = [shapely.geometry.shape(f["geometry"]) for f in prints if f.get("geometry")]
    union = shapely.union_all(polys)
    outlines = shapely.union_all([p.boundary for p in polys])
    w, s, e, n = union.bounds
    tiles = tmp_path / "tiles"
    _write_tiles(tiles, (w - 0.2, s - 0.2, e + 0.2, n + 0.2), [8, 9, 10, 11, 12])
    basemap = tiles if kind == "folder" else _mbtiles(tiles, tmp_path / "tiles.mbtiles")
    page = tmp_path / "map.html"
    r = eoloc_cli("map", "--footprints", tmp_path / "klv" / "footprints.geojson", "--basemap", basemap, "-o", page)
    assert r.returncode == 0, r.stderr
    img, zoom, pixel, d = _screen(page, wait_tiles=True)
    try:
        attribution = d.execute_script("return document.querySelector('.leaflet-control-attribution').textContent")
        alerts = d.execute_script("return document.querySelectorAll('.leaflet-control-attribution b').length")
        if kind == "mbtiles":
            assert "<b onmouseover=alert(1)>test tiles</b>" in attribution and alerts == 0
        z = min(int(zoom), 12)
        rng = np.random.default_rng(5)
        checked = 0
        for _ in range(400):
            lon, lat = rng.uniform(w, e), rng.uniform(s, n)
            point = shapely.Point(lon, lat)
            if not union.contains(point):
                continue
            t = mercantile.tile(lon, lat, z)
            b = mercantile.xy_bounds(t)
            x, y = mercantile.xy(lon, lat)
            fx, fy = (x - b.left) / (b.right - b.left), (b.top - y) / (b.top - b.bottom)
            if min(fx, fy, 1 - fx, 1 - fy) < 0.03:  # on a tile's edge: either colour
                continue
            px_per_deg = 256 * 2 ** zoom / 360  # along a parallel; more along a meridian
            if outlines.distance(point) * px_per_deg < 4:  # an outline passes there
                continue
            px, py = (round(c) for c in pixel(lat, lon))
            if not (0 <= px < img.shape[1] and 0 <= py < img.shape[0]):
                continue
            expected = np.array(_tile_colour(t.x, t.y))
            assert np.abs(img[py, px] - expected).max() <= 6, (lat, lon, img[py, px], expected)
            checked += 1
    finally:
        d.quit()
    assert checked >= 30


@pytest.mark.browser
def test_50_10_the_world_layer_the_time_slider_and_many_footprints(tmp_path):
    """Without tiles the bundled world layer is under the flight (Colorado: land colour, not the
    sea's or a grey canvas); the time slider shows the footprints up to its time, or that time
    only; 80 footprints are drawn as unfilled outlines."""
    import json

    import numpy as np

    r = eoloc_cli("klv", MOUNTAIN / "flight.klv", "--dem", MOUNTAIN / "longs_peak_srtmgl3.tif", "--out",
                  tmp_path / "klv")
    assert r.returncode == 0, r.stderr
    page = tmp_path / "klv" / "map.html"
    prints = json.loads((tmp_path / "klv" / "footprints.geojson").read_text())["features"]
    times = sorted({f["properties"]["time_s"] for f in prints if f.get("geometry")})
    img, zoom, pixel, d = _screen(page, wait_tiles=False)
    try:
        lat, lon = 40.31 + 0.02, -105.70 - 0.02  # beyond the DEM's hillshade, still in Colorado
        px, py = (round(c) for c in pixel(lat, lon))
        assert 0 <= px < img.shape[1] and 0 <= py < img.shape[0]
        assert np.abs(img[py, px] - np.array([0xF2, 0xEF, 0xE6])).max() < 12, img[py, px]  # the land's colour
        visible = ("return [...document.querySelectorAll('path.eoloc-footprint')]"
                   ".filter(e => getComputedStyle(e).display !== 'none').length")
        assert d.execute_script(visible) == len(times)
        set_range = ("var r = document.getElementById('eoloc-time-range'); r.value = arguments[0];"
                     "r.dispatchEvent(new Event('input'));")
        d.execute_script(set_range, 9)
        assert d.execute_script(visible) == 10
        assert d.execute_script("return document.getElementById('eoloc-time-label').textContent").endswith("UTC")
        d.execute_script("var c = document.getElementById('eoloc-time-only'); c.checked = true;"
                         "c.dispatchEvent(new Event('change'));")
        assert d.execute_script(visible) == 1
    finally:
        d.quit()
    many = [dict(f, properties={**f["properties"], "time_s": f["properties"]["time_s"] + 0.5 * (i % 2)})
            for i, f in enumerate(prints * 2) if f.get("geometry")]
    (tmp_path / "many.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": many}))
    r = eoloc_cli("map", "--footprints", tmp_path / "many.geojson", "-o", tmp_path / "many.html")
    assert r.returncode == 0, r.stderr
    img, zoom, pixel, d = _screen(tmp_path / "many.html", wait_tiles=False)
    try:
        fills = d.execute_script("return [...document.querySelectorAll('path.eoloc-footprint')]"
                                 ".map(e => e.getAttribute('fill'))")
        assert len(fills) == len(many) and set(fills) == {"none"}
    finally:
        d.quit()


def test_50_11_the_gis_layers_an_analyst_expects(tmp_path):
    """`eoloc klv --format gpkg --format geoparquet`: the frame centres (points) and the sensor track
    (a line) as layers in each format, read back by GDAL (pyogrio) at frames.csv's coordinates and
    telemetry.csv's path; eoloc.kml (valid OGC KML 2.2) has one shared style per layer and none per
    placemark, a TimeStamp on every fix, footprint and frame centre (Google Earth animates them),
    its data fields declared once per layer (a Schema; heights with their datum); `eoloc report`
    hashes the DEM it was given."""
    import hashlib
    import xml.etree.ElementTree as ET
    from importlib.resources import files

    import geopandas
    import numpy as np
    import pyogrio
    import shapely
    import xmlschema

    out = tmp_path / "klv"
    r = eoloc_cli("klv", MOUNTAIN / "flight.klv", "--dem", MOUNTAIN / "longs_peak_srtmgl3.tif", "--out", out,
                  "--format", "csv", "--format", "geojson", "--format", "gpkg", "--format", "geoparquet")
    assert r.returncode == 0, r.stderr
    with (out / "frames.csv").open(newline="", encoding="utf-8") as fh:
        frames = list(csv.DictReader(fh))
    with (out / "telemetry.csv").open(newline="", encoding="utf-8") as fh:
        telemetry = list(csv.DictReader(fh))
    def geometries(path: Path):  # GDAL for GeoJSON and GeoPackage, geopandas for GeoParquet
        if path.suffix == ".parquet":
            return np.asarray(geopandas.read_parquet(path).geometry)
        return shapely.from_wkb(pyogrio.raw.read(path, return_fids=False)[2])

    for ext in ("geojson", "gpkg", "parquet"):
        pts = geometries(out / f"frame_centres.{ext}")
        assert len(pts) == len(frames) and set(shapely.get_type_id(pts)) == {0}  # points
        assert np.allclose(shapely.get_x(pts), [float(f["eoloc_lon_deg"]) for f in frames], atol=1e-7)
        assert np.allclose(shapely.get_y(pts), [float(f["eoloc_lat_deg"]) for f in frames], atol=1e-7)
        (line,) = geometries(out / f"sensor_track.{ext}")
        assert line.geom_type == "LineString" and len(line.coords) == len(telemetry)
        assert np.allclose([c[1] for c in line.coords], [float(t["lat_deg"]) for t in telemetry], atol=1e-7)

    kml = out / "eoloc.kml"
    schema = xmlschema.XMLSchema(str(files("pykml") / "schemas" / "ogckml22.xsd"))
    assert not list(schema.iter_errors(str(kml)))
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    doc = ET.parse(kml).getroot().find("k:Document", ns)
    styles = {s.get("id") for s in doc.findall("k:Style", ns)}
    folders = {f.find("k:name", ns).text: f for f in doc.findall("k:Folder", ns)}
    assert len(styles) == len(folders) and not doc.findall(".//k:Placemark/k:Style", ns)
    for name in ("fixes", "footprints", "frame centres"):
        marks = folders[name].findall("k:Placemark", ns)
        assert marks and all(m.find("k:styleUrl", ns).text[1:] in styles for m in marks)
        whens = [m.find("k:TimeStamp/k:when", ns) for m in marks]
        assert all(w is not None and w.text.startswith("2026-07-14T16:00") for w in whens), name
    h = [f for f in doc.iter("{http://www.opengis.net/kml/2.2}SimpleField") if f.get("name") == "h_m"]
    assert h and all("ellipsoid" in f.find("k:displayName", ns).text for f in h)  # declared once per layer
    assert not list(doc.iter("{http://www.opengis.net/kml/2.2}Data"))  # no field name repeated per placemark

    cal = tmp_path / "cal"
    r = eoloc_cli("compensate", "simulate", "--config", DEMO / "camera.toml", "--flights", 2, "--test-flights", 1,
                  "--looks", 40, "--out", cal)
    assert r.returncode == 0, r.stderr
    r = eoloc_cli("report", cal / "train.csv", "--config", DEMO / "camera.toml", "--dem", cal / "dem.tif",
                  "--vertical", "ellipsoid", "--out", tmp_path / "report")
    assert r.returncode == 0, r.stderr
    page = (tmp_path / "report" / "report.html").read_text(encoding="utf-8")
    assert hashlib.sha256((cal / "dem.tif").read_bytes()).hexdigest() in page


def test_50_1_nothing_a_user_reads_or_runs_points_outside_the_repository():
    """A user's clone has no ../shared: the README, the docs, the code, the examples, the benches
    and the Makefile name no path outside the repository, and every relative link of the README
    and the docs leads to a file of the repository."""
    import re

    root = ROOT
    texts = [root / "README.md", root / "Makefile", *(root / "docs").glob("*.md"),
             *(root / "src").rglob("*.py"), *(root / "examples").glob("*.py"), *(root / "bench").glob("*.py"),
             *(root / "bench").glob("*.md")]
    outside = [str(p.relative_to(root)) for p in texts if re.search(r"\.\./shared|/shared/data", p.read_text(
        encoding="utf-8", errors="replace"))]
    assert not outside, outside
    for doc in [root / "README.md", *(root / "docs").glob("*.md")]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text(encoding="utf-8")):
            if "://" in target or target.startswith("mailto:"):
                continue
            assert (doc.parent / target).resolve().is_relative_to(root), (doc.name, target)
            assert (doc.parent / target).exists(), (doc.name, target)


def test_50_2_a_cameras_attitude_column_is_not_taken_for_the_aircrafts():
    """A header a drone user writes, gimbal_pitch_deg (or camera_yaw, gimbal_hdg): eoloc does not
    suggest the aircraft's pitch_deg, whose name is close but whose meaning is not; it says where
    a gimbal's angles go (relative: gimbal1_deg, gimbal2_deg) and where a camera attitude in the
    earth frame goes (yaw/pitch/roll with the gimbal angles 0, as the README's drone rule says).
    gimbal_az keeps its plain suggestion."""
    from eoloc.io.table import unknown_columns
    from eoloc.io.telemetry import TELEMETRY_COLUMNS

    header = ["time_s", "lat_deg", "lon_deg", "h_m", "gimbal_pitch_deg", "camera_yaw", "gimbal_hdg", "gimbal_az"]
    said = unknown_columns(header, TELEMETRY_COLUMNS, {"time_s": 0, "lat_deg": 1, "lon_deg": 2, "h_m": 3},
                           "telemetry")
    assert len(said) == 4
    for msg in said[:3]:
        assert "'gimbal1_deg' (azimuth)" in msg and "'yaw_deg', 'pitch_deg', 'roll_deg'" in msg, msg
        assert "did you mean" not in msg
    assert "did you mean 'azimuth_deg', i.e. 'gimbal1_deg'?" in said[3]
