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
from .localset import num
from .reader import KLVPacket, KLVStream

# ST 0601 tags eoloc reads (name -> tag); see klv_telemetry for how they combine
TAGS = {
    "time": 2, "heading": 5, "pitch": 6, "roll": 7, "lat": 13, "lon": 14, "alt_msl": 15, "hfov": 16, "vfov": 17,
    "rel_az": 18, "rel_el": 19, "rel_roll": 20, "slant_range": 21, "fc_lat": 23, "fc_lon": 24, "fc_el_msl": 25,
    "target_lat": 40, "target_lon": 41, "target_el": 42, "target_ce90": 45, "target_le90": 46, "flags": 47,
    "vmti": 74, "alt_hae": 75, "fc_hae": 78, "pitch_full": 90, "roll_full": 91,
}
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


def stream_order(packets: list[KLVPacket], path: str) -> tuple[list[KLVPacket], list[Issue]]:
    """A stream's packets in the order of their own time stamps (stable; untimed packets stay after
    their predecessor), with an issue for packets that came out of order and for jumps in time."""
    t = np.array([packet_time_s(p.fields) for p in packets])
    issues: list[Issue] = []
    if t.size < 2 or not np.isfinite(t).any():
        return packets, issues
    key = fill_forward(t)
    key = np.where(np.isfinite(key), key, -np.inf)
    order = np.argsort(key, kind="stable")
    name = packets[0].stream
    where = f"{path}{f' [{name}]' if name else ''}"
    late = np.flatnonzero(np.diff(key) < 0)
    if late.size:
        issues.append(Issue(where, int(packets[late[0] + 1].index),
                            f"{late.size} packet(s) with a time stamp earlier than the packet before them, first "
                            f"packet {packets[late[0] + 1].index}; rows put in time order"))
    ts = np.sort(t[np.isfinite(t)])
    dt = np.diff(ts)
    if dt.size >= 4:
        step = float(np.median(dt[dt > 0])) if (dt > 0).any() else 0.0
        jumps = np.flatnonzero(dt > max(20 * step, 1.0))
        if jumps.size:
            issues.append(Issue(where, int(packets[0].index),
                                f"{jumps.size} gap(s) in time longer than 20 packet intervals (largest "
                                f"{dt[jumps].max():.1f} s, typical interval {step:.3f} s)"))
    return [packets[i] for i in order], issues


def missing_pose(packets: list[KLVPacket]) -> list[str]:
    """The pose items (position, height, heading) a stream never sends."""
    sent = set().union(*(p.fields for p in packets)) if packets else set()
    return [name for name, tags in POSE_TAGS.items() if not sent.intersection(tags)]


