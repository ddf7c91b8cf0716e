"""XYZ map tiles (the "slippy map" scheme of OpenStreetMap, Leaflet, QGIS's XYZ layer): a raster
warped into Web Mercator 256-pixel PNG tiles with transparency, ``{z}/{x}/{y}.png``.

mercantile does the tile arithmetic, rasterio (GDAL's warper) the reprojection: average when a
tile pixel covers several raster cells, bilinear when it covers less than one. Images that are
not 8-bit are stretched to 8 bits between their 2nd and 98th percentiles (display only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

TILE_PX = 256
WEB_MERCATOR_M = 2 * math.pi * 6378137.0  # the Web Mercator world's width at the equator (m)


@dataclass(frozen=True)
class TileSet:
    """Tiles written: folder, zoom range, count, and (west, south, east, north) degrees."""

    folder: Path
    min_zoom: int
    max_zoom: int
    count: int
    bounds: tuple[float, float, float, float]

    @property
    def url(self) -> str:
        """The Leaflet / QGIS URL template, relative to the folder's parent."""
        return f"{self.folder.name}/{{z}}/{{x}}/{{y}}.png"


def rasterio_crs(crs):
    """A pyproj CRS (or anything rasterio takes) as rasterio's CRS."""
    import rasterio

    return rasterio.crs.CRS.from_wkt(crs.to_wkt()) if hasattr(crs, "to_wkt") else crs


def rgba(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(4, rows, cols) uint8 for display: one band grey, three or more as RGB (8-bit, stretched
    when not 8-bit: :func:`to_8bit`), ``valid`` as the alpha."""
    img = to_8bit(data, valid)
    rgb = img[:3] if img.shape[0] >= 3 else np.repeat(img[:1], 3, axis=0)
    return np.concatenate([rgb, np.where(valid, 255, 0).astype(np.uint8)[None]])


def native_zoom(cell_m: float, lat_deg: float) -> int:
    """The zoom whose tile pixel is about one ``cell_m`` at ``lat_deg`` (never coarser than it)."""
    return int(min(max(math.ceil(math.log2(WEB_MERCATOR_M * math.cos(math.radians(lat_deg)) / (TILE_PX * cell_m))),
                       0), 24))


def to_8bit(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Bands (b, r, c) as uint8 for display: 8-bit data as they are, others stretched linearly
    between their 2nd and 98th percentiles over the valid cells."""
    if data.dtype == np.uint8:
        return data
    vals = data[:, valid].astype(np.float64)
    if vals.size == 0:
        return np.zeros(data.shape, np.uint8)
    lo, hi = np.percentile(vals, [2, 98])
    scale = 255.0 / (hi - lo) if hi > lo else 1.0
    return np.clip((data.astype(np.float64) - lo) * scale, 0, 255).astype(np.uint8)


def write_xyz_tiles(folder: str | Path, data: np.ndarray, valid: np.ndarray, transform, crs, *,
                    cell_m: float, zoom_levels: int = 5) -> TileSet:
    """``data`` (bands, rows, cols) on ``transform``/``crs`` as XYZ tiles under ``folder``, from the
    native zoom (tile pixel ≈ ``cell_m``) down ``zoom_levels`` levels (not below the zoom where it
    all fits in one tile). One band is drawn grey, three or more as RGB; ``valid`` is the alpha."""
    import cv2
    import mercantile
    from rasterio.transform import from_bounds
    from rasterio.warp import Resampling, reproject, transform_bounds

    folder = Path(folder)
    crs = rasterio_crs(crs)
    rows, cols = valid.shape
    x0, y1 = transform.c, transform.f
    x1, y0 = x0 + cols * transform.a, y1 + rows * transform.e
    west, south, east, north = transform_bounds(crs, "EPSG:4326", x0, y0, x1, y1, densify_pts=21)
    zmax = native_zoom(cell_m, 0.5 * (south + north))
    whole = mercantile.bounding_tile(west, south, east, north)
    zmin = min(max(zmax - zoom_levels + 1, whole.z, 0), zmax)
    src = rgba(data, valid)
    count = 0
    for z in range(zmin, zmax + 1):
        tile_m = WEB_MERCATOR_M / (2**z * TILE_PX)
        method = Resampling.average if tile_m > cell_m else Resampling.bilinear
        for t in mercantile.tiles(west, south, east, north, zooms=z):
            b = mercantile.xy_bounds(t)
            dst = np.zeros((4, TILE_PX, TILE_PX), np.uint8)
            reproject(src, dst, src_transform=transform, src_crs=crs,
                      dst_transform=from_bounds(b.left, b.bottom, b.right, b.top, TILE_PX, TILE_PX),
                      dst_crs="EPSG:3857", resampling=method, src_alpha=4, dst_alpha=4)
            if not dst[3].any():
                continue
            out = folder / str(z) / str(t.x) / f"{t.y}.png"
            out.parent.mkdir(parents=True, exist_ok=True)
            ok, png = cv2.imencode(".png", np.moveaxis(dst[[2, 1, 0, 3]], 0, -1))
            if not ok:
                raise OSError(f"{out}: PNG encoding failed")
            out.write_bytes(png.tobytes())
            count += 1
    return TileSet(folder, zmin, zmax, count, (west, south, east, north))
