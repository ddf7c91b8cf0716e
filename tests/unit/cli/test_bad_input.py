"""Every command of the README against bad input, through the real command line.

Each case is a command (as the README runs it, on the bundled demo data) with one input spoilt:
a telemetry, detections, GCP or observations file that is missing, a folder, UTF-16, empty,
header-only or without the needed columns; a config that is missing, a folder, not UTF-8, not
TOML, with a coerced type or an implausible value; a DEM that is a picture or missing; an output
folder under a file. Each must end with exit code 2 and a message naming the file and the
problem, never a traceback. A file with bad lines among good ones must instead keep every good
record: the command succeeds, names each bad line, and writes as many rows as with the clean file.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from where import DATA

import eoloc
from eoloc.cli import main

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
KLV = DATA / "klv"

# The README's commands on the demo data; {name} is a file of the `files` fixture.
COMMANDS = {
    "locate": ["locate", "{tel}", "{det}", "--config", "{cfg}", "--target-height", "600", "--out", "{out}"],
    "locate-dem": ["locate", "{tel}", "{det}", "--config", "{cfg}", "--dem", "{dem}", "--out", "{out}"],
    "footprint": ["footprint", "{tel}", "--config", "{cfg}", "--target-height", "600", "--out", "{out}"],
    "track": ["track", "{tel}", "{det}", "--config", "{cfg}", "--target-height", "600", "--out", "{out}"],
    "track-static": ["track", "{tel}", "{det}", "--config", "{cfg}", "--target-height", "600", "--static",
                     "--out", "{out}"],
    "triangulate": ["triangulate", "{tel}", "{det}", "--config", "{cfg}", "--out", "{out}"],
    "calibrate": ["calibrate", "{tel}", "{gcps}", "--config", "{cfg}", "--out", "{out}"],
    "rectify": ["rectify", "{img}", "--config", "{cfg}", "--telemetry", "{tel}", "--time", "4",
                "--target-height", "600", "--out", "{out}"],
    "compensate-train": ["compensate", "train", "{obs}", "--config", "{cfg}", "--target-height", "600",
                         "--out", "{out}", "-o", "{out}/model.json"],
    "accuracy": ["accuracy", "{cfg}", "-n", "200", "--no-sensitivity", "--no-plots", "--out", "{out}"],
    "klv": ["klv", "{klv}", "--out", "{out}"],
    "batch": ["batch", "{klv}", "--out", "{out}"],
    "map": ["map", "--telemetry", "{tel}", "-o", "{out}/map.html"],
    "evaluate": ["evaluate", "{fixes}", "--truth", "{truth}", "--bootstrap", "50", "--no-plots", "--out", "{out}"],
    "report": ["report", "{obs}", "--config", "{cfg}", "--bootstrap", "50", "--out", "{out}"],
    "video": ["video", "{ts}", "--target-height", "0", "--every", "10", "--out", "{out}"],
    "video-tel": ["video", "{ts}", "--telemetry", "{tel}", "--config", "{cfg}", "--target-height", "600", "--every",
                  "10", "--no-mosaic", "--out", "{out}"],
}
READS_TELEMETRY = ["locate", "footprint", "track", "triangulate", "calibrate", "rectify", "video-tel"]
READS_CONFIG = ["locate", "footprint", "track", "triangulate", "calibrate", "rectify", "video-tel", "compensate-train",
                "accuracy", "report"]
WRITES_OUT = ["locate", "footprint", "track", "track-static", "triangulate", "calibrate", "rectify", "video",
              "compensate-train", "accuracy", "klv", "batch", "evaluate", "report"]
READS_DEM = ["locate-dem"]
CONFIG = (DEMO / "camera.toml").read_text(encoding="utf-8")
ACCURACY = """
[accuracy.pose]
lat_deg = 35.12
lon_deg = 112.66
h_m = 2600.0
yaw_deg = 30.0
pitch_deg = 1.0
roll_deg = 0.0
gimbal_deg = [20.0, -60.0]

