"""TAK as TAK users run it (issue 51): CoT over TLS with client certificates through a real TAK
server (taky, its CA, server certificate and client connection data packages made by its own
`takyctl`; other certificates made by the test as an admin would), certificate problems as
one-line errors, TAK protocol 1 (negotiated on a stream, mesh on UDP) decoded by a decoder
compiled from TAK's published message definitions, and the ``__video`` link with its video data
package parsed as ATAK and TAK servers parse them. (FreeTAKServer, the plain-TCP test's server,
cannot carry a stream on its TLS port: see tests/helpers/tak_server.py.)"""

from __future__ import annotations

import csv
import importlib
import socket
import ssl
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
import zipfile
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.hazmat.primitives.serialization import pkcs12
from cryptography.x509.oid import NameOID
from livecmd import summary_of, wait_until
from ports import free_udp_port
from tak_server import TakClient, taky_client, taky_server
from where import DATA

import eoloc
from eoloc.io.klv.reader import decode_klv_bytes, split_klv

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT, DEM, CONFIG = MOUNTAIN / "flight.klv", MOUNTAIN / "longs_peak_srtmgl3.tif", MOUNTAIN / "klv.toml"
EOLOC = str(Path(sys.executable).parent / "eoloc")
PROTO = DATA / "tak" / "tak_reference.proto"


# --- certificates, made as a TAK server's admin makes them --------------------------------------

def make_ca(cn: str):
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])
    now = datetime.now(UTC)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - timedelta(days=1))
            .not_valid_after(now + timedelta(days=30))
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    return cert, key


def make_client(ca_cert, ca_key, cn: str, not_before=None, not_after=None):
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    now = datetime.now(UTC)
    cert = (x509.CertificateBuilder().subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)]))
            .issuer_name(ca_cert.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(not_before or now - timedelta(days=1))
            .not_valid_after(not_after or now + timedelta(days=30))
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(ca_key, hashes.SHA256()))
    return cert, key


def p12(cert, key, cas, password: str, name: bytes = b"eoloc") -> bytes:
    return pkcs12.serialize_key_and_certificates(name, key, cert, cas,
                                                 serialization.BestAvailableEncryption(password.encode()))


def pem(cert) -> bytes:
    return cert.public_bytes(serialization.Encoding.PEM)


TAKY_PASSWORD = "atakatak"  # what takyctl protects its .p12 files with (TAK Server's default too)


@pytest.fixture(scope="module")
def tak(tmp_path_factory):
    """taky on a TLS port requiring client certificates; its CA loaded for the tests."""
    folder = tmp_path_factory.mktemp("taky")
    with taky_server(folder) as server:
        ssl_dir = server["site"] / "ssl"
        ca_cert = x509.load_pem_x509_certificate((ssl_dir / "ca.crt").read_bytes())
        ca_key = serialization.load_pem_private_key((ssl_dir / "ca.key").read_bytes(), None)
        yield {**server, "ca": (ca_cert, ca_key), "ca_file": ssl_dir / "ca.crt"}


def package_p12(package: Path, tmp_path: Path) -> Path:
    """The client .p12 of a connection package (the one that holds a key), as a file."""
    with zipfile.ZipFile(package) as zf:
        for name in zf.namelist():
            if name.endswith(".p12"):
                key, _, _ = pkcs12.load_key_and_certificates(zf.read(name), TAKY_PASSWORD.encode())
                if key is not None:
                    (tmp_path / "client.p12").write_bytes(zf.read(name))
                    return tmp_path / "client.p12"
    raise AssertionError(f"{package}: no client .p12")


