"""Telemetry and detections CSVs (the schemas are documented in the README and `eoloc locate --help`).

Telemetry, one row per image/record:
    time_s | frame (at least one), lat_deg, lon_deg, the height (h_m ellipsoidal, or h_msl_m above
    mean sea level: converted with the geoid), the attitude (yaw_deg, pitch_deg, roll_deg; or the
    quaternion qw, qx, qy, qz; or the direction-cosine matrix dcm_11 ... dcm_33 - see
    :data:`ATTITUDE_SETS`), gimbal1_deg, gimbal2_deg (az-el: azimuth_deg, elevation_deg;
    roll-pitch: frame_roll_deg, frame_pitch_deg), optional sensor_roll_deg, optional range_m,
    optional per-record zoom (hfov_deg, focal_px or focal_mm - see :data:`ZOOM_COLUMNS`).
Detections, one row per target seen in an image:
    time_s | frame, target_id, u_px, v_px, optional range_m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..kernels.backend import in_chunks
from ..sensor.camera import Camera
from ..sensor.model import Pose
from ..util.search import searchsorted
from .table import Column, Issue, Table, TableError, read_table

TELEMETRY_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("lat_deg", ("lat", "latitude"), lo=-90, hi=90, unit="deg"),
    Column("lon_deg", ("lon", "longitude"), lo=-180, hi=360, unit="deg"),
    Column("h_m", ("height_m", "hae_m", "alt_hae_m"), lo=-12_000, hi=100_000, unit="m"),
    Column("yaw_deg", ("heading_deg",), lo=-360, hi=360, unit="deg"),
    Column("pitch_deg", (), lo=-90, hi=90, unit="deg"),
    Column("roll_deg", (), lo=-180, hi=180, unit="deg"),
    Column("gimbal1_deg", ("azimuth_deg", "frame_roll_deg"), required=False, lo=-360, hi=360, unit="deg"),
    Column("gimbal2_deg", ("elevation_deg", "frame_pitch_deg"), required=False, lo=-360, hi=360, unit="deg"),
    Column("sensor_roll_deg", (), required=False, lo=-360, hi=360, unit="deg"),
    Column("range_m", ("slant_range_m",), required=False, lo=0, hi=1e7, unit="m"),
]

#: The ways a telemetry file may give the aircraft's attitude (exactly one per file), all of the
#: body frame (x forward, y right, z down) relative to the local NED frame:
#: Euler angles (yaw, pitch, roll: R_ned_body = Rz(yaw) Ry(pitch) Rx(roll), degrees); the unit
#: quaternion of that rotation (Hamilton, scalar first: v_ned = q v_body q*, PX4's vehicle_attitude
#: convention; a quaternion within 1 % of unit length is normalised, others are refused); the
#: direction-cosine matrix R_ned_body, dcm_RC = row R, column C (v_ned = R v_body).
ATTITUDE_SETS = {
    "Euler angles": ("yaw_deg", "pitch_deg", "roll_deg"),
    "quaternion": ("qw", "qx", "qy", "qz"),
    "direction-cosine matrix": tuple(f"dcm_{r}{c}" for r in (1, 2, 3) for c in (1, 2, 3)),
}
#: A zoom lens's focal length per record (at most one of them): the horizontal field of view
#: across the image width, the focal length in pixels, or in mm (the config's camera then needs
#: pixel_um). Relative to the config's camera this is each pose's ``focal_scale``.
ZOOM_COLUMNS = ("hfov_deg", "focal_px", "focal_mm")
HEIGHT_COLUMNS = ("h_m", "h_msl_m")

_OPTIONAL_TELEMETRY = [
    Column("h_msl_m", ("alt_msl_m", "msl_m", "height_msl_m"), required=False, lo=-12_000, hi=100_000, unit="m"),
    *(Column(q, (f"q_{q[1]}",), required=False) for q in ATTITUDE_SETS["quaternion"]),
    *(Column(d, (), required=False, lo=-1.5, hi=1.5) for d in ATTITUDE_SETS["direction-cosine matrix"]),
    Column("hfov_deg", ("sensor_hfov_deg", "fov_h_deg"), required=False, lo=1e-6, hi=179.999, unit="deg"),
    Column("focal_px", ("fx_px",), required=False, lo=1e-6, unit="px"),
    Column("focal_mm", ("focal_length_mm",), required=False, lo=1e-6, unit="mm"),
]

DETECTION_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("target_id", ("id", "target"), text=True),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("range_m", ("slant_range_m",), required=False, lo=0, hi=1e7, unit="m"),
]


GCP_COLUMNS = [
    Column("time_s", required=False, unit="s"),
    Column("frame", required=False, lo=0),
    Column("gcp_id", ("id", "gcp", "name"), text=True),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("lat_deg", ("lat", "latitude"), lo=-90, hi=90, unit="deg"),
    Column("lon_deg", ("lon", "longitude"), lo=-180, hi=360, unit="deg"),
    Column("h_m", ("height_m", "hae_m"), lo=-12_000, hi=100_000, unit="m"),
]


#: Calibration observations (compensation training): one row per sighting of a surveyed point,
#: with the pose as the telemetry reported it, the pixel, and the point's surveyed position.
OBSERVATION_COLUMNS = [
    Column("flight", ("flight_id", "sortie"), required=False, text=True),
    Column("time_s", required=False, unit="s"),
    *TELEMETRY_COLUMNS[2:10],
    Column("sensor_roll_deg", (), required=False, lo=-360, hi=360, unit="deg"),
    Column("u_px", ("u", "col", "x_px"), unit="px"),
    Column("v_px", ("v", "row", "y_px"), unit="px"),
    Column("gcp_id", ("gcp",), required=False, text=True),
    Column("gcp_lat_deg", ("true_lat_deg",), lo=-90, hi=90, unit="deg"),
    Column("gcp_lon_deg", ("true_lon_deg",), lo=-180, hi=360, unit="deg"),
    Column("gcp_h_m", ("true_h_m",), lo=-12_000, hi=100_000, unit="m"),
]


def read_observations(path: str | Path) -> Table:
    """Read calibration observations: flight (id; held out together in cross-validation), pose
    (lat_deg, lon_deg, h_m ellipsoidal, yaw/pitch/roll_deg, gimbal1/2_deg, optional
    sensor_roll_deg), u_px, v_px and the surveyed gcp_lat_deg, gcp_lon_deg, gcp_h_m (ellipsoidal).
    Without a flight column every row counts as one flight."""
    t = read_table(path, OBSERVATION_COLUMNS, what="calibration observations", key=("u_px", "v_px"))
    t.add_missing(["flight"], Path(path).stem, object)
    t.add_missing(["sensor_roll_deg"], 0.0)
    t.add_missing(["gimbal1_deg", "gimbal2_deg", "time_s"])
    return t


def read_gcps(path: str | Path) -> Table:
    """Read GCP observations: time_s or frame, gcp_id, u_px, v_px (where the GCP is in that image)
    and the GCP's surveyed lat_deg, lon_deg, h_m (ellipsoidal)."""
    t = read_table(path, GCP_COLUMNS, what="GCP observations", key=("time_s", "frame"))
    t.add_missing(["time_s", "frame"])
    return t


