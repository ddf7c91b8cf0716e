"""The shell's promises (issue: CLI and job layer): the CSV reader's line accounting on hostile
files, strict configuration, one meaning per flag, --json in file mode, outputs through the writer
registry (CoT data package, KML, ISO 8601 times) - each through the real command line, asserting
exit code 2 and a message naming the fix, no traceback, and every good record kept."""

from __future__ import annotations

import csv
import json
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import eoloc
from eoloc.cli import main
from eoloc.io.config import ConfigError, load_config
from eoloc.io.telemetry import read_detections, read_telemetry

DEMO = Path(eoloc.__file__).parent / "data" / "demo"
HEADER = "time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg\n"
GOOD = "{t},45,7,3000,0,0,0,0,-45\n"


def _run(*args):
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert "Traceback" not in r.output
    return r


def test_quoted_newline_keeps_the_line_numbers_and_an_unterminated_quote_costs_one_line(tmp_path):
    p = tmp_path / "det.csv"
    p.write_text("time_s,target_id,u_px,v_px\n"
                 '0,"T\n1",10,20\n'        # lines 2-3: one record, its id spans a newline
                 "1,T2,11,21\n"            # line 4
                 '2,"T3,12,22\n'           # line 5: quote never closed
                 "3,T4,13,23\n"            # line 6
                 "4,T5,14,24\n")           # line 7
    t = read_detections(p)
    assert t.line.tolist() == [2, 4, 6, 7]
    assert t.columns["target_id"].tolist() == ["T\n1", "T2", "T4", "T5"]
    assert [(i.line, "unterminated quote" in i.message) for i in t.issues] == [(5, True)]


def test_comma_only_lines_non_finite_keys_and_fractional_frames_are_reported(tmp_path):
    p = tmp_path / "tel.csv"
    p.write_text(HEADER + GOOD.format(t=0) + ",,,,,,,,\n" + GOOD.format(t="inf") + GOOD.format(t="1e400")
                 + GOOD.format(t="Infinity") + GOOD.format(t=5))
    t = read_telemetry(p)
    assert t.line.tolist() == [2, 7]
    msgs = {i.line: i.message for i in t.issues}
    assert "only commas" in msgs[3]
    assert all("no usable time_s" in msgs[k] and "not a finite number" in msgs[k] for k in (4, 5, 6))
    d = tmp_path / "det.csv"
    d.write_text("frame,target_id,u_px,v_px\n1,A,10,20\n2.5,B,10,20\n3,C,inf,20\n")
    det = read_detections(d)
    assert det.line.tolist() == [2, 4] and np.isnan(det.columns["u_px"][1])  # the pixel: per-record status later
    text = " ".join(str(i) for i in det.issues)
    assert "2.5 is not a whole frame number" in text and "column 'u_px': inf is not a finite number" in text


def test_pyarrow_reader_agrees_with_the_csv_module_on_the_demo_files():
    for path, reader in ((DEMO / "telemetry.csv", read_telemetry), (DEMO / "detections.csv", read_detections)):
        t = reader(path)
        with path.open() as fh:
            rows = [r for r in csv.DictReader(line for line in fh if not line.startswith("#"))]
        assert len(t) == len(rows)
        for name in ("time_s", "u_px") if reader is read_detections else ("time_s", "lat_deg", "yaw_deg"):
            np.testing.assert_array_equal(t.columns[name], [float(r[name]) for r in rows])


@pytest.mark.parametrize("line, fix", [
    ("width = true", "valid integer"),
    ('width = "1024"', "valid integer"),
    ("focal_mm = \"50\"", "valid number"),
])
def test_config_types_are_not_coerced(tmp_path, line, fix):
    base = {"width": "width = 1024", "focal_mm": "focal_mm = 50"}
    key = line.split(" ")[0]
    base[key] = line
    p = tmp_path / "c.toml"
    p.write_text("[camera]\n" + "\n".join(base.values()) + "\nheight = 768\npixel_um = 5.5\n")
    with pytest.raises(ConfigError, match=fix):
        load_config(p)


