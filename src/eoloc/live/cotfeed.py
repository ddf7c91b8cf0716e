"""Cursor-on-Target events of live packets, for TAK clients and servers (after MISB ST 0805,
"KLV to CoT conversion", as jMISB implements it).

Per packet, each event one standalone XML document:

- the **platform** (``a-f-A-M-F-Q``, a friendly UAV; uid ``eoloc-<platform>``, the platform
  designation or the stream) at the sensor's position, with a ``<sensor>`` detail — azimuth
  and elevation of the line of sight, horizontal and vertical field of view, range to the frame
  centre, model — which ATAK and WinTAK draw as the sensor's field-of-view cone, and its heading
  in ``<track course>``, and with ``video_url`` a ``<__video>`` link to the stream (ATAK opens it
  from the marker);
- the **sensor point of interest** (``b-m-p-s-p-i``, uid ``<platform>-spi``): eoloc's frame
  centre on the chosen surface, linked to the platform (``relation="p-p"``);
- the **footprint** as a closed shape (``u-d-f``, uid ``<platform>-footprint``: a ``<link
  point>`` per corner, first repeated last);
- one event per **located target** (``a-u-G``, uid ``<platform>-<target id>``: a VMTI target
  keeps its marker from packet to packet), ``ce``/``le`` the 1-sigma horizontal and vertical
  errors from its covariance (9999999, unknown, without an error budget), CE90/LE90 in the
  remarks;
- with ``targets="estimates"`` each target's **refined estimate** instead (:mod:`eoloc.live.refine`:
  RLS for a static target, the Kalman track for a moving one) under the same uid, so the marker
  converges as fixes accumulate: ``ce``/``le`` from its calibrated covariance by the same
  convention as a fix (:mod:`eoloc.io.cot`; ``le`` unknown for a track, which refines the
  horizontal position only), the model and fix count in the remarks, a moving target's speed and
  course in ``<track>``; a target whose fixes do not agree with one point (INCONSISTENT) gets no
  marker — a point there would be a plausible wrong one; ``targets="both"``: the fixes, and the
  estimates as ``<platform>-<target id>-refined``;
- one event per **mover found in the video** (``eoloc live --detect``, :mod:`eoloc.live.movers`;
  ``a-u-G``, uid ``<platform>-mover-<id>``): where it was in its frame, its course and speed in
  ``<track>``, ``ce``/``le`` from its fix's covariance as for a target (unknown without a budget).

``time``/``start`` are when the event is sent and ``stale`` that plus ``stale_packets`` packet
intervals of its stream (the median of the last 15 by the ST 0601 time stamps, between ``min_stale_s`` and
``max_stale_s``): a marker lasts a few packets after its stream stops. The packet's own UTC time
goes in the remarks (a replayed stream's clock is not now, and TAK drops events already stale).
:meth:`CotFeed.silence` re-sends each platform already stale when its stream goes quiet.
"""

from __future__ import annotations

import math
import socket
import statistics
from collections import deque
from datetime import UTC, datetime, timedelta

from ..io.cot import ce_le, element_xml, event_xml, fix_remarks, iso_utc, video_detail
from .update import PacketUpdate

PLATFORM_TYPE = "a-f-A-M-F-Q"  # friendly / air / military / fixed wing / UAV
TARGET_TYPE = "a-u-G"  # unknown affiliation, ground
SPI_TYPE = "b-m-p-s-p-i"  # sensor point of interest (MISB ST 0805)
SHAPE_TYPE = "u-d-f"  # a drawn shape (TAK's freehand polygon)
TARGET_CHOICES = ("fixes", "estimates", "both")  # what a target's events carry


