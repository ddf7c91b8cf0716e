"""Hostile input through the services and writers (issue 46): each numbered defect found by attacking
eoloc from outside has a regression test named after it (``test_46_<item>_...``), which failed on
the code before its fix; the seeded suites beside them (mutated KLV, fuzzed CSV, hostile HTTP
bodies, injection strings through every writer) run at a size that fits ``make test``, and
``bench/bench_hostile.py`` runs them big."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from livecmd import summary_of, until_listening, wait_for_packets
from ports import free_udp_port

import eoloc
from eoloc.cli import main
from eoloc.io.klv import build_uas_packet, decode_klv_bytes, klv_telemetry, uas_items, vmti_detections
from eoloc.io.klv.localset import encode_items, parse_items
from eoloc.io.klv.reader import split_klv
from eoloc.rules import AtHeight

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT = MOUNTAIN / "flight.klv"
DEM = MOUNTAIN / "longs_peak_srtmgl3.tif"
EOLOC = str(Path(sys.executable).parent / "eoloc")
ALL_ONES = b"\xff" * 8  # a time stamp no clock can be at: 2^64 - 1 µs is year ~586 000


def _packets() -> list[bytes]:
    return [raw for raw, _ in split_klv(FLIGHT.read_bytes())]


def _with_items(packet: bytes, change) -> bytes:
    """The ST 0601 packet rebuilt (checksum valid) with its items passed through ``change``."""
    return build_uas_packet(change(uas_items(packet)))


def _bad_time_flight() -> tuple[bytes, int, int]:
    """The mountain flight with ST 0601 tag 2 all ones in packet 3 and the VMTI set's own time
    stamp (ST 0903 tag 2) all ones in packet 6, both with valid checksums: the bytes, and the
    number of packets and of located targets (status OK) the untouched stream gives."""
    pk = _packets()
    pk[3] = _with_items(pk[3], lambda items: [(t, ALL_ONES if t == 2 else v) for t, v in items])

    def vmti_time(items):
        return [(t, encode_items([(2, ALL_ONES), *parse_items(v)[0]]) if t == 74 else v) for t, v in items]

    pk[6] = _with_items(pk[6], vmti_time)
    return b"".join(pk), len(pk)


# -- item 1: one datagram stopped `eoloc live` ------------------------------------------------------


def test_46_1_time_stamp_of_all_ones_is_a_note_and_the_packet_is_kept():
    """ST 0601 and ST 0903 time stamps of FF..FF (checksums valid): the packets are kept, each with
    a note naming the field; nothing raises (before: OverflowError: date value out of range)."""
    data, n = _bad_time_flight()
    stream = decode_klv_bytes(data)
    assert len(stream.packets) == n - 1  # the demo's one corrupted packet (17) is the only loss
    p3 = next(p for p in stream.packets if p.index == 3)
    assert 2 not in p3.fields and 13 in p3.fields  # the time stamp left out, the rest kept
    notes = {(x.tag, x.first_packet) for x in stream.notes if "past the year 9999" in x.message}
    assert ("2", 3) in notes and ("74.2", 6) in notes, stream.notes
    tel = klv_telemetry(stream)
    ok_time = ~(tel.columns["time_s"] != tel.columns["time_s"])
    assert ok_time.sum() == len(tel) - 1  # packet 3 has no time; every other one has its own
    det = vmti_detections(stream)
    assert 6 in set(det.columns["frame"].astype(int))  # packet 6's targets are still there


def test_46_1_eoloc_klv_keeps_the_good_packets(tmp_path):
    data, _ = _bad_time_flight()
    path = tmp_path / "bad_time.klv"
    path.write_bytes(data)
    r = CliRunner().invoke(main, ["klv", str(path), "--dem", str(DEM), "--out", str(tmp_path / "o")])
    assert r.exit_code == 0 and "Traceback" not in r.output and "internal error" not in r.output, r.output
    assert "past the year 9999" in r.output
    lines = (tmp_path / "o" / "fixes.csv").read_text(encoding="utf-8").splitlines()
    assert sum(",OK," in x or x.endswith(",OK") for x in lines) >= 90  # the stream's located targets kept


def test_46_1_eoloc_batch_marks_the_file_done(tmp_path):
    data, _ = _bad_time_flight()
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "bad_time.klv").write_bytes(data)
    r = CliRunner().invoke(main, ["batch", str(tmp_path / "in"), "--out", str(tmp_path / "out"), "--dem", str(DEM)])
    assert "Traceback" not in r.output and r.exit_code == 0, r.output
    status = (tmp_path / "out" / "batch_status.csv").read_text(encoding="utf-8")
    assert ",done," in status, status


def test_46_1_eoloc_live_goes_on_after_the_packet(tmp_path):
    """The packets after the bad one are located: live's summary counts every packet."""
    data, n = _bad_time_flight()
    port = free_udp_port()
    out = tmp_path / "fixes.ndjson"
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--dem", str(DEM), "--ndjson", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    head = until_listening(proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for raw, _ in split_klv(data):
            tx.sendto(raw, ("127.0.0.1", port))
    seen = wait_for_packets(out, n - 1, proc)  # every packet but the corrupted one, located and written
    proc.send_signal(signal.SIGINT)
    log, _ = proc.communicate(timeout=30)
    log = head + log
    assert proc.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log)
    assert summary["packets"] == n - 1 and summary["corrupt"] == 1, summary
    assert seen == n - 1


# -- item 2: script injection in `eoloc map` ---------------------------------------------------------

#: strings that run a script, break a page, an XML document or a spreadsheet when pasted raw; each
#: sets ``window.__eoloc_pwned`` where it runs
INJECTIONS = (
    "${window.__eoloc_pwned = 'template'}",
    "`;window.__eoloc_pwned = 'backtick';`",
    '<img src=x onerror="window.__eoloc_pwned = \'onerror\'">',
    "</script><script>window.__eoloc_pwned = 'script'</script>",
    "<b>bold</b> & <i>italic</i>",
    "a & b < c > d \" ' ]]> <![CDATA[x]]> -->",
    "=1+2",
    "+SUM(A1:A2)",
    "-2+3",
    "@HYPERLINK(\"http://x\")",
    "ünïcødé ✓ \u2028 sep",
)


