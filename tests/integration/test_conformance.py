"""Issue 49: what other projects' vectors, schemas and tools say, each departure fixed and kept
as a regression test named after its item. Independent references only: klvdata (a decoder that
shares nothing with eoloc), the ST 0601 checksum restated here from the standard, GeographicLib's
GeoConvert (Debian's geographiclib-tools) for MGRS.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from klvfuzz import with_reserved_null_cell
from misbcheck import bcc16, cot_schema
from where import TESTS

DATA = TESTS / "data"


def test_49_3_a_damaged_stream_is_recognised_by_content_as_klv(tmp_path):
    """The telemetry seam takes such a file as KLV (the key's tail is enough), whatever its name."""
    from eoloc.io.sources import identify

    disguised = tmp_path / "flight.dat"
    disguised.write_bytes((DATA / "klv" / "sitrec_day_truncated_keys.klv").read_bytes())
    assert identify(disguised).name == "klv"


def _vectors():
    return json.loads((DATA / "conformance" / "jmisb_st0903_vectors.json").read_text())["vectors"]


def _ber(n: int) -> bytes:
    return bytes([n]) if n < 128 else bytes([0x81, n])


def _item(tag: int, value: bytes) -> bytes:
    return bytes([tag]) + _ber(len(value)) + value


@pytest.mark.parametrize("vec", _vectors(), ids=lambda v: f"{v['set']}-{v['tag']}-v{v['version']}-{v['hex']}")
def test_49_1_st0903_current_and_legacy_sets_read_as_jmisb_reads_them(vec):
    """jMISB's ST 0903 vectors (current IMAPB and ST 0903.3 legacy), each put in a VMTI set whose
    LS version (tag 4) is the vector's, the set built byte by byte here: eoloc's value = jMISB's
    expected value within its tolerance; a legacy set carries a note saying how it was read."""
    from eoloc.io.klv.st0903 import decode_vmti

    raw = bytes.fromhex(vec["hex"])
    head = _item(4, bytes([vec["version"]]))
    if vec["set"] == "vmti":
        vset, notes = decode_vmti(head + _item(vec["tag"], raw))
        got = vset.value(vec["tag"])
    else:
        pack = bytes([1]) + _item(vec["tag"], raw)  # target id 1, then the item
        series = _ber(len(pack)) + pack
        vset, notes = decode_vmti(head + _item(6, b"\x01") + bytes([101]) + _ber(len(series)) + series)
        (target,) = vset.targets
        got = target.value(vec["tag"])
    if isinstance(vec["expect"], list):
        names = ("lat_deg", "lon_deg", "h_m", "sigma_east_m", "sigma_north_m", "sigma_up_m")
        for name, want, tol in zip(names, vec["expect"], vec["tol"], strict=False):
            assert getattr(got, name) == pytest.approx(want, abs=max(tol, 1e-9)), (name, vec["from"])
    else:
        assert got == pytest.approx(vec["expect"], abs=max(vec["tol"], 1e-9)), vec["from"]
    assert any(n.kind == "legacy version" for n in notes) == (vec["version"] <= 3)


# the VMTI set's outermost items as jMISB's VmtiLocalSetFactoryTest lists them: time stamp, system
# name, LS version, frame number, width, height, source sensor, VTarget, Algorithm, Ontology series
JMISB_0903_TAGS = {2, 3, 4, 7, 8, 9, 10, 101, 102, 103}


def test_49_2_stand_alone_st0903_sets_are_read_and_their_checksum_checked(tmp_path):
    """jMISB's 0903.bin: five stand-alone VMTI sets read (their targets under tag 74, as when
    embedded), each with jMISB's outer items; each checksum verifies by the standard's sum; a set
    with one byte spoilt is refused by its checksum, named, and the other four kept."""
    from eoloc.io.klv import read_klv

    path = DATA / "conformance" / "jmisb_0903.bin"
    stream = read_klv(path)
    assert stream.n_good == 5 and stream.n_bad == 0
    for p in stream.packets:
        vset = p.fields[74]
        assert set(vset.values) | {101} == JMISB_0903_TAGS and len(vset.targets) == 2
        assert p.standard == "ST 0903" and bcc16(p.raw) == int.from_bytes(p.raw[-2:], "big")
    raw = bytearray(path.read_bytes())
    second = stream.packets[1]
    raw[second.offset + 40] ^= 0x20
    spoilt = tmp_path / "spoilt.bin"
    spoilt.write_bytes(bytes(raw))
    again = read_klv(spoilt)
    assert again.n_good == 4 and [i.kind for i in again.issues] == ["checksum"]
    assert again.issues[0].packet == 1


def test_49_5_eg0104_labels_carry_the_registrys_version_bytes():
    """Every element eoloc writes into an EG 0104 packet has the full 16-byte label jMISB's table
    has (its version byte included: jMISB dropped 17 of 29 elements written with 01), and the
    packet still reads back to the values written."""
    import json
    from datetime import UTC, datetime

    from eoloc.io.klv.eg0104 import LABELS, decode_eg0104, encode_eg0104

    registry = set(json.loads((DATA / "conformance" / "jmisb_eg0104_labels.json").read_text())["labels"].values())
    values = {}
    for _, kind, name in LABELS.values():
        values[name] = (datetime(2024, 1, 4, 22, 23, 10, tzinfo=UTC) if kind == "time" else "EO" if kind == "text"
                        else 12.5)
    packet = encode_eg0104(values)
    body, pos, written = packet[17:] if packet[16] < 0x80 else packet[16 + 1 + (packet[16] & 0x7F):], 0, []
    while pos < len(body):
        label = body[pos:pos + 16]
        n = body[pos + 16]
        start = pos + 17 if n < 0x80 else pos + 17 + (n & 0x7F)
        length = n if n < 0x80 else int.from_bytes(body[pos + 17:start], "big")
        written.append(label.hex().upper())
        pos = start + length
    assert len(written) == len(LABELS) == 29
    assert set(written) <= registry, sorted(set(written) - registry)
    decoded, notes = decode_eg0104(packet[16 + (1 if packet[16] < 0x80 else 1 + (packet[16] & 0x7F)):])
    assert decoded[13] == 12.5 and decoded[16] == 12.5 and not [n for n in notes if n.kind != "field"]


def test_49_6_a_footprint_across_the_antimeridian_is_cut(tmp_path):
    """A frame seen at 179.999°E looking straight down: `eoloc footprint` writes it as a MultiPolygon
    cut at ±180 (RFC 7946 §3.1.9): shapely finds it valid, every longitude in [-180, 180], every
    exterior ring counter-clockwise, the parts' geodesic areas (pyproj.Geod) add up to the frame's;
    the KML holds the two parts in a MultiGeometry (read back by the standard library's parser)."""
    import json
    import xml.etree.ElementTree as ET

    import shapely
    from click.testing import CliRunner
    from pyproj import Geod

    from eoloc.cli.main import main

    tel = tmp_path / "telemetry.csv"
    tel.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n"
                   "0,10.0,179.999,3000,0,0,0,0,-90\n1,10.0,-179.9995,3000,30,0,0,0,-90\n", encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 1280\nheight = 960\nfx = 1000.0\n", encoding="utf-8")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["footprint", str(tel), "--config", str(cfg), "--target-height", "0",
                                  "--out", str(out), "--format", "geojson", "--format", "kml"])
    assert r.exit_code == 0, r.output
    feats = json.loads((out / "footprints.geojson").read_text())["features"]
    geod = Geod(ellps="WGS84")
    for f in feats:
        g = f["geometry"]
        assert g["type"] == "MultiPolygon" and len(g["coordinates"]) == 2
        shape = shapely.from_geojson(json.dumps(g))
        assert shape.is_valid
        area = 0.0
        for (ring,) in g["coordinates"]:
            lon = np.array([c[0] for c in ring])
            lat = np.array([c[1] for c in ring])
            assert (np.abs(lon) <= 180.0).all() and shapely.Polygon(list(zip(lon, lat, strict=True))).exterior.is_ccw
            area += geod.polygon_area_perimeter(lon, lat)[0]
        assert area == pytest.approx(f["properties"]["area_m2"], rel=1e-3)
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    root = ET.parse(out / "footprints.kml").getroot()
    multis = root.findall(".//k:MultiGeometry", ns)
    assert len(multis) == len(feats) and all(len(m.findall("k:Polygon", ns)) == 2 for m in multis)


