"""The KLV job: ST 0601 telemetry + ST 0903 detections -> frame checks, footprints and target fixes.

In memory only (tables in, arrays and GeoJSON features out); :mod:`eoloc.io.klv` reads the
stream and the CLI writes the files.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..geodesy import horizontal_distance_m
from ..ground.footprint import polygon_geometry
from ..ground.frame import FrameGeometry, frame_geometry, frame_sensor, misb_sensor, packet_heights, packet_pose
from ..io.records import Records
from ..io.table import Table
from ..result import Fixes, Status
from ..rules import AtHeight, OnDEM, StopRule
from ..sensor.model import Pose, SensorModel
from .tables import locate_by_rule

if TYPE_CHECKING:
    from ..accuracy.budget import ErrorBudget
    from ..io.geotable import WKBColumn


@dataclass(frozen=True)
class FrameCheck:
    """eoloc's frame centre and corners against the encoder's, per packet (metres, NaN where
    either side has no point)."""

    geometry: FrameGeometry
    centre_m: np.ndarray  # (F,) horizontal distance, ours vs the encoder's frame centre
    corners_m: np.ndarray  # (F, 4)
    range_m: np.ndarray  # (F,) our slant range to the centre minus tag 21's

    def stats(self, rows: np.ndarray | None = None) -> list[tuple[str, int, float, float, float]]:
        """(what, n, median, p90, max) for the centre, each corner and |slant range difference|,
        over all packets or the boolean ``rows`` (one stream)."""
        sel = slice(None) if rows is None else rows
        cols = [("frame centre", self.centre_m[sel])] + [(f"corner {k + 1}", self.corners_m[sel, k])
                                                          for k in range(4)]
        cols.append(("slant range (|ours - tag 21|)", np.abs(self.range_m[sel])))
        out = []
        for name, d in cols:
            d = d[np.isfinite(d)]
            out.append((name, int(d.size), *(
                (float(np.median(d)), float(np.percentile(d, 90)), float(d.max())) if d.size else (np.nan,) * 3)))
        return out


def check_frames(tel: Table, ground: StopRule | None = None, *, sensor: SensorModel | None = None) -> FrameCheck:
    """Recompute every packet's frame centre and corners and compare them with the encoder's.

    ground: a stop rule (OnDEM), or None for the ellipsoid at the encoder's own frame-centre elevation (tag 78,
    or tag 25 + geoid) of each packet; the encoder's choice of terrain then cancels out and what
    is left is the pointing model (rotation order, angle conventions, FOV).
    """
    c = tel.columns
    sensor = sensor or misb_sensor()
    geom = frame_geometry(sensor, packet_pose(tel), c["hfov_deg"], c["vfov_deg"],
                          packet_heights(c["fc_h_m"]) if ground is None else ground)
    centre = horizontal_distance_m(geom.centre.lat_deg, geom.centre.lon_deg, c["fc_lat_deg"], c["fc_lon_deg"])
    corners = np.stack([horizontal_distance_m(geom.corners.lat_deg[:, k], geom.corners.lon_deg[:, k],
                                              c[f"corner{k + 1}_lat_deg"], c[f"corner{k + 1}_lon_deg"])
                        for k in range(4)], -1)
    with np.errstate(invalid="ignore"):
        rng = np.where(c["range_m"] > 0, geom.centre.range_m - c["range_m"], np.nan)
    return FrameCheck(geom, centre, corners, rng)


def corner_footprint_features(tel: Table, geom: FrameGeometry | None = None, every: int = 1) -> list[dict]:
    """Frame footprints by their four corners as GeoJSON polygons: eoloc's (``geom``) or, with geom
    None, the encoder's corner tags. Frames with a missing corner get a null geometry."""
    c = tel.columns
    feats = []
    for i in range(0, len(tel), max(every, 1)):
        if geom is None:
            lat = np.array([c[f"corner{k + 1}_lat_deg"][i] for k in range(4)])
            lon = np.array([c[f"corner{k + 1}_lon_deg"][i] for k in range(4)])
            h = np.full(4, c["fc_h_m"][i])
        else:
            lat, lon, h = geom.corners.lat_deg[i], geom.corners.lon_deg[i], geom.corners.h_m[i]
        ok = bool(np.all(np.isfinite(lat) & np.isfinite(lon)))
        geometry = polygon_geometry(lon, lat, np.where(np.isfinite(h), h, 0.0)) if ok else None
        feats.append({"type": "Feature", "geometry": geometry,
                      "properties": _frame_properties(tel, i)})
    return feats