def listener(tak, tmp_path) -> TakClient:
    """A TAK client on the server's TLS port with a package of its own from the server's tool, its
    context built by the standard library (the .p12 opened by cryptography)."""
    p12_file = package_p12(taky_client(tak["site"], "listener"), tmp_path)
    key, cert, _ = pkcs12.load_key_and_certificates(p12_file.read_bytes(), TAKY_PASSWORD.encode())
    (tmp_path / "listener.pem").write_bytes(pem(cert) + key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname = False
    ctx.load_verify_locations(cadata=pem(tak["ca"][0]).decode())
    ctx.load_cert_chain(tmp_path / "listener.pem")
    client = TakClient(tak["port"], tls=ctx)
    client.wait_routed(tak["port"], tls=ctx)  # the server relays to it before the stream starts
    return client


def live_paced(args: list[str], timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    """`eoloc live` on a UDP port, the flight's datagrams sent to it 50 ms apart (a TAK server
    takes a stream at a stream's pace: FreeTAKServer drops much of a burst of hundreds of events
    written at once); it stops by itself after the flight's last good packet (--packets)."""
    port = free_udp_port()
    packets = split_klv(FLIGHT.read_bytes())
    good = len(decode_klv_bytes(FLIGHT.read_bytes()).packets)
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{port}", "--packets", str(good), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    head = []
    while "listening on" not in (line := proc.stderr.readline()):
        head.append(line)
        assert line or proc.poll() is None, "".join(head)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for raw, _ in packets:
            tx.sendto(raw, ("127.0.0.1", port))
            time.sleep(0.05)
    out, err = proc.communicate(timeout=timeout_s)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, "".join(head) + line + err)


def klv_fixes(tmp_path) -> dict[str, list[tuple[float, float]]]:
    """`eoloc klv`'s fixes of the flight (the reference the TAK events must equal), by target id."""
    out = tmp_path / "klv"
    subprocess.run([EOLOC, "klv", str(FLIGHT), "--dem", str(DEM), "--config", str(CONFIG), "--out", str(out),
                    "--format", "csv"], check=True, capture_output=True)
    fixes: dict[str, list[tuple[float, float]]] = {}
    with open(out / "fixes.csv") as f:
        for row in csv.DictReader(f):
            if row["status"] == "OK":
                fixes.setdefault(row["target_id"], []).append((float(row["lat_deg"]), float(row["lon_deg"])))
    return fixes


def test_51_tls_through_a_tak_server_with_its_connection_package(tak, tmp_path):
    """`eoloc live --tak-package` with the package the server's admin tool made, on its TLS port
    (asking for TAK protocol 1, which this server does not offer: XML kept): every event reaches a
    TLS client of the server, each target where `eoloc klv` puts it to the precision the server
    relays (taky writes 6 decimals: 5e-7 degrees, 0.06 m; eoloc's own values are checked to 1e-8
    degrees where nothing rewrites them, in the TAK protocol test below and in test_live_tak)."""
    client = listener(tak, tmp_path)
    package = taky_client(tak["site"], "eoloc-desk")
    r = live_paced(["--dem", str(DEM), "--config", str(CONFIG), "--tak-package", str(package), "--tak-protocol", "1"])
    log = r.stdout + r.stderr
    assert r.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log)
    sent = summary["cot"][0]
    assert sent["url"] == f"tls://127.0.0.1:{tak['port']}" and sent["tak_protocol"] == "xml", sent
    assert sent["sent"] == summary["cot_events"] > 100 and sent["connects"] == 1 and sent["lost"] == 0
    assert "offers no TAK protocol 1: XML kept" in log
    ours = lambda evs: [e for e in evs if e.get("uid", "").startswith("eoloc-")  # noqa: E731
                        and e.get("type") != "a-f-G-E-S"]  # eoloc's own presence, sent first
    client.wait_for(lambda evs: len(ours(evs)) >= summary["cot_events"], 120)
    client.close()
    relayed = ours(client.events)
    assert len(relayed) == summary["cot_events"]
    assert next(e.get("type") for e in client.events if e.get("uid", "").startswith("eoloc-")) == "a-f-G-E-S"
    reference = klv_fixes(tmp_path)
    targets = [e for e in relayed if e.get("type") == "a-u-G"]
    assert len(targets) == sum(map(len, reference.values())) == summary["fixes_ok"]
    for ev in targets:
        pt = ev.find("point")
        lat, lon = float(pt.get("lat")), float(pt.get("lon"))
        candidates = reference[ev.get("uid").rsplit("-", 1)[1]]
        k = min(range(len(candidates)), key=lambda j: abs(candidates[j][0] - lat) + abs(candidates[j][1] - lon))
        lat_k, lon_k = candidates.pop(k)  # each fix matched once
        assert abs(lat - lat_k) <= 5e-7 + 1e-8 and abs(lon - lon_k) <= 5e-7 + 1e-8


@pytest.mark.parametrize("case", ["good", "wrong password", "expired", "client from another CA",
                                  "server not from the CA given"])
