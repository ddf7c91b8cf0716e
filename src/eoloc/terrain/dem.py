"""Digital elevation models: files through rasterio, held as ellipsoidal heights on a lat/lon grid.

Formats: anything GDAL reads — GeoTIFF, DTED (.dt0/.dt1/.dt2), SRTM .hgt (plain, or zipped: a
``.zip`` path is opened through GDAL's /vsizip/), ESRI ASCII grids. Several tiles become one
surface (rasterio.merge). A DEM in a projected CRS is resampled to geographic coordinates at
load. No-data cells stay voids (NaN): a ray that meets one gets DEM_VOID, never an invented
height.

Vertical datum: DEM heights are usually orthometric (SRTM, DTED: EGM96; Copernicus: EGM2008).
``vertical="egm96"`` (default) adds the bundled EGM96 undulation; ``vertical="ellipsoid"`` takes
the heights as they are; ``geoid=PATH`` uses another grid (e.g. EGM2008) for the conversion.
"""

from __future__ import annotations

import warnings
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DEMError
from .geoid import Geoid, default_geoid
from .grid import LatLonGrid


@dataclass(frozen=True, eq=False)
class DEM:
    """Ellipsoidal heights (m) on a lat/lon grid, bilinear between posts; NaN = void."""

    grid: LatLonGrid
    source: str = ""
    vertical: str = "ellipsoid"
    files: tuple[str, ...] = ()  # the files it was read from (open_dem), for reports to name and hash

    # -- constructors -------------------------------------------------------------------------

    @classmethod
    def from_array(cls, z: ArrayLike, *, lat0: float, lon0: float, dlat: float, dlon: float,
                   source: str = "array") -> DEM:
        """Heights ``z[i, j]`` (ellipsoidal m) at (lat0 + i dlat, lon0 + j dlon)."""
        return cls(LatLonGrid(np.asarray(z, dtype=np.float64), lat0, lon0, dlat, dlon), source)

    @classmethod
    def from_function(cls, f: Callable[[np.ndarray, np.ndarray], np.ndarray], bounds: Sequence[float],
                      spacing_deg: float, *, source: str = "function") -> DEM:
        """Sample an analytic terrain ``f(lat, lon) -> h`` (ellipsoidal m) on a grid over
        ``bounds`` = (west, south, east, north); the bilinear surface of the samples is the DEM."""
        west, south, east, north = bounds
        lats = np.arange(north, south - 0.5 * spacing_deg, -spacing_deg)
        lons = np.arange(west, east + 0.5 * spacing_deg, spacing_deg)
        z = f(lats[:, None], lons[None, :])
        return cls.from_array(np.broadcast_to(z, (lats.size, lons.size)), lat0=north, lon0=west,
                              dlat=-spacing_deg, dlon=spacing_deg, source=source)

    @classmethod
    def constant(cls, height_m: float, bounds: Sequence[float] = (-180.0, -90.0, 180.0, 90.0)) -> DEM:
        """A flat terrain at ellipsoidal height ``height_m`` over ``bounds``."""
        west, south, east, north = bounds
        return cls.from_array(np.full((2, 2), float(height_m)), lat0=north, lon0=west, dlat=south - north,
                              dlon=east - west, source=f"constant {height_m:g} m")

    # -- queries ------------------------------------------------------------------------------

    def height(self, lat: ArrayLike, lon: ArrayLike) -> np.ndarray:
        """Bilinear ellipsoidal height (m); NaN outside the coverage and in voids."""
        return self.grid.sample(lat, lon)[0]

    def sample(self, lat: ArrayLike, lon: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(height, inside): NaN height with inside=True is a void; inside=False is out of coverage."""
        return self.grid.sample(lat, lon)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(west, south, east, north) degrees."""
        return self.grid.bounds

    @cached_property
    def height_range(self) -> tuple[float, float]:
        """(lowest, highest) ellipsoidal height of the posts (voids ignored); computed once."""
        return float(np.nanmin(self.grid.z)), float(np.nanmax(self.grid.z))

    @property
    def spacing_m(self) -> float:
        """Post spacing in metres (the smaller of the two axes, at the grid's mid-latitude)."""
        w, s, e, n = self.bounds
        lat = np.radians(0.5 * (s + n))
        return float(min(abs(self.grid.dlat) * 111_132.0, self.grid.dlon * 111_320.0 * max(np.cos(lat), 1e-6)))

    @cached_property
    def block_max(self) -> np.ndarray:
        """Highest post of each 8 x 8-cell block (+inf where a block holds a void), built once:
        lets the M4 march skip stretches where the ray is above all terrain."""
        from ..kernels.march import block_max

        return block_max(self.grid.z)

    @property
    def n_voids(self) -> int:
        return int(np.isnan(self.grid.z).sum())

    def __repr__(self) -> str:
        w, s, e, n = self.bounds
        lo, hi = self.height_range
        return (f"DEM({self.source!r}, {self.grid.shape[0]}x{self.grid.shape[1]} posts, "
                f"lon {w:.4f}..{e:.4f}, lat {s:.4f}..{n:.4f}, h {lo:.1f}..{hi:.1f} m {self.vertical})")


def _gdal_path(path: Path) -> str:
    if path.suffix.lower() == ".zip":
        with zipfile.ZipFile(path) as zf:
            members = [m for m in zf.namelist() if not m.endswith("/")]
        if len(members) != 1:
            raise DEMError(f"DEM archive {str(path)!r} holds {len(members)} files; give the one to use as "
                           f"/vsizip/{path}/NAME")
        return f"/vsizip/{path}/{members[0]}"
    return str(path)


def open_dem(paths: str | Path | Sequence[str | Path], *, vertical: str = "egm96", geoid: str | Path | None = None,
             assume_crs: str | None = None) -> DEM:
    """Open one DEM file or several tiles as one ellipsoidal-height surface.

    vertical: "egm96" (heights above the EGM96 geoid: SRTM, DTED; the default), "egm2008" (needs
    ``geoid``, a grid file), or "ellipsoid" (already ellipsoidal). geoid: a geoid grid path
    overriding the bundled EGM96. assume_crs: the CRS of files that carry none (ESRI ASCII
    grids), e.g. "EPSG:4326"; without it such a file is an error.
    """
    import rasterio
    from rasterio.crs import CRS
    from rasterio.merge import merge

    if isinstance(paths, (str, Path)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    if not paths:
        raise DEMError("no DEM file given")
    vertical = vertical.lower()
    if vertical not in ("egm96", "egm2008", "ellipsoid"):
        raise DEMError(f"vertical datum {vertical!r} unknown; use 'egm96', 'egm2008' (with a geoid grid) or "
                       "'ellipsoid'")
    if vertical == "egm2008" and geoid is None:
        raise DEMError("EGM2008 heights need an EGM2008 geoid grid: pass geoid=PATH (--geoid), or accept the bundled "
                       "EGM96 with vertical='egm96' (the two differ by up to a few metres)")
    datasets = []
    try:
        for p in paths:
            if not p.exists():
                raise DEMError(f"DEM file {str(p)!r} does not exist (check the path)")
            try:
                with warnings.catch_warnings():  # GDAL's "not georeferenced" warning: said below, in words
                    warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
                    ds = rasterio.open(_gdal_path(p))
            except rasterio.errors.RasterioIOError as exc:
                raise DEMError(f"DEM file {str(p)!r} cannot be read by GDAL: {exc}") from None
            datasets.append(ds)
            if ds.crs is None:
                if ds.transform.is_identity:  # no georeferencing at all: a picture, not a terrain model
                    raise DEMError(f"DEM file {str(p)!r} ({ds.driver}) has no georeferencing at all: it is not a "
                                   "terrain model (DEMs come as GeoTIFF, DTED, SRTM .hgt or ESRI ASCII grids)")
                if assume_crs is None:
                    raise DEMError(f"DEM file {str(p)!r} has no coordinate reference system (an ESRI ASCII grid "
                                   "without .prj?); if it is lon/lat, say so with --dem-crs EPSG:4326 "
                                   "(a config's [accuracy]: dem_crs = \"EPSG:4326\"; Python: "
                                   "open_dem(..., assume_crs='EPSG:4326'))")
        crs = datasets[0].crs or CRS.from_user_input(assume_crs)
        nodata = datasets[0].nodata
        if len(datasets) == 1:
            ds = datasets[0]
            arr = ds.read(1, masked=True)
            transform = ds.transform
        else:
            crss = {str(d.crs or assume_crs) for d in datasets}
            if len(crss) > 1:
                raise DEMError(f"DEM tiles have different CRSs {sorted(crss)}; reproject them to one first")
            merged, transform = merge(datasets, nodata=nodata if nodata is not None else -32768)
            arr = np.ma.masked_equal(merged[0], nodata if nodata is not None else -32768)
        z = np.ma.filled(arr.astype(np.float64), np.nan)
        if crs is not None and not crs.is_geographic:
            z, transform = _to_geographic(z, transform, crs)
    finally:
        for ds in datasets:
            ds.close()
    lat0 = transform.f + 0.5 * transform.e
    lon0 = transform.c + 0.5 * transform.a
    grid = LatLonGrid(z, lat0, lon0, transform.e, transform.a)
    label = ", ".join(str(p) for p in paths)
    if vertical != "ellipsoid":
        g = Geoid(geoid) if geoid is not None else default_geoid()
        lats, lons = grid.post_coordinates()
        n = g.undulation(lats[:, None], lons[None, :])
        grid = LatLonGrid(z + n, lat0, lon0, transform.e, transform.a)
        vertical = f"ellipsoidal ({vertical.upper()} heights + {g.name} geoid)"
    return DEM(grid, label, vertical, tuple(str(p) for p in paths))


def _to_geographic(z: np.ndarray, transform, crs):
    """Resample a projected DEM onto a lat/lon grid of about the same spacing (bilinear)."""
    from rasterio.warp import Resampling, calculate_default_transform, reproject

    h, w = z.shape
    dst_crs = "EPSG:4326"
    left, top = transform @ (0, 0)
    right, bottom = transform @ (w, h)
    dst_t, dw, dh = calculate_default_transform(crs, dst_crs, w, h, left=left, bottom=bottom, right=right, top=top)
    out = np.full((dh, dw), np.nan)
    reproject(z, out, src_transform=transform, src_crs=crs, dst_transform=dst_t, dst_crs=dst_crs,
              src_nodata=np.nan, dst_nodata=np.nan, resampling=Resampling.bilinear)
    return out, dst_t