def _located_with_ids(tmp_path: Path, ids) -> Path:
    """`eoloc locate` of the mountain flight with the detections' target ids replaced by ``ids`` (in
    turn): the fixes.geojson it writes."""
    import csv

    rows = list(csv.DictReader((MOUNTAIN / "detections.csv").open(encoding="utf-8")))
    for k, r in enumerate(rows):
        r["target_id"] = ids[k % len(ids)]
    det = tmp_path / "detections.csv"
    with det.open("w", encoding="utf-8", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    out = tmp_path / "located"
    r = CliRunner().invoke(main, ["locate", str(MOUNTAIN / "telemetry.csv"), str(det),
                                  "--config", str(MOUNTAIN / "camera.toml"), "--dem", str(DEM), "--out", str(out)])
    assert r.exit_code == 0, r.output
    return out / "fixes.geojson"


@pytest.mark.browser
def test_46_2_target_ids_never_run_a_script_in_eoloc_map(tmp_path):
    """Target ids from a detections CSV reach the map's tooltips as text: nothing runs on load or on
    hover, and each tooltip reads exactly the id (before: pasted raw into the page's JavaScript)."""
    from browser import chromium

    fixes = _located_with_ids(tmp_path, INJECTIONS)
    page = tmp_path / "map.html"
    r = CliRunner().invoke(main, ["map", "--fixes", str(fixes), "-o", str(page), "--title", INJECTIONS[2]])
    assert r.exit_code == 0, r.output
    d = chromium()
    try:
        d.get(page.as_uri())
        state = d.execute_script("""
            const tips = [];
            const targets = [];
            for (const k in window) {
                const v = window[k];
                if (v && v instanceof L.CircleMarker && !(v instanceof L.Circle) && v.getTooltip()) targets.push(v);
            }
            for (const m of targets) {
                m.openTooltip();
                tips.push(m.getTooltip().getElement().textContent);
                m.closeTooltip();
            }
            return {pwned: window.__eoloc_pwned || null, tips: tips,
                    title: document.getElementById('eoloc-title').textContent};""")
        errors = [e for e in d.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    finally:
        d.quit()
    assert state["pwned"] is None and errors == [], (state["pwned"], errors)
    assert state["title"] == INJECTIONS[2]
    ok = [f["properties"]["target_id"] for f in json.loads(fixes.read_text(encoding="utf-8"))["features"]
          if f["properties"]["status"] == "OK"]
    tips = [t for t in state["tips"] if "target_id=" in t]  # "time_s=… target_id=<id> h_m=… status=OK"
    assert len(tips) == len(ok) and len(set(ok)) >= 5
    for target_id in set(ok):  # each id shown as it is, once per fix
        assert sum(f" target_id={target_id} h_m=" in t for t in tips) == ok.count(target_id), target_id


# -- item 5: writers break on ordinary characters ----------------------------------------------------

CONTROL = "ctl\x00\x01\x07\x08\x0b\x0c\x1b\x1f\x7f end"  # what a platform designation may carry
FORMULAS = ("=1+2", "+SUM(A1:A2)", "-2+3", "@HYPERLINK(\"x\")", "\t=tab", "'=quoted", "''@twice")


def _fix_records(ids):
    import numpy as np

    from eoloc.io.records import Records

    n = len(ids)
    return Records({"target_id": np.array(ids, dtype=object), "lat_deg": np.linspace(40.0, 40.1, n),
                    "lon_deg": np.linspace(-105.6, -105.5, n), "h_m": np.full(n, 3900.0),
                    "range_m": np.full(n, 9000.0), "status": np.array(["OK"] * n, dtype=object),
                    "sigma_e_m": np.full(n, 3.0), "sigma_n_m": np.full(n, 4.0), "sigma_u_m": np.full(n, 5.0)})


def test_46_5_every_writer_keeps_hostile_text_as_text(tmp_path):
    """Injection strings, control characters and formulas as target ids through every writer; each
    file read back by a parser that is not eoloc's writer: strict XML (ElementTree, and GDAL for
    KML), json, Python's csv, geopandas. Every id comes back as it was (XML: with the characters
    XML 1.0 cannot hold as U+FFFD). Before: KML raised, CoT was malformed, CSV wrote formulas."""
    import csv
    import io
    import xml.etree.ElementTree as ET
    import zipfile

    import geopandas

    from eoloc.io.writers import FORMATS, write_layer
    from eoloc.io.xmltext import NOT_XML

    ids = [*INJECTIONS, CONTROL, *FORMULAS, "../../outside", "/abs/path"]
    paths = {p.suffix if p.suffix != ".zip" else ".cot": p
             for p in write_layer(tmp_path, "fixes", _fix_records(ids), FORMATS)}
    assert set(paths) == {".csv", ".geojson", ".kml", ".cot", ".parquet", ".gpkg"}
    as_xml = [NOT_XML.sub("\ufffd", i) for i in ids]
    # CSV: Python's csv module reads every id; a formula is guarded by an apostrophe
    rows = list(csv.DictReader(io.StringIO(paths[".csv"].read_text(encoding="utf-8"), newline="")))
    got = [r["target_id"] for r in rows]
    for written, original in zip(got, ids, strict=True):
        starts_formula = original.lstrip("'")[:1] in ("=", "+", "-", "@", "\t", "\r")
        assert written == ("'" + original if starts_formula else original), (written, original)
    # GeoJSON: strict JSON
    feats = json.loads(paths[".geojson"].read_text(encoding="utf-8"), parse_constant=pytest.fail)["features"]
    assert [f["properties"]["target_id"] for f in feats] == ids
    # KML: well-formed, and GDAL's KML driver reads every value
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    marks = ET.parse(paths[".kml"]).getroot().findall(".//k:Placemark", ns)
    assert [m.find("k:name", ns).text for m in marks] == as_xml
    assert [m.find(".//k:SimpleData[@name='target_id']", ns).text for m in marks] == as_xml
    assert list(geopandas.read_file(paths[".kml"], layer="fixes")["target_id"]) == as_xml
    # CoT: every event of the data package a well-formed document with the id as its callsign
    with zipfile.ZipFile(paths[".cot"]) as zf:
        entries = [n for n in zf.namelist() if n.endswith(".cot")]
        # each entry <name>/<name>.cot, its name a plain file name whatever the id said (no zip slip)
        assert all(re.fullmatch(r"([A-Za-z0-9_-][A-Za-z0-9._-]*)/\1\.cot", n) for n in entries), entries
        events = [ET.fromstring(zf.read(n)) for n in entries]
        ET.fromstring(zf.read("MANIFEST/manifest.xml"))
    assert sorted(e.find("detail/contact").get("callsign") for e in events) == sorted(as_xml)
    # GeoParquet and GeoPackage: binary columns, every id as it was
    assert list(geopandas.read_parquet(paths[".parquet"])["target_id"]) == ids
    # (GDAL passes text to SQLite as C strings: a NUL is written as U+FFFD instead of ending the value)
    assert list(geopandas.read_file(paths[".gpkg"])["target_id"]) == [i.replace("\x00", "\ufffd") for i in ids]


def test_46_5_eoloc_reads_its_guarded_csv_cells_back_as_they_were(tmp_path):
    """The apostrophe before a formula is taken off by eoloc's CSV reader (detections and fixes):
    ``eoloc evaluate`` and ``eoloc map`` see the ids that were written."""
    from eoloc.io.points import read_points
    from eoloc.io.writers import write_layer

    ids = [*FORMULAS, "plain", "-12.5", "a,b"]
    (path,) = write_layer(tmp_path, "fixes", _fix_records(ids), ["csv"])
    assert list(read_points(path).column("target_id")) == ids


def test_46_5_live_cot_with_control_characters_in_the_platform_name_is_well_formed():
    """ST 0601 tag 10 (platform designation) and 11 (image source sensor) with control characters
    and markup: every CoT event of the live feed parses (before: 20 of 220 malformed)."""
    import xml.etree.ElementTree as ET

    from eoloc.io.xmltext import xml_text
    from eoloc.live.cotfeed import CotFeed
    from eoloc.live.session import LiveSession
    from eoloc.terrain import open_dem

    name = f"UAV {CONTROL} <b>&'\"]]>"
    session = LiveSession("udp://test", dem=open_dem(DEM))
    feed = CotFeed(targets="both")
    events = []
    for raw in _packets()[:8]:
        packet = _with_items(raw, lambda items: [*[(t, v) for t, v in items if t not in (10, 11)],
                                                  (10, name.encode()), (11, name.encode())])
        for update in session.feed(packet):
            events += feed.events(update)
    parsed = [ET.fromstring(e) for e in events]
    assert len(parsed) >= 8 * 3
    shown = {e.find("detail/contact").get("callsign") for e in parsed if e.find("detail/contact") is not None}
    assert any(xml_text(name) in s for s in shown), shown  # the name, with what XML cannot hold as U+FFFD


# -- item 6: the CSV reader's tracebacks -------------------------------------------------------------


def test_46_6_old_mac_line_ends_and_fields_over_128_kib_are_read(tmp_path):
    """CR-only line ends, and a 140 KiB id in a file that has a quote: every record read (before:
    _csv.Error tracebacks, the file lost)."""
    from eoloc.io.telemetry import read_detections

    (tmp_path / "cr.csv").write_bytes(b"time_s,target_id,u_px,v_px\r0,A,1,2\r1,B,3,4\r")
    t = read_detections(tmp_path / "cr.csv")
    assert list(t.columns["target_id"]) == ["A", "B"] and t.issues == []
    big = "x" * 140_000
    (tmp_path / "big.csv").write_text(f'time_s,target_id,u_px,v_px\n0,"A,q",1,2\n1,{big},3,4\n2,C,5,6\n')
    t = read_detections(tmp_path / "big.csv")
    assert list(t.columns["target_id"]) == ["A,q", big, "C"] and t.issues == []


def test_46_6_fuzzed_csv_files_keep_every_good_line(tmp_path):
    """400 seeded files with every line-end and size oddity (tests/helpers/csvfuzz.py): no exception,
    every good record read with its values, every bad line reported, nothing invented."""
    import numpy as np
    from csvfuzz import fuzzed_csv

    from eoloc.io.telemetry import read_detections

    for seed in range(400):
        f = fuzzed_csv(seed)
        path = tmp_path / f"f{seed}.csv"
        path.write_bytes(f.data)
        t = read_detections(path)
        got = list(zip(t.columns["time_s"].tolist(), t.columns["target_id"].tolist(), t.columns["u_px"].tolist(),
                       t.columns["v_px"].tolist(), strict=True))
        want = [(tt, tid.replace("\r\n", "\n").replace("\r", "\n").strip(), u, v) for tt, tid, u, v in f.expected]
        assert got == want, (seed, [(a, b) for a, b in zip(got, want, strict=False) if a != b][:2], len(got), len(want))
        assert len(t.issues) == f.bad, (seed, [str(i) for i in t.issues])
        assert np.all(np.isfinite(t.columns["u_px"]))


# -- items 4 and 7: the HTTP server's memory, time-outs and types -------------------------------------

S13_POSE = {"lat_deg": 42.0, "lon_deg": 125.0, "h_m": 10_000.0, "yaw_deg": 10.0, "pitch_deg": 5.0, "roll_deg": -2.0,
            "gimbal_deg": [45.0, -75.0]}
TIMEOUT_S = 1.0  # the test server's --request-timeout and --send-timeout


@pytest.fixture(scope="module")
def server():
    """`eoloc serve` with the mountain camera and short time-outs."""
    from served import eoloc_serve

    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml"), "--request-timeout", str(TIMEOUT_S),
                     "--send-timeout", str(TIMEOUT_S)) as url:
        yield url


def _arrow_stream(n: int, *, compression: str | None = None, observation: dict | None = None) -> bytes:
    import numpy as np
    import pyarrow as pa

    obs = observation or {"pose": S13_POSE, "stop": {"target_height_m": 100.0}}
    table = pa.table({"u_px": np.zeros(n), "v_px": np.zeros(n)}).replace_schema_metadata({"eoloc": json.dumps(obs)})
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema, options=pa.ipc.IpcWriteOptions(compression=compression)) as w:
        w.write_table(table)
    return sink.getvalue().to_pybytes()


