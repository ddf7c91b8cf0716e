"""`eoloc klv` end to end on the bundled KLV flight: fixes, KML, Cursor-on-Target, the re-encoded
stream, and the HTML map loaded in a real headless Chromium."""

from __future__ import annotations

import csv
import json
import math
import re
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from browser import page_state
from click.testing import CliRunner

import eoloc
from eoloc.cli import main
from eoloc.io.klv import klv_telemetry, read_klv
from eoloc.terrain.geoid import default_geoid

DEMO = Path(str(resources.files("eoloc") / "data" / "demo" / "mountain"))
KML_NS = {"k": "http://www.opengis.net/kml/2.2"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("klv")
    res = CliRunner().invoke(main, ["klv", str(DEMO / "flight.klv"), "--dem", str(DEMO / "longs_peak_srtmgl3.tif"),
                                    "--config", str(DEMO / "klv.toml"), "--out", str(out),
                                    "--write-klv", str(out / "with_targets.klv")])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader((out / "fixes.csv").open()))
    return out, " ".join(res.output.split()), rows  # rich wraps long lines


def test_cli_reports_the_bad_packet_and_locates_the_rest(run):
    out, text, rows = run
    assert "39 good ST 0601 packets; 1 checksum" in text
    assert "packet 17" in text
    assert len(rows) == 108
    status = [r["status"] for r in rows]
    assert status.count("OK") == 103 and status.count("OUT_OF_COVERAGE") == 5
    ok = [r for r in rows if r["status"] == "OK"]
    assert all(float(r["cep50_m"]) > 0 and float(r["ce90_m"]) > float(r["cep50_m"]) for r in ok)
    assert all(r["lat_deg"] == "" for r in rows if r["status"] != "OK")  # no point for a failed fix
    frames = list(csv.DictReader((out / "frames.csv").open()))
    assert len(frames) == 39 and max(float(r["centre_distance_m"]) for r in frames) < 5.0


def test_kml_has_every_layer_with_msl_heights(run):
    out, _, rows = run
    doc = ET.parse(out / "eoloc.kml").getroot()
    folders = {f.find("k:name", KML_NS).text: f for f in doc.iter(f"{{{KML_NS['k']}}}Folder")}
    assert set(folders) >= {"aircraft", "footprints", "encoder footprints", "fixes"}
    marks = folders["fixes"].findall("k:Placemark", KML_NS)
    ok = [r for r in rows if r["status"] == "OK"]
    assert len(marks) == len(ok)
    lon, lat, alt = (float(x) for x in marks[0].find(".//k:coordinates", KML_NS).text.split(","))
    r = ok[0]
    assert (lat, lon) == pytest.approx((float(r["lat_deg"]), float(r["lon_deg"])), abs=1e-9)
    assert alt == pytest.approx(float(r["h_m"]) - default_geoid().undulation(lat, lon), abs=1e-3)
    assert marks[0].find(".//k:altitudeMode", KML_NS).text == "absolute"


def test_cot_events_carry_the_fix_and_its_one_sigma_errors(run):
    """A TAK data package: MANIFEST/manifest.xml lists one <uid>/<uid>.cot entry per OK fix; each
    entry is one standalone <event> document (TAK ingests no <events> wrapper) whose time is the
    fix's own UTC time from the stream, not the time of writing."""
    import zipfile

    out, _, rows = run
    with zipfile.ZipFile(out / "fixes.cot.zip") as zf:
        manifest = ET.fromstring(zf.read("MANIFEST/manifest.xml"))
        entries = [c.get("zipEntry") for c in manifest.iter("Content")]
        events = [ET.fromstring(zf.read(e)) for e in entries]
    assert manifest.tag == "MissionPackageManifest" and manifest.get("version") == "2"
    ok = [r for r in rows if r["status"] == "OK"]
    assert len(events) == len(ok) == len(set(entries))
    assert all(ev.tag == "event" and e == f"{ev.get('uid')}/{ev.get('uid')}.cot" for ev, e in zip(events, entries,
                                                                                                   strict=True))
    for ev, r in zip(events, ok, strict=True):
        assert ev.get("time") == r["time_utc"] and r["time_utc"].endswith("Z")
        assert float(r["time_s"]) == pytest.approx(
            __import__("datetime").datetime.fromisoformat(r["time_utc"].replace("Z", "+00:00")).timestamp(),
            abs=1e-3)
        p = ev.find("point")
        assert float(p.get("lat")) == pytest.approx(float(r["lat_deg"]), abs=1e-8)
        assert float(p.get("hae")) == pytest.approx(float(r["h_m"]), abs=0.01)
        # ce: what MITRE's CoT Event 2.0 schema says it is where it is an error, "the one sigma point
        # for a zero mean normal (Gaussian) distribution" (point/@ce; tests/data/conformance/SOURCES.md):
        # the sigma of the circular normal with the fix's CE90; the CE90 of the row's sigmas and
        # correlation from 2 x 10^5 draws of that normal (1 % tolerance); le likewise the vertical sigma
        se, sn, rho = float(r["sigma_e_m"]), float(r["sigma_n_m"]), float(r["rho_en"])
        cov = np.array([[se * se, rho * se * sn], [rho * se * sn, sn * sn]])
        draws = np.random.default_rng(0).multivariate_normal([0.0, 0.0], cov, 200_000)
        ce90 = float(np.quantile(np.hypot(draws[:, 0], draws[:, 1]), 0.9))
        assert float(p.get("ce")) * math.sqrt(-2 * math.log(0.1)) == pytest.approx(ce90, rel=0.01)
        assert float(p.get("le")) == pytest.approx(float(r["sigma_u_m"]), abs=0.01)
        assert ev.get("how") == "m-i" and ev.get("stale") > ev.get("time")


