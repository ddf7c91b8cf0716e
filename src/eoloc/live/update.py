"""One live packet worked out: where the aircraft is, where its sensor looks (frame centre,
footprint, look angles) and where each of its VMTI targets is. Every output (NDJSON, CoT, the
map, KLV out) is written from a :class:`PacketUpdate`.

One driver, :class:`PacketLocator`, whatever the ground (each packet's frame-centre elevation or
a DEM) and with or without an error budget: the packet's pose read as plain numbers
(:func:`eoloc.io.klv.tables.packet_view`), its rays — frame centre, four corners, every VMTI
target — stopped by the ground's rule (one by one through the single-target kernel,
:meth:`eoloc.sensor.model.SensorModel.locate_one`, ~1 µs a ray, where the rule has one: a packet
of 20 targets in a fraction of a millisecond; in one array call on a DEM), the rows written by
the batch's own writer. It gives `eoloc klv`'s numbers (tests/integration/live/test_live_fast.py
holds it to the batch functions — :func:`eoloc.io.klv.klv_telemetry`,
:func:`eoloc.ground.frame.frame_geometry`, :func:`eoloc.jobs.klvframes.locate_vmti` — on every
ground, with and without a budget, over real streams and hostile packets: NaN angles, fields of
view out of range, pixels outside the frame, rays above the horizon)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..io.export import fix_records, utc_times
from ..io.klv.st0601 import Tag
from ..kernels.backend import load_compiled
from ..result import Fixes, Status
from ..rules import AtHeight, OnDEM


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
    movers: list[dict] = field(default_factory=list)  # movers found in one video frame (GeoJSON), see live.movers
    name: str | None = None  # the platform's name where ``platform`` is not given (a movers' update)
    view: dict | None = field(default=None, repr=False, compare=False)  # the packet's pose (packet_view)
    _features: list[dict] | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def kind(self) -> str:
        """"packet" (one KLV packet's results), or "movers" (the movers of one video frame, no packet)."""
        return "movers" if self.movers and self.platform is None and not self.fixes else "packet"

    @property
    def key(self) -> str:
        """A name for the platform's things that stays the same packet after packet (CoT uids,
        map layers): the platform designation, else the stream."""
        name = (self.platform or {}).get("name") or self.name or self.stream or "stream"
        return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)

    def features(self) -> list[dict]:
        """GeoJSON features (RFC 7946: lon, lat, h): the aircraft, the footprint and the frame
        centre when known, and every target (a failed one with a null geometry); each with
        ``what``, ``stream``, ``packet`` and ``time_utc`` properties; then the targets refined over
        the packets so far (``what`` "estimate", :mod:`eoloc.live.refine`) and the movers found in
        the video (``what`` "mover", :mod:`eoloc.live.movers`). Made once (every sink
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
        return out + self.estimates + self.movers


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
    """Works out the packets of one live session (:meth:`locate`): the sensor, the ground (a
    ``dem``, else each packet's frame-centre elevation) and the error ``budget`` stay the same
    from packet to packet.

    One driver for every ground: a packet's pose is read as plain numbers
    (:func:`eoloc.io.klv.tables.packet_view`), its rays — the frame centre, the four corners and
    every VMTI target, in normalised image coordinates — are stopped together by the ground's
    rule (:meth:`_stop`: a rule with a single-target kernel takes them one by one, ~1 µs a ray;
    a DEM all of them in one array call), and the rows are written by the batch's own writer
    (:func:`eoloc.io.export.fix_records`). On a DEM the footprint is the image border traced on
    the terrain (:func:`eoloc.ground.footprint.footprints`, as `eoloc klv`); with a ``budget`` each
    target's covariance comes with its fix (one call per VMTI frame camera)."""

    def __init__(self, *, dem=None, sensor=None, budget=None) -> None:
        from ..ground.frame import FrameSensors, misb_sensor
        from ..sensor.camera import Camera

        self.sensor = sensor or misb_sensor()
        self.terrain = None if dem is None else OnDEM(dem)  # None: each packet's frame-centre elevation
        self.budget = budget
        # the frame's own rays in normalised image coordinates: a camera whose pixels are them
        self.view = replace(self.sensor, camera=Camera(1, 1, 1.0, 1.0, 0.0, 0.0))
        self.frames = FrameSensors(self.sensor)  # the VMTI frames' sensors
        load_compiled()  # a live session runs for long: numba loaded now, not in the first packet's time

    def locate(self, source: str, packet, known=None, *, late: bool = False) -> PacketUpdate:
        """The :class:`PacketUpdate` of ``packet`` (a :class:`~eoloc.io.klv.reader.KLVPacket`).
        ``known``: the same packet with the values it left out (report-on-change) filled in from
        those its stream sent before (default: the packet as it is); the pose comes from it, the
        VMTI targets from ``packet`` alone."""
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
        # without a DEM the frame-centre elevation stops the rays
        ground = self.terrain if self.terrain is not None else AtHeight(c["fc_h_m"])
        usable = all(math.isfinite(x) for x in pose) and abs(pose[0]) <= 90.0 and \
            (self.terrain is not None or math.isfinite(c["fc_h_m"]))
        det = vmti_detections(KLVStream(source, "klv", [packet]))
        targets = self._target_rays(det, c, usable)
        hfov, vfov = c["hfov_deg"], c["vfov_deg"]
        tx = ty = math.nan
        if 0 < hfov < 180 and 0 < vfov < 180:
            tx, ty = math.tan(math.radians(hfov) / 2.0), math.tan(math.radians(vfov) / 2.0)
        # the packet's rays: the frame centre and the four corners (with the aircraft), then its targets
        xn = np.array([0.0, *(CORNERS[:, 0] * tx)] if platform is not None else [])
        yn = np.array([0.0, *(CORNERS[:, 1] * ty)] if platform is not None else [])
        n_frame = xn.size
        if self.budget is None:
            xn, yn = np.concatenate([xn, targets.xn]), np.concatenate([yn, targets.yn])
        ends = self._stop(pose, usable, ground, xn, yn)
        centre = footprint = look = None
        if platform is not None:
            if ends.status[0] == Status.OK:
                centre = (float(ends.lat_deg[0]), float(ends.lon_deg[0]), float(ends.h_m[0]))
            footprint = self._footprint(pose, hfov, vfov, ends.flat(slice(1, n_frame)))
            look = look_of(f, c, platform, centre, float(ends.range_m[0]))
        iso = utc_times(np.concatenate([[c["time_s"]], det.columns["time_s"]]), "unix")  # one call: ~25 µs each
        update = PacketUpdate(source, packet.stream, packet.index, c["time_s"], late, platform, look, centre, footprint,
                              time_utc=iso[0], view=c)
        if len(det):
            self._fixes(update, det, iso[1:], targets, ends.flat(slice(n_frame, None)), pose, usable, ground)
        return update

    def _stop(self, pose: tuple, usable: bool, ground, xn: np.ndarray, yn: np.ndarray) -> Fixes:
        """The rays of normalised image coordinates (xn, yn) from ``pose`` stopped by ``ground``:
        one by one through the single-target kernel where the rule has one, else in one array
        call; INVALID_INPUT for all where the pose (or the height it needs) is not usable, and for
        each ray whose coordinates are not numbers (as the batch path)."""
        n = xn.size
        out = Fixes(*(np.full(n, np.nan) for _ in range(4)), np.full(n, int(Status.INVALID_INPUT), np.int8))
        todo = np.flatnonzero(np.isfinite(xn) & np.isfinite(yn)) if usable else np.zeros(0, np.intp)
        if not todo.size:
            return out
        if ground.scalar_stop() is not None:
            one = self.view.locate_one
            got = np.array([one(*pose[:8], x, y, rule=ground, g3_deg=pose[8], in_image=False)
                            for x, y in zip(xn[todo].tolist(), yn[todo].tolist(), strict=True)]).T
        else:
            from ..ground.frame import packet_rays, stop_on
            from ..sensor.model import Pose

            f = stop_on(packet_rays(self.view, Pose(*pose[:6], pose[6:]), xn[todo], yn[todo]), ground, self.view)
            got = (f.lat_deg, f.lon_deg, f.h_m, f.range_m, f.status)
        for name, values in zip(("lat_deg", "lon_deg", "h_m", "range_m", "status"), got, strict=True):
            getattr(out, name)[todo] = values
        return out

    def _footprint(self, pose: tuple, hfov: float, vfov: float, corners: Fixes) -> dict | None:
        """The frame's footprint as a GeoJSON geometry: on a DEM the image border traced on the
        terrain and clipped at its edge or the horizon (as `eoloc klv`), else the four corners
        when all four reached the ground."""
        from ..ground.footprint import footprints, polygon_geometry

        if self.terrain is None:
            ok = bool(np.all(corners.status == Status.OK))
            return polygon_geometry(corners.lon_deg, corners.lat_deg, corners.h_m) if ok else None
        if not (0 < hfov < 180 and 0 < vfov < 180):
            return None
        from ..sensor.model import Pose

        traced = footprints(self._frame_sensor(hfov, vfov, 1000, 1000), Pose(*pose[:6], pose[6:]), self.terrain,
                            edge_samples=8)
        return traced[0].geojson_geometry()

    def _frame_sensor(self, hfov: float, vfov: float, width: int, height: int):
        """The sensor of a VMTI frame: a pinhole over its size with the given fields of view."""
        return self.frames.get(width, height, hfov, vfov)

    def _target_rays(self, det, c: dict, usable: bool) -> TargetRays:
        """The VMTI targets' rays: each pixel through its frame's camera to normalised image
        coordinates; INVALID_INPUT without a usable field of view or frame size, OUT_OF_IMAGE off
        the frame (where the pose is usable), as the batch path decides them."""
        from ..jobs.klvframes import camera_groups

        d = det.columns
        n = len(det)
        hfov = np.where(np.isfinite(d["vmti_hfov_deg"]), d["vmti_hfov_deg"], c["hfov_deg"])
        vfov = np.where(np.isfinite(d["vmti_vfov_deg"]), d["vmti_vfov_deg"], c["vfov_deg"])
        w, h, u, v = d["frame_width"], d["frame_height"], d["u_px"], d["v_px"]
        framed = np.isfinite(hfov) & np.isfinite(vfov) & (w > 0) & (h > 0) & (hfov > 0) & (hfov < 180) & \
            (vfov > 0) & (vfov < 180)
        xn, yn = np.full(n, np.nan), np.full(n, np.nan)
        status = np.where(framed, -1, int(Status.INVALID_INPUT)).astype(np.int8)  # -1: to be located
        groups = []
        for key, idx in camera_groups(hfov, vfov, w, h, framed):
            cam = self._frame_sensor(*key).camera
            xn[idx], yn[idx] = cam.pixel_to_normalized(u[idx], v[idx])
            if usable:
                status[idx[cam.outside(u[idx], v[idx], xn[idx], yn[idx])]] = int(Status.OUT_OF_IMAGE)
            groups.append((key, idx))
        todo = status == -1
        return TargetRays(np.where(todo, xn, np.nan), np.where(todo, yn, np.nan), status, groups)

    def _fixes(self, update: PacketUpdate, det, time_utc: np.ndarray, targets: TargetRays, stopped: Fixes,
               pose: tuple, usable: bool, ground) -> None:
        """``update``'s target rows (the layout of `eoloc klv`'s fixes) from the ``stopped`` rays,
        or with the error budget from one call per frame camera that gives each fix its
        covariance (and each budget source's effect on it)."""
        n = len(det)
        d = det.columns
        status = targets.status.copy()
        unc: dict[str, np.ndarray] = {}
        if self.budget is None:
            fixes = stopped
            status[status == -1] = stopped.status[status == -1]
        else:
            from ..accuracy.covariance import CovarianceRows

            fixes = Fixes(*(np.full(n, np.nan) for _ in range(4)), status)
            if not usable:
                status[status == -1] = int(Status.INVALID_INPUT)
            covs = CovarianceRows(n)
            for key, idx in targets.groups:  # every framed target, as the batch locates them
                self._covariance(covs, fixes, self._frame_sensor(*key), pose, ground, idx, d["u_px"][idx],
                                 d["v_px"][idx])
            unc = covs.columns
            update.cov_enu, update.effects, update.tau_s = covs.cov_enu, covs.effects, covs.tau_s
        ok = status == Status.OK
        located = Fixes(*(np.where(ok, x, np.nan) for x in (fixes.lat_deg, fixes.lon_deg, fixes.h_m, fixes.range_m)),
                        status)
        extra = {"stream": d["stream"], "frame": d["frame"].astype(np.int64), "time_s": d["time_s"],
                 "time_utc": time_utc, "target_id": d["target_id"], "u_px": d["u_px"], "v_px": d["v_px"]}
        update.fixes = fix_records(located, extra, unc).rows()

    def _covariance(self, covs, fixes: Fixes, sensor, pose: tuple, ground, idx: np.ndarray, u: np.ndarray,
                    v: np.ndarray) -> None:
        """The targets ``idx`` of one frame camera located with their covariance (into ``fixes`` and
        ``covs``, a :class:`~eoloc.accuracy.covariance.CovarianceRows`); a status decided before
        (``fixes.status`` not -1) stands."""
        from ..jobs.tables import locate_by_rule
        from ..sensor.model import Pose

        m = idx.size
        p = Pose(*(np.full(m, x) for x in pose[:6]), tuple(np.full(m, x) for x in pose[6:]))
        f, cov = locate_by_rule(sensor, p, (u, v), ground, budget=self.budget)
        for name in ("lat_deg", "lon_deg", "h_m", "range_m"):
            getattr(fixes, name)[idx] = getattr(f, name)
        decided = fixes.status[idx] != -1  # no frame, off the frame, or a pose that cannot be used
        fixes.status[idx] = np.where(decided, fixes.status[idx], f.status)
        covs.put(idx, cov, fixes.status[idx] == Status.OK)


@dataclass(frozen=True)
class TargetRays:
    """A packet's VMTI targets as rays: normalised image coordinates (NaN where the target is not
    to be located), the status decided before any ray is stopped (-1: to be located) and the
    targets of each frame camera ((hfov, vfov, width, height), indices)."""

    xn: np.ndarray
    yn: np.ndarray
    status: np.ndarray
    groups: list
