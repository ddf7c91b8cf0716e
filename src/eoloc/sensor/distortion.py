"""Lens distortion models, both ways, in normalised image coordinates (x = (u - cx) / fx, ...).

- :class:`BrownConrady` — OpenCV's model (k1, k2, k3 radial; p1, p2 tangential). Distorting is
  the closed form; undistorting is Newton's method on the 2x2 Jacobian (OpenCV's undistortPoints
  takes 5 fixed-point steps by default, not converged for strong lenses: ours converges to
  < 1e-12, tested against cv2.undistortPointsIter run to convergence).
- :class:`DistortionRatio` — [Z15]'s measured distortion ratio D = (eta - zeta) / zeta (eta the
  actual image height, zeta the ideal) as a function of the normalised field
  w = arctan(eta / f) / w0, w0 = arctan(eta_max / f); the table is fitted piecewise by monotone
  cubic polynomials (PCHIP). Undistorting is direct (x_r = x / (1 + D)); distorting solves
  eta = zeta (1 + D(w(eta))) by fixed-point iteration.

- :class:`FisheyePix4D` — Pix4D's fisheye polynomial and affine (the drone camera database's fisheye
  lenses); undistorting is Newton's method on the polynomial.

All models are evaluated by :mod:`eoloc.kernels.core` (``undistort`` / ``distort``), so the
compiled frame kernels and the array path share one implementation.
Every stop rule sees undistorted rays: the camera applies ``undistort`` in pixel -> ray and
``distort`` in ground -> pixel.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..kernels import core as kernels

# [Z15] measured table: normalised field w -> distortion ratio D in percent
Z15_FIELD = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
Z15_D_PERCENT = (0.0, 0.003, 0.057, 0.160, 0.309, 0.500, 0.731, 1.000, 1.303, 1.637, 2.000)


@dataclass(frozen=True)
class BrownConrady:
    """OpenCV's distortion (k1, k2, p1, p2, k3 in OpenCV's coefficient order: cv2 distCoeffs)."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    name = "brown-conrady"
    kind: ClassVar[int] = kernels.DIST_BROWN

    @property
    def coefficients(self) -> np.ndarray:
        """OpenCV's distCoeffs order: (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    @cached_property
    def packed(self) -> np.ndarray:
        """Parameters as the compiled kernels take them (eoloc.kernels.core.undistort)."""
        return self.coefficients

    def distort(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised coordinates -> distorted normalised coordinates."""
        return kernels.distort(self.kind, self.packed, _f64(x), _f64(y))

    def undistort(self, xd: ArrayLike, yd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Distorted normalised coordinates -> ideal ones (Newton, converged to ~1e-15)."""
        with np.errstate(all="ignore"):
            return kernels.undistort(self.kind, self.packed, _f64(xd), _f64(yd))


@dataclass(frozen=True)
class DistortionRatio:
    """[Z15]'s distortion-ratio model. ``r_max``: the largest normalised image height
    (half-diagonal / f) that the field w = 1 refers to; ``field`` and ``d_percent``: the table."""

    r_max: float
    field: tuple[float, ...] = Z15_FIELD
    d_percent: tuple[float, ...] = Z15_D_PERCENT

    name = "ratio"
    kind: ClassVar[int] = kernels.DIST_RATIO

    def __post_init__(self) -> None:
        if not self.r_max > 0:
            raise ValueError(f"r_max (half-diagonal / focal length) must be > 0, got {self.r_max!r}")
        if len(self.field) != len(self.d_percent) or len(self.field) < 3:
            raise ValueError("the distortion table needs matching field and d_percent lists of >= 3 values")
        if np.any(np.diff(self.field) <= 0):
            raise ValueError(f"distortion table field values must increase, got {self.field}")

    @classmethod
    def for_camera(cls, camera, field: tuple[float, ...] = Z15_FIELD,
                   d_percent: tuple[float, ...] = Z15_D_PERCENT) -> DistortionRatio:
        """The table referred to the image half-diagonal of ``camera`` (w = 1 at the corners)."""
        r_max = float(np.hypot(camera.width / 2.0 / camera.fx, camera.height / 2.0 / camera.fy))
        return cls(r_max, tuple(field), tuple(d_percent))

    @cached_property
    def packed(self) -> np.ndarray:
        """(w0, n, breakpoints, PCHIP coefficients per interval): the layout of
        eoloc.kernels.core.ppoly_eval. scipy fits the monotone cubic pieces; the kernels evaluate them."""
        from scipy.interpolate import PchipInterpolator

        fit = PchipInterpolator(np.asarray(self.field), np.asarray(self.d_percent) / 100.0)
        return np.concatenate([[np.arctan(self.r_max), len(self.field)], fit.x, fit.c.T.ravel()]).astype(np.float64)

    def ratio(self, r_distorted: ArrayLike) -> np.ndarray:
        """D at distorted normalised image height(s) r = eta / f."""
        return kernels.distortion_ratio(_f64(r_distorted), self.packed)

    def undistort(self, xd: ArrayLike, yd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        return kernels.undistort(self.kind, self.packed, _f64(xd), _f64(yd))

    def distort(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        return kernels.distort(self.kind, self.packed, _f64(x), _f64(y))


@dataclass(frozen=True)
class FisheyePix4D:
    """Pix4D's fisheye lens model (the drone camera database's ``lensType = fisheye`` entries):
    a ray at angle phi off the axis has theta = 2 phi / pi, rho = p0 + p1 theta + ... + p4 theta^4,
    and lands at (xh, yh) = rho (X, Y) / sqrt(X^2 + Y^2), then pixel = (C D; E F) (xh, yh) + (cx, cy).
    Here in normalised coordinates of a camera whose fx = fy = C: ``affine`` = (1, D/C, E/C, F/C).
    Undistorting solves rho(theta) by Newton; rays 90 degrees or more off the axis are not rays."""

    poly: tuple[float, float, float, float, float]
    affine: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 1.0)

    name = "pix4d-fisheye"
    kind: ClassVar[int] = kernels.DIST_FISHEYE

    def __post_init__(self) -> None:
        if len(self.poly) != 5 or not self.poly[1] > 0:
            raise ValueError(f"the fisheye polynomial needs p0..p4 with p1 > 0, got {self.poly!r}")
        a, b, c, d = self.affine
        if not abs(a * d - b * c) > 0:
            raise ValueError(f"the fisheye affine {self.affine!r} is singular")

    @cached_property
    def packed(self) -> np.ndarray:
        return np.array([*self.poly, *self.affine], dtype=np.float64)

    def distort(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        return kernels.distort(self.kind, self.packed, _f64(x), _f64(y))

    def undistort(self, xd: ArrayLike, yd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(all="ignore"):
            return kernels.undistort(self.kind, self.packed, _f64(xd), _f64(yd))


def _f64(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


Distortion = BrownConrady | DistortionRatio | FisheyePix4D