def test_cot_without_covariance_says_unknown():
    from eoloc.io.cot import UNKNOWN, cot_event

    ev = cot_event({"status": "OK", "lat_deg": 40.0, "lon_deg": -105.0, "h_m": 1500.0, "target_id": "T"})
    assert float(ev.find("point").get("ce")) == UNKNOWN and float(ev.find("point").get("le")) == UNKNOWN
    assert cot_event({"status": "OUT_OF_COVERAGE", "lat_deg": None, "lon_deg": None, "h_m": None}) is None


def test_reencoded_stream_carries_the_fixes_in_tags_40_to_46(run):
    out, _, rows = run
    s = read_klv(out / "with_targets.klv")
    assert s.n_good == 39 and s.n_bad == 0  # the good packets, in order; the corrupt one is not carried over
    original = [p.index for p in read_klv(DEMO / "flight.klv").packets]
    by_frame: dict[int, dict] = {}
    for r in rows:
        if r["status"] == "OK":
            f = int(r["frame"])
            if f not in by_frame or r["target_id"] < by_frame[f]["target_id"]:
                by_frame[f] = r
    tel = klv_telemetry(s).columns
    checked = 0
    for i, p in enumerate(s.packets):
        r = by_frame.get(original[i])
        v = p.fields
        if r is None:
            assert 40 not in v
            continue
        assert v[40] == pytest.approx(float(r["lat_deg"]), abs=1e-7)
        assert v[41] == pytest.approx(float(r["lon_deg"]), abs=1e-7)
        assert tel["target_h_m"][i] == pytest.approx(float(r["h_m"]), abs=0.2)  # MSL in tag 42, back to HAE
        assert v[45] == pytest.approx(float(r["ce90_m"]), abs=0.07)
        assert v[46] == pytest.approx(float(r["le90_m"]), abs=0.07)
        checked += 1
    assert checked >= 30


def test_map_loads_offline_in_chromium_with_every_marker(run):
    out, _, rows = run
    html = (out / "map.html").read_text()
    assert not re.search(r'<(script|link|img)[^>]+(src|href)="http', html)  # self-contained: nothing fetched
    prints = json.loads((out / "footprints.geojson").read_text())["features"]
    n_prints = sum(f["geometry"] is not None for f in prints)
    n_ok = sum(r["status"] == "OK" for r in rows)
    counts, errors = page_state(
        out / "map.html",
        "const n = s => document.querySelectorAll(s).length;"
        "return {leaflet: window.L && L.version, targets: n('path.eoloc-target'), cep: n('path.eoloc-cep'),"
        " footprints: n('path.eoloc-footprint'), aircraft: n('path.eoloc-aircraft'),"
        " terrain: n('img.leaflet-image-layer'), title: document.getElementById('eoloc-title').textContent};")
    assert errors == []
    assert counts == {"leaflet": "1.9.4", "targets": n_ok, "cep": n_ok, "footprints": n_prints, "aircraft": 1,
                      "terrain": 1, "title": "eoloc: flight.klv"}
    assert n_prints == 39


def test_map_command_from_files(run, tmp_path):
    out, _, rows = run
    res = CliRunner().invoke(main, ["map", "--telemetry", str(DEMO / "telemetry.csv"), "--fixes",
                                    str(out / "fixes.geojson"), "--footprints", str(out / "footprints.geojson"),
                                    "-o", str(tmp_path / "m.html")])
    assert res.exit_code == 0, res.output
    html = (tmp_path / "m.html").read_text()
    assert html.count("eoloc-target") == sum(r["status"] == "OK" for r in rows)
    res = CliRunner().invoke(main, ["map", "-o", str(tmp_path / "empty.html")])
    assert res.exit_code == 2 and "nothing to draw" in " ".join(res.output.split())


def test_klv_command_on_a_file_with_no_klv(tmp_path):
    p = tmp_path / "noise.bin"
    p.write_bytes(np.random.default_rng(1).integers(0, 255, 3000, dtype=np.uint8).tobytes())
    res = CliRunner().invoke(main, ["klv", str(p), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "no MISB ST 0601 packet" in " ".join(res.output.split())


def test_klv_footprints_are_counter_clockwise_rings(tmp_path):
    """RFC 7946: exterior rings counter-clockwise (shoelace in lon/lat, positive), closed; both
    eoloc's footprints and the encoder's corners."""
    from click.testing import CliRunner

    from eoloc.cli import main

    flight = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "flight.klv"
    r = CliRunner().invoke(main, ["klv", str(flight), "--out", str(tmp_path), "--no-map"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "footprints.geojson").read_text())
    rings = [f["geometry"]["coordinates"][0] for f in doc["features"] if f["geometry"]]
    assert rings
    for ring in rings:
        x = np.array([p[0] for p in ring])
        y = np.array([p[1] for p in ring])
        assert ring[0] == ring[-1] and np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]) > 0
