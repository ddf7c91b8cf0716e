"""A real TAK server on loopback for the CoT tests: FreeTAKServer (PyPI) from the venv `make tak`
builds, configured by files this helper writes (ports, a persistence folder of its own, its
certificates: the CA, server and client certificates FreeTAKServer makes on its first start, in
that folder), and a TAK client that connects to it as ATAK does (announces itself, then reads
what the server relays), on its plain port or, with a TLS context, on its TLS port."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import ssl
import subprocess
import threading
import time
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta
from pathlib import Path

from ports import free_tcp_port

ROOT = Path(__file__).resolve().parents[2]
TAK_PYTHON = ROOT / ".venv-tak" / "bin" / "python"


CERT_PASSWORD = "eoloc-test-secret"  # the password of the .p12 files FreeTAKServer makes here


@contextlib.contextmanager
def freetakserver(folder: Path, timeout_s: float = 120.0):
    """Run FreeTAKServer until the block ends; yields its plain CoT port (TCP, loopback)."""
    with freetakserver_ports(folder, timeout_s) as ports:
        yield ports["cot"]


@contextlib.contextmanager
def freetakserver_ports(folder: Path, timeout_s: float = 120.0):
    """Run FreeTAKServer until the block ends; yields {"cot": plain port, "ssl": TLS port, "certs":
    its certificate folder (ca.pem, ca.key, server.pem, Client.p12 with CERT_PASSWORD)}."""
    assert TAK_PYTHON.exists(), "the TAK server test needs FreeTAKServer: `make tak` (part of `make test`) installs it"
    p = folder / "fts"
    for sub in ("certs", "Logs", "dp", "ExCheck/template", "ExCheck/checklist"):
        (p / sub).mkdir(parents=True, exist_ok=True)
    (p / "FTSDataBase.db").touch()
    cot, ssl_cot, dp, ssl_dp, api, fed = (free_tcp_port() for _ in range(6))
    (folder / "FTSConfig.yaml").write_text(f"""System:
  FTS_CONNECTION_MESSAGE: eoloc test server
Addresses:
  FTS_COT_PORT: {cot}
  FTS_SSLCOT_PORT: {ssl_cot}
  FTS_DP_ADDRESS: 127.0.0.1
  FTS_USER_ADDRESS: 127.0.0.1
  FTS_API_PORT: {api}
  FTS_FED_PORT: {fed}
  FTS_API_ADDRESS: 127.0.0.1
Filesystem:
  FTS_COT_TO_DB: True
  FTS_PERSISTENCE_PATH: {p}
  FTS_DB_PATH: {p}/FTSDataBase.db
  FTS_CERTS_PATH: {p}/certs
  FTS_LOGFILE_PATH: {p}/Logs
  FTS_DATAPACKAGE_PATH: {p}/dp
  FTS_EXCHECK_PATH: {p}/ExCheck
  FTS_EXCHECK_TEMPLATE_PATH: {p}/ExCheck/template
  FTS_EXCHECK_CHECKLIST_PATH: {p}/ExCheck/checklist
""")
    certs = p / "certs"  # by environment variables: FreeTAKServer's YAML wants every path to exist already
    env = {**os.environ, "FTS_FIRST_START": "false", "FTS_CONFIG_PATH": str(folder / "FTSConfig.yaml"),
           "FTS_SERVER_KEYDIR": f"{certs}/server.key", "FTS_SERVER_PEMDIR": f"{certs}/server.pem",
           "FTS_TESTCLIENT_PEMDIR": f"{certs}/Client.pem", "FTS_TESTCLIENT_KEYDIR": f"{certs}/Client.key",
           "FTS_UNENCRYPTED_KEYDIR": f"{certs}/server.key.unencrypted", "FTS_SERVER_P12DIR": f"{certs}/server.p12",
           "FTS_CADIR": f"{certs}/ca.pem", "FTS_CAKEYDIR": f"{certs}/ca.key",
           "FTS_FEDERATION_CERTDIR": f"{certs}/server.pem", "FTS_FEDERATION_KEYDIR": f"{certs}/server.key",
           "FTS_CLIENT_CERT_PASSWORD": CERT_PASSWORD, "FTS_CRLDIR": f"{certs}/FTS_CRL.json"}
    log = open(folder / "fts.log", "w")
    proc = subprocess.Popen([str(TAK_PYTHON), "-m", "FreeTAKServer.controllers.services.FTS", "-AutoStart", "True",
                             "-CoTIP", "127.0.0.1", "-CoTPort", str(cot), "-SSLCoTPort", str(ssl_cot),
                             "-DataPackageIP", "127.0.0.1", "-DataPackagePort", str(dp), "-SSLDataPackagePort",
                             str(ssl_dp), "-RestAPIIP", "127.0.0.1", "-RestAPIPort", str(api)],
                            cwd=folder, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + timeout_s
        for port in (cot, ssl_cot):
            while True:
                assert proc.poll() is None, (folder / "fts.log").read_text()[-3000:]
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    break
                except OSError:
                    assert time.monotonic() < deadline, (folder / "fts.log").read_text()[-3000:]
                    time.sleep(0.5)
        yield {"cot": cot, "ssl": ssl_cot, "certs": certs}
    finally:
        stop_group(proc)
        log.close()


def stop_group(proc: subprocess.Popen) -> None:
    """Stop a server started in a session of its own: SIGTERM to its group, SIGKILL after 15 s."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def _iso(t: datetime) -> str:
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


