"""Issue 48: the telemetry-source seam, DJI .SRT video telemetry and Airdata flight logs.

Independent references: the `srt` package (a SubRip parser that shares nothing with eoloc) for the
blocks and time codes of every real SRT that it can parse; values read by eye from the files and
written here (each with its line); pandas for the Airdata logs' columns; and synthetic flights
over a real DEM tile written by the test in each format from camera poses chosen first, their
image centres located by the oracle (scipy rotations, pyproj, its own DEM walk) and by
`eoloc locate` — within 1 cm.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import coverage_lib as C
import droneflight as DF
import numpy as np
import pandas as pd
import pytest
import srt
from demtruth import TILE
from where import DATA

import eoloc
from eoloc.errors import EolocError
from eoloc.io.sources import SOURCES, identify, read_source

DRONE = DATA / "drone"
SRTS = sorted(p for p in (DRONE / "srt").iterdir() if p.suffix.lower() == ".srt")
LOGS = sorted((DRONE / "logs").glob("*.csv"))
EOLOC = str(Path(sys.executable).parent / "eoloc")

# what the files cannot give, and the words their message must carry
REFUSED = {"broken_empty.SRT": "empty (0 bytes)", "broken_empty2.SRT": "no subtitle record",
           "mavic_air.SRT": "no position"}


def test_48_every_source_is_registered_and_told_apart_by_content(tmp_path):
    """The registry names each source once; a KLV, a photo, an SRT, an Airdata log and an eoloc CSV
    are recognised by their bytes whatever their file names."""
    names = [s.name for s in SOURCES]
    assert len(names) == len(set(names)) and names[-1] == "csv"
    demo = Path(eoloc.__file__).parent / "data" / "demo"
    cases = {"klv": demo / "mountain" / "flight.klv", "photos": DRONE / "H20N__DJI_0006_R.JPG",
             "dji-srt": DRONE / "srt" / "p4_rtk.SRT", "airdata": LOGS[0], "csv": demo / "telemetry.csv"}
    for name, path in cases.items():
        disguised = tmp_path / f"input-{name}.txt"  # the extension says nothing
        disguised.write_bytes(path.read_bytes())
        assert identify(disguised).name == name, name
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "a.bin").write_bytes((DRONE / "H20N__DJI_0006_R.JPG").read_bytes())
    assert identify(folder).name == "photos"


@pytest.mark.parametrize("path", SRTS, ids=[p.name for p in SRTS])
def test_48_every_real_srt_is_read_or_refused_by_name(path):
    """Every real DJI SRT is read, or refused with a message naming the file; a block the `srt`
    package reads is a record here with the same start time (or a named skipped block)."""
    if path.name in REFUSED:
        with pytest.raises(EolocError) as e:
            read_source(path)
        assert path.name in str(e.value) and REFUSED[path.name] in str(e.value)
        return
    data = read_source(path)
    t = data.telemetry
    assert data.source == "dji-srt" and data.camera_attitude and len(t) > 0
    try:
        subs = list(srt.parse(path.read_text(encoding="utf-8-sig")))
    except srt.SRTParseError:
        subs = None  # files the strict parser refuses (no time codes, truncated): checked by hand below
    if subs is not None:
        starts = np.array([s.start.total_seconds() for s in subs if s.content.strip()])
        skipped = [i for i in t.issues if "block skipped" in i.message]
        assert len(t) + len(skipped) == starts.size
        if not skipped:
            np.testing.assert_allclose(t.columns["time_s"], starts, atol=1e-9)
    c = t.columns
    placed = np.isfinite(c["lat_deg"])
    assert placed.any() and (np.abs(c["lat_deg"][placed]) <= 90).all() and (np.abs(c["lon_deg"][placed]) <= 180).all()


# (file, record, lat, lon, yaw, pitch, roll) as the file writes them (line of the record in the comment)
BY_EYE = [
    # l.3: GPS (-58.851745, -34.237922, 15), G.PRY (-24.4°, 0.0°, 110.4°)
    ("p4_rtk.SRT", 0, -34.237922, -58.851745, 110.4, -24.4, 0.0),
    ("matrice_300.srt", 0, 36.6146, -6.1120, None, None, None),  # l.4: GPS(36.6146,-6.1120,0.0M): latitude first
    ("mavic_pro.SRT", 0, -20.2533, 149.0251, None, None, None),  # l.4: GPS(149.0251,-20.2533,16)
    ("old_format.SRT", 0, -20.2533, 149.0251, None, None, None),  # l.4: GPS(149.0251,-20.2533,16) Hb:1.9
    ("m2zoom.SRT", 0, 31.452012, 74.398751, None, None, None),  # l.5: [latitude : 31.452012] [longtitude : 74.398751]
    ("mavic_2_style.SRT", 0, -20.2533, 149.0251, None, None, None),  # l.3, no time code
    ("mavic_mini.SRT", 0, 48.0771, -121.7458, None, None, None),  # l.3: GPS (-121.7458, 48.0771, 17)
    # l.5: [gb_yaw: -162.8 gb_pitch: 0.0 gb_roll: 0.0]
    ("Avata360__clip.SRT", 0, 53.365080, 6.460739, -162.8, 0.0, 0.0),
    ("avata2__clip.SRT", 0, 39.906217, 116.391305, None, None, None),  # l.3: GPS(39.906217,116.391305,69.800)
    ("MICK_folsomake_DJI_0031-01.srt", 0, 38.7225, -121.1689, None, None, None),  # l.3: GPS (-121.1689, 38.7225, 21)
]


@pytest.mark.parametrize("name,k,lat,lon,yaw,pitch,roll", BY_EYE, ids=[b[0] for b in BY_EYE])
def test_48_srt_values_as_the_file_writes_them(name, k, lat, lon, yaw, pitch, roll):
    """Latitude/longitude in each format's order (GPS(lon, lat, sats); the Matrice 300's
    GPS(lat, lon, 0.0M); a file whose tuples only make sense the other way, read so and said so),
    the longtitude typo, and the gimbal's attitude (G.PRY as pitch, roll, yaw; gb_*)."""
    data = read_source(DRONE / "srt" / name)
    c = data.telemetry.columns
    assert c["lat_deg"][k] == pytest.approx(lat, abs=1e-9) and c["lon_deg"][k] == pytest.approx(lon, abs=1e-9)
    if yaw is None:
        assert math.isnan(c["yaw_deg"][k]) and any("no camera attitude" in i.message for i in data.telemetry.issues)
    else:
        assert (c["yaw_deg"][k], c["pitch_deg"][k], c["roll_deg"][k]) == (yaw, pitch, roll)
    if name == "avata2__clip.SRT":
        assert any("(latitude, longitude)" in n for n in data.notes)