def with_heading_bias(t: Table, heading_bias_deg: float) -> Table:
    """The telemetry with a calibrated INS heading bias removed from every yaw (true = measured - bias)."""
    if heading_bias_deg == 0.0:
        return t
    return replace(t, columns={**t.columns, "yaw_deg": t.columns["yaw_deg"] - heading_bias_deg})


def read_telemetry(path: str | Path, *, geoid=None) -> Table:
    """Read a telemetry CSV; bad values become NaN (reported), unusable lines are skipped (reported).

    The height may be given as h_msl_m (converted to ellipsoidal with ``geoid``, default the
    bundled EGM96) and the attitude as a quaternion or a direction-cosine matrix
    (:data:`ATTITUDE_SETS`): the table always comes back with h_m, yaw_deg, pitch_deg, roll_deg.
    """
    columns = [replace(c, required=False) if c.name in ("h_m", *ATTITUDE_SETS["Euler angles"]) else c
               for c in TELEMETRY_COLUMNS]
    t = read_table(path, columns + _OPTIONAL_TELEMETRY, what="telemetry", key=("time_s", "frame"))
    _height(t, geoid)
    _attitude(t)
    zoom = [z for z in ZOOM_COLUMNS if z in t.columns]
    if len(zoom) > 1:
        raise TableError(f"{t.path} gives the focal length twice ({', '.join(zoom)}): keep one column")
    if zoom:  # an empty cell: this image's focal length is unknown, and no default would be right
        named = {i.line for i in t.issues if f"'{zoom[0]}'" in i.message}
        t.issues.extend(Issue(t.path, int(line), f"column '{zoom[0]}' is empty: the focal length of this image is "
                              "unknown; record not located")
                        for line in t.line[np.isnan(t.columns[zoom[0]])] if int(line) not in named)
        t.issues.sort(key=lambda i: i.line)
    t.add_missing(["gimbal1_deg", "gimbal2_deg", "sensor_roll_deg", "range_m", "time_s", "frame"])
    return without_repeated_times(t)