def test_config_refuses_large_misalignments_unless_allowed(tmp_path):
    cam = "[camera]\nwidth = 1024\nheight = 768\nhfov_deg = 20\n"
    p = tmp_path / "c.toml"
    p.write_text(cam + "[installation]\nmount_misalignment_deg = [0, 90, 0]\n")
    with pytest.raises(ConfigError, match=r"small correction.*allow_large_misalignment"):
        load_config(p)
    p.write_text(cam + "[installation]\nmount_misalignment_deg = [0, 90, 0]\nallow_large_misalignment = true\n")
    assert load_config(p).installation.mount_misalignment_deg == (0, 90, 0)
    p.write_text(cam + "[installation]\nboresight_misalignment_deg = [1e9, 0, 0]\n")
    with pytest.raises(ConfigError, match="boresight_misalignment_deg"):
        load_config(p)
    p.write_text(cam + "[telemetry]\ntime_origin = \"yesterday\"\n")
    with pytest.raises(ConfigError, match="ISO 8601"):
        load_config(p)


def test_negative_range_is_refused_by_name_in_both_spellings():
    one = ["locate", "--lat", 45, "--lon", 7, "--aircraft-height", 1000, "--gimbal-angles", 0, -90]
    for spelling in (["--range=-5"], ["--range", "-5"]):
        r = _run(*one, *spelling)
        assert r.exit_code == 2 and "--range (the laser slant range along every ray, metres) must be > 0" in r.output \
            and "No such option" not in r.output
    r = _run(*one, "--range", "500", "--json")
    assert r.exit_code == 0 and json.loads(r.output)["range"] == pytest.approx(500.0)


def test_static_with_associate_is_refused():
    r = _run("track", DEMO / "telemetry.csv", DEMO / "detections.csv", "--config", DEMO / "camera.toml",
             "--target-height", 600, "--static", "--associate")
    assert r.exit_code == 2 and "--associate" in r.output and "--static" in r.output


