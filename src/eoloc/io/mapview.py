"""A self-contained HTML map (folium / Leaflet): aircraft track, frame footprints, targets with
their CEP circles, tracks, a time slider; underneath, offline basemaps: the bundled Natural
Earth countries, a user's raster tiles (MBTiles or a tile folder, embedded), the DEM's hillshade.

"Self-contained" means it opens from a USB stick in a ground station with no network: Leaflet
1.9.4 (BSD-2-Clause, ``eoloc/data/leaflet``) is inlined instead of folium's CDN links, its few
images are data URIs, targets are vector circles (no marker images), the basemap's tiles are
data URIs, and there are no web tiles unless ``tiles=`` asks for them. Every layer is a GeoJSON
feature list, the same that goes to .geojson and KML. SVG paths carry CSS classes
(``eoloc-target``, ``eoloc-cep``, ``eoloc-footprint``, ``eoloc-aircraft``, ``eoloc-track``, and
``eoloc-tK`` for the K-th time step of the slider) so a browser test can count them.

Data reaches the page only through serialisers: every tooltip (target ids, frames, track ids come
from the user's files) is a JSON string (Jinja's ``tojson``, which also escapes ``<``, ``>``, ``&``
and ``'`` for a script) set as a DOM node's ``textContent``, never parsed as HTML or pasted into
JavaScript source; the title goes through :func:`html.escape`.
"""

from __future__ import annotations

import base64
import html
import io
from importlib import resources
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import InputError

_COLOURS = {"aircraft": "#1f77b4", "footprints": "#ff9900", "encoder footprints": "#888888", "targets": "#d62728",
            "tracks": "#9467bd", "truth": "#2ca02c"}


def _text_tooltip():
    """folium's Tooltip, with its text as text: folium pastes a tooltip's text into a JavaScript
    template literal that Leaflet then parses as HTML (``${…}`` runs, ``<img onerror>`` runs on
    hover, a backtick breaks the page). This one hands Leaflet a node whose ``textContent`` is the
    text, written as a JSON string."""
    import folium
    from folium.template import Template

    class TextTooltip(folium.Tooltip):
        _template = Template("""
            {% macro script(this, kwargs) %}
            {{ this._parent.get_name() }}.bindTooltip(
                (function (text) { var node = document.createElement("div"); node.textContent = text; return node; })(
                    {{ this.text|tojson }}),
                {{ this.options|tojavascript }});
            {% endmacro %}
            """)

    return TextTooltip


def _inline_leaflet():
    import folium

    class OfflineMap(folium.Map):  # no CDN links: Leaflet goes inline below
        default_js: ClassVar[list] = []
        default_css: ClassVar[list] = []

    base = resources.files("eoloc") / "data" / "leaflet"
    js = (base / "leaflet.js").read_text(encoding="utf-8")
    css = (base / "leaflet.css").read_text(encoding="utf-8")
    return OfflineMap, js, css


def offline_page(template: str, scripts: dict[str, str], fields: dict[str, str]) -> str:
    """A page that needs no network, from eoloc/data: the HTML ``template`` (a path under
    eoloc/data) with Leaflet's CSS and JS inlined at /*LEAFLET_CSS*/ and /*LEAFLET_JS*/, each other
    /*MARK*/ of ``scripts`` replaced by the data file it names, and each {{NAME}} of ``fields`` by
    its value, HTML-escaped. The live map and the video player are made this way."""
    base = resources.files("eoloc") / "data"
    page = (base / template).read_text(encoding="utf-8")
    parts = {"/*LEAFLET_CSS*/": "leaflet/leaflet.css", "/*LEAFLET_JS*/": "leaflet/leaflet.js", **scripts}
    for mark, name in parts.items():
        page = page.replace(mark, (base / name).read_text(encoding="utf-8"))
    for name, value in fields.items():
        page = page.replace("{{" + name + "}}", html.escape(value))
    return page