def klv_telemetry(stream: KLVStream, *, geoid=None, report_on_change: bool = True) -> Table:
    """Decoded packets -> an eoloc telemetry :class:`Table` (one row per good packet, grouped by
    stream, each stream in time order).

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
    groups: dict[str, list[KLVPacket]] = {}
    for p in stream.packets:
        groups.setdefault(p.stream, []).append(p)
    parts, issues = [], []
    for name, pk in groups.items():
        ordered, found = stream_order(pk, stream.path)
        issues += found
        lacking = missing_pose(pk)
        if lacking:
            issues.append(Issue(f"{stream.path}{f' [{name}]' if name else ''}", pk[0].index,
                                f"this stream never sends {', '.join(lacking)}: it carries no pose, so its "
                                f"{len(pk)} packet(s) give no frame centre, footprint or fix"))
        parts.append(_stream_columns(ordered, geoid, report_on_change))
    if not parts:
        parts = [_stream_columns([], geoid, report_on_change)]
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return Table(stream.path, cols, cols["frame"].astype(np.int64), issues)


def _stream_columns(packets: list[KLVPacket], geoid, report_on_change: bool) -> dict[str, np.ndarray]:
    rows = [p.fields for p in packets]
    n = len(rows)

    def col(tag: int) -> np.ndarray:
        return np.array([num(r.get(tag)) for r in rows], dtype=np.float64)

    def seen(tag: int) -> np.ndarray:
        """True from the first packet that carries ``tag`` (the receiver-current state)."""
        return np.maximum.accumulate(np.array([tag in r for r in rows], dtype=bool)) if n else np.zeros(0, bool)

    raw = {tag: col(tag) for tag in (*set(TAGS.values()) - {2, 74}, *OFFSET_CORNER_TAGS, *FULL_CORNER_TAGS)}
    fill = fill_forward if report_on_change else (lambda c: c)
    v = {tag: fill(c) for tag, c in raw.items()}

    def prefer(a: int, b: int) -> np.ndarray:
        """Tag a where the packet state has it, else tag b."""
        return np.where(np.isfinite(v[a]), v[a], v[b])

    time_s = np.array([packet_time_s(r) for r in rows], dtype=np.float64)
    lat, lon = v[13], v[14]
    n_sensor = geoid.undulation(lat, lon) if n else np.zeros(0)
    h = np.where(np.isfinite(v[75]), v[75], v[15] + n_sensor)
    fc_lat, fc_lon = v[23], v[24]
    n_fc = geoid.undulation(fc_lat, fc_lon) if n else np.zeros(0)
    fc_h = np.where(np.isfinite(v[78]), v[78], v[25] + n_fc)
    # tag 42's datum follows the frame-centre height in use (ST 0601.19 §8.42.1): HAE once 78 is sent
    target_hae = seen(78)
    target_h = np.where(target_hae, v[42], v[42] + geoid.undulation(v[40], v[41])) if n else v[42]
    flags = v[47]
    measured = np.where(np.isfinite(flags), (np.nan_to_num(flags).astype(np.int64) & SLANT_RANGE_MEASURED) > 0,
                        np.nan)
    cols: dict[str, np.ndarray] = {
        "stream": np.array([p.stream for p in packets], dtype=object).astype(str),
        "time_s": time_s, "frame": np.array([p.index for p in packets], dtype=np.float64),
        "pts_s": np.array([math.nan if p.pts_s is None else p.pts_s for p in packets], dtype=np.float64),
        "lat_deg": lat, "lon_deg": lon, "h_m": h, "h_msl_m": v[15],
        "yaw_deg": v[5], "pitch_deg": prefer(90, 6), "roll_deg": prefer(91, 7),
        "gimbal1_deg": v[18], "gimbal2_deg": v[19], "sensor_roll_deg": v[20],
        "range_m": v[21], "range_measured": measured.astype(np.float64), "hfov_deg": v[16], "vfov_deg": v[17],
        "fc_lat_deg": fc_lat, "fc_lon_deg": fc_lon, "fc_h_m": fc_h, "fc_h_msl_m": v[25],
        "target_lat_deg": v[40], "target_lon_deg": v[41], "target_h_m": target_h,
        "target_elevation_hae": target_hae.astype(np.float64),
        "target_ce90_m": v[45], "target_le90_m": v[46],
    }
    for k in range(4):
        full_lat, full_lon = v[FULL_CORNER_TAGS[2 * k]], v[FULL_CORNER_TAGS[2 * k + 1]]
        off_lat, off_lon = v[OFFSET_CORNER_TAGS[2 * k]], v[OFFSET_CORNER_TAGS[2 * k + 1]]
        cols[f"corner{k + 1}_lat_deg"] = np.where(np.isfinite(full_lat), full_lat, fc_lat + off_lat)
        cols[f"corner{k + 1}_lon_deg"] = np.where(np.isfinite(full_lon), full_lon, fc_lon + off_lon)
    return cols


def packet_view(fields: dict[int, Any], geoid=None) -> dict[str, float]:
    """One packet's time, pose and view as plain floats, named and converted as
    :func:`klv_telemetry`'s columns (tag preferences, MSL -> ellipsoidal through the geoid;
    NaN where absent): time_s, lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, gimbal1_deg,
    gimbal2_deg, sensor_roll_deg, hfov_deg, vfov_deg, fc_lat_deg, fc_lon_deg, fc_h_m. ``fields``
    already holds every value the packet stands for (report-on-change carried by the caller):
    the live path's one packet at a time, without building a table."""
    from ...terrain.geoid import default_geoid

    def val(tag: int) -> float:
        return num(fields.get(tag))

    def prefer(a: int, b: int) -> float:
        x = val(a)
        return x if math.isfinite(x) else val(b)

    lat, lon, fc_lat, fc_lon = val(13), val(14), val(23), val(24)
    h, fc_h = val(75), val(78)
    if not (math.isfinite(h) and math.isfinite(fc_h)):  # MSL: one geoid look-up for both points
        n_sensor, n_fc = (geoid or default_geoid()).undulation(np.array([lat, fc_lat]), np.array([lon, fc_lon]))
        h = h if math.isfinite(h) else val(15) + float(n_sensor)
        fc_h = fc_h if math.isfinite(fc_h) else val(25) + float(n_fc)
    return {"time_s": packet_time_s(fields), "lat_deg": lat, "lon_deg": lon, "h_m": h, "yaw_deg": val(5),
            "pitch_deg": prefer(90, 6), "roll_deg": prefer(91, 7), "gimbal1_deg": val(18), "gimbal2_deg": val(19),
            "sensor_roll_deg": val(20), "hfov_deg": val(16), "vfov_deg": val(17), "fc_lat_deg": fc_lat,
            "fc_lon_deg": fc_lon, "fc_h_m": fc_h}