def test_file_mode_json_kml_cot_and_utc_times(tmp_path):
    cfg = tmp_path / "camera.toml"
    cfg.write_text((DEMO / "camera.toml").read_text() + '\n[telemetry]\ntime_origin = "2026-11-23T09:30:00Z"\n')
    r = CliRunner().invoke(main, ["locate", str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config",
                                  str(cfg), "--target-height", "600", "--out", str(tmp_path / "o"), "--json",
                                  "-f", "csv", "-f", "kml", "-f", "cot"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    n_ok = doc["status_counts"]["OK"]
    assert len(doc["fixes"]) == len(read_detections(DEMO / "detections.csv"))
    first = doc["fixes"][0]
    from datetime import UTC, datetime

    t = datetime.fromisoformat(first["time_utc"].replace("Z", "+00:00"))
    assert (t - datetime(2026, 11, 23, 9, 30, tzinfo=UTC)).total_seconds() == pytest.approx(first["time_s"], abs=1e-3)
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["fixes.cot.zip", "fixes.csv", "fixes.kml"]
    with zipfile.ZipFile(tmp_path / "o" / "fixes.cot.zip") as zf:
        cots = [n for n in zf.namelist() if n.endswith(".cot")]
    assert len(cots) == len(set(cots)) == n_ok


RUN_COMMAND = """
import atexit, os, sys
atexit.register(lambda: print("loaded:", sorted(m for m in ("pandas", "numba", "eoloc.kernels.compiled", "rich.live",
                                                             "pyarrow.compute") if sys.modules.get(m) is not None),
                              "pydantic plugins:", os.environ.get("PYDANTIC_DISABLE_PLUGINS"), file=sys.stderr))
from eoloc.cli import run
sys.argv = ["eoloc", *sys.argv[1:]]
run()
"""


def test_the_command_loads_neither_pandas_nor_numba_for_work_numpy_does_faster(tmp_path):
    """The `eoloc` command on the demo files at a height: the same fixes.csv as the library in this
    process, without importing pandas (pyarrow would, where it is installed; eoloc does not use
    it) or loading numba (0.7-1.5 s to load for milliseconds of work: numpy runs it); off a
    terminal, without rich's live display (its spinner would show nothing there); without
    pyarrow.compute's 25 ms of function wrappers (eoloc.io.arrowfn calls the functions by name);
    and with pydantic's scan of every distribution for plugins turned off."""
    import subprocess
    import sys

    args = [str(DEMO / "telemetry.csv"), str(DEMO / "detections.csv"), "--config", str(DEMO / "camera.toml"),
            "--target-height", "600", "-f", "csv"]
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("EOLOC_BACKEND", "PYDANTIC_DISABLE_PLUGINS")}
    out = subprocess.run([sys.executable, "-c", RUN_COMMAND, "locate", *args, "--out", str(tmp_path / "cmd")],
                         capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert "loaded: [] pydantic plugins: __all__" in out.stderr, out.stderr
    r = CliRunner().invoke(main, ["locate", *args, "--out", str(tmp_path / "lib")])
    assert r.exit_code == 0, r.output
    with open(tmp_path / "cmd" / "fixes.csv") as a, open(tmp_path / "lib" / "fixes.csv") as b:
        rows_cmd, rows_lib = list(csv.DictReader(a)), list(csv.DictReader(b))
    assert len(rows_cmd) == len(rows_lib) == len(read_detections(DEMO / "detections.csv"))
    for x, y in zip(rows_cmd, rows_lib, strict=True):
        assert x["status"] == y["status"] and x["target_id"] == y["target_id"]
        for k in ("lat_deg", "lon_deg"):  # numpy and numba agree to 1e-8 m; the file rounds to 1e-9 deg
            assert x[k] == "" == y[k] or abs(float(x[k]) - float(y[k])) <= 2e-9
        for k in ("h_m", "range_m"):
            assert x[k] == "" == y[k] or abs(float(x[k]) - float(y[k])) <= 2e-4


_cell = st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
                  st.sampled_from(["", "x", "inf", "nan", " 3 ", "1e400", "-0"]))


@settings(max_examples=60, deadline=None)
@given(rows=st.lists(st.tuples(st.integers(0, 10**6).map(str) | _cell, _cell, _cell), min_size=1, max_size=40),
       at=st.integers(0, 40))
def test_clean_files_read_in_one_go_agree_with_the_line_by_line_path(tmp_path_factory, rows, at):
    """A file with no comment, quote or odd line is read by pyarrow in one go; a comment line
    sends the same content line by line. Both must keep the same records with the same values
    and report the same issues, at line numbers that differ by the comment's line exactly."""
    tmp = tmp_path_factory.mktemp("csv")
    lines = [f"{t},T,{u},{v}\n" for t, u, v in rows]
    at = min(at, len(lines))
    fast, slow = tmp / "fast.csv", tmp / "slow.csv"
    fast.write_text("time_s,target_id,u_px,v_px\n" + "".join(lines))
    slow.write_text("time_s,target_id,u_px,v_px\n" + "".join(lines[:at]) + "# a comment\n" + "".join(lines[at:]))
    a, b = read_detections(fast), read_detections(slow)
    shift = lambda n: n + (n >= at + 2)  # noqa: E731 - the comment sits on line at + 2
    assert [shift(n) for n in a.line.tolist()] == b.line.tolist()
    for name in ("time_s", "u_px", "v_px"):
        np.testing.assert_array_equal(a.columns[name], b.columns[name])
    np.testing.assert_array_equal(a.columns["time_s"], [float(rows[n - 2][0]) for n in a.line])  # Python's parse
    assert [(shift(i.line), i.message) for i in a.issues] == [(i.line, i.message) for i in b.issues]


_text = st.text(alphabet=st.sampled_from(list('ab ,"\n\r;é=-1.\'')), max_size=6)
_FORMULA = re.compile(r"'*[=+\-@\t\r]")  # OWASP's CSV injection rule: a spreadsheet reads these as formulas
_PLAIN_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _csv_cell(text: str) -> str:
    """A text cell as the CSV must hold it: after an apostrophe where it starts like a formula and
    is not a plain number (so -1.5 stays a number, =1 and -a become text in a spreadsheet)."""
    return "'" + text if _FORMULA.match(text) and not _PLAIN_NUMBER.fullmatch(text) else text


@settings(max_examples=60, deadline=None)
@given(floats=st.lists(st.floats(min_value=-1e9, max_value=1e9) | st.sampled_from([float("nan"), float("inf"),
                                                                                   -float("inf")]),
                      min_size=1, max_size=30),
       data=st.data())
def test_columnar_csv_reads_back_as_written(tmp_path_factory, floats, data):
    """Records -> write_csv (pyarrow, chunked on two threads) -> Python's csv module: every row
    there, text cells exact (commas, quotes, line breaks quoted), numbers within the stated
    rounding (9 decimals for *_deg, 4 otherwise), no value as an empty cell, booleans True/False."""
    from eoloc.io import csvfile
    from eoloc.io.records import Records

    n = len(floats)
    texts = data.draw(st.lists(st.none() | _text, min_size=n, max_size=n))
    flags = data.draw(st.lists(st.booleans(), min_size=n, max_size=n))
    recs = Records({"id": np.arange(n), "lat_deg": np.array(floats), "range_m": np.array(floats),
                    "note": np.array(texts, dtype=object), "ok": np.array(flags)})
    path = tmp_path_factory.mktemp("w") / "r.csv"
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = 7  # several chunks, rendered in parallel and written in order
    try:
        csvfile.write_csv(path, recs)
    finally:
        csvfile.CSV_CHUNK = old
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["id"]) for r in rows] == list(range(n))
    body = path.read_text(encoding="utf-8")
    assert all(f"\n{i}," in body for i in range(n))  # numbers are never quoted, even where text is
    for r, x, t, b in zip(rows, floats, texts, flags, strict=True):
        for key, tol in (("lat_deg", 0.5e-9), ("range_m", 0.5e-4)):
            if np.isnan(x):
                assert r[key] == ""
            elif np.isinf(x):
                assert float(r[key]) == x
            elif all(not np.isinf(y) and float(y) == round(float(y)) for y in floats if not np.isnan(y)):  # whole
                assert r[key] == str(round(x))
            else:
                assert abs(float(r[key]) - x) <= tol + 1e-15 * abs(x)
        assert r["note"] == ("" if t is None else _csv_cell(t))
        assert r["ok"] == str(b)


