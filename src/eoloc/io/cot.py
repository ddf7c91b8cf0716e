"""Cursor-on-Target (CoT 2.0) XML events of fixes, for TAK (ATAK/WinTAK/TAK Server) users.

One ``<event>`` per located target, each its own XML document (TAK ingests one event per file or
per message, never an ``<events>`` wrapper); many events go into a TAK data package (a zip with
``MANIFEST/manifest.xml``, version 2, one ``<uid>/<uid>.cot`` entry per event) that ATAK and
WinTAK import whole. Event times are the fix's ``time_utc`` (ISO 8601) when the inputs give the
clock's origin, else the time of writing. CoT's ``<point>`` takes lat/lon in WGS-84 degrees and
``hae`` in metres above the ellipsoid (eoloc's h_m as is), with ``ce``/``le`` the circular and
linear 1-sigma errors in metres (the CoT base schema); 9999999 means unknown, which is what a fix
without a covariance gets, never an invented number. CE90/LE90 and CEP50 go in the remarks.

The convention, for a receiver to draw the right circle: ``ce`` is the sigma of the circular
normal error that has the fix's own CE90 (ce = CE90 / 2.1460, the CE90 computed exactly from the
error ellipse), so the circle of radius 2.1460 ce holds the target with probability 0.9 whatever
the ellipse's shape, and one of radius ce holds it with 0.39 for a round ellipse; ``le`` is the
sigma of the vertical error (LE90 / 1.6449). Both are checked by coverage (tests/integration/
test_coverage.py) as a receiver parses them.

Events are written as text by :func:`event_xml`: one template whose every value goes through the
standard library's XML escaping (:func:`xml.sax.saxutils.quoteattr` and ``escape``) after
:func:`eoloc.io.xmltext.xml_text` (the characters XML cannot hold at all become U+FFFD), so a
callsign, id or remark holding ``&``, ``<``, quotes or control characters is still one well-formed
event. Not ElementTree: the live feed sends thousands a second and it costs 2.5x the template
(46 against 18 µs an event, measured).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from .xmltext import xml_text

UNKNOWN = 9999999.0
_FILE_NAME = re.compile(r"[^A-Za-z0-9._-]|^[.]+")  # what may not stand in a zip entry's file name as it is


def iso_utc(t: datetime) -> str:
    """CoT's time format: ISO 8601 UTC with milliseconds and a Z."""
    return t.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _num(row: dict, key: str) -> float:
    v = row.get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else math.nan


CE90_PER_SIGMA = math.sqrt(-2.0 * math.log(0.1))  # CE90 of a circular normal error, in sigmas (2.1460)
LE90_PER_SIGMA = 1.6448536269514722  # two-sided 90 % of a normal, in sigmas


def ce_le(row: dict) -> tuple[float, float]:
    """CoT's 1-sigma circular (ce) and vertical (le) errors (see the module notes) of a fix row or
    an estimate's properties from their ce90_m / le90_m (else sigma_e/n/u_m) columns;
    :data:`UNKNOWN` for what the row does not know, or knows only as no usable error (not finite,
    negative, or as large as UNKNOWN itself)."""
    ce90, le90 = _num(row, "ce90_m"), _num(row, "le90_m")
    se, sn, su = _num(row, "sigma_e_m"), _num(row, "sigma_n_m"), _num(row, "sigma_u_m")
    if math.isfinite(ce90):
        ce = ce90 / CE90_PER_SIGMA
    else:
        ce = math.sqrt((se * se + sn * sn) / 2.0) if math.isfinite(se + sn) else UNKNOWN
    le = le90 / LE90_PER_SIGMA if math.isfinite(le90) else (su if math.isfinite(su) else UNKNOWN)
    return (ce if 0.0 <= ce < UNKNOWN else UNKNOWN), (le if 0.0 <= le < UNKNOWN else UNKNOWN)


_PLAIN = re.compile("[^&<>\"'\x00-\x1f\ufffe\uffff\ud800-\udfff]*\\Z")  # an attribute value as it is


def _attr(v) -> str:
    v = str(v)
    return f'"{v}"' if _PLAIN.match(v) else quoteattr(xml_text(v))  # most values need no escaping