MSL_AGREEMENT_M = 5.0  # h_m and h_msl_m + N further apart than this: one of them is mislabelled


def _height(t: Table, geoid) -> None:
    """h_m from h_msl_m + N when only the MSL height is given; a check when both are."""
    c = t.columns
    if "h_msl_m" not in c:
        if "h_m" not in c:
            raise TableError(f"{t.path} has no height column: give h_m (ellipsoidal, m) or h_msl_m (above mean sea "
                             "level, m; converted to ellipsoidal with EGM96)")
        return
    from ..terrain.geoid import default_geoid

    geoid = geoid or default_geoid()
    h_from_msl = c.pop("h_msl_m") + geoid.undulation(c["lat_deg"], c["lon_deg"])
    if "h_m" not in c:
        c["h_m"] = h_from_msl
        return
    with np.errstate(invalid="ignore"):
        apart = np.flatnonzero(np.abs(c["h_m"] - h_from_msl) > MSL_AGREEMENT_M)
    if apart.size:
        k = apart[0]
        t.issues.append(Issue(t.path, int(t.line[k]), f"h_m and h_msl_m + geoid ({geoid.name}) differ by "
                              f"{abs(c['h_m'][k] - h_from_msl[k]):.1f} m here and on {apart.size - 1} more lines: "
                              "is one of them mislabelled? h_m is used"))


def _attitude(t: Table) -> None:
    """yaw/pitch/roll from whichever attitude set the file gives (exactly one)."""
    from ..rotation import euler_from_R_ned_body

    c = t.columns
    given = {k: [n for n in names if n in c] for k, names in ATTITUDE_SETS.items()}
    complete = [k for k, names in ATTITUDE_SETS.items() if len(given[k]) == len(names)]
    partial = [k for k in ATTITUDE_SETS if given[k] and k not in complete]
    if partial:
        k = partial[0]
        missing = [n for n in ATTITUDE_SETS[k] if n not in c]
        raise TableError(f"{t.path} gives part of the attitude as a {k}: {', '.join(missing)} missing")
    if len(complete) != 1:
        ways = "; ".join(f"{k}: {', '.join(v) if len(v) < 5 else v[0] + ' ... ' + v[-1]}"
                         for k, v in ATTITUDE_SETS.items())
        raise TableError(f"{t.path} " + ("has no attitude" if not complete else
                                         f"gives the attitude {len(complete)} ways ({', '.join(complete)})")
                         + f": give exactly one of {ways}")
    kind = complete[0]
    if kind == "Euler angles":
        return
    n = len(t)
    if kind == "quaternion":
        from scipy.spatial.transform import Rotation

        q = np.column_stack([c.pop(k) for k in ATTITUDE_SETS[kind]])
        norm = np.linalg.norm(q, axis=1)
        with np.errstate(invalid="ignore"):
            bad = np.isfinite(norm) & (np.abs(norm - 1.0) > 0.01)
        ok = np.isfinite(norm) & ~bad
        R = np.full((n, 3, 3), np.nan)
        if ok.any():
            R[ok] = Rotation.from_quat(q[ok] / norm[ok, None], scalar_first=True).as_matrix()
        why = {int(k): f"quaternion (qw, qx, qy, qz) has length {norm[k]:.4g}, not 1: not an attitude; record not "
                       "located (check the column order and scaling)" for k in np.flatnonzero(bad)}
    else:
        R = np.column_stack([c.pop(k) for k in ATTITUDE_SETS[kind]]).reshape(n, 3, 3)
        with np.errstate(invalid="ignore"):
            off = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
            det = np.linalg.det(np.where(np.isfinite(R), R, 0.0))
        bad = np.isfinite(off) & ((off > 1e-3) | (det < 0))
        R[bad] = np.nan
        why = {int(k): f"dcm_11 ... dcm_33 is not a rotation (|RᵀR - I| = {off[k]:.2g}, det {det[k]:.3g}); record "
                       "not located (rows and columns swapped, or a reflection?)" for k in np.flatnonzero(bad)}
    c["yaw_deg"], c["pitch_deg"], c["roll_deg"] = euler_from_R_ned_body(R, warn_gimbal_lock=False)
    t.issues.extend(Issue(t.path, int(t.line[k]), msg) for k, msg in why.items())
    t.issues.sort(key=lambda i: i.line)