@settings(max_examples=40, deadline=None)
@given(names=st.lists(_text, min_size=1, max_size=5, unique=True), data=st.data())
def test_coded_text_columns_write_the_same_csv(tmp_path_factory, names, data):
    """A text column also held as codes into its names (statuses, ids as read) writes the very
    same CSV as the plain column: quoting of commas, quotes and line breaks included."""
    from eoloc.io import csvfile
    from eoloc.io.records import Coded, Records

    codes = np.array(data.draw(st.lists(st.integers(0, len(names) - 1), min_size=1, max_size=25)), dtype=np.int32)
    table = np.array(names, dtype=object)
    cols = {"id": np.arange(codes.size), "note": table[codes]}
    tmp = tmp_path_factory.mktemp("coded")
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = 4
    try:
        plain = csvfile.write_csv(tmp / "plain.csv", Records(cols))
        coded = csvfile.write_csv(tmp / "coded.csv", Records(cols, {"note": Coded(codes, table)}))
    finally:
        csvfile.CSV_CHUNK = old
    assert coded.read_bytes() == plain.read_bytes()


def test_text_columns_as_read_are_coded_consistently(tmp_path):
    """The reader's text columns come with their codes: names[codes] is the column, after the
    records without a usable key are dropped too."""
    from eoloc.io.telemetry import read_detections

    path = tmp_path / "d.csv"
    path.write_text("time_s,target_id,u_px,v_px\n1, A ,1,2\n2,B,3,4\n,A,5,6\n3,,7,8\n4,A,9,10\n")
    det = read_detections(path)
    assert det.columns["target_id"].tolist() == ["A", "B", "", "A"]
    c = det.coded["target_id"]
    assert (c.names[c.codes] == det.columns["target_id"]).all() and len(set(c.names.tolist())) == len(c.names)