def corner_footprint_table(tel: Table, geom: FrameGeometry | None = None, every: int = 1, first: int = 0
                           ) -> tuple[Records, WKBColumn]:
    """:func:`corner_footprint_features` as a table for the archive: the properties as columns
    (frame, time_s and stream where there is one, as the features carry them) and the polygons as
    a column of WKB (:class:`eoloc.io.geotable.WKBColumn`, null where a corner is missing), built
    with numpy.
    The rings :func:`eoloc.ground.footprint.polygon_geometry` would build the same way (within
    10 degrees of longitude, away from the poles and the antimeridian) are oriented by their
    planar signed area; the others (and near-degenerate ones) go through it one by one. ``first``:
    the first row drawn (every ``every``-th from it: a segment of a longer stream)."""
    from shapely.geometry import shape

    from ..io.geotable import ring_wkb

    c = tel.columns
    rows = np.arange(first, len(tel), max(every, 1))
    if geom is None:
        lat = np.stack([c[f"corner{k + 1}_lat_deg"][rows] for k in range(4)], -1)
        lon = np.stack([c[f"corner{k + 1}_lon_deg"][rows] for k in range(4)], -1)
        h = np.repeat(c["fc_h_m"][rows][:, None], 4, axis=1)
    else:
        lat, lon, h = geom.corners.lat_deg[rows], geom.corners.lon_deg[rows], geom.corners.h_m[rows]
    h = np.where(np.isfinite(h), h, 0.0)
    ok = np.all(np.isfinite(lat) & np.isfinite(lon), axis=1)
    with np.errstate(invalid="ignore"):
        span_lon, span_lat = np.ptp(lon, axis=1), np.ptp(lat, axis=1)
        twice_area = np.sum(lon * np.roll(lat, -1, axis=1) - np.roll(lon, -1, axis=1) * lat, axis=1)
        simple = ok & (span_lon < 10.0) & (np.abs(lon).max(axis=1) < 170.0) & (np.abs(lat).max(axis=1) < 80.0) & \
            (np.abs(twice_area) > 1e-6 * (span_lon ** 2 + span_lat ** 2))
    ring = np.stack([lon, lat, h], -1)
    ring = np.where((twice_area < 0)[:, None, None], ring[:, ::-1], ring)  # counter-clockwise, as RFC 7946 wants
    ring = np.round(np.concatenate([ring, ring[:, :1]], axis=1), 10)  # closed; as the GeoJSON rings are rounded
    others = np.full(rows.size, None, dtype=object)
    for j in np.flatnonzero(ok & ~simple):
        others[j] = shape(polygon_geometry(lon[j], lat[j], h[j]))
    geoms = ring_wkb(ring, simple, others)
    time_s = c["time_s"][rows]
    props: dict[str, np.ndarray] = {"frame": np.asarray(tel.line)[rows].astype(np.int64),
                                    "time_s": np.where(np.isfinite(time_s), time_s, np.nan)}
    if "stream" in c and np.any(c["stream"][rows] != ""):
        names = c["stream"][rows]
        props["stream"] = np.where(names != "", names.astype(object), None)
    return Records(props), geoms


def dem_footprint_features(tel: Table, dem, sensor: SensorModel | None = None, every: int = 1,
                           edge_samples: int = 8, first: int = 0) -> list[dict]:
    """Frame footprints on a DEM (image border traced and clipped at the DEM's edge or the horizon,
    :func:`eoloc.ground.footprint.footprints`), one batched call per distinct field of view; every
    ``every``-th row from row ``first``."""
    from ..ground.footprint import footprints

    base = sensor or misb_sensor()
    c = tel.columns
    rows = np.arange(first, len(tel), max(every, 1))
    feats: dict[int, dict] = {}
    groups: dict[tuple[float, float], list[int]] = {}
    for i in rows:
        groups.setdefault((float(c["hfov_deg"][i]), float(c["vfov_deg"][i])), []).append(int(i))
    pose_all = packet_pose(tel)
    for (hf, vf), idx in groups.items():
        geometry: list = [None] * len(idx)
        if 0 < hf < 180 and 0 < vf < 180:
            sensor_g = frame_sensor(base, hf, vf, 1000, 1000)
            geometry = [fp.geojson_geometry() for fp in footprints(sensor_g, pose_all.take(np.asarray(idx)), OnDEM(dem),
                                                                   edge_samples=edge_samples)]
        for i, g in zip(idx, geometry, strict=True):
            feats[i] = {"type": "Feature", "geometry": g,
                        "properties": _frame_properties(tel, i)}
    return [feats[i] for i in rows]