def test_46_4_a_compressed_arrow_bomb_is_refused_before_it_is_decompressed(server):
    """A few KB of zstd declaring 10^8 rows (1.6 GB once decompressed): 413, and the server's memory
    does not move (before: 1.5 GB per request, kept)."""
    import httpx
    from served import rss_mb

    def post(body: bytes):
        return httpx.post(server + "/v1/locate/arrow", content=body,
                          headers={"content-type": "application/vnd.apache.arrow.stream"}, timeout=60)

    # a sane request first: what the server loads once for the Arrow route (pyarrow itself, ~50 MB
    # resident) is not what a bomb would cost, and the test must not depend on which test ran before
    assert post(_arrow_stream(1000, compression="lz4")).status_code == 200  # compressed streams are read
    bomb = _arrow_stream(10**8, compression="zstd")
    assert len(bomb) < 100_000
    before = rss_mb(server)
    for _ in range(3):
        r = post(bomb)
        assert r.status_code == 413 and "declares 100000000 rows" in r.text, r.text
    assert rss_mb(server) - before < 20  # one decompressed bomb would be 1 600 MB


def test_46_4_a_chunked_body_over_the_limit_is_413_without_a_traceback():
    import httpx
    from served import eoloc_serve

    def chunks():
        for _ in range(9):
            yield b"x" * 2**20

    with eoloc_serve("--max-body-mb", "8") as url:
        r = httpx.post(url + "/v1/locate", content=chunks(), headers={"content-type": "application/json"})
        assert r.status_code == 413 and "over this server's limit" in r.text, r.text
        assert httpx.get(url + "/v1/health").status_code == 200


