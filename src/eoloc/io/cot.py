"""Cursor-on-Target (CoT 2.0) XML events of fixes, for TAK (ATAK/WinTAK/TAK Server) users.

One ``<event>`` per located target. CoT's ``<point>`` takes lat/lon in WGS-84 degrees and
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
    """The CoT event of one fix row (``export.fix_rows`` layout, with the covariance columns when
    known); None for a fix that failed (no point to send)."""
    if row.get("status") != "OK":
        return None
    t_s = _num(row, "time_s")
    t = datetime.fromtimestamp(t_s, UTC) if math.isfinite(t_s) else (now or datetime.now(UTC))
    tid = row.get("target_id", row.get("track_id", "fix"))
    frame = row.get("frame")
    uid = f"{uid_prefix}-{tid}" if frame is None else f"{uid_prefix}-{tid}-{frame}"
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


def write_cot(path: str | Path, rows: list[dict], **kwargs) -> tuple[Path, int]:
    """All OK fixes as CoT events in one XML file (root ``<events>``); returns (path, count).
    A TAK feed sends each event on its own; :func:`cot_event` gives them one at a time."""
    root = ET.Element("events")
    n = 0
    for row in rows:
        ev = cot_event(row, **kwargs)
        if ev is not None:
            root.append(ev)
            n += 1
    ET.indent(root)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path, n
