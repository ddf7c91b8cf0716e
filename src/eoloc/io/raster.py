"""Rasters through rasterio: a frame's bands read; a DEM's posts and an orthorectified frame written as
GeoTIFFs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:
    from ..ground.rectify import Ortho
    from ..terrain.dem import DEM

DEM_NODATA = -32768.0


def read_image(path) -> np.ndarray:
    """The frame's bands (GDAL reads PNG, JPEG, TIFF, ...), as (bands, rows, cols)."""
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as ds:
                return ds.read()
    except RasterioIOError as exc:
        raise InputError(f"image {str(path)!r} cannot be read (GDAL reads PNG, JPEG, TIFF, ...): {exc}") from None


def read_reference_band(path) -> tuple[np.ndarray, object, object]:
    """A georeferenced image (an orthophoto, a hillshade) as one grey band (the mean of its first
    three bands; nodata cells NaN), with its affine transform and CRS; an InputError naming the
    file when it cannot be read or carries no georeferencing."""
    import rasterio
    from rasterio.errors import RasterioIOError

    try:
        with rasterio.open(path) as ds:
            if ds.crs is None or ds.transform.is_identity:
                raise InputError(f"reference {str(path)!r} has no georeferencing (a CRS and a geotransform): give a "
                                 "GeoTIFF, or a world file and .prj beside the image")
            bands = ds.read(list(range(1, min(ds.count, 3) + 1)), masked=True).astype(np.float32)
            grey = bands.mean(axis=0)
            return np.ma.filled(grey, np.nan), ds.transform, ds.crs
    except RasterioIOError as exc:
        raise InputError(f"reference {str(path)!r} cannot be read (GDAL reads GeoTIFF, JPEG2000, ...): {exc}") from None


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


def write_cog(path: str | Path, data: np.ndarray, transform, crs, *, nodata: float | None = None,
              mask: np.ndarray | None = None, band_names: list[str] | None = None, tags: dict | None = None,
              threads: int | str = "ALL_CPUS") -> Path:
    """A Cloud-Optimised GeoTIFF (GDAL's COG driver: 512-pixel tiles, averaged overviews, deflate) of
    ``data`` (bands, rows, cols) on ``transform`` (rasterio Affine) and ``crs`` (pyproj or
    rasterio); ``mask`` (rows, cols) True where a cell holds data, written as the internal mask
    GIS software honours; ``band_names`` as band descriptions; ``tags`` as dataset tags;
    ``threads``: GDAL's compression threads."""
    import rasterio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    b, h, w = data.shape
    crs = rasterio.crs.CRS.from_wkt(crs.to_wkt()) if hasattr(crs, "to_wkt") else crs
    profile = {"driver": "COG", "width": w, "height": h, "count": b, "dtype": data.dtype.name, "crs": crs,
               "transform": transform, "nodata": nodata, "compress": "deflate",
               # averaged overviews, compressed on every core; no predictor: it cost 35 % more time
               # for a few % smaller files (measured on a rectified frame)
               "overview_resampling": "average", "num_threads": str(threads)}
    with rasterio.open(path, "w", **profile) as ds:
        ds.write(data)
        if mask is not None:
            ds.write_mask(np.where(mask, 255, 0).astype(np.uint8))
        for i, name in enumerate(band_names or []):
            ds.set_band_description(i + 1, name)
        if tags:
            ds.update_tags(**{k: str(v) for k, v in tags.items()})
    return path


def write_ortho(ortho: Ortho, path: str | Path, *, tags: dict | None = None, threads: int | str = "ALL_CPUS") -> Path:
    """An orthorectified frame as a Cloud-Optimised GeoTIFF with its CRS, transform, nodata and
    the cells the camera saw as its internal mask; ``tags`` as dataset tags."""
    return write_cog(path, ortho.data, ortho.transform, ortho.crs, nodata=ortho.nodata, mask=ortho.valid, tags=tags,
                     threads=threads)