def aircraft_features(tel: Table) -> list[dict]:
    """One aircraft path per stream (a KLV PID; the whole table when it has no stream column)."""
    if "stream" not in tel.columns:
        return [aircraft_feature(tel)]
    s = tel.columns["stream"]
    return [aircraft_feature(tel, s == name, name) for name in dict.fromkeys(s)]


def aircraft_feature(tel: Table, rows: np.ndarray | None = None, stream: str | None = None) -> dict:
    """The aircraft path as one GeoJSON LineString (lon, lat, ellipsoidal h) with coordTimes, over
    all rows or the boolean ``rows`` of one ``stream``."""
    c = tel.columns
    ok = np.isfinite(c["lat_deg"]) & np.isfinite(c["lon_deg"]) & np.isfinite(c["h_m"])
    if rows is not None:
        ok &= rows
    coords = [[float(a), float(b), float(z)] for a, b, z in zip(c["lon_deg"][ok], c["lat_deg"][ok], c["h_m"][ok],
                                                                strict=True)]
    geom = {"type": "LineString", "coordinates": coords} if len(coords) > 1 else None
    return {"type": "Feature", "geometry": geom,
            "properties": {"what": "aircraft", **({"stream": stream} if stream else {}),
                           "coordTimes": [_finite(t) for t in c["time_s"][ok]]}}


@dataclass(frozen=True)
class VMTIFixes:
    """Located VMTI detections: fixes (N,), per-target columns, covariance columns (or {}), and
    the covariance itself (N, 3, 3) ENU m^2 when a budget gave one (NaN for the fixes without),
    with its structure: ``effects`` (N, 3, S) each budget source's 1-sigma effect on each fix (m,
    ENU) and ``tau_s`` (S,) their correlation times (:class:`eoloc.accuracy.FixCovariance`)."""

    fixes: Fixes
    extra: dict[str, np.ndarray]
    uncertainty: dict[str, np.ndarray]
    cov_enu: np.ndarray | None = None
    effects: np.ndarray | None = None
    tau_s: np.ndarray | None = None


def vmti_frames(tel: Table, det: Table):
    """Each detection's packet: (row of ``tel``, found, horizontal and vertical field of view — the
    VMTI set's (tags 11, 12), else the packet's (16, 17) — and usable: found with a field of view
    in (0, 180) degrees and a frame size)."""
    n = len(det)
    frames = det.columns["frame"].astype(np.int64)
    by_packet = np.argsort(tel.line, kind="stable")  # rows are grouped by stream and in time order
    pos = np.clip(np.searchsorted(tel.line[by_packet], frames), 0, max(len(tel) - 1, 0))
    row = by_packet[pos] if len(tel) else pos
    found = tel.line[row] == frames if len(tel) else np.zeros(n, bool)
    d, c = det.columns, tel.columns
    hfov = np.where(np.isfinite(d["vmti_hfov_deg"]), d["vmti_hfov_deg"], c["hfov_deg"][row])
    vfov = np.where(np.isfinite(d["vmti_vfov_deg"]), d["vmti_vfov_deg"], c["vfov_deg"][row])
    w, h = d["frame_width"], d["frame_height"]
    usable = found & np.isfinite(hfov) & np.isfinite(vfov) & (w > 0) & (h > 0) & (hfov > 0) & (hfov < 180) & \
        (vfov > 0) & (vfov < 180)
    return row, found, hfov, vfov, usable


def camera_groups(hfov: np.ndarray, vfov: np.ndarray, w: np.ndarray, h: np.ndarray, rows: np.ndarray
                  ) -> list[tuple[tuple[float, float, int, int], np.ndarray]]:
    """The ``rows`` (a mask) grouped by camera: ((hfov, vfov, width, height), their indices), groups
    in order of their first row."""
    idx = np.flatnonzero(rows)
    if not idx.size:
        return []
    keys = np.stack([hfov[idx], vfov[idx], np.trunc(w[idx]), np.trunc(h[idx])], -1)
    if (keys == keys[0]).all():  # one camera (the common case: no sort)
        return [((float(keys[0, 0]), float(keys[0, 1]), int(keys[0, 2]), int(keys[0, 3])), idx)]
    uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    return [((float(uniq[g, 0]), float(uniq[g, 1]), int(uniq[g, 2]), int(uniq[g, 3])), idx[inverse == g])
            for g in np.argsort(first, kind="stable")]