def test_49_9_two_st0601_leniencies_are_decided_and_said():
    """Where jMISB refuses and eoloc reads, as decided (docs/reliability.md "Conformance"): tag 47 with a zero
    length is ST 0601 §6.2's "no longer known" (read as such, no note: the standard allows it);
    tag 65 sent as two bytes 00 00 is read as version 0, with a note naming the length."""
    from eoloc.io.klv.encode import build_uas_packet
    from eoloc.io.klv.reader import decode_klv_bytes
    from eoloc.io.klv.st0601 import Special

    items = [(2, (1_700_000_000 * 10**6).to_bytes(8, "big")), (13, b"\x20\x00\x00\x00"), (47, b""), (65, b"\x00\x00")]
    stream = decode_klv_bytes(build_uas_packet(items))
    (p,) = stream.packets
    assert p.fields[47] is Special.UNKNOWN and p.fields[65] == 0
    notes = [str(n) for n in stream.notes]
    assert any("tag 65" in n and "2 bytes" in n for n in notes) and not any("tag 47" in n for n in notes)


def test_49_7_every_kml_eoloc_writes_is_valid_ogc_kml_2_2(tmp_path):
    """The KML of a KLV flight (points, footprints, the aircraft's track), of footprints cut at the
    antimeridian (MultiGeometry) and of moving-target tracks: each valid against the OGC KML 2.2
    schema (ogckml22.xsd with its Atom and xAL imports, as pykml ships them), checked by xmlschema."""
    from importlib.resources import files

    import xmlschema
    from click.testing import CliRunner

    import eoloc
    from eoloc.cli.main import main

    schema = xmlschema.XMLSchema(str(files("pykml") / "schemas" / "ogckml22.xsd"))
    demo = Path(eoloc.__file__).parent / "data" / "demo"
    runner = CliRunner()
    outs = []
    r = runner.invoke(main, ["klv", str(demo / "mountain" / "flight.klv"), "--out", str(tmp_path / "klv")])
    assert r.exit_code == 0, r.output
    outs += sorted((tmp_path / "klv").glob("*.kml"))
    tel = tmp_path / "telemetry.csv"
    tel.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n"
                   "0,10.0,179.999,3000,0,0,0,0,-90\n", encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 1280\nheight = 960\nfx = 1000.0\n", encoding="utf-8")
    r = runner.invoke(main, ["footprint", str(tel), "--config", str(cfg), "--target-height", "0",
                             "--out", str(tmp_path / "fp"), "--format", "kml"])
    assert r.exit_code == 0, r.output
    outs += sorted((tmp_path / "fp").glob("*.kml"))
    r = runner.invoke(main, ["track", str(demo / "telemetry.csv"), str(demo / "detections.csv"), "--config",
                             str(demo / "camera.toml"), "--target-height", "600", "--out", str(tmp_path / "tr"),
                             "--format", "kml"])
    assert r.exit_code == 0, r.output
    outs += sorted((tmp_path / "tr").glob("*.kml"))
    assert len(outs) >= 3
    for path in outs:
        errors = [str(e)[:300] for e in schema.iter_errors(str(path))]
        assert not errors, (path.name, errors[:3])


