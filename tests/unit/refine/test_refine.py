"""Refining the telemetry from the pixels (issue 52): tie points and the bundle adjustment against
flights rendered without eoloc (tests/helpers/terrain_scene.py) with injected installation, heading and
clock errors. The truths are the injected values; the ground truth of the fixes is each pixel's
ray through the scene's own camera (scipy rotations, pymap3d) to the DEM's bilinear surface."""

from __future__ import annotations

import csv
import dataclasses
import json
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pymap3d
import pytest
import terrain_scene as ts
from hypothesis import example, given, settings
from hypothesis import strategies as st
from where import DATA

from eoloc import AzElGimbal, Camera, Pose, SensorModel, open_dem
from eoloc.refine.adjust import AdjustSettings, adjust
from eoloc.refine.tiepoints import (
    TieSettings,
    choose_pairs,
    find_tie_points,
    keypoints,
    mutual_matches,
    predicted_overlap,
)
from eoloc.rules import OnDEM
from eoloc.sequence.calibration import TelemetryTrack, pose_with_biases

ERRORS = ts.Errors(mount_deg=(0.3, -0.6, 0.4), heading_bias_deg=1.2, time_offset_s=0.3)
TIMES = np.arange(0.0, 60.0, 2.0)  # keyframes: 30 over a minute of orbit (48 deg of it)
NAMES = ("mount_x_deg", "mount_y_deg", "mount_z_deg", "heading_bias_deg", "time_offset_s")


def truth_vector(err: ts.Errors) -> np.ndarray:
    return np.array([*err.mount_deg, err.heading_bias_deg, err.time_offset_s])


def sensor(mount=(0.0, 0.0, 0.0)) -> SensorModel:
    k = ts.K()
    return SensorModel(Camera(ts.W, ts.H, k[0, 0], k[1, 1], k[0, 2], k[1, 2]), AzElGimbal(),
                       mount_misalignment_deg=mount)


def track_of(rows: list[dict]) -> TelemetryTrack:
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    pose = Pose(col["lat_deg"], col["lon_deg"], col["h_m"], col["yaw_deg"], col["pitch_deg"], col["roll_deg"],
                gimbal_deg=(col["azimuth_deg"], col["elevation_deg"], np.zeros(len(rows))))
    return TelemetryTrack(col["time_s"], pose)


@pytest.fixture(scope="module")
def orbit(tmp_path_factory):
    """The orbit's keyframes rendered with the mounting error, and the DEM for eoloc."""
    folder = tmp_path_factory.mktemp("orbit")
    flight = ts.Flight()
    images = [ts.render(flight, ERRORS, t) for t in TIMES]
    dem_path = ts.write_dem(folder / "dem.tif")
    return flight, images, dem_path, open_dem(dem_path, vertical="ellipsoid")


def refine_frames(images, flight, err, dem, s: SensorModel, times=TIMES):
    track = track_of(ts.telemetry_rows(flight, err, float(times[-1])))
    rule = OnDEM(dem)
    start = pose_with_biases(None, track, times, 0.0, 0.0)
    overlap = predicted_overlap([s] * len(times), [start.take(i) for i in range(len(times))], rule)
    ties = find_tie_points(images, choose_pairs(overlap, TieSettings()))
    return adjust([s], np.zeros(len(times), np.int64), track, times, ties, rule, dem, AdjustSettings()), track, rule


def horizontal_errors(flight, err, dem, s: SensorModel, track, rule, heading, offset, n_frames=8, per_frame=25):
    """Horizontal distance (m) from each of n_frames x per_frame truth points to its pixel located
    by eoloc with sensor ``s`` and the telemetry corrected by ``heading``/``offset``."""
    rng = np.random.default_rng(5)
    out = []
    for t in np.linspace(1.0, 57.0, n_frames):
        u, v, truth = ts.ground_truth_points(flight, err, float(t), per_frame, rng)
        ok = np.isfinite(truth[:, 0])
        pose = pose_with_biases(None, track, np.array([t]), heading, offset).take(0)
        f = rule.locate(s, pose, np.stack([u[ok], v[ok]], -1))
        e, n, _ = pymap3d.geodetic2enu(f.lat_deg, f.lon_deg, f.h_m, truth[ok, 0], truth[ok, 1], truth[ok, 2])
        out.append(np.where(f.ok, np.hypot(e, n), np.inf))
    return np.concatenate(out)


def test_sift_points_are_where_a_mirror_puts_them(orbit):
    """OpenCV's SIFT reports points a quarter pixel down-right of where they are; mirroring the
    image moves a point by twice any such offset, so the points of an image and of its mirror,
    mirrored back, must coincide (median over > 100 points within 0.03 px)."""
    image = orbit[1][5]
    a, da = keypoints(image)
    for axis in (0, 1):
        b, db = keypoints(np.ascontiguousarray(np.flip(image, axis=1 - axis)))
        b[:, axis] = image.shape[1 - axis] - 1 - b[:, axis]
        m = cv2.BFMatcher().match(da, db)
        d = np.array([a[x.queryIdx] - b[x.trainIdx] for x in m])
        d = d[np.hypot(d[:, 0], d[:, 1]) < 1.0]
        assert len(d) > 100
        assert np.abs(np.median(d, axis=0)).max() < 0.03, np.median(d, axis=0)


def test_matches_are_opencvs_mutual_ratio_tested_neighbours(orbit):
    """The BLAS matcher = OpenCV's brute-force matcher asked both ways (k=2, Lowe's ratio 0.8,
    mutual best), pair for pair, on two frames of the orbit."""
    images = orbit[1]
    _, d1 = keypoints(images[3])
    _, d2 = keypoints(images[6])
    bf = cv2.BFMatcher(cv2.NORM_L2)

    def one_way(a, b):
        return {m[0].queryIdx: m[0].trainIdx for m in bf.knnMatch(a, b, k=2)
                if len(m) == 2 and m[0].distance < 0.8 * m[1].distance}

    ab, ba = one_way(d1, d2), one_way(d2, d1)
    expected = {(a, b) for a, b in ab.items() if ba.get(b) == a}
    got = {tuple(int(x) for x in m) for m in mutual_matches(d1, d2, 0.8)}
    assert len(expected) > 200
    # a distance within float32 rounding of the ratio's edge may fall either way
    assert len(got ^ expected) <= 0.002 * len(expected), (len(got - expected), len(expected - got))


def test_orbit_biases_recovered_within_two_sigma_and_fixes_five_times_better(orbit):
    flight, images, _, dem = orbit
    s = sensor()
    ref, track, rule = refine_frames(images, flight, ERRORS, dem, s)
    assert ref.names == NAMES
    err = ref.values - truth_vector(ERRORS)
    assert np.all(np.abs(err) <= 2 * ref.sigma), (ref.values, ref.sigma)
    # the sigmas mean something: far tighter than the priors, and than the injected errors
    assert np.all(ref.sigma < [0.05, 0.05, 0.05, 0.1, 0.02]), ref.sigma
    assert not ref.undetermined
    rb, ra = np.hypot(*ref.residual_px_before.T), np.hypot(*ref.residual_px_after.T)
    assert np.sqrt(np.nanmean(ra ** 2)) < 0.5 < 5 < np.sqrt(np.nanmean(rb ** 2))
    before = horizontal_errors(flight, ERRORS, dem, s, track, rule, 0.0, 0.0)
    after = horizontal_errors(flight, ERRORS, dem, ref.sensors[0], track, rule, ref.heading_bias_deg,
                              ref.time_offset_s)
    ce90_before, ce90_after = np.percentile(before, 90), np.percentile(after, 90)
    assert len(before) >= 150
    assert ce90_before > 5 * ce90_after, (ce90_before, ce90_after)
    assert ce90_after < 5.0


