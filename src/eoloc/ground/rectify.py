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

import functools
import math
from dataclasses import dataclass

import numpy as np
import pyproj
from numpy.typing import ArrayLike

from .. import geodesy
from ..errors import InputError
from ..kernels.backend import backend, implements
from ..result import Fixes, Status
from ..rules import OnDEM, StopRule
from ..sensor.model import Pose, SensorModel
from .footprint import Footprint, footprints

RESAMPLING = {"nearest": 0, "bilinear": 1, "cubic": 3}
_WGS84 = pyproj.CRS.from_epsg(4326)


def level_height(ground: StopRule) -> float:
    """The one height (ellipsoidal m) of a ground without a terrain map (``AtHeight(h)``);
    InputError for a height per target (one frame's ground is one surface)."""
    h = np.asarray(ground.ground_height(0.0, 0.0), dtype=np.float64)
    if h.ndim:
        raise InputError(f"the ground of one frame is one surface: {ground.describe()} has a value per target")
    return float(h)


# -- ground grids ------------------------------------------------------------------------------


@dataclass(frozen=True)
class GroundGrid:
    """Ground coordinates of a grid of image points: u_px, v_px (R, C) and their fixes (R, C)."""

    u_px: np.ndarray
    v_px: np.ndarray
    fixes: Fixes


def ground_grid(sensor: SensorModel, pose: Pose, ground: StopRule, *, step_px: float = 32.0) -> GroundGrid:
    """The ground point of every ``step_px``-th pixel (both directions, the last row and column
    always included) of one frame, on the ``ground`` rule's surface (AtHeight or OnDEM)."""
    cam = sensor.camera
    if not step_px > 0:
        raise ValueError(f"step_px must be > 0, got {step_px!r}")
    us = np.unique(np.r_[np.arange(0.0, cam.width - 1, step_px), cam.width - 1.0])
    vs = np.unique(np.r_[np.arange(0.0, cam.height - 1, step_px), cam.height - 1.0])
    u, v = np.meshgrid(us, vs)
    return GroundGrid(u, v, ground.locate(sensor, pose, (u, v)))


# -- output grids ------------------------------------------------------------------------------


def output_crs(name: str | pyproj.CRS, lat_deg: float, lon_deg: float) -> pyproj.CRS:
    """The output CRS for a frame centred at (lat, lon): ``utm`` (the WGS-84 UTM zone, EPSG:326xx /
    327xx), ``gk6`` / ``gk3`` (Gauss-Krüger 6° / 3° zone on WGS-84, false easting with the zone
    number in front as in the Chinese and Russian grids: zone * 10^6 + 500 000 m), or anything
    pyproj accepts (``EPSG:4547``, a PROJ string, ``EPSG:4326`` for a lat/lon grid, a pyproj CRS)."""
    if isinstance(name, pyproj.CRS):
        return name
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
        tr = transformer(self.crs, _WGS84)
        return tr.transform_bounds(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1), densify_pts=101)

def native_gsd_m(sensor: SensorModel, pose: Pose, ground: StopRule) -> float:
    """Ground sample distance (m) at the principal point: the mean ground distance to the
    neighbouring pixel across and down."""
    cx, cy = sensor.camera.centre_px
    f = ground.locate(sensor, pose, (np.array([cx, cx + 1.0, cx]), np.array([cy, cy, cy + 1.0])))
    if not f.ok.all():
        raise InputError("the principal point does not see the ground: give the output resolution (gsd_m)")
    d = geodesy.horizontal_distance_m(f.lat_deg[0], f.lon_deg[0], f.lat_deg[1:], f.lon_deg[1:])
    return float(np.mean(d))


