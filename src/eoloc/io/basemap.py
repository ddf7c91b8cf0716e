"""Offline basemaps for the maps: a user's raster tiles, from an MBTiles file or a folder of
``{z}/{x}/{y}.png`` (or .jpg, .webp) XYZ tiles, taken over the map's area and embedded in the
page, so that it still opens with no network.

MBTiles (the SQLite format of MapTiler, QGIS's "Generate XYZ tiles", TileMill, gdal_translate
-of MBTiles) stores rows in the TMS scheme (row 0 at the south); a folder is read as XYZ (row 0
at the north), as QGIS and gdal2tiles --xyz write it. Tiles are taken zoom by zoom from the
coarsest, over the map's bounds with a margin, while the page stays under ``budget_bytes``:
Leaflet scales the finest zoom embedded for closer views. Vector tiles (pbf) are refused: the
page draws images only.
"""

from __future__ import annotations

import base64
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

BUDGET_BYTES = 24_000_000  # the tiles embedded in one page at most
IMAGE_TYPES = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}
_MAGIC = {b"\x89PNG": "image/png", b"\xff\xd8\xff": "image/jpeg", b"RIFF": "image/webp"}


@dataclass
class Basemap:
    """Tiles as data URLs keyed "z/x/y" (XYZ), the zooms embedded, the attribution (plain text)
    and what was left out (a note for the user)."""

    tiles: dict[str, str]
    min_zoom: int
    max_zoom: int
    name: str
    attribution: str = ""
    notes: list[str] = field(default_factory=list)


def _mime(data: bytes, path: str) -> str:
    for magic, mime in _MAGIC.items():
        if data.startswith(magic):
            return mime
    raise InputError(f"basemap {path}: a tile is not a PNG, JPEG or WebP image (vector tiles, pbf, cannot be drawn "
                     "offline: give raster tiles)")


class _Source:
    """Tiles by (z, x, y) XYZ from a folder or an MBTiles file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.attribution = ""
        self.name = path.stem
        if path.is_dir():
            self.db = None
            zooms = sorted(int(p.name) for p in path.iterdir() if p.is_dir() and p.name.isdigit())
            if not zooms:
                raise InputError(f"basemap folder {str(path)!r} holds no {{z}}/{{x}}/{{y}}.png tiles (no zoom folders "
                                 "0, 1, 2, ...): give a tile folder as QGIS or gdal2tiles --xyz write it, or an "
                                 ".mbtiles file")
            self.zooms = zooms
        elif path.is_file():
            with path.open("rb") as fh:
                head = fh.read(16)
            if head != b"SQLite format 3\x00":
                raise InputError(f"basemap {str(path)!r} is neither a tile folder nor an MBTiles file (SQLite)")
            self.db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
            try:
                meta = dict(self.db.execute("SELECT name, value FROM metadata").fetchall())
                zooms = [z for (z,) in self.db.execute("SELECT DISTINCT zoom_level FROM tiles ORDER BY zoom_level")]
            except sqlite3.DatabaseError as exc:
                raise InputError(f"basemap {str(path)!r} is an SQLite file but not MBTiles ({exc}): it needs the "
                                 "tables metadata and tiles") from None
            if str(meta.get("format", "png")).lower() in ("pbf", "mvt"):
                raise InputError(f"basemap {str(path)!r} holds vector tiles (format {meta['format']}): the map "
                                 "draws raster tiles only (png, jpg, webp)")
            self.attribution = str(meta.get("attribution", ""))
            self.name = str(meta.get("name", path.stem))
            self.zooms = [int(z) for z in zooms]
            if not self.zooms:
                raise InputError(f"basemap {str(path)!r} has no tile")
        else:
            raise InputError(f"basemap {str(path)!r} does not exist (a tile folder or an .mbtiles file)")

    def get(self, z: int, x: int, y: int) -> bytes | None:
        if self.db is None:
            for ext in IMAGE_TYPES:
                p = self.path / str(z) / str(x) / f"{y}.{ext}"
                if p.is_file():
                    return p.read_bytes()
            return None
        row = self.db.execute("SELECT tile_data FROM tiles WHERE zoom_level=? AND tile_column=? AND tile_row=?",
                              (z, x, (1 << z) - 1 - y)).fetchone()
        return None if row is None else bytes(row[0])

    def close(self) -> None:
        if self.db is not None:
            self.db.close()


def read_basemap(path: str | Path, bounds: tuple[float, float, float, float], *,
                 budget_bytes: int = BUDGET_BYTES, margin: float = 0.5) -> Basemap:
    """The tiles of ``path`` over ``bounds`` (west, south, east, north, degrees) widened by
    ``margin`` of their size on each side, zoom by zoom from the coarsest while they fit in
    ``budget_bytes``."""
    import mercantile

    src = _Source(Path(path))
    try:
        w, s, e, n = bounds
        dx, dy = max(e - w, 1e-4) * margin, max(n - s, 1e-4) * margin
        box = (max(w - dx, -180.0), max(s - dy, -85.05), min(e + dx, 180.0), min(n + dy, 85.05))
        tiles: dict[str, str] = {}
        used, zooms, notes = 0, [], []
        for z in src.zooms:
            level = {}
            for t in mercantile.tiles(*box, zooms=z):
                data = src.get(t.z, t.x, t.y)
                if data is not None:
                    level[f"{t.z}/{t.x}/{t.y}"] = data
            size = sum(len(d) * 4 // 3 for d in level.values())
            if zooms and used + size > budget_bytes:
                notes.append(f"basemap {path}: zoom {z} and finer left out (the page would pass "
                             f"{budget_bytes / 1e6:.0f} MB); closer views enlarge zoom {zooms[-1]}")
                break
            for key, data in level.items():
                tiles[key] = f"data:{_mime(data, str(path))};base64," + base64.b64encode(data).decode("ascii")
            used += size
            if level:
                zooms.append(z)
        if not tiles:
            raise InputError(f"basemap {path} has no tile over the map's area (lon {w:.4f}..{e:.4f}, lat "
                             f"{s:.4f}..{n:.4f}; zooms {src.zooms[0]}-{src.zooms[-1]})")
        return Basemap(tiles, min(zooms), max(zooms), src.name, src.attribution, notes)
    finally:
        src.close()
