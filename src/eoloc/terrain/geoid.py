"""Geoid undulation N (h_ellipsoid = H_orthometric + N) from a grid file, EGM96 15' bundled.

The EGM96 15-minute grid (NGA/NASA, public domain; PROJ .gtx format, from CNES demcompare, see
src/eoloc/data/geoid/SOURCE.md) ships with eoloc, so nothing is fetched at run time. Any other
grid rasterio can read (EGM2008 .gtx/.tif) can be given by path.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from .grid import LatLonGrid


class Geoid:
    """Geoid undulation grid (m) with bilinear lookup; longitudes wrap at ±180°."""

    def __init__(self, path: str | Path, name: str | None = None) -> None:
        import rasterio

        from ..errors import DEMError

        self.path = str(path)
        self.name = name or Path(path).stem
        try:
            with rasterio.open(self.path) as ds:
                z = ds.read(1, masked=True).astype(np.float64).filled(np.nan)
                t = ds.transform
        except rasterio.errors.RasterioIOError as exc:
            raise DEMError(f"geoid grid {self.path!r} cannot be read: {exc}") from None
        lat0 = t.f + 0.5 * t.e
        lon0 = t.c + 0.5 * t.a
        if abs(z.shape[1] * t.a - 360.0) < 1e-6:  # a global grid: repeat the first column at +360
            z = np.concatenate([z, z[:, :1]], axis=1)
        self.grid = LatLonGrid(z, lat0, lon0, t.e, t.a)

    def undulation(self, lat: ArrayLike, lon: ArrayLike) -> np.ndarray:
        """N in metres at (lat, lon) degrees (NaN outside the grid)."""
        lon = (np.asarray(lon, dtype=np.float64) + 180.0) % 360.0 - 180.0
        n, _ = self.grid.sample(lat, lon)
        return n

    def __repr__(self) -> str:
        return f"Geoid({self.name!r}, {self.path!r})"


@cache
def default_geoid() -> Geoid:
    """The bundled EGM96 15' grid."""
    path = resources.files("eoloc") / "data" / "geoid" / "egm96_15.gtx"
    return Geoid(Path(str(path)), "EGM96")