@settings(max_examples=60, deadline=None)
@given(data=st.data(), n=st.integers(1, 12), width=st.integers(1, 6))
def test_csv_reads_back_in_any_column_order(tmp_path_factory, data, n, width):
    """Any order of column kinds (ints, floats with gaps, whole floats, one value throughout, no
    value at all, text with commas/quotes/line breaks, booleans, coded text), the last column and
    a lone column included: Python's csv module reads back every row and cell as meant."""
    from eoloc.io import csvfile
    from eoloc.io.records import Coded, Records

    kinds = data.draw(st.lists(st.sampled_from(["int", "float", "whole", "same", "none", "text", "bool", "coded"]),
                               min_size=width, max_size=width))
    cols, coded, want = {}, {}, {}
    for i, kind in enumerate(kinds):
        name = f"c{i}_deg" if i % 2 else f"c{i}"
        if kind == "int":
            v = np.array(data.draw(st.lists(st.integers(-2**62, 2**62), min_size=n, max_size=n)), dtype=np.int64)
            want[name] = [str(x) for x in v.tolist()]
        elif kind in ("float", "whole", "same", "none"):
            xs = data.draw(st.lists(st.floats(-1e6, 1e6) | st.just(float("nan")), min_size=n, max_size=n))
            v = {"float": np.array(xs), "whole": np.round(np.array(xs)), "same": np.full(n, 2.5),
                 "none": np.full(n, np.nan)}[kind]
            r = np.round(v, 9 if name.endswith("_deg") else 4)  # the stated rounding
            whole = all(x == int(x) for x in r.tolist() if not np.isnan(x))  # (|x| < 1e6 here: exact)
            want[name] = [None if np.isnan(x) else (float(x), whole) for x in r.tolist()]
        elif kind == "bool":
            v = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
            want[name] = [str(x) for x in v.tolist()]
        else:
            texts = data.draw(st.lists(_text, min_size=n, max_size=n))
            v = np.array(texts, dtype=object)
            if kind == "coded":
                table, codes = np.unique(np.array(texts, dtype=object).astype(str), return_inverse=True)
                coded[name] = Coded(codes.astype(np.int32), table.astype(object))
            want[name] = [_csv_cell(t) for t in texts]
        cols[name] = v
    tmp = tmp_path_factory.mktemp("order")
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = 5
    try:
        path = csvfile.write_csv(tmp / "o.csv", Records(cols, coded))
    finally:
        csvfile.CSV_CHUNK = old
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == list(cols) and len(rows) == n + 1
    for j, row in enumerate(rows[1:]):
        assert len(row) == len(cols)
        for cell, name in zip(row, cols, strict=True):
            expected = want[name][j]
            if expected is None:
                assert cell == ""
            elif isinstance(expected, tuple):
                value, whole = expected
                assert float(cell) == value and (("." not in cell and "e" not in cell) if whole else True)
            else:
                assert cell == expected
    assert path.read_bytes().endswith(b"\n")  # a blank line would have failed the row count above


def test_whole_number_columns_are_written_alike_in_every_chunk(tmp_path):
    """A float column of whole numbers is written as integers in every chunk (no value: empty);
    a column with one fraction, past its first chunk, keeps the float form everywhere."""
    from eoloc.io import csvfile
    from eoloc.io.records import Records

    frame = np.array([3.0, np.nan, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0])
    late = np.array([1.0] * 8 + [1.5])
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = 4
    try:
        path = csvfile.write_csv(tmp_path / "w.csv", Records({"frame": frame, "t_s": late}))
    finally:
        csvfile.CSV_CHUNK = old
    rows = [line.split(",") for line in path.read_text().splitlines()[1:]]
    assert [r[0] for r in rows] == ["3", "", "4", "5", "6", "7", "8", "9", "10"]
    assert [r[1] for r in rows] == ["1.0"] * 8 + ["1.5"]


def _digits(number: str) -> str:
    """The significant digits of a number's text (no sign, point, exponent or outer zeros)."""
    return number.lower().split("e")[0].lstrip("-").replace(".", "").strip("0")


@settings(max_examples=80, deadline=None)
@given(floats=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=40),
       ints=st.lists(st.integers(-2**63, 2**63 - 1), min_size=1, max_size=40), data=st.data())
def test_number_cells_are_the_shortest_round_trip(floats, ints, data):
    """eoloc's number formatter (orjson's Ryu, its output made a pyarrow string array of cells,
    each followed by its separator) against Python: every finite float reads back as exactly the
    same double, with the same significant digits as Python's repr (the shortest that do); every
    int64 as str(); cells marked missing are null; one value throughout is one scalar."""
    import pyarrow as pa

    from eoloc.io.csvfile import number_cells

    def texts(cells, sep=","):
        out = cells.to_pylist()
        assert all(c is None or c.endswith(sep) for c in out)
        return [None if c is None else c[:-1] for c in out]

    missing = np.array(data.draw(st.lists(st.booleans(), min_size=len(floats), max_size=len(floats))))
    for cell, x, gone in zip(texts(number_cells(np.array(floats), ",", missing)), floats, missing, strict=True):
        if gone:
            assert cell is None
        else:
            assert float(cell) == x and _digits(cell) == _digits(repr(x))
    many = np.array([*ints, ints[0] + 1 if ints[0] < 2**63 - 1 else 0], dtype=np.int64)  # two values at least
    assert texts(number_cells(many, "\n"), "\n") == [str(i) for i in many.tolist()]
    two = np.array([*floats, 1.5, 2.5])  # two values at least: an array, not one scalar
    strided = np.repeat(two, 2)[::2]  # not contiguous; and half precision, widened
    assert number_cells(strided).to_pylist() == number_cells(two).to_pylist()
    half = np.clip(two, -6e4, 6e4).astype(np.float16)  # finite in half precision
    assert [float(c) for c in texts(number_cells(half))] == half.astype(np.float64).tolist()
    same = number_cells(np.full(len(floats) + 1, floats[0]))  # one value throughout: made once
    assert isinstance(same, pa.StringScalar) and float(same.as_py()[:-1]) == floats[0]
    assert number_cells(np.zeros(0)).to_pylist() == [] and isinstance(number_cells(np.zeros(0)), pa.StringArray)