def test_49_4_klv_out_without_a_fix_says_so(tmp_path):
    """`eoloc klv FILE --klv-out F` on a stream without VMTI: no file, and a note saying why
    (before: nothing written and nothing said)."""
    from click.testing import CliRunner

    from eoloc.cli.main import main

    dest = tmp_path / "with_fixes.klv"
    r = CliRunner().invoke(main, ["klv", str(DATA / "klv" / "realflight.bin"), "--out", str(tmp_path / "o"),
                                  "--no-map", "--klv-out", str(dest)])
    assert r.exit_code == 0, r.output
    assert not dest.exists()
    assert "--klv-out: the stream has no VMTI targets" in " ".join(r.output.split()), r.output


def _strict_st1402(path: Path) -> tuple[list, list]:
    """stanag4609's own demultiplexer and ST 1402 metadata decoder (strict: an asynchronous PES
    must have stream_id 0xBD, no PTS or DTS, a length; a synchronous one the metadata AU cells of
    a declared service) over the whole file: (the PMT's KLV stream declarations, the KLV events,
    the byte offsets of the video PES packets)."""
    from stanag4609.transport.demux import PESStreamEvent, PMTEvent, StreamKind, TransportDemuxer
    from stanag4609.transport.metadata_stream import MetadataStreamDecoder

    demux, decoder = TransportDemuxer(), MetadataStreamDecoder()
    data = path.read_bytes()
    events = list(demux.feed(data)) + list(demux.finish())
    streams = list({s.elementary_pid: s for e in events if isinstance(e, PMTEvent) for s in e.table.streams
                    if s.stream_type in (0x06, 0x15)}.values())
    klv = [k for e in events if isinstance(e, PESStreamEvent) and e.kind is StreamKind.KLV for k in decoder.feed(e)]
    decoder.finish()
    video = [e.pes.offset for e in events if isinstance(e, PESStreamEvent) and e.kind is StreamKind.VIDEO]
    return streams, klv, video


