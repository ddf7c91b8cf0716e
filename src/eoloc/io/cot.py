"""Cursor-on-Target (CoT 2.0) XML events of fixes, for TAK (ATAK/WinTAK/TAK Server) users.

One ``<event>`` per located target, each its own XML document (TAK ingests one event per file or
per message, never an ``<events>`` wrapper); many events go into a TAK data package (a zip with
``MANIFEST/manifest.xml``, version 2, one ``<uid>/<uid>.cot`` entry per event) that ATAK and
WinTAK import whole. Event times are the fix's ``time_utc`` (ISO 8601) when the inputs give the
clock's origin, else the time of writing. CoT's ``<point>`` takes lat/lon in WGS-84 degrees and
``hae`` in metres above the ellipsoid (eoloc's h_m as is), with ``ce``/``le`` the circular and
linear 1-sigma errors in metres (the CoT base schema); 9999999 means unknown, which is what a fix
without a covariance gets, never an invented number. CE90/LE90 and CEP50 go in the remarks.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta
from pathlib import Path

UNKNOWN = 9999999.0


def _iso(t: datetime) -> str:
    return t.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _num(row: dict, key: str) -> float:
    v = row.get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else math.nan


def cot_event(row: dict, *, uid_prefix: str = "eoloc", cot_type: str = "a-u-G", stale_s: float = 300.0,
              now: datetime | None = None) -> ET.Element | None:
    """The CoT event of one fix row (``export.fix_records`` layout, with the covariance columns when
    known); None for a fix that failed (no point to send)."""
    if row.get("status") != "OK":
        return None
    iso = row.get("time_utc")
    t = datetime.fromisoformat(iso) if isinstance(iso, str) and iso else (now or datetime.now(UTC))
    tid = row.get("target_id", row.get("track_id", "fix"))
    # one fix, one uid: the frame (or the source line) tells fixes of the same target apart
    which = next((row[k] for k in ("frame", "line") if row.get(k) is not None), None)
    uid = f"{uid_prefix}-{tid}" if which is None else f"{uid_prefix}-{tid}-{which}"
    ev = ET.Element("event", version="2.0", uid=str(uid), type=cot_type, how="m-i", time=_iso(t), start=_iso(t),
                    stale=_iso(t + timedelta(seconds=stale_s)))
    se, sn, su = _num(row, "sigma_e_m"), _num(row, "sigma_n_m"), _num(row, "sigma_u_m")
    ce = math.sqrt((se * se + sn * sn) / 2.0) if math.isfinite(se + sn) else UNKNOWN
    le = su if math.isfinite(su) else UNKNOWN
    ET.SubElement(ev, "point", lat=f"{row['lat_deg']:.8f}", lon=f"{row['lon_deg']:.8f}", hae=f"{row['h_m']:.2f}",
                  ce=f"{ce:.2f}", le=f"{le:.2f}")
    detail = ET.SubElement(ev, "detail")
    ET.SubElement(detail, "contact", callsign=str(tid))
    parts = [f"eoloc fix of target {tid}"]
    for key, label in (("cep50_m", "CEP50"), ("ce90_m", "CE90"), ("le90_m", "LE90"), ("range_m", "slant range")):
        v = _num(row, key)
        if math.isfinite(v):
            parts.append(f"{label} {v:.1f} m")
    ET.SubElement(detail, "remarks").text = "; ".join(parts)
    return ev


def cot_events(rows: list[dict], **kwargs) -> list[ET.Element]:
    """The CoT events of every OK fix row, in order."""
    return [ev for ev in (cot_event(row, **kwargs) for row in rows) if ev is not None]


def event_bytes(ev: ET.Element) -> bytes:
    """One event as a standalone XML document (what a TAK feed sends as one message)."""
    ET.indent(ev)
    return ET.tostring(ev, encoding="utf-8", xml_declaration=True)


def write_cot(path: str | Path, rows: list[dict], *, name: str = "eoloc fixes", **kwargs) -> tuple[Path, int]:
    """All OK fixes as a TAK data package (zip: one ``<uid>/<uid>.cot`` per event and
    ``MANIFEST/manifest.xml``); returns (path, number of events)."""
    import zipfile

    events = cot_events(rows, **kwargs)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    manifest = ET.Element("MissionPackageManifest", version="2")
    conf = ET.SubElement(manifest, "Configuration")
    ET.SubElement(conf, "Parameter", name="uid", value=f"eoloc-{path.stem}")
    ET.SubElement(conf, "Parameter", name="name", value=name)
    ET.SubElement(conf, "Parameter", name="onReceiveImport", value="true")
    contents = ET.SubElement(manifest, "Contents")
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for ev in events:
            uid = ev.get("uid")
            entry = f"{uid}/{uid}.cot"
            zf.writestr(entry, event_bytes(ev))
            c = ET.SubElement(contents, "Content", ignore="false", zipEntry=entry)
            ET.SubElement(c, "Parameter", name="uid", value=uid)
        ET.indent(manifest)
        zf.writestr("MANIFEST/manifest.xml", ET.tostring(manifest, encoding="utf-8", xml_declaration=True))
    return path, len(events)