def test_records_from_rows_round_trip_and_streamed_geojson(tmp_path):
    """Dict rows -> Records -> rows gives the same values back (None for a missing key), and the
    streamed GeoJSON equals the features built in memory."""
    from eoloc.io.export import fix_features
    from eoloc.io.geojsonfile import write_fix_geojson
    from eoloc.io.records import Records

    rows = [{"target_id": "A", "lat_deg": 45.0, "lon_deg": 7.0, "h_m": 600.0, "status": "OK", "frame": 3},
            {"target_id": "B", "lat_deg": None, "lon_deg": None, "h_m": None, "status": "NO_INTERSECTION",
             "frame": 4, "extra": True}]
    recs = Records.from_rows(rows)
    assert recs["frame"].dtype == np.int64 and recs["lat_deg"].dtype == np.float64
    back = recs.rows()
    assert back[0] == {**rows[0], "extra": None} and back[1] == rows[1]
    path = write_fix_geojson(tmp_path / "f.geojson", recs, chunk=1)
    doc = json.loads(path.read_text())
    assert doc["features"] == fix_features(recs)
    assert doc["features"][0]["geometry"]["coordinates"] == [7.0, 45.0, 600.0]
    assert doc["features"][1]["geometry"] is None


@settings(max_examples=40, deadline=None)
@given(codes=st.lists(st.integers(0, 8), max_size=60))
def test_status_counts_count_every_status(codes):
    """Fixes.status_counts against Python's Counter: the statuses that occur, each counted."""
    from collections import Counter

    from eoloc.result import Fixes, Status

    n = len(codes)
    fixes = Fixes(np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.array(codes, dtype=np.int8))
    assert fixes.status_counts() == {Status(c).name: k for c, k in Counter(codes).items()}


@settings(max_examples=60, deadline=None)
@given(texts=st.lists(st.one_of(st.none(), st.text(max_size=6), st.sampled_from(['a,b', '"q"', " x ", "", "\n"])),
                      min_size=1, max_size=40),
       numbers=st.lists(st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=True, width=64)), min_size=1,
                        max_size=40),
       seed=st.integers(0, 2**32 - 1))
