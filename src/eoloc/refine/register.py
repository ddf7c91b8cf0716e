"""Automatic ground control: frames matched to a georeferenced reference image (an orthophoto, a
hillshade of the DEM).

For each frame the reference is drawn as the frame would see it with the current pose: a grid of
the frame's pixels (every ``grid_px``) put on the ground by the stop rule, the ground points
carried into the reference's CRS (pyproj) and its pixels, the grid interpolated exactly to every
pixel (scipy, bilinear) and the reference resampled there (OpenCV). The frame and this predicted
view differ only by what the pose gets wrong (a few degrees at most: nearly a homography), so SIFT
matches them where a frame and a map seen from above would not match. Each verified match (mutual
ratio test, RANSAC homography) is a control point: the frame's pixel sees the ground point the
predicted view shows at the matched pixel (its latitude, longitude and DEM height interpolated
from the same grid).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from ..errors import InputError
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel
from .tiepoints import TieSettings, keypoints, mutual_matches


@dataclass(frozen=True)
class Reference:
    """A georeferenced single-band image: ``image`` (rows, cols), the affine ``transform`` (rasterio's,
    pixel corners), its ``crs`` (anything pyproj takes) and the horizontal 1-sigma of its
    georeferencing (``sigma_m``: an error the whole image shares, which moves an adjustment held to
    it as a whole)."""

    image: np.ndarray
    transform: object
    crs: object
    sigma_m: float = 1.0

    @property
    def cell_m(self) -> float:
        """The reference's cell size in metres (a geographic CRS's degrees at ~111 km)."""
        from pyproj import CRS

        size = float(np.sqrt(abs(self.transform.a * self.transform.e - self.transform.b * self.transform.d)))
        return size * 111_320.0 if CRS.from_user_input(self.crs).is_geographic else size

    def __post_init__(self) -> None:
        if self.image.ndim != 2 or min(self.image.shape) < 16:
            raise InputError(f"a reference image must be one band of at least 16 x 16 cells, got {self.image.shape}")
        if not self.sigma_m > 0:
            raise InputError(f"the reference's sigma must be > 0 m, got {self.sigma_m!r}")


@dataclass(frozen=True)
class ControlPoints:
    """Frame pixels (u_px, v_px) of frame ``frame`` (positions in the frames given) that see the
    ground points (lat_deg, lon_deg, h_m; h on the DEM) the reference shows there."""

    frame: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.size)


def predicted_view(sensor: SensorModel, pose: Pose, rule: StopRule, ref: Reference, grid_px: int = 8):
    """The reference as the frame would see it: (image (h, w) float32, NaN where the frame sees no
    ground or the reference has nothing; per pixel the reference cell it shows (col, row: cell
    centres at integers) and the ground grid's heights (gh, gw) with the grid's step)."""
    from pyproj import Transformer

    w, h = sensor.camera.width, sensor.camera.height
    gu = np.arange(0, w - 1 + grid_px, grid_px, dtype=np.float64)
    gv = np.arange(0, h - 1 + grid_px, grid_px, dtype=np.float64)
    uu, vv = np.meshgrid(gu, gv)
    f = rule.locate(sensor, pose, np.stack([uu.ravel(), vv.ravel()], -1))
    lat = np.where(f.ok, f.lat_deg, np.nan).reshape(uu.shape)
    lon = np.where(f.ok, f.lon_deg, np.nan).reshape(uu.shape)
    hh = np.where(f.ok, f.h_m, np.nan).reshape(uu.shape)
    x, y = Transformer.from_crs("EPSG:4326", ref.crs, always_xy=True).transform(lon, lat)
    inv = ~ref.transform
    x, y = np.asarray(x), np.asarray(y)
    col, row = inv.a * x + inv.b * y + inv.c, inv.d * x + inv.e * y + inv.f
    # cell centres at integer positions for the resampler
    col, row = np.asarray(col) - 0.5, np.asarray(row) - 0.5
    pu, pv = np.meshgrid(np.arange(w, dtype=np.float64) / grid_px, np.arange(h, dtype=np.float64) / grid_px)
    mx = map_coordinates(col, [pv, pu], order=1, mode="nearest", cval=np.nan)
    my = map_coordinates(row, [pv, pu], order=1, mode="nearest", cval=np.nan)
    img = cv2.remap(ref.image.astype(np.float32), mx.astype(np.float32), my.astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    img[~(np.isfinite(mx) & np.isfinite(my))] = np.nan
    return img, (mx, my, hh), grid_px


def control_points(images: Sequence[np.ndarray], sensors: Sequence[SensorModel], poses: Sequence[Pose],
                   rule: StopRule, ref: Reference, tie: TieSettings | None = None, *, grid_px: int = 8,
                   ransac_px: float = 3.0, min_inliers: int = 12) -> ControlPoints:
    """Control points of every frame matched to the reference (see the module notes)."""
    from pyproj import Transformer

    tie = tie if tie is not None else TieSettings()
    sift = cv2.SIFT_create(nfeatures=tie.features)
    to_geographic = Transformer.from_crs(ref.crs, "EPSG:4326", always_xy=True)
    out: list[list[np.ndarray]] = [[] for _ in range(6)]
    for k, (image, sensor, pose) in enumerate(zip(images, sensors, poses, strict=True)):
        view, (mx, my, hh), step = predicted_view(sensor, pose, rule, ref, grid_px)
        seen = np.isfinite(view)
        if seen.mean() < 0.2:
            continue
        lo, hi = np.nanpercentile(view, (0.5, 99.5))
        view8 = np.clip((np.nan_to_num(view, nan=lo) - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).astype(np.uint8)
        a, da = keypoints(image, tie, sift)
        b, db = keypoints(view8, tie, sift)
        if da is None or db is None:
            continue
        m = mutual_matches(da, db, tie.ratio)
        if len(m) < min_inliers:
            continue
        pa, pb = a[m[:, 0]], b[m[:, 1]]
        # the predicted view's pixels next to its edge of no-data carry the edge's blur: left out
        inside = map_coordinates(seen.astype(np.float64), [pb[:, 1], pb[:, 0]], order=0, mode="constant") > 0
        pa, pb = pa[inside], pb[inside]
        if len(pa) < min_inliers:
            continue
        _, mask = cv2.findHomography(pa, pb, cv2.RANSAC, ransac_px)
        if mask is None:
            continue
        ok = mask.ravel().astype(bool)
        if ok.sum() < min_inliers:
            continue
        pa, pb = pa[ok], pb[ok]
        # the ground the matched pixel shows: the reference cell there, through the reference's own
        # georeferencing (exact); its height from the ground grid (the DEM constrains it anyway)
        col = map_coordinates(mx, [pb[:, 1], pb[:, 0]], order=1, mode="nearest")
        row = map_coordinates(my, [pb[:, 1], pb[:, 0]], order=1, mode="nearest")
        t = ref.transform
        x, y = t.a * (col + 0.5) + t.b * (row + 0.5) + t.c, t.d * (col + 0.5) + t.e * (row + 0.5) + t.f
        lon_c, lat_c = to_geographic.transform(np.asarray(x), np.asarray(y))
        h_c = map_coordinates(hh, [pb[:, 1] / step, pb[:, 0] / step], order=1, mode="nearest")
        gl = [np.asarray(lat_c), np.asarray(lon_c), h_c]
        good = np.isfinite(gl[0]) & np.isfinite(gl[1]) & np.isfinite(gl[2])
        for store, values in zip(out, (np.full(good.sum(), k), pa[good, 0], pa[good, 1], *(g[good] for g in gl)),
                                 strict=True):
            store.append(values)
    cols = [np.concatenate(c) if c else np.zeros(0) for c in out]
    return ControlPoints(cols[0].astype(np.int64), *cols[1:])
