"""Decoded KLV packets -> eoloc tables: telemetry (one row per packet) and VMTI detections.

Each stream (one KLV PID, or the whole raw file) is mapped on its own: report-on-change (a tag
absent from a packet keeps its last value *in that stream*, ST 0601 §6), rows in the order of the
stream's own time stamps (packets out of order and jumps in time are reported), full-range
pitch/roll (tags 90/91) preferred over tags 6/7, HAE heights (75, 78) preferred over MSL (15, 25),
MSL converted to ellipsoidal height through the geoid (EGM96 bundled), offset corners (26-33)
turned into absolute ones. A stream without a position and attitude is named as such.

Angles come out in eoloc's conventions unchanged, because ST 0601's are the same: platform
heading/pitch/roll are the ZYX yaw/pitch/roll of SPEC §2, and the sensor relative azimuth,
elevation and roll are the az-el turret's angles (azimuth about body z, clockwise from the nose;
elevation about the new y, negative down; roll about the boresight, clockwise seen from behind the
camera). The line of sight is R_ned_body(5, 90|6, 91|7) . Rz(18) . Ry(19) . Rx(20) applied to x.
"""

from __future__ import annotations

import math
from datetime import datetime
from typing import Any

import numpy as np

from ..table import Issue, Table
from .columnar import KLVColumns, concat_columns, empty_chunk
from .localset import num
from .reader import KLVStream
from .st0601 import Tag

# The packet's pose and view by column name, from the ST 0601 items: the first item of each tuple
# that the packet state has. One mapping for the batch (whole columns, _stream_columns) and the live
# path (one packet, packet_view).
VIEW: dict[str, tuple[Tag, ...]] = {
    "lat_deg": (Tag.SENSOR_LATITUDE,), "lon_deg": (Tag.SENSOR_LONGITUDE,), "yaw_deg": (Tag.PLATFORM_HEADING_ANGLE,),
    "pitch_deg": (Tag.PLATFORM_PITCH_ANGLE_FULL, Tag.PLATFORM_PITCH_ANGLE),
    "roll_deg": (Tag.PLATFORM_ROLL_ANGLE_FULL, Tag.PLATFORM_ROLL_ANGLE),
    "gimbal1_deg": (Tag.SENSOR_RELATIVE_AZIMUTH_ANGLE,), "gimbal2_deg": (Tag.SENSOR_RELATIVE_ELEVATION_ANGLE,),
    "sensor_roll_deg": (Tag.SENSOR_RELATIVE_ROLL_ANGLE,), "hfov_deg": (Tag.SENSOR_HORIZONTAL_FIELD_OF_VIEW,),
    "vfov_deg": (Tag.SENSOR_VERTICAL_FIELD_OF_VIEW,), "fc_lat_deg": (Tag.FRAME_CENTER_LATITUDE,),
    "fc_lon_deg": (Tag.FRAME_CENTER_LONGITUDE,),
}
# Heights: the ellipsoidal item, else the MSL item plus the geoid's undulation at the point (its columns).
HEIGHTS: dict[str, tuple[Tag, Tag, str, str]] = {
    "h_m": (Tag.SENSOR_ELLIPSOID_HEIGHT, Tag.SENSOR_TRUE_ALTITUDE, "lat_deg", "lon_deg"),
    "fc_h_m": (Tag.FRAME_CENTER_HEIGHT_ABOVE_ELLIPSOID, Tag.FRAME_CENTER_ELEVATION, "fc_lat_deg", "fc_lon_deg"),
}
READ_TAGS = frozenset({*(t for tags in VIEW.values() for t in tags), *(h[i] for h in HEIGHTS.values() for i in (0, 1)),
                       Tag.SLANT_RANGE, Tag.TARGET_LOCATION_LATITUDE, Tag.TARGET_LOCATION_LONGITUDE,
                       Tag.TARGET_LOCATION_ELEVATION, Tag.TARGET_ERROR_ESTIMATE_CE90, Tag.TARGET_ERROR_ESTIMATE_LE90,
                       Tag.GENERIC_FLAG_DATA})  # the items of the telemetry table besides time and the corners
