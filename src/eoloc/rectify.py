"""Image georeferencing (M5, [P]): ground grids of a frame, and an orthorectified GeoTIFF.

Collinearity both ways: image -> ground by the frame's rays (the stop rules of M3/M4), ground ->
image by the sensor's projection (:meth:`SensorModel.ground_to_image`). Orthorectification is the
inverse map: every cell of the output grid (UTM, Gauss-Krüger or any CRS pyproj knows) goes to
its ground point (projected x, y -> lat, lon by pyproj; height from the DEM or the constant
surface), into the image, and takes the image's value there (nearest, bilinear or cubic, scipy).
Any band count and dtype (visible RGB, 16-bit IR). Cells the camera does not see are nodata; on a
DEM, cells hidden behind terrain (the ray through their pixel meets the ground elsewhere first)
are nodata too, instead of a copy of the terrain in front ("double mapping").

[P] then reads a target's coordinates off the rectified image's bounds:
``lat = N - v (N - S) / Height``, ``lon = W + u (E - W) / Width``. That is exact only for an
output grid that is linear in lat/lon (EPSG:4326); in a projected grid the meridians converge and
the map scale varies, and :func:`shortcut_error` measures what that costs against the rigorous
ray.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyproj
from numpy.typing import ArrayLike

from . import geodesy
from .errors import InputError
from .footprint import footprints
from .result import Fixes, Status
from .rules import locate_dem, surface_rule
from .sensor.model import Pose, SensorModel
from .terrain.dem import DEM

RESAMPLING = {"nearest": 0, "bilinear": 1, "cubic": 3}
_WGS84 = pyproj.CRS.from_epsg(4326)


def _surface_height(surface: float | DEM, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    if isinstance(surface, DEM):
        return surface.height(lat, lon)
    return np.full(np.shape(lat), float(surface))


# -- ground grids ------------------------------------------------------------------------------


@dataclass(frozen=True)
class GroundGrid:
    """Ground coordinates of a grid of image points: u_px, v_px (R, C) and their fixes (R, C)."""

    u_px: np.ndarray
    v_px: np.ndarray
    fixes: Fixes


def ground_grid(sensor: SensorModel, pose: Pose, surface: float | DEM, *, step_px: float = 32.0) -> GroundGrid:
    """The ground point of every ``step_px``-th pixel (both directions, the last row and column
    always included) of one frame, on a constant ellipsoidal height or a DEM."""
    cam = sensor.camera
    if not step_px > 0:
        raise ValueError(f"step_px must be > 0, got {step_px!r}")
    us = np.unique(np.r_[np.arange(0.0, cam.width - 1, step_px), cam.width - 1.0])
    vs = np.unique(np.r_[np.arange(0.0, cam.height - 1, step_px), cam.height - 1.0])
    u, v = np.meshgrid(us, vs)
    return GroundGrid(u, v, surface_rule(surface).locate(sensor, pose, (u, v)))


# -- output grids ------------------------------------------------------------------------------


def output_crs(name: str, lat_deg: float, lon_deg: float) -> pyproj.CRS:
    """The output CRS for a frame centred at (lat, lon): ``utm`` (the WGS-84 UTM zone, EPSG:326xx /
    327xx), ``gk6`` / ``gk3`` (Gauss-Krüger 6° / 3° zone on WGS-84, false easting with the zone
    number in front as in the Chinese and Russian grids: zone * 10^6 + 500 000 m), or anything
    pyproj accepts (``EPSG:4547``, a PROJ string, ``EPSG:4326`` for a lat/lon grid)."""
    key = name.lower()
    if key == "utm":
        zone = math.floor((lon_deg + 180.0) / 6.0) % 60 + 1
        return pyproj.CRS.from_epsg((32600 if lat_deg >= 0 else 32700) + zone)
    if key in ("gk", "gk6", "gk3"):
        width = 3.0 if key == "gk3" else 6.0
        lon = ((lon_deg + 180.0) % 360.0) - 180.0
        zone = round(lon / 3.0) if width == 3.0 else math.floor(lon / 6.0) + 1
        cm = 3.0 * zone if width == 3.0 else 6.0 * zone - 3.0
        return pyproj.CRS.from_proj4(f"+proj=tmerc +lat_0=0 +lon_0={cm:g} +k=1 +x_0={zone * 1_000_000 + 500_000} "
                                     "+y_0=0 +ellps=WGS84 +units=m +no_defs +type=crs")
    try:
        return pyproj.CRS.from_user_input(name)
    except pyproj.exceptions.CRSError as exc:
        raise InputError(f"output CRS {name!r}: use utm, gk6, gk3 or an EPSG code / PROJ string ({exc})") from None


@dataclass(frozen=True)
class Ortho:
    """An orthorectified frame: ``data`` (bands, rows, cols) in the input's dtype, ``valid`` (rows,
    cols), the affine ``transform`` (rasterio Affine, pixel corners) and ``crs`` (pyproj)."""

    data: np.ndarray
    valid: np.ndarray
    transform: object
    crs: pyproj.CRS
    nodata: float
    res: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.valid.shape

    def cell_xy(self, row: ArrayLike, col: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """CRS coordinates of (fractional) pixel positions (row, col); centres at integer + 0.5."""
        t = self.transform
        col, row = np.asarray(col, float), np.asarray(row, float)
        return t.c + col * t.a + row * t.b, t.f + col * t.d + row * t.e

    def pixel_of(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) (fractional, pixel corners at integers) of CRS coordinates (x, y)."""
        t = ~self.transform
        x, y = np.asarray(x, float), np.asarray(y, float)
        return t.f + x * t.d + y * t.e, t.c + x * t.a + y * t.b

    def geographic_bounds(self) -> tuple[float, float, float, float]:
        """(west, south, east, north) degrees of the raster's outline (densified, pyproj)."""
        t = self.transform
        rows, cols = self.shape
        x0, x1 = t.c, t.c + cols * t.a
        y1, y0 = t.f, t.f + rows * t.e
        tr = pyproj.Transformer.from_crs(self.crs, _WGS84, always_xy=True)
        return tr.transform_bounds(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1), densify_pts=101)