def test_a_keyframe_at_the_telemetrys_end_claims_no_certainty(orbit):
    """The last keyframe exactly at the last record: a step of the clock offset takes it off the
    telemetry. That must not count as information (it once made the offset's sigma 5e-10 s): the
    offset's sigma stays of the order the other frames give (> 1e-5 s)."""
    flight, images, _, dem = orbit
    s = sensor()
    rows = [r for r in ts.telemetry_rows(flight, ERRORS, float(TIMES[-1])) if r["time_s"] <= TIMES[-1] + 1e-9]
    track = track_of(rows)
    rule = OnDEM(dem)
    start = pose_with_biases(None, track, TIMES, 0.0, 0.0)
    ties = find_tie_points(images, choose_pairs(
        predicted_overlap([s] * len(TIMES), [start.take(i) for i in range(len(TIMES))], rule), TieSettings()))
    ref = adjust([s], np.zeros(len(TIMES), np.int64), track, TIMES, ties, rule, dem, AdjustSettings())
    assert ref.sigma[NAMES.index("time_offset_s")] > 1e-5, ref.sigma


def test_with_nothing_wrong_it_corrects_nothing(orbit):
    """The same frames, the mounting given in the config and the telemetry right: every estimate
    within 2 sigma of the truth (the mounting as configured, no heading bias, no clock offset)."""
    flight, images, _, dem = orbit
    right = ts.Errors(mount_deg=ERRORS.mount_deg)
    ref, _, _ = refine_frames(images, flight, right, dem, sensor(ERRORS.mount_deg))
    err = ref.values - truth_vector(right)
    assert np.all(np.abs(err) <= 2 * ref.sigma), (ref.values, ref.sigma)
    assert np.all(ref.sigma < [0.05, 0.05, 0.05, 0.1, 0.02])


def test_a_straight_pass_over_flat_ground_says_what_it_cannot_separate(tmp_path):
    """Constant attitude, the turret still, flat ground: a clock offset moves every fix along the
    track alike, which no tie point can see, and the mount's yaw is the heading bias. The answer
    must say so (undetermined / correlated) and stay honest: every estimate within 3 sigma."""
    flight = ts.Flight(straight=True, flat=True, gusts=False)
    times = np.arange(0.0, 24.0, 2.0)
    images = [ts.render(flight, ERRORS, t) for t in times]
    dem = open_dem(ts.write_dem(tmp_path / "flat.tif", flat=True), vertical="ellipsoid")
    ref, _, _ = refine_frames(images, flight, ERRORS, dem, sensor(), times)
    assert "time_offset_s" in ref.undetermined
    said = " ".join(ref.warnings)
    assert "mount_z_deg and heading_bias_deg" in said and "time_offset_s" in said
    err = ref.values - truth_vector(ERRORS)
    assert np.all(np.abs(err) <= 3 * ref.sigma), (ref.values, ref.sigma)


POSITION_BIAS = (6.0, -4.0, 3.0)  # the GPS reads 6 m east, 4 m south, 3 m up of the truth


def test_a_reference_ortho_makes_it_absolute(orbit, tmp_path):
    """A GPS position bias moves every fix alike: the frames still agree with each other, so tie
    points cannot see it and the relative solution says it is relative. With an orthophoto of the
    ground (`terrain_scene.write_reference`: UTM 13N, 2.5 m cells, sampled from the scene's own
    texture) the keyframes' control points make the solution absolute: the position bias within
    2 sigma, the other biases too, and the fixes within 1 m CE90 of the truth."""
    from eoloc.io.raster import read_reference_band
    from eoloc.refine.register import Reference, control_points

    flight, images, _, dem = orbit
    err = ts.Errors(mount_deg=ERRORS.mount_deg, heading_bias_deg=ERRORS.heading_bias_deg,
                    time_offset_s=ERRORS.time_offset_s, position_enu_m=POSITION_BIAS)
    s = sensor()
    track = track_of(ts.telemetry_rows(flight, err, float(TIMES[-1])))
    rule = OnDEM(dem)
    start = pose_with_biases(None, track, TIMES, 0.0, 0.0)
    poses = [start.take(i) for i in range(len(TIMES))]
    ties = find_tie_points(images, choose_pairs(predicted_overlap([s] * len(TIMES), poses, rule), TieSettings()))
    relative = adjust([s], np.zeros(len(TIMES), np.int64), track, TIMES, ties, rule, dem, AdjustSettings())
    assert any("relative" in w for w in relative.warnings)
    ref = Reference(*read_reference_band(ts.write_reference(tmp_path / "ortho.tif", half_m=3000.0)), sigma_m=1.0)
    control = control_points(images, [s] * len(TIMES), poses, rule, ref)
    assert len(control) > 20 * len(TIMES) * 0.5
    settings = AdjustSettings(estimate=("mount", "heading", "time", "position"))
    absolute = adjust([s], np.zeros(len(TIMES), np.int64), track, TIMES, ties, rule, dem, settings, control=control,
                      control_sigma_m=0.5 * ref.cell_m, control_shared_sigma_m=ref.sigma_m)
    assert not any("relative" in w for w in absolute.warnings)
    truth = np.r_[truth_vector(ERRORS), POSITION_BIAS]
    assert np.all(np.abs(absolute.values - truth) <= 2 * absolute.sigma), (absolute.values, absolute.sigma)
    # the reference's 1 m georeferencing moves the whole solution: east/north sigma at least that
    assert np.all(absolute.sigma[-3:-1] >= 1.0) and np.all(absolute.sigma[-3:] < 1.5), absolute.sigma

    def ce90(r, position):
        from eoloc.refine.adjust import shift_position

        errs = []
        rng = np.random.default_rng(5)
        for t in np.linspace(1.0, 57.0, 8):
            u, v, p = ts.ground_truth_points(flight, err, float(t), 25, rng)
            ok = np.isfinite(p[:, 0])
            pose = shift_position(pose_with_biases(None, track, np.array([t]), r.heading_bias_deg, r.time_offset_s),
                                  np.asarray(position)).take(0)
            f = rule.locate(r.sensors[0], pose, np.stack([u[ok], v[ok]], -1))
            e, n, _ = pymap3d.geodetic2enu(f.lat_deg, f.lon_deg, f.h_m, p[ok, 0], p[ok, 1], p[ok, 2])
            errs.append(np.where(f.ok, np.hypot(e, n), np.inf))
        return np.percentile(np.concatenate(errs), 90)

    ce90_relative = ce90(relative, (0.0, 0.0, 0.0))
    ce90_absolute = ce90(absolute, absolute.values[-3:])
    print(f"reference: {len(control)} control points; estimates {absolute.values} +- {absolute.sigma}; CE90 "
          f"relative {ce90_relative:.2f} m, absolute {ce90_absolute:.2f} m")
    assert ce90_absolute <= 1.0, (ce90_relative, ce90_absolute)
    assert ce90_relative > 3 * ce90_absolute, (ce90_relative, ce90_absolute)


def truth_detections(flight, path: Path, times, seed: int,
                     video_offset_s: float = 0.0) -> tuple[list[dict], np.ndarray]:
    """20 pixels per scene time of ``times`` as a detections CSV at ``path`` (time_s: the scene's
    time + ``video_offset_s``, the video's clock), and the ground (lat, lon, h) each truly sees."""
    rng = np.random.default_rng(seed)
    dets, truth = [], []
    for t in times:
        u, v, p = ts.ground_truth_points(flight, ERRORS, float(t), 20, rng)
        for i in np.flatnonzero(np.isfinite(p[:, 0])):
            dets.append({"time_s": float(t) + video_offset_s, "target_id": f"p{len(dets)}", "u_px": float(u[i]),
                         "v_px": float(v[i])})
            truth.append(p[i])
    write_csv(path, dets)
    return dets, np.array(truth)