def element_xml(tag: str, text: str | None = None, /, **attrs) -> str:
    """One XML element as text, attributes escaped (None values left out); ``text`` escaped."""
    a = "".join(f" {k}={_attr(v)}" for k, v in attrs.items() if v is not None)
    return f"<{tag}{a}/>" if text is None else f"<{tag}{a}>{escape(xml_text(text))}</{tag}>"


def event_xml(*, uid: str, cot_type: str, how: str, time: datetime | str, stale: datetime | str, lat: float,
              lon: float, hae: float, ce: float = UNKNOWN, le: float = UNKNOWN, detail: str = "") -> bytes:
    """One CoT event as a standalone UTF-8 XML document; ``detail`` is the inner XML of ``<detail>``
    (from :func:`element_xml`); times as datetimes or already as :func:`iso_utc` text."""
    t = time if isinstance(time, str) else iso_utc(time)
    stale = stale if isinstance(stale, str) else iso_utc(stale)
    return (f'<?xml version="1.0" encoding="utf-8"?>\n<event version="2.0" uid={_attr(uid)} '
            f'type={_attr(cot_type)} how={_attr(how)} time="{t}" start="{t}" stale="{stale}">'
            f'<point lat="{lat:.8f}" lon="{lon:.8f}" hae="{hae:.2f}" ce="{ce:.2f}" le="{le:.2f}"/>'
            f"<detail>{detail}</detail></event>").encode()


def fix_remarks(row: dict, tid) -> str:
    parts = [f"eoloc fix of target {tid}"]
    for key, label in (("cep50_m", "CEP50"), ("ce90_m", "CE90"), ("le90_m", "LE90"), ("range_m", "slant range")):
        v = _num(row, key)
        if math.isfinite(v):
            parts.append(f"{label} {v:.1f} m")
    return "; ".join(parts)


def cot_event(row: dict, *, uid_prefix: str = "eoloc", cot_type: str = "a-u-G", stale_s: float = 300.0,
              now: datetime | None = None) -> ET.Element | None:
    """The CoT event of one fix row (``export.fix_records`` layout, with the covariance columns when
    known); None for a fix that failed (no point to send)."""
    data = cot_event_bytes(row, uid_prefix=uid_prefix, cot_type=cot_type, stale_s=stale_s, now=now)
    return None if data is None else ET.fromstring(data)


def cot_event_bytes(row: dict, *, uid_prefix: str = "eoloc", cot_type: str = "a-u-G", stale_s: float = 300.0,
                    now: datetime | None = None) -> bytes | None:
    """:func:`cot_event` as the XML document TAK reads."""
    if row.get("status") != "OK":
        return None
    iso = row.get("time_utc")
    t = datetime.fromisoformat(iso) if isinstance(iso, str) and iso else (now or datetime.now(UTC))
    tid = row.get("target_id", row.get("track_id", "fix"))
    # one fix, one uid: the frame (or the source line) tells fixes of the same target apart
    which = next((row[k] for k in ("frame", "line") if row.get(k) is not None), None)
    uid = f"{uid_prefix}-{tid}" if which is None else f"{uid_prefix}-{tid}-{which}"
    ce, le = ce_le(row)
    detail = element_xml("contact", callsign=str(tid)) + element_xml("remarks", fix_remarks(row, tid))
    course, speed = _num(row, "heading_deg"), _num(row, "speed_mps")
    if math.isfinite(course) and math.isfinite(speed):  # a mover's course (deg from true north) and speed (m/s)
        detail += element_xml("track", course=f"{course:.1f}", speed=f"{speed:.2f}")
    return event_xml(uid=str(uid), cot_type=cot_type, how="m-i", time=t, stale=t + timedelta(seconds=stale_s),
                     lat=float(row["lat_deg"]), lon=float(row["lon_deg"]), hae=float(row["h_m"]), ce=ce, le=le,
                     detail=detail)


def write_cot(path: str | Path, rows: list[dict], *, name: str = "eoloc fixes", **kwargs) -> tuple[Path, int]:
    """All OK fixes as a TAK data package (zip: one ``<uid>/<uid>.cot`` per event, the uid made a
    safe file name, and ``MANIFEST/manifest.xml``); returns (path, number of events)."""
    events = [e for e in (cot_event_bytes(row, **kwargs) for row in rows) if e is not None]
    entries, used = [], set()
    for k, ev in enumerate(events):
        uid = ET.fromstring(ev).get("uid")
        # ATAK's layout, <uid>/<uid>.cot, with the uid as a file name (it holds what the inputs
        # said: slashes, "..", anything) and numbered where two events would share an entry
        stem = _FILE_NAME.sub("_", uid)[:100] or "event"
        stem = stem if stem not in used else f"{stem}-{k}"
        used.add(stem)
        entries.append((f"{stem}/{stem}.cot", ev, uid))
    return write_package(path, f"eoloc-{Path(path).stem}", name, entries), len(events)


