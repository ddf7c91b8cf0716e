"""Moving-target indication (eoloc.detect, `eoloc video --detect motion`) against a scene eoloc
did not draw: vehicles driving on flat textured ground, rendered by OpenCV through a pinhole
whose pose pymap3d turns into telemetry (tests/helpers/moving_scene.py). Truth: the vehicles' known
tracks, in pymap3d's ENU. Tolerances: the plane departs from eoloc's ellipsoidal ground by at
most 0.1 m over the scene; a ground pixel is about 1 m.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from dataclasses import replace
from datetime import UTC, datetime

import hypothesis.strategies as st
import moving_scene as ms
import numpy as np
import pymap3d
import pytest
from hypothesis import HealthCheck, given, settings
from tinymodel import yellow_model
from where import DATA

from eoloc import AzElGimbal, Camera, Pose, SensorModel
from eoloc.detect import MotionDetector, MotionSettings
from eoloc.detect.movers import MoverSettings, MoverTracker, mover_tracker_config
from eoloc.jobs.detect import detect_movers
from eoloc.rules import AtHeight

CARS = ms.CARS
N_FRAMES = 60
RULE = AtHeight(ms.ORIGIN[2])


def sensor() -> SensorModel:
    K = ms.K()
    return SensorModel(Camera(ms.W, ms.H, K[0, 0], K[1, 1], K[0, 2], K[1, 2]), AzElGimbal())


def pose_at(t_s: float, jitter_deg: float = 0.0, seed: int = 0, **cam) -> Pose:
    tel = ms.telemetry(t_s, **cam)
    rng = np.random.default_rng(seed)
    az, el = tel["az_deg"] + rng.normal(0, jitter_deg), tel["el_deg"] + rng.normal(0, jitter_deg)
    return Pose(tel["lat_deg"], tel["lon_deg"], tel["h_m"], 0.0, 0.0, 0.0, (az, el, tel["roll_deg"]))


@pytest.fixture(scope="module")
def texture():
    return ms.ground_texture()


@pytest.fixture(scope="module")
def images(texture):
    return [ms.render(texture, CARS, i / ms.FPS) for i in range(N_FRAMES)]


def frames(images, jitter_deg: float = 0.0):
    s = sensor()
    return [(i, i / ms.FPS, img, s, pose_at(i / ms.FPS, jitter_deg, seed=i)) for i, img in enumerate(images)]


def score(movers, n_frames: int = N_FRAMES, cars=CARS) -> dict:
    """Each track's vehicle (nearest by median, within 10 m; else false), per vehicle its frames
    found over the frames it is in view, the detections' distances from its true centre, and the
    track's smoothed speed and heading against the true ones."""
    rows = [r for r in movers.rows if r["status"] == "OK"]
    out = {"false": 0, "tracks": {}, "vehicles": {k: {"found": set(), "err": [], "speed": [], "heading": []}
                                                  for k in range(len(cars))}}
    for tid in sorted({r["track_id"] for r in rows}):
        rr = [r for r in rows if r["track_id"] == tid]
        t = np.array([r["time_s"] for r in rr])
        d = []
        for c in cars:
            lat, lon = ms.truth_geodetic(c, t)
            e, n, _ = pymap3d.geodetic2enu([r["lat_deg"] for r in rr], [r["lon_deg"] for r in rr], ms.ORIGIN[2],
                                           lat, lon, ms.ORIGIN[2])
            d.append(np.hypot(e, n))
        k = int(np.argmin([np.median(x) for x in d]))
        if np.median(d[k]) > 10:
            out["false"] += 1
            continue
        out["tracks"].setdefault(k, []).append(tid)
        v = out["vehicles"][k]
        v["found"] |= {r["frame"] for r in rr}
        v["err"] += list(d[k])
        v["speed"] += [r["speed_mps"] for r in rr]
        v["heading"] += [r["heading_deg"] for r in rr]
    for k, v in out["vehicles"].items():
        seen = {i for i in range(n_frames) if ms.in_view(cars[k], i / ms.FPS)}
        v["recall"] = len(v["found"] & seen) / max(len(seen), 1)
    return out


