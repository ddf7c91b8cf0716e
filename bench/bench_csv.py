"""CSV reading: eoloc's telemetry reader (line accounting + pyarrow + value checks) against
pyarrow.csv reading the same file with no checks, alternated in one run (goal <= 3x); and
`eoloc locate` on 10^5 telemetry + 10^6 detections against pandas reading the two files, five
alternated pairs, median ratio (goal <= 10x, peak memory <= 1.5 GB); and the GeoJSON of 10^6
fixes (`eoloc locate`'s other default format) against Python's json module writing the same
features one by one.

    python bench/bench_csv.py [--lines 1000000]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import HEADER, machine, row

TEL_COLUMNS = ("time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "azimuth_deg",
               "elevation_deg")


def telemetry_file(path: Path, n: int, seed: int = 0) -> Path:
    import pyarrow as pa
    from pyarrow import csv as pacsv

    rng = np.random.default_rng(seed)
    cols = {"time_s": np.arange(n) * 0.04, "lat_deg": 45 + rng.normal(0, 0.01, n),
            "lon_deg": 7 + rng.normal(0, 0.01, n),
            "h_m": 3000 + rng.normal(0, 5, n), "yaw_deg": rng.uniform(0, 360, n), "pitch_deg": rng.normal(0, 2, n),
            "roll_deg": rng.normal(0, 2, n), "azimuth_deg": rng.uniform(-180, 180, n),
            "elevation_deg": rng.uniform(-90, -20, n)}
    pacsv.write_csv(pa.table(cols), path, pacsv.WriteOptions(quoting_style="none"))
    return path


def detections_file(path: Path, n: int, n_tel: int, seed: int = 1) -> Path:
    import pyarrow as pa
    from pyarrow import csv as pacsv

    rng = np.random.default_rng(seed)
    rec = rng.integers(0, n_tel, n)
    cols = {"time_s": rec * 0.04, "target_id": pa.array([f"T{k}" for k in rng.integers(0, 50, n)]),
            "u_px": rng.uniform(0, 1023, n), "v_px": rng.uniform(0, 767, n)}
    pacsv.write_csv(pa.table(cols), path, pacsv.WriteOptions(quoting_style="none"))
    return path


def read_pair(path: Path, repeat: int = 3) -> tuple[float, float]:
    """(eoloc, pyarrow) best times, alternated."""
    from pyarrow import csv as pacsv

    from eoloc.io.telemetry import read_telemetry

    read_telemetry(path)
    pacsv.read_csv(path)
    te, tp = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        t = read_telemetry(path)
        te.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        pacsv.read_csv(path)
        tp.append(time.perf_counter() - t0)
    assert len(t) > 0 and not t.issues
    return min(te), min(tp)


def locate_pair(tel: Path, det: Path, out: Path, repeat: int = 5) -> tuple[float, float, float, float]:
    """`eoloc locate` against pandas reading both files, alternated ``repeat`` times: (median
    ratio, median eoloc wall s, its peak RSS in MB (largest), median pandas s)."""
    import pandas as pd

    cfg = Path(__file__).parents[1] / "src" / "eoloc" / "data" / "demo" / "camera.toml"
    walls, pandas_s, peaks = [], [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        pd.read_csv(tel)
        pd.read_csv(det)
        pandas_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", _PEAK_REPORTING_EOLOC, "locate", str(tel), str(det), "--config",
                               str(cfg), "--target-height", "600", "--out", str(out), "-f", "csv"], check=True,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        walls.append(time.perf_counter() - t0)
        peaks.append([int(line.split()[1]) for line in done.stderr.splitlines() if line.startswith("VmHWM:")][-1])
    ratio = float(np.median(np.array(walls) / np.array(pandas_s)))
    return ratio, float(np.median(walls)), max(peaks) / 1024, float(np.median(pandas_s))


# the eoloc console script (eoloc.cli.run), reporting its own peak resident size as it exits. Not
# getrusage(RUSAGE_CHILDREN): a child's ru_maxrss starts from the resident size of the process it
# was forked from (this benchmark, with pandas and the files in memory: +300 MB); VmHWM is the
# peak of the command's own address space
_PEAK_REPORTING_EOLOC = """
import atexit, sys
from pathlib import Path

def _peak():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            print(line, file=sys.stderr)

