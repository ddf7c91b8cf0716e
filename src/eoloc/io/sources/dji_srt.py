"""DJI ``.SRT`` video telemetry: the subtitle track DJI drones write beside (or into) each video.

Each subtitle block is one record; its start time is the video's clock (``time_s``, seconds from
the first frame), ``frame`` the block's FrameCnt/SrtCnt when it has one, else its number. Every
format in the wild is read, told apart block by block (the rules and their sources):

- bracket formats (Mavic 2/3, Air 2/2S/3/3S, Mini 3/4/5, Avata): ``[latitude: …] [longitude: …]``
  (also the ``longtitude`` typo), ``[rel_alt: … abs_alt: …]`` or ``[altitude: …]`` (absolute),
  ``[focal_len: …]`` (35 mm equivalent: ``240`` = 24 mm on older models, ``24.00`` on newer:
  a value over 100 is tenths), ``[gb_yaw: … gb_pitch: … gb_roll: …]`` (the gimbal's attitude);
- function formats (Phantom 3/4, Mavic Pro, Mini, Matrice 300, P4 RTK): ``GPS(a, b, c)`` is
  *(longitude, latitude, satellites)* — except the Matrice 300's ``GPS(lat, lon, 0.0M)``, whose third
  value carries a unit (the rule of JuanIrache's DJI_SRT_Parser, MIT) — ``HOME(lon, lat[, alt])``,
  ``BAROMETER``/``Hb``/``H`` (metres above the take-off point), ``F.PRY (pitch, roll, yaw)`` (the
  aircraft) and ``G.PRY (pitch, roll, yaw)`` (the gimbal). A file whose tuples only make sense the
  other way round (a latitude past 90°) is read the other way, and said so;
- the Mavic Air 2 firmware that wrote latitude and longitude in radians (all within ±π, spanning
  under 0.001) is converted, and said so (JuanIrache's rule).

DJI's gimbal angles (``G.PRY``, ``gb_*``) are the camera's own attitude, earth-referenced (yaw from
true north, pitch negative below the horizon), as in DJI's photos; most formats carry no attitude
at all: their records are kept (positions, heights, times) and named as unlocatable. Heights follow
:mod:`.heights`. A block that cannot be read costs its own record, named with its line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ...errors import TableError
from ..table import Issue, Table
from .base import SourceData, is_text
from .heights import resolve_heights

_TIMECODE = re.compile(r"(\d+):(\d{2}):(\d{2})[,.](\d{1,3})\s*-->")
_COUNTER = re.compile(r"\b(?:FrameCnt|SrtCnt)\s*:\s*(\d+)")
_DATE = re.compile(r"(\d{4})[-.](\d{1,2})[-.](\d{1,2})\s+(\d{1,2}):(\d{2}):(\d{2})(?:[.,](\d{1,3}))?")
_BRACKET = re.compile(r"\[([^\[\]]*)\]")
_PAIR = re.compile(r"([A-Za-z_][A-Za-z_ ]*?)\s*:\s*(-?\d+(?:\.\d+)?(?:/\d+(?:\.\d+)?)?)")
_TUPLE = re.compile(r"\b(GPS|HOME|F\.PRY|G\.PRY|BAROMETER)\s*\(([^)]*)\)")
_SCALAR = re.compile(r"(?:(?<![\w.])(BAROMETER|Hb|Hs)\s*:\s*|(?<![\w.])(H|D)\s+)(-?\d+(?:\.\d+)?)\s*[mM]?\b")
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")
_TAG = re.compile(r"<[^>]*>")


class DjiSrt:
    name = "dji-srt"
    summary = "DJI video telemetry (.SRT subtitles)"

    def sniff(self, path: Path, head: bytes) -> bool:
        """SubRip text: the first line that is not blank is a bare block number."""
        if not is_text(head):
            return False
        for line in head.decode("utf-8", "replace").lstrip("\ufeff").splitlines():
            if line.strip():
                return line.strip().isdigit()
        return False

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        return read_srt(path, geoid=geoid, dem=dem)


def _blocks(text: str):
    """(first line number, lines) of each subtitle block: blank lines separate them; a block also
    starts at a lone number followed by a time code (files that lost their blank lines)."""
    lines = text.splitlines()
    start, block = 1, []
    for i, raw in enumerate(lines, 1):
        line = raw.strip()
        new = line.isdigit() and i < len(lines) and ("-->" in lines[i] or _DATE.search(lines[i]) is not None)
        if not line or (new and block):
            if block:
                yield start, block
            block = [] if not line else [line]
            start = i + 1 if not line else i
            continue
        if not block:
            start = i
        block.append(line)
    if block:
        yield start, block


def _floats(s: str) -> list[float]:
    return [float(x) for x in _NUMBER.findall(s)]


def parse_srt_records(text: str) -> tuple[list[dict], list[tuple[int, str]]]:
    """Each block's raw values (dicts of floats and a few strings) and the blocks that could not be
    read ((line, why))."""
    records, bad = [], []
    for start, block in _blocks(text):
        body = [b for b in block if not b.isdigit()]
        if not body:
            bad.append((start, "a subtitle number with nothing after it (the file ends early?)"))
            continue
        joined = _TAG.sub(" ", " ".join(body)).replace("°", "").replace("Â", "")
        r: dict = {"line": start}
        m = _TIMECODE.search(joined)
        if m:
            hh, mm, ss, ms = m.groups()
            r["t"] = int(hh) * 3600 + int(mm) * 60 + int(ss) + int(ms.ljust(3, "0")) / 1000.0
        m = _COUNTER.search(joined)
        if m:
            r["count"] = float(m.group(1))
        m = _DATE.search(joined)
        if m:
            y, mo, d, hh, mi, ss, frac = m.groups()
            r["date"] = (f"{int(y):04d}-{int(mo):02d}-{int(d):02d} {int(hh):02d}:{mi}:{ss}"
                         + (f".{frac}" if frac else ""))
        for inside in _BRACKET.findall(joined):
            for key, value in _PAIR.findall(inside):
                key = key.strip().lower().replace("longtitude", "longitude")
                if "/" not in value:
                    r[key] = float(value)
        for key, inside in _TUPLE.findall(joined):
            if key == "BAROMETER":  # BAROMETER(91.2): metres above take-off, like BAROMETER:91.2
                values = _floats(inside)
                if values:
                    r[key] = values[0]
            else:
                r[key] = inside
        for k1, k2, value in _SCALAR.findall(joined):
            r.setdefault((k1 or k2).upper() if (k1 or k2) in ("H", "D") else (k1 or k2), float(value))
        if not any(k in r for k in ("latitude", "GPS")):
            if "t" not in r and "date" not in r:
                bad.append((start, f"no time code, date or position in {' '.join(body)[:60]!r}"))
                continue
        records.append(r)
    return records, bad


def read_srt(path: str | Path, *, geoid=None, dem=None) -> SourceData:
    """The records of a DJI SRT file (see the module's notes); a TableError naming the file when
    nothing in it is a record."""
    path = Path(path)
    src = str(path)
    data = path.read_bytes()
    if not data.strip(b"\xef\xbb\xbf \r\n\t0123456789"):
        raise TableError(f"DJI SRT {src!r} has no subtitle record (empty, or only numbers): the recording stopped "
                         "before it wrote any; use the SRT of another clip or the flight log")
    text = data.decode("utf-8", "replace").lstrip("\ufeff")
    records, bad = parse_srt_records(text)
    issues = [Issue(src, line, why + "; block skipped") for line, why in bad]
    if not records:
        raise TableError(f"DJI SRT {src!r}: no block could be read ({len(bad)} tried; the first at line "
                         f"{bad[0][0] if bad else 1}: {bad[0][1] if bad else 'nothing there'})")
    n = len(records)
    line = np.array([r["line"] for r in records], dtype=np.int64)

    def col(key: str) -> np.ndarray:
        return np.array([r.get(key, np.nan) for r in records], dtype=np.float64)

    notes: list[str] = []
    lat, lon = col("latitude"), col("longitude")
    order = _tuple_order(records)
    gps = [_tuple(r.get("GPS")) for r in records]
    sats = np.full(n, np.nan)
    h_gps = np.full(n, np.nan)
    for k, g in enumerate(gps):
        if len(g) >= 2 and not np.isfinite(lat[k]):
            lat[k], lon[k] = (g[1], g[0]) if order == "lon,lat" else (g[0], g[1])
            if len(g) >= 3:  # a satellite count, or an altitude (with a unit or decimals: Matrice 300, Avata 2)
                third = records[k]["GPS"].split(",")[-1]
                (h_gps if "M" in third.upper() or "." in third else sats)[k] = g[2]
    if order == "lat,lon" and not _m300(records):
        notes.append("its GPS(…) tuples only make sense as (latitude, longitude): read so")
    finite = np.isfinite(lat) & np.isfinite(lon)
    if finite.any() and _radians(lat[finite], lon[finite]):
        lat, lon = np.degrees(lat), np.degrees(lon)
        notes.append("latitude and longitude are in radians (a Mavic Air 2 firmware's bug): converted")
    zero = finite & (lat == 0.0) & (lon == 0.0)
    if zero.any():
        issues.append(Issue(src, int(line[np.flatnonzero(zero)[0]]), f"position 0, 0 (no GPS fix) on {zero.sum()} "
                            "record(s): not located"))
        lat[zero] = lon[zero] = np.nan
    with np.errstate(invalid="ignore"):
        wild = (np.abs(lat) > 90) | (np.abs(lon) > 180)
    if wild.any():
        issues.append(Issue(src, int(line[np.flatnonzero(wild)[0]]), f"latitude/longitude out of range on "
                            f"{wild.sum()} record(s): not located"))
        lat[wild] = lon[wild] = np.nan
    missing = ~(np.isfinite(lat) & np.isfinite(lon))
    lat[missing] = lon[missing] = np.nan  # half a position (a block cut short) is none
    if missing.all():
        raise TableError(f"DJI SRT {src!r} gives no position in any of its {n} records (this model writes only camera "
                         "settings): its poses must come from the flight log")
    if missing.any():
        issues.append(Issue(src, int(line[np.flatnonzero(missing)[0]]), f"{missing.sum()} record(s) without a "
                            "position: not located"))

    # heights
    h_rel, rel_tag = col("rel_alt"), "rel_alt"
    for tag in ("BAROMETER", "Hb", "H"):
        if not np.isfinite(h_rel).any() and np.isfinite(col(tag)).any():
            h_rel, rel_tag = col(tag), tag
    h_msl, msl_tag = col("abs_alt"), "abs_alt"
    if not np.isfinite(h_msl).any():
        h_msl, msl_tag = col("altitude"), "altitude"
    if not np.isfinite(h_msl).any() and np.isfinite(h_gps).any() and np.nanmax(np.abs(h_gps)) > 0:
        h_msl, msl_tag = h_gps, "GPS altitude"
    homes = [_tuple(r.get("HOME")) for r in records]
    home = next((h for h in homes if len(h) >= 2), None)
    takeoff, how = None, ""
    if home is not None:
        takeoff = (home[1], home[0]) if order == "lon,lat" else (home[0], home[1])
        how = "the HOME point"
    elif np.isfinite(h_rel).any():
        k = int(np.flatnonzero(np.isfinite(h_rel) & ~missing)[0]) if (np.isfinite(h_rel) & ~missing).any() else -1
        if k >= 0 and abs(h_rel[k]) < 2.0:
            takeoff, how = (float(lat[k]), float(lon[k])), f"the first record, {rel_tag} {h_rel[k]:g} m"
    h, found, how_h = resolve_heights(src, line, lat, lon, h_msl=h_msl if np.isfinite(h_msl).any() else None,
                                      h_rel=h_rel if np.isfinite(h_rel).any() else None, takeoff=takeoff,
                                      msl_tag=msl_tag, rel_tag=rel_tag, takeoff_how=how, geoid=geoid, dem=dem)
    issues += found
    notes.append(f"heights: {how_h}")

    # attitude: the gimbal's, earth-referenced
    yaw, pitch, roll = col("gb_yaw"), col("gb_pitch"), col("gb_roll")
    g_pry = [_tuple(r.get("G.PRY")) for r in records]
    for k, g in enumerate(g_pry):
        if len(g) == 3 and not np.isfinite(yaw[k]):
            pitch[k], roll[k], yaw[k] = g
    no_att = ~(np.isfinite(yaw) & np.isfinite(pitch))
    if no_att.all():
        issues.append(Issue(src, int(line[0]), "this SRT carries no camera attitude (no G.PRY or gb_yaw/gb_pitch): "
                            "its records are not located; give a flight log with the gimbal angles (an Airdata CSV) "
                            "instead"))
    elif no_att.any():
        issues.append(Issue(src, int(line[np.flatnonzero(no_att)[0]]), f"{no_att.sum()} record(s) without the "
                            "gimbal's attitude: not located"))
    roll = np.where(np.isfinite(roll), roll, 0.0)

    t = col("t")
    clock = np.array([_seconds(r.get("date")) for r in records])
    if not np.isfinite(t).any():  # no time codes (Mavic 2 early firmware): the dates' clock
        if np.isfinite(clock).any():
            t = clock - np.nanmin(clock)
            notes.append("no subtitle time codes: time_s from the blocks' dates (1 s resolution), 0 at the first")
    count = col("count")
    # a file with frame counters has a block per video frame, the first at 0: frame = block index
    frame = np.where(np.isfinite(count), np.arange(n, dtype=np.float64), np.nan)
    cols = {"time_s": t, "frame": frame, "lat_deg": lat, "lon_deg": lon, "h_m": h, "yaw_deg": yaw,
            "pitch_deg": pitch, "roll_deg": roll, "gimbal1_deg": np.zeros(n), "gimbal2_deg": np.zeros(n),
            "sensor_roll_deg": np.zeros(n), "range_m": np.full(n, np.nan), "h_rel_m": h_rel, "h_abs_m": h_msl,
            "satellites": sats, "frame_count": count,
            "date_s": clock}
    focal = col("focal_len")
    if np.isfinite(focal).any():
        focal = np.where(focal > 100, focal / 10.0, focal)  # older firmware: tenths of a millimetre
        cols["focal_35mm"] = focal
    f_pry = [_tuple(r.get("F.PRY")) for r in records]
    if any(len(f) == 3 for f in f_pry):
        fp = np.array([f if len(f) == 3 else (np.nan,) * 3 for f in f_pry], dtype=np.float64)
        cols["aircraft_pitch_deg"], cols["aircraft_roll_deg"], cols["aircraft_yaw_deg"] = fp.T
    table = Table(src, cols, line, sorted(issues, key=lambda i: i.line))
    return SourceData(table, DjiSrt.name, camera_attitude=True, notes=notes)


def _tuple(s: str | None) -> list[float]:
    return _floats(s) if s else []


def _m300(records: list[dict]) -> bool:
    """The Matrice 300's GPS(lat, lon, 0.0M): a unit on the third value."""
    return any(re.search(r",\s*-?\d+(?:\.\d+)?\s*M\s*$", r.get("GPS", "")) for r in records[:50])


def _tuple_order(records: list[dict]) -> str:
    """How the file's GPS(a, b, …) tuples are ordered: (longitude, latitude) as DJI writes them,
    (latitude, longitude) on the Matrice 300, or whichever order only makes sense."""
    tuples = [_tuple(r.get("GPS")) for r in records if r.get("GPS")]
    if not tuples:
        return "lon,lat"
    order = "lat,lon" if _m300(records) else "lon,lat"
    first = np.array([t[0] for t in tuples if len(t) >= 2])
    second = np.array([t[1] for t in tuples if len(t) >= 2])
    if order == "lon,lat" and (np.abs(second) > 90).any() and not (np.abs(first) > 90).any():
        order = "lat,lon"
    return order


def _radians(lat: np.ndarray, lon: np.ndarray) -> bool:
    return bool(np.abs(lon).max() <= math.pi and np.abs(lat).max() <= math.pi / 2
                and np.ptp(lat) < 0.001 and np.ptp(lon) < 0.001 and (np.abs(lat) > 0.01).any())


def _seconds(date: str | None) -> float:
    if not date:
        return np.nan
    from datetime import UTC, datetime

    try:  # the drone's clock, no time zone: taken as UTC (the user corrects it with --start-utc)
        return datetime.fromisoformat(date).replace(tzinfo=UTC).timestamp()
    except ValueError:
        return np.nan
