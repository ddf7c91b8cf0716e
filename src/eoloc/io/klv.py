"""MISB ST 0601 (UAS Datalink Local Set) and ST 0903 (VMTI) metadata in, from raw KLV or MPEG-TS.

What is ours and what is not:

- **Field decoding** (BER-OID tags, IMAPB and fixed-point mappings, special values, the bcc-16
  checksum, nested ST 0903 VMTI packs) is `stanag4609`'s, a maintained pure-Python MISB toolkit
  (README: why it and not klvdata). **MPEG-TS demultiplexing** is its transport layer too.
- **Framing** is ours: the stream is scanned for the ST 0601 key, every packet is decoded on its
  own, and after a corrupt or truncated packet the scan resumes at the next key *inside* the bad
  bytes, so a truncated packet never swallows the good packet that follows it. Every bad packet
  and every skipped run of bytes is reported with its byte offset; every good packet is kept.
- **Mapping** into eoloc telemetry is ours (:func:`klv_telemetry`): report-on-change (a tag absent
  from a packet keeps its last value, ST 0601 §6), full-range pitch/roll (tags 90/91) preferred
  over tags 6/7, HAE heights (75, 78) preferred over MSL (15, 25), MSL converted to ellipsoidal
  height through the geoid (EGM96 bundled), offset corners (26-33) turned into absolute ones.

Angles come out in eoloc's conventions unchanged, because ST 0601's are the same: platform
heading/pitch/roll are the ZYX yaw/pitch/roll of SPEC §2, and the sensor relative azimuth,
elevation and roll are the az-el turret's angles (azimuth about body z, clockwise from the nose;
elevation about the new y, negative down; roll about the boresight, clockwise seen from behind the
camera). The line of sight is R_ned_body(5, 90|6, 91|7) . Rz(18) . Ry(19) . Rx(20) applied to x.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import KLVError
from .table import Table

UAS_KEY = bytes.fromhex("060E2B34020B01010E01030101000000")
TS_PACKET = 188

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


@dataclass(frozen=True)
class KLVIssue:
    """A packet (or run of bytes) that could not be used, with its place in the file."""

    path: str
    packet: int | None  # packet number in the stream (good and bad counted), None for skipped bytes
    offset: int  # byte offset in the file (raw KLV) or in the PID's KLV stream (MPEG-TS)
    kind: str  # "checksum" | "truncated" | "malformed" | "skipped bytes"
    message: str

    def __str__(self) -> str:
        where = f"packet {self.packet} at byte {self.offset}" if self.packet is not None else f"byte {self.offset}"
        return f"{self.path}: {where}: {self.kind}: {self.message}"


@dataclass(frozen=True)
class KLVPacket:
    """One good ST 0601 packet: its number, byte offset, transport PTS (s, MPEG-TS only) and fields."""

    index: int
    offset: int
    pts_s: float | None
    uas: Any  # stanag4609.st0601.UASLocalSet

    def values(self) -> dict[int, Any]:
        """tag -> decoded value (the last one for a repeated tag)."""
        return {f.definition.tag: f.value for f in self.uas.fields}


@dataclass
class KLVStream:
    """Everything read from one file: the good packets, the bad ones, and field-level warnings."""

    path: str
    container: str  # "klv" or "mpegts"
    packets: list[KLVPacket]
    issues: list[KLVIssue] = field(default_factory=list)
    field_warnings: list[str] = field(default_factory=list)

    @property
    def n_good(self) -> int:
        return len(self.packets)

    @property
    def n_bad(self) -> int:
        return sum(1 for i in self.issues if i.packet is not None)

    def counts(self) -> dict[str, int]:
        """How many packets or byte runs of each problem kind, plus the good packets."""
        c = Counter(i.kind for i in self.issues)
        return {"good": self.n_good, **c}

    def summary(self) -> str:
        bad = ", ".join(f"{n} {k}" for k, n in self.counts().items() if k != "good") or "none bad"
        return f"{self.path} ({self.container}): {self.n_good} good ST 0601 packets; {bad}"


# -- reading ------------------------------------------------------------------------------------


def read_klv(path: str | Path) -> KLVStream:
    """Read every ST 0601 packet of a raw KLV file (.klv/.bin) or an MPEG-TS file (.ts/.mpg).

    The container is recognised from the content (0x47 sync bytes every 188 bytes), not the name.
    Raises :class:`KLVError` only when nothing can be read; bad packets are reported in
    ``issues`` and the good ones kept.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise KLVError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not data:
        raise KLVError(f"{path} is empty")
    if _looks_like_ts(data):
        stream = _read_ts(data, str(path))
    else:
        stream = decode_klv_bytes(data, str(path))
    if not stream.packets and stream.n_bad == 0:
        raise KLVError(f"{path}: no MISB ST 0601 packet found (key {UAS_KEY.hex(' ')}); is this a KLV "
                       "stream or an MPEG-TS file with a KLV data stream?")
    return stream