def test_51_certificates_good_and_bad(tak, tmp_path, case):
    """--tak-cert with a client .p12 the server's tool made and --tak-ca its CA works; a wrong
    password, an expired certificate, a certificate the server's CA did not sign and a --tak-ca
    that did not sign the server each end the run with one line naming the problem and the fix,
    exit 2, no traceback."""
    client_p12 = package_p12(taky_client(tak["site"], f"desk-{abs(hash(case)) % 10**6}"), tmp_path)
    args = ["--tak-cert", str(client_p12), "--tak-cert-password", TAKY_PASSWORD, "--tak-ca", str(tak["ca_file"])]
    expect = None
    if case == "wrong password":
        args[3], expect = "not-the-password", "wrong password (--tak-cert-password)"
    elif case == "expired":
        cert, key = make_client(*tak["ca"], "old-desk", datetime(2020, 1, 1, tzinfo=UTC),
                                datetime(2021, 1, 1, tzinfo=UTC))
        (tmp_path / "old.p12").write_bytes(p12(cert, key, [tak["ca"][0]], "pw"))
        args, expect = ["--tak-cert", str(tmp_path / "old.p12"), "--tak-cert-password", "pw"], \
            "expired on 2021-01-01"
    elif case == "client from another CA":
        other = make_ca("not the server's CA")
        cert, key = make_client(*other, "stranger")
        (tmp_path / "stranger.p12").write_bytes(p12(cert, key, [], "pw"))
        args = ["--tak-cert", str(tmp_path / "stranger.p12"), "--tak-cert-password", "pw", "--tak-ca",
                str(tak["ca_file"])]
        expect = "the server refused eoloc's client certificate"
    elif case == "server not from the CA given":
        (tmp_path / "wrong-ca.pem").write_bytes(pem(make_ca("some other CA")[0]))
        args[-1] = str(tmp_path / "wrong-ca.pem")
        expect = "the server's certificate cannot be trusted"
    r = subprocess.run([EOLOC, "live", str(FLIGHT), "--packets", "10", "--cot", f"tls://127.0.0.1:{tak['port']}",
                        *args], capture_output=True, text=True, timeout=120)
    log = r.stdout + r.stderr
    assert "Traceback" not in log, log
    if expect is None:
        assert r.returncode == 0, log
        sent = summary_of(log)["cot"][0]
        assert sent["sent"] > 10 and sent["connects"] == 1 and sent["lost"] == 0, log
        return
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert r.returncode == 2 and len(errors) == 1 and expect in errors[0], log
    assert r.stderr.rstrip().splitlines()[-1] == errors[0]  # the last word, one line


# --- TAK protocol 1 ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tak_pb2(tmp_path_factory):
    """TAK's message definitions compiled by protoc (grpcio-tools): the independent decoder."""
    from grpc_tools import protoc

    out = tmp_path_factory.mktemp("proto")
    assert protoc.main(["protoc", f"-I{PROTO.parent}", f"--python_out={out}", PROTO.name]) == 0
    sys.path.insert(0, str(out))
    try:
        return importlib.import_module("tak_reference_pb2")
    finally:
        sys.path.remove(str(out))


def varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b = data[i]
        value |= (b & 0x7F) << shift
        i += 1
        if not b & 0x80:
            return value, i
        shift += 7