def _cut_after(sock: socket.socket, trickle: bytes, limit_s: float = 60.0) -> tuple[float, bytes]:
    """Send ``trickle`` a byte at a time until the server cuts the connection: (seconds it took,
    what the server answered)."""
    t0 = time.monotonic()
    sock.settimeout(0.2)
    answer = b""
    for k in range(10**6):
        try:
            sock.sendall(trickle[k % len(trickle):k % len(trickle) + 1])
            answer += sock.recv(4096)
            if answer == b"" or answer.endswith(b"\n"):
                break
        except TimeoutError:
            continue
        except OSError:  # reset or broken pipe: cut
            break
        finally:
            assert time.monotonic() - t0 < limit_s, "never cut"
    try:
        while chunk := sock.recv(4096):
            answer += chunk
    except OSError:
        pass
    return time.monotonic() - t0, answer


def test_46_4_slow_headers_and_slow_bodies_are_cut_after_the_request_timeout(server):
    host, port = server.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port))) as s:
        s.sendall(b"POST /v1/locate HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        took, answer = _cut_after(s, b"X-Slow: 1\r\n")
    # the server's clock starts at the request's first bytes, sent just before _cut_after's own
    # start: a few milliseconds of it are not in ``took``
    assert took >= TIMEOUT_S - 0.05 and answer.startswith(b"HTTP/1.1 408"), answer
    with socket.create_connection((host, int(port))) as s:
        s.sendall(b"POST /v1/locate HTTP/1.1\r\nHost: 127.0.0.1\r\ncontent-type: application/json\r\n"
                  b"content-length: 100000\r\n\r\n{")
        took, _ = _cut_after(s, b" ")
    assert took >= TIMEOUT_S - 0.05


def _tcp_state(sock: socket.socket) -> int:
    """The kernel's TCP state of a socket (tcp_info's first byte: 1 established, 7 closed, 8 close-wait)."""
    return sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 8)[0]


def _unread_round(server: str, body: bytes, size: int, clients: int) -> None:
    """``clients`` connections ask for the answer to ``body`` (``size`` bytes) and read none of it:
    waits until the server has cut every one, and checks none got the whole answer."""
    host, port = server.removeprefix("http://").split(":")
    socks = []
    for _ in range(clients):
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # (before connecting: a small window)
        s.connect((host, int(port)))
        s.sendall(b"POST /v1/locate HTTP/1.1\r\nHost: 127.0.0.1\r\ncontent-type: application/json\r\n"
                  + f"content-length: {len(body)}\r\n\r\n".encode() + body)
        socks.append(s)
    t0 = time.monotonic()
    while any(_tcp_state(s) == 1 for s in socks):  # wait, reading nothing, until the server has cut them all
        assert time.monotonic() - t0 < 180, [_tcp_state(s) for s in socks]
        time.sleep(0.1)
    assert time.monotonic() - t0 >= TIMEOUT_S
    for s in socks:  # what had reached each client before the cut: not the whole answer
        got = 0
        s.settimeout(5)
        try:
            while chunk := s.recv(1 << 16):
                got += len(chunk)
        except OSError:
            pass
        s.close()
        assert got < size