OFFSET_CORNER_TAGS = tuple(range(26, 34))  # lat1, lon1, ..., lat4, lon4 as offsets from the frame centre
FULL_CORNER_TAGS = tuple(range(82, 90))  # lat1, lon1, ..., lat4, lon4
SLANT_RANGE_MEASURED = 1 << 4  # tag 47 bit: slant range measured (laser) rather than computed
POSE_TAGS = {"latitude (13)": (13,), "longitude (14)": (14,), "height (15 or 75)": (15, 75), "heading (5)": (5,)}


def fill_forward(col: np.ndarray) -> np.ndarray:
    """Report-on-change: each NaN takes the last value before it (NaN before the first value)."""
    idx = np.where(np.isfinite(col), np.arange(col.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, col[np.maximum(idx, 0)], np.nan)


def packet_time_s(values: dict[int, Any]) -> float:
    t = values.get(2)
    return t.timestamp() if isinstance(t, datetime) else math.nan


def as_columns(source: KLVStream | KLVColumns) -> KLVColumns:
    """The packets of a read stream as columns (they may be so already)."""
    from .columnar import columns_from_stream

    return source if isinstance(source, KLVColumns) else columns_from_stream(source)


def stream_groups(cols: KLVColumns) -> dict[str, np.ndarray]:
    """Stream name -> its rows, streams in order of their first packet."""
    names, first, inverse = np.unique(cols.stream, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    return {str(names[g]): np.flatnonzero(inverse == g) for g in order}


def stream_order(cols: KLVColumns, rows: np.ndarray, where: str) -> tuple[np.ndarray, list[Issue]]:
    """A stream's rows in the order of their own time stamps (stable; untimed packets stay after
    their predecessor), with an issue for packets that came out of order and for jumps in time."""
    t = cols.time_s[rows]
    issues: list[Issue] = []
    if t.size < 2 or not np.isfinite(t).any():
        return rows, issues
    key = fill_forward(t)
    key = np.where(np.isfinite(key), key, -np.inf)
    order = np.argsort(key, kind="stable")
    index = cols.index[rows]
    late = np.flatnonzero(np.diff(key) < 0)
    if late.size:
        issues.append(Issue(where, int(index[late[0] + 1]),
                            f"{late.size} packet(s) with a time stamp earlier than the packet before them, first "
                            f"packet {index[late[0] + 1]}; rows put in time order"))
    ts = np.sort(t[np.isfinite(t)])
    dt = np.diff(ts)
    if dt.size >= 4:
        step = float(np.median(dt[dt > 0])) if (dt > 0).any() else 0.0
        jumps = np.flatnonzero(dt > max(20 * step, 1.0))
        if jumps.size:
            issues.append(Issue(where, int(index[np.argmax(index >= 0)]),  # (not a carried state's row)
                                f"{jumps.size} gap(s) in time longer than 20 packet intervals (largest "
                                f"{dt[jumps].max():.1f} s, typical interval {step:.3f} s)"))
    return rows[order], issues


def missing_pose(cols: KLVColumns, rows: np.ndarray) -> list[str]:
    """The pose items (position, height, heading) a stream never sends."""
    return [name for name, tags in POSE_TAGS.items() if not any(cols.has(t)[rows].any() for t in tags)]


def klv_telemetry(stream: KLVStream | KLVColumns, *, geoid=None, report_on_change: bool = True) -> Table:
    """Decoded packets (objects or columns) -> an eoloc telemetry :class:`Table` (one row per good
    packet, grouped by stream, each stream in time order).

    Columns (degrees, metres, ellipsoidal heights): stream, time_s (UNIX, from tag 2), frame
    (packet number), lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, gimbal1_deg (relative
    azimuth), gimbal2_deg (relative elevation), sensor_roll_deg, range_m (slant range),
    range_measured (1 laser, 0 computed, NaN unknown), hfov_deg, vfov_deg, fc_lat_deg, fc_lon_deg,
    fc_h_m (frame centre), corner{1-4}_lat_deg/_lon_deg (1 upper-left, 2 upper-right, 3
    lower-right, 4 lower-left), target_lat_deg, target_lon_deg, target_h_m, target_ce90_m,
    target_le90_m, target_elevation_hae (1 where tag 42 is HAE, 0 MSL), pts_s, h_msl_m and
    fc_h_msl_m (as sent). ``line`` holds the packet numbers; ``issues`` the streams' order, time
    and missing-pose findings.
    """
    from ...terrain.geoid import default_geoid

    geoid = geoid or default_geoid()
    cols = as_columns(stream)
    parts, issues = [], []
    for name, rows in stream_groups(cols).items():
        where = f"{cols.path}{f' [{name}]' if name else ''}"
        ordered, found = stream_order(cols, rows, where)
        issues += found
        lacking = missing_pose(cols, rows)
        packets = rows[cols.index[rows] >= 0]  # (not a carried state's row)
        if lacking and packets.size:
            issues.append(Issue(where, int(cols.index[packets[0]]),
                                f"this stream never sends {', '.join(lacking)}: it carries no pose, so its "
                                f"{packets.size} packet(s) give no frame centre, footprint or fix"))
        parts.append(_stream_columns(cols, ordered, geoid, report_on_change))
    if not parts:
        parts = [_stream_columns(cols, np.zeros(0, np.intp), geoid, report_on_change)]
    table = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return Table(cols.path, table, table["frame"].astype(np.int64), issues)


def _stream_columns(cols: KLVColumns, rows: np.ndarray, geoid, report_on_change: bool) -> dict[str, np.ndarray]:
    n = rows.size

    def seen(tag: int) -> np.ndarray:
        """True from the first packet that carries ``tag`` (the receiver-current state)."""
        return np.maximum.accumulate(cols.has(tag)[rows]) if n else np.zeros(0, bool)

    fill = fill_forward if report_on_change else (lambda c: c)
    v = {tag: fill(cols.col(tag)[rows]) for tag in (*READ_TAGS, *OFFSET_CORNER_TAGS, *FULL_CORNER_TAGS)}
    view: dict[str, np.ndarray] = {}
    for name, tags in VIEW.items():
        x = v[tags[0]]
        for t in tags[1:]:
            x = np.where(np.isfinite(x), x, v[t])
        view[name] = x
    for name, (hae, msl, at_lat, at_lon) in HEIGHTS.items():
        undulation = geoid.undulation(view[at_lat], view[at_lon]) if n else np.zeros(0)
        view[name] = np.where(np.isfinite(v[hae]), v[hae], v[msl] + undulation)
    # the target's elevation datum follows the frame-centre height in use (ST 0601.19 §8.42.1): HAE once 78 is sent
    target_hae = seen(Tag.FRAME_CENTER_HEIGHT_ABOVE_ELLIPSOID)
    lat_t, lon_t, h_t = (v[t] for t in (Tag.TARGET_LOCATION_LATITUDE, Tag.TARGET_LOCATION_LONGITUDE,
                                        Tag.TARGET_LOCATION_ELEVATION))
    target_h = np.where(target_hae, h_t, h_t + geoid.undulation(lat_t, lon_t)) if n else h_t
    flags = v[Tag.GENERIC_FLAG_DATA]
    measured = np.where(np.isfinite(flags), (np.nan_to_num(flags).astype(np.int64) & SLANT_RANGE_MEASURED) > 0,
                        np.nan)
    out: dict[str, np.ndarray] = {
        "stream": cols.stream[rows].astype(str),
        "time_s": cols.time_s[rows], "frame": cols.index[rows].astype(np.float64), "pts_s": cols.pts_s[rows],
        **{k: view[k] for k in ("lat_deg", "lon_deg", "h_m")}, "h_msl_m": v[Tag.SENSOR_TRUE_ALTITUDE],
        **{k: view[k] for k in ("yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg", "sensor_roll_deg")},
        "range_m": v[Tag.SLANT_RANGE], "range_measured": measured.astype(np.float64),
        **{k: view[k] for k in ("hfov_deg", "vfov_deg", "fc_lat_deg", "fc_lon_deg", "fc_h_m")},
        "fc_h_msl_m": v[Tag.FRAME_CENTER_ELEVATION], "target_lat_deg": lat_t, "target_lon_deg": lon_t,
        "target_h_m": target_h, "target_elevation_hae": target_hae.astype(np.float64),
        "target_ce90_m": v[Tag.TARGET_ERROR_ESTIMATE_CE90], "target_le90_m": v[Tag.TARGET_ERROR_ESTIMATE_LE90],
    }
    fc_lat, fc_lon = view["fc_lat_deg"], view["fc_lon_deg"]
    for k in range(4):
        full_lat, full_lon = v[FULL_CORNER_TAGS[2 * k]], v[FULL_CORNER_TAGS[2 * k + 1]]
        off_lat, off_lon = v[OFFSET_CORNER_TAGS[2 * k]], v[OFFSET_CORNER_TAGS[2 * k + 1]]
        out[f"corner{k + 1}_lat_deg"] = np.where(np.isfinite(full_lat), full_lat, fc_lat + off_lat)
        out[f"corner{k + 1}_lon_deg"] = np.where(np.isfinite(full_lon), full_lon, fc_lon + off_lon)
    return out


def platform_name(fields: dict[int, Any]) -> str | None:
    """The platform's name: its designation (tag 10), else its tail number (tag 4), else None."""
    return fields.get(Tag.PLATFORM_DESIGNATION) or fields.get(Tag.PLATFORM_TAIL_NUMBER) or None


def packet_view(fields: dict[int, Any], geoid=None) -> dict[str, float]:
    """One packet's time, pose and view as plain floats, named and converted as
    :func:`klv_telemetry`'s columns (tag preferences, MSL -> ellipsoidal through the geoid;
    NaN where absent): time_s, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, gimbal1_deg,
    gimbal2_deg, sensor_roll_deg, hfov_deg, vfov_deg, fc_lat_deg, fc_lon_deg, fc_h_m. ``fields``
    already holds every value the packet stands for (report-on-change carried by the caller):
    the live path's one packet at a time, without building a table."""
    from ...terrain.geoid import default_geoid

    out = {"time_s": packet_time_s(fields)}
    for name, tags in VIEW.items():
        x = num(fields.get(tags[0]))
        for t in tags[1:]:
            x = x if math.isfinite(x) else num(fields.get(t))
        out[name] = x
    heights = {name: num(fields.get(hae)) for name, (hae, *_) in HEIGHTS.items()}
    if not all(math.isfinite(h) for h in heights.values()):  # MSL: one geoid look-up for both points
        at = [(out[la], out[lo]) for _, _, la, lo in HEIGHTS.values()]
        undulation = (geoid or default_geoid()).undulation(np.array([a[0] for a in at]), np.array([a[1] for a in at]))
        for (name, (_, msl, _, _)), n in zip(HEIGHTS.items(), undulation, strict=True):
            if not math.isfinite(heights[name]):
                heights[name] = num(fields.get(msl)) + float(n)
    return out | heights


# -- ST 0903 VMTI -------------------------------------------------------------------------------

DETECTION_COLUMNS = ("stream", "frame", "time_s", "target_id", "u_px", "v_px", "bbox_u0", "bbox_v0", "bbox_u1",
                     "bbox_v1", "frame_width", "frame_height", "vmti_hfov_deg", "vmti_vfov_deg",
                     "encoder_lat_deg", "encoder_lon_deg", "encoder_h_m")


def vmti_detections(stream: KLVStream | KLVColumns, *, pixels_from: int = 1) -> Table:
    """Target detections from the VMTI local sets (ST 0601 tag 74) -> a detections :class:`Table`.

    Columns: stream, frame (the packet number, so each detection pairs with its own packet's
    pose), time_s, target_id, u_px, v_px (centroid, eoloc pixel convention: 0-based, centre of the
    top-left pixel at (0, 0)), bbox_u0/v0/u1/v1 (px, NaN when absent), frame_width, frame_height
    (carried forward from earlier packets of the same stream when a set leaves them out),
    vmti_hfov_deg, vmti_vfov_deg (NaN when the VMTI set has none), encoder_lat_deg,
    encoder_lon_deg, encoder_h_m (the encoder's own target location: ST 0903 tag 17, or the
    offsets 10/11 from the frame centre with height 12; NaN when absent; heights as sent, HAE by the
    standard). ST 0903 pixel numbers are 1-based (row - 1) x width + column, rows/columns (tags
    19/20) 1-based; ``pixels_from=0`` reads them as 0-based (an encoder that numbers from 0).
    """
    cols = as_columns(stream)
    n = len(cols)
    has_vmti = cols.has_vmti
    width, height = cols.vmti_f[:, 2].copy(), cols.vmti_f[:, 3].copy()
    fc_sent = cols.has(23) | cols.has(24)
    fc_lat, fc_lon = np.full(n, np.nan), np.full(n, np.nan)
    for rows in stream_groups(cols).values():  # the frame size and centre carried within each stream
        for value, sent in ((width, has_vmti), (height, has_vmti)):
            value[rows] = _carried(np.where(sent[rows], value[rows], np.nan), sent[rows] & np.isfinite(value[rows]))
        fc_lat[rows] = _carried(cols.col(23)[rows], fc_sent[rows])
        fc_lon[rows] = _carried(cols.col(24)[rows], fc_sent[rows])
    ti, tf = cols.target_i, cols.target_f
    r = ti[:, 0]
    w = width[r]
    (u0, v0), (u1, v1) = _pixel_numbers(ti[:, 3], w, pixels_from), _pixel_numbers(ti[:, 4], w, pixels_from)
    u, v = _centroids(ti, w, pixels_from, (u0 + u1) / 2.0, (v0 + v1) / 2.0)
    bad = ~(np.isfinite(u) & np.isfinite(v))
    issues = [Issue(cols.path, 0, f"packet {cols.index[r[k]]}: VMTI target {ti[k, 1]} has no usable centroid "
                    f"(frame width {float(w[k])}); skipped") for k in np.flatnonzero(bad)]
    keep = ~bad
    r, w, ti, tf, u, v, u0, v0, u1, v1 = (x[keep] for x in (r, w, ti, tf, u, v, u0, v0, u1, v1))
    sent = ti[:, 7] == 1
    out = {
        "stream": cols.stream[r].astype(str), "frame": cols.index[r].astype(np.float64), "time_s": cols.time_s[r],
        "target_id": ti[:, 1].astype(str), "u_px": u, "v_px": v, "bbox_u0": u0, "bbox_v0": v0, "bbox_u1": u1,
        "bbox_v1": v1, "frame_width": w, "frame_height": height[r], "vmti_hfov_deg": cols.vmti_f[r, 0],
        "vmti_vfov_deg": cols.vmti_f[r, 1],
        "encoder_lat_deg": np.where(sent, tf[:, 3], fc_lat[r] + tf[:, 0]),
        "encoder_lon_deg": np.where(sent, tf[:, 4], fc_lon[r] + tf[:, 1]),
        "encoder_h_m": np.where(sent, tf[:, 5], tf[:, 2]),
    }
    table = {k: out[k] for k in DETECTION_COLUMNS}
    return Table(cols.path, table, table["frame"].astype(np.int64), issues)


def _carried(value: np.ndarray, sent: np.ndarray) -> np.ndarray:
    """Each row's value from the last row at or before it where ``sent`` (NaN before the first)."""
    idx = np.where(sent, np.arange(value.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, value[np.maximum(idx, 0)], np.nan)


def _pixel_numbers(value: np.ndarray, width: np.ndarray, pixels_from: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """ST 0903 pixel numbers (-1: none) -> (u, v) in eoloc's 0-based convention (1-based numbers by
    the standard); NaN where there is no number or no usable frame width."""
    ok = (value >= pixels_from) & np.isfinite(width) & (width > 0)
    # (a width past 2^62 is wider than any pixel number: one row, as Python's divmod would say)
    wi = np.maximum(np.where(ok, np.minimum(width, 2.0 ** 62), 1.0).astype(np.int64), 1)  # (ok: width finite)
    row, col = np.divmod(np.where(ok, value - pixels_from, 0), wi)
    return np.where(ok, col, np.nan), np.where(ok, row, np.nan)


def _centroids(ti: np.ndarray, width: np.ndarray, pixels_from: int, box_u: np.ndarray, box_v: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Each target's centroid pixel: its row and column (tags 19/20) where both are sent, else its
    centroid pixel number (tag 1), else the middle of its box (``box_u``, ``box_v``: tags 2/3)."""
    row, col = ti[:, 5], ti[:, 6]
    by_rc = (row >= pixels_from) & (col >= pixels_from)
    u1, v1 = _pixel_numbers(ti[:, 2], width, pixels_from)
    by_number = np.isfinite(u1)
    u = np.where(by_rc, col - pixels_from, np.where(by_number, u1, box_u))
    v = np.where(by_rc, row - pixels_from, np.where(by_number, v1, box_v))
    return u.astype(np.float64), v.astype(np.float64)


# -- report-on-change across segments (the archive's streaming reader) -----------------------------

def carried_state(cols: KLVColumns) -> KLVColumns:
    """What a receiver knows after the last packet of each stream of ``cols`` (one row per stream,
    packet number -1): every ST 0601 item's last value in the stream's time order, the items ever
    sent, the VMTI frame size last sent. Put before the next segment's packets
    (:func:`with_state`), it carries report-on-change across the cut as one reading of the
    whole file would (see :mod:`.segments`)."""
    groups = stream_groups(cols)
    k = len(groups)
    state = empty_chunk(k)
    state["index"][:], state["offset"][:] = -1, -1
    for s, rows in enumerate(groups.values()):
        ordered, _ = stream_order(cols, rows, "")
        vals = cols.values[ordered]
        last = np.where(np.isfinite(vals), np.arange(vals.shape[0])[:, None], -1).max(axis=0)
        state["values"][s] = np.where(last >= 0, vals[np.maximum(last, 0), np.arange(vals.shape[1])], np.nan)
        state["present"][s] = cols.present[rows].any(axis=0)
        sent = np.flatnonzero(cols.has_vmti[rows])
        state["has_vmti"][s] = sent.size > 0
        for c in (2, 3):  # the frame width and height, carried where a set sends them
            given = sent[np.isfinite(cols.vmti_f[rows[sent], c])]
            state["vmti_f"][s, c] = cols.vmti_f[rows[given[-1]], c] if given.size else np.nan
    names = np.array(list(groups), dtype=str) if k else np.zeros(0, str)
    return KLVColumns(cols.path, cols.container, state["index"], state["offset"], np.full(k, np.nan), names,
                      state["standard"], state["time_us"], state["values"], state["present"], state["has_vmti"],
                      state["vmti_f"], state["target_i"], state["target_f"])


def with_state(cols: KLVColumns, state: KLVColumns | None) -> KLVColumns:
    """``cols`` with the rows of ``state`` (:func:`carried_state`) before its packets, its issues
    and notes unchanged; rows of packet number -1 are the state's, to be left out of tables."""
    if state is None or not len(state):
        return cols
    return concat_columns(cols.path, cols.container, [state, cols], [], cols.notes)
