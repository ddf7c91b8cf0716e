"""One live packet worked out: where the aircraft is, where its sensor looks (frame centre,
footprint, look angles) and where each of its VMTI targets is — the same functions as
`eoloc klv` (:func:`eoloc.io.klv.klv_telemetry`, :func:`eoloc.misb.frame_geometry`,
:func:`eoloc.video.locate_vmti`), on one packet. Every output (NDJSON, CoT, the map, KLV out)
is written from a :class:`PacketUpdate`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..io.export import fix_records, utc_times, with_utc


@dataclass
class PacketUpdate:
    """One packet's results. Angles in degrees, heights ellipsoidal (m); ``look`` is the line of
    sight to the frame centre (azimuth from true north, elevation negative below the horizon)."""

    source: str
    stream: str
    index: int  # packet number in the session
    time_s: float  # ST 0601 time stamp (UNIX s), NaN when the packet has none
    late: bool
    platform: dict | None  # name, lat_deg, lon_deg, h_m, heading_deg
    look: dict | None  # azimuth_deg, elevation_deg, hfov_deg, vfov_deg, range_m, sensor
    centre: tuple[float, float, float] | None  # frame centre (lat, lon, h) on the chosen surface
    footprint: dict | None  # GeoJSON Polygon: the four frame corners, or on a DEM the traced border
    fixes: list[dict] = field(default_factory=list)  # one row per VMTI target (export.fix_records layout)
    cov_enu: np.ndarray | None = None  # (len(fixes), 3, 3) ENU m^2, with an error budget

    time_utc: str | None = None  # the time stamp as ISO 8601 UTC
    estimates: list[dict] = field(default_factory=list)  # refined targets (GeoJSON), see live.refine

    @property
    def key(self) -> str:
        """A name for the platform's things that stays the same packet after packet (CoT uids,
        map layers): the platform designation, else the stream."""
        name = (self.platform or {}).get("name") or self.stream or "stream"
        return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)

    def features(self) -> list[dict]:
        """GeoJSON features (RFC 7946: lon, lat, h): the aircraft, the footprint and the frame
        centre when known, and every target (a failed one with a null geometry); each with
        ``what``, ``stream``, ``packet`` and ``time_utc`` properties; then the targets refined over
        the packets so far (``what`` "estimate", :mod:`eoloc.live.refine`)."""
        common = {"stream": self.stream, "packet": self.index, "time_utc": self.time_utc}
        out = []
        p = self.platform
        if p is not None:
            out.append(_feature("aircraft", _point(p["lon_deg"], p["lat_deg"], p["h_m"]),
                                {**common, **p, **(self.look or {})}))
        if self.footprint is not None:
            out.append(_feature("footprint", self.footprint, common))
        if self.centre is not None:
            out.append(_feature("frame centre", _point(self.centre[1], self.centre[0], self.centre[2]), common))
        for row in self.fixes:
            ok = row.get("status") == "OK"
            props = {k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}
            out.append(_feature("target", _point(row["lon_deg"], row["lat_deg"], row["h_m"]) if ok else None,
                                {**common, **props}))
        return out + self.estimates


def _point(lon, lat, h) -> dict:
    return {"type": "Point", "coordinates": [float(lon), float(lat), float(h)]}


def _feature(what: str, geometry: dict | None, props: dict) -> dict:
    return {"type": "Feature", "geometry": geometry, "properties": {"what": what, **props}}


def _finite(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def locate_packet(source: str, packet, known=None, *, late: bool = False, dem=None, sensor=None,
                  budget=None) -> PacketUpdate:
    """The :class:`PacketUpdate` of ``packet`` (a :class:`~eoloc.io.klv.reader.KLVPacket`).
    ``known``: the same packet with the values it left out (report-on-change) filled in from
    those its stream sent before (default: the packet as it is); the pose comes from it, the
    VMTI targets from ``packet`` alone."""
    from ..io.klv import klv_telemetry, vmti_detections
    from ..io.klv.reader import KLVStream
    from ..misb import frame_geometry, misb_sensor, packet_pose
    from ..video import locate_vmti

    sensor = sensor or misb_sensor()
    known = known or packet
    tel = klv_telemetry(KLVStream(source, "klv", [known]), report_on_change=False)
    c = {k: v[0] for k, v in tel.columns.items()}
    f = known.fields
    name = f.get(10) or f.get(4) or None
    platform = None
    if all(math.isfinite(c[k]) for k in ("lat_deg", "lon_deg", "h_m")):
        platform = {"name": name, "lat_deg": float(c["lat_deg"]), "lon_deg": float(c["lon_deg"]),
                    "h_m": float(c["h_m"]), "heading_deg": _finite(c["yaw_deg"])}
    surface = dem if dem is not None else tel.columns["fc_h_m"]
    centre = footprint = look = None
    if platform is not None:
        from ..footprint import polygon_geometry
        from ..geodesy import geodetic_to_ned

        geom = frame_geometry(sensor, packet_pose(tel), tel.columns["hfov_deg"], tel.columns["vfov_deg"], surface)
        if bool(geom.centre.ok[0]):
            centre = (float(geom.centre.lat_deg[0]), float(geom.centre.lon_deg[0]), float(geom.centre.h_m[0]))
        if dem is not None:  # the image border traced on the terrain, clipped at its edge (as `eoloc klv`)
            from ..video import dem_footprint_features

            footprint = dem_footprint_features(tel, dem, sensor)[0]["geometry"]
        elif bool(np.all(geom.corners.ok[0])):
            k = geom.corners
            footprint = polygon_geometry(k.lon_deg[0], k.lat_deg[0], k.h_m[0])
        look = {"hfov_deg": _finite(c["hfov_deg"]), "vfov_deg": _finite(c["vfov_deg"]),
                "sensor": f.get(11) or None, "range_m": None, "azimuth_deg": None, "elevation_deg": None}
        if centre is not None:
            n, e, d = (float(v) for v in geodetic_to_ned(*centre, platform["lat_deg"], platform["lon_deg"],
                                                          platform["h_m"]))
            look |= {"azimuth_deg": math.degrees(math.atan2(e, n)) % 360.0,
                     "elevation_deg": math.degrees(math.atan2(-d, math.hypot(n, e))),
                     "range_m": float(geom.centre.range_m[0])}
    fixes: list[dict] = []
    cov_enu = None
    det = vmti_detections(KLVStream(source, "klv", [packet]))
    if len(det):
        v = locate_vmti(tel, det, dem, budget=budget, base=sensor)
        extra = with_utc({"stream": det.columns["stream"], **v.extra}, "unix")
        fixes = fix_records(v.fixes, extra, v.uncertainty).rows()
        cov_enu = v.cov_enu
    t = float(c["time_s"])
    iso = utc_times([t], "unix")[0]
    return PacketUpdate(source, packet.stream, packet.index, t, late, platform, look, centre, footprint, fixes,
                        cov_enu, iso)
