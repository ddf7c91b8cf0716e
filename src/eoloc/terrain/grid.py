"""A regular latitude/longitude grid of values with bilinear lookup (DEM heights, geoid undulations)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..kernels import core as kernels


@dataclass(frozen=True, eq=False)
class LatLonGrid:
    """Posts ``z[i, j]`` at latitude lat0 + i dlat, longitude lon0 + j dlon (degrees); NaN = void.

    Bilinear between posts; the coverage is the rectangle spanned by the outermost posts.
    """

    z: np.ndarray
    lat0: float
    lon0: float
    dlat: float
    dlon: float

    def __post_init__(self) -> None:
        z = np.ascontiguousarray(self.z, dtype=np.float64)
        if z.ndim != 2 or min(z.shape) < 2:
            raise ValueError(f"a grid needs at least 2 x 2 posts, got shape {np.shape(self.z)}")
        if not (self.dlat != 0 and self.dlon > 0):
            raise ValueError(f"grid spacing must be dlat != 0 and dlon > 0, got {self.dlat}, {self.dlon}")
        object.__setattr__(self, "z", z)

    @property
    def shape(self) -> tuple[int, int]:
        return self.z.shape

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(west, south, east, north) of the posts, degrees."""
        lat1 = self.lat0 + (self.z.shape[0] - 1) * self.dlat
        lon1 = self.lon0 + (self.z.shape[1] - 1) * self.dlon
        return (self.lon0, min(self.lat0, lat1), lon1, max(self.lat0, lat1))

    def sample(self, lat: ArrayLike, lon: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear values at (lat, lon) degrees and an ``inside`` mask (NaN outside and in voids)."""
        lat = np.asarray(lat, dtype=np.float64)
        lon = np.asarray(lon, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            h, inside = kernels.grid_height(self.z, self.lat0, self.lon0, self.dlat, self.dlon, lat, lon)
        return np.asarray(h), np.asarray(inside)

    def post_coordinates(self) -> tuple[np.ndarray, np.ndarray]:
        """Latitudes (rows) and longitudes (columns) of the posts."""
        return (self.lat0 + self.dlat * np.arange(self.z.shape[0]), self.lon0 + self.dlon * np.arange(self.z.shape[1]))
