"""Points from the files people have: fixes and surveyed points as CSV, GeoJSON, KML or CoT.

Any eoloc output (fixes CSV/GeoJSON/KML/CoT data package) and other tools' files read into one
:class:`Points`: latitude, longitude, ellipsoidal height (NaN when the file gives none) and every
other column or property, with where each point came from (a CSV line, a GeoJSON feature, a KML
placemark, a CoT event) so that every message names it.

- **CSV**: eoloc's ``lat_deg, lon_deg, h_m`` or the usual other names (lat/latitude, lon/lng/
  longitude, h/hae/height_m); ``columns=(LAT, LON[, H])`` names them otherwise. Read by
  :func:`eoloc.io.table.read_table` (bad lines and cells reported, the good ones kept).
- **GeoJSON** (RFC 7946): Point features, ``[lon, lat, h]`` with h above the WGS-84 ellipsoid;
  properties become columns; ``columns`` picks properties instead of the geometry.
- **KML**: Placemarks with a Point. KML heights are above mean sea level (EGM96) when the
  altitudeMode is ``absolute`` and are converted to ellipsoidal with the bundled geoid; other
  modes give no height. ExtendedData becomes columns (eoloc writes its fix columns, h_m
  ellipsoidal among them, there); the placemark's name is ``name``.
- **CoT**: one ``<event>`` per file, several, an ``<events>`` wrapper, or a TAK data package (zip)
  of them. ``<point>`` lat/lon/hae (ellipsoidal); ``ce``/``le`` (1-sigma, m; 9999999 = unknown)
  become ``sigma_e_m = sigma_n_m = ce`` and ``sigma_u_m = le``; the contact's callsign is
  ``callsign`` (eoloc writes the target id there).

A record whose ``status`` column says it was not located (eoloc writes every fix, failed ones
with an empty position) is counted in ``not_located``, never reported as a bad line.
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import TableError
from .table import Column, Issue, read_table

LAT_NAMES = ("lat_deg", "lat", "latitude", "lat_dd", "y_deg")
LON_NAMES = ("lon_deg", "lon", "lng", "long", "longitude", "lon_dd", "x_deg")
H_NAMES = ("h_m", "hae_m", "h", "hae", "height_m", "height", "alt_hae_m", "ellipsoidal_height_m")
MAX_BYTES = 1 << 30  # a points file (or a data package's content) larger than this is not a points file
UNKNOWN_COT = 9999999.0


@dataclass
class Points:
    """Points of one file. ``where``: 1-based line (CSV) or feature/placemark/event number, named
    by ``unit``; ``columns``: every other column as read, as text (str objects, "" where empty;
    :meth:`numeric` gives a column as numbers); ``not_located``: records whose status says they
    have no position, by status."""

    path: str
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    columns: dict[str, np.ndarray]
    where: np.ndarray
    unit: str
    issues: list[Issue] = field(default_factory=list)
    not_located: Counter = field(default_factory=Counter)

    def __len__(self) -> int:
        return int(self.lat_deg.size)

    def place(self, i: int) -> str:
        """Where point ``i`` came from, as messages name it (file:line, or file feature n)."""
        n = int(self.where[i])
        return f"{self.path}:{n}" if self.unit == "line" else f"{self.path} {self.unit} {n}"

    def has_heights(self) -> bool:
        return bool(np.isfinite(self.h_m).any())

    def column(self, name: str) -> np.ndarray | None:
        return self.columns.get(name.lower())

    def numeric(self, name: str) -> np.ndarray | None:
        """A column as float64, NaN where empty (None when absent or when a cell is not a number)."""
        v = self.column(name)
        return None if v is None else numbers(v)


def numbers(text: np.ndarray) -> np.ndarray | None:
    """Text cells as float64 (NaN where blank), or None when a non-blank cell is not a number."""
    t = np.asarray(text, dtype=str)
    blank = np.char.strip(t) == ""
    try:
        return np.where(blank, "nan", t).astype(np.float64)
    except ValueError:
        return None


def _text(values) -> np.ndarray:
    """Cells of any kind (str, numbers, None) as str objects, "" for None."""
    vals = np.asarray(values, dtype=object)
    return np.where(np.equal(vals, None), "", vals).astype(str).astype(object)


def read_points(path: str | Path, *, columns: tuple[str, ...] | None = None, what: str = "points") -> Points:
    """The points of a CSV, GeoJSON, KML/KMZ or CoT (XML or TAK data package) file, by its suffix
    (or content when the suffix says nothing). ``columns``: the names of the latitude, longitude
    and (optional) height columns or properties, when they are not the usual ones."""
    path = Path(path)
    if not path.is_file():
        raise TableError(f"{what} file {str(path)!r} does not exist (check the path)")
    if columns is not None and len(columns) not in (2, 3):
        raise TableError(f"columns for {what}: give LAT,LON or LAT,LON,H, got {','.join(columns)!r}")
    cols = tuple(c.strip().lower() for c in columns) if columns else None
    kind = _kind(path)
    if kind == "csv":
        return _read_csv(path, cols, what)
    records, unit, issues = {"geojson": _geojson_records, "kml": _kml_records, "cot": _cot_records}[kind](path, what)
    return _from_records(str(path), records, unit, cols, issues, what)


def _kind(path: Path) -> str:
    suffix = path.suffix.lower()
    by_suffix = {".csv": "csv", ".txt": "csv", ".geojson": "geojson", ".json": "geojson", ".kml": "kml",
                 ".kmz": "kml", ".cot": "cot", ".xml": "cot", ".zip": "cot"}
    if suffix in by_suffix:
        return by_suffix[suffix]
    with path.open("rb") as fh:
        head = fh.read(4096).lstrip()
    if head.startswith(b"PK"):
        return "cot"
    if head.startswith((b"{", b"[")):
        return "geojson"
    if head.startswith(b"<"):
        return "kml" if b"<kml" in head else "cot"
    return "csv"


# -- CSV ------------------------------------------------------------------------------------------


def _read_csv(path: Path, cols: tuple[str, ...] | None, what: str) -> Points:
    """The user's column names (``cols``) or eoloc's with the usual other names."""
    spec = (("lat_deg", LAT_NAMES[1:], -90, 90, "deg"), ("lon_deg", LON_NAMES[1:], -180, 360, "deg"),
            ("h_m", H_NAMES[1:], -12_000, 100_000, "m"))
    declared = [Column(cols[i] if cols else name, () if cols else aliases, required=False, lo=lo, hi=hi, unit=unit)
                for i, (name, aliases, lo, hi, unit) in enumerate(spec) if not cols or i < len(cols)]
    t = read_table(path, declared, what=what, key=(), keep_other=True)
    src = str(path)
    missing = [c for c in declared[:2] if c.name not in t.columns]
    if missing:
        names = ", ".join(c.name + (f" (or {', '.join(c.aliases)})" if c.aliases else "") for c in missing)
        raise TableError(f"{what} file {src!r} lacks required column(s) {names}: name its latitude, longitude and "
                         f"height columns with --{what.split()[0]}-columns LAT,LON,H")
    lat, lon = t.columns.pop(declared[0].name), t.columns.pop(declared[1].name)
    h = t.columns.pop(declared[2].name) if len(declared) > 2 and declared[2].name in t.columns else np.nan
    other = {k: _text(v) for k, v in t.columns.items()}
    return _finish(src, lat, lon, np.broadcast_to(h, lat.shape), other, np.asarray(t.line), "line", list(t.issues))


def _finish(src: str, lat, lon, h, other: dict, where, unit: str, issues: list[Issue]) -> Points:
    """Drop records without a position: silently counted when their status says so, else with an
    issue naming the record."""
    lat, lon, h = (np.asarray(a, dtype=np.float64) for a in (lat, lon, h))
    has = np.isfinite(lat) & np.isfinite(lon)
    status = other.get("status")
    not_located: Counter = Counter()
    if status is not None:
        failed = (status != "OK") & (status != "")
        not_located.update(str(s) for s in status[failed & ~has])
        has &= ~failed
        quiet = failed
    else:
        quiet = np.zeros(has.size, dtype=bool)
    for i in np.flatnonzero(~has & ~quiet):
        issues.append(Issue(src, int(where[i]), f"no position (latitude and longitude needed); {unit} skipped"))
    issues.sort(key=lambda i: i.line)
    return Points(src, lat[has], lon[has], h[has], {k: np.asarray(v)[has] for k, v in other.items()},
                  np.asarray(where)[has], unit, issues, not_located)


def _from_records(src: str, records: list[tuple[int, dict, tuple[float, float, float] | None]], unit: str,
                  cols: tuple[str, ...] | None, issues: list[Issue], what: str) -> Points:
    """Points from (number, properties, (lat, lon, h) of the geometry or None) records."""
    names = list(dict.fromkeys(k.lower() for _, props, _ in records for k in props))
    lower = [{k.lower(): v for k, v in props.items()} for _, props, _ in records]
    other = {k: _text([p.get(k) for p in lower]) for k in names}
    where = np.array([n for n, _, _ in records], dtype=np.int64)
    n = len(records)
    if cols:
        missing = [c for c in cols if c not in other]
        if missing:
            raise TableError(f"{what} file {src!r} has no propert{'y' if len(missing) == 1 else 'ies'} "
                             f"{', '.join(repr(m) for m in missing)}; it has {names}")
        values = [numbers(other[c]) for c in cols]
        bad = [c for c, v in zip(cols, values, strict=True) if v is None]
        if bad:
            raise TableError(f"{what} file {src!r}: property {bad[0]!r} is not numeric in every record")
        lat, lon = values[0], values[1]
        h = values[2] if len(cols) > 2 else np.full(n, np.nan)
    else:
        geo = np.array([g if g is not None else (math.nan,) * 3 for _, _, g in records], dtype=np.float64)
        geo = geo.reshape(n, 3)
        lat, lon, h = geo[:, 0], geo[:, 1], geo[:, 2]
        prop_h = numbers(other["h_m"]) if "h_m" in other else None
        if prop_h is not None:  # eoloc's own ellipsoidal height column
            h = np.where(np.isfinite(prop_h), prop_h, h)
    with np.errstate(invalid="ignore"):
        wild = (np.abs(lat) > 90) | (lon < -180) | (lon > 360)
    for i in np.flatnonzero(wild):
        issues.append(Issue(src, int(where[i]), f"latitude {lat[i]:g}° / longitude {lon[i]:g}° out of range; "
                                                f"{unit} skipped"))
    lat = np.where(wild, np.nan, lat)
    return _finish(src, lat, lon, h, other, where, unit, issues)


def _read_bytes(path: Path, what: str) -> bytes:
    if path.stat().st_size > MAX_BYTES:
        raise TableError(f"{what} file {str(path)!r} is larger than {MAX_BYTES >> 20} MiB: not a points file")
    return path.read_bytes()


# -- GeoJSON --------------------------------------------------------------------------------------


def _geojson_records(path: Path, what: str):
    src = str(path)
    try:
        doc = json.loads(_read_bytes(path, what).decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise TableError(f"{what} file {src!r} is not UTF-8 text (byte {exc.start}): save it as UTF-8") from None
    except json.JSONDecodeError as exc:
        raise TableError(f"{what} file {src!r} is not valid JSON: {exc.msg} at line {exc.lineno} column "
                         f"{exc.colno}") from None
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        feats = doc.get("features")
    elif isinstance(doc, dict) and doc.get("type") == "Feature":
        feats = [doc]
    elif isinstance(doc, list):
        feats = doc
    else:
        raise TableError(f"{what} file {src!r} is not a GeoJSON FeatureCollection or Feature")
    if not isinstance(feats, list):
        raise TableError(f"{what} file {src!r}: 'features' is not a list")
    records, issues, shapes = [], [], []
    for k, f in enumerate(feats, start=1):
        if not isinstance(f, dict):
            issues.append(Issue(src, k, "not a GeoJSON feature; feature skipped"))
            continue
        props = f.get("properties") if isinstance(f.get("properties"), dict) else {}
        props = {key: v for key, v in props.items() if not isinstance(v, (dict, list))}
        if "id" in f and "id" not in props:
            props["id"] = f["id"]
        g = f.get("geometry")
        geo = None
        if isinstance(g, dict):
            c = g.get("coordinates")
            if g.get("type") != "Point":
                shapes.append(k)
                continue
            if (isinstance(c, list) and len(c) in (2, 3) and all(isinstance(x, (int, float)) and
                                                                  not isinstance(x, bool) for x in c)):
                geo = (float(c[1]), float(c[0]), float(c[2]) if len(c) > 2 else math.nan)
            else:
                issues.append(Issue(src, k, f"Point coordinates {c!r} are not [lon, lat] or [lon, lat, h]; "
                                            "feature skipped"))
                continue
        records.append((k, props, geo))
    if shapes:
        issues.append(_not_points(src, shapes, "feature"))
    return records, "feature", issues


# -- KML ------------------------------------------------------------------------------------------


def _xml(data: bytes, src: str, what: str, kind: str) -> ET.Element:
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise TableError(f"{what} file {src!r} is not valid {kind} XML: {exc}") from None


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _kml_records(path: Path, what: str):
    from ..terrain.geoid import default_geoid

    src = str(path)
    data = _read_bytes(path, what)
    if data[:2] == b"PK":  # KMZ: the first .kml inside
        with zipfile.ZipFile(path) as zf:
            inner = next((n for n in zf.namelist() if n.lower().endswith(".kml")), None)
            if inner is None:
                raise TableError(f"{what} file {src!r} is a zip without a .kml document")
            if zf.getinfo(inner).file_size > MAX_BYTES:
                raise TableError(f"{what} file {src!r}: {inner} is larger than {MAX_BYTES >> 20} MiB")
            data = zf.read(inner)
    root = _xml(data, src, what, "KML")
    records, issues, shapes = [], [], []
    geoid = None
    for k, pm in enumerate((e for e in root.iter() if _local(e.tag) == "Placemark"), start=1):
        props: dict = {}
        point = None
        mode = "clampToGround"
        for e in pm.iter():
            tag = _local(e.tag)
            if tag == "name" and "name" not in props:
                props["name"] = (e.text or "").strip()
            elif tag == "Data":
                val = next((c.text for c in e if _local(c.tag) == "value"), None)
                props[e.get("name", "")] = (val or "").strip()
            elif tag == "SimpleData":
                props[e.get("name", "")] = (e.text or "").strip()
            elif tag == "Point":
                point = e
        if point is None:
            shapes.append(k)
            continue
        coords = ""
        for e in point:
            if _local(e.tag) == "coordinates":
                coords = (e.text or "").strip()
            elif _local(e.tag) in ("altitudeMode",):
                mode = (e.text or "").strip()
        try:
            parts = [float(x) for x in coords.split()[0].split(",")]
            if len(parts) not in (2, 3):
                raise ValueError
        except (ValueError, IndexError):
            issues.append(Issue(src, k, f"coordinates {coords[:60]!r} are not lon,lat[,alt]; placemark skipped"))
            continue
        h = math.nan
        if mode == "absolute" and len(parts) == 3:  # metres above mean sea level (EGM96)
            geoid = geoid or default_geoid()
            h = parts[2] + float(geoid.undulation(parts[1], parts[0]))
        records.append((k, props, (parts[1], parts[0], h)))
    if shapes:
        issues.append(_not_points(src, shapes, "placemark"))
    return records, "placemark", issues


def _not_points(src: str, numbers: list[int], unit: str) -> Issue:
    n = len(numbers)
    return Issue(src, numbers[0], f"{n} {unit}{'s are' if n > 1 else ' is'} not a point (a line or polygon: an "
                                  f"aircraft path, a footprint) and {'were' if n > 1 else 'was'} left out, the first "
                                  f"being {unit} {numbers[0]}")


# -- CoT ------------------------------------------------------------------------------------------


def _cot_documents(path: Path, what: str) -> list[tuple[str, bytes]]:
    src = str(path)
    data = _read_bytes(path, what)
    if data[:2] != b"PK":
        return [(src, data)]
    docs = []
    try:
        with zipfile.ZipFile(path) as zf:
            total = 0
            for info in zf.infolist():
                if info.filename.lower().endswith((".cot", ".xml")) and not info.filename.startswith("MANIFEST"):
                    total += info.file_size
                    if total > MAX_BYTES:
                        raise TableError(f"{what} file {src!r}: its events hold more than {MAX_BYTES >> 20} MiB")
                    docs.append((f"{src}!{info.filename}", zf.read(info)))
    except zipfile.BadZipFile:
        raise TableError(f"{what} file {src!r} is not a valid zip (TAK data package)") from None
    if not docs:
        raise TableError(f"{what} file {src!r} is a zip without CoT events (.cot entries)")
    return docs


def _events(data: bytes, src: str, what: str) -> list[ET.Element]:
    body = re.sub(r"<\?xml[^>]*\?>", "", data.decode("utf-8", errors="replace"))  # declarations of each event
    root = _xml(f"<eoloc-root>{body}</eoloc-root>".encode(), src, what, "CoT")
    return [e for e in root.iter() if _local(e.tag) == "event"]


def _cot_records(path: Path, what: str):
    records, issues = [], []
    k = 0
    for src, data in _cot_documents(path, what):
        for ev in _events(data, src, what):
            k += 1
            pt = next((e for e in ev if _local(e.tag) == "point"), None)
            props: dict = {"uid": ev.get("uid", ""), "type": ev.get("type", ""), "time": ev.get("time", "")}
            contact = next((e for e in ev.iter() if _local(e.tag) == "contact"), None)
            if contact is not None and contact.get("callsign"):
                props["callsign"] = contact.get("callsign")
            try:
                lat, lon = float(pt.get("lat")), float(pt.get("lon"))
                hae = float(pt.get("hae", "nan"))
            except (AttributeError, TypeError, ValueError):
                issues.append(Issue(str(path), k, "event without a readable <point lat lon>; event skipped"))
                continue
            for attr, names in (("ce", ("sigma_e_m", "sigma_n_m")), ("le", ("sigma_u_m",))):
                try:
                    v = float(pt.get(attr, "nan"))
                except ValueError:
                    v = math.nan
                for name in names:
                    props[name] = v if math.isfinite(v) and v < UNKNOWN_COT else math.nan
            props["rho_en"] = 0.0
            records.append((k, props, (lat, lon, hae if hae < UNKNOWN_COT else math.nan)))
    return records, "event", issues