class TakClient:
    """A TAK client on a server's CoT port: announces itself (its SA event) and collects every
    event the server relays to it, each parsed as XML."""

    def __init__(self, port: int, callsign: str = "listener", tls=None) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        if tls is not None:  # an ssl.SSLContext with the client's certificate
            self.sock = tls.wrap_socket(self.sock, server_hostname="127.0.0.1")
        self.callsign = callsign
        self.announce()
        self.buffer = b""
        self.events: list[ET.Element] = []
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def announce(self) -> None:
        """Its presence (SA) event, as ATAK sends it on connecting."""
        now, callsign = datetime.now(UTC), self.callsign
        self.sock.sendall(
            f'<?xml version="1.0" encoding="UTF-8"?><event version="2.0" uid="ANDROID-{callsign}" type="a-f-G-U-C" '
            f'how="h-e" time="{_iso(now)}" start="{_iso(now)}" stale="{_iso(now + timedelta(minutes=10))}">'
            f'<point lat="40.0" lon="-105.0" hae="1600" ce="10" le="10"/><detail><contact callsign="{callsign}" '
            f'endpoint="*:-1:stcp"/><__group name="Cyan" role="Team Member"/><takv platform="test" version="1"/>'
            f"</detail></event>".encode())

    def wait_routed(self, port: int, tls=None, timeout_s: float = 60.0) -> None:
        """Until the server relays to this client: a second client announces itself (again, every
        half second) until its presence arrives here; then it leaves."""
        probe = TakClient(port, callsign=f"{self.callsign}-probe", tls=tls)
        arrived = lambda evs: any(e.get("uid") == f"ANDROID-{probe.callsign}" for e in evs)  # noqa: E731
        deadline = time.monotonic() + timeout_s
        try:
            while not arrived(self.events):
                assert time.monotonic() < deadline, f"the server relays nothing to {self.callsign}"
                probe.announce()
                self.wait_for(arrived, 0.5)
        finally:
            probe.close()

    def _run(self) -> None:
        self.sock.settimeout(0.5)
        while self.running:
            try:
                data = self.sock.recv(65536)
            except (TimeoutError, ssl.SSLWantReadError):
                continue
            except OSError:
                return
            if not data:
                return
            self.buffer += data
            while (end := self.buffer.find(b"</event>")) >= 0:
                doc, self.buffer = self.buffer[:end + 8], self.buffer[end + 8:]
                self.events.append(ET.fromstring(doc[doc.find(b"<event"):]))

    def wait_for(self, count, timeout_s: float = 30.0) -> None:
        """Until ``count(self.events)`` is true (or the time is up)."""
        deadline = time.monotonic() + timeout_s
        while not count(self.events) and time.monotonic() < deadline:
            time.sleep(0.1)

    def wait_until_quiet(self, measure, quiet_s: float = 3.0, timeout_s: float = 60.0) -> None:
        """Until ``measure(self.events)`` has not changed for ``quiet_s`` (or the time is up)."""
        deadline, last, since = time.monotonic() + timeout_s, None, time.monotonic()
        while time.monotonic() < deadline:
            now = measure(self.events)
            if now != last:
                last, since = now, time.monotonic()
            elif now and time.monotonic() - since > quiet_s:
                return
            time.sleep(0.1)

    def close(self) -> None:
        self.running = False
        self.thread.join()
        self.sock.close()


TAKY = ROOT / ".venv-taky" / "bin"


@contextlib.contextmanager
def taky_server(folder: Path, timeout_s: float = 60.0):
    """Run taky (a TAK server from PyPI, in the venv `make tak` builds) on a TLS port of loopback
    that requires client certificates, set up by its own `takyctl setup` (its CA and server
    certificate); yields {"port", "site"}. Clients: :func:`taky_client`."""
    assert (TAKY / "taky").exists(), "the TLS TAK server test needs taky: `make tak` (part of `make test`) installs it"
    site = folder / "taky"
    subprocess.run([str(TAKY / "takyctl"), "setup", "--public-ip", "127.0.0.1", "--host", "127.0.0.1", "--bind-ip",
                    "127.0.0.1", str(site)], check=True, capture_output=True)
    port = free_tcp_port()
    conf = site / "taky.conf"
    conf.write_text(conf.read_text().replace("port = 8089", f"port = {port}"))
    log = open(folder / "taky.log", "w")
    proc = subprocess.Popen([str(TAKY / "taky"), "-c", str(conf), "-l", "info"], cwd=site, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + timeout_s
        while "Listening for ssl" not in (folder / "taky.log").read_text():
            assert proc.poll() is None and time.monotonic() < deadline, (folder / "taky.log").read_text()[-3000:]
            time.sleep(0.2)
        yield {"port": port, "site": site}
    finally:
        stop_group(proc)
        log.close()


def taky_client(site: Path, name: str) -> Path:
    """A client's connection data package, made by the server's own tool (`takyctl build_client`:
    MANIFEST, a .pref naming the server, the client's .p12 and the server's truststore .p12)."""
    subprocess.run([str(TAKY / "takyctl"), "-c", str(site / "taky.conf"), "build_client", name], check=True,
                   capture_output=True, cwd=site)
    return site / f"{name}.zip"