class CotFeed:
    """CoT events of :class:`PacketUpdate`s, with stale times from each stream's rate and an
    optional minimum interval per uid (``interval_s``; ``held`` counts the events left out)."""

    def __init__(self, *, uid_prefix: str = "eoloc", stale_packets: float = 10.0, min_stale_s: float = 2.0,
                 max_stale_s: float = 60.0, interval_s: float = 0.0, targets: str = "fixes",
                 video_url: str | None = None) -> None:
        if targets not in TARGET_CHOICES:
            raise ValueError(f"targets must be one of {TARGET_CHOICES}, not {targets!r}")
        self.uid_prefix = uid_prefix
        self.targets = targets
        self.video_url = video_url
        self.stale_packets, self.min_stale_s, self.max_stale_s = stale_packets, min_stale_s, max_stale_s
        self.interval_s = interval_s
        self.period_s: dict[str, float] = {}  # stream -> its packet interval (median of the last 15)
        self.intervals: dict[str, deque] = {}
        self.last_time: dict[str, float] = {}
        self.last_sent: dict[str, float] = {}
        self.platforms: dict[str, PacketUpdate] = {}  # uid -> its last update
        self.events_out = 0
        self.held = 0

    def stale_s(self, stream: str) -> float:
        """How long this stream's events stay current: ``stale_packets`` packet intervals."""
        p = self.period_s.get(stream)
        if p is None:
            return 10.0
        return min(max(self.stale_packets * p, self.min_stale_s), self.max_stale_s)

    def _rate(self, u: PacketUpdate) -> None:
        t, last = u.time_s, self.last_time.get(u.stream)
        if not math.isfinite(t) or u.late:
            return
        if last is not None and 0.0 < t - last < 30.0:
            recent = self.intervals.setdefault(u.stream, deque(maxlen=15))
            recent.append(t - last)
            self.period_s[u.stream] = statistics.median(recent)  # a lost packet or two does not move it
        self.last_time[u.stream] = t

    def _due(self, uid: str, now_s: float) -> bool:
        if self.interval_s <= 0:
            return True
        last = self.last_sent.get(uid)
        if last is not None and now_s - last < self.interval_s:
            self.held += 1
            return False
        self.last_sent[uid] = now_s
        return True

    def events(self, u: PacketUpdate, now: datetime | None = None) -> list[bytes]:
        """The events of one packet: platform, sensor point of interest, footprint, targets."""
        now_dt = now or datetime.now(UTC)
        now_s = now_dt.timestamp()
        self._rate(u)
        now, stale = iso_utc(now_dt), iso_utc(now_dt + timedelta(seconds=self.stale_s(u.stream)))
        base = f"{self.uid_prefix}-{u.key}"
        name = (u.platform or {}).get("name") or u.key
        when = u.time_utc or "no time stamp"
        out: list[bytes] = []
        if u.platform is not None and not u.late:
            self.platforms[base] = u
            if self._due(base, now_s):
                out.append(self._platform(u, base, name, now, stale, f"{name}: packet {u.index} of {when}"))
        link = element_xml("link", uid=base, type=PLATFORM_TYPE, relation="p-p")
        if u.centre is not None and not u.late and self._due(base + "-spi", now_s):
            lat, lon, h = u.centre
            out.append(event_xml(uid=base + "-spi", cot_type=SPI_TYPE, how="m-i", time=now, stale=stale, lat=lat,
                                 lon=lon, hae=h, detail=element_xml("contact", callsign=f"{name} SPI") + link
                                 + element_xml("remarks", f"eoloc frame centre of {name} at {when}")))
        if u.footprint is not None and not u.late and self._due(base + "-footprint", now_s):
            fp = u.footprint  # cut at the antimeridian: CoT has one shape, so the larger part
            ring = fp["coordinates"][0] if fp["type"] == "Polygon" else max((q[0] for q in fp["coordinates"]), key=len)
            lon, lat, h = (sum(c) / (len(ring) - 1) for c in zip(*ring[:-1], strict=True))  # the centroid
            detail = "".join(element_xml("link", point=f"{p[1]:.8f},{p[0]:.8f},{p[2]:.2f}") for p in ring)
            detail += (element_xml("strokeColor", value="-256") + element_xml("strokeWeight", value="2.0")
                       + element_xml("fillColor", value="822083328") + element_xml("labels_on", value="false")
                       + element_xml("contact", callsign=f"{name} footprint") + link)
            out.append(event_xml(uid=base + "-footprint", cot_type=SHAPE_TYPE, how="m-i", time=now, stale=stale,
                                 lat=lat, lon=lon, hae=h, detail=detail))
        for row in u.fixes if self.targets != "estimates" else ():
            if row.get("status") != "OK":
                continue
            tid = row.get("target_id")
            uid = f"{base}-{tid}"
            if not self._due(uid, now_s):
                continue
            ce, le = ce_le(row)
            detail = (element_xml("contact", callsign=f"{name} {tid}") + link
                      + element_xml("remarks", f"{fix_remarks(row, tid)}; {when}"))
            out.append(event_xml(uid=uid, cot_type=TARGET_TYPE, how="m-i", time=now, stale=stale,
                                 lat=float(row["lat_deg"]), lon=float(row["lon_deg"]), hae=float(row["h_m"]), ce=ce,
                                 le=le, detail=detail))
        if self.targets != "fixes":
            suffix = "-refined" if self.targets == "both" else ""
            for est in u.estimates:
                if est["geometry"] is None:  # INCONSISTENT: no point to show
                    continue
                uid = f"{base}-{est['properties']['target_id']}{suffix}"
                if self._due(uid, now_s):
                    out.append(self._estimate(est, uid, name, link, now, stale, when))
        for mover in u.movers:
            uid = f"{base}-mover-{mover['properties']['track_id']}"
            if self._due(uid, now_s):
                out.append(self._mover(mover, uid, name, link, now, stale, when))
        self.events_out += len(out)
        return out

    def _estimate(self, est: dict, uid: str, name: str, link: str, now: str, stale: str, when: str) -> bytes:
        """A target's refined estimate (a live.refine GeoJSON feature) as its marker."""
        p = est["properties"]
        lon, lat, h = est["geometry"]["coordinates"]
        cep = p.get("cep50_m")
        remarks = [f"eoloc estimate of target {p['target_id']}: {p['model']} over {p['n_fixes']} fixes"]
        if cep is not None:
            remarks.append(f"CEP50 {cep:.1f} m")
        if p.get("warning"):
            remarks.append(p["warning"])
        detail = element_xml("contact", callsign=f"{name} {p['target_id']}") + link
        if p.get("speed_mps") is not None:
            detail += element_xml("track", course=_fmt(p.get("heading_deg")), speed=_fmt(p["speed_mps"]))
        detail += element_xml("remarks", f"{'; '.join(remarks)}; {when}")
        ce, le = ce_le(p)
        return event_xml(uid=uid, cot_type=TARGET_TYPE, how="m-i", time=now, stale=stale, lat=lat, lon=lon, hae=h,
                         ce=ce, le=le, detail=detail)

    def _mover(self, mover: dict, uid: str, name: str, link: str, now: str, stale: str, when: str) -> bytes:
        """A mover found in the video (a live.movers GeoJSON feature) as its marker: where it was in
        its frame, its filtered course and speed, ce/le from its fix's covariance (unknown without
        an error budget)."""
        p = mover["properties"]
        lon, lat, h = mover["geometry"]["coordinates"]
        label = f"M{p['track_id']}" + (f" {p['class']}" if p.get("class") else "")
        detail = (element_xml("contact", callsign=f"{name} {label}") + link
                  + element_xml("track", course=_fmt(p.get("heading_deg")), speed=_fmt(p.get("speed_mps")))
                  + element_xml("remarks", f"eoloc mover {label} found in the video (frame {p['frame']}): "
                                           f"{p['speed_mps']:.1f} m/s; {when}"))
        ce, le = ce_le(p)
        return event_xml(uid=uid, cot_type=TARGET_TYPE, how="m-i", time=now, stale=stale, lat=lat, lon=lon, hae=h,
                         ce=ce, le=le, detail=detail)

    def _platform(self, u: PacketUpdate, uid: str, name: str, now: datetime | str, stale: datetime | str,
                  remarks: str) -> bytes:
        p, look = u.platform, u.look or {}
        sensor = element_xml("sensor", azimuth=_fmt(look.get("azimuth_deg")), elevation=_fmt(look.get("elevation_deg")),
                             fov=_fmt(look.get("hfov_deg")), vfov=_fmt(look.get("vfov_deg")),
                             range=_fmt(look.get("range_m")), model=look.get("sensor"))
        track = element_xml("track", course=_fmt(p.get("heading_deg"))) if p.get("heading_deg") is not None else ""
        video = video_detail(self.video_url, self.video_uid(), name) if self.video_url else ""
        detail = element_xml("contact", callsign=name) + sensor + track + video + element_xml("remarks", remarks)
        return event_xml(uid=uid, cot_type=PLATFORM_TYPE, how="m-g", time=now, stale=stale, lat=p["lat_deg"],
                         lon=p["lon_deg"], hae=p["h_m"], detail=detail)

    def video_uid(self) -> str:
        """The uid of the video link (the same in the platform's CoT and in the video package)."""
        return f"{self.uid_prefix}-video"

    def presence_uid(self) -> str:
        """eoloc's own uid as a TAK client (its presence event's)."""
        return f"{self.uid_prefix}-{socket.gethostname()}"

    def presence(self, now: datetime | None = None) -> bytes:
        """eoloc itself as a TAK client announces itself (a friendly ground sensor with a contact
        and ``<takv>``): what a TAK server expects first on a new connection."""
        from .. import __version__

        now = now or datetime.now(UTC)
        detail = (element_xml("contact", callsign=self.uid_prefix, endpoint="*:-1:stcp")
                  + element_xml("__group", name="Cyan", role="Team Member")
                  + element_xml("takv", platform="eoloc", version=__version__, device="ground station", os="")
                  + element_xml("remarks", "eoloc live: geolocated targets from MISB KLV"))
        return event_xml(uid=self.presence_uid(), cot_type="a-f-G-E-S", how="h-g-i-g-o",
                         time=now, stale=now + timedelta(hours=1), lat=0.0, lon=0.0, hae=0.0, detail=detail)

    def silence(self, quiet_s: float, now: datetime | None = None) -> list[bytes]:
        """Each platform's last event again, stale at once: TAK shows it as lost."""
        now = now or datetime.now(UTC)
        out = []
        for uid, u in self.platforms.items():
            name = (u.platform or {}).get("name") or u.key
            out.append(self._platform(u, uid, name, now, now, f"{name}: no metadata for {quiet_s:.0f} s"))
        self.events_out += len(out)
        return out


def _fmt(v) -> str | None:
    return None if v is None else f"{float(v):.3f}"
