"""One live packet worked out: where the aircraft is, where its sensor looks (frame centre,
footprint, look angles) and where each of its VMTI targets is. Every output (NDJSON, CoT, the
map, KLV out) is written from a :class:`PacketUpdate`.

Two drivers of the same kernels, chosen once per session by :class:`PacketLocator`:

- **per ray** (the common case: the frame-centre elevation as the surface, no error budget, no
  lens model): the packet's pose read as plain numbers (:func:`eoloc.io.klv.tables.packet_view`)
  and each of its rays — frame centre, four corners, every VMTI target — put through the
  single-target kernel (:meth:`eoloc.sensor.model.SensorModel.locate_one`, ~1 µs a ray): a packet
  of 20 targets in a fraction of a millisecond, nothing set up per packet but its numbers;
- **per packet as a batch** (a DEM, an error budget): `eoloc klv`'s own functions
  (:func:`eoloc.io.klv.klv_telemetry`, :func:`eoloc.ground.frame.frame_geometry`,
  :func:`eoloc.jobs.klvframes.locate_vmti`) on a one-packet stream.

Both give the same numbers (tests/integration/live/test_live_fast.py holds them to each other and to the batch
path over hostile packets: NaN angles, fields of view out of range, pixels outside the frame,
rays above the horizon), and both build what they report the same way (:func:`platform_of`,
:func:`look_of`, :class:`PacketUpdate`): they differ only in how the rays are stopped."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..io.export import STATUS_NAMES, fix_records, utc_times, with_utc
from ..io.klv.st0601 import Tag
from ..kernels.backend import load_compiled
from ..result import Status
from ..rules import AtHeight


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
    effects: np.ndarray | None = None  # (len(fixes), 3, S) each budget source's 1-sigma effect (m, ENU)
    tau_s: np.ndarray | None = None  # (S,) the sources' correlation times (0 noise, inf bias)

    time_utc: str | None = None  # the time stamp as ISO 8601 UTC
    estimates: list[dict] = field(default_factory=list)  # refined targets (GeoJSON), see live.refine
    _features: list[dict] | None = field(default=None, init=False, repr=False, compare=False)

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
        the packets so far (``what`` "estimate", :mod:`eoloc.live.refine`). Made once (every sink
        reads the same list: do not change it)."""
        if self._features is None:
            self._features = self._make_features()
        return self._features

    def _make_features(self) -> list[dict]:
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


def platform_of(fields: dict, c: dict) -> dict | None:
    """The aircraft of a packet (name, position, heading) from its view ``c``
    (:func:`eoloc.io.klv.tables.packet_view`'s names), None without a position."""
    from ..io.klv.tables import platform_name

    if not all(math.isfinite(c[k]) for k in ("lat_deg", "lon_deg", "h_m")):
        return None
    return {"name": platform_name(fields), "lat_deg": float(c["lat_deg"]), "lon_deg": float(c["lon_deg"]),
            "h_m": float(c["h_m"]), "heading_deg": _finite(c["yaw_deg"])}


def look_of(fields: dict, c: dict, platform: dict, centre: tuple | None, range_m: float) -> dict:
    """The sensor's look (fields of view, sensor name; azimuth, elevation and slant range to the
    frame ``centre`` when there is one), the same whichever driver located the packet."""
    from ..geodesy import look_angles

    look = {"hfov_deg": _finite(c["hfov_deg"]), "vfov_deg": _finite(c["vfov_deg"]),
            "sensor": fields.get(Tag.IMAGE_SOURCE_SENSOR) or None, "range_m": None, "azimuth_deg": None,
            "elevation_deg": None}
    if centre is not None:
        az, el = look_angles(platform["lat_deg"], platform["lon_deg"], platform["h_m"], *centre)
        look |= {"azimuth_deg": az, "elevation_deg": el, "range_m": float(range_m)}
    return look