def test_46_4_clients_that_never_read_their_answers_are_cut_and_their_memory_freed(server):
    """Rounds of ten clients that ask for ~15 MB of JSON each and read none of it: each is cut
    after the send time-out, the server goes on answering, and its memory stays far below what the
    unread answers would hold (before: every one held for as long as its client stayed connected)."""
    import httpx
    from served import rss_mb

    body = json.dumps({"pose": {**S13_POSE, "gimbal_deg": [45.0, -30.0]}, "stop": {"target_height_m": 100.0},
                       "pixels": [[float(k % 1280), float(k // 1280)] for k in range(100_000)]}).encode()
    size = len(httpx.post(server + "/v1/locate", content=body, headers={"content-type": "application/json"}).content)
    assert size > 10_000_000
    base = rss_mb(server)
    rounds = []
    for _ in range(3):
        _unread_round(server, body, size, 10)
        assert httpx.get(server + "/v1/health").status_code == 200
        # the server gives the freed memory back on a thread of its own, just after: its lowest RSS
        # over the next two seconds (a floor, whatever this machine's speed)
        lowest = rss_mb(server)
        for _ in range(20):
            time.sleep(0.1)
            lowest = min(lowest, rss_mb(server))
        rounds.append(lowest)
    print(f"RSS (MB): {base:.0f} before, {' / '.join(f'{r:.0f}' for r in rounds)} after each round of 10")
    # bounded: 450 MB of unread answers over the rounds, held they would be all of it; measured 30-100 MB
    # growth, settling near +90 MB after six rounds (bench/bench_hostile.py and the README have figures)
    assert max(rounds) - base < 150


@pytest.mark.parametrize("change, field, words", [
    (lambda o: o["pose"].update(lat_deg=True), "pose.lat_deg", "valid number"),
    (lambda o: o["pose"].update(lat_deg="42"), "pose.lat_deg", "valid number"),
    (lambda o: o["pose"].update(lat_deg=" 42 "), "pose.lat_deg", "valid number"),
    (lambda o: o["pose"].update(h_m="1e4"), "pose.h_m", "valid number"),
    (lambda o: o.update(pixels=[["1", "2"]]), "pixels.0.0", "valid number"),
    (lambda o: o["stop"].update(target_height_m=False), "stop.target_height_m", "valid number"),
    (lambda o: o.update(camera={"width": 1024, "height": 768, "focal_mm": 1e-300, "pixel_um": 1e300}),
     "camera.focal_mm", "greater than or equal to 0.1"),
], ids=["bool", "string", "padded string", "exponent string", "string pixels", "bool height", "absurd camera"])
def test_46_7_the_api_takes_only_the_types_it_asks_for(server, change, field, words):
    """A value of the wrong type is refused by name, as the config loader refuses it (before: `true`
    located at latitude 1.02 deg, strings were numbers, an absurd camera gave HTTP 500)."""
    import copy

    import httpx

    obs = copy.deepcopy({"pose": S13_POSE, "stop": {"target_height_m": 100.0}, "pixels": [[512.0, 384.0]]})
    change(obs)
    r = httpx.post(server + "/v1/locate", json=obs)
    assert r.status_code == 422, r.text
    problems = r.json()["problems"]
    assert any(p["field"] == field and words in p["message"] for p in problems), problems


def test_46_7_no_cross_site_post_and_no_foreign_host(server):
    """A form or fetch from another site can only send text/plain without a preflight: refused 415 on
    both routes; a Host header naming another site (DNS rebinding): 400."""
    import httpx

    obs = json.dumps({"pose": S13_POSE, "stop": {"target_height_m": 100.0}})
    r = httpx.post(server + "/v1/locate", content=obs, headers={"content-type": "text/plain"})
    assert r.status_code == 415
    r = httpx.post(server + "/v1/locate/arrow", content=_arrow_stream(3), headers={"content-type": "text/plain"})
    assert r.status_code == 415
    r = httpx.get(server + "/v1/health", headers={"host": "attacker.example"})
    assert r.status_code == 400
    assert httpx.get(server + "/v1/health", headers={"host": "localhost"}).status_code == 200


def test_46_7_a_config_with_an_absurd_pixel_pitch_is_refused(tmp_path):
    from eoloc.errors import ConfigError
    from eoloc.io.config import load_config

    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nwidth = 1024\nheight = 768\nfocal_mm = 50.0\npixel_um = 1e-300\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="pixel_um"):
        load_config(bad)


# -- item 8: two telemetry records for one frame -----------------------------------------------------


def test_46_8_a_frame_given_two_different_poses_is_not_located(tmp_path):
    """Frame-keyed telemetry with frame 5 twice, with different headings: the detections of frame 5
    get no point and a warning naming both lines (before: paired with the second, OK, silently); a
    record repeated exactly is one record, as with times."""
    import csv

    rows = [r for r in csv.reader((MOUNTAIN / "telemetry.csv").open(encoding="utf-8"))
            if r and not r[0].startswith("#")]
    header, body = rows[0], rows[1:21]
    tel = tmp_path / "telemetry.csv"
    det = tmp_path / "detections.csv"
    other = [*body[5][:4], str((float(body[5][4]) + 30.0) % 360.0), *body[5][5:]]  # frame 5 again, 30 deg off
    with tel.open("w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", *header[1:]])
        for k, r in enumerate(body):
            w.writerow([k, *r[1:]])
            if k == 5:
                w.writerow([5, *other[1:]])
            if k == 7:
                w.writerow([7, *r[1:]])  # an exact copy
    with det.open("w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "target_id", "u_px", "v_px"])
        for k in range(20):
            w.writerow([k, "T", 640.0, 360.0])
    r = CliRunner().invoke(main, ["locate", str(tel), str(det), "--config", str(MOUNTAIN / "camera.toml"),
                                  "--dem", str(DEM), "--out", str(tmp_path / "o"), "--json"])
    assert r.exit_code == 0, r.output
    fixes = list(csv.DictReader((tmp_path / "o" / "fixes.csv").open(encoding="utf-8")))
    by_frame = {int(float(f["frame"])): f for f in fixes}
    assert by_frame[5]["status"] != "OK" and by_frame[5]["lat_deg"] == ""
    assert by_frame[7]["status"] == "OK" and sum(f["status"] == "OK" for f in fixes) == 19
    assert "gives frame 5 twice with different values (lines 7 and 8)" in " ".join(r.output.split())


# -- item 9: `eoloc batch` kept the partitions of files gone -------------------------------------------


def test_46_9_batch_after_a_rename_and_a_delete_holds_each_input_once(tmp_path):
    """A file renamed and another deleted between two runs into one --out: the dataset then holds
    exactly what a fresh run over the same inputs holds (before: the old partitions stayed, 405 rows
    instead of 237); --keep-missing keeps them on purpose."""
    import shutil

    import pyarrow.dataset as ds

    from eoloc.io.klv.synthetic import write_circling_flights

    inputs = tmp_path / "in"
    write_circling_flights(inputs, 3, 30, seed=3)
    shutil.copy(FLIGHT, inputs / "mountain.klv")
    out = tmp_path / "out"

    def run(*args, into=out):
        r = CliRunner().invoke(main, ["batch", str(inputs), "--out", str(into), "--dem", str(DEM), *args])
        assert r.exit_code == 0 and "Traceback" not in r.output, r.output
        return r.output

    def rows(where: Path) -> int:
        return ds.dataset(where / "fixes", format="parquet", partitioning="hive").count_rows()

    run()
    first = rows(out)
    flights = sorted(inputs.glob("flight_*.klv"))
    flights[0].rename(inputs / "renamed.klv")
    flights[1].unlink()
    said = run()
    assert "removed the partitions of 2 file(s) no longer among the inputs" in " ".join(said.split())
    fresh = tmp_path / "fresh"
    run(into=fresh)
    assert rows(out) == rows(fresh) < first
    assert sorted(p.name for p in (out / "fixes").iterdir()) == sorted(p.name for p in (fresh / "fixes").iterdir())
    # kept on request: a run over one file leaves the others' partitions
    only = tmp_path / "only"
    only.mkdir()
    shutil.copy(inputs / "mountain.klv", only / "mountain.klv")
    before = rows(out)
    r = CliRunner().invoke(main, ["batch", str(only), "--out", str(out), "--dem", str(DEM), "--keep-missing"])
    assert r.exit_code == 0 and "removed" not in r.output, r.output
    alone = tmp_path / "alone"
    CliRunner().invoke(main, ["batch", str(only), "--out", str(alone), "--dem", str(DEM)])
    assert rows(out) == before + rows(alone)  # the others kept beside the new file's


# -- item 10: the single-target path and the terrain's edge cases ---------------------------------------


def test_46_10_locate_one_refuses_pixels_outside_the_image():
    """locate_one's status is OUT_OF_IMAGE exactly where the pixel is more than 0.5 px past the outer
    edge of the edge pixels (the README's rule, computed here), as eoloc.locate says (before: OK
    points for 27 725 of 10^6 such pixels)."""
    import numpy as np

    from eoloc import AzElGimbal, Camera, Pose, SensorModel
    from eoloc.result import Status

    sensor = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())
    rng = np.random.default_rng(46)
    u = rng.uniform(-60.0, 1084.0, 3000)
    v = rng.uniform(-60.0, 828.0, 3000)
    u[:8] = [-1.0, -1.0000001, 1024.0, 1024.0000001, 5.0, 5.0, 5.0, 5.0]  # on and just past each edge
    v[:8] = [5.0, 5.0, 5.0, 5.0, -1.0, -1.0001, 768.0, 768.1]
    outside = (u < -1.0) | (u > 1024.0) | (v < -1.0) | (v > 768.0)
    pose = Pose(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, (45.0, -60.0))
    array = eoloc.locate(sensor, pose, eoloc.AtHeight(100.0), np.c_[u, v]).status
    for backend in eoloc.available_backends():
        with eoloc.use_backend(backend):
            one = np.array([sensor.locate_one(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, 45.0, -60.0, a, b,
                                              rule=AtHeight(100.0))[4] for a, b in zip(u, v, strict=True)])
        assert np.array_equal(one == Status.OUT_OF_IMAGE, outside), backend
        assert np.array_equal(one, array), backend


def test_46_10_a_camera_within_a_micrometre_of_the_terrain_is_below_surface_on_both_backends():
    """Cameras 0 to 0.9 µm above the SRTM terrain (heights from scipy's bilinear interpolation of the
    DEM's posts, not eoloc's), or just under it: BELOW_SURFACE on every backend (before: OK at 0.1-0.5
    µm, and the backends disagreed on 1.2 % of the rays exactly on it); 1 cm above: never."""
    import numpy as np
    from scipy.interpolate import RegularGridInterpolator

    from eoloc import AzElGimbal, Camera, Pose, SensorModel, open_dem
    from eoloc.result import Status

    dem = open_dem(DEM)
    g = dem.grid
    lats = g.lat0 + g.dlat * np.arange(g.z.shape[0])
    lons = g.lon0 + g.dlon * np.arange(g.z.shape[1])
    order = np.argsort(lats)
    terrain = RegularGridInterpolator((lats[order], lons), g.z[order], method="linear")
    rng = np.random.default_rng(10)
    lat = rng.uniform(lats.min() + 0.05, lats.max() - 0.05, 400)
    lon = rng.uniform(lons.min() + 0.05, lons.max() - 0.05, 400)
    ground = terrain(np.c_[lat, lon])
    sensor = SensorModel(Camera.from_hfov(30.0, 640, 480), AzElGimbal())
    for offset, want_below in ((-1e-3, True), (-1e-9, True), (0.0, True), (1e-7, True), (5e-7, True), (9e-7, True),
                               (1e-2, False)):
        pose = Pose(lat, lon, ground + offset, rng.uniform(0, 360, 400), 0.0, 0.0, (0.0, -45.0))
        for backend in eoloc.available_backends():
            with eoloc.use_backend(backend):
                st = eoloc.locate_dem(sensor, pose, dem).status
            assert np.all((st == Status.BELOW_SURFACE) == want_below), (offset, backend, np.unique(st))


def test_46_10_rays_grazing_the_highest_post_over_a_void_are_called_alike_by_both_backends():
    """Near-horizontal rays whose lowest point over a void lies within micrometres of the highest
    post, above or below: every ray gets the same status on numpy and numba (before: DEM_VOID on
    numpy, NO_INTERSECTION on numba, just above the highest post); well under it: DEM_VOID."""
    import numpy as np

    from eoloc import AzElGimbal, Camera, Pose, SensorModel
    from eoloc.result import Status

    assert set(eoloc.available_backends()) == {"numba", "numpy"}  # (make test installs numba)
    spacing = 100.0 / 111_195.0
    z = np.full((60, 60), 100.0)
    z[30, 2] = 300.0  # the highest post, far west
    z[28:33, 20:26] = np.nan  # a void under the rays' path
    dem = eoloc.DEM.from_array(z, lat0=40.0, lon0=-105.0, dlat=spacing, dlon=spacing)
    sensor = SensorModel(Camera.from_hfov(1.0, 64, 64), AzElGimbal())
    rng = np.random.default_rng(11)
    n = 2000
    h = 300.0 + rng.uniform(-3e-5, 3e-5, n)  # at the band's top, flying west over the void
    pose = Pose(40.0 + 30.2 * spacing, -105.0 + 40 * spacing, h, 270.0, 0.0, 0.0,
                (rng.uniform(-0.2, 0.2, n), rng.uniform(-1e-6, 0.0, n)))
    got = {}
    for backend in eoloc.available_backends():
        with eoloc.use_backend(backend):
            got[backend] = eoloc.locate_dem(sensor, pose, dem).status
    a, b = got.values()
    assert np.array_equal(a, b), np.c_[h[a != b] - 300.0, a[a != b], b[a != b]][:5]
    low = Pose(40.0 + 30.2 * spacing, -105.0 + 40 * spacing, 250.0, 270.0, 0.0, 0.0, (0.0, -0.01))
    for backend in eoloc.available_backends():
        with eoloc.use_backend(backend):
            assert eoloc.locate_dem(sensor, low, dem).status == Status.DEM_VOID, backend


# -- item 3: live's memory and its stderr under a flood --------------------------------------------------


def _flood(rng, good: list[bytes], n: int):
    """``n`` hostile datagrams, cycling through: random bytes, a good packet with a flipped byte (bad
    checksum), a good packet whose time stamp is all ones (valid checksum), random "transport
    packets" (188-byte cells that start with 0x47)."""
    for k in range(n):
        kind = k % 4
        if kind == 0:
            yield "garbage", rng.bytes(int(rng.integers(1, 1400)))
        elif kind == 1:
            raw = bytearray(good[k % len(good)])
            raw[int(rng.integers(20, len(raw) - 4))] ^= 0xFF
            yield "checksum", bytes(raw)
        elif kind == 2:
            yield "time", _with_items(good[k % len(good)], lambda items: [(t, ALL_ONES if t == 2 else v)
                                                                          for t, v in items])
        else:
            cells = rng.bytes(188 * 7)
            yield "transport", b"".join(b"\x47" + cells[i * 188 + 1:(i + 1) * 188] for i in range(7))


def test_46_3_a_flood_of_bad_datagrams_keeps_memory_bounded_and_every_good_packet():
    """12 000 hostile datagrams through a live session, the flight's good packets among them: every
    good packet located, the faults counted by kind, memory flat after warm-up (before: ~170 bytes
    kept per bad datagram, forever), and the fault lines rate-limited: the first of each kind, then
    a count per kind and period (before: one stderr line per datagram)."""
    import tracemalloc

    import numpy as np

    from eoloc.live.session import LiveSession
    from eoloc.terrain import open_dem

    clock = [0.0]
    session = LiveSession("udp://flood", dem=open_dem(DEM))
    session.faults.clock = lambda: clock[0]
    good = [p for p in _packets() if decode_klv_bytes(p).packets]
    rng = np.random.default_rng(3)
    bad = list(_flood(rng, good, 12_000))
    lines, located, sent_good = [], 0, 0
    for k, (_, datagram) in enumerate(bad):
        if k % 50 == 0 and sent_good < len(good):  # the good packets among the first part of the flood
            located += sum(1 for u in session.feed(good[sent_good]) if u.platform is not None)
            sent_good += 1
        session.feed(datagram)
        clock[0] += 1e-4  # 10 000 datagrams a second
        lines += session.faults.due()
        if k == 2_000:  # the good packets are in: from here on what stays allocated is what the flood keeps
            tracemalloc.start()
    grown = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    lines += session.faults.flush()
    assert sent_good == len(good) == 39 and located == 39
    counts = session.faults.counts()
    assert counts["not KLV"] == 3_000 and counts["checksum"] == 3_000, counts
    # the all-ones time stamps: the 39 distinct packets kept with a note each, their copies dropped as duplicates
    assert counts["tag 2 field"] == 39 and session.counters.duplicates == 3_000 - 39, counts
    assert session.counters.packets == 39 + 39
    assert grown < 64 * 1024, grown  # bytes, over the 10 000 datagrams after the good packets
    # 1.2 s of flood: the first line of each kind, then at most one per kind every 5 s
    assert len(lines) <= 2 * len(counts), (len(lines), lines[:5])


# -- the mutated-KLV suite: valid checksums, hostile items -------------------------------------------------


def test_46_mutated_klv_never_raises_in_any_path_and_keeps_every_packet(tmp_path):
    """1 000 packets of the mountain flight with random item mutations and valid checksums
    (tests/helpers/klvfuzz.py; `bench/bench_hostile.py klv` runs 10^5): `read_klv`, the tables, `eoloc klv`
    and `eoloc batch` take them all without an exception, a live session the first 300; every packet
    is kept (its bad items left out with a note), and the good packets are located as before."""
    from klvfuzz import mutated_packets

    from eoloc.io.klv import read_klv
    from eoloc.live.session import LiveSession
    from eoloc.terrain import open_dem

    good = [p for p in _packets() if decode_klv_bytes(p).packets]
    bad = mutated_packets(good, 1_000, seed=46)
    path = tmp_path / "mutated.klv"
    path.write_bytes(b"".join(good + bad))
    stream = read_klv(path)
    assert len(stream.packets) == len(good) + len(bad)  # every packet kept, item by item
    tel = klv_telemetry(stream)
    vmti_detections(stream)
    assert len(tel) >= len(good)
    session = LiveSession("udp://mutated", dem=open_dem(DEM))
    located = sum(1 for raw in good for u in session.feed(raw) if u.platform is not None)
    assert located == len(good)
    for raw in bad[:300]:  # (each is located, footprint on the DEM and all: 300 say what 1 000 would)
        session.feed(raw)
    assert session.counters.packets + session.counters.duplicates == len(good) + 300
    r = CliRunner().invoke(main, ["klv", str(path), "--dem", str(DEM), "--out", str(tmp_path / "o")])
    assert r.exit_code == 0 and "Traceback" not in r.output and "internal error" not in r.output, r.output[-2000:]
    (tmp_path / "in").mkdir()
    path.rename(tmp_path / "in" / "mutated.klv")
    r = CliRunner().invoke(main, ["batch", str(tmp_path / "in"), "--out", str(tmp_path / "b"), "--dem", str(DEM)])
    assert ",done," in (tmp_path / "b" / "batch_status.csv").read_text(encoding="utf-8"), r.output[-2000:]


# -- hostile HTTP bodies -------------------------------------------------------------------------------


def _hostile_bodies(rng, n: int):
    """(content type, body) of ``n`` hostile requests: JSON observations with values of every wrong
    kind, broken JSON, deep nesting, random bytes, and Arrow streams truncated or with bytes
    changed (the compressed bomb has a test of its own)."""

    good = {"pose": S13_POSE, "stop": {"target_height_m": 100.0}, "pixels": [[512.0, 384.0]]}
    wrong = [True, None, "42", " 1e4 ", [], {}, -1e308, 1e308, 2**70, "NaN", "\u0000", [[1, 2]], {"$ref": "x"}]
    arrow = _arrow_stream(20)
    for k in range(n):
        kind = k % 8
        if kind < 3:
            doc = json.loads(json.dumps(good))
            where = [doc, doc["pose"], doc["stop"]][kind]
            where[rng.choice(sorted(where))] = wrong[int(rng.integers(len(wrong)))]
            yield "application/json", json.dumps(doc).encode()
        elif kind == 3:
            text = json.dumps(good)
            yield "application/json", text[:int(rng.integers(len(text)))].encode() + rng.bytes(3)
        elif kind == 4:
            yield "application/json", b'{"pose":' * 5000 + b"1" + b"}" * 5000  # deep nesting
        elif kind == 5:
            yield "application/json", rng.bytes(int(rng.integers(1, 5000)))
        elif kind == 6:
            cut = int(rng.integers(1, len(arrow)))
            yield "application/vnd.apache.arrow.stream", arrow[:cut] + rng.bytes(int(rng.integers(0, 64)))
        else:
            mutated = bytearray(arrow)
            for _ in range(int(rng.integers(1, 6))):
                mutated[int(rng.integers(len(mutated)))] = int(rng.integers(256))
            yield "application/vnd.apache.arrow.stream", bytes(mutated)


def test_46_hostile_http_bodies_get_4xx_never_5xx_and_no_traceback():
    """200 hostile bodies (seeded) on both routes: each answered 4xx with a message (or 200 where the
    mutation left a good request), never a 5xx;
    the server answers a good request after them and its log has no traceback."""
    import httpx
    import numpy as np
    from served import eoloc_serve, stop_and_log

    rng = np.random.default_rng(46)
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml")) as url:
        statuses = []
        with httpx.Client(base_url=url, timeout=30) as client:
            for ctype, body in _hostile_bodies(rng, 200):
                route = "/v1/locate/arrow" if "arrow" in ctype else "/v1/locate"
                r = client.post(route, content=body, headers={"content-type": ctype})
                statuses.append(r.status_code)
                assert r.status_code < 500, (r.status_code, r.text[:300], body[:200])
            ok = client.post("/v1/locate", json={"pose": S13_POSE, "stop": {"target_height_m": 100.0}})
            assert ok.status_code == 200 and ok.json()["fixes"][0]["status"] == "OK"
        log = stop_and_log(url)
    # (a mutation can leave a request that is still good: a pixel list of [[1, 2]], a changed float)
    assert set(statuses) <= {200, 400, 413, 415, 422} and statuses.count(422) > 150, sorted(set(statuses))
    assert "Traceback" not in log and "Exception in ASGI" not in log, log[-3000:]


def test_46_3_one_damaged_transport_packet_costs_its_own_packet_only(tmp_path):
    """The flight as MPEG-TS with one cell of the KLV PID damaged (its PES length, or its error flag):
    the file reader and a live session keep every other KLV packet (before: stanag4609's PES
    assembler stayed confused and the rest of the stream was lost; a file was refused whole)."""
    from eoloc.io.klv import read_klv
    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.live.session import LiveSession

    good = [p for p in _packets() if decode_klv_bytes(p).packets]
    ts = tmp_path / "flight.ts"
    write_klv_ts(ts, [[(raw, k / 2.0) for k, raw in enumerate(good)]])
    from stanag4609.transport.mpegts import parse_transport_packet

    cells = bytearray(ts.read_bytes())
    parsed = [parse_transport_packet(bytes(cells[k:k + 188]), offset=k) for k in range(0, len(cells), 188)]
    klv_pid = max({p.pid for p in parsed}, key=lambda pid: sum(q.pid == pid for q in parsed))  # the busiest PID
    heads = [p for p in parsed if p.pid == klv_pid and p.payload_unit_start]
    assert len(heads) == len(good)  # one PES per KLV packet
    pes = heads[5].offset + 188 - len(heads[5].payload)  # PES 5's header: its packet length (bytes 4-5) now 5,
    cells[pes + 4:pes + 6] = b"\x00\x05"  # which its transport packets overrun
    cells[heads[20].offset + 1] |= 0x80  # PES 20's first transport packet: the error flag set
    damaged = tmp_path / "damaged.ts"
    damaged.write_bytes(bytes(cells))
    stream = read_klv(damaged)
    assert len(stream.packets) == len(good) - 2, len(stream.packets)
    assert sum("MPEG-TS" in i.message for i in stream.issues) >= 2
    session = LiveSession("udp://ts")
    located = 0
    for j in range(0, len(cells), 7 * 188):
        located += sum(1 for u in session.feed(bytes(cells[j:j + 7 * 188])) if u.platform is not None)
    assert located == len(good) - 2


@pytest.mark.browser
def test_46_5_the_live_map_shows_hostile_names_as_text(tmp_path):
    """Platform designations, stream names, target ids and filter models that are markup or script,
    published to the live map (`eoloc live --map`'s server and page) and shown in headless Chromium:
    no script runs, on load or when every tooltip opens, and each tooltip reads the text sent."""
    from browser import chromium

    from eoloc.service.api import create_app
    from eoloc.service.livemap import LiveHub, MapServer

    hub = LiveHub()
    server = MapServer(create_app(hub=hub), "127.0.0.1", 0)
    url = server.start()

    class Update:  # a PacketUpdate's shape
        kind, stream, late, time_utc = "packet", "s", False, "2026-07-14T16:00:00Z"

        def __init__(self, i):
            self.index, self.key = i, f"stream {INJECTIONS[i % len(INJECTIONS)]}"

    def features(i):
        name = INJECTIONS[i % len(INJECTIONS)]
        lat, lon = 40.25 + 0.001 * i, -105.6
        return [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, 6000.0]},
                 "properties": {"what": "aircraft", "name": name, "h_m": 6000.0, "heading_deg": 10.0,
                                "time_utc": name}},
                {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat - 0.05, 3900.0]},
                 "properties": {"what": "target", "target_id": name, "cep50_m": 5.0, "ce90_m": 9.0}},
                {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat - 0.06, 3900.0]},
                 "properties": {"what": "estimate", "target_id": name, "model": name, "n_fixes": name,
                                "cep50_m": 3.0}}]

    d = chromium()
    try:
        d.get(url)
        deadline = time.monotonic() + 30
        while not d.execute_script("return window.eoloc && window.eoloc.connects === 1"):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        for i in range(len(INJECTIONS)):
            hub.publish(Update(i), features(i))
        while d.execute_script("return window.eoloc.packets") < len(INJECTIONS):
            assert time.monotonic() < deadline + 30
            time.sleep(0.05)
        tips = d.execute_script("""
            for (const el of document.querySelectorAll('path.eoloc-aircraft, path.eoloc-target, path.eoloc-estimate')) {
                el.dispatchEvent(new MouseEvent('mouseover', {bubbles: true}));
            }
            return [...document.querySelectorAll('.leaflet-tooltip')].map(t => t.textContent);""")
        pwned = d.execute_script("return window.__eoloc_pwned || null")
        errors = [e for e in d.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    finally:
        d.quit()
        server.close()
    assert pwned is None and errors == [], (pwned, errors)
    text = "\n".join(tips)
    for name in INJECTIONS:  # each name shown as the text it is (a target's id, a platform's name)
        assert f"target {name}" in text, name


@pytest.mark.browser
def test_46_5_the_accuracy_report_shows_hostile_flight_names_as_text(tmp_path):
    """`eoloc report` on observations whose flight names and GCP ids are markup and script, from a
    file whose own name is one: loaded in headless Chromium, no script runs and the names are text."""
    import csv

    from browser import page_state

    demo = MOUNTAIN.parent
    r = CliRunner().invoke(main, ["compensate", "simulate", "--config", str(demo / "camera.toml"), "--flights", "2",
                                  "--test-flights", "0", "--looks", "30", "--out", str(tmp_path / "cal")])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((tmp_path / "cal" / "train.csv").open(encoding="utf-8")))
    names = {f: INJECTIONS[k] for k, f in enumerate(sorted({r["flight"] for r in rows}))}
    for row in rows:
        row["flight"], row["gcp_id"] = names[row["flight"]], INJECTIONS[3]
    hostile = tmp_path / "<img src=x onerror=window.__eoloc_pwned=1>.csv"
    with hostile.open("w", encoding="utf-8", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    r = CliRunner().invoke(main, ["report", str(hostile), "--config", str(demo / "camera.toml"), "--dem",
                                  str(tmp_path / "cal" / "dem.tif"), "--vertical", "ellipsoid", "--out",
                                  str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    state, errors = page_state(tmp_path / "out" / "report.html",
                               "return {pwned: window.__eoloc_pwned || null, text: document.body.innerText,"
                               " h1: document.querySelector('h1').textContent};")
    assert state["pwned"] is None and errors == [], (state["pwned"], errors)
    assert state["h1"] == f"eoloc accuracy report: {hostile.name}"
    assert all(n in state["text"] for n in names.values()), state["text"][:2000]