def locate_vmti(tel: Table, det: Table, ground: StopRule | None = None, *, budget: ErrorBudget | None = None,
                base: SensorModel | None = None) -> VMTIFixes:
    """Geolocate VMTI detections with their own packet's pose and field of view.

    ground: a stop rule (OnDEM), or None for the ellipsoid at the packet's frame-centre elevation. The image
    geometry of a detection is a pinhole over the VMTI frame size with the VMTI set's FOV (tags
    11, 12) or else the packet's (tags 16, 17). With an error ``budget`` each fix gets its
    first-order covariance; fixes are computed per distinct (size, FOV) group, one batched call each.
    """
    base = base or misb_sensor()
    n = len(det)
    row, found, hfov, vfov, usable = vmti_frames(tel, det)
    d, c = det.columns, tel.columns
    w, h = d["frame_width"], d["frame_height"]
    lat, lon, hh, rng = (np.full(n, np.nan) for _ in range(4))
    status = np.full(n, int(Status.NO_TELEMETRY), dtype=np.int8)
    covs = None  # CovarianceRows, with a budget
    pose_all = packet_pose(tel).take(row) if n else None
    status[found & ~usable] = int(Status.INVALID_INPUT)
    for (hf, vf, wi, hi), idx in camera_groups(hfov, vfov, w, h, usable):
        sensor = frame_sensor(base, hf, vf, wi, hi)
        pose = pose_all.take(idx)
        rule = ground if ground is not None else AtHeight(np.nan_to_num(c["fc_h_m"][row[idx]]))
        fixes, cov = locate_by_rule(sensor, pose, (d["u_px"][idx], d["v_px"][idx]), rule, budget=budget)
        st = np.asarray(fixes.status).copy()
        if ground is None:
            st[~np.isfinite(c["fc_h_m"][row[idx]])] = int(Status.INVALID_INPUT)
        ok = st == Status.OK
        lat[idx], lon[idx], hh[idx], rng[idx] = (np.where(ok, x, np.nan) for x in
                                                 (fixes.lat_deg, fixes.lon_deg, fixes.h_m, fixes.range_m))
        status[idx] = st
        if cov is not None:
            if covs is None:
                from ..accuracy.covariance import CovarianceRows  # scipy (1.2 s): only when a budget asks for it

                covs = CovarianceRows(n)
            covs.put(idx, cov, ok)
    extra = {"frame": d["frame"].astype(np.int64), "time_s": d["time_s"], "target_id": d["target_id"],
             "u_px": d["u_px"], "v_px": d["v_px"]}
    if covs is None:
        return VMTIFixes(Fixes(lat, lon, hh, rng, status), extra, {}, None, None, None)
    return VMTIFixes(Fixes(lat, lon, hh, rng, status), extra, covs.columns, covs.cov_enu, covs.effects, covs.tau_s)


def _frame_properties(tel: Table, i: int) -> dict:
    c = tel.columns
    props = {"frame": int(tel.line[i]), "time_s": _finite(c["time_s"][i])}
    if "stream" in c and c["stream"][i]:
        props["stream"] = str(c["stream"][i])
    return props


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


@dataclass(frozen=True)
class VMTIFlight:
    """The located-able VMTI detections of a stream as one batch for the error analysis: one camera
    (the frame size the stream's VMTI sets give, the first usable field of view) and each
    detection's zoom as its pose's ``focal_scale``; the stop rule with one value per detection on
    the frame-centre elevation; ``index`` the detections' rows in ``det``."""

    sensor: SensorModel
    pose: object
    pixels: tuple[np.ndarray, np.ndarray]
    rule: object
    time_s: np.ndarray
    target_id: np.ndarray
    index: np.ndarray


