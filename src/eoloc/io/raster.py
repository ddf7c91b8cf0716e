"""Raster writers (rasterio): a DEM's posts and an orthorectified frame as GeoTIFFs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..rectify import Ortho
    from ..terrain.dem import DEM

DEM_NODATA = -32768.0


def write_dem(dem: DEM, path: str | Path) -> Path:
    """A DEM's posts as a float32 GeoTIFF in EPSG:4326, ellipsoidal heights (read it back with
    ``open_dem(path, vertical="ellipsoid")``); voids become the nodata value -32768."""
    import rasterio
    from rasterio.transform import from_origin

    g = dem.grid
    if g.dlon <= 0 or g.dlat >= 0:
        raise ValueError("write_dem needs a north-up grid (dlat < 0, dlon > 0)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    z = np.where(np.isnan(g.z), DEM_NODATA, g.z).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype="float32",
                       crs="EPSG:4326", nodata=DEM_NODATA, compress="deflate",
                       transform=from_origin(g.lon0 - 0.5 * g.dlon, g.lat0 - 0.5 * g.dlat, g.dlon, -g.dlat)) as ds:
        ds.write(z, 1)
        ds.update_tags(1, VERTICAL="WGS-84 ellipsoidal heights, metres", SOURCE=dem.source)
    return path


def write_ortho(ortho: Ortho, path: str | Path, *, tags: dict | None = None) -> Path:
    """An orthorectified frame as a GeoTIFF (deflate, tiled when large) with its CRS, transform
    and nodata; ``tags`` as dataset tags."""
    import rasterio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    b, h, w = ortho.data.shape
    profile = {"driver": "GTiff", "width": w, "height": h, "count": b, "dtype": ortho.data.dtype.name,
               "crs": rasterio.crs.CRS.from_wkt(ortho.crs.to_wkt()), "transform": ortho.transform,
               "nodata": ortho.nodata, "compress": "deflate"}
    if w >= 256 and h >= 256:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    with rasterio.open(path, "w", **profile) as ds:
        ds.write(ortho.data)
        if tags:
            ds.update_tags(**{k: str(v) for k, v in tags.items()})
    return path