[accuracy]
stop = {target_height_m = 600.0}
"""


def _run(args: list[str]):
    r = CliRunner().invoke(main, args)
    assert "Traceback" not in r.output, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    return r


def _rows(path: Path) -> tuple[int, int]:
    """(rows, rows with status OK) of an output CSV."""
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return len(rows), sum(r.get("status", "OK") == "OK" for r in rows)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The demo's files, plus the inputs the other commands take, all from the demo flight."""
    d = tmp_path_factory.mktemp("inputs")
    truth = {r["target_id"]: r for r in csv.DictReader((DEMO / "truth.csv").open())}
    det = list(csv.DictReader(line for line in (DEMO / "detections.csv").open() if not line.startswith("#")))
    gcps = d / "gcps.csv"
    with gcps.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "gcp_id", "u_px", "v_px", "lat_deg", "lon_deg", "h_m"])
        for r in det[:40]:
            t = truth[r["target_id"]]
            w.writerow([r["time_s"], r["target_id"], r["u_px"], r["v_px"], t["lat_deg"], t["lon_deg"], t["h_m"]])
    cfg = d / "camera.toml"
    cfg.write_text(CONFIG + ACCURACY, encoding="utf-8")
    import warnings

    import rasterio

    img = d / "frame.png"
    with warnings.catch_warnings():  # a frame has no georeferencing: that is the point of rectify
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(img, "w", driver="PNG", width=1024, height=768, count=1, dtype="uint8") as ds:
            ds.write((np.indices((768, 1024)).sum(axis=0) % 256).astype(np.uint8), 1)
    sim = d / "cal"
    r = CliRunner().invoke(main, ["compensate", "simulate", "--config", str(cfg), "--flights", "2",
                                  "--test-flights", "0", "--looks", "20", "--out", str(sim)])
    assert r.exit_code == 0, r.output
    fixes = d / "fixes.csv"
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config",
                                  str(cfg), "--target-height", "600", "--out", str(d)])
    assert r.exit_code == 0, r.output
    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.io.klv.reader import split_klv
    from eoloc.io.klv.synthetic import circling_flight_klv

    ts = write_klv_ts(d / "flight.ts", [split_klv(circling_flight_klv(30))], video_fps=10)
    return {"tel": DEMO / "telemetry.csv", "det": DEMO / "detections.csv", "cfg": cfg, "gcps": gcps, "img": img,
            "ts": ts,
            "fixes": fixes, "truth": DEMO / "truth.csv",
            "obs": sim / "train.csv", "dem": sim / "dem.tif",
            "klv": KLV / "realflight.bin" if (KLV / "realflight.bin").exists() else next(KLV.glob("*.bin"))}


def _args(command: str, files: dict, out: Path, **spoilt) -> list[str]:
    names = {**{k: str(v) for k, v in files.items()}, "out": str(out), **{k: str(v) for k, v in spoilt.items()}}
    return [a.format(**names) for a in COMMANDS[command]]


def test_every_command_runs_on_the_good_inputs(files, tmp_path):
    """The baseline the bad cases are measured against: every command succeeds on them."""
    for command in COMMANDS:
        r = _run(_args(command, files, tmp_path / command))
        assert r.exit_code == 0, (command, r.output)


# -- a spoilt input file: exit 2 and the file and the problem named -------------------------------

UTF16 = "time_s,lat_deg\n0,45\n"