def vmti_flight(tel: Table, det: Table, ground: StopRule | None = None, *,
                base: SensorModel | None = None) -> VMTIFlight:
    """:class:`VMTIFlight` of the detections (as :func:`locate_vmti` pairs them with their packets).
    A stream whose VMTI frames differ in size or aspect is refused (a KLVError naming both)."""
    from ..errors import KLVError

    base = base or misb_sensor()
    d, c = det.columns, tel.columns
    row, _, hfov, vfov, usable = vmti_frames(tel, det)
    w, h = d["frame_width"], d["frame_height"]
    if ground is None:
        usable &= np.isfinite(c["fc_h_m"][row])
    idx = np.flatnonzero(usable)
    if idx.size == 0:
        raise KLVError("no VMTI detection with its packet's pose, a field of view and a frame size: nothing to "
                       "analyse")
    sizes = {(int(w[i]), int(h[i])) for i in idx}
    if len(sizes) > 1:
        raise KLVError(f"the stream's VMTI frames have several sizes ({', '.join(f'{a}x{b}' for a, b in sorted(sizes))}"
                       "): the accuracy of a flight takes one camera")
    tx, ty = np.tan(np.radians(hfov[idx]) / 2.0), np.tan(np.radians(vfov[idx]) / 2.0)
    scale, scale_y = tx[0] / tx, ty[0] / ty
    if not np.allclose(scale, scale_y, rtol=1e-6):
        raise KLVError("the VMTI frames' horizontal and vertical fields of view do not zoom together (the aspect "
                       "changes): the accuracy of a flight takes one camera")
    (wi, hi), = sizes
    sensor = frame_sensor(base, float(hfov[idx[0]]), float(vfov[idx[0]]), wi, hi)
    p = packet_pose(tel).take(row[idx])
    pose = Pose(p.lat_deg, p.lon_deg, p.h_m, p.yaw_deg, p.pitch_deg, p.roll_deg, p.gimbal_deg, scale)
    rule = ground if ground is not None else AtHeight(c["fc_h_m"][row[idx]])
    return VMTIFlight(sensor, pose, (d["u_px"][idx], d["v_px"][idx]), rule, d["time_s"][idx],
                      np.asarray(d["target_id"])[idx].astype(str), idx)


#: The ST 0601 items behind each input of a VMTI fix, as :func:`explain_vmti` names them.
KLV_NAMES = {"lat_deg": "the sensor latitude (tag 13)", "lon_deg": "the sensor longitude (tag 14)",
             "h_m": "the sensor height (tag 75, or 15 + geoid)", "yaw_deg": "the platform heading (tag 5)",
             "pitch_deg": "the platform pitch (tag 6)", "roll_deg": "the platform roll (tag 7)",
             "gimbal1": "the sensor relative azimuth (tag 18)", "gimbal2": "the sensor relative elevation (tag 19)",
             "gimbal3": "the sensor relative roll (tag 20)", "u_px": "the target's pixel (ST 0903 centroid)",
             "v_px": "the target's pixel (ST 0903 centroid)"}


def explain_vmti(tel: Table, det: Table, fixes: Fixes, ground: StopRule | None = None) -> str | None:
    """One line when most VMTI detections failed for one reason, naming the KLV items at fault: a
    stream without a frame-centre elevation (tags 78, 25) located without --dem, no field of view,
    no frame size, no matching packet (:func:`eoloc.jobs.explain.explain_failures`)."""
    from .explain import commonest_failure, explain_failures

    if not len(det) or commonest_failure(fixes) is None:  # nothing to explain: no inputs gathered (batch)
        return None
    row, found, hfov, vfov, _ = vmti_frames(tel, det)
    d = det.columns
    with np.errstate(invalid="ignore"):
        more = {"the detection's packet (no ST 0601 packet carries its VMTI set)": ~found,
                "the field of view (tags 16, 17 or the VMTI set's 11, 12)":
                    found & ~((hfov > 0) & (hfov < 180) & (vfov > 0) & (vfov < 180)),
                "the VMTI frame size (ST 0903 tags 8, 9)": found & ~((d["frame_width"] > 0) & (d["frame_height"] > 0))}
    if ground is None:
        more["the frame-centre elevation (tag 78, or 25 + geoid)"] = (
            found & ~np.isfinite(tel.columns["fc_h_m"][row]),
            "without a DEM the rays stop at that height: give --dem")
    pose = packet_pose(tel).take(row) if len(tel) else None
    return explain_failures(fixes, pose=pose, pixels=(d["u_px"], d["v_px"]), names=KLV_NAMES,
                            what="VMTI detections", more=more)
