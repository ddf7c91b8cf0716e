"""Terrain models: DEM grids (GeoTIFF, DTED, SRTM .hgt, ESRI ASCII via rasterio), the geoid, and
constant/synthetic terrains. Heights are always ellipsoidal (WGS-84) once loaded."""

from .dem import DEM, DEMError, open_dem
from .geoid import Geoid, default_geoid

__all__ = ["DEM", "DEMError", "Geoid", "default_geoid", "open_dem"]