def _spoil(kind: str, d: Path) -> tuple[Path, str]:
    """A bad input file of ``kind`` and the words the message must contain."""
    p = d / f"{kind}.csv"
    if kind == "missing":
        return p, "does not exist"
    if kind == "folder":
        p.mkdir()
        return p, "is a "  # folder (eoloc) or directory (click's check of the argument)
    if kind == "utf16":
        p.write_text(UTF16, encoding="utf-16")
        return p, "UTF-16"
    if kind == "empty":
        p.write_text("", encoding="utf-8")
        return p, "empty"
    if kind == "header-only":
        p.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg,target_id,"
                     "u_px,v_px,gcp_id,gcp_lat_deg,gcp_lon_deg,gcp_h_m\n", encoding="utf-8")
        return p, "no usable"
    if kind == "wrong-columns":
        p.write_text("a,b,c\n1,2,3\n", encoding="utf-8")
        return p, "lacks required column"
    if kind == "binary":
        p.write_bytes(bytes(range(256)) * 8)
        return p, "is not text"
    raise AssertionError(kind)


SPOILS = ["missing", "folder", "utf16", "empty", "header-only", "wrong-columns", "binary"]


# -- a spoilt config -----------------------------------------------------------------------------

def _bad_config(kind: str, d: Path) -> tuple[Path, str]:
    p = d / f"{kind}.toml"
    text = CONFIG + ACCURACY
    if kind == "missing":
        return p, "does not exist"
    if kind == "folder":
        p.mkdir()
        return p, "is a "
    if kind == "latin1":
        p.write_bytes(text.replace("# Demo sensor", "# Démo sensor").encode("latin-1"))
        return p, "not UTF-8"
    if kind == "not-toml":
        p.write_text("[camera\nwidth = 1024\n", encoding="utf-8")
        return p, "not valid TOML"
    if kind == "bool-width":
        p.write_text(text.replace("width = 1024", "width = true"), encoding="utf-8")
        return p, "width"
    if kind == "string-focal":
        p.write_text(text.replace("focal_mm = 50.0", 'focal_mm = "50"'), encoding="utf-8")
        return p, "focal_mm"
    if kind == "big-misalignment":
        p.write_text(text.replace("mount_misalignment_deg = [0.0, 0.0, 0.0]",
                                  "mount_misalignment_deg = [0.0, 90.0, 0.0]"), encoding="utf-8")
        return p, "allow_large_misalignment"
    if kind == "nan-bias":
        p.write_text(text + "\n[telemetry]\nheading_bias_deg = nan\n", encoding="utf-8")
        return p, "heading_bias_deg"
    if kind == "nan-distortion":
        p.write_text(text.replace("[gimbal]", "[camera.distortion]\nmodel = \"ratio\"\n"
                                              "radius_mm = [0.0, 1.0, 2.0]\nratio = [0.0, nan, 0.01]\n\n[gimbal]"),
                     encoding="utf-8")
        return p, "ratio"
    raise AssertionError(kind)


CONFIG_SPOILS = ["missing", "folder", "latin1", "not-toml", "bool-width", "string-focal", "big-misalignment",
                 "nan-bias", "nan-distortion"]


SPOILT = ([(command, "tel", kind) for command in READS_TELEMETRY for kind in SPOILS]
          + [(command, slot, kind) for command, slot in (("locate", "det"), ("track", "det"), ("triangulate", "det"),
                                                         ("calibrate", "gcps"), ("compensate-train", "obs"),
                                                         ("evaluate", "fixes"), ("evaluate", "truth"),
                                                         ("report", "obs"))
             for kind in SPOILS]
          + [(command, "cfg", kind) for command in READS_CONFIG for kind in CONFIG_SPOILS])


@pytest.mark.parametrize("command, slot, kind", SPOILT)
def test_a_spoilt_input_is_named_with_its_problem(files, tmp_path, command, slot, kind):
    """Telemetry, the second file (detections, GCPs, observations) and the config, each spoilt
    in every way above, in every command that reads it."""
    bad, words = (_bad_config if slot == "cfg" else _spoil)(kind, tmp_path)
    r = _run(_args(command, files, tmp_path / "out", **{slot: bad}))
    assert r.exit_code == 2 and words in r.output and bad.name in r.output, (command, kind, r.output)