class PacketLocator:
    """Works out the packets of one live session (:meth:`locate`): the sensor, the surface (a
    ``dem``, else each packet's frame-centre elevation) and the error ``budget`` stay the same
    from packet to packet, and so does the driver (see the module notes)."""

    def __init__(self, *, dem=None, sensor=None, budget=None) -> None:
        from ..ground.frame import misb_sensor
        from ..sensor.camera import Camera

        self.sensor = sensor or misb_sensor()
        self.dem, self.budget = dem, budget
        self.per_ray = dem is None and budget is None and self.sensor.camera.distortion is None
        # the frame's own rays in normalised image coordinates: a camera whose pixels are them
        self.view = replace(self.sensor, camera=Camera(1, 1, 1.0, 1.0, 0.0, 0.0))
        self.frames: dict[tuple, object] = {}  # (hfov, vfov, width, height) -> the VMTI frame's sensor
        load_compiled()  # a live session runs for long: numba loaded now, not in the first packet's time

    def locate(self, source: str, packet, known=None, *, late: bool = False) -> PacketUpdate:
        """The :class:`PacketUpdate` of ``packet`` (a :class:`~eoloc.io.klv.reader.KLVPacket`).
        ``known``: the same packet with the values it left out (report-on-change) filled in from
        those its stream sent before (default: the packet as it is); the pose comes from it, the
        VMTI targets from ``packet`` alone."""
        if not self.per_ray:
            return locate_packet(source, packet, known, late=late, dem=self.dem, sensor=self.sensor,
                                 budget=self.budget)
        from ..ground.frame import CORNERS
        from ..io.klv import vmti_detections
        from ..io.klv.reader import KLVStream
        from ..io.klv.tables import packet_view

        known = known or packet
        f = known.fields
        c = packet_view(f)
        platform = platform_of(f, c)
        roll = c["sensor_roll_deg"]
        pose = (c["lat_deg"], c["lon_deg"], c["h_m"], c["yaw_deg"], c["pitch_deg"], c["roll_deg"],
                c["gimbal1_deg"], c["gimbal2_deg"], 0.0 if math.isnan(roll) else roll)
        surface_h = c["fc_h_m"]
        usable = all(math.isfinite(x) for x in pose) and abs(pose[0]) <= 90.0 and math.isfinite(surface_h)
        ground = AtHeight(surface_h)  # the packet's frame-centre elevation stops its rays
        centre = footprint = look = None
        if platform is not None:
            hfov, vfov = c["hfov_deg"], c["vfov_deg"]
            tx = ty = math.nan
            if 0 < hfov < 180 and 0 < vfov < 180:
                tx, ty = math.tan(math.radians(hfov) / 2.0), math.tan(math.radians(vfov) / 2.0)
            ends = [self._ray(self.view, pose, usable, ground, x, y, in_image=False)
                    for x, y in ((0.0, 0.0), *((cx * tx, cy * ty) for cx, cy in CORNERS))]
            if ends[0][4] == Status.OK:
                centre = ends[0][:3]
            if all(e[4] == Status.OK for e in ends[1:]):
                from ..ground.footprint import polygon_geometry

                k = np.array([e[:3] for e in ends[1:]])
                footprint = polygon_geometry(k[:, 1], k[:, 0], k[:, 2])
            look = look_of(f, c, platform, centre, ends[0][3])
        det = vmti_detections(KLVStream(source, "klv", [packet]))
        fixes = self._targets(det, c, pose, usable, ground) if len(det) else []
        t = c["time_s"]
        return PacketUpdate(source, packet.stream, packet.index, t, late, platform, look, centre, footprint, fixes,
                            time_utc=utc_times([t], "unix")[0])

    @staticmethod
    def _ray(sensor, pose: tuple, usable: bool, ground: AtHeight, u: float, v: float, in_image: bool = True) -> tuple:
        """(lat, lon, h, range, status) of one ray: the pose's pixel (u, v) stopped on ``ground``;
        INVALID_INPUT where the pose, the height or the pixel is not a number (as the batch path);
        ``in_image=False`` for the view sensor, whose pixels are normalised coordinates."""
        if not (usable and math.isfinite(u) and math.isfinite(v)):
            return math.nan, math.nan, math.nan, math.nan, Status.INVALID_INPUT
        return sensor.locate_one(*pose[:8], u, v, rule=ground, g3_deg=pose[8], in_image=in_image)

    def _frame_sensor(self, hfov: float, vfov: float, width: int, height: int):
        """The sensor of a VMTI frame: a pinhole over its size with the given fields of view."""
        key = (hfov, vfov, width, height)
        sensor = self.frames.get(key)
        if sensor is None:
            from ..sensor.camera import Camera

            if len(self.frames) > 64:
                self.frames.clear()
            sensor = self.frames[key] = replace(self.sensor, camera=Camera.from_hfov(hfov, width, height,
                                                                                      vfov_deg=vfov))
        return sensor

    def _targets(self, det, c: dict, pose: tuple, usable: bool, ground: AtHeight) -> list[dict]:
        """The rows of a packet's VMTI targets (the layout of :func:`eoloc.io.export.fix_records`,
        as the batch path writes them): each through its frame's camera, OUT_OF_IMAGE off the
        frame, INVALID_INPUT without a usable field of view or frame size."""
        d = det.columns
        hfov = np.where(np.isfinite(d["vmti_hfov_deg"]), d["vmti_hfov_deg"], c["hfov_deg"])
        vfov = np.where(np.isfinite(d["vmti_vfov_deg"]), d["vmti_vfov_deg"], c["vfov_deg"])
        w, h, u, v = d["frame_width"], d["frame_height"], d["u_px"], d["v_px"]
        ok_frame = np.isfinite(hfov) & np.isfinite(vfov) & (w > 0) & (h > 0) & (hfov > 0) & (hfov < 180) & \
            (vfov > 0) & (vfov < 180)
        outside = np.zeros(len(det), bool)
        sensors = [None] * len(det)  # each target's frame sensor (None: no usable frame)
        for key in {(float(hfov[i]), float(vfov[i]), int(w[i]), int(h[i])) for i in np.flatnonzero(ok_frame)}:
            idx = np.flatnonzero(ok_frame & (hfov == key[0]) & (vfov == key[1]) & (w == key[2]) & (h == key[3]))
            sensor = self._frame_sensor(*key)
            cam = sensor.camera
            outside[idx] = cam.outside(u[idx], v[idx], *cam.pixel_to_normalized(u[idx], v[idx]))
            for i in idx:
                sensors[i] = sensor
        iso = utc_times(d["time_s"], "unix")
        rows = []
        for i in range(len(det)):
            if sensors[i] is None:
                fix = (math.nan, math.nan, math.nan, math.nan, Status.INVALID_INPUT)
            elif outside[i] and usable:
                fix = (math.nan, math.nan, math.nan, math.nan, Status.OUT_OF_IMAGE)
            else:
                fix = self._ray(sensors[i], pose, usable, ground, float(u[i]), float(v[i]))
            status = int(fix[4])
            good = status == Status.OK
            rows.append({"stream": str(d["stream"][i]), "frame": int(d["frame"][i]), "time_s": _finite(d["time_s"][i]),
                         "time_utc": iso[i], "target_id": str(d["target_id"][i]), "u_px": float(u[i]),
                         "v_px": float(v[i]), "lat_deg": fix[0] if good else None, "lon_deg": fix[1] if good else None,
                         "h_m": fix[2] if good else None, "range_m": fix[3] if good else None,
                         "status": STATUS_NAMES[status]})
        return rows