def write_package(path: str | Path, uid: str, name: str, entries: list[tuple[str, bytes, str | None]]) -> Path:
    """A TAK data package: a zip of ``entries`` ((zip entry, bytes, the content's uid or None)) and
    ``MANIFEST/manifest.xml`` (version 2, imported on receipt) listing them."""
    import zipfile

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    manifest = ET.Element("MissionPackageManifest", version="2")
    conf = ET.SubElement(manifest, "Configuration")
    for key, value in (("uid", uid), ("name", name), ("onReceiveImport", "true")):
        ET.SubElement(conf, "Parameter", name=key, value=value)
    contents = ET.SubElement(manifest, "Contents")
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for entry, data, content_uid in entries:
            zf.writestr(entry, data)
            c = ET.SubElement(contents, "Content", ignore="false", zipEntry=entry)
            if content_uid is not None:
                ET.SubElement(c, "Parameter", name="uid", value=content_uid)
        ET.indent(manifest)
        zf.writestr("MANIFEST/manifest.xml", ET.tostring(manifest, encoding="utf-8", xml_declaration=True))
    return path


def video_link(url: str, uid: str, alias: str) -> dict[str, str]:
    """ATAK's description of a video stream (its ``ConnectionEntry``): protocol, address, port and
    path of ``url`` (rtsp://, rtsps://, srt://, udp://, rtmp://, http(s)://), with the uid and the
    name shown in ATAK's video list."""
    from urllib.parse import urlsplit

    u = urlsplit(url)
    default_port = {"rtsp": 554, "rtsps": 322, "rtmp": 1935, "http": 80, "https": 443}.get(u.scheme, -1)
    try:
        port = u.port
    except ValueError:
        port = None
    path = u.path + (f"?{u.query}" if u.query else "")
    return {"protocol": u.scheme, "address": u.hostname or "", "port": str(port or default_port), "path": path,
            "uid": uid, "alias": alias}


def video_detail(url: str, uid: str, alias: str) -> str:
    """The ``<__video>`` detail of a platform's CoT event: the stream a TAK user opens from its
    marker (``url``, and ATAK's ``ConnectionEntry`` of it)."""
    v = video_link(url, uid, alias)
    entry = element_xml("ConnectionEntry", networkTimeout="12000", uid=v["uid"], path=v["path"],
                        protocol=v["protocol"], bufferTime="-1", address=v["address"], port=v["port"],
                        roverPort="-1", rtspReliable="0", ignoreEmbeddedKLV="false", alias=v["alias"])
    return f"<__video uid={_attr(uid)} url={_attr(url)}>{entry}</__video>"


def write_video_package(path: str | Path, url: str, uid: str, alias: str) -> Path:
    """A TAK data package holding the video connection (ATAK's ``<videoConnections><feed>``, the
    form TAK servers' video manager serves): imported, the stream appears in ATAK's video list."""
    v = video_link(url, uid, alias)
    feeds = ET.Element("videoConnections")
    feed = ET.SubElement(feeds, "feed")
    for key, value in (("protocol", v["protocol"]), ("alias", alias), ("uid", uid), ("address", v["address"]),
                       ("port", v["port"]), ("roverPort", "-1"), ("ignoreEmbeddedKLV", "false"),
                       ("preferredMacAddress", ""), ("preferredInterfaceAddress", ""), ("path", v["path"]),
                       ("buffer", "-1"), ("timeout", "12000"), ("rtspReliable", "0")):
        ET.SubElement(feed, key).text = xml_text(value)
    stem = _FILE_NAME.sub("_", uid)[:100] or "video"
    return write_package(path, f"{uid}-package", f"{alias} video",
                         [(f"{stem}/{stem}.xml", ET.tostring(feeds, encoding="utf-8", xml_declaration=True), None)])
