"""TLS to a TAK server (``tls://HOST:8089``): the client certificate, the server's CA and TAK's
connection data packages, read as TAK users are given them, with every certificate problem
named before the first connection.

What an admin hands out is one of:

- a client certificate as PKCS#12 (``user.p12``, password-protected; TAK Server's default
  password is ``atakatak``, FreeTAKServer's ``supersecret``), often with the CA chain inside, and
  the server's CA as a truststore (``truststore-root.p12``) or PEM file;
- a **connection data package**: a zip with ``MANIFEST/manifest.xml``, a ``.pref`` file (ATAK's
  preferences: ``cot_streams`` with ``connectString0`` = ``host:port:ssl``, and the certificate
  locations and passwords, either as ``caLocation``/``certificateLocation``/``caPassword``/
  ``clientPassword`` in ``com.atakmap.app_preferences`` or per stream as ``caLocation0`` …) and
  the two ``.p12`` files. The locations are paths on the phone (``cert/user.p12``); the entry of
  the zip with that file name is used.

The ``.p12`` files are read by the ``cryptography`` package (Python's ``ssl`` reads PEM files
only); the key reaches ``ssl`` through a private temporary file encrypted with a one-off
password, so the decrypted key never touches the disk.

The server is trusted when its certificate chains to the CA given, as ATAK does; its host name is
not compared with the certificate (TAK servers' certificates name whatever their admin typed,
often not the address clients use), unless the URL asks for it (``?check_hostname=1``).

Problems found before connecting (a wrong password, an expired or not yet valid certificate, a
file that is no certificate, no CA) raise :class:`eoloc.errors.InputError`; problems the
handshake reveals (the server's certificate not from the CA given, the server refusing ours) are
described by :func:`handshake_problem` in one line with the fix.
"""

from __future__ import annotations

import os
import secrets
import ssl
import tempfile
import zipfile
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath

from defusedxml import ElementTree as SafeET

from ..errors import InputError

DEFAULT_PASSWORDS = ("atakatak", "supersecret")  # TAK Server's and FreeTAKServer's defaults, tried last


@dataclass
class TlsCredentials:
    """What a TLS connection to a TAK server needs: the client key and certificate (with any
    intermediate certificates), the CA certificates that sign the server, and where they came
    from (for messages)."""

    key: object  # a cryptography private key
    cert: object  # a cryptography x509.Certificate
    chain: list
    cas: list
    source: str

    def subject(self) -> str:
        return self.cert.subject.rfc4514_string()

    def context(self, check_hostname: bool = False) -> ssl.SSLContext:
        """An :class:`ssl.SSLContext` for the client side (TLS 1.2 or later)."""
        from cryptography.hazmat.primitives import serialization

        ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        ctx.minimum_version = ssl.TLSVersion.TLSv1_2
        ctx.check_hostname = check_hostname
        ctx.verify_mode = ssl.CERT_REQUIRED
        ctx.load_verify_locations(cadata="".join(
            c.public_bytes(serialization.Encoding.PEM).decode("ascii") for c in self.cas))
        one_off = secrets.token_urlsafe(24)
        pem = self.key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                     serialization.BestAvailableEncryption(one_off.encode()))
        pem += b"".join(c.public_bytes(serialization.Encoding.PEM) for c in [self.cert, *self.chain])
        with tempfile.TemporaryDirectory(prefix="eoloc-tls-") as folder:
            path = Path(folder) / "client.pem"
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as f:
                f.write(pem)
            ctx.load_cert_chain(path, password=one_off)
        return ctx


@dataclass
class ConnectionPackage:
    """A TAK connection data package, read: the server (``url``) and the credentials."""

    url: str
    credentials: TlsCredentials | None  # None for a plain tcp:// or udp:// server


def _valid_now(cert, what: str) -> None:
    now = datetime.now(UTC)
    name = cert.subject.rfc4514_string()
    if cert.not_valid_after_utc < now:
        raise InputError(f"{what}: the certificate {name!r} expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC; "
                         "ask the TAK server's admin for a new one")
    if cert.not_valid_before_utc > now:
        raise InputError(f"{what}: the certificate {name!r} is not valid before "
                         f"{cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC; check this machine's clock")