def test_movers_are_found_located_and_timed_in_an_independent_scene(images):
    m = detect_movers(frames(images), RULE)
    s = score(m)
    assert s["false"] == 0 and m.dropped_blobs == 0
    for k, c in enumerate(CARS):
        v = s["vehicles"][k]
        assert s["tracks"][k] == [s["tracks"][k][0]], "one track per vehicle, its id kept"
        assert v["recall"] >= 0.95, (k, v["recall"])
        err = np.array(v["err"])
        assert np.median(err) < 0.5 and err.max() < 3.0, (k, np.median(err), err.max())
        assert np.median(v["speed"]) == pytest.approx(c.speed_mps, rel=0.03)
        dh = (np.median(v["heading"]) - c.heading_deg + 180) % 360 - 180
        assert abs(dh) < 3.0
    # the rows are what the CSV promises: a box around the reference pixel, a ground area, a sigma
    r = m.rows[len(m.rows) // 2]
    assert r["bbox_u0"] <= r["u_px"] <= r["bbox_u1"] and r["bbox_v0"] <= r["v_px"] <= r["bbox_v1"]
    assert 6 < r["area_m2"] < 40 and r["compared"] in ("both", "before", "after")
    # the speed's sigma (smoothed track) covers: no false certainty (it is loose: the fixes' weight
    # assumes 3 m of frame-to-frame telemetry noise, none here)
    z = []
    for k, c in enumerate(CARS):
        tid = s["tracks"][k][0]
        z += [abs(r["speed_mps"] - c.speed_mps) / r["speed_sigma_mps"] for r in m.rows if r["track_id"] == tid]
    assert np.mean(np.array(z) <= 1.6449) >= 0.9


def test_the_images_take_out_what_the_attitude_gets_wrong(images):
    """0.1 deg of attitude noise per frame (about 2 px): the residual measured from the images
    keeps the warps aligned (no false track, hardly a false blob, every vehicle tracked); the
    poses alone cannot."""
    jittered = frames(images, jitter_deg=0.1)
    aligned = detect_movers(jittered, RULE)
    s = score(aligned)
    assert s["false"] == 0 and aligned.dropped_blobs <= 0.03 * aligned.blobs
    assert all(s["vehicles"][k]["recall"] >= 0.9 for k in range(len(CARS)))
    posed_only = detect_movers(jittered, RULE, MotionSettings(align=False))
    assert posed_only.blobs > aligned.blobs + 5
    # the fixes carry the attitude error (0.1 deg at ~1.1 km: ~2 m), the speed hardly
    for k, c in enumerate(CARS):
        assert np.median(s["vehicles"][k]["err"]) < 4.0
        assert np.median(s["vehicles"][k]["speed"]) == pytest.approx(c.speed_mps, rel=0.05)


def test_a_vehicle_hidden_for_a_second_keeps_its_track(texture):
    """An overpass 12 m wide (ground texture over the road, fixed in the world) hides the 6 m
    vehicle wholly for 0.5 s, and partly around that: no detection for up to a second, shorter
    than max_coast_s (1.5 s), so the same track carries on after it."""
    car = ms.Vehicle(-100, 20, 90, 12)
    e_mid = -100 + 12 * 3.0  # where the car is at t = 3 s
    cols = slice(int((e_mid - 6 + ms.HALF_M) / ms.TEXEL_M), int((e_mid + 6 + ms.HALF_M) / ms.TEXEL_M))
    s = sensor()
    fr = []
    for i in range(N_FRAMES):
        t = i / ms.FPS
        tex = ms.paint(texture, [car], t)
        tex[:, cols] = texture[:, cols]  # the overpass: drawn over the road and the car
        fr.append((i, t, ms.warp_texture(tex, t), s, pose_at(t)))
    m = detect_movers(fr, RULE)
    sc = score(m, cars=[car])
    assert sc["false"] == 0
    found = sorted(sc["vehicles"][0]["found"])
    gap_s = max(np.diff(found)) / ms.FPS
    assert 0.5 <= gap_s <= 1.3, gap_s  # it was hidden, not too long
    wholly = {i for i in range(N_FRAMES) if abs(car.centre(i / ms.FPS)[0] - e_mid) <= 6 - car.length_m / 2}
    assert len(wholly) >= 4 and sc["vehicles"][0]["found"].isdisjoint(wholly)
    assert len(sc["tracks"][0]) == 1, sc["tracks"]
    assert len(found) >= N_FRAMES - 12


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(speed=st.floats(20.0, 70.0), alt=st.floats(500.0, 1200.0), jitter=st.floats(0.0, 0.08),
       seed=st.integers(0, 1000))
def test_ground_that_stands_still_gives_no_mover(texture, speed, alt, jitter, seed):
    """Any flight over the still scene, with attitude noise: blobs may come and go, movers never."""
    s = sensor()
    cam = {"speed_mps": speed, "alt_m": alt}
    fr = [(i, i / ms.FPS, ms.render(texture, [], i / ms.FPS, **cam), s,
           pose_at(i / ms.FPS, jitter, seed=seed + i, **cam)) for i in range(40)]
    m = detect_movers(fr, RULE)
    assert m.tracks == [] and m.rows == []
    assert online_movers(fr)[0] == {}, "no still ground is declared a mover online either"


def test_buildings_on_a_surface_model_are_no_movers(texture, tmp_path):
    """Tall things the ground model does not know are the motion detector's false-alarm source
    (their roofs and walls shift by parallax); given a surface model holding them (a DSM), the warp
    goes over the roofs and the cells at a surface step (walls) are not compared: no false mover,
    the vehicles found as before. The scene: the three vehicles among six buildings 15-35 m tall,
    drawn by OpenCV far to near; the DSM rasterised from the same boxes."""
    from eoloc import open_dem
    from eoloc.rules import OnDEM

    blds = [(-40, 90, 12, 30), (60, 40, 10, 20), (-20, -40, 14, 35), (160, -20, 12, 15), (-150, 80, 10, 25),
            (100, 160, 15, 30)]
    imgs = [ms.draw_buildings(ms.render(texture, CARS, i / ms.FPS), blds, i / ms.FPS) for i in range(40)]
    fr = frames(imgs)
    flat = score(detect_movers(fr, RULE), n_frames=40)
    assert flat["false"] >= 1  # on a flat ground the buildings make movers (what the DSM must take out)
    dsm = OnDEM(open_dem(ms.surface_model(blds, tmp_path / "dsm.tif"), vertical="ellipsoid"))
    s = score(detect_movers(fr, dsm), n_frames=40)
    assert s["false"] == 0
    # found as on the flat ground, but where one drives along a wall's foot: the cells at a surface
    # step are not compared (here 5 of the 40 frames of the one passing 10 m from a 20 m building)
    recall = [s["vehicles"][k]["recall"] for k in range(len(CARS))]
    assert min(recall) >= 0.85 and np.mean(recall) >= 0.95, recall
    for k in range(len(CARS)):
        assert np.median(s["vehicles"][k]["err"]) < 1.0


def online_movers(frames):
    """The live stream's decision (MoverTracker.is_mover after each frame, as eoloc live takes it):
    {track key: time first declared}, and the batch's movers' keys from the same tracker."""
    detector, tracker = MotionDetector(RULE), MoverTracker(RULE)
    posed, declared = {}, {}

    def take(blobs_list):
        for b in blobs_list:
            for row in tracker.add(b, *posed.pop(b.index)):
                if row["track"] not in declared and tracker.is_mover(row["track"]):
                    declared[row["track"]] = b.time_s

    for index, t, image, s, pose in frames:
        posed[index] = (s, pose)
        take(detector.push(index, t, image, s, pose))
    take(detector.flush())
    tracks = {id(tr): tr.track_id for tr in tracker.tracker.tracks()}
    return declared, {tracks[id(tr)] for tr in tracker.result().tracks}


def test_the_online_decision_is_the_batch_decision_a_second_in(images):
    """eoloc live decides a track is a mover as it goes: the same tracks as the whole pass's decision
    (smoothed at the end), each within 1.5 s of its first detection (min_track_s is 1 s)."""
    declared, batch = online_movers(frames(images))
    assert set(declared) == batch and len(batch) == 3
    assert all(t <= 1.5 for t in declared.values()), declared


def test_settings_are_checked():
    with pytest.raises(ValueError, match="window_s"):
        MotionSettings(window_s=0)
    with pytest.raises(ValueError, match="min_area_m2 must be below"):
        MotionSettings(min_area_m2=10, max_area_m2=5)
    with pytest.raises(ValueError, match="min_hit_ratio"):
        MoverSettings(min_hit_ratio=0)
    det = MotionDetector(RULE)
    with pytest.raises(Exception, match="integer images"):
        det.push(0, 0.0, np.zeros((4, 4), np.float32), sensor(), pose_at(0.0))


def test_cli_video_detect_writes_detections_and_movers(images, tmp_path):
    from eoloc.io.klv.mux import write_klv_ts

    ts = write_klv_ts(tmp_path / "drive.ts", [ms.klv_packets(N_FRAMES)], video_fps=ms.FPS, video_size=(ms.W, ms.H),
                      frame_source=lambda i: images[i])
    eoloc = [sys.executable, "-m", "eoloc", "video", str(ts)]
    bad = subprocess.run([*eoloc, "--detect", "motion", "--out", str(tmp_path / "x")], capture_output=True, text=True)
    assert bad.returncode == 2 and "--detect needs the ground" in bad.stderr and "Traceback" not in bad.stderr
    out = tmp_path / "out"
    run = subprocess.run([*eoloc, "--target-height", str(ms.ORIGIN[2]), "--detect", "motion", "--no-frames",
                          "--no-mosaic", "--no-player", "--klv-out", str(out / "movers.ts"), "--out", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    rows = list(csv.DictReader((out / "detections.csv").open()))
    for col in ("frame", "time_s", "track_id", "u_px", "v_px", "bbox_u0", "bbox_v0", "bbox_u1", "bbox_v1",
                "area_m2", "lat_deg", "lon_deg", "h_m", "speed_mps", "speed_sigma_mps", "heading_deg", "status"):
        assert col in rows[0], col
    movers = json.loads((out / "movers.geojson").read_text())["features"]
    assert len(movers) == 3 and all(f["geometry"]["type"] == "LineString" for f in movers)
    report = json.loads((out / "video.json").read_text())
    assert report["movers"]["tracks"] == 3
    # TAK: each mover where it was last seen, valid against MITRE's CoT schema, its course and speed
    import zipfile

    import xmlschema

    schema = xmlschema.XMLSchema(str(DATA / "conformance" / "cot_event_2_0.xsd"))
    with zipfile.ZipFile(out / "movers.cot.zip") as z:
        events = [z.read(n) for n in z.namelist() if n.endswith(".cot")]
    assert len(events) == 3
    import xml.etree.ElementTree as ET

    for ev in events:
        schema.validate(ev)
        e = ET.fromstring(ev)
        assert e.get("uid").startswith("eoloc-mover-")
        t = datetime.fromisoformat(e.get("time").replace("Z", "+00:00")).timestamp() - \
            datetime(2026, 7, 14, 16, 0, 0, tzinfo=UTC).timestamp()  # the KLV's clock
        tr, pt = e.find("detail/track"), e.find("point")
        best = min(CARS, key=lambda c: np.hypot(*pymap3d.geodetic2enu(float(pt.get("lat")), float(pt.get("lon")),
                                                                     ms.ORIGIN[2], *ms.truth_geodetic(c, t),
                                                                     ms.ORIGIN[2])[:2]))
        assert float(tr.get("speed")) == pytest.approx(best.speed_mps, rel=0.03)
        assert abs((float(tr.get("course")) - best.heading_deg + 180) % 360 - 180) < 3
        assert float(pt.get("ce")) == 9999999  # no error budget: unknown, not a guess
    # with a config's [accuracy.budget]: every detection's fix carries its uncertainty (its coverage:
    # tests/integration/test_coverage.py), and the CoT markers their ce/le from it
    (tmp_path / "budget.toml").write_text("[accuracy.budget]\nyaw_deg = {normal = 0.2}\npitch_deg = {normal = 0.1}\n"
                                          "lat_deg = {normal = 1e-5}\nlon_deg = {normal = 1e-5}\n")
    out_b = tmp_path / "out_budget"
    run = subprocess.run([*eoloc, "--target-height", str(ms.ORIGIN[2]), "--detect", "motion", "--no-frames",
                          "--no-mosaic", "--no-player", "--config", str(tmp_path / "budget.toml"), "--out", str(out_b)],
                         capture_output=True, text=True)
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    with_budget = list(csv.DictReader((out_b / "detections.csv").open()))
    assert len(with_budget) == len(rows)
    ce90 = np.array([float(r["ce90_m"]) for r in with_budget])
    assert np.all(np.isfinite(ce90) & (ce90 > 0)), ce90
    with zipfile.ZipFile(out_b / "movers.cot.zip") as z:
        ces = [float(ET.fromstring(z.read(n)).find("point").get("ce")) for n in z.namelist() if n.endswith(".cot")]
    assert len(ces) == 3 and all(0 < c < 1000 for c in ces), ces
    # --klv-out: the movers as ST 0903 VMTI in a KLV stream of its own, read back by PyAV (the
    # transport stream) and stanag4609 (ST 0601 and ST 0903), neither of them eoloc
    import av
    from stanag4609.st0601 import decode_uas_local_set

    with av.open(str(out / "movers.ts")) as c:
        assert len(c.streams.data) == 2 and len(c.streams.video) == 1  # the flight's KLV kept, the movers'
        mine = [decode_uas_local_set(bytes(p)) for p in c.demux(c.streams.data) if p.size]
    mine = [p for p in mine if p.get(74) is not None]
    by_time = {}
    for r in rows:
        by_time.setdefault(r["time_utc"], []).append(r)
    assert len(mine) == len(by_time)  # one packet per frame with movers
    for p in mine:
        when = p.get(2).value
        want = by_time[when.isoformat(timespec="milliseconds")]
        got = {t.target_id: t for t in p.get(74).value.targets}
        assert sorted(got) == sorted(int(r["track_id"]) for r in want)
        for r in want:
            t = {f.name: f.value for f in got[int(r["track_id"])].fields}
            assert t["centroidPixRow"] == round(float(r["v_px"])) + 1
            assert t["centroidPixCol"] == round(float(r["u_px"])) + 1
            loc = t["targetLocation"]
            # ST 0903's IMAPB(-90, 90) and (-180, 180) in 4 bytes: one LSB is 2^-23 and 2^-22 deg
            assert loc.latitude == pytest.approx(float(r["lat_deg"]), abs=2**-23)
            assert loc.longitude == pytest.approx(float(r["lon_deg"]), abs=2**-22)
            assert loc.hae == pytest.approx(float(r["h_m"]), abs=0.5)
            box0, box1 = t["boundingBoxTopLeft"], t["boundingBoxBottomRight"]
            assert box0 == int(r["bbox_v0"]) * ms.W + int(r["bbox_u0"]) + 1
            assert box1 == int(r["bbox_v1"]) * ms.W + int(r["bbox_u1"]) + 1
    # through H.264 and KLV the same movers, located as well (KLV quantises the angles to ~1e-7 deg)
    from types import SimpleNamespace

    m = SimpleNamespace(rows=[{**r, "frame": int(r["frame"]), "time_s": float(r["time_s"]),
                               "track_id": int(r["track_id"]), "lat_deg": float(r["lat_deg"]),
                               "lon_deg": float(r["lon_deg"]), "speed_mps": float(r["speed_mps"]),
                               "heading_deg": float(r["heading_deg"])} for r in rows])
    s = score(m)
    assert s["false"] == 0
    for k, c in enumerate(CARS):
        assert s["vehicles"][k]["recall"] >= 0.95
        assert np.median(s["vehicles"][k]["err"]) < 0.6
        assert np.median(s["vehicles"][k]["speed"]) == pytest.approx(c.speed_mps, rel=0.03)


def test_a_learned_detector_finds_what_stands_still_too(texture, tmp_path):
    """The ONNX path: the model's boxes (letterboxed 640 x 360 -> 640 x 384: 12 rows of padding
    above) located and tracked like the movers; a parked vehicle, which the motion detector cannot
    see, is found and has no speed."""
    from eoloc.detect.learned import LearnedDetector

    model = tmp_path / "yellow.onnx"
    yellow_model(model)
    parked = ms.Vehicle(20, 60, 30, 0.0)
    cars = [*CARS, parked]
    imgs = [ms.render(texture, cars, i / ms.FPS) for i in range(40)]
    fr = frames(imgs)
    found = detect_movers(fr, RULE, learned=LearnedDetector(model, RULE, point="centre"))
    s = score(found, n_frames=40, cars=cars)
    assert s["false"] == 0
    for k, c in enumerate(cars):
        v = s["vehicles"][k]
        assert v["recall"] >= 0.9, (k, v["recall"])
        assert np.median(v["err"]) < 4.0  # the model's box sits on a 4-px cell (~5 m on the ground here)
        assert np.median(v["speed"]) == pytest.approx(c.speed_mps, abs=0.8)
    assert {r["class"] for r in found.rows} == {"vehicle"} and all(0.35 <= r["score"] <= 1 for r in found.rows)
    moving = score(detect_movers(fr, RULE), n_frames=40, cars=cars)
    assert moving["vehicles"][len(CARS)]["found"] == set()  # standing still: not a mover
    # the bottom-centre point (upright objects) lies 12 px (half the box) below the centre
    quick = MoverSettings(min_track_s=0.1, tracker=replace(mover_tracker_config(), confirm_hits=1))
    low = detect_movers(fr[:5], RULE, learned=LearnedDetector(model, RULE), movers=quick)
    high = detect_movers(fr[:5], RULE, learned=LearnedDetector(model, RULE, point="centre"), movers=quick)
    dv = [a["v_px"] - b["v_px"] for a, b in zip(low.rows, high.rows, strict=True)]
    assert dv and np.allclose(dv, 12.0, atol=0.01)


def test_a_model_that_is_not_one_is_refused_by_name(tmp_path):
    from eoloc.detect.learned import LearnedDetector
    from eoloc.errors import InputError

    bad = tmp_path / "not_a_model.onnx"
    bad.write_bytes(b"\x08\x01garbage")
    with pytest.raises(InputError, match=r"not_a_model\.onnx: not an ONNX model"):
        LearnedDetector(bad, RULE)
    with pytest.raises(InputError, match="no such model file"):
        LearnedDetector(tmp_path / "missing.onnx", RULE)


@pytest.mark.parametrize("depth", [8, 16])
def test_grey_and_16_bit_frames(images, depth):
    """A thermal camera's frames: one channel, 8 or 16 bits (16-bit scaled once for the whole
    video, no automatic gain): the vehicles are found as in colour."""
    import cv2

    grey = [cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) for img in images]
    if depth == 16:
        grey = [g.astype(np.uint16) * 64 + 1000 for g in grey]  # 14 bits of signal over an offset
    fr = [(i, t, g, s, p) for (i, t, _, s, p), g in zip(frames(images), grey, strict=True)]
    sc = score(detect_movers(fr, RULE))
    assert sc["false"] == 0
    for k in range(len(CARS)):
        assert sc["vehicles"][k]["recall"] >= 0.9 and np.median(sc["vehicles"][k]["err"]) < 1.0