atexit.register(_peak)
sys.argv[0] = "eoloc"
from eoloc.cli import run
run()
"""


def fix_records(n: int, seed: int = 2):
    """Records shaped like `eoloc locate`'s fixes (ids and statuses coded, as the job makes them)."""
    from eoloc.io.export import STATUS_NAMES
    from eoloc.io.records import Coded, Records

    rng = np.random.default_rng(seed)
    ids = np.array([f"T{k}" for k in range(50)], dtype=object)
    id_codes = rng.integers(0, 50, n).astype(np.int32)
    status = np.where(rng.random(n) < 0.97, 0, 3).astype(np.int8)
    ok = status == 0
    cols = {"line": np.arange(2, n + 2), "time_s": np.round(rng.uniform(0, 4000, n), 2), "frame": np.full(n, np.nan),
            "target_id": ids[id_codes], "u_px": rng.uniform(0, 1023, n), "v_px": rng.uniform(0, 767, n),
            "record_line": rng.integers(2, 100_002, n), "lat_deg": np.where(ok, 45 + rng.normal(0, 0.02, n), np.nan),
            "lon_deg": np.where(ok, 7 + rng.normal(0, 0.02, n), np.nan), "h_m": np.where(ok, 600.0, np.nan),
            "range_m": np.where(ok, rng.uniform(2000, 8000, n), np.nan), "status": STATUS_NAMES[status]}
    return Records(cols, {"target_id": Coded(id_codes, ids), "status": Coded(status, STATUS_NAMES)})


def geojson_pair(out: Path, n: int = 1_000_000) -> tuple[float, float]:
    """(eoloc's GeoJSON writer, Python's json module feature by feature) seconds on n fixes."""
    import json

    from eoloc.io.export import fix_features
    from eoloc.io.geojsonfile import write_fix_geojson

    recs = fix_records(n)
    write_fix_geojson(out / "warm.geojson", fix_records(1000))
    t0 = time.perf_counter()
    write_fix_geojson(out / "eoloc.geojson", recs)
    t_eoloc = time.perf_counter() - t0
    t0 = time.perf_counter()
    with (out / "json.geojson").open("w") as fh:  # the hand-written way: one dict and one dumps per feature
        fh.write('{"type": "FeatureCollection", "features": [\n')
        for start in range(0, n, 65536):
            feats = fix_features(recs.slice(start, start + 65536))
            fh.write(",\n".join(json.dumps(f) for f in feats))
        fh.write("\n]}\n")
    t_json = time.perf_counter() - t0
    assert len(json.loads((out / "eoloc.geojson").read_bytes())["features"]) == n
    return t_eoloc, t_json


def main(lines: int = 1_000_000, locate: bool = True) -> list[str]:
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        tel = telemetry_file(tmp / "tel.csv", lines)
        te, tp = read_pair(tel)
        mb = tel.stat().st_size / 1e6
        out.append(row(f"read {lines:,} telemetry lines ({mb:.0f} MB), every line checked", f"{te:.2f} s",
                       f"pyarrow.csv, no checks: {tp:.2f} s", tp / te))
        print(f"csv read: eoloc {te:.2f} s, pyarrow {tp:.2f} s, eoloc/pyarrow {te / tp:.2f}x (goal <= 3x)",
              file=sys.stderr)
        if locate:
            tel5 = telemetry_file(tmp / "tel5.csv", 100_000)
            det = detections_file(tmp / "det.csv", 1_000_000, 100_000)
            ratio, wall, peak, t_pd = locate_pair(tel5, det, tmp / "out")
            out.append(row("eoloc locate: 10^5 telemetry + 10^6 detections, M3, fixes.csv (median of 5 alternated)",
                           f"{wall:.2f} s, peak {peak:.0f} MB", f"pandas reading both files: {t_pd:.2f} s",
                           1 / ratio))
            print(f"locate: {wall:.2f} s = {ratio:.1f}x pandas' read (median of 5 alternated pairs; goal <= 10x), "
                  f"peak {peak:.0f} MB (goal <= 1500)", file=sys.stderr)
            t_eoloc, t_json = geojson_pair(tmp)
            out.append(row("GeoJSON of 10^6 fixes (write_fix_geojson)", f"{t_eoloc:.2f} s",
                           f"json module, feature by feature: {t_json:.1f} s", t_json / t_eoloc))
            print(f"geojson: eoloc {t_eoloc:.2f} s, json module {t_json:.1f} s, {t_json / t_eoloc:.0f}x faster",
                  file=sys.stderr)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=1_000_000)
    ap.add_argument("--no-locate", action="store_true")
    a = ap.parse_args()
    print(f"Machine: {machine()}\n\n{HEADER}")
    for line in main(a.lines, not a.no_locate):
        print(line)