def located(tel: Path, dets_path: Path, cfg: Path, dem_path: Path, dets, truth, out: Path, *extra):
    """`eoloc locate TEL DETS --config CFG --dem --interpolate [extra]`: each truth pixel's horizontal
    error (m) and its fix's row."""
    r = eoloc("locate", tel, dets_path, "--config", cfg, "--dem", dem_path, "--vertical", "ellipsoid",
              "--interpolate", "--json", "--out", out, *extra)
    assert r.returncode == 0, r.stderr
    fixes = {f["target_id"]: f for f in json.loads(r.stdout)["fixes"]}
    err, rows = [], []
    for d, p in zip(dets, truth, strict=True):
        f = fixes[d["target_id"]]
        assert f["status"] == "OK"
        e, n, _ = pymap3d.geodetic2enu(f["lat_deg"], f["lon_deg"], f["h_m"], *p)
        err.append(np.hypot(e, n))
        rows.append(f)
    return np.array(err), rows


def located_ce90(tel: Path, dets_path: Path, cfg: Path, dem_path: Path, dets, truth, out: Path) -> float:
    """CE90 (m) of `eoloc locate TEL DETS --config CFG --dem --interpolate` against the truth."""
    return float(np.percentile(located(tel, dets_path, cfg, dem_path, dets, truth, out)[0], 90))


def write_video(path: Path, images, rate: Fraction) -> None:
    import av

    with av.open(str(path), "w") as c:
        s = c.add_stream("libx264", rate=rate)
        s.width, s.height, s.pix_fmt = ts.W, ts.H, "yuv420p"
        s.options = {"crf": "8", "preset": "veryfast"}
        for img in images:
            frame = av.VideoFrame.from_ndarray(cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), format="rgb24")
            for p in s.encode(frame):
                c.mux(p)
        for p in s.encode():
            c.mux(p)


def write_csv(path: Path, rows: list[dict]) -> None:
    keys = list(rows[0])
    path.write_text(",".join(keys) + "\n" + "".join(",".join(str(r[k]) for k in keys) + "\n" for r in rows))