def test_errors_come_in_order_while_the_detections_are_read_ahead(files, tmp_path):
    """`eoloc locate` reads the detections on a thread while the config loads: a bad config is
    still reported before bad detections, and bad telemetry before them too."""
    det, det_words = _spoil("utf16", tmp_path)
    cfg, cfg_words = _bad_config("bool-width", tmp_path)
    tel = tmp_path / "no-telemetry.csv"
    for spoilt, name, words in (({"det": det, "cfg": cfg}, cfg.name, cfg_words),
                                ({"det": det, "tel": tel}, tel.name, "does not exist"),
                                ({"det": det}, det.name, det_words)):
        r = _run(_args("locate", files, tmp_path / "out", **spoilt))
        assert r.exit_code == 2 and words in r.output and name in r.output, r.output
        assert all(str(p.name) not in r.output for p in spoilt.values() if p.name != name), r.output


# -- outputs and DEMs -------------------------------------------------------------------------------

@pytest.mark.parametrize("command", WRITES_OUT)
def test_an_output_folder_under_a_file_is_named(files, tmp_path, command):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder", encoding="utf-8")
    r = _run(_args(command, files, blocker / "out"))
    assert r.exit_code == 2 and "a-file" in r.output, (command, r.output)


@pytest.mark.parametrize("kind, words", [("picture", "not a terrain model"), ("missing", "does not exist")])
@pytest.mark.parametrize("command", READS_DEM)
def test_a_bad_dem_is_named(files, tmp_path, command, kind, words):
    dem = files["img"] if kind == "picture" else tmp_path / "N00E000.tif"
    r = _run(_args(command, files, tmp_path / "out", dem=dem))
    assert r.exit_code == 2 and words in r.output and dem.name in r.output, (command, kind, r.output)


# -- bad lines among good ones: every good record kept ----------------------------------------------

def _dirty_telemetry(d: Path) -> tuple[Path, list[int]]:
    """The demo telemetry with bad lines added at its end: a Latin-1 byte, a 200 000-digit field,
    a line of commas, a short line, an infinite time. Returns the file and the added lines."""
    clean = (DEMO / "telemetry.csv").read_bytes()
    n = clean.count(b"\n")
    header = next(line for line in clean.decode().splitlines() if not line.startswith("#"))
    width = header.count(",") + 1
    bad = [b"99,35.1,112.6,2600,0,0,0,0,-60,1000 caf\xe9", b"98," + b"9" * 200_000 + b",112.6,2600,0,0,0,0,-60,1000",
           b"," * (width - 1), b"97,35.1", b"inf,35.1,112.6,2600,0,0,0,0,-60,1000"]
    p = d / "dirty.csv"
    p.write_bytes(clean + b"\n".join(bad) + b"\n")
    return p, list(range(n + 1, n + 1 + len(bad)))


@pytest.mark.parametrize("command, product", [("locate", "fixes.csv"), ("footprint", "footprints.csv"),
                                              ("track", "track_fixes.csv"), ("triangulate", "triangulated.csv")])
def test_bad_lines_cost_only_themselves(files, tmp_path, command, product):
    dirty, lines = _dirty_telemetry(tmp_path)
    good = _run(_args(command, files, tmp_path / "good"))
    r = _run(_args(command, files, tmp_path / "dirty", tel=dirty))
    assert good.exit_code == 0 and r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    for n in lines:
        assert f"dirty.csv:{n}:" in text, (n, r.output)
    # every good record's row is there; a record kept with a bad cell has a row too, never an OK one
    (n_dirty, ok_dirty), (n_good, ok_good) = _rows(tmp_path / "dirty" / product), _rows(tmp_path / "good" / product)
    assert ok_dirty == ok_good and n_good <= n_dirty <= n_good + len(lines)


# -- streams, maps and clusters -------------------------------------------------------------------