def without_repeated_times(t: Table) -> Table:
    """Records that repeat a time_s: an exact copy of an earlier record is dropped; records that
    give different poses at one time are all dropped (which one is right cannot be told). Each
    is reported with the line it repeats."""
    times = t.columns["time_s"]
    finite = np.flatnonzero(np.isfinite(times))
    if finite.size < 2:
        return t
    order = finite[np.argsort(times[finite], kind="stable")]
    same = np.flatnonzero(np.diff(times[order]) == 0.0)
    if same.size == 0:
        return t
    drop = np.zeros(len(t), dtype=bool)
    names = [k for k, v in t.columns.items() if v.dtype.kind == "f"]
    for k in same:
        first, later = order[k], order[k + 1]
        while k > 0 and times[order[k - 1]] == times[first]:  # compare with the first record of the time
            k -= 1
            first = order[k]
        identical = all(np.array_equal(t.columns[n][first], t.columns[n][later], equal_nan=True) for n in names)
        if identical:
            drop[later] = True
            t.issues.append(Issue(t.path, int(t.line[later]), f"repeats line {int(t.line[first])} exactly; "
                                                               "record skipped"))
        else:
            drop[[first, later]] = True
            t.issues.append(Issue(t.path, int(t.line[later]), f"time_s {times[later]:g} also at line "
                                  f"{int(t.line[first])} with another pose: neither record is used"))
    return t.keep(~drop)


def read_detections(path: str | Path) -> Table:
    """Read a detections CSV (time_s or frame, target_id, u_px, v_px[, range_m])."""
    t = read_table(path, DETECTION_COLUMNS, what="detections", key=("time_s", "frame"))
    t.add_missing(["range_m", "time_s", "frame"])
    return t


def telemetry_pose(t: Table, index: np.ndarray | slice = slice(None), camera: Camera | None = None) -> Pose:
    """The poses of telemetry records ``index`` (gimbal angles: gimbal1, gimbal2, sensor roll;
    with a zoom column, each record's focal length relative to ``camera``'s)."""
    c = t.columns
    sensor_roll = np.nan_to_num(c["sensor_roll_deg"][index], nan=0.0)
    return Pose(c["lat_deg"][index], c["lon_deg"][index], c["h_m"][index], c["yaw_deg"][index],
                c["pitch_deg"][index], c["roll_deg"][index],
                (c["gimbal1_deg"][index], c["gimbal2_deg"][index], sensor_roll), focal_scale(t, camera, index))


def focal_scale(t: Table, camera: Camera | None, index: np.ndarray | slice = slice(None)) -> np.ndarray | float:
    """Each record's focal length over ``camera``'s from the telemetry's zoom column (1.0 without
    one). ``camera`` is needed when there is one; focal_mm needs a camera given with pixel_um."""
    name = next((z for z in ZOOM_COLUMNS if z in t.columns), None)
    if name is None:
        return 1.0
    if camera is None:
        raise TypeError(f"telemetry {t.path} has a {name} column: pass the camera to scale its focal length")
    x = t.columns[name][index]
    if name == "hfov_deg":
        return (camera.width / 2.0) / np.tan(np.radians(x) / 2.0) / camera.fx
    if name == "focal_px":
        return x / camera.fx
    if camera.pixel_um is None:
        raise TableError(f"telemetry {t.path} gives focal_mm, but the config's camera has no pixel size: give the "
                         "camera as focal_mm + pixel_um, or the telemetry's zoom as hfov_deg or focal_px")
    return x * 1e3 / camera.pixel_um / camera.fx


@dataclass
class Matched:
    """Detections paired with the telemetry record of their image (-1: none)."""

    record: np.ndarray
    issues: list[Issue]