def eoloc(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eoloc", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


BUDGET = """
[accuracy.budget]
mount_x_deg = {normal = 1.0}
mount_y_deg = {normal = 1.0}
mount_z_deg = {normal = 1.0}
yaw_deg = {normal = 2.0, kind = "bias"}
time_s = {normal = 0.5}
lat_deg = {normal = 4.5e-5}
lon_deg = {normal = 6e-5}
h_m = {normal = 5.0}
u_px = {normal = 0.5}
v_px = {normal = 0.5}
terrain_m = {normal = 1.0}
"""


def test_cli_refines_a_video_and_the_refined_telemetry_locates_better(orbit, tmp_path):
    """`eoloc refine` on an H.264 video of the orbit with a telemetry CSV, a config with an error
    budget (the priors) and an orthophoto of the ground (--reference): the estimates within 2 sigma
    (the GPS position bias, none here, too), the solution absolute, the files written; then
    `eoloc locate --covariance` with telemetry_refined.csv and config_refined.toml puts truth pixels
    5x closer (CE90) than with the telemetry as given, and says so: the refined budget holds the
    estimates' sigma, its stated CE90 is 5x smaller, and both cover the truth."""
    flight, images, dem_path, dem = orbit
    video = tmp_path / "orbit.mp4"
    write_video(video, images, Fraction(1, 2))  # a frame every 2 s: the keyframes' times
    rows = ts.telemetry_rows(flight, ERRORS, float(TIMES[-1]))
    write_csv(tmp_path / "tel.csv", rows)
    k = ts.K()
    fx, fy, cx, cy = (float(x) for x in (k[0, 0], k[1, 1], k[0, 2], k[1, 2]))
    (tmp_path / "cam.toml").write_text(
        f"# the orbit's camera\n[camera]\nwidth = {ts.W}\nheight = {ts.H}\nfx = {fx!r}\nfy = {fy!r}\n"
        f"cx = {cx!r}\ncy = {cy!r}\n\n[gimbal]\nmodel = \"az-el\"\n" + BUDGET)
    out = tmp_path / "out"
    ortho = ts.write_reference(tmp_path / "ortho.tif", half_m=3000.0)
    r = eoloc("refine", video, "--telemetry", tmp_path / "tel.csv", "--config", tmp_path / "cam.toml", "--dem",
              dem_path, "--vertical", "ellipsoid", "--every-s", 2, "--reference", ortho, "--reference-sigma", 0.5,
              "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    rep = json.loads(r.stdout)
    names = (*NAMES, "position_e_m", "position_n_m", "position_u_m")
    values = np.array([rep["parameters"][n] for n in names])
    sigma = np.array([rep["sigma"][n] for n in names])
    assert rep["keyframes"] == len(TIMES)
    assert rep["absolute"] and rep["control_points"] > 10 * len(TIMES)
    assert np.all(np.abs(values - np.r_[truth_vector(ERRORS), 0.0, 0.0, 0.0]) <= 2 * sigma), (values, sigma)
    for name in ("refine.json", "telemetry_refined.csv", "config_refined.toml", "tiepoints.csv", "residuals.png"):
        assert (out / name).stat().st_size > 0, name
    assert cv2.imread(str(out / "residuals.png")) is not None
    assert "# the orbit's camera" in (out / "config_refined.toml").read_text()  # comments kept
    # truth pixels at times between the keyframes, located with each telemetry
    # the refined budget: what was estimated now at its estimate's sigma (a bias), the rest as it was
    import tomllib

    budget = tomllib.loads((out / "config_refined.toml").read_text())["accuracy"]["budget"]
    sig = rep["sigma"]
    for name, source in (("mount_x_deg", "mount_x_deg"), ("mount_z_deg", "mount_z_deg"),
                         ("heading_bias_deg", "yaw_deg"), ("time_offset_s", "time_s")):
        assert budget[source] == {"normal": float(f"{sig[name]:.3g}"), "kind": "bias"}, (source, budget[source])
    # the position is Gauss-Markov (tau 300 s): its wander about the pass's mean (58 s) stays,
    # sigma sqrt(58 / 900); 111 035 m per degree of latitude at 40 deg N (pyproj's Geod)
    wander = np.sqrt(58 / 900)
    assert budget["h_m"]["normal"] == pytest.approx(np.hypot(sig["position_u_m"], 5.0 * wander), rel=0.01)
    assert budget["lat_deg"]["normal"] * 111_035 == pytest.approx(np.hypot(sig["position_n_m"], 4.5e-5 * 111_035
                                                                           * wander), rel=0.01)
    assert budget["u_px"] == {"normal": 0.5} and budget["vibration_yaw_deg"] == {"normal": 0.01, "kind": "noise"}
    assert len(rep["budget"]) == 11 and rep["frame_sigma_deg"] == 0.01
    # truth pixels at times between the keyframes, located with each telemetry and its budget
    dets, truth = truth_detections(flight, tmp_path / "dets.csv", np.linspace(3.0, 55.0, 6), 3)
    loc = {name: located(tel, tmp_path / "dets.csv", cfg, dem_path, dets, truth, tmp_path / f"loc_{name}",
                         "--covariance")
           for name, tel, cfg in (("given", tmp_path / "tel.csv", tmp_path / "cam.toml"),
                                  ("refined", out / "telemetry_refined.csv", out / "config_refined.toml"))}
    ce90 = {name: float(np.percentile(err, 90)) for name, (err, _) in loc.items()}
    stated = {name: np.array([f["ce90_m"] for f in rows]) for name, (_, rows) in loc.items()}
    assert ce90["given"] > 5 * ce90["refined"], ce90
    assert np.median(stated["given"]) > 5 * np.median(stated["refined"]), {k: np.median(v) for k, v in stated.items()}
    for name, (err, _) in loc.items():  # each fix's truth within its stated CE90 (nine in ten or more)
        assert np.mean(err <= stated[name]) >= 0.9, (name, np.mean(err <= stated[name]))
    # `eoloc video --refine`: refined first (into OUT/refine/), then every frame posed by the refined
    # telemetry: the aircraft where it was at the frame's time, its heading without the bias
    vid = tmp_path / "vid"
    r = eoloc("video", video, "--telemetry", tmp_path / "tel.csv", "--config", tmp_path / "cam.toml", "--dem",
              dem_path, "--vertical", "ellipsoid", "--refine", "--no-frames", "--no-mosaic", "--no-tiles",
              "--no-player", "--out", vid)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert json.loads((vid / "refine" / "refine.json").read_text())["keyframes"] == len(TIMES)
    import csv

    frames = list(csv.DictReader((vid / "frames.csv").open()))
    assert len(frames) == len(TIMES)
    for row, t in zip(frames, TIMES, strict=True):
        lat, lon, h, yaw, *_ = flight.state(float(t))
        e, n, _ = pymap3d.geodetic2enu(float(row["lat_deg"]), float(row["lon_deg"]), float(row["h_m"]), lat, lon, h)
        assert np.hypot(e, n) < 1.0, (t, e, n)  # 15 m with the clock 0.3 s off at 50 m/s
        assert abs((float(row["yaw_deg"]) - float(yaw) + 180) % 360 - 180) < 0.1, (t, row["yaw_deg"], yaw)


PHOTO_W, PHOTO_H, PHOTO_F = 640, 480, 560.0
PHOTO_MOUNT = (0.0, 0.4, -0.3)  # the camera's mounting error (deg, about its body x, y, z)
PHOTO_YAW_BIAS = 1.5  # the gimbal yaw reads 1.5 deg high


def photo_set(folder: Path, n: int = 20):
    """n overlapping DJI photos (XMP Version 7.0: ellipsoidal altitude; calibrated intrinsics) from
    a ring of 450 m radius, 400 m above the origin, each looking at the ring's centre from its own
    pitch (-35 .. -70 deg) and roll; the XMP attitude is the truth seen through the mounting error
    and the yaw bias. Returns each photo's path, true (c_ecef, R_ecef_cam) and true (yaw, pitch, roll)."""
    from dronephoto import write_photo
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(52)
    o = ts.origin()
    k = np.array([[PHOTO_F, 0, (PHOTO_W - 1) / 2], [0, PHOTO_F, (PHOTO_H - 1) / 2], [0, 0, 1.0]])
    R_mount = Rotation.from_euler("ZYX", PHOTO_MOUNT[::-1], degrees=True)
    out = []
    for i in range(n):
        a = 2 * np.pi * i / n
        e, nn = 450 * np.sin(a), 450 * np.cos(a)
        lat, lon, h = pymap3d.enu2geodetic(e, nn, 400.0, *o)
        yaw_t = (np.degrees(a) + 180.0 + rng.uniform(-8, 8)) % 360.0
        pitch_t, roll_t = rng.uniform(-70, -35), rng.uniform(-3, 3)
        c, R_ec = ts.photo_camera(float(lat), float(lon), float(h), yaw_t, pitch_t, roll_t)
        # what the drone writes: R_ned<-body(given) = Rz(bias) R(true) R_mount^T
        given = (Rotation.from_euler("Z", PHOTO_YAW_BIAS, degrees=True)
                 * Rotation.from_euler("ZYX", [yaw_t, pitch_t, roll_t], degrees=True) * R_mount.inv())
        yaw_g, pitch_g, roll_g = given.as_euler("ZYX", degrees=True)
        image = ts.render_view(c, R_ec, k, (PHOTO_W, PHOTO_H))
        tags = {"Version": "7.0", "GpsStatus": "Normal", "GpsLatitude": f"{float(lat):+.10f}",
                "GpsLongitude": f"{float(lon):+.10f}", "AbsoluteAltitude": f"{float(h):+.4f}",
                "RelativeAltitude": "+400.000", "GimbalYawDegree": f"{yaw_g:+.6f}",
                "GimbalPitchDegree": f"{pitch_g:+.6f}", "GimbalRollDegree": f"{roll_g:+.6f}",
                "CalibratedFocalLength": f"{PHOTO_F}", "CalibratedOpticalCenterX": f"{(PHOTO_W - 1) / 2}",
                "CalibratedOpticalCenterY": f"{(PHOTO_H - 1) / 2}"}
        path = write_photo(folder / f"DJI_{i:04d}.JPG", PHOTO_W, PHOTO_H, tags, model="FC6310", focal_mm=8.8,
                           picture=np.repeat(image[..., None], 3, axis=2))
        out.append((path, (c, R_ec), (yaw_t, pitch_t, roll_t)))
    return out, k


def sidecar_description(path: Path):
    """The rdf:Description of an XMP sidecar (xml.etree)."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(path.read_text(encoding="utf-8").split("?>", 1)[1].rsplit("<?xpacket", 1)[0])
    return next(root.iter("{http://www.w3.org/1999/02/22-rdf-syntax-ns#}Description"))


def test_a_photo_set_refined_as_json_rows(tmp_path):
    """`eoloc refine PHOTO... --dem --json`: a ring of 20 overlapping DJI photos with a biased gimbal
    yaw and a camera mounting error. One row per photo under `eoloc photo --json`'s keys; the shared
    mounting error and yaw bias (refine.json) and every refined camera yaw/pitch/roll within 2 of
    its sigma of the truth (sigma under 0.1 deg; before the outliers were judged on the tie points'
    own noise, matches a few pixels off along the epipolar line put this ring's heading 2.3 sigma
    off), and the truth pixels located with the refined attitude 5x closer (CE90) than with the
    XMP's; the refined poses
    written as OpenDroneMap's geo.txt and taken back by `eoloc photo --poses`, its fixes 5x closer."""
    folder = tmp_path / "photos"
    folder.mkdir()
    photos, k = photo_set(folder)
    dem_path = ts.write_dem(tmp_path / "dem.tif")
    r = eoloc("refine", folder, "--dem", dem_path, "--vertical", "ellipsoid", "--json", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
    assert [Path(x["file"]).name for x in rows] == [p.name for p, _, _ in photos]
    keys = {"file", "camera_lat", "camera_lon", "camera_h", "camera_yaw", "camera_pitch", "camera_roll",
            "sigma_camera_yaw", "sigma_camera_pitch", "sigma_camera_roll"}
    assert all(keys <= set(x) for x in rows)
    photo_json = eoloc("photo", photos[0][0], "--dem", dem_path, "--vertical", "ellipsoid", "--json", "--out",
                       tmp_path / "p")
    assert photo_json.returncode == 0, photo_json.stderr
    given = json.loads(photo_json.stdout.splitlines()[0])
    assert given["camera_yaw"] == pytest.approx(rows[0]["given_camera_yaw"], abs=1e-9)
    rep = json.loads((tmp_path / "out" / "refine.json").read_text())
    for name, truth in (("mount_x_deg", PHOTO_MOUNT[0]), ("mount_y_deg", PHOTO_MOUNT[1]),
                        ("mount_z_deg", PHOTO_MOUNT[2]), ("heading_bias_deg", PHOTO_YAW_BIAS)):
        assert abs(rep["parameters"][name] - truth) <= 2 * rep["sigma"][name], (name, rep["parameters"], rep["sigma"])
    for row, (_, _, truth) in zip(rows, photos, strict=True):
        got = np.array([row["camera_yaw"], row["camera_pitch"], row["camera_roll"]])
        sig = np.array([row["sigma_camera_yaw"], row["sigma_camera_pitch"], row["sigma_camera_roll"]])
        diff = (got - np.array(truth) + 180.0) % 360.0 - 180.0
        assert np.all(sig < 0.1), sig
        assert np.all(np.abs(diff) <= 2 * sig + 1e-4), (row["file"], diff, sig)
    # the truth seen at pixels of three photos, located with each attitude on the DEM
    dem = open_dem(dem_path, vertical="ellipsoid")
    rule = OnDEM(dem)
    cam = Camera(PHOTO_W, PHOTO_H, PHOTO_F, PHOTO_F, (PHOTO_W - 1) / 2, (PHOTO_H - 1) / 2)
    s = SensorModel(cam, AzElGimbal())
    rng = np.random.default_rng(9)
    err = {"given": [], "refined": []}
    for row, (_, (c, R_ec), _) in list(zip(rows, photos, strict=True))[::4]:
        u, v = rng.uniform(30, PHOTO_W - 30, 25), rng.uniform(30, PHOTO_H - 30, 25)
        truth = ts.ground_points(c, R_ec, k, u, v)
        ok = np.isfinite(truth[:, 0])
        for name, pre in (("given", "given_"), ("refined", "")):
            pose = Pose(row["camera_lat"], row["camera_lon"], row["camera_h"], row[pre + "camera_yaw"],
                        row[pre + "camera_pitch"], row[pre + "camera_roll"], (0.0, 0.0))
            f = rule.locate(s, pose, np.stack([u[ok], v[ok]], -1))
            e, n, _ = pymap3d.geodetic2enu(f.lat_deg, f.lon_deg, f.h_m, truth[ok, 0], truth[ok, 1], truth[ok, 2])
            err[name].append(np.where(f.ok, np.hypot(e, n), np.inf))
    ce90 = {name: np.percentile(np.concatenate(v), 90) for name, v in err.items()}
    assert ce90["given"] > 5 * ce90["refined"], ce90
    # each photo's own XMP again with the refined attitude (OUT/xmp/NAME.xmp, read here by the standard
    # library's XML parser)
    dji = "{http://www.dji.com/drone-dji/1.0/}"
    for row in rows:
        desc = sidecar_description(tmp_path / "out" / "xmp" / f"{Path(row['file']).stem}.xmp")
        for tag, key in (("GimbalYawDegree", "camera_yaw"), ("GimbalPitchDegree", "camera_pitch"),
                         ("GimbalRollDegree", "camera_roll")):
            assert float(desc.attrib[dji + tag]) == pytest.approx(row[key], abs=1e-6)
        assert float(desc.attrib[dji + "GpsLatitude"]) == pytest.approx(row["given_camera_lat"], abs=1e-10)
    # the refined poses as ODM's image geolocation file, and back into `eoloc photo --poses`
    geo = (tmp_path / "out" / "geo.txt").read_text().splitlines()
    assert geo[0] == "EPSG:4326" and len(geo) == 1 + len(rows)
    name, lon, lat, h, yaw, *_ = geo[1].split()
    assert name == photos[0][0].name and float(lon) == pytest.approx(rows[0]["camera_lon"], abs=1e-8)
    assert float(yaw) == pytest.approx(rows[0]["camera_yaw"], abs=1e-5)
    (c, R_ec) = photos[0][1]
    u, v = rng.uniform(30, PHOTO_W - 30, 6), rng.uniform(30, PHOTO_H - 30, 6)
    truth = ts.ground_points(c, R_ec, k, u, v)
    pix = [a for uu, vv in zip(u, v, strict=True) for a in ("--pixel", uu, vv)]
    off = {}
    for name, extra in (("given", ()), ("refined", ("--poses", tmp_path / "out" / "photos_refined.csv"))):
        r = eoloc("photo", photos[0][0], *pix, "--dem", dem_path, "--vertical", "ellipsoid", "--json", "--out",
                  tmp_path / f"p_{name}", *extra)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        fixes = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
        assert len(fixes) == 6
        if name == "refined":
            assert fixes[0]["camera_yaw"] == pytest.approx(rows[0]["camera_yaw"], abs=1e-8)  # the CSV: 9 decimals
        e, n, _ = pymap3d.geodetic2enu([f["lat"] for f in fixes], [f["lon"] for f in fixes],
                                       [f["h"] for f in fixes], truth[:, 0], truth[:, 1], truth[:, 2])
        off[name] = float(np.max(np.hypot(e, n)))
    assert off["given"] > 5 * off["refined"], off
    # `eoloc photo --refine`: the same in one go (refined into OUT/refine/, then located)
    r = eoloc("photo", folder, "--dem", dem_path, "--vertical", "ellipsoid", "--refine", "--json", "--out",
              tmp_path / "p_one_go")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    first = json.loads(r.stdout.splitlines()[0])
    assert first["camera_yaw"] == pytest.approx(rows[0]["camera_yaw"], abs=1e-6)
    assert (tmp_path / "p_one_go" / "refine" / "photos_refined.csv").is_file()
    # with a budget: the fixes made with the refined poses carry what refinement left unknown
    # (config_refined.toml), their stated CE90 5x smaller than the budget's and still covering the truth
    (tmp_path / "drone.toml").write_text("[accuracy.budget]\nyaw_deg = {normal = 2.0, kind = \"bias\"}\n"
                                         "pitch_deg = {normal = 1.0, kind = \"bias\"}\n"
                                         "roll_deg = {normal = 1.0, kind = \"bias\"}\n"
                                         "mount_x_deg = {normal = 1.0}\nmount_y_deg = {normal = 1.0}\n"
                                         "mount_z_deg = {normal = 1.0}\nlat_deg = {normal = 1e-7}\n"
                                         "lon_deg = {normal = 1e-7}\nh_m = {normal = 0.1}\n")
    u, v = rng.uniform(30, PHOTO_W - 30, 4), rng.uniform(PHOTO_H / 2, PHOTO_H - 30, 4)  # the near ground
    pix = [a for uu, vv in zip(u, v, strict=True) for a in ("--pixel", uu, vv)]
    truth = np.concatenate([ts.ground_points(c, R_ec, k, u, v) for _, (c, R_ec), _ in photos])
    stated, covered = {}, {}
    for name, extra in (("given", ()), ("refined", ("--refine",))):
        r = eoloc("photo", folder, *pix, "--dem", dem_path, "--vertical", "ellipsoid", "--config",
                  tmp_path / "drone.toml", "--json", "--out", tmp_path / f"p_budget_{name}", *extra)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        fixes = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
        assert len(fixes) == len(truth)
        ok = np.isfinite(truth[:, 0]) & np.array([f["status"] == "OK" for f in fixes])
        e, n, _ = pymap3d.geodetic2enu(*np.array([[f["lat"], f["lon"], f["h"]] for f in fixes])[ok].T,
                                       *truth[ok].T)
        ce = np.array([f["ce90_m"] for f in fixes])[ok]
        stated[name], covered[name] = float(np.median(ce)), float(np.mean(np.hypot(e, n) <= ce))
    assert (tmp_path / "p_budget_refined" / "refine" / "config_refined.toml").is_file()
    assert stated["given"] > 5 * stated["refined"], stated
    assert covered["given"] >= 0.9 and covered["refined"] >= 0.9, covered
    # `eoloc locate PHOTOS --refine` (and --poses FILE): each photo's image centre located with the
    # refined pose, against the ground the true camera's centre pixel sees
    cx, cy = np.array([(PHOTO_W - 1) / 2]), np.array([(PHOTO_H - 1) / 2])
    centre_truth = np.array([ts.ground_points(c, R_ec, k, cx, cy)[0] for _, (c, R_ec), _ in photos])
    centre_err = {}
    for name, extra in (("given", ()), ("refine", ("--refine",)),
                        ("poses", ("--poses", tmp_path / "p_one_go" / "refine" / "photos_refined.csv"))):
        r = eoloc("locate", folder, "--dem", dem_path, "--vertical", "ellipsoid", "--json", "--out",
                  tmp_path / f"loc_{name}", *extra)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        fixes = json.loads(r.stdout)["fixes"]
        assert [Path(f["file"]).name for f in fixes] == [p.name for p, _, _ in photos]
        e, n, _ = pymap3d.geodetic2enu([f["lat_deg"] for f in fixes], [f["lon_deg"] for f in fixes],
                                       [f["h_m"] for f in fixes], *centre_truth.T)
        centre_err[name] = np.hypot(e, n)
    assert np.max(centre_err["refine"]) < np.percentile(centre_err["given"], 10) / 5, centre_err
    assert np.allclose(centre_err["poses"], centre_err["refine"], atol=0.05), centre_err
    # with an orthophoto of the ground: the position is estimated too (no bias here: within 2 sigma of
    # the XMP's), the attitude as before
    ortho = ts.write_reference(tmp_path / "ortho.tif", half_m=1500.0, cell_m=1.0)
    r = eoloc("refine", folder, "--dem", dem_path, "--vertical", "ellipsoid", "--reference", ortho, "--json",
              "--out", tmp_path / "out_ref")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
    for row, (_, _, truth) in zip(rows, photos, strict=True):
        assert row["refined"] == "attitude and position"
        desc = sidecar_description(tmp_path / "out_ref" / "xmp" / f"{Path(row['file']).stem}.xmp")
        assert float(desc.attrib[dji + "GpsLatitude"]) == pytest.approx(row["camera_lat"], abs=1e-9)
        assert float(desc.attrib[dji + "AbsoluteAltitude"]) == pytest.approx(row["camera_h"], abs=1e-3)  # Version 7
        e, n, u = pymap3d.geodetic2enu(row["camera_lat"], row["camera_lon"], row["camera_h"], row["given_camera_lat"],
                                       row["given_camera_lon"], row["given_camera_h"])
        assert abs(e) <= 2 * row["sigma_camera_lon_m"] and abs(n) <= 2 * row["sigma_camera_lat_m"], (e, n, row)
        assert abs(u) <= 2 * row["sigma_camera_h"], (u, row)
        got = np.array([row["camera_yaw"], row["camera_pitch"], row["camera_roll"]])
        sig = np.array([row["sigma_camera_yaw"], row["sigma_camera_pitch"], row["sigma_camera_roll"]])
        diff = (got - np.array(truth) + 180.0) % 360.0 - 180.0
        assert np.all(np.abs(diff) <= 2 * sig + 1e-4), (row["file"], diff, sig)


def test_a_klv_video_is_refined_from_its_own_metadata(orbit, tmp_path):
    """An MPEG-TS of the orbit whose ST 0601 KLV (platform attitude, sensor position with HAE,
    turret angles, fields of view, at 10 Hz) carries the injected errors: `eoloc refine VIDEO.ts
    --dem` with no telemetry file and no config; the estimates within 2 sigma; the refined CSV and
    the config written for it locate truth pixels between the keyframes within 5 m CE90."""
    from datetime import UTC, datetime

    from eoloc.io.klv.encode import encode_uas_packet, encode_vmti
    from eoloc.io.klv.mux import write_klv_ts

    flight, images, dem_path, _ = orbit
    vfov = 2 * np.degrees(np.arctan(np.tan(np.radians(ts.HFOV_DEG / 2)) * ts.H / ts.W))
    packets = []
    vmti_truth = {}  # VMTI target id -> the ground its pixel truly sees (5 targets a second, 3 s .. 55 s)
    rng = np.random.default_rng(74)
    for k, r in enumerate(ts.telemetry_rows(flight, ERRORS, float(TIMES[-1]))):
        values = {2: datetime.fromtimestamp(1_780_000_000 + r["time_s"], UTC), 5: r["yaw_deg"], 6: r["pitch_deg"],
                  7: r["roll_deg"], 13: r["lat_deg"], 14: r["lon_deg"], 75: r["h_m"], 16: ts.HFOV_DEG, 17: vfov,
                  18: r["azimuth_deg"] % 360.0, 19: r["elevation_deg"], 20: 0.0}
        if k % 10 == 0 and 3.0 <= r["time_s"] <= 55.0:  # the targets of the frame shown at the packet's time
            u, v, p = ts.ground_truth_points(flight, ERRORS, r["time_s"], 5, rng)
            ids = [100 * k + j + 1 for j in range(5) if np.isfinite(p[j, 0])]
            vmti_truth |= {i: p[(i - 1) % 100] for i in ids}
            values[74] = encode_vmti([(i, u[(i - 1) % 100], v[(i - 1) % 100]) for i in ids], ts.W, ts.H)
        packets.append((encode_uas_packet(values), r["time_s"]))
    # the stream starts with the first record (stamped -1 s): frame i is at scene time i - 1, and the
    # odd frames are the rendered ones (the keyframes, 1 s in from the metadata's start, every 2 s)
    video = write_klv_ts(tmp_path / "orbit.ts", [packets], video_fps=1.0, video_size=(ts.W, ts.H),
                         frame_source=lambda i: images[min(max(i - 1, 0) // 2, len(images) - 1)])
    out = tmp_path / "out"
    r = eoloc("refine", video, "--dem", dem_path, "--vertical", "ellipsoid", "--every-s", 2, "--json", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    rep = json.loads(r.stdout)
    values = np.array([rep["parameters"][n] for n in NAMES])
    sigma = np.array([rep["sigma"][n] for n in NAMES])
    assert np.all(np.abs(values - truth_vector(ERRORS)) <= 2 * sigma), (values, sigma)
    dets, truth = truth_detections(flight, tmp_path / "dets.csv", np.linspace(3.0, 55.0, 5), 4, video_offset_s=1.0)
    ce90 = located_ce90(out / "telemetry_refined.csv", tmp_path / "dets.csv", out / "config_refined.toml", dem_path,
                        dets, truth, tmp_path / "loc")
    assert ce90 < 5.0, ce90
    # the video again with its KLV corrected in place: only the KLV's transport packets differ
    refined = out / "orbit_refined.ts"
    before = np.frombuffer(video.read_bytes(), np.uint8).reshape(-1, 188)
    after = np.frombuffer(refined.read_bytes(), np.uint8).reshape(-1, 188)
    assert before.shape == after.shape
    changed = (before != after).any(1)
    pid = ((before[:, 1].astype(np.int64) & 0x1F) << 8) | before[:, 2]
    from stanag4609.st0601 import SpecialValue, decode_uas_local_set

    from eoloc.io.klv import read_klv

    klv_pid = int(read_klv(video).packets[0].stream.removeprefix("PID "))
    assert set(pid[changed].tolist()) == {klv_pid}
    # every packet rewritten and valid for another decoder (stanag4609 checks the checksum); the
    # last ones, whose corrected time (+0.3 s) leaves the telemetry, sent without a position
    new = read_klv(refined)
    assert len(new.packets) == len(packets) and not new.issues
    assert all(p.raw != q for p, (q, _) in zip(new.packets, packets, strict=True))
    lat = [decode_uas_local_set(p.raw).value(13) for p in new.packets]
    unknown = [i for i, x in enumerate(lat) if x is SpecialValue.RESERVED]
    assert len(unknown) in (2, 3, 4) and unknown[-1] == len(packets) - 1 and np.all(np.diff(unknown) == 1), unknown
    assert any(f"{len(unknown)} packet(s) whose corrected time leaves the telemetry" in n for n in rep["klv_notes"])
    # the corrected stream alone (no config: the installation is in the sensor angles) puts truth
    # pixels within 5 m CE90, where the stream as it came is tens of metres off
    for d in dets:
        d["time_s"] = 1_780_000_000 + d["time_s"] - 1.0  # tag 2's UNIX clock: scene time + 1.78e9
    write_csv(tmp_path / "dets_unix.csv", dets)
    (tmp_path / "cam.toml").write_text(f"[camera]\nwidth = {ts.W}\nheight = {ts.H}\nhfov_deg = {ts.HFOV_DEG!r}\n")
    ce = {}
    for name, ts_path in (("given", video), ("refined", refined)):
        r = eoloc("locate", ts_path, tmp_path / "dets_unix.csv", "--config", tmp_path / "cam.toml", "--dem", dem_path,
                  "--vertical", "ellipsoid",
                  "--interpolate", "--json", "--out", tmp_path / f"klv_{name}")
        assert r.returncode == 0, r.stderr
        fixes = {f["target_id"]: f for f in json.loads(r.stdout)["fixes"]}
        err = []
        for d, p in zip(dets, truth, strict=True):
            f = fixes[d["target_id"]]
            assert f["status"] == "OK", f
            e, n, _ = pymap3d.geodetic2enu(f["lat_deg"], f["lon_deg"], f["h_m"], *p)
            err.append(np.hypot(e, n))
        ce[name] = float(np.percentile(err, 90))
    assert ce["refined"] < 5.0 and ce["given"] > 5 * ce["refined"], ce
    # in one go: `eoloc locate TS DETS --refine` (refined into OUT/refine/, located from the refined TS
    # with the config written for it: the camera's, no installation to apply)
    r = eoloc("locate", video, tmp_path / "dets_unix.csv", "--config", tmp_path / "cam.toml", "--dem", dem_path,
              "--vertical", "ellipsoid", "--interpolate", "--refine", "--json", "--out", tmp_path / "klv_one_go")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "refined: mount_x_deg" in r.stderr
    # every second frame of this video repeats the one before it (each image shown twice): at a
    # keyframe a second those are left out, said, instead of pairing old pixels with a later pose
    assert "keyframe(s) repeat the frame before them" in r.stderr
    ts_config = tmp_path / "klv_one_go" / "refine" / "orbit_refined.toml"
    assert "mount_misalignment_deg = [0.0, 0.0, 0.0]" in ts_config.read_text()
    fixes = {f["target_id"]: f for f in json.loads(r.stdout)["fixes"]}
    e, n, _ = pymap3d.geodetic2enu([fixes[d["target_id"]]["lat_deg"] for d in dets],
                                   [fixes[d["target_id"]]["lon_deg"] for d in dets],
                                   [fixes[d["target_id"]]["h_m"] for d in dets], *truth.T)
    assert np.percentile(np.hypot(e, n), 90) < 5.0
    # `eoloc klv TS --refine`: the stream's own VMTI targets located from the refined packets (their
    # pose and sensor angles alone), against the ground each target's pixel truly sees; with a config
    # budget the fixes carry the refined one
    (tmp_path / "budget.toml").write_text("[accuracy.budget]\nmount_x_deg = {normal = 1.0}\n"
                                          "mount_y_deg = {normal = 1.0}\nmount_z_deg = {normal = 1.0}\n"
                                          "yaw_deg = {normal = 2.0, kind = \"bias\"}\ntime_s = {normal = 0.5}\n"
                                          "lat_deg = {normal = 1e-6}\nlon_deg = {normal = 1e-6}\n")
    vmti_ce, vmti_fixes = {}, {}
    for name, extra in (("given", ()), ("refined", ("--refine", "--config", tmp_path / "budget.toml"))):
        out_klv = tmp_path / f"vmti_{name}"
        r = eoloc("klv", video, "--dem", dem_path, "--vertical", "ellipsoid", "--format", "csv", "--no-map",
                  "--out", out_klv, *extra)
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        with open(out_klv / "fixes.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        assert {int(x["target_id"]) for x in rows} == set(vmti_truth)
        assert all(x["status"] == "OK" for x in rows)
        e, n, _ = pymap3d.geodetic2enu([float(x["lat_deg"]) for x in rows], [float(x["lon_deg"]) for x in rows],
                                       [float(x["h_m"]) for x in rows],
                                       *np.array([vmti_truth[int(x["target_id"])] for x in rows]).T)
        vmti_ce[name] = float(np.percentile(np.hypot(e, n), 90))
        vmti_fixes[name] = (rows, np.hypot(e, n))
    assert vmti_ce["refined"] < 5.0 and vmti_ce["given"] > 5 * vmti_ce["refined"], vmti_ce
    refined_budget = (tmp_path / "vmti_refined" / "refine" / "orbit_refined.toml").read_text()
    assert "refined by eoloc refine" in refined_budget
    rows, err = vmti_fixes["refined"]
    stated = np.array([float(x["ce90_m"]) for x in rows])
    assert np.median(stated) < 10.0, np.median(stated)  # the prior budget's: ~100 m
    assert np.mean(err <= stated) >= 0.8, np.mean(err <= stated)  # and honest


def test_repeated_frames_are_told_from_a_still_scene():
    """A keyframe whose mean difference to the frame before is compression noise (< 1 grey level,
    and a tenth of the others') repeats it; a hovering camera's frames, all alike, are none."""
    from eoloc.jobs.refine import repeated_frames

    pulldown = {k: (0.3 if k % 2 == 0 else 28.0) + 0.01 * k for k in range(1, 40)}
    assert repeated_frames(pulldown) == [k for k in range(1, 40) if k % 2 == 0]
    hover = {k: 0.4 + 0.01 * (k % 5) for k in range(1, 40)}
    assert repeated_frames(hover) == []
    assert repeated_frames({}) == []


def test_what_cannot_be_refined_is_named_without_a_traceback(tmp_path):
    """Exit status 2 and one line naming the problem: a video with neither KLV nor telemetry, a
    folder with no photo, a clock offset asked of photos, no DEM; --refine of klv and locate on
    what has no images, or without a DEM; --poses for what are not photos."""
    rng = np.random.default_rng(1)
    video = tmp_path / "v.mp4"
    write_video(video, [rng.integers(0, 255, (ts.H, ts.W), dtype=np.uint8) for _ in range(3)], Fraction(1, 1))
    dem = ts.write_dem(tmp_path / "dem.tif")
    (tmp_path / "empty").mkdir()
    (tmp_path / "notes.txt").write_text("not a photo")
    cases = [((video, "--dem", dem), "without its own KLV a video needs its telemetry: --telemetry FILE"),
             ((tmp_path / "empty", "--dem", dem), "refining needs three or more"),
             ((tmp_path / "notes.txt", "--dem", dem, "--estimate", "heading,time"), "photos have no clock offset"),
             ((tmp_path / "empty",), "refining needs the terrain")]
    for args, said in cases:
        r = eoloc("refine", *args, "--out", tmp_path / "out")
        assert r.returncode == 2, (args, r.stderr)
        assert said in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
    # --refine elsewhere: a KLV file without a video, telemetry without its images, no DEM
    from eoloc.io.klv.encode import encode_uas_packet

    klv = tmp_path / "bare.klv"
    from datetime import UTC, datetime

    klv.write_bytes(encode_uas_packet({2: datetime(2026, 11, 27, tzinfo=UTC), 13: 40.0, 14: -105.0, 15: 3000.0}))
    tel = tmp_path / "tel.csv"
    write_csv(tel, [{"time_s": 0.0, "lat_deg": 40.0, "lon_deg": -105.3, "h_m": 3000.0, "yaw_deg": 0.0,
                     "pitch_deg": 0.0, "roll_deg": 0.0, "gimbal1_deg": 0.0, "gimbal2_deg": -60.0}])
    poses = tmp_path / "poses.csv"
    write_csv(poses, [{"file": "DJI_0001.JPG", "camera_lat": 40.0, "camera_lon": -105.3, "camera_h": 3000.0,
                       "camera_yaw": 10.0, "camera_pitch": -45.0, "camera_roll": 0.0}])
    cases = [(("klv", klv, "--dem", dem, "--refine"), "raw KLV has no pixels to refine from"),
             (("klv", video, "--refine"), "--refine needs the terrain"),
             (("video", video, "--dem", dem, "--refine"), "without its own KLV a video needs its telemetry"),
             (("locate", tel, "--dem", dem, "--refine"), "is csv telemetry without them"),
             (("locate", klv, "--dem", dem, "--refine"), "raw KLV has no pixels to refine from"),
             (("locate", tel, "--dem", dem, "--poses", poses), "poses replace drone photos' own")]
    for args, said in cases:
        r = eoloc(*args, "--out", tmp_path / "out2")
        assert r.returncode == 2, (args, r.stderr)
        assert said in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)


@settings(max_examples=40, deadline=None)
@given(st.tuples(*[st.floats(-3.0, 3.0)] * 3), st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       st.floats(0.0, 360.0), st.one_of(st.floats(-90.0, 30.0), st.floats(-90.0, -89.99999)),
       st.floats(-30.0, 30.0), st.floats(-20.0, 20.0))
@example((0.0, 0.0, 0.0), (0.0, 1e-6, 0.0), 0.0, 0.0, 0.0, 0.0)  # 1e-6 deg off nadir's lock (a fresh CI found it)
def test_an_installation_folded_into_the_gimbal_angles_points_the_same_way(mount, bore, az, el, roll, pitch):
    """The refined KLV's sensor angles: a turret without installation terms at the folded angles has
    the camera orientation of the turret with them (to 1e-9 rad), nadir's gimbal lock and the
    elevations a hair from it included."""
    from scipy.spatial.transform import Rotation

    from eoloc.ground.frame import misb_sensor
    from eoloc.refine.correct import fold_installation

    pose = Pose(np.array([40.0, -33.0]), np.array([-105.0, 151.0]), np.array([3000.0, 500.0]),
                np.array([10.0, 250.0]), np.array([pitch, -pitch]), np.array([5.0, -12.0]),
                (np.array([az, 360.0 - az]), np.array([el, -90.0]), np.array([roll, 0.0])))
    s = misb_sensor(mount, bore)
    g, ok = fold_installation(s, pose)
    assert ok.all()
    want = Rotation.from_matrix(s.camera_frame(pose).R_ecef_cam.reshape(-1, 3, 3))
    got = Rotation.from_matrix(misb_sensor().camera_frame(dataclasses.replace(pose, gimbal_deg=g))
                               .R_ecef_cam.reshape(-1, 3, 3))
    assert np.all((want * got.inv()).magnitude() < 1e-9)


@settings(max_examples=300, deadline=None)
@given(st.floats(-180.0, 180.0), st.one_of(st.floats(-90.0, 90.0), st.floats(-1e-5, 1e-5).map(lambda d: 90.0 - abs(d)),
                                           st.floats(-1e-5, 1e-5).map(lambda d: abs(d) - 90.0)),
       st.floats(-180.0, 180.0))
def test_turret_angles_compose_back_to_the_rotation_also_at_the_lock(a, b, c):
    """refine.correct.zyx_angles: the angles of a Z-Y-X rotation made by scipy compose back to it to
    1e-12 rad, within 1e-5 deg of the elevation's gimbal lock too (where scipy's own as_euler gives
    up ~2e-8 rad)."""
    from scipy.spatial.transform import Rotation

    from eoloc.refine.correct import zyx_angles

    R = Rotation.from_euler("ZYX", [a, b, c], degrees=True)
    got = Rotation.from_euler("ZYX", zyx_angles(R.as_matrix()[None])[0], degrees=True)
    assert (R * got.inv()).magnitude() < 1e-12


def synthetic_ties(flight, err: ts.Errors, rng: np.random.Generator, times=TIMES, per_aim=60):
    """Tie points without pictures: ground points on the DEM around the aim points of every third
    keyframe, projected into every keyframe by the scene's own camera (pymap3d, scipy), 1-px
    Gaussian noise; tracks seen in two frames or more."""
    from eoloc.refine.tiepoints import TiePoints

    k = ts.K()
    pts = []
    for t in times[::3]:
        aim = flight.state(t)[-1]
        la, lo, _ = pymap3d.enu2geodetic(aim[0] + rng.uniform(-400, 400, per_aim),
                                         aim[1] + rng.uniform(-400, 400, per_aim), 0.0, *ts.origin())
        pts.append(np.stack([la, lo, ts.dem_height(la, lo)], -1))
    p = np.concatenate(pts)
    x = np.stack(pymap3d.geodetic2ecef(p[:, 0], p[:, 1], p[:, 2]), -1)
    frame, track, u, v = [], [], [], []
    for i, t in enumerate(times):
        c, R, _, _ = ts.true_camera(flight, err, float(t))
        xc = (x - c) @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            uu, vv = k[0, 0] * xc[:, 0] / xc[:, 2] + k[0, 2], k[1, 1] * xc[:, 1] / xc[:, 2] + k[1, 2]
        j = np.flatnonzero((xc[:, 2] > 0) & (uu > 0) & (uu < ts.W - 1) & (vv > 0) & (vv < ts.H - 1))
        frame.append(np.full(j.size, i))
        track.append(j)
        u.append(uu[j] + rng.normal(0.0, 1.0, j.size))
        v.append(vv[j] + rng.normal(0.0, 1.0, j.size))
    frame, track, u, v = map(np.concatenate, (frame, track, u, v))
    seen = np.bincount(track, minlength=len(x))
    keep = seen[track] >= 2
    return TiePoints(frame[keep], (np.cumsum(seen >= 2) - 1)[track[keep]], u[keep], v[keep], [], [])


def test_the_estimates_sigma_cover_the_truth_over_many_flights(orbit):
    """Coverage of the adjustment's own 1-sigma (what refine prints and writes into the budget):
    24 flights of the orbit with errors drawn afresh (mount 0.4, heading 1 deg, clock 0.2 s 1-sigma),
    tie points with 1-px noise: the estimates within 2 sigma of the truth in >= 90 % of the 120
    cases, none past 4 sigma, and the sigma not more than 3x too large (mean z^2 >= 0.1). The
    telemetry at 10 Hz misses the gusts' attitude between records: the per-keyframe attitude terms
    (frame_sigma_deg) are what keeps the shared biases' sigma honest (without them the clock's
    2-sigma coverage falls to ~89 %, heading's mean z^2 to 1.6)."""
    flight, _, _, dem = orbit
    z = []
    for seed in range(24):
        rng = np.random.default_rng(100 + seed)
        err = ts.Errors(mount_deg=tuple(rng.normal(0, 0.4, 3)), heading_bias_deg=float(rng.normal(0, 1.0)),
                        time_offset_s=float(rng.normal(0, 0.2)))
        ties = synthetic_ties(flight, err, rng)
        track = track_of(ts.telemetry_rows(flight, err, float(TIMES[-1])))
        ref = adjust([sensor()], np.zeros(len(TIMES), np.int64), track, TIMES, ties, OnDEM(dem), dem,
                     AdjustSettings())
        z.append((ref.values - truth_vector(err)) / ref.sigma)
    z = np.abs(np.array(z))
    assert np.mean(z <= 2.0) >= 0.9 and z.max() < 4.0, np.round(z, 2)
    assert np.all(np.mean(z ** 2, axis=0) <= 1.3) and np.mean(z ** 2) >= 0.1, np.mean(z ** 2, axis=0)


def test_photo_poses_that_cannot_be_used_are_named(tmp_path):
    """`eoloc photo --poses FILE`: a file without poses, a row without its pose keys, and --refine
    without the terrain: exit status 2 and one line naming the file, the line and the fix."""
    photo = DATA / "drone" / "H20N__DJI_0006_R.JPG"
    (tmp_path / "empty.csv").write_text("file,camera_lat\n")
    (tmp_path / "short.csv").write_text("file,camera_lat\nx.JPG,40\n")
    (tmp_path / "words.jsonl").write_text('{"file": "x.JPG", "camera_lat": "north", "camera_lon": 1, "camera_h": 1, '
                                          '"camera_yaw": 1, "camera_pitch": 1, "camera_roll": 1}\n')
    cases = [(("--poses", tmp_path / "empty.csv"), "empty.csv: no photo pose in it"),
             (("--poses", tmp_path / "short.csv"), "short.csv:2: no camera_lon, camera_h"),
             (("--poses", tmp_path / "words.jsonl"), "words.jsonl:1: camera_lat, camera_lon"),
             (("--refine",), "--refine needs the terrain: --dem FILE")]
    for args, message in cases:
        r = eoloc("photo", photo, *args, "--out", tmp_path / "out")
        assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