@pytest.mark.parametrize("carriage", ["async", "sync"])
def test_49_8_mux_writes_st1402_carriage_and_reads_it_back(tmp_path, carriage):
    """`eoloc mux --carriage async|sync`, checked by stanag4609's strict ST 1402 decoder and by
    FFmpeg (PyAV's demultiplexer). async: stream_type 0x06 with the 'KLVA' registration
    descriptor, every PES stream_id 0xBD without PTS (before: 0xFC with a PTS, as FFmpeg writes);
    sync: stream_type 0x15 with the metadata (0x26) and metadata STD (0x27) descriptors, every
    access unit with its frame's PTS. Both: one packet per frame, each right after its frame's
    video (sync's last: just before it); FFmpeg (PyAV's, and Debian's ffprobe) demultiplexes the
    same bytes with that stream id and timing; eoloc reads each back at its frame's time exactly
    (async: by arrival, said in a note)."""
    import av
    from click.testing import CliRunner

    from eoloc.cli.main import main
    from eoloc.io.klv import read_klv
    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.io.videofile import frame_times

    video = write_klv_ts(tmp_path / "video.ts", [], video_fps=10, duration_s=2.0)
    times = frame_times(video)
    t = np.arange(times[0] - 1, times[-1] + 1.01, 0.5)
    tel = tmp_path / "telemetry.csv"
    tel.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n" + "".join(
        f"{x:.3f},{40 + 1e-5 * k:.6f},-105.0,3000,0,0,0,0,-60\n" for k, x in enumerate(t)), encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 160\nheight = 96\nfx = 140.0\n", encoding="utf-8")
    out = tmp_path / "out.ts"
    r = CliRunner().invoke(main, ["mux", str(video), "--telemetry", str(tel), "--config", str(cfg), "-o", str(out),
                                  "--carriage", carriage, "--start-utc", "2026-01-01T00:00:00Z"])
    assert r.exit_code == 0, r.output
    streams, klv, video_at = _strict_st1402(out)
    (decl,) = streams
    tags = {d.tag for d in decl.descriptors}
    if carriage == "async":
        assert decl.stream_type == 0x06 and any(d.tag == 0x05 and d.data == b"KLVA" for d in decl.descriptors)
        assert all(k.source.pes.stream_id == 0xBD and k.pts is None for k in klv)
    else:
        assert decl.stream_type == 0x15 and {0x26, 0x27} <= tags
        assert all(k.source.pes.stream_id == 0xFC for k in klv)
        np.testing.assert_allclose([k.pts / 90_000 for k in klv], times, atol=1.2e-5)
    assert len(klv) == times.size == len(video_at) == 20
    after = np.searchsorted(video_at, [k.source.pes.offset for k in klv])  # how many frames began before each packet
    # each right after its frame's video; sync's last just before it (its PTS says which frame it is)
    np.testing.assert_array_equal(after, np.r_[np.arange(1, 20), 20 if carriage == "async" else 19])
    with av.open(str(out)) as c:  # FFmpeg's reading: the same packets, in the same order
        ff = [bytes(p) for p in c.demux(c.streams.data[0]) if p.size]
    assert ff == [bytes(k.packet.raw) for k in klv]
    # Debian's ffprobe (FFmpeg 5.1, another build than PyAV's): one KLV data stream, its packets with
    # the PES stream id and timing of the carriage
    exe = shutil.which("ffprobe")
    assert exe, "ffprobe (Debian's ffmpeg) is installed by `make test` (target ffmpeg)"
    probe = json.loads(subprocess.run([exe, "-v", "error", "-select_streams", "d", "-show_streams", "-show_packets",
                                       "-of", "json", str(out)], capture_output=True, text=True, check=True).stdout)
    (stream,) = probe["streams"]
    assert stream["codec_name"] == "klv" and stream["codec_tag_string"] == "KLVA"
    assert [int(p["size"]) for p in probe["packets"]] == [len(k.packet.raw) for k in klv]
    assert {p["side_data_list"][0]["id"] for p in probe["packets"]} == {0xBD if carriage == "async" else 0xFC}
    if carriage == "async":
        assert all("pts" not in p for p in probe["packets"])
    else:
        np.testing.assert_allclose([float(p["pts_time"]) for p in probe["packets"]], times, atol=1.2e-5)
    back = read_klv(out)
    np.testing.assert_allclose([p.pts_s for p in back.packets], times, atol=1.2e-5)
    assert [p.raw for p in back.packets] == [bytes(k.packet.raw) for k in klv]
    assert any(n.kind == "timed by arrival" and n.count == 20 for n in back.notes) == (carriage == "async")
    # and through the tolerant path: a null cell with the reserved adaptation field control (00)
    # slipped in halfway makes the stream unclean, and changes nothing of the KLV or its timing
    damaged = tmp_path / "damaged.ts"
    damaged.write_bytes(with_reserved_null_cell(out.read_bytes()))
    again = read_klv(damaged)
    assert [p.raw for p in again.packets] == [p.raw for p in back.packets]
    np.testing.assert_allclose([p.pts_s for p in again.packets], times, atol=1.2e-5)