def test_compute_functions_called_by_name_equal_pyarrow_compute(texts, numbers, seed):
    """eoloc.io.arrowfn (pyarrow's compute functions by name, without importing pyarrow.compute)
    against pyarrow.compute's own wrappers, on the same arrays: text, numbers with nulls and
    infinities, and every option the CSV reader and writer use."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from eoloc.io import arrowfn

    text, num = pa.array(texts, type=pa.string()), pa.array(numbers, type=pa.float64())
    idx = pa.array(np.random.default_rng(seed).integers(0, len(texts), 25))
    pairs = [
        (arrowfn.fill_null(text, "-"), pc.fill_null(text, "-")),
        (arrowfn.cast(num, pa.string()), num.cast(pa.string())),
        (arrowfn.is_null(num), num.is_null()),
        (arrowfn.dictionary_encode(text), text.dictionary_encode()),
        (arrowfn.utf8_trim_whitespace(text), pc.utf8_trim_whitespace(text)),
        (arrowfn.take(text, idx), pc.take(text, idx)),
        (arrowfn.join_cells(text, text, ";"), pc.binary_join_element_wise(text, text, ";")),
        (arrowfn.join_cells(text, "<", ""), pc.binary_join_element_wise(text, "<", "")),
        (arrowfn.join_cells(text, text, "", null_replacement="~"),
         pc.binary_join_element_wise(text, text, "", null_handling="replace", null_replacement="~")),
        (arrowfn.matches(text, '[,"\r\n]'), pc.match_substring_regex(text, '[,"\r\n]')),
        (arrowfn.replace_all(text, '"', '""'), pc.replace_substring(text, '"', '""')),
        (arrowfn.equal(text, ""), pc.equal(text, "")),
        (arrowfn.or_(arrowfn.equal(text, ""), arrowfn.is_null(text)), pc.or_(pc.equal(text, ""), text.is_null())),
        (arrowfn.if_else(text.is_null(), "none", text), pc.if_else(text.is_null(), "none", text)),
    ]
    for k, (ours, theirs) in enumerate(pairs):
        assert ours.equals(theirs), (k, ours, theirs)
    assert arrowfn.any_true(pc.equal(text, "")) is bool(pc.any(pc.equal(text, "")).as_py())
    with pytest.raises(pa.ArrowInvalid):
        arrowfn.cast(pa.array(["1.5", "x"]), pa.float64())


def test_columns_a_file_lacks_are_one_value_with_no_memory(tmp_path):
    """A detections file without range_m and frame: those columns are NaN for every record, as a
    read-only view of one value (no 8 MB column per million records)."""
    path = tmp_path / "det.csv"
    path.write_text("time_s,target_id,u_px,v_px\n" + "".join(f"{k * 0.04:.2f},T{k % 3},{k},{k}\n" for k in range(500)))
    t = read_detections(path)
    assert len(t) == 500
    for name in ("range_m", "frame"):
        col = t.columns[name]
        assert col.shape == (500,) and np.isnan(col).all() and col.strides == (0,) and not col.flags.writeable
    kept = t.keep(np.arange(500) % 2 == 0)  # a selection of them is an ordinary array
    assert kept.columns["frame"].shape == (250,) and np.isnan(kept.columns["frame"]).all()


@settings(max_examples=80, deadline=None)
@given(values=st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                                 st.floats(-1e6, 1e6), st.sampled_from([1e306, -1.7e308, 2.0**52, 2.0**53 + 2])),
                       min_size=1, max_size=60),
       name=st.sampled_from(["x_m", "lat_deg"]))
def test_every_finite_number_is_written_as_itself_rounded_however_large(values, name, tmp_path_factory):
    """A float column of any values (huge ones, infinities, gaps) read back with Python's csv
    module: each cell is the number to the column's decimals (half a unit of the last decimal,
    and the double's own spacing), a number of 2^52 or more exactly itself, an infinity "inf",
    a gap empty; never "null" (numpy's rounding scales 1e306 to infinity first)."""
    from eoloc.io.csvfile import decimals, write_csv
    from eoloc.io.records import Records

    path = tmp_path_factory.mktemp("big") / "big.csv"
    v = np.array(values, dtype=np.float64)
    write_csv(path, Records({name: v}))
    with open(path, newline="") as fh:
        cells = [row[name] for row in csv.DictReader(fh)]
    assert len(cells) == len(v)
    step = 10.0 ** -decimals(name)
    for x, cell in zip(v.tolist(), cells, strict=True):
        if np.isnan(x):
            assert cell in ("", '""'), (x, cell)
        elif np.isinf(x):
            assert cell == ("inf" if x > 0 else "-inf"), (x, cell)
        elif abs(x) >= 2.0**52:
            assert float(cell) == x, (x, cell)
        else:
            assert abs(float(cell) - x) <= step / 2 * (1 + 1e-9) + 4 * np.spacing(abs(x)), (x, cell)


@settings(max_examples=80, deadline=None)
@given(chunks=st.lists(st.lists(st.one_of(st.none(), st.sampled_from(["T1", " T1", "T1 ", "\tT2", "T2", " ", "a b"]),
                                          st.text(max_size=4)), max_size=30),
                       min_size=1, max_size=4))
def test_text_cells_are_the_stripped_cells_each_name_once(chunks):
    """A text column read as codes into its names: names[codes] are the cells stripped of
    surrounding white space as Python strips them ("" where there is no value), and no name
    twice (cells that differ only by spaces share one)."""
    import pyarrow as pa

    from eoloc.io.table import text_cells

    coded = text_cells(pa.chunked_array([pa.array(c, type=pa.string()) for c in chunks], type=pa.string()))
    want = [("" if x is None else x.strip()) for c in chunks for x in c]
    assert coded.names[coded.codes].tolist() == want if want else len(coded.codes) == 0
    assert len(set(coded.names.tolist())) == len(coded.names)
