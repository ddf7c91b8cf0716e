"""Pinhole camera intrinsics and the pixel <-> camera-ray mapping.

Camera frame (computer vision): x right in the image, y down, z along the boresight out of the
lens. Pixels: u = column (right), v = row (down); the centre of the top-left pixel is (0, 0), so
the default principal point of a W x H image is ((W - 1) / 2, (H - 1) / 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from ..kernels import core as kernels
from .distortion import Distortion


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics: focal lengths fx, fy and principal point cx, cy in pixels; image size;
    optional lens distortion (removed on pixel -> ray, applied on ray -> pixel)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: Distortion | None = None
    pixel_um: float | None = None  # the pixel pitch when the camera was given by focal length in mm

    def __post_init__(self) -> None:
        if not (int(self.width) == self.width > 0 and int(self.height) == self.height > 0):
            raise ValueError(f"image size must be positive whole pixels, got {self.width} x {self.height}")
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"camera {name} must be a positive number of pixels, got {value!r}")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"camera {name} must be finite, got {getattr(self, name)!r}")

    # -- named constructors (units vary with the source) --------------------------------------

    @classmethod
    def from_focal_mm(cls, focal_mm: float, pixel_um: float, width: int, height: int, *,
                      pixel_um_y: float | None = None, cx: float | None = None,
                      cy: float | None = None) -> Camera:
        """From focal length (mm) and pixel pitch (µm); principal point at the image centre unless given."""
        if not (focal_mm > 0 and pixel_um > 0):
            raise ValueError(f"focal_mm and pixel_um must be > 0, got {focal_mm!r} and {pixel_um!r}")
        f_px = focal_mm * 1e3 / pixel_um
        fy = focal_mm * 1e3 / (pixel_um_y or pixel_um)
        return cls(width, height, f_px, fy, *_centre(width, height, cx, cy), pixel_um=float(pixel_um))

    @classmethod
    def from_hfov(cls, hfov_deg: float, width: int, height: int, *, vfov_deg: float | None = None,
                  cx: float | None = None, cy: float | None = None) -> Camera:
        """From the horizontal field of view (deg) across ``width`` pixels (square pixels unless
        ``vfov_deg`` is given). The FOV spans the outer edges of the edge pixels."""
        if not 0 < hfov_deg < 180:
            raise ValueError(f"hfov_deg must be in (0, 180), got {hfov_deg!r}")
        fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        fy = fx if vfov_deg is None else (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)
        return cls(width, height, fx, fy, *_centre(width, height, cx, cy))

    @classmethod
    def from_matrix(cls, K: ArrayLike, width: int, height: int) -> Camera:
        """From a 3x3 intrinsic matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] (skew must be 0)."""
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3) or K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        return cls(width, height, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))

    def with_distortion(self, distortion: Distortion | None) -> Camera:
        """The same camera with a lens distortion model."""
        return replace(self, distortion=distortion)

    # -- properties ---------------------------------------------------------------------------

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan(self.width / (2.0 * self.fx)))

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan(self.height / (2.0 * self.fy)))

    @property
    def centre_px(self) -> tuple[float, float]:
        """The principal point (u, v)."""
        return (self.cx, self.cy)

    def corners_px(self) -> np.ndarray:
        """Outer corners of the image (4, 2): top-left, top-right, bottom-right, bottom-left."""
        w, h = self.width - 0.5, self.height - 0.5
        return np.array([[-0.5, -0.5], [w, -0.5], [w, h], [-0.5, h]])

    # -- mapping ------------------------------------------------------------------------------

    def pixel_to_normalized(self, u: ArrayLike, v: ArrayLike, *, focal_error_px: ArrayLike = 0.0,
                            principal_point_error_px: tuple[ArrayLike, ArrayLike] = (0.0, 0.0),
                            focal_scale: ArrayLike = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Pixels to ideal (undistorted) normalised image coordinates ((u - cx) / fx, (v - cy) / fy).

        ``focal_scale``: this image's focal length over the camera's (a zoom lens, per record);
        ``focal_error_px`` (added to fx, fy scaled alike) and ``principal_point_error_px`` (added to
        cx, cy) let Monte Carlo perturb the intrinsics per sample; all broadcast with the pixels.
        The lens distortion is taken as fixed in normalised coordinates across the zoom range.
        """
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        scale = np.asarray(focal_scale, dtype=np.float64) + np.asarray(focal_error_px, dtype=np.float64) / self.fx
        dcx, dcy = principal_point_error_px
        xn = (u - (self.cx + dcx)) / (self.fx * scale)
        yn = (v - (self.cy + dcy)) / (self.fy * scale)
        if self.distortion is not None:
            xn, yn = self.distortion.undistort(xn, yn)
        return xn, yn

    def outside(self, u: ArrayLike, v: ArrayLike, xn: ArrayLike, yn: ArrayLike, *,
                focal_scale: ArrayLike = 1.0) -> np.ndarray:
        """True where finite pixels (u, v) are not to be located: outside the image (beyond
        ``IMAGE_MARGIN_PX`` = 0.5 px past the outer edges of the edge pixels) or where the lens
        model does not map them to one ray (their undistortion ``(xn, yn)`` from
        :meth:`pixel_to_normalized` is not the inverse, e.g. past the fold of a barrel lens)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        m = 0.5 + kernels.IMAGE_MARGIN_PX
        if self.distortion is None and u.size and v.size and u.min() >= -m and v.min() >= -m \
                and u.max() <= self.width - 1.0 + m and v.max() <= self.height - 1.0 + m:
            return np.False_  # all inside (and finite): four reductions instead of a mask
        with np.errstate(all="ignore"):
            usable = kernels.pixel_in_image(u, v, float(self.width), float(self.height))
            if self.distortion is not None:
                d = self.distortion
                k = np.asarray(focal_scale, dtype=np.float64)
                usable = usable & kernels.undistort_ok(d.kind, d.packed, (u - self.cx) / (self.fx * k),
                                                       (v - self.cy) / (self.fy * k), np.asarray(xn), np.asarray(yn))
            return np.isfinite(u + v) & ~usable

    def normalized_to_pixel(self, xn: ArrayLike, yn: ArrayLike, *,
                            focal_scale: ArrayLike = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised image coordinates to (distorted) pixels (``focal_scale``: the zoom)."""
        if self.distortion is not None:
            xn, yn = self.distortion.distort(xn, yn)
        k = np.asarray(focal_scale, dtype=np.float64)
        return np.asarray(xn) * (self.fx * k) + self.cx, np.asarray(yn) * (self.fy * k) + self.cy

    def pixel_to_los_cam(self, u: ArrayLike, v: ArrayLike) -> np.ndarray:
        """Unit line-of-sight vectors (..., 3) in the camera frame for pixels (u, v)."""
        xn, yn = self.pixel_to_normalized(u, v)
        los = np.stack(np.broadcast_arrays(xn, yn, np.ones_like(xn)), -1)
        return los / np.linalg.norm(los, axis=-1, keepdims=True)

    def los_cam_to_pixel(self, los_cam: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame directions (..., 3) to pixels; NaN for directions not in front (z <= 0)."""
        los = np.asarray(los_cam, dtype=np.float64)
        z = np.where(los[..., 2] > 0, los[..., 2], np.nan)
        return self.normalized_to_pixel(los[..., 0] / z, los[..., 1] / z)


def _centre(width: int, height: int, cx: float | None, cy: float | None) -> tuple[float, float]:
    return ((width - 1) / 2.0 if cx is None else float(cx), (height - 1) / 2.0 if cy is None else float(cy))