def test_49_cot_every_event_eoloc_sends_is_valid_against_the_cot_schema(tmp_path):
    """MITRE's CoT Event 2.0 schema (tests/data/conformance/cot_event_2_0.xsd) on every kind of
    event eoloc makes: the TAK data package of `eoloc klv` (each fix), and a whole live flight's
    feed over its DEM (aircraft with its sensor, sensor point of interest, footprint shape, each
    target, each refined estimate), the silence event and the presence event."""
    import zipfile
    from datetime import UTC, datetime

    from click.testing import CliRunner

    import eoloc
    from eoloc.cli.main import main
    from eoloc.io.config import load_config
    from eoloc.io.klv.reader import split_klv
    from eoloc.jobs.setup import misb_setup
    from eoloc.live.cotfeed import CotFeed
    from eoloc.live.refine import TargetFilters
    from eoloc.live.session import LiveSession
    from eoloc.terrain import open_dem

    schema = cot_schema()
    mountain = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
    flight, dem, config = mountain / "flight.klv", mountain / "longs_peak_srtmgl3.tif", mountain / "klv.toml"
    r = CliRunner().invoke(main, ["klv", str(flight), "--dem", str(dem), "--config", str(config), "--out",
                                  str(tmp_path / "klv"), "--no-map"])
    assert r.exit_code == 0, r.output
    with zipfile.ZipFile(tmp_path / "klv" / "fixes.cot.zip") as zf:
        packaged = [zf.read(n) for n in zf.namelist() if n.endswith(".cot")]
    session = LiveSession("test", dem=open_dem([dem]), budget=misb_setup(load_config(config))[1],
                          refine=TargetFilters("static"))
    feed = CotFeed(targets="both")
    now = datetime(2026, 11, 27, 12, tzinfo=UTC)
    live = [e for raw, _ in split_klv(flight.read_bytes()) for u in session.feed(raw) for e in feed.events(u, now=now)]
    live += [*feed.silence(7.0, now=now), feed.presence(now=now)]
    kinds = {schema.to_dict(e.decode()).get("@type") for e in live}
    assert {"a-f-A-M-F-Q", "b-m-p-s-p-i", "u-d-f", "a-u-G", "a-f-G-E-S"} <= kinds
    assert len(packaged) == 103 and len(live) > 250
    for event in [*packaged, *live]:
        errors = [str(e)[:300] for e in schema.iter_errors(event.decode())]
        assert not errors, (event[:400], errors[:2])