@dataclass(frozen=True)
class OutputGrid:
    """A north-up output raster: ``crs`` (pyproj), ``transform`` (rasterio Affine, pixel corners),
    ``shape`` (rows, cols) and ``res`` (x, y cell size in the CRS's units)."""

    crs: pyproj.CRS
    transform: object
    shape: tuple[int, int]
    res: tuple[float, float]

    def centres(self, rows: ArrayLike, cols: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """CRS coordinates (x, y) of the centres of cells (rows, cols)."""
        t = self.transform
        return t.c + (np.asarray(cols, float) + 0.5) * t.a, t.f + (np.asarray(rows, float) + 0.5) * t.e


def output_grid(sensor: SensorModel, pose: Pose, ground: StopRule, *, crs: str | pyproj.CRS = "utm",
                gsd_m: float | None = None, res: tuple[float, float] | None = None, max_cells: int = 40_000_000,
                edge_samples: int = 16, footprint: Footprint | None = None) -> OutputGrid:
    """The grid a frame is rectified onto: its footprint's bounding box in ``crs`` (see
    :func:`output_crs`), cell edges on multiples of the cell size (so the grids of a pass line up),
    at ``gsd_m`` metres per cell (default: the native ground sample distance at the image centre;
    for a geographic CRS that many metres at the frame centre's latitude), or at ``res`` (x, y) in
    the CRS's units (the frames of a pass after the first: the same cells exactly). ``footprint``:
    the frame's footprint when the caller has it already."""
    if footprint is None:
        prints = footprints(sensor, pose, ground, edge_samples=edge_samples)
        if len(prints) != 1:
            raise ValueError(f"orthorectify takes the pose of one frame, got {len(prints)}")
        footprint = prints[0]
    fp = footprint
    if fp.status != Status.OK:
        raise InputError(f"the frame sees no ground ({fp.status.name}): nothing to rectify")
    clat, clon = (fp.centre[0], fp.centre[1]) if np.isfinite(fp.centre[0]) else (float(np.mean(fp.lat_deg)),
                                                                                 float(np.mean(fp.lon_deg)))
    out_crs = output_crs(crs, clat, clon)
    if res is not None:
        res = (float(res[0]), float(res[1]))
        gsd = math.radians(res[1]) * _radii(clat)[0] if out_crs.is_geographic else res[0]
    else:
        gsd = float(gsd_m) if gsd_m is not None else native_gsd_m(sensor, pose, ground)
        if not gsd > 0:
            raise InputError(f"gsd_m must be > 0, got {gsd_m!r}")
        if out_crs.is_geographic:
            M, N = _radii(clat)
            res = (gsd / (N * math.cos(math.radians(clat))) * 180.0 / math.pi, gsd / M * 180.0 / math.pi)
        else:
            res = (gsd, gsd)
    x, y = transformer(_WGS84, out_crs).transform(fp.lon_deg, fp.lat_deg)
    return grid_covering(out_crs, res, (np.min(x), np.min(y), np.max(x), np.max(y)), max_cells=max_cells,
                         what=f"at {gsd:g} m (the footprint reaches {'the horizon' if fp.clipped.any() else 'far'})")


def grid_covering(crs: pyproj.CRS, res: tuple[float, float], bounds: tuple[float, float, float, float], *,
                  max_cells: int = 40_000_000, what: str = "") -> OutputGrid:
    """The north-up grid of cells ``res`` on multiples of the cell size that covers ``bounds``
    (xmin, ymin, xmax, ymax in ``crs``)."""
    from rasterio.transform import from_origin

    xmin, ymin, xmax, ymax = bounds
    x0 = math.floor(xmin / res[0]) * res[0]
    y1 = math.ceil(ymax / res[1]) * res[1]
    cols = max(math.ceil((xmax - x0) / res[0]), 1)
    rows = max(math.ceil((y1 - ymin) / res[1]), 1)
    if rows * cols > max_cells:
        raise InputError(f"the output would be {rows} x {cols} cells {what}: give a coarser gsd_m (--gsd) or "
                         "raise max_cells")
    return OutputGrid(crs, from_origin(x0, y1, res[0], res[1]), (rows, cols), res)


@functools.lru_cache(maxsize=64)
def transformer(src: pyproj.CRS, dst: pyproj.CRS) -> pyproj.Transformer:
    """pyproj's transformer from ``src`` to ``dst`` (x = longitude / easting first), made once."""
    return pyproj.Transformer.from_crs(src, dst, always_xy=True)


FOLD_TILE_PX = 16  # image tiles where the terrain folds over get the z-buffer
NODE_STEP = 32  # cells between the nodes where pyproj and the exact geodesy are evaluated (< 1e-4 px, 0.4 mm
# of range off the exact path at 3 m cells; 16: 4x less, but the per-row loops between nodes too short to vectorise)


@dataclass(frozen=True)
class FramePixels:
    """Where every cell of an output grid falls in a frame: pixel (u, v) and range (m), NaN
    without ground or behind the camera; ``valid`` where the camera sees the cell; ``map_x``,
    ``map_y``: OpenCV remap's float32 maps (the seen cells' pixels clamped to the outermost pixel
    centres, -16 elsewhere: outside the image, nodata)."""

    u_px: np.ndarray
    v_px: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray

    map_x: np.ndarray
    map_y: np.ndarray


def frame_pixels(sensor: SensorModel, pose: Pose, ground: StopRule, grid: OutputGrid, *,
                 occlusion: bool = True) -> FramePixels:
    """Project every cell of ``grid`` (its ground point on the ``ground`` rule's surface) into the frame seen from
    ``pose`` and decide which cells the camera sees: inside the image, and (``occlusion``, on a
    DEM) not hidden by nearer terrain (a z-buffer of the terrain mesh). Compiled (numba) passes,
    eoloc.kernels.ortho; with the numpy backend, the reference path (M4 rays for the hiding)."""
    return backend().frame_pixels(sensor, pose, ground, grid, occlusion=occlusion)


@implements("frame_pixels", "numba")
def _frame_pixels_compiled(sensor: SensorModel, pose: Pose, ground: StopRule, grid: OutputGrid, *,
                           occlusion: bool = True) -> FramePixels:
    """numba: the cells projected at nodes and interpolated, visibility by the terrain mesh's
    z-buffer where it folds (eoloc.kernels.ortho)."""
    from ..kernels import compiled, ortho
    from ..kernels import core as kernels

    cam = sensor.camera
    rows, cols = grid.shape
    nr, nc = ortho.node_count(rows, NODE_STEP), ortho.node_count(cols, NODE_STEP)
    node_x, _ = grid.centres(0, np.arange(nc) * NODE_STEP)
    _, node_y = grid.centres(np.arange(nr) * NODE_STEP, 0)
    gx, gy = np.meshgrid(node_x, node_y)
    lon, lat = transformer(grid.crs, _WGS84).transform(gx, gy)
    frame = sensor.camera_frame(pose)
    R = np.reshape(frame.R_ecef_cam, (3, 3))
    o = np.array([float(np.ravel(a)[0]) for a in (frame.ox, frame.oy, frame.oz)])
    p0 = np.stack(geodesy.geodetic_to_ecef(lat, lon, 0.0), -1)
    la, lo = np.radians(lat), np.radians(lon)
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)
    nodes = np.empty((nr, nc, ortho.N_NODE))
    terrain = ground.terrain
    if terrain is not None:  # the DEM's fractional row and column (linear in lat, lon: interpolated as they are)
        g = terrain.grid
        nodes[..., 0], nodes[..., 1] = (lat - g.lat0) / g.dlat, (lon - g.lon0) / g.dlon
        dem = (g.z, 0.0, True)
    else:
        nodes[..., 0], nodes[..., 1] = 0.0, 0.0
        dem = (np.zeros((2, 2)), level_height(ground), False)
    nodes[..., 2:5] = (p0 - o) @ R  # R^T (p - o), row vectors
    nodes[..., 5:8] = up @ R
    row_i0, row_a = ortho.node_index(rows, NODE_STEP)
    _, col_a = ortho.node_index(cols, NODE_STEP)
    fs = float(np.ravel(pose.focal_scale)[0])
    dist = cam.distortion
    kind, dp = (dist.kind, np.asarray(dist.packed, float)) if dist is not None else (kernels.DIST_NONE, np.zeros(1))
    r2_max = _ideal_radius2(cam, fs) * 1.02**2
    u, v, rng = (np.empty((rows, cols)) for _ in range(3))
    valid = np.empty((rows, cols), np.uint8)
    map_x, map_y = np.empty((rows, cols), np.float32), np.empty((rows, cols), np.float32)
    use_zbuf = occlusion and terrain is not None
    zbuf = np.full((cam.height, cam.width) if use_zbuf else (1, 1), np.inf, np.float32)  # ranges to mm: ample
    # the image tiles the mesh's back faces touch: only there can terrain hide terrain (eoloc.kernels.ortho.fold_tiles)
    tiles = np.zeros((-(-cam.height // FOLD_TILE_PX), -(-cam.width // FOLD_TILE_PX)) if use_zbuf else (1, 1), np.uint8)
    boxes = ortho.block_boxes(rows, cols) if use_zbuf else np.zeros((1, 1, 4))  # the z-buffer blocks' image boxes
    if bool(np.any(frame.invalid)):
        u[:], v[:], rng[:], valid[:], map_x[:], map_y[:] = np.nan, np.nan, np.nan, 0, -16.0, -16.0
        n_front = n_back = 0
    else:
        n_front, n_back = compiled.ortho_project_cells(
            nodes, row_i0, row_a, NODE_STEP, col_a, *dem, cam.fx * fs, cam.fy * fs, cam.cx, cam.cy, int(kind), dp,
            r2_max, cam.width, cam.height, u, v, rng, valid, map_x, map_y, use_zbuf, FOLD_TILE_PX, tiles, boxes)
    if use_zbuf:
        if n_back > n_front:  # a mirrored view: clockwise triangles face the camera
            tiles[:] = 0
            n_back, n_front = compiled.ortho_fold_tiles(u, v, FOLD_TILE_PX, -1.0, tiles)
        if n_back:  # terrain can hide terrain only where the mesh folds over: the z-buffer there
            compiled.ortho_rasterize_depth(u, v, rng, FOLD_TILE_PX, tiles, boxes, zbuf)
            compiled.ortho_hide_folded(u, v, rng, zbuf, FOLD_TILE_PX, tiles, boxes, cam.width, cam.height, valid, map_x,
                                       map_y)
    return FramePixels(u, v, rng, valid.view(bool), map_x, map_y)


def _ideal_radius2(cam, focal_scale: float) -> float:
    """The largest squared ideal (undistorted) normalised radius the image reaches (its outer
    border, sampled densely, undistorted)."""
    t = np.linspace(0.0, 1.0, 65)
    w, h = cam.width - 0.5, cam.height - 0.5
    u = np.r_[-0.5 + (w + 0.5) * t, np.full(65, w), w - (w + 0.5) * t, np.full(65, -0.5)]
    v = np.r_[np.full(65, -0.5), -0.5 + (h + 0.5) * t, np.full(65, h), h - (h + 0.5) * t]
    xn, yn = cam.pixel_to_normalized(u, v, focal_scale=focal_scale)
    r2 = xn * xn + yn * yn
    return float(np.max(r2[np.isfinite(r2)])) if np.isfinite(r2).any() else math.inf


@implements("frame_pixels", "numpy")
def _frame_pixels_reference(sensor: SensorModel, pose: Pose, ground: StopRule, grid: OutputGrid, *,
                            occlusion: bool = True) -> FramePixels:
    """numpy: every cell through pyproj, the DEM and :meth:`SensorModel.ground_to_image`; a cell is
    hidden when the M4 ray through its own pixel stops on terrain well before reaching it."""
    rows, cols = grid.shape
    rr, cc = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    gx, gy = grid.centres(rr, cc)
    lon, lat = transformer(grid.crs, _WGS84).transform(gx, gy)
    h = ground.ground_height(lat, lon) if ground.terrain is not None else np.full(lat.shape, level_height(ground))
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
    u, v = sensor.ground_to_image(pose, p)
    cam = sensor.camera
    cam_p = np.stack(np.broadcast_arrays(*geodesy.geodetic_to_ecef(pose.lat_deg, pose.lon_deg, pose.h_m)), -1)
    rng = np.linalg.norm(p - cam_p, axis=-1)
    with np.errstate(invalid="ignore"):
        valid = (np.isfinite(u) & np.isfinite(v) & (u >= -0.5) & (u <= cam.width - 0.5) & (v >= -0.5)
                 & (v <= cam.height - 0.5))
    if occlusion and ground.terrain is not None and valid.any():
        f = OnDEM(ground.terrain).locate(sensor, pose, (u[valid], v[valid]))
        gsd = float(min(abs(grid.res[0]), abs(grid.res[1])))
        if grid.crs.is_geographic:
            gsd *= math.pi / 180.0 * 6.37e6
        # the ray through the cell's own pixel stops before reaching the cell: something is in front
        seen = np.where(f.ok, f.range_m >= rng[valid] - max(2.0 * gsd, 1.0), False)
        valid[valid] = seen
    map_x = np.where(valid, np.clip(u, 0.0, cam.width - 1.0), -16.0).astype(np.float32)
    map_y = np.where(valid, np.clip(v, 0.0, cam.height - 1.0), -16.0).astype(np.float32)
    return FramePixels(u, v, np.where(np.isfinite(u), rng, np.nan), valid, map_x, map_y)


# the images OpenCV's remap samples bilinearly within a count of exact (measured and tested; its int16 path
# quantises the position to 1/32 px, 1 000+ counts off on 16-bit noise, so int16 and floats take eoloc's sampler)
REMAP_DTYPES = ("uint8", "uint16")


def resample(image: np.ndarray, px: FramePixels, *, resampling: str = "bilinear", nodata: float = 0) -> np.ndarray:
    """Every band of ``image`` (bands, H, W) read at the cells' pixels (nearest, bilinear or
    cubic), nodata where the camera does not see the cell; the image's dtype (integers rounded
    and clipped). Bilinear on 8- and 16-bit images is OpenCV's remap (SIMD, fixed-point weights:
    within one count of exact bilinear at the float32 positions, tested); float images, nearest and
    other integer types go through eoloc's compiled sampler (exact weights), cubic through scipy."""
    if resampling not in RESAMPLING:
        raise InputError(f"resampling {resampling!r}: choose from {sorted(RESAMPLING)}")
    rows, cols = px.valid.shape
    is_int = np.issubdtype(image.dtype, np.integer)
    fill = np.asarray(nodata).astype(image.dtype)[()]
    if resampling == "bilinear" and image.dtype.name in REMAP_DTYPES:
        import cv2

        out = np.empty((image.shape[0], rows, cols), dtype=image.dtype)
        for b0 in range(0, image.shape[0], 4):  # remap takes up to 4 channels at once
            planes = [np.ascontiguousarray(image[b]) for b in range(b0, min(b0 + 4, image.shape[0]))]
            chunk = planes[0] if len(planes) == 1 else cv2.merge(planes)  # interleaved, as remap wants
            got = cv2.remap(chunk, px.map_x, px.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=(float(fill),) * 4)
            if got.ndim == 2:
                out[b0] = got
            else:
                for i in range(got.shape[2]):  # de-interleave straight into the band planes
                    cv2.extractChannel(got, i, dst=out[b0 + i])
        return out
    out = np.empty((image.shape[0], rows, cols), dtype=image.dtype)
    if resampling != "cubic":
        return backend().sample_bands(image, px, resampling == "bilinear", is_int, fill, out)
    return _sample_bands_scipy(image, px, RESAMPLING[resampling], is_int, fill, out)


@implements("sample_bands", "numba")
def _sample_bands_compiled(image: np.ndarray, px: FramePixels, bilinear: bool, is_int: bool, fill, out: np.ndarray):
    """Nearest or bilinear, exact weights: eoloc's compiled sampler."""
    from ..kernels import compiled

    compiled.ortho_sample_bands(np.ascontiguousarray(image), px.u_px, px.v_px, px.valid.view(np.uint8), bilinear,
                                is_int, fill, out)
    return out


@implements("sample_bands", "numpy")
def _sample_bands_numpy(image: np.ndarray, px: FramePixels, bilinear: bool, is_int: bool, fill, out: np.ndarray):
    """Nearest or bilinear through scipy."""
    return _sample_bands_scipy(image, px, 1 if bilinear else 0, is_int, fill, out)


def _sample_bands_scipy(image: np.ndarray, px: FramePixels, order: int, is_int: bool, fill, out: np.ndarray):
    """Every band through scipy's map_coordinates (spline ``order``: 0, 1, 3), ``fill`` outside."""
    from scipy.ndimage import map_coordinates

    info = np.iinfo(image.dtype) if is_int else None
    valid = px.valid
    coords = np.stack([np.where(valid, px.v_px, -10.0), np.where(valid, px.u_px, -10.0)])
    for b in range(image.shape[0]):
        band = map_coordinates(image[b].astype(np.float64), coords, order=order, mode="nearest", prefilter=order > 1)
        if is_int:
            band = np.clip(np.rint(band), info.min, info.max)
        out[b] = np.where(valid, band, fill).astype(image.dtype)
    return out


def orthorectify(image: ArrayLike, sensor: SensorModel, pose: Pose, ground: StopRule, *, crs: str = "utm",
                 gsd_m: float | None = None, resampling: str = "bilinear", nodata: float = 0,
                 occlusion: bool = True, max_cells: int = 40_000_000, edge_samples: int = 16,
                 grid: OutputGrid | None = None) -> Ortho:
    """Orthorectify one frame ``image`` ((H, W) or (bands, H, W), or (H, W, bands) with 3-4 bands
    last, as images load) seen from ``pose`` onto the ``ground`` rule's surface (``AtHeight(h)``, or
    ``OnDEM(dem)``) in ``crs`` (see :func:`output_crs`), at ``gsd_m`` metres per cell (default: the native
    ground sample distance at the image centre; for a geographic CRS the cell is that many metres
    at the frame centre's latitude), or onto a given ``grid``. Cells outside the footprint, off the
    DEM, or (``occlusion``, DEM only) hidden by terrain get ``nodata``."""
    if resampling not in RESAMPLING:
        raise InputError(f"resampling {resampling!r}: choose from {sorted(RESAMPLING)}")
    img = _bands_first(np.asarray(image), sensor)
    if grid is None:
        grid = output_grid(sensor, pose, ground, crs=crs, gsd_m=gsd_m, max_cells=max_cells,
                           edge_samples=edge_samples)
    px = frame_pixels(sensor, pose, ground, grid, occlusion=occlusion)
    data = resample(img, px, resampling=resampling, nodata=nodata)
    return Ortho(data, px.valid, grid.transform, grid.crs, nodata, grid.res)


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


def shortcut_error(ortho: Ortho, sensor: SensorModel, pose: Pose, ground: StopRule, pixels: ArrayLike) -> \
        ShortcutError:
    """Locate ``pixels`` ((N, 2) u, v of the original frame) rigorously, find them in the
    rectified image, read them back with :func:`bounds_shortcut`, and return the distances."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    f = ground.locate(sensor, pose, (px[:, 0], px[:, 1]))
    x, y = transformer(_WGS84, ortho.crs).transform(f.lon_deg, f.lat_deg)
    row, col = ortho.pixel_of(x, y)
    lat1, lon1 = bounds_shortcut(ortho, row, col)
    lat2, lon2 = bounds_shortcut(ortho, np.floor(row) + 0.5, np.floor(col) + 0.5)
    return ShortcutError(geodesy.horizontal_distance_m(f.lat_deg, f.lon_deg, lat1, lon1),
                         geodesy.horizontal_distance_m(f.lat_deg, f.lon_deg, lat2, lon2))


__all__ = ["FramePixels", "GroundGrid", "Ortho", "OutputGrid", "ShortcutError", "bounds_shortcut", "frame_pixels",
           "grid_covering", "ground_grid", "native_gsd_m", "orthorectify", "output_crs", "output_grid", "resample",
           "shortcut_error", "transformer"]
