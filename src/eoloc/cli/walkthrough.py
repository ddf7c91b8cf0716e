"""`eoloc demo`: the bundled example flight, located two ways and compared with the truth."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table as RichTable

from ..accuracy.covariance import covariance_columns
from ..geodesy import horizontal_distance_m
from ..io.config import load_config
from ..io.export import fix_records
from ..io.telemetry import read_detections, read_telemetry
from ..io.writers import write_layer
from ..jobs.setup import error_budget
from ..jobs.tables import locate_tables
from ..rules import AtHeight, OnDEM, RangeFromRecords, locate_range
from ..sensor import AzElGimbal, Camera, Pose, SensorModel
from .render import titled_table

S13_EXPECTED = (42.02058646, 125.03195512, 419.58)


def s13_check(console: Console) -> float:
    """[S13] Table 2 -> Table 3: the convention check every eoloc build must pass. Returns metres."""
    sensor = SensorModel(Camera(1, 1, 1.0, 1.0, 0.0, 0.0), AzElGimbal())
    f = locate_range(sensor, Pose(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, (45.0, -75.0)), 10_200.0)
    d = float(horizontal_distance_m(f.lat_deg, f.lon_deg, S13_EXPECTED[0], S13_EXPECTED[1]))
    dh = float(f.h_m) - S13_EXPECTED[2]
    console.print(
        f"[bold][S13] reference case[/] (aircraft 125°E 42°N 10 000 m, yaw 10 pitch 5 roll -2, az 45 el -75, "
        f"range 10 200 m)\n  eoloc  {float(f.lat_deg):.8f}°N {float(f.lon_deg):.8f}°E h {float(f.h_m):.3f} m\n"
        f"  paper  {S13_EXPECTED[0]:.8f}°N {S13_EXPECTED[1]:.8f}°E h {S13_EXPECTED[2]:.2f} m\n"
        f"  difference: {d * 1000:.1f} mm horizontal, {dh * 1000:.1f} mm vertical (paper rounds h to cm)"
    )
    return max(d, abs(dh))


def _read_truth(path: Path) -> dict[str, tuple[float, float, float]]:
    with path.open(newline="") as fh:
        return {r["target_id"]: (float(r["lat_deg"]), float(r["lon_deg"]), float(r["h_m"])) for r in csv.DictReader(fh)}


def _error_table(title: str, ids: np.ndarray, err: np.ndarray) -> RichTable:
    t = titled_table(title)
    for c in ("target", "fixes", "mean error (m)", "CEP50 (m)", "max (m)"):
        t.add_column(c, justify="right")
    for tid in sorted(set(ids.tolist())):
        e = err[(ids == tid) & np.isfinite(err)]
        if e.size:
            t.add_row(str(tid), str(e.size), f"{e.mean():.1f}", f"{np.median(e):.1f}", f"{e.max():.1f}")
    return t


def run_demo(out_dir: Path, *, console: Console, data) -> None:
    """Locate the demo flight by laser range (image centres) and on the ellipsoid (all detections)."""
    console.rule("eoloc demo")
    s13_check(console)
    data = Path(str(data))
    sensor = load_config(data / "camera.toml").sensor()
    tel = read_telemetry(data / "telemetry.csv")
    det = read_detections(data / "detections.csv")
    truth = _read_truth(data / "truth.csv")
    console.print(f"\n[bold]Demo flight[/] ([Z15]-like: 1140 m, 50 mm lens, az-el turret, [Z15] telemetry noise): "
                  f"{len(tel)} telemetry records, {len(det)} detections of {len(truth)} surveyed targets")
    for issue in tel.issues + det.issues:
        console.print(f"[yellow]input issue (kept going):[/] {escape(str(issue))}", highlight=False)

    # M1: the turret tracks T1, so the image centre + laser range is T1
    # with each fix's first-order uncertainty from the config's [accuracy.budget]
    budget = error_budget(load_config(data / "camera.toml"), data / "camera.toml")
    m1 = locate_tables(sensor, tel, None, RangeFromRecords(), budget=budget)
    t1 = truth["T1"]
    err1 = horizontal_distance_m(m1.fixes.lat_deg, m1.fixes.lon_deg, t1[0], t1[1])
    err1 = np.where(m1.fixes.ok, err1, np.nan)
    # M3: every detection on the ellipsoid at the targets' known ground height
    m3 = locate_tables(sensor, tel, det, AtHeight(t1[2]))
    for issue in m3.issues:
        console.print(f"[yellow]input issue (kept going):[/] {escape(str(issue))}", highlight=False)
    ids = np.asarray(m3.extra["target_id"], dtype=object)
    tlat = np.array([truth.get(i, (np.nan,) * 3)[0] for i in ids])
    tlon = np.array([truth.get(i, (np.nan,) * 3)[1] for i in ids])
    err3 = np.where(m3.fixes.ok, horizontal_distance_m(m3.fixes.lat_deg, m3.fixes.lon_deg, tlat, tlon), np.nan)

    console.print(_error_table("M1 laser range, image centre (= T1)", np.full(err1.shape, "T1", dtype=object), err1))
    console.print(_error_table("M3 ellipsoid at h = 600 m, every detection", ids, err3))
    console.print("status counts  M1: " + str(m1.fixes.status_counts()) + "   M3: " + str(m3.fixes.status_counts()))
    console.print("[dim]Errors come from the telemetry noise the flight was given ([Z15] Table 1 sigmas); "
                  "[Z15] reports CEP 28.7 m single-frame for the same budget.[/]")
    cov1 = covariance_columns(m1.covariance, m1.fixes.ok)
    ok1 = np.isfinite(err1)
    inside = int(np.sum(err1[ok1] <= cov1["ce90_m"][ok1]))
    console.print(f"Honest uncertainty (eoloc locate --covariance): predicted CEP50 per fix "
                  f"{np.nanmedian(cov1['cep50_m']):.1f} m (median), observed median error {np.nanmedian(err1):.1f} m; "
                  f"{inside} of {int(ok1.sum())} true errors inside their own CE90 (expect ~90 %).")

    _many_frames(console, sensor, tel, det, truth, budget)

    written = []
    for name, located, err in (("fixes_range", m1, err1), ("fixes_ellipsoid", m3, err3)):
        extra = dict(located.extra, error_vs_truth_m=err)
        after = covariance_columns(located.covariance, located.fixes.ok) if located.covariance is not None else None
        written += write_layer(out_dir, name, fix_records(located.fixes, extra, after))
    console.print("wrote " + ", ".join(str(p) for p in written))
    run_mountain_demo(out_dir, console=console, data=data / "mountain")
    run_klv_demo(out_dir / "klv", console=console, data=data / "mountain")
    flights = run_compensation_demo(out_dir / "compensation", console=console, sensor=sensor)
    run_report_demo(out_dir / "report", console=console, config_path=data / "camera.toml", flights=flights)
    run_rectify_demo(out_dir / "rectify", console=console, data=data / "mountain")
    run_batch_demo(out_dir / "archive", console=console, data=data / "mountain")
    run_live_demo(out_dir / "live", console=console, data=data / "mountain")


def run_compensation_demo(out_dir: Path, *, console: Console, sensor):
    """[P]: synthetic calibration flights with installation errors; the model learnt on 6 flights
    corrects 3 others; CEP by oblique band before and after, and [P] Fig. 1 as a PNG. Returns the
    training flights (the accuracy report's observations)."""
    from ..accuracy import compensation as C
    from ..accuracy.calflight import calibration_flights
    from ..accuracy.plots import plot_compensation
    from .render import print_bands

    console.rule("Large oblique angles: learned error compensation ([P]; eoloc compensate)")
    tr = calibration_flights(sensor, n_flights=6, looks_per_flight=300, seed=0)
    te = calibration_flights(sensor, n_flights=3, looks_per_flight=300, seed=1000, first_flight=6)
    o_tr = C.locate_observations(sensor, tr.columns, OnDEM(tr.dem))
    o_te = C.locate_observations(sensor, te.columns, OnDEM(te.dem))
    model = C.fit(o_tr.features, o_tr.errors_enu, groups=o_tr.groups)
    model.save(out_dir / "compensation.json")
    pred = model.predict(o_te.features)
    before = o_te.errors_enu[:, :2]
    after = before + pred.correction_enu[:, :2]
    rows = C.band_table(o_te.features.oblique_deg, before, {"compensated": after})
    console.print(f"{len(tr)} calibration looks on 6 flights (heights 1-4.5 km, oblique 0-78°) train the physical "
                  f"model; {len(te)} looks on 3 other flights test it ({int((~pred.applied).sum())} outside the "
                  "trained range flagged, left as located):")
    print_bands(rows, "held-out flights, located on the station DEM: CEP50 by oblique band", console)
    png = plot_compensation(o_te.features.oblique_deg, before, {"compensated": after}, rows,
                            out_dir / "compensation.png", title="held-out flights, before and after compensation")
    console.print(f"wrote {out_dir / 'compensation.json'} and {png}")
    return tr


def run_report_demo(out_dir: Path, *, console: Console, config_path: Path, flights) -> None:
    """`eoloc report` on the calibration flights: their observations and station DEM written as a
    user would have them, then the accuracy report (HTML + CSV) made from those files."""
    from ..io.raster import write_dem
    from ..io.records import Records
    from ..jobs.report import report_job, write_report
    from ..terrain import open_dem

    console.rule("Flight-test accuracy report (eoloc report)")
    (obs,) = write_layer(out_dir, "observations", Records(dict(flights.columns)), ["csv"])
    dem_path = write_dem(flights.dem, out_dir / "dem.tif")
    dem = open_dem([dem_path], vertical="ellipsoid")
    job = report_job(load_config(config_path), config_path, obs, rule=OnDEM(dem), estimate=("mount", "heading"),
                     compensation=True, n_boot=1000,
                     command=f"eoloc report {obs} --config {config_path} --dem {dem_path} --vertical ellipsoid "
                             "--estimate mount,heading --compensation --bootstrap 1000")
    for stage in job.stages:
        v = stage.evaluation.overall
        console.print(f"{stage.name:>30}: CEP {v.value['cep50_m']:.2f} m ({v.low['cep50_m']:.2f}–"
                      f"{v.high['cep50_m']:.2f}), CE90 {v.value['ce90_m']:.2f} m, LE90 {v.value['le90_m']:.2f} m")
    written = write_report(job, out_dir)
    console.print("wrote " + ", ".join(str(p) for p in written))


def run_rectify_demo(out_dir: Path, *, console: Console, data: Path) -> None:
    """M5: a synthetic checkerboard frame seen obliquely over the Longs Peak DEM, orthorectified
    to UTM on the DEM, with [P]'s bounds shortcut measured against the rigorous ray."""
    from ..ground import rectify
    from ..io.raster import write_ortho
    from ..rules import locate_dem
    from ..terrain import open_dem

    console.rule("Image georeferencing (M5; eoloc rectify)")
    dem = open_dem(data / "longs_peak_srtmgl3.tif")
    sensor = SensorModel(Camera.from_hfov(30.0, 640, 480), AzElGimbal())
    pose = Pose(40.25, -105.58, 6000.0, 270.0, 1.0, -2.0, (5.0, -45.0))
    u, v = np.meshgrid(np.arange(640.0), np.arange(480.0))
    f = locate_dem(sensor, pose, dem, (u, v))
    frame = np.where(f.ok, 60 + 140 * ((np.floor(f.lat_deg / 0.001) + np.floor(f.lon_deg / 0.001)) % 2), 0)
    ortho = rectify.orthorectify(frame.astype(np.uint8), sensor, pose, OnDEM(dem), crs="utm")
    path = write_ortho(ortho, out_dir / "ortho.tif")
    grid = rectify.ground_grid(sensor, pose, OnDEM(dem), step_px=40)
    ok = grid.fixes.ok.ravel()
    short = rectify.shortcut_error(ortho, sensor, pose, OnDEM(dem),
                                   np.c_[grid.u_px.ravel(), grid.v_px.ravel()][ok]).summary()
    console.print(f"A 640 x 480 frame of a 0.001° checkerboard on the terrain, seen 45° below the horizon from "
                  f"6000 m: {ortho.shape[1]} x {ortho.shape[0]} cells of {ortho.res[0]:.2f} m in {ortho.crs.name}, "
                  f"{100 * ortho.valid.mean():.0f} % seen (terrain-hidden cells blanked). [P]'s bounds shortcut "
                  f"against the rigorous ray: median {short['exact_median_m']:.1f} m, max {short['exact_max_m']:.1f} m "
                  "(grid convergence and scale; exact only on a lat/lon grid).")
    console.print(f"wrote {path}")


def _many_frames(console: Console, sensor, tel, det, truth, budget) -> None:
    """RLS per static target over all frames (M6) and range-free triangulation (M8), against truth."""
    from ..io.telemetry import match_detections, telemetry_pose
    from ..sequence import rls_static, triangulate

    t1 = next(iter(truth.values()))
    m3 = locate_tables(sensor, tel, det, AtHeight(t1[2]), budget=budget)
    ids = np.asarray(m3.extra["target_id"]).astype(str)
    matched = match_detections(tel, det)
    rays = sensor.rays(telemetry_pose(tel, np.maximum(matched.record, 0)), (det.columns["u_px"], det.columns["v_px"]))
    table = titled_table("many frames: one estimate per target from all its frames")
    for c in ("target", "frames", "1-frame CEP50 (m)", "RLS error (m)", "RLS CEP50 pred. (m)",
              "triangulated error (m)"):
        table.add_column(c, justify="right")
    for tid, (lat, lon, _h) in truth.items():
        sel = np.flatnonzero(ids == tid)
        f = m3.fixes.flat(sel)
        est = rls_static(f, covariance=m3.covariance.take(sel), time_s=np.asarray(m3.extra["time_s"])[sel])
        single = np.nanmedian(np.where(f.ok, horizontal_distance_m(f.lat_deg, f.lon_deg, lat, lon), np.nan))
        good = sel[matched.record[sel] >= 0]
        tri = triangulate(rays.take(good), np.radians(1.0))
        table.add_row(tid, str(int(est.n_used)), f"{single:.1f}",
                      f"{float(horizontal_distance_m(est.lat_deg, est.lon_deg, lat, lon)):.1f}",
                      f"{float(est.cep50_m):.1f}",
                      f"{float(horizontal_distance_m(tri.lat_deg, tri.lon_deg, lat, lon)):.1f}")
    console.print(table)
    console.print("[dim]The demo's telemetry errors are independent from frame to frame, so recursive least squares "
                  "over the frames (eoloc track --static) removes most of them, and its own covariance says by how "
                  "much; a bias in the telemetry would stay (examples/rls_static_targets.py). Triangulation "
                  "(eoloc triangulate) needs neither range nor terrain: the flight's 65° of turn around the "
                  "targets is the baseline.[/]")


def run_mountain_demo(out_dir: Path, *, console: Console, data: Path) -> None:
    """M4 over real terrain (SRTM, Longs Peak): every detection on the DEM, against the truth and
    against what the ellipsoid at one height would give; footprints on the DEM."""
    from ..ground.footprint import footprint_features, footprints
    from ..io.telemetry import telemetry_pose
    from ..terrain import open_dem

    dem = open_dem(data / "longs_peak_srtmgl3.tif")  # SRTM heights are EGM96: converted with the bundled geoid
    sensor = load_config(data / "camera.toml").sensor()
    tel = read_telemetry(data / "telemetry.csv")
    det = read_detections(data / "detections.csv")
    truth = _read_truth(data / "truth.csv")
    lo, hi = dem.height_range
    console.rule("mountain flight: M4 on a real DEM")
    console.print("DEM longs_peak_srtmgl3.tif (real SRTMGL3 around Longs Peak, Colorado): "
                  f"{dem.grid.z.shape[1]} x {dem.grid.z.shape[0]} posts, "
                  f"{dem.spacing_m:.0f} m, ellipsoidal heights {lo:.0f}-{hi:.0f} m; "
                  f"{len(tel)} telemetry records at 6 000 m, {len(det)} detections")
    m4 = locate_tables(sensor, tel, det, OnDEM(dem))
    flat_h = float(np.nanmean(dem.grid.z))
    m3 = locate_tables(sensor, tel, det, AtHeight(flat_h))
    ids = np.asarray(m4.extra["target_id"], dtype=object)
    t = np.array([truth.get(i, (np.nan,) * 3) for i in ids])
    errors = {}
    for name, located in (("dem", m4), ("flat", m3)):
        f = located.fixes
        errors[name] = np.where(f.ok, horizontal_distance_m(f.lat_deg, f.lon_deg, t[:, 0], t[:, 1]), np.nan)
    known = np.isfinite(t[:, 0])
    console.print(_error_table("M4 on the DEM", ids[known], errors["dem"][known]))
    console.print(_error_table(f"M3 on the ellipsoid at the DEM's mean height {flat_h:.0f} m (no terrain model)",
                               ids[known], errors["flat"][known]))
    console.print("status counts  M4: " + str(m4.fixes.status_counts()))
    peaks = np.isin(ids, ["LONGS_PEAK", "MT_MEEKER"]) & np.isfinite(errors["dem"])
    behind = int((errors["dem"][peaks] > 100.0).sum())
    console.print("[dim]FAR_HILL lies beyond the DEM's west edge: its rays leave the terrain grid and come back "
                  f"OUT_OF_COVERAGE, with no point. The two summits are seen almost edge-on from 9 km: {behind} of "
                  f"their {int(peaks.sum())} rays, tilted by the 0.03° attitude noise, pass just over the top and "
                  "meet the slopes behind (the long tail of their errors). That is the geometry, not the method: "
                  "a ray that clears a summit really does land behind it.[/]")
    every = np.arange(0, len(tel), 5)
    prints = footprints(sensor, telemetry_pose(tel, every), OnDEM(dem), edge_samples=12)
    clipped = sum(bool(p.clipped.any()) for p in prints)
    records = fix_records(m4.fixes, dict(m4.extra, error_vs_truth_m=errors["dem"]))
    feats = footprint_features(prints, [{"time_s": float(tel.columns["time_s"][i])} for i in every])
    written = [*write_layer(out_dir, "fixes_dem", records),
               *write_layer(out_dir, "footprints_dem", [f["properties"] for f in feats], ["geojson"], features=feats)]
    console.print(f"{len(prints)} frame footprints on the DEM, {clipped} clipped where the image sees past the "
                  "DEM's edge (the outline stops at the edge instead of guessing)")
    console.print("wrote " + ", ".join(str(p) for p in written))


def run_klv_demo(out_dir: Path, *, console: Console, data: Path) -> None:
    """The mountain flight as a MISB ST 0601 stream with ST 0903 targets (flight.klv, one packet
    corrupted on purpose): decoded, checked against the encoder's frame centres, targets located on
    the DEM and compared with the survey, and written as CSV, GeoJSON, KML, CoT and an HTML map."""
    from ..accuracy.budget import ErrorBudget
    from ..jobs.klv import klv_job, write_klv_products
    from ..terrain import open_dem
    from .render import print_klv_job

    console.rule("KLV in: MISB ST 0601 + ST 0903 VMTI -> fixes, footprints, map (eoloc klv)")
    dem = open_dem(data / "longs_peak_srtmgl3.tif")
    budget = ErrorBudget.from_mapping(load_config(data / "klv.toml").accuracy.budget)
    job = klv_job(data / "flight.klv", dem=dem, budget=budget)
    print_klv_job(job, console, console)
    written, _ = write_klv_products(job, out_dir)
    console.print("wrote " + ", ".join(str(p) for p in written))
    v = job.vmti
    truth = _read_truth(data / "truth.csv")
    with (data / "vmti_targets.csv").open() as fh:
        names = {r["vmti_target_id"]: r["target_id"] for r in csv.DictReader(fh)}
    ids = np.array([names.get(str(i), str(i)) for i in v.extra["target_id"]], dtype=object)
    t = np.array([truth.get(i, (np.nan,) * 3) for i in ids])
    err = np.where(v.fixes.ok, horizontal_distance_m(v.fixes.lat_deg, v.fixes.lon_deg, t[:, 0], t[:, 1]), np.nan)
    known = np.isfinite(t[:, 0])
    console.print(_error_table("VMTI targets from the KLV stream, located on the DEM, against the survey",
                               ids[known], err[known]))
    console.print("[dim]Same flight as the CSV run above, through the KLV path: heading sent with 0.0055° steps "
                  "(tag 5), heights as MSL (tag 15, back to ellipsoidal through EGM96), pixels as whole VMTI "
                  f"pixels. Open {out_dir / 'map.html'} in a browser (it works offline).[/]")


def run_batch_demo(out_dir: Path, *, console: Console, data: Path) -> None:
    """An archive: the mountain flight's stream and four generated circling flights, each file a
    task, into one GeoParquet dataset per layer (eoloc batch), run twice to show the resume."""
    import shutil

    from ..io.klv.synthetic import write_circling_flights
    from ..jobs.batch import BatchSettings, batch_job
    from .render import batch_table

    console.rule("An archive: every recording a task -> GeoParquet datasets (eoloc batch)")
    inputs = out_dir / "recordings"
    write_circling_flights(inputs, 4, 300)
    shutil.copy(data / "flight.klv", inputs / "mountain.klv")
    settings = BatchSettings(str(out_dir / "datasets"))
    job = batch_job([str(inputs)], settings, redo=True)
    console.print(batch_table(job))
    again = batch_job([str(inputs)], settings)
    console.print(f"run again: {again.counts()} (nothing changed, nothing redone). Read the fixes with "
                  f"geopandas.read_parquet('{settings.out_dir}/fixes') or DuckDB: SELECT * FROM "
                  f"read_parquet('{settings.out_dir}/fixes/*/*.parquet', hive_partitioning = true)")


def run_live_demo(out_dir: Path, *, console: Console, data: Path) -> None:
    """A live session on loopback: the mountain flight muxed into MPEG-TS, sent as ST 1402
    datagrams to `eoloc live` (the real command, its own process), Cursor-on-Target out by UDP to a
    receiver here, NDJSON to a file; what went where printed."""
    import json
    import socket
    import subprocess
    import sys
    import threading
    import time

    from ..io.klv.mux import write_klv_ts
    from ..io.klv.reader import split_klv
    from ..io.mapview import write_map
    from ..live.sources import DatagramSink, file_datagrams

    console.rule("Live: MPEG-TS over UDP -> eoloc live -> Cursor-on-Target (TAK), a live map, KLV out, NDJSON")
    out_dir.mkdir(parents=True, exist_ok=True)
    packets = split_klv((data / "flight.klv").read_bytes())
    ts = write_klv_ts(out_dir / "flight.ts", [packets], video_fps=10)

    def free_port() -> int:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    port, cot_port = free_port(), free_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        map_port = s.getsockname()[1]
    cot = DatagramSink(f"udp://127.0.0.1:{cot_port}")  # the TAK client's place: every CoT datagram kept
    ndjson = out_dir / "live.ndjson"
    cmd = [sys.executable, "-m", "eoloc", "live", f"udp://127.0.0.1:{port}", "--dem",
           str(data / "longs_peak_srtmgl3.tif"), "--config", str(data / "klv.toml"), "--cot",
           f"udp://127.0.0.1:{cot_port}", "--ndjson", str(ndjson), "--klv-out", str(out_dir / "klv_out.ts"),
           "--map", f"127.0.0.1:{map_port}", "--packets", str(len(packets) - 1), "--duration", "60"]
    console.print("$ " + " ".join(["eoloc", *cmd[3:]]), highlight=False, soft_wrap=True)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    while "listening on" not in (line := proc.stdout.readline()):
        if not line:
            raise RuntimeError("eoloc live did not start")
    browser = {"packets": 0}

    def watch_map() -> None:  # a browser's view: the live map's WebSocket
        from websockets.exceptions import ConnectionClosed
        from websockets.sync.client import connect

        try:
            with connect(f"ws://127.0.0.1:{map_port}/v1/live/ws") as ws:
                for message in ws:
                    browser["packets"] += json.loads(message)["type"] == "packet"
        except ConnectionClosed:  # the session ended: eoloc live stops its server
            pass

    threading.Thread(target=watch_map, daemon=True).start()
    time.sleep(0.3)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = 0
    for datagram, _ in file_datagrams(str(ts), lambda: False):
        tx.sendto(datagram, ("127.0.0.1", port))
        sent += 1
        time.sleep(0.005)
    log, _ = proc.communicate(timeout=120)
    time.sleep(0.3)
    cot.stop()
    received = cot.datagrams
    summary = json.loads(log[log.index("{", log.index("eoloc live stopped")):].splitlines()[0])
    (out_dir / "cot_received.xml").write_bytes(b"\n".join(received))
    kinds: dict[str, int] = {}
    for ev in received:
        kind = ev.split(b' type="', 1)[1].split(b'"', 1)[0].decode() if b' type="' in ev else "?"
        kinds[kind] = kinds.get(kind, 0) + 1
    names = {"a-f-A-M-F-Q": "aircraft + sensor FOV", "b-m-p-s-p-i": "frame centre (SPI)", "u-d-f": "footprint",
             "a-u-G": "targets"}
    console.print(f"sent {sent} UDP datagrams of MPEG-TS ({ts.stat().st_size:,} bytes, {len(packets)} KLV packets "
                  f"with the corrupt one); eoloc live: {summary['packets']} packets, {summary['corrupt']} corrupt "
                  f"(named), {summary['fixes_ok']} targets located, latency p50 "
                  f"{summary['latency_ms_median']:.1f} ms")
    console.print("CoT received on udp://127.0.0.1:" + str(cot_port) + ": " + ", ".join(
        f"{n} {names.get(k, k)}" for k, n in kinds.items()) + f" -> {out_dir / 'cot_received.xml'}")
    feats = [json.loads(line) for line in ndjson.read_text(encoding="utf-8").splitlines()]
    by = {w: [f for f in feats if f["properties"]["what"] == w and f["geometry"]] for w in
          ("aircraft", "footprint", "target", "estimate")}
    track = [f["geometry"]["coordinates"] for f in by["aircraft"]]
    last_estimates = {f["properties"]["target_id"]: f for f in by["estimate"]}
    page = write_map(out_dir / "map.html", aircraft=[{"type": "Feature", "properties": {},
                                                     "geometry": {"type": "LineString", "coordinates": track}}],
                     footprints=by["footprint"][::5], targets=list(last_estimates.values()),
                     title="eoloc live: the session's aircraft, footprints and refined targets")
    console.print(f"live map (http://127.0.0.1:{map_port}/live while it ran): {browser['packets']} packet updates "
                  f"reached a WebSocket client; the session drawn after: {page}")
    klv = summary.get("klv_out", {})
    console.print(f"KLV out: {klv.get('with_target', 0)} of {klv.get('packets', 0)} packets with their first target "
                  f"in ST 0601 tags 40-42, 45, 46, the H.264 video passed on untouched -> {out_dir / 'klv_out.ts'}")
    console.print(f"NDJSON (one GeoJSON feature per line): {ndjson}. In ATAK/WinTAK: point `eoloc live --cot "
                  "udp://239.2.3.1:6969` at the SA multicast, or `--cot tcp://TAKSERVER:8087` at a TAK server.")