def native_gsd_m(sensor: SensorModel, pose: Pose, surface: float | DEM) -> float:
    """Ground sample distance (m) at the principal point: the mean ground distance to the
    neighbouring pixel across and down."""
    cx, cy = sensor.camera.centre_px
    f = surface_rule(surface).locate(sensor, pose, (np.array([cx, cx + 1.0, cx]), np.array([cy, cy, cy + 1.0])))
    if not f.ok.all():
        raise InputError("the principal point does not see the ground: give the output resolution (gsd_m)")
    d = geodesy.horizontal_distance_m(f.lat_deg[0], f.lon_deg[0], f.lat_deg[1:], f.lon_deg[1:])
    return float(np.mean(d))


def orthorectify(image: ArrayLike, sensor: SensorModel, pose: Pose, surface: float | DEM, *, crs: str = "utm",
                 gsd_m: float | None = None, resampling: str = "bilinear", nodata: float = 0,
                 occlusion: bool = True, max_cells: int = 40_000_000, edge_samples: int = 16) -> Ortho:
    """Orthorectify one frame ``image`` ((H, W) or (bands, H, W), or (H, W, bands) with 3-4 bands
    last, as images load) seen from ``pose`` onto ``surface`` (constant ellipsoidal height, or a
    DEM) in ``crs`` (see :func:`output_crs`), at ``gsd_m`` metres per cell (default: the native
    ground sample distance at the image centre; for a geographic CRS the cell is that many metres
    at the frame centre's latitude). Cells outside the footprint, off the DEM, or (``occlusion``,
    DEM only) hidden by terrain get ``nodata``."""
    from rasterio.transform import from_origin
    from scipy.ndimage import map_coordinates

    if resampling not in RESAMPLING:
        raise InputError(f"resampling {resampling!r}: choose from {sorted(RESAMPLING)}")
    img = _bands_first(np.asarray(image), sensor)
    prints = footprints(sensor, pose, surface, edge_samples=edge_samples)
    if len(prints) != 1:
        raise ValueError(f"orthorectify takes the pose of one frame, got {len(prints)}")
    fp = prints[0]
    if fp.status != Status.OK:
        raise InputError(f"the frame sees no ground ({fp.status.name}): nothing to rectify")
    clat, clon = (fp.centre[0], fp.centre[1]) if np.isfinite(fp.centre[0]) else (float(np.mean(fp.lat_deg)),
                                                                                 float(np.mean(fp.lon_deg)))
    out_crs = output_crs(crs, clat, clon)
    gsd = float(gsd_m) if gsd_m is not None else native_gsd_m(sensor, pose, surface)
    if not gsd > 0:
        raise InputError(f"gsd_m must be > 0, got {gsd_m!r}")
    to_crs = pyproj.Transformer.from_crs(_WGS84, out_crs, always_xy=True)
    if out_crs.is_geographic:
        M, N = _radii(clat)
        res = (gsd / (N * math.cos(math.radians(clat))) * 180.0 / math.pi, gsd / M * 180.0 / math.pi)
    else:
        res = (gsd, gsd)
    x, y = to_crs.transform(fp.lon_deg, fp.lat_deg)
    x0 = math.floor(np.min(x) / res[0]) * res[0]
    y1 = math.ceil(np.max(y) / res[1]) * res[1]
    cols = math.ceil((np.max(x) - x0) / res[0])
    rows = math.ceil((y1 - np.min(y)) / res[1])
    if rows * cols > max_cells:
        raise InputError(f"the output would be {rows} x {cols} cells at {gsd:g} m (the footprint reaches "
                         f"{'the horizon' if fp.clipped.any() else 'far'}): give a coarser gsd_m (--gsd) or "
                         "raise max_cells")
    transform = from_origin(x0, y1, res[0], res[1])
    cc, rr = np.meshgrid(np.arange(cols) + 0.5, np.arange(rows) + 0.5)
    gx, gy = x0 + cc * res[0], y1 - rr * res[1]
    lon, lat = pyproj.Transformer.from_crs(out_crs, _WGS84, always_xy=True).transform(gx, gy)
    h = _surface_height(surface, lat, lon)
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
    u, v = sensor.ground_to_image(pose, p)
    cam = sensor.camera
    with np.errstate(invalid="ignore"):
        valid = (np.isfinite(u) & np.isfinite(v) & (u >= -0.5) & (u <= cam.width - 0.5) & (v >= -0.5)
                 & (v <= cam.height - 0.5))
    if occlusion and isinstance(surface, DEM) and valid.any():
        f = locate_dem(sensor, pose, surface, (u[valid], v[valid]))
        cam_p = np.stack(np.broadcast_arrays(*geodesy.geodetic_to_ecef(pose.lat_deg, pose.lon_deg, pose.h_m)), -1)
        rng_cell = np.linalg.norm(p[valid] - cam_p, axis=-1)
        # the ray through the cell's own pixel stops before reaching the cell: something is in front
        seen = np.where(f.ok, f.range_m >= rng_cell - max(2.0 * gsd, 1.0), False)
        valid[valid] = seen
    data = np.empty((img.shape[0], rows, cols), dtype=img.dtype)
    order = RESAMPLING[resampling]
    coords = np.stack([np.where(valid, v, -10.0), np.where(valid, u, -10.0)])
    for b in range(img.shape[0]):
        band = map_coordinates(img[b].astype(np.float64), coords, order=order, mode="nearest",
                               prefilter=order > 1)
        if np.issubdtype(img.dtype, np.integer):
            info = np.iinfo(img.dtype)
            band = np.clip(np.rint(band), info.min, info.max)
        data[b] = np.where(valid, band, nodata).astype(img.dtype)
    return Ortho(data, valid, transform, out_crs, nodata, res)