# -- ST 0903 VMTI -------------------------------------------------------------------------------

DETECTION_COLUMNS = ("stream", "frame", "time_s", "target_id", "u_px", "v_px", "bbox_u0", "bbox_v0", "bbox_u1",
                     "bbox_v1", "frame_width", "frame_height", "vmti_hfov_deg", "vmti_vfov_deg",
                     "encoder_lat_deg", "encoder_lon_deg", "encoder_h_m")


def vmti_detections(stream: KLVStream, *, pixels_from: int = 1) -> Table:
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
    rows: list[tuple] = []  # one tuple per detection, in DETECTION_COLUMNS order
    issues = []
    size: dict[str, tuple[float, float]] = {}
    fc: dict[str, tuple[float, float]] = {}
    for p in stream.packets:
        vals = p.fields
        if 23 in vals or 24 in vals:
            fc[p.stream] = (num(vals.get(23)), num(vals.get(24)))
        vm = vals.get(74)
        if vm is None or not hasattr(vm, "targets"):
            continue
        last_w, last_h = size.get(p.stream, (math.nan, math.nan))
        w = num(vm.value(8)) if vm.value(8) is not None else last_w
        hgt = num(vm.value(9)) if vm.value(9) is not None else last_h
        size[p.stream] = (w, hgt)
        t = packet_time_s(vals)
        fc_lat, fc_lon = fc.get(p.stream, (math.nan, math.nan))
        vm_hfov, vm_vfov = num(vm.value(11)), num(vm.value(12))
        for tg in vm.targets:
            u, v = vmti_centroid(tg, w, pixels_from)
            if not (math.isfinite(u) and math.isfinite(v)):
                issues.append(f"packet {p.index}: VMTI target {tg.target_id} has no usable centroid "
                              f"(frame width {w}); skipped")
                continue
            u0, v0 = pixel_number(tg.value(2), w, pixels_from)
            u1, v1 = pixel_number(tg.value(3), w, pixels_from)
            loc = tg.value(17)
            if loc is not None and hasattr(loc, "lat_deg"):
                elat, elon, eh = loc.lat_deg, loc.lon_deg, loc.h_m
            else:
                elat, elon = fc_lat + num(tg.value(10)), fc_lon + num(tg.value(11))
                eh = num(tg.value(12))
            rows.append((p.stream, p.index, t, str(tg.target_id), u, v, u0, v0, u1, v1, w, hgt, vm_hfov, vm_vfov,
                         elat, elon, eh))
    columns = list(zip(*rows, strict=True)) if rows else [()] * len(DETECTION_COLUMNS)
    cols = {k: np.array(val, dtype=object if k in ("target_id", "stream") else np.float64)
            for k, val in zip(DETECTION_COLUMNS, columns, strict=True)}
    cols["target_id"] = cols["target_id"].astype(str)
    cols["stream"] = cols["stream"].astype(str)
    return Table(stream.path, cols, cols["frame"].astype(np.int64), [Issue(stream.path, 0, m) for m in issues])


def pixel_number(value: Any, width: float, pixels_from: int = 1) -> tuple[float, float]:
    """ST 0903 pixel number -> (u, v) in eoloc's 0-based convention (1-based numbers by the standard)."""
    if not isinstance(value, int) or isinstance(value, bool) or not (np.isfinite(width) and width > 0) or \
            value < pixels_from:
        return math.nan, math.nan
    row, col = divmod(value - pixels_from, int(width))
    return float(col), float(row)


def vmti_centroid(target, width: float, pixels_from: int = 1) -> tuple[float, float]:
    row, col = target.value(19), target.value(20)
    if isinstance(row, int) and isinstance(col, int) and row >= pixels_from and col >= pixels_from:
        return float(col - pixels_from), float(row - pixels_from)
    u, v = pixel_number(target.value(1), width, pixels_from)
    if np.isfinite(u):
        return u, v
    (u0, v0), (u1, v1) = pixel_number(target.value(2), width, pixels_from), pixel_number(target.value(3), width,
                                                                                          pixels_from)
    return (u0 + u1) / 2.0, (v0 + v1) / 2.0