def _load_p12(data: bytes, password: str | None, what: str, option: str):
    """(key, cert, extra certificates) of PKCS#12 bytes: the password given, else none and the TAK
    defaults; an InputError naming the file and the option for a wrong one."""
    from cryptography.hazmat.primitives.serialization import pkcs12

    tries = [password] if password is not None else [None, *DEFAULT_PASSWORDS]
    for p in tries:
        try:
            return pkcs12.load_key_and_certificates(data, None if p is None else p.encode())
        except ValueError as exc:
            if "password" not in str(exc).lower() and "mac" not in str(exc).lower():
                raise InputError(f"{what}: not a PKCS#12 (.p12) certificate file ({exc}); give the .p12 the TAK "
                                 "server's admin made, or a PEM file") from None
    if password is not None:
        raise InputError(f"{what}: wrong password ({option}); it is the one given with the .p12 "
                         "(TAK Server's default is atakatak)")
    raise InputError(f"{what}: the .p12 opens neither without a password nor with the TAK defaults; give its "
                     f"password ({option})")


def _load_pem(data: bytes, password: str | None, what: str):
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    certs = x509.load_pem_x509_certificates(data) if b"-----BEGIN CERTIFICATE" in data else []
    key = None
    if b"PRIVATE KEY-----" in data:
        try:
            key = serialization.load_pem_private_key(data, None if password is None else password.encode())
        except (TypeError, ValueError) as exc:
            raise InputError(f"{what}: the private key cannot be read ({exc}); give its password "
                             "(--tak-cert-password) or the .p12") from None
    return key, certs


def read_certificates(data: bytes, what: str, password: str | None = None, option: str = "--tak-cert-password"):
    """(key or None, [certificates]) of a .p12, PEM or DER file's bytes."""
    from cryptography import x509

    if b"-----BEGIN" in data[:4096] or data.lstrip().startswith(b"-----"):
        return _load_pem(data, password, what)
    try:
        return None, [x509.load_der_x509_certificate(data)]
    except ValueError:
        pass
    key, cert, extra = _load_p12(data, password, what, option)
    return key, [c for c in (cert, *extra) if c is not None]


def credentials(cert_file: bytes, cert_what: str, password: str | None, ca_file: bytes | None = None,
                ca_what: str = "", ca_password: str | None = None, ca_option: str = "--tak-ca") -> TlsCredentials:
    """The credentials of a client certificate (.p12, or PEM with its key) and, optionally, a CA
    file (PEM, DER or .p12 truststore); without a CA file the CA certificates in the client's
    .p12 are used."""
    key, certs = read_certificates(cert_file, cert_what, password)
    if key is None or not certs:
        raise InputError(f"{cert_what}: holds no client key and certificate; give the client's .p12 "
                         "(or a PEM file with its certificate and private key)")
    cert = next((c for c in certs if c.public_key() == key.public_key()), None)  # the key's own certificate
    if cert is None:
        raise InputError(f"{cert_what}: no certificate in it belongs to its private key; give the client's .p12 "
                         "as the TAK server's admin made it")
    others = [c for c in certs if c is not cert]
    _valid_now(cert, cert_what)
    if ca_file is not None:
        _, cas = read_certificates(ca_file, ca_what, ca_password if ca_password is not None else password,
                                   option=ca_option)
        if not cas:
            raise InputError(f"{ca_what}: holds no certificate; give the TAK server's CA (PEM, DER or a .p12 "
                             "truststore)")
        where = ca_what
    else:
        cas = [c for c in others if _is_ca(c)]
        if not cas:
            raise InputError(f"{cert_what}: holds no CA certificate, so the server cannot be checked; give the "
                             f"server's CA ({ca_option} CA.pem or the truststore .p12)")
        where = cert_what
    for c in cas:
        _valid_now(c, f"{where} (CA)")
    return TlsCredentials(key=key, cert=cert, chain=[c for c in others if not _is_ca(c)], cas=cas, source=cert_what)


def _is_ca(cert) -> bool:
    from cryptography import x509

    try:
        return bool(cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca)
    except x509.ExtensionNotFound:
        return cert.issuer == cert.subject


def credentials_from_files(cert: Path, password: str | None, ca: Path | None,
                           ca_password: str | None = None) -> TlsCredentials:
    """:func:`credentials` of files (messages name them)."""
    try:
        cert_bytes = Path(cert).read_bytes()
        ca_bytes = None if ca is None else Path(ca).read_bytes()
    except OSError as exc:
        raise InputError(f"{exc.filename}: cannot be read ({exc.strerror})") from None
    return credentials(cert_bytes, str(cert), password, ca_bytes, str(ca) if ca else "", ca_password)