def _hillshade_png(dem) -> tuple[str, list[list[float]]]:
    """The DEM as a hillshaded PNG data URL and its [[south, west], [north, east]] bounds."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.colors import LightSource

    g = dem.grid
    z = np.asarray(g.z, dtype=np.float64)
    z = np.where(np.isfinite(z), z, np.nanmin(z))
    step = max(1, int(np.ceil(max(z.shape) / 1200)))  # keep the page small
    z = z[::step, ::step]
    shade = LightSource(azdeg=315, altdeg=45).hillshade(z, vert_exag=2.0, dx=1.0, dy=1.0)
    rgba = (np.dstack([shade] * 3 + [np.full_like(shade, 0.8)]) * 255).astype(np.uint8)
    if g.dlat > 0:  # the PNG's first row must be the north edge
        rgba = rgba[::-1]
    buf = io.BytesIO()
    import matplotlib.image as mpimg

    mpimg.imsave(buf, rgba, format="png")
    lat = [g.lat0, g.lat0 + g.dlat * (g.z.shape[0] - 1)]
    lon = [g.lon0, g.lon0 + g.dlon * (g.z.shape[1] - 1)]
    bounds = [[min(lat), min(lon)], [max(lat), max(lon)]]
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode(), bounds


def _tile_layer(basemap):
    """A Leaflet tile layer whose tiles are the basemap's data URLs (no network, no files)."""
    import json

    from branca.element import MacroElement
    from folium.template import Template

    class EmbeddedTiles(MacroElement):
        _template = Template("""
            {% macro script(this, kwargs) %}
            (function (tiles) {
                var Embedded = L.TileLayer.extend({getTileUrl: function (c) {
                    return tiles[c.z + "/" + c.x + "/" + c.y] || "data:image/gif;base64,R0lGODlhAQABAAAAACw=";
                }});
                new Embedded("", {minNativeZoom: {{ this.min_zoom }}, maxNativeZoom: {{ this.max_zoom }},
                                  maxZoom: 22, className: "eoloc-basemap",
                                  attribution: {{ this.attribution }}}).addTo({{ this._parent.get_name() }});
            })({{ this.tiles }});
            {% endmacro %}
            """)

        def __init__(self) -> None:
            super().__init__()
            self.tiles = json.dumps(basemap.tiles)
            self.min_zoom, self.max_zoom = int(basemap.min_zoom), int(basemap.max_zoom)
            # Leaflet writes the attribution as HTML: the file's text escaped first, then a JSON string
            self.attribution = json.dumps(html.escape(basemap.attribution or basemap.name)).replace("</", "<\\/")

    return EmbeddedTiles()


def _world_layer():
    """The bundled Natural Earth countries (public domain, eoloc/data/world): land and borders under
    everything, so that a map with no tiles is not a grey canvas."""
    import json

    import folium

    data = json.loads((resources.files("eoloc") / "data" / "world" / "ne_110m_countries.geojson")
                      .read_text(encoding="utf-8"))
    return folium.GeoJson(data, name="world (Natural Earth)", control=False, interactive=False, pane="eoloc-world",
                          style_function=lambda f: {"color": "#a09c8c", "weight": 0.7, "fillColor": "#f2efe6",
                                                    "fillOpacity": 1.0, "className": "eoloc-world"})


def _time_keys(*layers: list[dict] | None) -> list:
    """The distinct times of the features (time_s, else frame), sorted: the time slider's steps."""
    keys = {k for layer in layers for f in layer or () if (k := _time_of(f)) is not None}
    return sorted(keys)


def _time_of(f: dict):
    props = f.get("properties") or {}
    for name in ("time_s", "frame"):
        v = props.get(name)
        if isinstance(v, (int, float)) and np.isfinite(v):
            return float(v)
    return None


#: Above this many footprints they are drawn as thin outlines coloured by time (no fill): even
#: forty filled polygons on top of each other are one opaque blob hiding the map.
MANY_FOOTPRINTS = 8
_SLIDER = """
<div id="eoloc-time" style="position:fixed;bottom:12px;left:50%%;transform:translateX(-50%%);z-index:1000;
     background:white;padding:6px 10px;font:13px sans-serif;border-radius:4px;box-shadow:0 1px 4px rgba(0,0,0,.3)">
  <label>time <input id="eoloc-time-range" type="range" min="0" max="%(last)d" value="%(last)d" step="1"
         style="width:260px;vertical-align:middle"></label>
  <span id="eoloc-time-label"></span>
  <label><input id="eoloc-time-only" type="checkbox"> this time only</label>
</div>
<style id="eoloc-time-style"></style>
<script>
(function (labels) {
  var range = document.getElementById("eoloc-time-range"), only = document.getElementById("eoloc-time-only");
  var style = document.getElementById("eoloc-time-style"), label = document.getElementById("eoloc-time-label");
  function show() {
    var v = +range.value, hide = [];
    for (var k = 0; k < labels.length; k++) {
      if (k > v || (only.checked && k !== v)) hide.push(".eoloc-t" + k);
    }
    style.textContent = hide.length ? hide.join(",") + "{display:none}" : "";
    label.textContent = labels[v];
  }
  range.addEventListener("input", show);
  only.addEventListener("change", show);
  show();
})(%(labels)s);
</script>
"""