def _rfc7946_problems(obj: dict) -> list[str]:
    """What RFC 7946 asks beyond the objects' shapes (which geojson-pydantic checks): no "crs"
    member (§4), positions in range (§3.1.1, §4), polygon rings by the right-hand rule: exterior
    counter-clockwise, holes clockwise (§3.1.6; shapely decides the turn)."""
    from shapely.geometry import LinearRing

    out = [] if "crs" not in obj else ["a 'crs' member (RFC 7946 §4 removed it)"]

    def polygons(g: dict | None):
        if g is None:
            return
        if g["type"] == "Polygon":
            yield g["coordinates"]
        elif g["type"] == "MultiPolygon":
            yield from g["coordinates"]
        elif g["type"] == "GeometryCollection":
            for part in g["geometries"]:
                yield from polygons(part)

    def positions(c):
        if c and isinstance(c[0], (int, float)):
            yield c
        else:
            for x in c:
                yield from positions(x)

    for f in obj.get("features", [obj]):
        g = f.get("geometry")
        if g is None:
            continue
        coords = g.get("coordinates", [p for part in g.get("geometries", []) for p in part["coordinates"]])
        out += [f"position {p} out of range" for p in positions(coords)
                if not (-180 <= p[0] <= 180 and -90 <= p[1] <= 90)]
        for rings in polygons(g):
            out += ["exterior ring clockwise"] if not LinearRing(rings[0]).is_ccw else []
            out += ["a hole counter-clockwise" for r in rings[1:] if LinearRing(r).is_ccw]
    return out


