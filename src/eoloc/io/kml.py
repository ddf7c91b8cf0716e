"""KML out: any GeoJSON features (fixes, footprints, tracks, aircraft path) as folders.

GeoJSON is the one in-memory form of every geometry eoloc writes, so KML and the HTML map are
converters of it, not second writers of each kind of result. Heights are written with
altitudeMode absolute, which in KML means metres above MSL (EGM96): ellipsoidal heights are
converted through the bundled geoid so Google Earth puts points on its terrain, not 15-100 m
off it.

The document is built with ElementTree (elements in OGC KML 2.2's order) and serialised by it, so
every name and value is escaped by the XML library: a target id of ``a & <b>`` stays that text,
``]]>`` breaks nothing; the characters XML 1.0 cannot hold at all (most C0 controls) become U+FFFD
(:func:`eoloc.io.xmltext.xml_text`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .xmltext import xml_text

KML_NS = "http://www.opengis.net/kml/2.2"
_STYLE = {  # layer colour (KML aabbggrr) and width
    "fixes": ("ff0000ff", 2), "footprints": ("ff00ffff", 2), "tracks": ("ffff00ff", 3), "aircraft": ("ffffff00", 2),
    "encoder footprints": ("ff00a5ff", 1),
}
def _msl(coords: np.ndarray, geoid) -> np.ndarray:
    """(N, 2|3) lon, lat[, h ellipsoidal] -> (N, 3) lon, lat, MSL height (0 where h is absent)."""
    c = np.asarray(coords, dtype=np.float64).reshape(-1, np.shape(coords)[-1])
    h = c[:, 2] - geoid.undulation(c[:, 1], c[:, 0]) if c.shape[1] > 2 else np.zeros(len(c))
    return np.column_stack([c[:, 0], c[:, 1], np.nan_to_num(h)])


def _coordinates(points: np.ndarray) -> str:
    return " ".join(f"{lon:.9f},{lat:.9f},{h:.3f}" for lon, lat, h in points)


def _style_id(layer: str) -> str:
    return "eoloc-" + "".join(ch if ch.isalnum() else "-" for ch in layer)


#: What each height field in ExtendedData is (the placemarks' own altitudes are MSL).
HEIGHT_NOTE = "metres above the WGS-84 ellipsoid (the placemark's altitude is above MSL, EGM96)"


def _fields(features: list[dict]) -> dict[str, str]:
    """The data fields of a layer's features (scalar properties, in order of first appearance)
    with their KML type: double when every value is a number, else string."""
    kinds: dict[str, str] = {}
    for f in features:
        for key, val in (f.get("properties") or {}).items():
            if val is None or isinstance(val, (list, dict)):
                continue
            number = isinstance(val, (int, float, np.integer, np.floating)) and not isinstance(val, bool)
            kinds[key] = "double" if number and kinds.get(key, "double") == "double" else "string"
    return kinds


def write_kml(path: str | Path, layers: Mapping[str, list[dict]], *, geoid=None, name: str = "eoloc") -> Path:
    """One KML document, one folder per layer ({name: GeoJSON features}), one shared style per
    layer (placemarks refer to it: no style repeated per placemark). Points, LineStrings and
    Polygons are supported; properties become ExtendedData as SchemaData of a Schema declared once
    per layer, each height field (``h_m``, ``*_h_m``) named there with its datum; a feature with
    a ``time_utc`` property (ISO 8601, known when the inputs give their clock's origin) gets a
    TimeStamp so Google Earth's time slider plays the flight."""
    from ..terrain.geoid import default_geoid

    geoid = geoid or default_geoid()

    def sub(parent: ET.Element, tag: str, text=None) -> ET.Element:
        e = ET.SubElement(parent, f"{{{KML_NS}}}{tag}")
        if text is not None:
            e.text = xml_text(text)
        return e

    root = ET.Element(f"{{{KML_NS}}}kml")
    doc = sub(root, "Document")
    sub(doc, "name", name)
    sub(doc, "description", "Written by eoloc. Placemark altitudes: metres above mean sea level (EGM96), "
                            "altitudeMode absolute. Height fields in the data (h_m, ...): " + HEIGHT_NOTE + ".")
    for layer in layers:  # one style per layer, shared by its placemarks
        colour, width = _STYLE.get(layer, ("ffffffff", 2))
        style = sub(doc, "Style")
        style.set("id", _style_id(layer))
        icon = sub(style, "IconStyle")
        sub(icon, "color", colour)
        sub(icon, "scale", "0.8")
        line = sub(style, "LineStyle")
        sub(line, "color", colour)
        sub(line, "width", str(width))
        sub(sub(style, "PolyStyle"), "color", "40" + colour[2:])
    fields = {layer: _fields(features) for layer, features in layers.items()}
    for layer, names in fields.items():  # each layer's data fields declared once, with their meaning
        if not names:
            continue
        schema = sub(doc, "Schema")
        schema.set("name", xml_text(layer))
        schema.set("id", _style_id(layer) + "-fields")
        for key, kind in names.items():
            field = sub(schema, "SimpleField")
            field.set("type", kind)
            field.set("name", xml_text(key))
            sub(field, "displayName", f"{key} ({HEIGHT_NOTE})" if key == "h_m" or key.endswith("_h_m") else key)
    for layer, features in layers.items():
        folder = sub(doc, "Folder")
        sub(folder, "name", layer)
        for k, feat in enumerate(features):
            geom = feat.get("geometry")
            if not geom:
                continue
            kind = geom["type"]
            if kind not in ("Point", "LineString", "Polygon", "MultiPolygon"):
                raise ValueError(f"write_kml: {kind} geometries are not supported (layer {layer!r}, feature {k})")
            props = feat.get("properties") or {}
            mark = sub(folder, "Placemark")
            sub(mark, "name", props.get("target_id", props.get("track_id", props.get("frame", k))))
            t = props.get("time_utc")
            if isinstance(t, str) and t:
                sub(sub(mark, "TimeStamp"), "when", t)
            sub(mark, "styleUrl", "#" + _style_id(layer))
            data = [(key, val) for key, val in props.items() if key in fields[layer] and val is not None]
            if data:
                values = sub(sub(mark, "ExtendedData"), "SchemaData")
                values.set("schemaUrl", "#" + _style_id(layer) + "-fields")
                for key, val in data:
                    item = sub(values, "SimpleData", val)
                    item.set("name", xml_text(key))
            if kind == "MultiPolygon":  # (a footprint cut at the antimeridian)
                multi = sub(mark, "MultiGeometry")
                for part in geom["coordinates"]:
                    poly = sub(multi, "Polygon")
                    sub(poly, "altitudeMode", "absolute")
                    ring = sub(sub(poly, "outerBoundaryIs"), "LinearRing")
                    sub(ring, "coordinates", _coordinates(_msl(part[0], geoid)))
                continue
            shape = sub(mark, kind)
            sub(shape, "altitudeMode", "absolute")
            if kind == "Point":
                sub(shape, "coordinates", _coordinates(_msl([geom["coordinates"]], geoid)))
            elif kind == "LineString":
                sub(shape, "coordinates", _coordinates(_msl(geom["coordinates"], geoid)))
            else:
                ring = sub(sub(shape, "outerBoundaryIs"), "LinearRing")
                sub(ring, "coordinates", _coordinates(_msl(geom["coordinates"][0], geoid)))
    ET.register_namespace("", KML_NS)
    ET.indent(root, space=" ")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path