def _latlon(coords) -> list[list[float]]:
    return [[float(c[1]), float(c[0])] for c in coords]


def drawable(*layers: list[dict] | None) -> bool:
    """True when some feature of the layers has a geometry (else there is no map to write)."""
    return any(f.get("geometry") for layer in layers for f in layer or ())


def write_map(path: str | Path, *, aircraft: list[dict] | None = None, footprints: list[dict] | None = None,
              targets: list[dict] | None = None, tracks: list[dict] | None = None, truth: list[dict] | None = None,
              encoder_footprints: list[dict] | None = None, dem=None, tiles: str | None = None,
              title: str = "eoloc", basemap=None, world: bool = True, notes: list[str] | None = None) -> Path:
    """Write the map. Each layer is a list of GeoJSON features: aircraft (LineString), footprints
    and encoder_footprints (Polygon), targets (Point, with optional ``cep50_m`` drawn as a circle
    in metres), tracks (LineString/Point), truth (Point). Underneath, from the bottom: the bundled
    world layer (``world``), ``basemap`` (a user's tiles, embedded: an MBTiles file or XYZ tile
    folder, read over the map's area by :func:`eoloc.io.basemap.read_basemap`, whose notes go
    into ``notes``; or a :class:`eoloc.io.basemap.Basemap`), the DEM's hillshade, and ``tiles``
    (a folium tile name, e.g. "OpenStreetMap", when the viewer is online). Footprints and targets
    with a time (time_s, else frame) get a time slider; more than :data:`MANY_FOOTPRINTS`
    footprints are thin outlines coloured by time."""
    import folium

    OfflineMap, js, css = _inline_leaflet()
    tip = _text_tooltip()
    points = [c for layer in (aircraft, footprints, targets, tracks, truth, encoder_footprints) for f in layer or ()
              if f.get("geometry") for c in _coords(f["geometry"])]
    if not points:
        raise InputError("write_map: nothing to draw (no feature has a geometry)")
    lat = np.array([p[1] for p in points])
    lon = np.array([p[0] for p in points])
    m = OfflineMap(location=[float(lat.mean()), float(lon.mean())], tiles=tiles, control_scale=True,
                   prefer_canvas=False)
    m.get_root().header.add_child(folium.Element(f"<style>{css}</style>\n<script>{js}</script>\n"
                                                 "<style>.leaflet-container{background:#cfe0ea}</style>"))
    if world:  # in a pane of its own under the tiles' (z-index 200): a basemap is drawn over the land
        folium.map.CustomPane("eoloc-world", z_index=150, pointer_events=False).add_to(m)
        _world_layer().add_to(m)
    if basemap is not None:
        from .basemap import Basemap, read_basemap

        if not isinstance(basemap, Basemap):
            basemap = read_basemap(basemap, (float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max())))
        if notes is not None:
            notes.extend(basemap.notes)
        m.add_child(_tile_layer(basemap))
    m.get_root().html.add_child(folium.Element(
        f'<div id="eoloc-title" style="position:fixed;top:8px;left:50px;z-index:1000;background:white;'
        f'padding:4px 8px;font:14px sans-serif;border-radius:4px">{html.escape(title)}</div>'))
    if dem is not None:
        url, bounds = _hillshade_png(dem)
        under = basemap is not None or tiles is not None  # then the shading lets the map under it show
        folium.raster_layers.ImageOverlay(url, bounds=bounds, name="terrain (hillshade)",
                                          opacity=0.4 if under else 0.9).add_to(m)

    def group(name: str):  # the encoder's outlines start hidden: a layer to compare with, not to read first
        return folium.FeatureGroup(name=name, show=name != "encoder footprints").add_to(m)

    if aircraft:
        g = group("aircraft")
        for f in aircraft:
            if f.get("geometry"):
                folium.PolyLine(_latlon(f["geometry"]["coordinates"]), color=_COLOURS["aircraft"], weight=3,
                                class_name="eoloc-aircraft", tooltip=tip("aircraft")).add_to(g)
    keys = _time_keys(footprints, targets)
    step = {k: i for i, k in enumerate(keys)}

    def timed(cls: str, f: dict) -> str:  # the slider hides what comes after its time by these classes
        k = _time_of(f)
        return cls if k is None or len(keys) < 2 else f"{cls} eoloc-t{step[k]}"

    for name, layer, cls in (("footprints", footprints, "eoloc-footprint"),
                             ("encoder footprints", encoder_footprints, "eoloc-encoder-footprint")):
        if layer:
            g = group(name)
            many = len(layer) > MANY_FOOTPRINTS
            for f in layer:
                geom = f.get("geometry")
                if geom and geom["type"] in ("Polygon", "MultiPolygon"):
                    props = f.get("properties") or {}
                    rings = [geom["coordinates"][0]] if geom["type"] == "Polygon" else [p[0] for p in
                                                                                       geom["coordinates"]]
                    colour = _COLOURS[name]
                    if many and name == "footprints":
                        k = _time_of(f)
                        colour = _ramp(step[k] / max(len(keys) - 1, 1)) if k is not None else colour
                    for ring in rings:  # a footprint cut at the antimeridian: each part
                        folium.Polygon(_latlon(ring), color=colour, weight=1, opacity=0.7 if many else 1.0,
                                       fill=not many, fill_opacity=0.08, class_name=timed(cls, f),
                                       tooltip=tip(f"{name}: frame {props.get('frame', '')}")).add_to(g)
    if tracks:
        g = group("tracks")
        for f in tracks:
            geom = f.get("geometry")
            if geom and geom["type"] == "LineString":
                folium.PolyLine(_latlon(geom["coordinates"]), color=_COLOURS["tracks"], weight=3,
                                class_name="eoloc-track",
                                tooltip=tip(f"track {(f.get('properties') or {}).get('track_id', '')}")).add_to(g)
    for name, layer, cls in (("targets", targets, "eoloc-target"), ("truth", truth, "eoloc-truth")):
        if not layer:
            continue
        g = group(name)
        for f in layer:
            geom = f.get("geometry")
            if not geom:
                continue
            props = f.get("properties") or {}
            lon_t, lat_t = geom["coordinates"][:2]
            cep = props.get("cep50_m")
            if isinstance(cep, (int, float)) and np.isfinite(cep) and cep > 0:
                folium.Circle([lat_t, lon_t], radius=float(cep), color=_COLOURS[name], weight=1, fill=True,
                              fill_opacity=0.1, class_name=timed("eoloc-cep", f),
                              tooltip=tip(f"CEP50 {cep:.1f} m")).add_to(g)
            label = " ".join(f"{k}={_short(v)}" for k, v in props.items() if v is not None and k in
                             ("target_id", "frame", "time_s", "h_m", "status", "cep50_m", "ce90_m", "le90_m"))
            folium.CircleMarker([lat_t, lon_t], radius=4, color=_COLOURS[name], weight=2, fill=True, fill_opacity=0.9,
                                class_name=timed(cls, f) if name == "targets" else cls,
                                tooltip=tip(label or name)).add_to(g)
    if len(keys) > 1:
        import json

        unit = "s" if any(_time_of(f) is not None and "time_s" in (f.get("properties") or {})
                          for layer in (footprints, targets) for f in layer or ()) else "frame"
        if unit == "s" and keys[0] > 1e9:  # UNIX times (KLV, drone logs): as UTC
            from .export import utc_times

            labels = [f"{t[:-1].replace('T', ' ')} UTC" for t in utc_times(keys, "unix")]
        else:
            labels = [f"{k:.2f} s" if unit == "s" else f"frame {k:g}" for k in keys]
        m.get_root().html.add_child(folium.Element(_SLIDER % {
            "last": len(keys) - 1, "labels": json.dumps(labels).replace("</", "<\\/")}))
    folium.LayerControl(collapsed=False).add_to(m)
    m.fit_bounds([[float(lat.min()), float(lon.min())], [float(lat.max()), float(lon.max())]])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    m.save(str(path))
    return path


def _ramp(x: float) -> str:
    """A colour from dark blue (early) through purple to yellow-orange (late), for x in [0, 1]:
    matplotlib's plasma without its palest end, so every step shows on a light map."""
    import matplotlib

    r, g, b, _ = matplotlib.colormaps["plasma"](0.05 + 0.8 * float(x))
    return f"#{int(r * 255):02x}{int(g * 255):02x}{int(b * 255):02x}"


def _coords(geom: dict):
    t, c = geom["type"], geom["coordinates"]
    if t == "Point":
        return [c]
    if t == "LineString":
        return c
    if t == "Polygon":
        return c[0]
    if t == "MultiPolygon":
        return [p for part in c for p in part[0]]
    return []


def _short(v) -> str:
    return f"{v:.1f}" if isinstance(v, float) else str(v)