def test_49_every_geojson_eoloc_writes_is_valid_rfc_7946(tmp_path):
    """Every GeoJSON file of `eoloc klv` (footprints, frame centres, sensor track, fixes), `eoloc
    locate`, `eoloc track`, `eoloc footprint` across the antimeridian, and every line of `eoloc
    live --ndjson`: strict JSON (no NaN or Infinity), each object valid for geojson-pydantic's
    RFC 7946 models, and RFC 7946's own rules (no crs, positions in range, right-hand rings)."""
    import sys

    from click.testing import CliRunner
    from geojson_pydantic import Feature, FeatureCollection

    import eoloc
    from eoloc.cli.main import main

    def strict(text: str):
        def refuse(name: str):
            raise AssertionError(f"{name} in JSON")
        return json.loads(text, parse_constant=refuse)

    demo = Path(eoloc.__file__).parent / "data" / "demo"
    mountain = demo / "mountain"
    runner = CliRunner()
    runs = [["klv", str(mountain / "flight.klv"), "--dem", str(mountain / "longs_peak_srtmgl3.tif"), "--config",
             str(mountain / "klv.toml"), "--no-map"],
            ["locate", str(demo / "telemetry.csv"), str(demo / "detections.csv"), "--config", str(demo / "camera.toml"),
             "--target-height", "600", "--format", "geojson"],
            ["track", str(demo / "telemetry.csv"), str(demo / "detections.csv"), "--config", str(demo / "camera.toml"),
             "--target-height", "600", "--format", "geojson"]]
    tel = tmp_path / "telemetry.csv"
    tel.write_text("time_s,lat_deg,lon_deg,h_m,yaw_deg,pitch_deg,roll_deg,gimbal1_deg,gimbal2_deg\n"
                   "0,10.0,179.999,3000,0,0,0,0,-90\n1,10.001,-179.999,3000,0,0,0,0,-60\n", encoding="utf-8")
    cfg = tmp_path / "camera.toml"
    cfg.write_text("[camera]\nwidth = 1280\nheight = 960\nfx = 1000.0\n", encoding="utf-8")
    runs.append(["footprint", str(tel), "--config", str(cfg), "--target-height", "0", "--format", "geojson"])
    files = []
    for k, args in enumerate(runs):
        r = runner.invoke(main, [*args, "--out", str(tmp_path / f"run{k}")])
        assert r.exit_code == 0, (args[0], r.output)
        files += sorted((tmp_path / f"run{k}").glob("*.geojson"))
    assert len(files) >= 7, files
    n = 0
    for path in files:
        obj = strict(path.read_text(encoding="utf-8"))
        FeatureCollection.model_validate(obj)
        assert not _rfc7946_problems(obj), (path.name, _rfc7946_problems(obj)[:3])
        n += len(obj["features"])
    lines = tmp_path / "live.ndjson"
    r = subprocess.run([str(Path(sys.executable).parent / "eoloc"), "live", str(mountain / "flight.klv"), "--dem",
                        str(mountain / "longs_peak_srtmgl3.tif"), "--config", str(mountain / "klv.toml"), "--ndjson",
                        str(lines)], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    for line in lines.read_text(encoding="utf-8").splitlines():
        obj = strict(line)
        Feature.model_validate(obj)
        assert not _rfc7946_problems(obj), (line[:300], _rfc7946_problems(obj))
        n += 1
    print(f"GeoJSON: {len(files)} files + live, {n} objects valid")
    assert n > 500


def _validate_gpkg(path: Path) -> subprocess.CompletedProcess:
    import sys

    return subprocess.run([sys.executable, "-m", "osgeo_utils.samples.validate_gpkg", "--extra", str(path)],
                          capture_output=True, text=True, timeout=120)


def test_49_every_geopackage_eoloc_writes_passes_gdals_validator(tmp_path):
    """GDAL's own GeoPackage validator (validate_gpkg.py of gdal-utils, with its extra checks) on
    every GeoPackage of `eoloc klv --format gpkg` (footprints, frame centres, sensor track, fixes)
    and `eoloc locate --format gpkg`: exit 0 and nothing said. The validator is seen to refuse a
    file whose geometry-columns table lost its row (so a pass means something)."""
    import sqlite3

    from click.testing import CliRunner

    import eoloc
    from eoloc.cli.main import main

    demo = Path(eoloc.__file__).parent / "data" / "demo"
    mountain = demo / "mountain"
    runner = CliRunner()
    for k, args in enumerate([
            ["klv", str(mountain / "flight.klv"), "--dem", str(mountain / "longs_peak_srtmgl3.tif"), "--config",
             str(mountain / "klv.toml"), "--no-map", "--format", "gpkg"],
            ["locate", str(demo / "telemetry.csv"), str(demo / "detections.csv"), "--config",
             str(demo / "camera.toml"), "--target-height", "600", "--format", "gpkg"]]):
        r = runner.invoke(main, [*args, "--out", str(tmp_path / f"run{k}")])
        assert r.exit_code == 0, r.output
    files = sorted(tmp_path.glob("run*/*.gpkg"))
    assert len(files) == 5, files
    for path in files:
        v = _validate_gpkg(path)
        assert v.returncode == 0 and not (v.stdout + v.stderr).strip(), (path.name, v.stdout, v.stderr)
    broken = tmp_path / "broken.gpkg"
    broken.write_bytes(files[0].read_bytes())
    with sqlite3.connect(broken) as db:
        db.execute("DELETE FROM gpkg_geometry_columns")
    v = _validate_gpkg(broken)
    assert v.returncode != 0 and "Req" in v.stdout + v.stderr, (v.stdout, v.stderr)


def test_49_st0601_items_read_as_jmisb_reads_them():
    """jMISB's ST 0601 item vectors (tests/data/conformance/jmisb_st0601_vectors.json: 158 byte
    strings from its testFactory tests, MIT): every one of a tag eoloc decodes (63 over 27 tags:
    positions, heights, angles, fields of view, corners, CE90/LE90, time stamp, LS version) gives
    jMISB's value within the tolerance its test allows; where jMISB reads an item's error value as
    infinite, eoloc returns ST 0601's special value (never a number). The tags eoloc keeps raw (it
    does not use them) are counted, not decoded."""
    from eoloc.io.klv.st0601 import TABLE, Special, decode_values

    vectors = json.loads((DATA / "conformance" / "jmisb_st0601_vectors.json").read_text())["vectors"]
    used = [v for v in vectors if v["tag"] in TABLE]
    assert len(vectors) == 158 and len(used) == 63 and len({v["tag"] for v in used}) == 27
    for v in used:
        values, notes = decode_values([(v["tag"], bytes.fromhex(v["hex"]))])
        got = values[v["tag"]]
        if v["expect"] == "inf":
            assert isinstance(got, Special), (v["from"], v["hex"], got)
            continue
        got = got.year if v["getter"] == "getYear" else float(got)
        assert got == pytest.approx(v["expect"], abs=max(v["tol"], 1e-9 * max(1.0, abs(v["expect"])))), (
            v["from"], v["hex"], got, v["expect"], notes)


def test_49_st0601_items_read_as_klvdata_and_the_standards_examples_say():
    """klvdata's ST 0601 test vectors (tests/data/conformance/klvdata_st0601_vectors.json, MIT): of
    the 79, the 43 of tags eoloc decodes. 'decoded': klvdata's stated reading (numbers to 1e-9
    relative, the time stamp and texts exactly). 'example': the standard's own conversion examples
    (ST 0601.11 §8 and earlier), the value the bytes were made from, so eoloc's reading lies within
    one step of the item's mapping (the range from stanag4609's field table, not eoloc's)."""
    from stanag4609.st0601 import FIELD_DEFINITIONS

    from eoloc.io.klv.st0601 import TABLE, decode_values

    vectors = json.loads((DATA / "conformance" / "klvdata_st0601_vectors.json").read_text())["vectors"]
    used = [v for v in vectors if v["tag"] in TABLE]
    assert len(vectors) == 79 and len(used) == 43
    for v in used:
        raw = bytes.fromhex(v["hex"])
        got = decode_values([(v["tag"], raw)])[0][v["tag"]]
        if v["kind"] == "example":
            spec = FIELD_DEFINITIONS[v["tag"]]  # integers (flags, the LS version) exactly
            step = 0.0 if spec.physical_min is None else float(spec.physical_max - spec.physical_min) / (
                2 ** (8 * len(raw)) - 2)
            assert abs(float(got) - v["expect"]) <= step, (v["from"], got, v["expect"], step)
        elif isinstance(got, (int, float)):
            assert float(got) == pytest.approx(float(v["expect"]), rel=1e-9, abs=1e-9), (v["from"], got)
        else:
            assert str(got) == v["expect"], (v["from"], got)


def test_49_kwivers_full_st0601_set_reads_as_kwiver_reads_it():
    """KWIVER's ST 0601 test set (tests/data/conformance/kwiver_st0601_set.json, BSD-3): one local
    set with every tag from 2 to 143, nested sets included. Read whole by eoloc's tolerant reader
    (every item kept: 141, none truncated), each of the 48 values of the tags eoloc decodes equal
    to KWIVER's to 1e-9 relative (time stamp in microseconds, texts exactly)."""
    from datetime import UTC, datetime, timedelta

    from eoloc.io.klv.localset import parse_items
    from eoloc.io.klv.st0601 import TABLE, decode_values

    kw = json.loads((DATA / "conformance" / "kwiver_st0601_set.json").read_text())
    items, notes = parse_items(bytes.fromhex(kw["set_hex"]))
    assert len(items) == 141 and not [n for n in notes if n.kind == "truncated item"]
    values, _ = decode_values(items)
    used = [v for v in kw["expected"] if v["tag"] in TABLE]
    assert len(used) == 48
    for v in used:
        got = values[v["tag"]]
        if v["tag"] == 2:
            assert (got - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(microseconds=1) == v["expect"]
        elif v["kind"] == "text":
            assert got == v["expect"], (v["name"], got)
        else:
            assert float(got) == pytest.approx(v["expect"], rel=1e-9, abs=1e-12), (v["name"], got, v["expect"])


def test_49_kwivers_st0903_set_reads_as_kwiver_reads_it():
    """KWIVER's ST 0903 test set (tests/data/conformance/kwiver_st0903_set.json, BSD-3): a VMTI set
    with two VTargets (one with every item, its location, history, colour, FPA index, empty nested
    series), the algorithm and ontology series. eoloc reads every value KWIVER states (time stamp
    to the microsecond, fields of view, offsets and target height exactly), and KWIVER's target
    location pack (latitude, longitude, height, the three sigmas) in a target of its own."""
    from datetime import UTC, datetime, timedelta

    from eoloc.io.klv.st0903 import decode_vmti

    kw = json.loads((DATA / "conformance" / "kwiver_st0903_set.json").read_text())
    vmti, _ = decode_vmti(bytes.fromhex(kw["set_hex"]))
    for tag, want in kw["expected_set"].items():
        got = vmti.values[int(tag)]
        if tag == "2":
            got = (got - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(microseconds=1)
        assert got == want, (tag, got, want)
    targets = {t.target_id: t.values for t in vmti.targets}
    assert sorted(targets) == [1, 1234]
    for tid, items in kw["expected_targets"].items():
        for tag, want in items.items():
            assert targets[int(tid)][int(tag)] == want, (tid, tag, targets[int(tid)][int(tag)], want)
    pack = bytes.fromhex(kw["location_pack_hex"])  # a VMTI set of version 5 with one target: its location, tag 17
    target = bytes([1, 17, len(pack)]) + pack
    series = bytes([len(target)]) + target
    vmti, _ = decode_vmti(bytes([4, 1, 5, 101, len(series)]) + series)
    location = vmti.targets[0].values[17]
    for name, want in kw["expected_location"].items():
        assert getattr(location, name) == pytest.approx(want, abs=1e-12), name