def decode_klv_bytes(data: bytes, path: str = "<bytes>", *, pts: list[tuple[int, float | None]] | None = None,
                     container: str = "klv") -> KLVStream:
    """Frame and decode a byte string of concatenated KLV packets (see the module notes).

    pts: optional (byte offset, PTS seconds) marks: a packet takes the PTS of the last mark at or
    before its key.
    """
    packets: list[KLVPacket] = []
    issues: list[KLVIssue] = []
    warnings: Counter = Counter()
    first_seen: dict[tuple, int] = {}
    marks = np.array([m[0] for m in pts], dtype=np.int64) if pts else None
    n = 0
    pos = 0
    size = len(data)
    after_bad = False  # bytes up to the next key after a bad packet belong to that packet: not reported twice
    while pos < size:
        k = data.find(UAS_KEY, pos)
        if k < 0:
            if size - pos and not after_bad:
                issues.append(KLVIssue(path, None, pos, "skipped bytes", f"{size - pos} bytes after the last packet "
                                       "are not an ST 0601 packet"))
            break
        if k > pos and not after_bad:
            issues.append(KLVIssue(path, None, pos, "skipped bytes",
                                   f"{k - pos} bytes before the next ST 0601 key are not a packet"))
        after_bad = True
        end, why = _packet_end(data, k)
        if end is None:
            issues.append(KLVIssue(path, n, k, "truncated", why))
            n += 1
            pos = k + 1  # the next key may sit inside what the bad length claimed
            continue
        raw = data[k:end]
        try:
            uas = _decode_uas(raw)
        except Exception as exc:  # any decoder failure is this packet's, never the stream's
            kind = "checksum" if type(exc).__name__ == "ChecksumError" else "malformed"
            issues.append(KLVIssue(path, n, k, kind, _one_line(exc)))
            n += 1
            pos = k + 1
            continue
        for fi in uas.issues:
            key = (fi.tag, fi.name, fi.message)
            warnings[key] += 1
            first_seen.setdefault(key, n)
        pts_s = None
        if marks is not None:
            j = int(np.searchsorted(marks, k, side="right")) - 1
            pts_s = pts[max(j, 0)][1]
        packets.append(KLVPacket(n, k, pts_s, uas))
        n += 1
        pos = end
        after_bad = False
    field_warnings = [f"tag {key[0]} ({key[1]}) not decoded in {count} packet(s), first packet {first_seen[key]}: "
                      f"{key[2]} (the rest of each packet is used)"
                      for key, count in warnings.items()]
    return KLVStream(path, container, packets, issues, field_warnings)


def _packet_end(data: bytes, k: int) -> tuple[int | None, str]:
    """End offset of the packet whose key starts at ``k`` (BER length), or None and why not."""
    i = k + len(UAS_KEY)
    if i >= len(data):
        return None, "the stream ends inside the packet's key or length"
    first = data[i]
    if first < 0x80:
        length, used = first, 1
    else:
        nbytes = first & 0x7F
        if nbytes == 0 or nbytes > 8:
            return None, f"invalid BER length byte 0x{first:02X}"
        if i + 1 + nbytes > len(data):
            return None, "the stream ends inside the packet's BER length"
        length, used = int.from_bytes(data[i + 1:i + 1 + nbytes], "big"), 1 + nbytes
    end = i + used + length
    if end > len(data):
        return None, (f"the packet declares {length} bytes of value but only {len(data) - i - used} remain "
                      "(cut short, or a corrupt length)")
    return end, ""