def _radii(lat_deg: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii of curvature (m) of WGS-84 at ``lat_deg``."""
    a, e2 = geodesy.WGS84.a, geodesy.WGS84.e2
    s2 = math.sin(math.radians(lat_deg)) ** 2
    w = math.sqrt(1.0 - e2 * s2)
    return a * (1.0 - e2) / w**3, a / w


def _bands_first(img: np.ndarray, sensor: SensorModel) -> np.ndarray:
    W, H = sensor.camera.width, sensor.camera.height
    if img.ndim == 2:
        img = img[None]
    elif img.ndim == 3 and img.shape[1:] != (H, W) and img.shape[:2] == (H, W):
        img = np.moveaxis(img, -1, 0)
    if img.ndim != 3 or img.shape[1:] != (H, W):
        raise InputError(f"image of shape {img.shape} does not match the camera's {W} x {H} pixels "
                         "((H, W), (bands, H, W) or (H, W, bands))")
    return img


# -- [P]'s bounds shortcut ---------------------------------------------------------------------


@dataclass(frozen=True)
class ShortcutError:
    """Horizontal error (m) of [P]'s bounds formula against the rigorous ray, per image point:
    ``exact``: the target's exact (sub-cell) position in the rectified image; ``cell``: the
    centre of the cell it falls in (what reading the image gives)."""

    exact_m: np.ndarray
    cell_m: np.ndarray

    def summary(self) -> dict[str, float]:
        out = {}
        for name, e in (("exact", self.exact_m), ("cell", self.cell_m)):
            e = e[np.isfinite(e)]
            out.update({f"{name}_median_m": float(np.median(e)) if e.size else math.nan,
                        f"{name}_max_m": float(np.max(e)) if e.size else math.nan})
        return out


def bounds_shortcut(ortho: Ortho, row: ArrayLike, col: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """[P]: lat/lon of (fractional) rectified-image positions by linear interpolation between the
    image's geographic bounds. row/col count pixels from the top-left corner (centres at +0.5)."""
    west, south, east, north = ortho.geographic_bounds()
    height, width = ortho.shape
    return (north - np.asarray(row, float) * (north - south) / height,
            west + np.asarray(col, float) * (east - west) / width)


def shortcut_error(ortho: Ortho, sensor: SensorModel, pose: Pose, surface: float | DEM, pixels: ArrayLike) -> \
        ShortcutError:
    """Locate ``pixels`` ((N, 2) u, v of the original frame) rigorously, find them in the
    rectified image, read them back with :func:`bounds_shortcut`, and return the distances."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    f = surface_rule(surface).locate(sensor, pose, (px[:, 0], px[:, 1]))
    x, y = pyproj.Transformer.from_crs(_WGS84, ortho.crs, always_xy=True).transform(f.lon_deg, f.lat_deg)
    row, col = ortho.pixel_of(x, y)
    lat1, lon1 = bounds_shortcut(ortho, row, col)
    lat2, lon2 = bounds_shortcut(ortho, np.floor(row) + 0.5, np.floor(col) + 0.5)
    return ShortcutError(geodesy.horizontal_distance_m(f.lat_deg, f.lon_deg, lat1, lon1),
                         geodesy.horizontal_distance_m(f.lat_deg, f.lon_deg, lat2, lon2))


__all__ = ["GroundGrid", "Ortho", "ShortcutError", "bounds_shortcut", "ground_grid", "native_gsd_m",
           "orthorectify", "output_crs", "shortcut_error"]