def match_detections(tel: Table, det: Table, *, time_tolerance_s: float = 0.02) -> Matched:
    """Pair each detection with its telemetry record: same ``frame`` if both files have frames,
    else the record nearest in ``time_s`` within ``time_tolerance_s``. Unmatched detections get -1
    and a reported issue (they end as NO_TELEMETRY; nothing is interpolated here)."""
    n = len(det)
    record = np.full(n, -1, dtype=np.int64)
    issues: list[Issue] = []
    has = {name: (np.isfinite(t.columns["frame"]).any(), np.isfinite(t.columns["time_s"]).any())
           for name, t in (("detections", det), ("telemetry", tel))}
    use_frames = has["detections"][0] and has["telemetry"][0]
    if n and not use_frames and not (has["detections"][1] and has["telemetry"][1]):
        def gives(name: str) -> str:
            f, t = has[name]
            return "frame and time_s" if f and t else "frame only" if f else "time_s only" if t else "neither"

        raise TableError(f"{det.path} gives {gives('detections')} and {tel.path} {gives('telemetry')}: nothing to "
                         "pair them by; add the same column (frame, or time_s) to both files")
    ambiguous: dict[int, str] = {}  # frame -> why its telemetry cannot be told
    if use_frames:  # a frame's one record (or its exact copies: the last of them)
        ft, fd = tel.columns["frame"], det.columns["frame"]
        good = np.flatnonzero(np.isfinite(ft))
        order = good[np.argsort(ft[good].astype(np.int64), kind="stable")]
        keys = ft[order].astype(np.int64)
        ambiguous = _frames_with_two_poses(tel, order, keys)
        wanted = np.isfinite(fd)
        q = np.where(wanted, fd, 0.0).astype(np.int64)
        if keys.size:
            def by_frame(i: int, j: int) -> None:
                pos = np.maximum(searchsorted(keys, q[i:j], side="right") - 1, 0)
                record[i:j] = np.where(wanted[i:j] & (keys[pos] == q[i:j]), order[pos], -1)

            in_chunks(n, by_frame)
            if ambiguous:  # no pose for a frame given two: which one is right cannot be told
                record[np.isin(q, np.fromiter(ambiguous, np.int64)) & wanted] = -1
    else:
        tt = tel.columns["time_s"]
        good = np.flatnonzero(np.isfinite(tt))
        order = good[np.argsort(tt[good], kind="stable")]
        ts = tt[order]
        td = det.columns["time_s"]
        if ts.size:
            def by_time(i: int, j: int) -> None:
                q = td[i:j]
                pos = np.clip(searchsorted(ts, q), 1, max(ts.size - 1, 1))
                left = np.clip(pos - 1, 0, ts.size - 1)
                right = np.clip(pos, 0, ts.size - 1)
                pick = np.where(np.abs(q - ts[left]) <= np.abs(ts[right] - q), left, right)
                close = np.abs(ts[pick] - q) <= time_tolerance_s
                record[i:j] = np.where(close & np.isfinite(q), order[pick], -1)

            in_chunks(n, by_time)  # each slice of the detections on a thread (numpy releases the GIL): 2x
    for j in np.flatnonzero(record < 0):
        key = f"frame {det.columns['frame'][j]:g}" if use_frames else f"time {det.columns['time_s'][j]:g} s"
        hint = "" if use_frames else f" within {time_tolerance_s:g} s (widen --time-tolerance?)"
        frame = det.columns["frame"][j]
        why = ambiguous.get(int(frame)) if use_frames and np.isfinite(frame) else None
        issues.append(Issue(det.path, int(det.line[j]), f"{key}: {why}; not located" if why else
                            f"no telemetry record for {key}{hint}"))
    return Matched(record, issues)


def _frames_with_two_poses(tel: Table, order: np.ndarray, keys: np.ndarray) -> dict[int, str]:
    """The frame numbers that more than one telemetry record gives, with different values (a pose
    or anything else), each with why: ``order`` sorts the records by frame, ``keys`` their frames.
    Exact copies of a record are not a conflict."""
    same = np.flatnonzero(keys[1:] == keys[:-1])
    if same.size == 0:
        return {}
    names = [k for k, v in tel.columns.items() if v.dtype.kind == "f" and k != "frame"]
    out: dict[int, str] = {}
    for k in same:
        a, b = order[k], order[k + 1]
        frame = int(keys[k])
        if frame in out:
            continue
        if not all(np.array_equal(tel.columns[c][a], tel.columns[c][b], equal_nan=True) for c in names):
            first = order[np.searchsorted(keys, frame)]
            out[frame] = (f"{tel.path} gives frame {frame} twice with different values (lines {int(tel.line[first])} "
                          f"and {int(tel.line[b])})")
    return out