@pytest.mark.parametrize("command, make, words", [
    ("klv", lambda d: d / "none.klv", "No such file"),
    ("klv", lambda d: _text(d / "text.klv", "time_s,lat_deg\n0,45\n"), "no MISB ST 0601 packet"),
    ("klv", lambda d: _text(d / "empty.ts", ""), "is empty"),
    ("map", lambda d: _text(d / "fixes.geojson", "{not json"), "fixes.geojson"),
    ("map", lambda d: _text(d / "fixes.geojson", '{"type": "Point"}'), "fixes.geojson"),
])
def test_a_bad_stream_or_layer_is_named(files, tmp_path, command, make, words):
    bad = make(tmp_path)
    args = (["klv", str(bad), "--out", str(tmp_path / "out")] if command == "klv" else
            ["map", "--fixes", str(bad), "-o", str(tmp_path / "map.html")])
    r = _run(args)
    assert r.exit_code == 2 and words in r.output and bad.name in r.output, r.output


def test_a_bad_video_is_named(files, tmp_path):
    """A video that is missing, not a video, without metadata, or cut short: exit 2 and the file
    named, or (cut short mid-packet) the torn bytes named and every frame with metadata rectified."""
    from eoloc.io.klv.mux import write_klv_ts

    plain = write_klv_ts(tmp_path / "plain.ts", [], video_fps=10, duration_s=1.0)
    cases = [(tmp_path / "none.ts", "does not exist"), (plain, "no KLV metadata stream"),
             (_text(tmp_path / "text.ts", "not a video\n"), "cannot be opened")]
    for bad, words in cases:
        r = _run(["video", str(bad), "--out", str(tmp_path / "out")])
        assert r.exit_code == 2 and words in r.output and bad.name in r.output, r.output
    data = Path(files["ts"]).read_bytes()
    cut = tmp_path / "cut.ts"
    cut.write_bytes(data[: (len(data) // 2 // 188) * 188 + 100])  # half the stream, the last packet torn
    r = _run(["video", str(cut), "--target-height", "0", "--out", str(tmp_path / "cut")])
    assert r.exit_code == 0 and "cut short" in r.output, r.output
    rows, ok = _rows(tmp_path / "cut" / "frames.csv")
    assert rows >= 10 and ok >= rows - 1  # a frame after the last KLV packet that survived has no pose


def _text(p: Path, text: str) -> Path:
    p.write_text(text, encoding="utf-8")
    return p


def test_an_unreachable_dask_scheduler_is_named(files, tmp_path):
    r = _run(["accuracy", "--scenario", "s13", "-n", "100", "--no-sensitivity", "--no-plots", "--dask",
              "tcp://127.0.0.1:1", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "127.0.0.1:1" in r.output, r.output


def test_batch_names_each_bad_stream_and_keeps_going(files, tmp_path):
    """The bad streams of the KLV cases above, all in one batch with a good one: each is listed
    with its reason, the good one is done, exit code 2."""
    d = tmp_path / "in"
    d.mkdir()
    (d / "good.klv").write_bytes(Path(files["klv"]).read_bytes())
    _text(d / "text.klv", "time_s,lat_deg\n0,45\n")
    _text(d / "empty.ts", "")
    r = _run(["batch", str(d), "--out", str(tmp_path / "out")])
    assert r.exit_code == 2, r.output
    with (tmp_path / "out" / "batch_status.csv").open(encoding="utf-8") as fh:
        status = {Path(r["path"]).name: r for r in csv.DictReader(fh)}
    assert status["good.klv"]["status"] == "done"
    assert status["text.klv"]["status"] == "failed" and "no MISB ST 0601 packet" in status["text.klv"]["message"]
    assert status["empty.ts"]["status"] == "failed" and "is empty" in status["empty.ts"]["message"]
    r = _run(["batch", str(d / "good.klv"), "--out", str(tmp_path / "out2"), "--dask", "tcp://127.0.0.1:1"])
    assert r.exit_code == 2 and "127.0.0.1:1" in r.output, r.output
