"""KML out (simplekml): any GeoJSON features (fixes, footprints, tracks, aircraft path) as folders.

GeoJSON is the one in-memory form of every geometry eoloc writes, so KML and the HTML map are
converters of it, not second writers of each kind of result. Heights are written with
altitudeMode absolute, which in KML means metres above MSL (EGM96): ellipsoidal heights are
converted through the bundled geoid so Google Earth puts points on its terrain, not 15-100 m
off it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

_STYLE = {  # layer colour (KML aabbggrr) and width
    "fixes": ("ff0000ff", 2), "footprints": ("ff00ffff", 2), "tracks": ("ffff00ff", 3), "aircraft": ("ffffff00", 2),
    "encoder footprints": ("ff00a5ff", 1),
}


def _msl(coords: np.ndarray, geoid) -> np.ndarray:
    """(N, 2|3) lon, lat[, h ellipsoidal] -> (N, 3) lon, lat, MSL height (0 where h is absent)."""
    c = np.asarray(coords, dtype=np.float64).reshape(-1, np.shape(coords)[-1])
    h = c[:, 2] - geoid.undulation(c[:, 1], c[:, 0]) if c.shape[1] > 2 else np.zeros(len(c))
    return np.column_stack([c[:, 0], c[:, 1], np.nan_to_num(h)])


def write_kml(path: str | Path, layers: Mapping[str, list[dict]], *, geoid=None, name: str = "eoloc") -> Path:
    """One KML document, one folder per layer ({name: GeoJSON features}). Points, LineStrings and
    Polygons are supported; properties become ExtendedData; a feature with a ``time_utc`` property
    (ISO 8601, known when the inputs give their clock's origin) gets a TimeStamp so Google Earth's
    time slider plays the flight."""
    import simplekml

    from ..terrain.geoid import default_geoid

    geoid = geoid or default_geoid()
    kml = simplekml.Kml(name=name)
    for layer, features in layers.items():
        folder = kml.newfolder(name=layer)
        colour, width = _STYLE.get(layer, ("ffffffff", 2))
        for k, feat in enumerate(features):
            geom = feat.get("geometry")
            if not geom:
                continue
            props = feat.get("properties") or {}
            label = str(props.get("target_id", props.get("track_id", props.get("frame", k))))
            kind = geom["type"]
            if kind == "Point":
                obj = folder.newpoint(name=label, coords=[tuple(_msl([geom["coordinates"]], geoid)[0])])
                obj.style.iconstyle.color = colour
                obj.style.iconstyle.scale = 0.8
            elif kind == "LineString":
                obj = folder.newlinestring(name=label, coords=[tuple(p) for p in _msl(geom["coordinates"], geoid)])
                obj.style.linestyle.color, obj.style.linestyle.width = colour, width
            elif kind == "Polygon":
                obj = folder.newpolygon(name=label, outerboundaryis=[tuple(p) for p in
                                                                     _msl(geom["coordinates"][0], geoid)])
                obj.style.linestyle.color, obj.style.linestyle.width = colour, width
                obj.style.polystyle.color = "40" + colour[2:]
            else:
                raise ValueError(f"write_kml: {kind} geometries are not supported (layer {layer!r}, feature {k})")
            obj.altitudemode = simplekml.AltitudeMode.absolute
            for key, val in props.items():
                if val is not None and not isinstance(val, (list, dict)):
                    obj.extendeddata.newdata(name=key, value=str(val))
            t = props.get("time_utc")
            if isinstance(t, str) and t:
                obj.timestamp.when = t
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    kml.save(str(path))
    return path
