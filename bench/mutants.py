"""A mutation run: plausible bugs put into eoloc one at a time; each must be caught by the tests of
its own package (issue 55). `make mutants` runs it; the list below is the declaration.

    python bench/mutants.py [--only ID ...] [--list]

Each mutant replaces one exact piece of source (it must occur exactly once) in the working tree,
runs the named tests with ``-x`` (stop at the first failure), and restores the file whatever
happens. The named tests must be the mutated module's own package's (tests/unit/<package>/; a
mutant named with another package's tests is a BAD SPEC, not run). Killed: the tests fail.
Survived: they pass — a gap in the suite, printed with the mutant's reason. The kernels' numba
cache is keyed by their source, so a kernel mutant recompiles (about a minute). Prints a
Markdown table and the score; exit 1 if any mutant survived.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "eoloc"


@dataclass(frozen=True)
class Mutant:
    id: str
    file: str  # under src/eoloc
    find: str
    replace: str
    tests: tuple[str, ...]
    why: str


MUTANTS = [
    # --- kernels: geodesy, rotations, rays, stops
    Mutant("geo-ecef-z", "kernels/core.py", "return r * co, r * so, (n * (1.0 - e2) + h) * sl",
           "return r * co, r * so, (n + h) * sl", ("tests/unit/kernels/test_references.py",),
           "ECEF z without the (1 - e²) of the ellipsoid"),
    Mutant("geo-bowring-1", "kernels/core.py", "sl, cl, p, h = bowring(x, y, z, a, b, e2, ep2, 2)",
           "sl, cl, p, h = bowring(x, y, z, a, b, e2, ep2, 1)", ("tests/unit/kernels/test_references.py",),
           "one Bowring step: latitude 0.09 mm off at 100 km"),
    Mutant("rot-y-sign", "kernels/core.py", "return (c, o, s, o, o + 1.0, o, -s, o, c)",
           "return (c, o, -s, o, o + 1.0, o, s, o, c)", ("tests/unit/kernels/test_references.py",),
           "rotation about y turned the wrong way (pitch and elevation mirrored)"),
    Mutant("azel-order", "kernels/core.py",
           "g = mat_mul(mat_mul(rot_z(az), rot_x(skew)), mat_mul(rot_y(el), rot_x(sensor_roll)))",
           "g = mat_mul(mat_mul(rot_y(el), rot_x(skew)), mat_mul(rot_z(az), rot_x(sensor_roll)))",
           ("tests/unit/kernels/test_references.py",), "az-el turret axes in the wrong order"),
    Mutant("rollpitch-axes", "kernels/core.py", "return (-s[1], s[0], s[2], -s[4], s[3], s[5], -s[7], s[6], s[8])",
           "return (s[1], -s[0], s[2], s[4], -s[3], s[5], s[7], -s[6], s[8])",
           ("tests/unit/kernels/test_references.py",), "roll-pitch camera axes mirrored"),
    Mutant("lever-sign", "kernels/core.py", "return R_ecef_cam, px + dx, py + dy, pz + dz",
           "return R_ecef_cam, px - dx, py - dy, pz - dz", ("tests/unit/kernels/test_references.py",),
           "lever arm applied backwards"),
    Mutant("ray-norm", "kernels/core.py", "k = 1.0 / np.sqrt(xn * xn + yn * yn + 1.0)",
           "k = 1.0 / np.sqrt(xn * xn + yn * yn + 1.01)", ("tests/unit/kernels/test_references.py",),
           "ray directions not unit vectors"),
    Mutant("range-zero", "kernels/core.py",
           "valid = ray_valid(ox, oy, oz, dx, dy, dz) & (rng > 0.0) & (rng <= MAX_RANGE_M)",
           "valid = ray_valid(ox, oy, oz, dx, dy, dz) & (rng >= 0.0) & (rng <= MAX_RANGE_M)",
           ("tests/unit/kernels/test_references.py",), "a zero range accepted as a fix at the camera"),
    Mutant("dem-later-root", "kernels/core.py", "first = pick(ok1 & ok2, np.minimum(r1, r2),",
           "first = pick(ok1 & ok2, np.maximum(r1, r2),", ("tests/unit/kernels/test_references.py",),
           "the later of two roots in a DEM cell (issue 55: 15.8 m too far)"),
    Mutant("dem-bilinear", "kernels/core.py", "h = (1.0 - ar) * top + ar * bottom",
           "h = (1.0 - ar) * top + ar * top",
           ("tests/unit/kernels/test_references.py",),
           "bilinear interpolation ignores the second row of posts"),
    Mutant("project-behind", "kernels/core.py", "zs = pick(cz > 0.0, cz, np.nan)", "zs = pick(cz != 0.0, cz, np.nan)",
           ("tests/unit/kernels/test_references.py",), "points behind the camera projected into the image"),
    # --- sensor
    Mutant("half-pixel", "sensor/camera.py", "xn = (u - (self.cx + dcx)) / (self.fx * scale)",
           "xn = (u + 0.5 - (self.cx + dcx)) / (self.fx * scale)", ("tests/unit/sensor/test_camera.py",),
           "pixel convention off by half a pixel"),
    # --- accuracy
    Mutant("cep-small", "accuracy/cep.py", "big, small = np.maximum(a, b), np.minimum(a, b)",
           "big, small = np.maximum(a, b), np.maximum(a, b)",
           ("tests/unit/accuracy/test_accuracy.py", "tests/unit/accuracy/test_cep.py"),
           "CEP of an elongated ellipse computed as a circle"),
    Mutant("ellipse-minor", "accuracy/cep.py", "minor = np.where(major > 0, (ee * nn - en * en) / major, 0.0)",
           "minor = np.where(major > 0, (ee * nn - 0.5 * en * en) / major, 0.0)",
           ("tests/unit/accuracy/test_accuracy.py", "tests/unit/accuracy/test_covariance.py"),
           "error ellipse's minor axis wrong"),
    Mutant("le90-one-sided", "accuracy/cep.py", "LE90_PER_SIGMA = 1.6448536269514722",
           "LE90_PER_SIGMA = 1.2815515655446004",
           ("tests/unit/accuracy/test_covariance.py", "tests/unit/accuracy/test_cep.py"),
           "LE90 as a one-sided quantile"),
    Mutant("jacobian-step", "accuracy/covariance.py", "a = a / rel_step  # J diag(sigma)",
           "a = a / (2.0 * rel_step)  # J diag(sigma)", ("tests/unit/accuracy/test_covariance.py",),
           "first-order covariance a quarter of what it is"),
    Mutant("rls-full-inverse", "sequence/rls.py", "    return np.where(use[..., None, None], W, 0.0)",
           "    return np.where(use[..., None, None], np.linalg.inv(Rw + 1e-6 * np.eye(3)), 0.0)",
           ("tests/unit/sequence/test_rls.py::test_47_near_singular_fix_covariances_make_no_false_certainty",),
           "near-singular 3-D fix covariances inverted whole: a false certainty (issue 47)"),
    Mutant("rls-all-noise", "sequence/rls.py", "Md = lam * self.M * r[:, None, :]", "Md = lam * self.M * 0.0",
           ("tests/unit/sequence/test_rls.py::test_47_rls_covariance_is_the_exact_sum_over_pairs",
            "tests/unit/sequence/test_rls.py::test_47_averaging_never_beats_the_systematic_floor"),
           "biases and Gauss–Markov errors averaged down like noise"),
    Mutant("rls-never-inconsistent", "sequence/rls.py",
           "return ~((self.n >= 3) & (q > chi2_quantile(1.0 - INCONSISTENT_P, dof)))",
           "return np.ones(len(self.n), dtype=bool)",
           ("tests/unit/sequence/test_rls.py::test_fixes_that_jump_between_two_places_are_inconsistent_and_ones_that_scatter_as_declared_are_not",),
           "fixes that jump between a summit and its slope averaged into a point"),
    Mutant("kalman-consider", "sequence/track.py", "Pxc = Pxc - K @ (H @ Pxc + A)", "Pxc = Pxc - K @ (H @ Pxc)",
           ("tests/unit/sequence/test_track_coverage.py",),
           "Schmidt–Kalman cross-covariance update missing the fix's own effects"),
    Mutant("rls-forgetting", "sequence/rls.py", "self.A = lam * self.A + W", "self.A = self.A + W",
           ("tests/unit/sequence/test_filters_calibration.py",), "forgetting factor ignored in the information"),
    # --- writers
    Mutant("csv-decimals", "io/csvfile.py",
           'return 9 if name.endswith("_deg") or name.rsplit("_", 1)[-1] in ANGLE_WORDS else 4',
           'return 6 if name.endswith("_deg") or name.rsplit("_", 1)[-1] in ANGLE_WORDS else 4',
           ("tests/unit/io/test_csvfile.py",),
           "angles written with 6 decimals (~0.1 m) instead of the promised 9"),
    Mutant("geojson-order", "io/geojsonfile.py", 'for k in ("lon_deg", "lat_deg", "h_m")]',
           'for k in ("lat_deg", "lon_deg", "h_m")]', ("tests/unit/io/test_geojsonfile.py",),
           "GeoJSON coordinates as lat, lon (RFC 7946 wants lon, lat)"),
    Mutant("cot-ce", "io/cot.py", "ce = ce90 / CE90_PER_SIGMA", "ce = ce90 / 1.1774",
           ("tests/unit/io/klv/test_klv_outputs.py",), "CoT ce from the CE90 with the CEP50 factor"),
    Mutant("cot-hae", "io/cot.py", 'hae="{hae:.2f}"', 'hae="{hae:.0f}"', ("tests/unit/io/klv/test_klv_outputs.py",),
           "CoT heights rounded to the metre"),
    Mutant("kml-msl", "io/kml.py", "h = c[:, 2] - geoid.undulation(c[:, 1], c[:, 0])",
           "h = c[:, 2] + geoid.undulation(c[:, 1], c[:, 0])",
           ("tests/unit/io/test_geoformats.py", "tests/unit/io/klv/test_klv_outputs.py"),
           "KML heights converted to MSL the wrong way"),
    # --- KLV
    Mutant("klv-bcc", "io/klv/reader.py", "return ((sum(data[0::2]) << 8) + sum(data[1::2])) & 0xFFFF",
           "return ((sum(data[0::2]) << 7) + sum(data[1::2])) & 0xFFFF", ("tests/unit/io/klv/test_klv.py",),
           "ST 0601 checksum computed wrong: good packets refused"),
    Mutant("klv-heading", "io/klv/st0601.py", '5: ("Platform Heading Angle", Mapped(2, F(0), F(360))),',
           '5: ("Platform Heading Angle", Mapped(2, F(0), F(359))),', ("tests/unit/io/klv/test_klv.py",),
           "ST 0601 tag 5 scaled over the wrong range"),
    Mutant("klv-alt", "io/klv/st0601.py", "_ALT = Mapped(2, F(-900), F(19000))",
           "_ALT = Mapped(2, F(-1000), F(19000))",
           ("tests/unit/io/klv/test_klv.py",), "ST 0601 altitudes offset by the wrong minimum"),
    Mutant("vmti-imapb", "io/klv/st0903.py", "return self.s_r * (y - self.z) + self.lo",
           "return self.s_r * (y + self.z) + self.lo",
           ("tests/unit/io/klv/test_klv.py", "tests/unit/io/klv/test_imapb.py"),
           "ST 1201 IMAPB decoded with the zero offset's sign flipped"),
    # --- photos (issue 48)
    Mutant("photo-datum", "io/photo.py", "        h = alt + n\n", "        h = alt - n\n",
           ("tests/unit/io/test_photo_tags.py",),
           "Skydio's AbsoluteAltitude (above EGM96) converted to ellipsoidal the wrong way"),
    Mutant("photo-db-scale", "sensor/dronemodels.py", 'scale = width / e["widthPixels"]', "scale = 1.0",
           ("tests/unit/sensor/test_dronemodels.py",), "a resized photo's focal length not scaled"),
    Mutant("photo-calib-halfpixel", "sensor/dronemodels.py", "(cx + 0.5) * k - 0.5, (cy + 0.5) * k - 0.5)",
           "cx * k, cy * k)", ("tests/unit/sensor/test_dronemodels.py",),
           "a resized photo's principal point scaled without the half-pixel convention"),
    Mutant("photo-pix4d-pitch", "io/photo.py", 'pitch = _num(tags, "Pitch", p.path) - 90.0',
           'pitch = 90.0 - _num(tags, "Pitch", p.path)', ("tests/unit/io/test_photo_tags.py",),
           "old Autel (Pix4D Camera:Pitch, 0 at nadir) turned the wrong way"),
    Mutant("fisheye-theta", "kernels/core.py", "t = _TWO_OVER_PI * np.arctan(r)", "t = _TWO_OVER_PI * r",
           ("tests/unit/kernels/test_references.py",), "Pix4D fisheye angle without the arctangent"),
    # --- telemetry sources (issue 48)
    Mutant("srt-gps-order", "io/sources/dji_srt.py",
           'lat[k], lon[k] = (g[1], g[0]) if order == "lon,lat" else (g[0], g[1])',
           'lat[k], lon[k] = (g[0], g[1]) if order == "lon,lat" else (g[1], g[0])',
           ("tests/unit/io/sources/test_flights.py",), "DJI GPS(…) tuples read in the wrong order"),
    Mutant("srt-gpry-order", "io/sources/dji_srt.py", "pitch[k], roll[k], yaw[k] = g", "roll[k], pitch[k], yaw[k] = g",
           ("tests/unit/io/sources/test_flights.py",), "G.PRY (pitch, roll, yaw) read as (roll, pitch, yaw)"),
    Mutant("heights-takeoff", "io/sources/heights.py", "h = ground0 + h_rel", "h = h_rel + 0.0 * ground0",
           ("tests/unit/io/sources/test_flights.py",), "heights above take-off used as ellipsoidal heights"),
    Mutant("airdata-feet", "io/sources/airdata.py", "FOOT_M = 0.3048", "FOOT_M = 0.3",
           ("tests/unit/io/sources/test_flights.py",), "Airdata feet converted with a rounded factor"),
    Mutant("flightlog-offset-sign", "jobs/flightlog.py", "time_offset_s=sync.offset_s,",
           "time_offset_s=-sync.offset_s,",
           ("tests/unit/jobs/test_flightlog.py",), "the flight log's poses taken at the wrong side of the offset"),
    Mutant("klv-key-head", "io/klv/reader.py", "KEY_HEAD, KEY_TAIL = UAS_KEY[:5], UAS_KEY[5:]",
           "KEY_HEAD, KEY_TAIL = UAS_KEY[:4], UAS_KEY[4:]", ("tests/unit/io/klv/test_klv_conformance.py",),
           "a damaged key repaired with the wrong number of bytes"),
    Mutant("mgrs-round", "io/gridref.py", "ei = np.floor(e[ok]).astype(np.int64)",
           "ei = np.round(e[ok]).astype(np.int64)", ("tests/unit/io/test_gridref.py",),
           "MGRS easting rounded instead of truncated"),
    # --- session 49: ortho against an independent projection, conformance items 4 and 8, CoT
    Mutant("ortho-half-pixel", "kernels/ortho.py", "ur[c] = fx * xs[c] + cx", "ur[c] = fx * xs[c] + cx + 0.5",
           ("tests/unit/kernels/test_ortho_kernel.py::test_every_cell_holds_the_value_an_independent_projection_reads",),
           "orthorectified cells read half a pixel off (issue 55: passed every ortho test before)"),
    Mutant("klv-out-missing-tags", "io/klv/encode.py", 'body += b"".join(new.values())', 'body += b""',
           ("tests/unit/io/klv/test_klv_conformance.py::test_49_4_klv_out_writes_a_fix_into_every_real_packet",),
           "--klv-out drops the target tags a packet did not send before"),
    Mutant("ts-arrival", "io/klv/transport.py", "t = video / PTS_HZ", "t = 0.0 * video / PTS_HZ",
           ("tests/unit/io/klv/test_ts_timing.py",),
           "asynchronous KLV without PTS not timed by the frame it follows (a damaged stream: the tolerant path)"),
    Mutant("ts-arrival-clean", "io/klv/demux.py", "j = int(np.searchsorted(self.video, k)) - 1",
           "j = int(np.searchsorted(self.video, k)) - 2",
           ("tests/unit/io/klv/test_ts_timing.py",),
           "asynchronous KLV of a clean stream timed by the frame before the one it follows"),
    Mutant("ts-chunk-open-pes", "io/klv/demux.py",
           "c, g = np.concatenate([carried[0], c]), np.concatenate([carried[1], g])", "c, g = c, g",
           ("tests/unit/io/klv/test_klv_columnar.py::test_a_clean_transport_stream_is_read_in_vectorised_passes_to_the_"
            "same_packets",),
           "a TS read a chunk at a time loses the start of each PES that runs across a chunk's end"),
    Mutant("ts-chunk-arrival", "io/klv/demux.py", "return carried[2] if k < self.k0 else arrival.get(k - self.k0)",
           "return None if k < self.k0 else arrival.get(k - self.k0)",
           ("tests/unit/io/klv/test_klv_columnar.py::test_a_clean_transport_stream_is_read_in_vectorised_passes_to_the_"
            "same_packets",),
           "a PES begun before a chunk's end and timed by arrival loses its time (ST 1402 carriage)"),
    Mutant("range-cut-any-key", "io/klv/segments.py",
           "if good_packet(block, k, nxt):", "if packet_end(block, k)[0] == nxt:",
           ("tests/unit/io/klv/test_klv_segments.py::test_a_byte_range_begins_where_a_good_packet_ends",),
           "a byte range may begin after a packet whose checksum fails (not where the reader stands)"),
    Mutant("range-numbering", "jobs/klv.py",
           "start = RangeStart(start.first_index + packets, start.rows + good, folded)",
           "start = RangeStart(start.first_index + good, start.rows + good, folded)",
           ("tests/unit/jobs/test_batch_ranges.py",),
           "a byte range's packets numbered without the bad packets before it"),
    Mutant("range-state", "jobs/klv.py",
           "folded = start.state if state is None else carried_state(with_state(state, start.state))",
           "folded = state",
           ("tests/unit/jobs/test_batch_ranges.py",),
           "a byte range starts from what only the range before it said (report-on-change items lost)"),
    Mutant("cot-unknown", "io/cot.py",
           "return (ce if 0.0 <= ce < UNKNOWN else UNKNOWN), (le if 0.0 <= le < UNKNOWN else UNKNOWN)",
           "return ce, le",
           ("tests/unit/io/test_cot.py",),
           "CoT ce/le past 'unknown' (or infinite) sent as they are"),
]


def own_package(m: Mutant) -> str:
    """Where the tests of the mutated module's own package live: tests/unit/<package>/ (a module
    at the package's root, e.g. geodesy.py: tests/unit/test_geodesy.py)."""
    parts = m.file.split("/")
    return f"tests/unit/test_{parts[0][:-3]}" if len(parts) == 1 else f"tests/unit/{parts[0]}/"