def test_48_heights_rule_and_the_named_suspect_tag():
    """Heights above take-off alone cannot be placed without a DEM (named, with the fix); an
    absolute altitude is taken as MSL + EGM96 (pyproj's EGM96 would agree: the geoid is tested
    elsewhere) and said to be the drone's own estimate."""
    from eoloc.terrain.geoid import default_geoid

    p4 = read_source(DRONE / "srt" / "p4_rtk.SRT")
    assert np.isnan(p4.telemetry.columns["h_m"]).all()
    assert any("--dem" in i.message and "H (above the take-off point)" in i.message for i in p4.telemetry.issues)
    air = read_source(DRONE / "srt" / "air2s.srt")  # [altitude: 117.000000] on line 5
    c = air.telemetry.columns
    n = float(default_geoid().undulation(c["lat_deg"][0], c["lon_deg"][0]))
    assert c["h_m"][0] == pytest.approx(117.0 + n, abs=1e-6)
    assert any("own estimate" in note for note in air.notes)


@pytest.mark.parametrize("path", LOGS, ids=[p.name for p in LOGS])
def test_48_airdata_logs_against_pandas(path):
    """Every record of a real Airdata log: time, position, heights (feet -> m) and the gimbal's
    attitude equal pandas' reading of the same columns (a time stamp given twice with different
    values drops both records, named)."""
    data = read_source(path)
    t = data.telemetry
    ref = pd.read_csv(path, skipinitialspace=True)
    ref.columns = [c.strip() for c in ref.columns]
    # a time given twice with different values: neither record can be trusted (named with its line)
    twice = ref["time(millisecond)"].duplicated(keep=False)
    for line in (np.flatnonzero(twice) + 2)[1:]:
        assert any(i.line == line and "neither record is used" in i.message for i in t.issues)
    ref = ref[~twice].reset_index(drop=True)
    assert data.source == "airdata" and len(t) == len(ref)
    c = t.columns
    np.testing.assert_allclose(c["time_s"], ref["time(millisecond)"] / 1000.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c["lat_deg"], ref["latitude"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(c["h_rel_m"], ref["height_above_takeoff(feet)"] * 0.3048, rtol=0, atol=1e-9)
    np.testing.assert_allclose(c["h_abs_m"], ref["altitude_above_seaLevel(feet)"] * 0.3048, rtol=0, atol=1e-9)
    np.testing.assert_allclose(c["yaw_deg"], ref["gimbal_heading(degrees)"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(c["pitch_deg"], ref["gimbal_pitch(degrees)"], rtol=0, atol=1e-12)
    from eoloc.terrain.geoid import default_geoid  # the geoid itself is tested against its grid elsewhere

    n = default_geoid().undulation(c["lat_deg"], c["lon_deg"])
    np.testing.assert_allclose(c["h_m"], ref["altitude_above_seaLevel(feet)"] * 0.3048 + n, rtol=0, atol=1e-9)
    assert any("own estimate" in note and "--dem" in note for note in data.notes)  # no DEM: the absolute one


# -- synthetic flights over a real DEM tile ---------------------------------------------------------

def _locate(tmp_path, tel, *more):
    cfg = tmp_path / "camera.toml"
    cfg.write_text(DF.CAMERA_TOML, encoding="utf-8")
    out = tmp_path / f"out-{tel.stem}"
    r = subprocess.run([EOLOC, "locate", str(tel), "--config", str(cfg), "--out", str(out), "--format", "csv",
                        *map(str, more)], capture_output=True, text=True, timeout=180)
    assert "Traceback" not in r.stderr, r.stderr
    return r, (pd.read_csv(out / "fixes.csv", comment="#") if (out / "fixes.csv").exists() else None)


@pytest.mark.parametrize("fmt", ["p4rtk", "bracket", "airdata"])
def test_48_synthetic_drone_flight_located_on_the_dem_within_1cm(tmp_path, fmt):
    """A drone flight over the real Longs Peak tile, written by the test as a P4 RTK SRT (GPS
    (lon, lat), HOME, H, G.PRY), a newer bracket SRT (FrameCnt, rel_alt + an abs_alt 60 m off,
    gb_yaw/gb_pitch/gb_roll) or an Airdata log (feet): `eoloc locate FILE --dem TILE` puts every
    image centre within 1 cm of the oracle's first DEM crossing; the heights come from the DEM's
    take-off ground + the height above take-off, and the wrong abs_alt is named."""
    grid, takeoff, poses, path = DF.write_flight(tmp_path, fmt)
    if fmt == "bracket":
        poses = {k: v[1:] for k, v in poses.items()}  # record 0 sits at take-off, looking at the horizon-ish
    truth = DF.truth(grid, takeoff[2], poses)
    r, fixes = _locate(tmp_path, path, "--dem", TILE, "--vertical", "ellipsoid")
    assert r.returncode == 0, r.stderr
    if fmt == "bracket":
        assert "abs_alt" in r.stderr and "not used" in r.stderr
        fixes = fixes.iloc[1:]
    assert (fixes["status"] == "OK").all(), fixes["status"].tolist()
    e = C.enu_error(fixes["lat_deg"].to_numpy(), fixes["lon_deg"].to_numpy(), fixes["h_m"].to_numpy(), truth)
    assert np.linalg.norm(e, axis=1).max() < 0.01, e


def test_48_a_camera_under_the_ground_names_its_height_tag(tmp_path):
    """An Airdata log whose heights above take-off are 400 m too low puts the camera under the
    ridge: those records are refused, the message names height_above_takeoff; nothing is located
    there (no plausible wrong point)."""
    grid, takeoff, poses = DF.flight(n=4)
    poses["lat"][0], poses["lon"][0] = takeoff[0], takeoff[1]
    poses["rel"] = poses["rel"] - (grid.hmax - takeoff[2] + 400.0)
    path = tmp_path / "low.csv"
    DF.write_airdata(path, poses)
    r, fixes = _locate(tmp_path, path, "--dem", TILE, "--vertical", "ellipsoid")
    assert "under the ground" in r.stderr and "height_above_takeoff" in r.stderr
    assert fixes is None or (fixes["status"] != "OK").all()


def test_48_no_attitude_and_no_height_are_said_not_assumed(tmp_path):
    """A real SRT without attitude or absolute height (Mini 2 SE): `eoloc locate` says why no
    record is located (no nadir assumed, no height guessed) and shows no traceback."""
    r, fixes = _locate(tmp_path, DRONE / "srt" / "MICK_folsomake_DJI_0031-01.srt", "--target-height", 100)
    assert "no camera attitude" in r.stderr and "above the take-off point" in r.stderr
    assert fixes is None or (fixes["status"] != "OK").all()


# -- a video's SRT completed by the flight log ------------------------------------------------------

FOLSOM_SRT = DRONE / "srt" / "MICK_folsomake_DJI_0031-01.srt"
FOLSOM_LOG = DRONE / "logs" / "Dec-22nd-2023-11-56AM-Flight-Airdata.csv"


def test_48_a_log_of_another_flight_is_refused(tmp_path):
    """The same clip against the log of another day's flight: no offset matches; the message names
    both files; `eoloc locate` shows no traceback."""
    other = DRONE / "logs" / "Jan-4th-2024-02-19PM-Flight-Airdata-first30s.csv"
    r, fixes = _locate(tmp_path, FOLSOM_SRT, "--flight-log", other, "--target-height", 100)
    assert r.returncode != 0 and "does not match the flight log" in r.stderr and other.name in r.stderr
    assert fixes is None


def test_48_synthetic_srt_and_log_located_within_1cm(tmp_path):
    """An old-style SRT (GPS (lon, lat) to 1e-4°, H, no attitude) and an Airdata log of the same
    synthetic flight, the video starting at 37.4 s on the log's clock (its isVideo edge): the
    offset is found to 0.05 s, and `eoloc locate SRT --flight-log LOG --dem TILE` puts each image
    centre within 1 cm of the oracle's DEM crossing seen from the log's pose at that time."""
    grid, takeoff, poses = DF.flight(n=60, seed=7)
    n = poses["lat"].size
    start = 37.4
    # a smooth flight: the poses drift slowly (the log at 10 Hz)
    k = np.arange(n)
    poses["lat"] = np.round(takeoff[0] + 1e-5 * k, 7)
    poses["lon"] = np.round(takeoff[1] + 1.5e-5 * k, 7)
    poses["rel"] = np.round(poses["rel"].min() + 0.5 * k, 2)
    poses["yaw"] = np.round(40 + 0.5 * k, 1)
    poses["pitch"] = np.round(-50 - 0.2 * k, 1)
    poses["roll"] = np.zeros(n)
    pre = round(start / 0.1)  # the log runs from motor start; the video starts `start` s later
    log_poses = {key: np.r_[np.full(pre, v[0]), v] for key, v in poses.items()}
    log_poses["lat"][0], log_poses["lon"][0] = takeoff[0], takeoff[1]
    log_poses["rel"][:pre] = np.linspace(0.0, poses["rel"][0], pre)
    path = tmp_path / "log.csv"
    DF.write_airdata(path, log_poses, is_video=np.arange(pre + n) >= pre)
    srt_path = tmp_path / "clip.SRT"
    blocks = []
    for j in range(0, n, 10):  # one block a second, as the old models write
        blocks += [str(j // 10 + 1), f"00:00:{j // 10:02d},000 --> 00:00:{j // 10 + 1:02d},000",
                   f"F/2.8, SS 100, ISO 100, EV 0, GPS ({poses['lon'][j]:.4f}, {poses['lat'][j]:.4f}, 18), "
                   f"D 10.00m, H {poses['rel'][j]:.2f}m, H.S 0.00m/s, V.S 0.00m/s", ""]
    srt_path.write_text("\n".join(blocks), encoding="utf-8")
    picked = {key: v[::10] for key, v in poses.items()}
    truth = DF.truth(grid, takeoff[2], picked)
    r, fixes = _locate(tmp_path, srt_path, "--flight-log", path, "--dem", TILE, "--vertical", "ellipsoid")
    assert r.returncode == 0, r.stderr
    offset = float(r.stderr.split("time + ")[1].split(" s")[0])
    assert abs(offset - start) < 0.05
    assert (fixes["status"] == "OK").all(), fixes["status"].tolist()
    e = C.enu_error(fixes["lat_deg"].to_numpy(), fixes["lon_deg"].to_numpy(), fixes["h_m"].to_numpy(), truth)
    assert np.linalg.norm(e, axis=1).max() < 0.01, e


# -- drone video -> MISB ------------------------------------------------------------------------------

def _drone_mp4(path, fps=10, seconds=3.0, size=(160, 96), bframes=0):
    """A small H.264 MP4 as a drone writes (avcC in an MP4 container), each frame showing its index;
    ``bframes``: B-frames between references, as real cameras write (the MPEG-TS a remux makes of it
    then starts 0.2 s later: its decoder delay)."""
    import av

    from eoloc.io.klv.mux import index_frame

    with av.open(str(path), "w", format="mp4") as out:
        s = out.add_stream("libx264", rate=fps)
        s.width, s.height, s.pix_fmt = size[0], size[1], "yuv420p"
        s.options = {"preset": "ultrafast", "x264-params": f"bframes={bframes}"}
        for i in range(int(fps * seconds)):
            frame = av.VideoFrame.from_ndarray(index_frame(i, size), format="gray").reformat(format="yuv420p")
            frame.pts = i
            for p in s.encode(frame):
                out.mux(p)
        for p in s.encode(None):
            out.mux(p)
    return path


@pytest.mark.parametrize(("carriage", "bframes"), [("async", 0), ("sync", 0), ("async", 2)])
def test_48_mux_drone_video_to_misb_read_back_frame_by_frame(tmp_path, carriage, bframes):
    """`eoloc mux clip.mp4 --telemetry clip.SRT -o out.ts`: one packet per frame, its PTS the
    frame's (also when B-frames make the transport stream's times start 0.2 s after the MP4's:
    session 49's mux paired those by the MP4's times and gave every frame the packet of the frame
    two later); each packet (decoded independently by `klvdata`) carries the SRT's values linearly
    interpolated at the frame's time (a straight, steady flight: eoloc's ECEF spline and a line
    agree to far below the tags' resolution): latitude, longitude, MSL altitude (tag 15), the
    gimbal's yaw as heading, its pitch as relative elevation; `eoloc video out.ts --target-height`
    then runs end to end on the result."""
    import klvdata

    from eoloc.io.klv import read_klv
    from eoloc.io.videofile import frame_times

    video = _drone_mp4(tmp_path / "clip.mp4", bframes=bframes)
    n = 4
    lat = 40.0 + 1e-4 * np.arange(n)
    lon = -105.0 + 2e-4 * np.arange(n)
    msl = 1700.0 + 2.0 * np.arange(n)
    pitch = -45.0 - 2.0 * np.arange(n)
    lines = []
    for k in range(n):
        lines += [str(k + 1), f"00:00:{k:02d},000 --> 00:00:{k + 1:02d},000",
                  f'<font size="28">FrameCnt: {k + 1}, DiffTime: 1000ms', f"2024-01-04 22:23:{10 + k:02d}.000",
                  f"[iso: 100] [focal_len: 24.00] [latitude: {lat[k]:.6f}] [longitude: {lon[k]:.6f}] "
                  f"[rel_alt: {msl[k] - 1600:.3f} abs_alt: {msl[k]:.3f}] "
                  f"[gb_yaw: 30.0 gb_pitch: {pitch[k]:.1f} gb_roll: 0.0] </font>", ""]
    srt_path = tmp_path / "clip.SRT"
    srt_path.write_text("\n".join(lines), encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 160\nheight = 96\nfx = 140.0\ncx = 79.5\ncy = 47.5\n", encoding="utf-8")
    out = tmp_path / "out.ts"
    r = subprocess.run([EOLOC, "mux", str(video), "--telemetry", str(srt_path), "--config", str(cfg), "-o", str(out),
                        "--carriage", carriage, "--target-height", "1500"], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    frames = frame_times(out)
    pk = read_klv(out).packets
    assert len(pk) == frames.size == 30
    np.testing.assert_allclose(sorted(p.pts_s for p in pk), frames, atol=2e-5)
    t = frames - frames[0]
    for i, p in enumerate(sorted(pk, key=lambda p: p.pts_s)):
        (ref,) = list(klvdata.StreamParser(p.raw))
        v = {k: val[3] for k, val in ref.MetadataList().items()}
        assert float(v[13]) == pytest.approx(np.interp(t[i], np.arange(n), lat), abs=1e-7)
        assert float(v[14]) == pytest.approx(np.interp(t[i], np.arange(n), lon), abs=1e-7)
        assert float(v[15]) == pytest.approx(np.interp(t[i], np.arange(n), msl), abs=0.35)  # 2 bytes over 19 900 m
        assert float(v[5]) == pytest.approx(30.0, abs=0.01)
        assert float(v[19]) == pytest.approx(np.interp(t[i], np.arange(n), pitch), abs=1e-4)
        assert v[2].startswith("2024-01-04 22:23:1")  # the SRT's dates (taken as UTC)
    r = subprocess.run([EOLOC, "video", str(out), "--target-height", "1500", "--out", str(tmp_path / "v"),
                        "--every", "10", "--no-player", "--no-tiles"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


def test_48_a_new_source_is_one_class_and_one_registry_line(tmp_path, monkeypatch):
    """The README's recipe: a class with name, summary, sniff and read, put in the registry before
    the generic CSV; `eoloc locate` (in-process, so the registry seen is this one) then takes the new
    file with no other change, and its fixes equal those of the same poses as an eoloc CSV."""
    from click.testing import CliRunner

    import eoloc.io.sources as sources
    from eoloc.cli.main import main
    from eoloc.io.sources import SourceData
    from eoloc.io.table import Table

    class MyLog:  # "#MYLOG" then "time lat lon h yaw pitch roll az el" per line, spaces between
        name = "mylog"
        summary = "MyCompany flight log ('#MYLOG' first line)"

        def sniff(self, path, head: bytes) -> bool:
            return head.startswith(b"#MYLOG")

        def read(self, path, *, geoid=None, dem=None) -> SourceData:
            rows = np.loadtxt(path, comments="#", ndmin=2)
            names = ("time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg",
                     "gimbal2_deg")
            cols = {k: rows[:, i] for i, k in enumerate(names)}
            n = rows.shape[0]
            cols.update(frame=np.full(n, np.nan), sensor_roll_deg=np.zeros(n), range_m=np.full(n, np.nan))
            return SourceData(Table(str(path), cols, np.arange(2, n + 2)), self.name)

    monkeypatch.setattr(sources, "SOURCES", [*sources.SOURCES[:-1], MyLog(), sources.SOURCES[-1]])
    poses = [(0.0, 40.0, -105.0, 3000.0, 10.0, 1.0, -2.0, 30.0, -60.0), (1.0, 40.001, -105.0, 3001.0, 12.0, 0.5, 0.0,
                                                                          35.0, -55.0)]
    log = tmp_path / "flight.mylog"
    log.write_text("#MYLOG\n" + "\n".join(" ".join(map(str, p)) for p in poses) + "\n", encoding="utf-8")
    csv_path = tmp_path / "telemetry.csv"
    csv_path.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n"
                        + "\n".join(",".join(map(str, p)) for p in poses) + "\n", encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text(DF.CAMERA_TOML, encoding="utf-8")
    outs = []
    for tel in (log, csv_path):
        out = tmp_path / f"o-{tel.suffix[1:]}"
        r = CliRunner().invoke(main, ["locate", str(tel), "--config", str(cfg), "--target-height", "1500",
                                      "--out", str(out), "--format", "csv"])
        assert r.exit_code == 0, r.output
        outs.append(pd.read_csv(out / "fixes.csv", comment="#"))
    assert identify(log).name == "mylog"
    np.testing.assert_array_equal(outs[0][["lat_deg", "lon_deg", "h_m"]].to_numpy(),
                                  outs[1][["lat_deg", "lon_deg", "h_m"]].to_numpy())
    assert (outs[0]["status"] == "OK").all()


def test_48_mux_writes_an_aircraft_turret_as_it_is(tmp_path):
    """Telemetry of an aircraft with an az-el turret (an eoloc CSV, not a drone's camera attitude):
    each packet carries the platform's heading/pitch/roll and the turret's azimuth/elevation as the
    CSV gives them, linearly interpolated at the frame's time (klvdata decodes them), not the
    camera-attitude mapping drones get."""
    import klvdata

    from eoloc.io.klv import read_klv
    from eoloc.io.videofile import frame_times

    video = _drone_mp4(tmp_path / "clip.mp4", seconds=2.0)
    tel = tmp_path / "telemetry.csv"
    tel.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,azimuth_deg,elevation_deg\n"
                   "0,40.0,-105.0,3000,10,2,-5,30,-40\n2,40.001,-105.0,3000,14,3,-3,34,-44\n", encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 160\nheight = 96\nfx = 140.0\n", encoding="utf-8")
    out = tmp_path / "out.ts"
    r = subprocess.run([EOLOC, "mux", str(video), "--telemetry", str(tel), "--config", str(cfg), "-o", str(out),
                        "--start-utc", "2024-01-04T22:23:10Z"], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    t = frame_times(out)
    t = t - t[0]
    for i, p in enumerate(sorted(read_klv(out).packets, key=lambda p: p.pts_s)):
        (ref,) = list(klvdata.StreamParser(p.raw))
        v = {k: float(val[3]) for k, val in ref.MetadataList().items() if k in (5, 6, 7, 18, 19)}
        want = {5: 10 + 2 * t[i], 6: 2 + 0.5 * t[i], 7: -5 + t[i], 18: 30 + 2 * t[i], 19: -40 - 2 * t[i]}
        for tag, w in want.items():
            assert v[tag] == pytest.approx(w, abs=0.01), (i, tag)