def _prefs(text: bytes, where: str) -> dict[str, str]:
    try:
        root = SafeET.fromstring(text)
    except Exception as exc:  # defusedxml's and expat's errors alike
        raise InputError(f"{where}: not an ATAK preference file ({exc})") from None
    return {e.get("key", ""): (e.text or "").strip() for e in root.iter("entry")}


def read_connection_package(path: Path) -> ConnectionPackage:
    """The TAK server and the credentials of a connection data package (see the module notes)."""
    path = Path(path)
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a TAK data package (a zip) ({exc})") from None
    with zf:
        names = [n for n in zf.namelist() if not n.endswith("/")]
        prefs: dict[str, str] = {}
        for n in names:
            if n.lower().endswith(".pref"):
                prefs.update(_prefs(zf.read(n), f"{path}:{n}"))
        connect = next((prefs[k] for k in sorted(prefs) if k.startswith("connectString")), None)
        if not connect:
            raise InputError(f"{path}: no .pref file with a server (cot_streams' connectString0 = host:port:ssl); "
                             "ask the TAK server's admin for the connection data package")
        host, _, rest = connect.partition(":")
        port, _, proto = rest.partition(":")
        if not host or not port.isdigit():
            raise InputError(f"{path}: connectString {connect!r} is not host:port:protocol")
        scheme = {"ssl": "tls", "tls": "tls", "tcp": "tcp", "udp": "udp"}.get(proto.lower() or "ssl")
        if scheme is None:
            raise InputError(f"{path}: connectString {connect!r}: protocol {proto!r} is not one eoloc speaks "
                             "(ssl, tcp, udp)")

        def pref(name: str) -> str | None:
            return prefs.get(name) or prefs.get(f"{name}0")

        def entry(location: str | None, what: str) -> tuple[bytes, str]:
            base = PurePosixPath(location or "").name
            match = [n for n in names if PurePosixPath(n).name == base] if base else []
            if not match:
                raise InputError(f"{path}: the {what} {location!r} named by the .pref is not in the package")
            return zf.read(match[0]), f"{path}:{match[0]}"

        url = f"{scheme}://{host}:{port}"
        if scheme != "tls":
            return ConnectionPackage(url=url, credentials=None)
        cert, cert_what = entry(pref("certificateLocation"), "client certificate")
        ca = pref("caLocation")
        ca_bytes, ca_what = entry(ca, "CA truststore") if ca else (None, "")
        creds = credentials(cert, cert_what, pref("clientPassword"), ca_bytes, ca_what, pref("caPassword"),
                            ca_option="the .pref's caPassword")
        return ConnectionPackage(url=url, credentials=creds)


def handshake_problem(exc: BaseException, url: str, creds: TlsCredentials | None) -> str | None:
    """One line naming a TLS handshake failure that retrying cannot mend (a certificate
    problem), with the fix; None for anything else (a network error: retried)."""
    if isinstance(exc, ssl.SSLCertVerificationError):
        where = f" ({creds.source})" if creds is not None else ""
        reason = exc.verify_message or str(exc)
        why = {62: "its name is not the host's (leave ?check_hostname=1 out, as ATAK does, or use the name it "
                   "was issued for)",
               10: "it has expired: the server's admin must renew it"}.get(exc.verify_code,
               f"it is not signed by the CA given{where}; give the server's own CA (--tak-ca) or the connection "
               "data package its admin made")
        return f"{url}: the server's certificate cannot be trusted ({reason}): {why}"
    if isinstance(exc, ssl.SSLError):
        reason = (exc.reason or str(exc)).lower()
        name = creds.subject() if creds is not None else "eoloc's certificate"
        refused = {"unknown_ca": "is signed by a CA it does not trust",
                   "certificate_expired": "has expired", "certificate_revoked": "has been revoked",
                   "bad_certificate": "is not acceptable", "certificate_unknown": "is not known to it",
                   "access_denied": "is not allowed", "handshake_failure": "was not accepted"}
        for key, why in refused.items():
            if key in reason.replace(" ", "_"):
                return (f"{url}: the server refused eoloc's client certificate {name!r}: it {why} "
                        f"(TLS alert {key}); ask the server's admin for a certificate it accepts")
        if "wrong_version" in reason or "record_layer" in reason or "packet_length" in reason:
            return (f"{url}: the server does not speak TLS on this port ({exc.reason}); a TAK server's TLS port "
                    "is usually 8089 and its plain one 8087 (tcp://)")
    return None