class NegotiatingServer:
    """A TAK server's side of a stream (ATAK's protocol.txt): offers version 1 on connect, answers
    the client's request, then reads TAK protocol 1 frames (0xbf, varint length, TakMessage)."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))  # the port the OS gives: no race
        self.port = self.listener.getsockname()[1]
        self.xml_before: list[bytes] = []
        self.frames: list[bytes] = []
        self.request = None
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        conn, _ = self.listener.accept()
        now = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.000Z")
        conn.sendall(f"<?xml version='1.0' encoding='UTF-8' standalone='yes'?><event version='2.0' uid='protouid' "
                     f"type='t-x-takp-v' time='{now}' start='{now}' stale='{now}' how='m-g'><point lat='0.0' "
                     "lon='0.0' hae='0.0' ce='999999' le='999999'/><detail><TakControl><TakProtocolSupport "
                     "version='1'/></TakControl></detail></event>".encode())
        buf = b""
        while self.request is None:
            data = conn.recv(65536)
            if not data:
                return
            buf += data
            while (end := buf.find(b"</event>")) >= 0:
                doc, buf = buf[:end + 8], buf[end + 8:]
                ev = ET.fromstring(doc[doc.find(b"<event"):])
                if ev.get("type") == "t-x-takp-q":
                    self.request = ev
                    break
                self.xml_before.append(doc)
        conn.sendall(f"<?xml version='1.0'?><event version='2.0' uid='protouid' type='t-x-takp-r' time='{now}' "
                     f"start='{now}' stale='{now}' how='m-g'><point lat='0.0' lon='0.0' hae='0.0' ce='999999' "
                     "le='999999'/><detail><TakControl><TakResponse status='true'/></TakControl></detail>"
                     "</event>".encode())
        while data := conn.recv(65536):
            buf += data
            while buf:
                assert buf[0] == 0xBF, buf[:20]
                n, i = varint(buf, 1)
                if len(buf) < i + n:
                    break
                self.frames.append(buf[i:i + n])
                buf = buf[i + n:]


class UdpSink:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.5)
        self.port = self.sock.getsockname()[1]
        self.datagrams: list[bytes] = []
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while self.running:
            try:
                self.datagrams.append(self.sock.recv(65536))
            except TimeoutError:
                continue

    def stop(self, n: int) -> list[bytes]:
        """Every datagram, once the ``n`` the sender counted are in (on loopback none is lost)."""
        wait_until(lambda: len(self.datagrams) >= n, f"{n} datagrams")
        self.running = False
        self.thread.join()
        self.sock.close()
        return self.datagrams


def ms(text: str) -> int:
    t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    return (t - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(milliseconds=1)


def same_event(msg, xml_event: ET.Element, check_times: bool = False) -> None:
    """A decoded TakMessage equals an XML event field by field (times as the XML's own offsets)."""
    e = msg.cotEvent
    assert (e.type, e.uid, e.how) == (xml_event.get("type"), xml_event.get("uid"), xml_event.get("how"))
    pt = xml_event.find("point")
    for name in ("lat", "lon", "hae", "ce", "le"):
        assert getattr(e, name) == float(pt.get(name)), name
    assert e.startTime == e.sendTime and e.staleTime - e.sendTime == ms(xml_event.get("stale")) - ms(
        xml_event.get("time"))
    if check_times:
        assert e.sendTime == ms(xml_event.get("time"))
    detail = xml_event.find("detail")
    typed = {"contact", "__group", "takv", "track", "status", "precisionlocation"}
    contact = detail.find("contact")
    assert e.detail.contact.callsign == (contact.get("callsign") if contact is not None else "")
    track = detail.find("track")
    if track is not None and track.get("course") is not None:
        assert e.detail.track.course == float(track.get("course"))
    rest = ET.fromstring(f"<detail>{e.detail.xmlDetail}</detail>")
    assert [c.tag for c in rest] == [c.tag for c in detail if c.tag not in typed]
    for got, want in zip(rest, [c for c in detail if c.tag not in typed], strict=True):
        assert got.attrib == want.attrib and (got.text or "") == (want.text or "")


def test_51_tak_protocol_1_negotiated_and_meshed_equals_the_xml(tak_pb2, tmp_path):
    """--tak-protocol 1: on a stream whose server offers version 1, the request, the answer, then
    protobuf frames; on UDP mesh datagrams. Decoded by TAK's own definitions compiled here, every
    message equals the XML event eoloc sends without it, field by field, in the same order."""
    server, mesh, reference = NegotiatingServer(), UdpSink(), UdpSink()
    common = [EOLOC, "live", str(FLIGHT), "--dem", str(DEM), "--config", str(CONFIG)]
    r1 = subprocess.run([*common, "--tak-protocol", "1", "--cot", f"udp://127.0.0.1:{mesh.port}", "--cot",
                         f"tcp://127.0.0.1:{server.port}"], capture_output=True, text=True, timeout=120)
    r0 = subprocess.run([*common, "--cot", f"udp://127.0.0.1:{reference.port}"], capture_output=True, text=True,
                        timeout=120)
    assert r1.returncode == r0.returncode == 0, r1.stderr + r0.stderr
    summary = summary_of(r1.stderr)
    datagrams = mesh.stop(summary["cot"][0]["sent"])
    xml_events = [ET.fromstring(d[d.find(b"<event"):]) for d in reference.stop(summary_of(r0.stderr)["cot"][0]["sent"])]
    assert summary["cot"][1]["tak_protocol"] == "1" and "TAK protocol 1 (protobuf) agreed" in r1.stderr
    assert server.request is not None and server.request.find("detail/TakControl/TakRequest").get("version") == "1"
    assert [ET.fromstring(d[d.find(b"<event"):]).get("type") for d in server.xml_before] == ["a-f-G-E-S"]  # hello
    wait_until(lambda: len(server.frames) >= summary["cot_events"], "the server's protobuf frames")
    assert len(datagrams) == len(server.frames) == len(xml_events) == summary["cot_events"] > 100
    for datagram, frame, want in zip(datagrams, server.frames, xml_events, strict=True):
        assert datagram[:3] == b"\xbf\x01\xbf"
        m, s = tak_pb2.TakMessage(), tak_pb2.TakMessage()
        m.ParseFromString(datagram[3:])
        s.ParseFromString(frame)
        same_event(m, want)
        same_event(s, want)
        assert abs(m.cotEvent.sendTime - s.cotEvent.sendTime) < 60_000  # the same run's clock


def test_51_tak_protocol_1_times_are_exact_milliseconds(tak_pb2):
    """The message times are the XML's to the millisecond (200 times, every millisecond digit)."""
    from eoloc.io.cot import event_xml
    from eoloc.live.takwire import mesh

    for k in range(200):
        t = datetime(2026, 11, 26, 22, 0, 0, tzinfo=UTC) + timedelta(milliseconds=7 * k + 1)
        ev = event_xml(uid=f"t{k}", cot_type="a-u-G", how="m-i", time=t, stale=t + timedelta(seconds=10), lat=1.0,
                       lon=2.0, hae=3.0)
        m = tak_pb2.TakMessage()
        m.ParseFromString(mesh(ev)[3:])
        same_event(m, ET.fromstring(ev[ev.find(b"<event"):]), check_times=True)


# --- the video ------------------------------------------------------------------------------------

FEED_FIELDS = ("protocol", "alias", "uid", "address", "port", "roverPort", "ignoreEmbeddedKLV",
               "preferredMacAddress", "path", "buffer", "timeout", "rtspReliable")  # what TAK servers read


def test_51_video_link_and_video_package(tmp_path):
    """--video-url: the aircraft's CoT carries <__video> with ATAK's ConnectionEntry of the URL;
    --video-package: a data package whose manifest lists what the zip holds and whose feed has every
    field a TAK server's video manager reads (FreeTAKServer's /Marti/vcm parser's list)."""
    sink = UdpSink()
    url = "rtsp://10.1.2.3:8554/uav/1?tcp"
    r = subprocess.run([EOLOC, "live", str(FLIGHT), "--packets", "5", "--cot", f"udp://127.0.0.1:{sink.port}",
                        "--video-url", url, "--video-package", str(tmp_path / "video.zip")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    events = [ET.fromstring(d[d.find(b"<event"):]) for d in sink.stop(summary_of(r.stderr)["cot"][0]["sent"])]
    platforms = [e for e in events if e.get("type") == "a-f-A-M-F-Q"]
    assert len(platforms) == 5
    for e in platforms:
        video = e.find("detail/__video")
        entry = video.find("ConnectionEntry")
        assert video.get("url") == url and entry.get("uid") == video.get("uid")
        assert (entry.get("protocol"), entry.get("address"), entry.get("port"), entry.get("path")) == \
            ("rtsp", "10.1.2.3", "8554", "/uav/1?tcp")
        assert entry.get("alias") == e.find("detail/contact").get("callsign")
    with zipfile.ZipFile(tmp_path / "video.zip") as zf:
        manifest = ET.fromstring(zf.read("MANIFEST/manifest.xml"))
        entries = [c.get("zipEntry") for c in manifest.iter("Content")]
        assert manifest.get("version") == "2" and entries and set(entries) <= set(zf.namelist())
        feeds = ET.fromstring(zf.read(entries[0]))
    assert feeds.tag == "videoConnections"
    feed = feeds.find("feed")
    values = {k: feed.find(k).text for k in FEED_FIELDS}
    assert (values["protocol"], values["address"], values["port"], values["path"]) == \
        ("rtsp", "10.1.2.3", "8554", "/uav/1?tcp")
    assert values["alias"] and values["uid"] == platforms[0].find("detail/__video").get("uid")  # one feed in ATAK


# --- without a server: the package's variants, the negotiation refused, the URL rules -----------

def _package(path: Path, pref_entries: str, files: dict[str, bytes]) -> Path:
    pref = ("<?xml version='1.0' standalone='yes'?><preferences><preference version=\"1\" name=\"cot_streams\">"
            f"{pref_entries}</preference></preferences>")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("MANIFEST/manifest.xml", "<MissionPackageManifest version=\"2\"/>")
        zf.writestr("conn/server.pref", pref)
        for name, data in files.items():
            zf.writestr(name, data)
    return path


def _entry(key: str, value: str) -> str:
    return f'<entry key="{key}" class="class java.lang.String">{value}</entry>'


def test_51_connection_package_variants_and_mistakes(tmp_path):
    """Per-stream keys (caLocation0 …, as some servers write them) read like the global ones; a
    package without a server, with a certificate the .pref names but the zip lacks, or a file that
    is no zip: one message naming the file and what is missing."""
    from eoloc.errors import InputError
    from eoloc.live.tls import read_connection_package

    ca = make_ca("test CA")
    cert, key = make_client(*ca, "desk")
    truststore = pkcs12.serialize_key_and_certificates(b"ca", None, None, [ca[0]],
                                                       serialization.BestAvailableEncryption(b"public"))
    per_stream = _package(tmp_path / "a.zip", _entry("connectString0", "tak.example:8089:ssl")
                          + _entry("caLocation0", "cert/trust.p12") + _entry("caPassword0", "public")
                          + _entry("certificateLocation0", "cert/desk.p12") + _entry("clientPassword0", "pw"),
                          {"certs/trust.p12": truststore, "certs/desk.p12": p12(cert, key, [], "pw")})
    got = read_connection_package(per_stream)
    assert got.url == "tls://tak.example:8089"
    assert got.credentials.cert == cert and got.credentials.cas == [ca[0]]
    with pytest.raises(InputError, match=r"b\.zip: no \.pref file with a server"):
        read_connection_package(_package(tmp_path / "b.zip", _entry("description0", "x"), {}))
    with pytest.raises(InputError, match=r"c\.zip: the client certificate 'cert/missing\.p12' .* not in the package"):
        read_connection_package(_package(tmp_path / "c.zip", _entry("connectString0", "h:8089:ssl")
                                         + _entry("certificateLocation0", "cert/missing.p12"), {}))
    (tmp_path / "d.zip").write_bytes(b"not a zip")
    with pytest.raises(InputError, match=r"d\.zip: not a TAK data package"):
        read_connection_package(tmp_path / "d.zip")
    with pytest.raises(InputError, match="holds no CA certificate"):  # no truststore and none in the .p12
        read_connection_package(_package(tmp_path / "e.zip", _entry("connectString0", "h:8089:ssl")
                                         + _entry("certificateLocation0", "desk.p12") + _entry("clientPassword0", "pw"),
                                         {"desk.p12": p12(cert, key, [], "pw")}))


def test_51_negotiation_refused_or_other_versions_keep_xml():
    """A server that refuses the request, or offers only other versions, keeps the stream in XML;
    what follows the server's agreement is not parsed as XML."""
    from eoloc.live.takwire import Negotiation

    def event(kind: str, inner: str) -> bytes:
        return (f"<event version='2.0' uid='s' type='{kind}' time='2026-01-01T00:00:00Z' start='2026-01-01T00:00:00Z'"
                f" stale='2026-01-01T00:01:00Z' how='m-g'><point lat='0' lon='0' hae='0' ce='1' le='1'/><detail>"
                f"<TakControl>{inner}</TakControl></detail></event>").encode()

    n = Negotiation("me")
    assert n.feed(event("t-x-takp-v", "<TakProtocolSupport version='2'/>")) == b"" and n.state == "xml"
    assert "not 1" in n.note
    n = Negotiation("me")
    request = n.feed(event("t-x-takp-v", "<TakProtocolSupport version='1'/>"))
    assert n.state == "asked" and ET.fromstring(request[request.find(b"<event"):]).get("type") == "t-x-takp-q"
    n.feed(event("t-x-takp-r", "<TakResponse status='false'/>"))
    assert n.state == "xml" and "refused" in n.note
    n = Negotiation("me")
    offer, answer = event("t-x-takp-v", "<TakProtocolSupport version='1'/>"), event(
        "t-x-takp-r", "<TakResponse status='true'/>")
    n.feed(offer[:40])  # split anywhere
    n.feed(offer[40:] + answer[:10])
    n.feed(answer[10:] + b"\xbf\x05hello")
    assert n.state == "proto" and n.buffer == b""  # what follows the answer is protobuf, not kept as XML


def test_51_tls_urls_need_a_certificate():
    from eoloc.errors import InputError
    from eoloc.live.senders import cot_sender

    with pytest.raises(InputError, match=r"--tak-cert CLIENT\.p12"):
        cot_sender("tls://127.0.0.1:8089")
    r = subprocess.run([EOLOC, "live", str(FLIGHT), "--cot", "udp://127.0.0.1:9", "--tak-cert", "x.p12"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "give --cot tls://HOST:PORT" in r.stderr and "Traceback" not in r.stderr


def test_51_a_silent_tls_server_is_not_a_dead_one(tmp_path):
    """A TLS 1.3 server sends session tickets after the handshake and then nothing: the socket is
    readable with no data for eoloc. The sender must not wait on it (it did, 5 s per connection,
    then counted the connection as failed and retried for ever): connected once, every event
    delivered, in well under a second after the handshake."""
    from eoloc.live.senders import TcpSender
    from eoloc.live.tls import credentials

    ca = make_ca("loopback CA")
    server_cert, server_key = make_client(*ca, "server")
    client_cert, client_key = make_client(*ca, "eoloc")
    (tmp_path / "server.pem").write_bytes(pem(server_cert) + server_key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_3
    ctx.verify_mode = ssl.CERT_REQUIRED
    ctx.load_verify_locations(cadata=pem(ca[0]).decode())
    ctx.load_cert_chain(tmp_path / "server.pem")
    listener_sock = socket.create_server(("127.0.0.1", 0))
    port, received = listener_sock.getsockname()[1], []

    def serve() -> None:
        conn, _ = listener_sock.accept()
        with ctx.wrap_socket(conn, server_side=True) as tls:  # sends its tickets, then only reads
            while data := tls.recv(65536):
                received.append(data)

    threading.Thread(target=serve, daemon=True).start()
    creds = credentials(p12(client_cert, client_key, [ca[0]], "pw"), "eoloc.p12", "pw")
    t0 = time.monotonic()
    sender = TcpSender(f"tls://127.0.0.1:{port}", tls=creds)
    for k in range(20):
        sender.send(b"<event uid='e%d'/>" % k)
    deadline = time.monotonic() + 10
    while sender.sent < 20 and time.monotonic() < deadline:
        time.sleep(0.02)
    elapsed = time.monotonic() - t0
    sender.close()
    assert sender.sent == 20 and sender.connects == 1 and sender.fatal is None, sender.summary()
    assert elapsed < 3.0  # the 1 s probe for a refusal, not a 5 s wait on the tickets
    wait_until(lambda: b"".join(received).count(b"<event") >= 20, "the 20 events at the server")
    assert b"".join(received).count(b"<event") == 20


def test_51_a_plain_port_given_as_tls_is_named(tmp_path):
    """--cot tls:// pointed at a plain TCP port (8087 instead of 8089): one line saying the server
    does not speak TLS there, exit 2, not a retry loop."""
    ca = make_ca("test CA")
    cert, key = make_client(*ca, "desk")
    (tmp_path / "desk.p12").write_bytes(p12(cert, key, [ca[0]], "pw"))
    plain = socket.create_server(("127.0.0.1", 0))
    port = plain.getsockname()[1]

    def answer() -> None:  # a plain CoT port: whatever comes, it answers with XML
        conn, _ = plain.accept()
        conn.recv(4096)
        conn.sendall(b"<?xml version='1.0'?><event version='2.0' uid='x' type='t-x-c-t'/>" * 20)
        time.sleep(2)
        conn.close()

    threading.Thread(target=answer, daemon=True).start()
    r = subprocess.run([EOLOC, "live", str(FLIGHT), "--packets", "5", "--cot", f"tls://127.0.0.1:{port}", "--tak-cert",
                        str(tmp_path / "desk.p12"), "--tak-cert-password", "pw"], capture_output=True, text=True,
                       timeout=120)
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert r.returncode == 2 and len(errors) == 1 and "does not speak TLS on this port" in errors[0], r.stderr
    assert "Traceback" not in r.stderr