def run(m: Mutant, python: str) -> tuple[str, float, str]:
    if not all(t.startswith(own_package(m)) for t in m.tests):
        return "BAD SPEC", 0.0, f"its tests must be its own package's ({own_package(m)}...), not {m.tests}"
    path = SRC / m.file
    text = path.read_text(encoding="utf-8")
    count = text.count(m.find)
    if count != 1:
        return "BAD SPEC", 0.0, f"the text to replace occurs {count} times in {m.file}"
    t0 = time.perf_counter()
    try:
        path.write_text(text.replace(m.find, m.replace), encoding="utf-8")
        r = subprocess.run([python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *m.tests], cwd=ROOT,
                           capture_output=True, text=True, timeout=1800)
    finally:
        path.write_text(text, encoding="utf-8")
    last = (r.stdout.strip().splitlines() or [""])[-1]
    return ("KILLED" if r.returncode != 0 else "SURVIVED"), time.perf_counter() - t0, last


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="mutant ids to run")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    a = ap.parse_args()
    todo = [m for m in MUTANTS if not a.only or m.id in a.only]
    if a.list:
        for m in todo:
            print(f"{m.id:24s} {m.file:26s} {m.why}")
        return 0
    rows, survived = [], []
    for m in todo:
        verdict, secs, last = run(m, sys.executable)
        rows.append((m, verdict, secs))
        print(f"{m.id:24s} {verdict:9s} {secs:6.0f} s  {last}", file=sys.stderr, flush=True)
        if verdict != "KILLED":
            survived.append(m)
    print(f"\n{len(rows) - len(survived)} of {len(rows)} mutants killed\n")
    print("| mutant | module | the bug | killed by | result |\n|---|---|---|---|---|")
    for m, verdict, secs in rows:
        print(f"| {m.id} | {m.file} | {m.why} | {', '.join(t.split('::')[0].split('/')[-1] for t in m.tests)} | "
              f"{verdict.lower()} ({secs:.0f} s) |")
    return 1 if survived else 0


if __name__ == "__main__":
    sys.exit(main())