def _decode_uas(raw: bytes):
    from stanag4609.st0601 import FieldDecodingMode, decode_uas_local_set

    # PRESERVE: a field that cannot be decoded (often a malformed security set) is reported and
    # skipped instead of losing the packet; the checksum and structure stay strict.
    return decode_uas_local_set(raw, field_decoding=FieldDecodingMode.PRESERVE, require_timestamp=False,
                                require_version=False)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().replace("\n", " ")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _looks_like_ts(data: bytes) -> bool:
    n = min(len(data) // TS_PACKET, 5)
    return n >= 2 and all(data[i * TS_PACKET] == 0x47 for i in range(n))


def _read_ts(data: bytes, path: str) -> KLVStream:
    """KLV packets from every KLV elementary stream (PID) of an MPEG-TS file, with their PTS.

    Asynchronous carriage (stream_type 0x06, 'KLVA') and synchronous carriage (0x15, metadata
    access units) both end up as one byte stream per PID, framed like a raw KLV file. Transport
    errors (lost sync, bad continuity) are recovered by the demultiplexer and reported.
    """
    from stanag4609.transport.demux import PESStreamEvent, StreamKind, TransportDemuxer
    from stanag4609.transport.metadata import parse_metadata_au_cells

    demux = TransportDemuxer(recover_transport=True)
    issues: list[KLVIssue] = []
    per_pid: dict[int, tuple[bytearray, list]] = {}
    try:
        events = demux.feed(data) + demux.finish()
    except Exception as exc:
        raise KLVError(f"{path}: the MPEG-TS transport cannot be read: {_one_line(exc)}") from None
    for ev in events:
        if not isinstance(ev, PESStreamEvent) or ev.kind is not StreamKind.KLV:
            continue
        buf, marks = per_pid.setdefault(ev.pid, (bytearray(), []))
        payload = ev.pes.payload
        if ev.stream.stream_type == 0x15:  # synchronous metadata: access-unit cells wrap the KLV
            try:
                payload = b"".join(cell.data for cell in parse_metadata_au_cells(payload))
            except Exception as exc:
                issues.append(KLVIssue(path, None, int(ev.pes.offset or 0), "malformed",
                                       f"PID {ev.pid}: metadata access unit cannot be read: {_one_line(exc)}"))
                continue
        marks.append((len(buf), ev.pes.pts_seconds))
        buf.extend(payload)
    packets: list[KLVPacket] = []
    warnings: list[str] = []
    for pid, (buf, marks) in sorted(per_pid.items()):
        s = decode_klv_bytes(bytes(buf), f"{path} [PID {pid}]", pts=marks, container="mpegts")
        base = len(packets)
        packets += [KLVPacket(base + p.index, p.offset, p.pts_s, p.uas) for p in s.packets]
        issues += s.issues
        warnings += s.field_warnings
    if not per_pid:
        raise KLVError(f"{path}: MPEG-TS with no KLV metadata stream (no PID with stream_type 0x06 'KLVA' or 0x15)")
    return KLVStream(path, "mpegts", packets, issues, warnings)


# -- mapping into telemetry ---------------------------------------------------------------------


def _num(v: Any) -> float:
    """A decoded value as a float; special values ('off earth', 'reserved', ...) become NaN."""
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        return float(v) if math.isfinite(v) else math.nan
    return math.nan


def _fill_forward(col: np.ndarray) -> np.ndarray:
    """Report-on-change: each NaN takes the last value before it (NaN before the first value)."""
    idx = np.where(np.isfinite(col), np.arange(col.size), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.where(idx >= 0, col[np.maximum(idx, 0)], np.nan)
    return out


def klv_telemetry(stream: KLVStream, *, geoid=None, report_on_change: bool = True) -> Table:
    """ST 0601 packets -> an eoloc telemetry :class:`Table` (one row per good packet).

    Columns (degrees, metres, ellipsoidal heights): time_s (UNIX, from tag 2), frame (packet
    number), lat_deg, lon_deg, h_m, yaw_deg, pitch_deg, roll_deg, gimbal1_deg (relative azimuth),
    gimbal2_deg (relative elevation), sensor_roll_deg, range_m (slant range), range_measured (1
    laser, 0 computed, NaN unknown), hfov_deg, vfov_deg, fc_lat_deg, fc_lon_deg, fc_h_m (frame
    centre), corner{1-4}_lat_deg/_lon_deg (1 upper-left, 2 upper-right, 3 lower-right, 4
    lower-left), target_lat_deg, target_lon_deg, target_h_m, target_ce90_m, target_le90_m,
    target_elevation_hae (1 where tag 42 is HAE, 0 MSL), pts_s, h_msl_m and fc_h_msl_m (as
    sent). ``line`` holds the packet numbers.
    """
    from ..terrain.geoid import default_geoid

    geoid = geoid or default_geoid()
    rows = [p.values() for p in stream.packets]
    n = len(rows)

    def col(tag: int) -> np.ndarray:
        return np.array([_num(r.get(tag)) for r in rows], dtype=np.float64)

    def seen(tag: int) -> np.ndarray:
        """True from the first packet that carries ``tag`` (the receiver-current state)."""
        return np.maximum.accumulate(np.array([tag in r for r in rows], dtype=bool)) if n else np.zeros(0, bool)

    raw = {tag: col(tag) for tag in (*set(TAGS.values()) - {2, 74}, *OFFSET_CORNER_TAGS, *FULL_CORNER_TAGS)}
    fill = _fill_forward if report_on_change else (lambda c: c)
    v = {tag: fill(c) for tag, c in raw.items()}

    def prefer(a: int, b: int) -> np.ndarray:
        """Tag a where the packet state has it, else tag b."""
        return np.where(np.isfinite(v[a]), v[a], v[b])

    time_s = np.array([r[2].timestamp() if isinstance(r.get(2), datetime) else math.nan for r in rows])
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
        "time_s": time_s, "frame": np.array([p.index for p in stream.packets], dtype=np.float64),
        "pts_s": np.array([math.nan if p.pts_s is None else p.pts_s for p in stream.packets], dtype=np.float64),
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
    return Table(stream.path, cols, np.array([p.index for p in stream.packets], dtype=np.int64), [])


# -- ST 0903 VMTI -------------------------------------------------------------------------------


def vmti_detections(stream: KLVStream) -> Table:
    """Target detections from the VMTI local sets (ST 0601 tag 74) -> a detections :class:`Table`.

    Columns: frame (the packet number, so each detection pairs with its own packet's pose),
    time_s, target_id, u_px, v_px (centroid, eoloc pixel convention: 0-based, centre of the
    top-left pixel at (0, 0)), bbox_u0/v0/u1/v1 (px, NaN when absent), frame_width,
    frame_height, vmti_hfov_deg, vmti_vfov_deg (NaN when the VMTI set has none). ST 0903 pixel
    numbers are 1-based (row - 1) x width + column; rows/columns (tags 19/20) are 1-based.
    """
    out: dict[str, list] = {k: [] for k in ("frame", "time_s", "target_id", "u_px", "v_px", "bbox_u0", "bbox_v0",
                                            "bbox_u1", "bbox_v1", "frame_width", "frame_height", "vmti_hfov_deg",
                                            "vmti_vfov_deg")}
    issues = []
    for p in stream.packets:
        vals = p.values()
        vm = vals.get(74)
        if vm is None or not hasattr(vm, "targets"):
            continue
        w, hgt = _num(vm.value(8)), _num(vm.value(9))
        t = vals[2].timestamp() if isinstance(vals.get(2), datetime) else math.nan
        for tg in vm.targets:
            u, v = _vmti_centroid(tg, w)
            if not (np.isfinite(u) and np.isfinite(v)):
                issues.append(f"packet {p.index}: VMTI target {tg.target_id} has no usable centroid "
                              f"(frame width {w}); skipped")
                continue
            u0, v0 = _pixel_number(tg.value(2), w)
            u1, v1 = _pixel_number(tg.value(3), w)
            for key, val in (("frame", p.index), ("time_s", t), ("target_id", str(tg.target_id)), ("u_px", u),
                             ("v_px", v), ("bbox_u0", u0), ("bbox_v0", v0), ("bbox_u1", u1), ("bbox_v1", v1),
                             ("frame_width", w), ("frame_height", hgt), ("vmti_hfov_deg", _num(vm.value(11))),
                             ("vmti_vfov_deg", _num(vm.value(12)))):
                out[key].append(val)
    cols = {k: (np.array(val, dtype=object if k == "target_id" else np.float64)) for k, val in out.items()}
    cols["target_id"] = cols["target_id"].astype(str)
    from .table import Issue

    return Table(stream.path, cols, cols["frame"].astype(np.int64),
                 [Issue(stream.path, 0, m) for m in issues])


def _pixel_number(value: Any, width: float) -> tuple[float, float]:
    """ST 0903 1-based pixel number -> (u, v) in eoloc's 0-based convention."""
    if not isinstance(value, int) or isinstance(value, bool) or not (np.isfinite(width) and width > 0) or value < 1:
        return math.nan, math.nan
    row, col = divmod(value - 1, int(width))
    return float(col), float(row)


def _vmti_centroid(target, width: float) -> tuple[float, float]:
    row, col = target.value(19), target.value(20)
    if isinstance(row, int) and isinstance(col, int) and row >= 1 and col >= 1:
        return float(col - 1), float(row - 1)
    u, v = _pixel_number(target.value(1), width)
    if np.isfinite(u):
        return u, v
    (u0, v0), (u1, v1) = _pixel_number(target.value(2), width), _pixel_number(target.value(3), width)
    return (u0 + u1) / 2.0, (v0 + v1) / 2.0


# -- writing (synthetic streams, re-encoded fixes) ----------------------------------------------


def encode_uas_packet(values: dict[int, Any]) -> bytes:
    """One ST 0601 packet from {tag: value} in the standard's units (degrees, metres, datetime
    for tag 2); the checksum is computed. Tag 65 (LS version) defaults to 19."""
    from stanag4609.st0601 import encode_uas_local_set

    return encode_uas_local_set({65: 19, **values})


def encode_vmti(targets: Iterable[tuple[int, float, float]], width: int, height: int, *,
                hfov_deg: float | None = None, vfov_deg: float | None = None) -> bytes:
    """An ST 0903 VMTI local set (for ST 0601 tag 74) with one VTarget per (id, u_px, v_px)
    (eoloc pixel convention; written as 1-based centroid pixel number and row/column)."""
    from stanag4609.st0903 import VTargetData, encode_vmti_local_set

    packs = []
    for tid, u, v in targets:
        col, row = round(u) + 1, round(v) + 1
        if not (1 <= col <= width and 1 <= row <= height):
            continue
        packs.append(VTargetData(int(tid), {1: (row - 1) * width + col, 19: row, 20: col}))
    values: dict[int, Any] = {4: 5, 8: int(width), 9: int(height)}
    if hfov_deg is not None:
        values[11] = float(hfov_deg)
    if vfov_deg is not None:
        values[12] = float(vfov_deg)
    return encode_vmti_local_set(values, targets=packs)


def with_target_location(packet: bytes, lat_deg: float, lon_deg: float, h_m: float, *, ce90_m: float | None = None,
                         le90_m: float | None = None) -> bytes:
    """The packet re-encoded with a fix in the target location tags: 40 lat, 41 lon, 42 elevation
    (``h_m`` must be in tag 42's datum: HAE when the packet stream sends tag 78, else MSL), 45
    CE90 and 46 LE90 (m). Every other item is kept byte for byte; the checksum is recomputed."""
    from stanag4609.st0601 import update_uas_local_set

    upd: dict[int, Any] = {40: float(lat_deg), 41: float(lon_deg), 42: float(h_m)}
    if ce90_m is not None and np.isfinite(ce90_m):
        upd[45] = float(min(ce90_m, 4095.0))
    if le90_m is not None and np.isfinite(le90_m):
        upd[46] = float(min(le90_m, 4095.0))
    return update_uas_local_set(packet, upd)