def locate_packet(source: str, packet, known=None, *, late: bool = False, dem=None, sensor=None,
                  budget=None) -> PacketUpdate:
    """:meth:`PacketLocator.locate` by `eoloc klv`'s own functions on a one-packet stream (the
    batch driver: any surface, with or without an error budget)."""
    from ..ground.frame import frame_geometry, misb_sensor, packet_heights, packet_pose
    from ..io.klv import klv_telemetry, vmti_detections
    from ..io.klv.reader import KLVStream
    from ..jobs.klvframes import locate_vmti
    from ..rules import OnDEM

    sensor = sensor or misb_sensor()
    known = known or packet
    tel = klv_telemetry(KLVStream(source, "klv", [known]), report_on_change=False)
    c = {k: v[0] for k, v in tel.columns.items()}
    f = known.fields
    platform = platform_of(f, c)
    ground = OnDEM(dem) if dem is not None else packet_heights(tel.columns["fc_h_m"])
    centre = footprint = look = None
    if platform is not None:
        from ..ground.footprint import polygon_geometry

        geom = frame_geometry(sensor, packet_pose(tel), tel.columns["hfov_deg"], tel.columns["vfov_deg"], ground)
        if bool(geom.centre.ok[0]):
            centre = (float(geom.centre.lat_deg[0]), float(geom.centre.lon_deg[0]), float(geom.centre.h_m[0]))
        if dem is not None:  # the image border traced on the terrain, clipped at its edge (as `eoloc klv`)
            from ..jobs.klvframes import dem_footprint_features

            footprint = dem_footprint_features(tel, dem, sensor)[0]["geometry"]
        elif bool(np.all(geom.corners.ok[0])):
            k = geom.corners
            footprint = polygon_geometry(k.lon_deg[0], k.lat_deg[0], k.h_m[0])
        look = look_of(f, c, platform, centre, float(geom.centre.range_m[0]))
    fixes: list[dict] = []
    cov_enu = effects = tau = None
    det = vmti_detections(KLVStream(source, "klv", [packet]))
    if len(det):
        v = locate_vmti(tel, det, ground if dem is not None else None, budget=budget, base=sensor)
        extra = with_utc({"stream": det.columns["stream"], **v.extra}, "unix")
        fixes = fix_records(v.fixes, extra, v.uncertainty).rows()
        cov_enu, effects, tau = v.cov_enu, v.effects, v.tau_s
    t = float(c["time_s"])
    iso = utc_times([t], "unix")[0]
    return PacketUpdate(source, packet.stream, packet.index, t, late, platform, look, centre, footprint, fixes,
                        cov_enu, effects, tau, iso)
