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

Every stop rule sees undistorted rays: the camera applies ``undistort`` in pixel -> ray and
``distort`` in ground -> pixel.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

# [Z15] measured table: normalised field w -> distortion ratio D in percent
Z15_FIELD = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
Z15_D_PERCENT = (0.0, 0.003, 0.057, 0.160, 0.309, 0.500, 0.731, 1.000, 1.303, 1.637, 2.000)

_NEWTON_STEPS = 12
_FIXED_POINT_STEPS = 30


@dataclass(frozen=True)
class BrownConrady:
    """OpenCV's distortion (k1, k2, p1, p2, k3 in OpenCV's coefficient order: cv2 distCoeffs)."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    name = "brown-conrady"

    @property
    def coefficients(self) -> np.ndarray:
        """OpenCV's distCoeffs order: (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    def distort(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised coordinates -> distorted normalised coordinates."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xy = x * y
        return (x * radial + 2.0 * self.p1 * xy + self.p2 * (r2 + 2.0 * x * x),
                y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * xy)

    def undistort(self, xd: ArrayLike, yd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Distorted normalised coordinates -> ideal ones (Newton, converged to ~1e-15)."""
        xd = np.asarray(xd, dtype=np.float64)
        yd = np.asarray(yd, dtype=np.float64)
        x, y = xd.copy(), yd.copy()
        k1, k2, k3, p1, p2 = self.k1, self.k2, self.k3, self.p1, self.p2
        for _ in range(_NEWTON_STEPS):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
            fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
            fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
            jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
            jxy = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            jyx = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
            det = jxx * jyy - jxy * jyx
            x = x - (jyy * fx - jxy * fy) / det
            y = y - (jxx * fy - jyx * fx) / det
        return x, y


@dataclass(frozen=True)
class DistortionRatio:
    """[Z15]'s distortion-ratio model. ``r_max``: the largest normalised image height
    (half-diagonal / f) that the field w = 1 refers to; ``field`` and ``d_percent``: the table."""

    r_max: float
    field: tuple[float, ...] = Z15_FIELD
    d_percent: tuple[float, ...] = Z15_D_PERCENT

    name = "ratio"

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
    def _fit(self):
        from scipy.interpolate import PchipInterpolator

        return PchipInterpolator(np.asarray(self.field), np.asarray(self.d_percent) / 100.0, extrapolate=True)

    def ratio(self, r_distorted: ArrayLike) -> np.ndarray:
        """D at distorted normalised image height(s) r = eta / f."""
        w0 = np.arctan(self.r_max)
        return self._fit(np.arctan(np.asarray(r_distorted, dtype=np.float64)) / w0)

    def undistort(self, xd: ArrayLike, yd: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        xd = np.asarray(xd, dtype=np.float64)
        yd = np.asarray(yd, dtype=np.float64)
        k = 1.0 + self.ratio(np.hypot(xd, yd))
        return xd / k, yd / k

    def distort(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        zeta = np.hypot(x, y)
        eta = zeta.copy()
        for _ in range(_FIXED_POINT_STEPS):  # contraction: |dD/deta| * zeta << 1
            eta = zeta * (1.0 + self.ratio(eta))
        k = 1.0 + self.ratio(eta)
        return x * k, y * k


Distortion = BrownConrady | DistortionRatio
