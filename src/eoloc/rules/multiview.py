"""M8 - multi-view triangulation: one target's rays from two or more poses, intersected by least squares.

The point minimises the weighted sum of squared perpendicular distances to the rays:
    p = (sum W_i)^-1 sum W_i o_i,   W_i = (I - d_i d_i^T) / (r_i sigma_i)^2,
with r_i the range from camera i to the point and sigma_i the ray's angular standard deviation
(rad), so a far ray counts for less. The same normal matrix gives the covariance,
cov = (sum W_i)^-1: exact for small, independent, isotropic angular errors. Two iterations (the
ranges come from the previous solution). When the rays are nearly parallel the depth is poorly
determined: the result carries the largest angle between the rays and the 1-sigma depth, and a
warning when the geometry is weak (angle below ``min_angle_deg``).

Validity domain: the rays must converge in front of every camera, at an angle of at least
``DEGENERATE_ANGLE_DEG`` (0.01°) between some two of them. Otherwise the status is DEGENERATE,
the point and its covariance are NaN (no output file carries it) and the warning says why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..errors import InputError
from ..result import Fixes, Status
from ..sensor.model import Rays

DEGENERATE_ANGLE_DEG = 0.01  # rays closer to parallel than this do not determine a point


@dataclass(frozen=True)
class Triangulation:
    """p_ecef (3,) m; lat/lon (deg), h (m, ellipsoidal); cov_enu (3, 3) m^2 at the point;
    residuals_m (N,) perpendicular distance of each ray from the point; max_angle_deg between
    any two rays; warning: "" or why the geometry is weak; s0: a-posteriori sigma factor, the
    RMS of the residuals in units of their declared sigma (NaN for 2 rays: no redundancy; s0 >> 1
    means the rays disagree more than sigma_rad allows)."""

    p_ecef: np.ndarray
    lat_deg: float
    lon_deg: float
    h_m: float
    cov_enu: np.ndarray
    residuals_m: np.ndarray
    max_angle_deg: float
    warning: str = ""
    s0: float = float("nan")
    status: Status = Status.OK

    @property
    def ok(self) -> bool:
        return self.status == Status.OK

    @property
    def sigma_enu(self) -> np.ndarray:
        return np.sqrt(np.diagonal(self.cov_enu))


def _max_angle_deg(d: np.ndarray) -> float:
    c = np.clip(d @ d.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(c.min())))


def triangulate(rays: Rays, sigma_rad: ArrayLike = 1e-4, *, min_angle_deg: float = 2.0) -> Triangulation:
    """Least-squares intersection of N >= 2 rays (a 1-D :class:`Rays`, ECEF) of one target.

    sigma_rad: angular standard deviation of each ray (scalar or (N,)), e.g. pixel sigma / focal
    length combined with the attitude's. Raises ValueError for fewer than 2 usable rays.
    """
    o = np.stack(np.broadcast_arrays(rays.ox, rays.oy, rays.oz), -1).reshape(-1, 3)
    d = np.stack(np.broadcast_arrays(rays.dx, rays.dy, rays.dz), -1).reshape(-1, 3)
    sig = np.broadcast_to(np.asarray(sigma_rad, dtype=np.float64), (o.shape[0],))
    good = np.all(np.isfinite(o), 1) & np.all(np.isfinite(d), 1) & np.isfinite(sig) & (sig > 0)
    good &= ~np.broadcast_to(rays.invalid, rays.shape).reshape(-1)
    o, d, sig = o[good], d[good], sig[good]
    if o.shape[0] < 2:
        raise InputError(f"triangulation needs at least 2 usable rays, got {o.shape[0]}")
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    P = np.eye(3) - d[:, :, None] * d[:, None, :]  # projectors onto each ray's normal plane
    w = np.ones(o.shape[0])
    # Least squares on the stacked rows sqrt(w_i) P_i (condition ~ 1/angle), not on the normal
    # matrix sum w_i P_i (condition ~ 1/angle^2: centimetres for near-parallel rays), and for the
    # offset from the last solution (first: the cameras' mean) rather than for ECEF coordinates.
    p = o.mean(axis=0)
    for _ in range(3):  # unweighted, then ranges from the last solution
        sw = np.sqrt(w)
        M = (sw[:, None, None] * P).reshape(-1, 3)
        rhs = (sw[:, None] * np.einsum("nij,nj->ni", P, o - p)).reshape(-1)
        p = p + np.linalg.lstsq(M, rhs, rcond=None)[0]  # exactly parallel rays: singular, still an answer
        rng = np.maximum(np.einsum("ni,ni->n", p - o, d), 1e-9)
        w = 1.0 / (rng * sig) ** 2
    A = np.einsum("n,nij->ij", w, P)
    cov_ecef = np.linalg.pinv(A)
    lat, lon, h = (float(x) for x in geodesy.ecef_to_geodetic(*p))
    R = geodesy.R_ecef_enu(lat, lon)
    cov_enu = R.T @ cov_ecef @ R
    resid = np.linalg.norm(np.einsum("nij,nj->ni", P, p - o), axis=1)
    dof = 2 * o.shape[0] - 3
    s0 = float(np.sqrt(np.sum(w * resid**2) / dof)) if dof > 1 else float("nan")
    angle = _max_angle_deg(d)
    warning = ""
    behind = ~(np.einsum("ni,ni->n", p - o, d) > 0)
    status = Status.OK
    if behind.any():
        warning = f"the point lies behind {int(behind.sum())} of the cameras: the rays do not converge"
        status = Status.DEGENERATE
    elif not angle >= DEGENERATE_ANGLE_DEG:
        warning = (f"the rays are parallel to within {angle:.2g}° (< {DEGENERATE_ANGLE_DEG:g}°): they do not "
                   "determine a point; fly a longer baseline or use a range/DEM stop")
        status = Status.DEGENERATE
    elif angle < min_angle_deg:
        depth = float(np.sqrt(np.linalg.eigvalsh(cov_ecef)[-1]))
        warning = (f"baseline too short for the range: the rays meet at {angle:.2f}° (< {min_angle_deg:g}°), "
                   f"depth uncertain by {depth:.3g} m (1 sigma); fly a longer baseline or use a range/DEM stop")
    if status != Status.OK:
        nan = float("nan")
        return Triangulation(np.full(3, nan), nan, nan, nan, np.full((3, 3), nan), resid, angle, warning, nan,
                             status)
    return Triangulation(p, lat, lon, h, cov_enu, resid, angle, warning, s0, status)


@dataclass(frozen=True)
class MultiView:
    """M8 as a stop rule over several rays: the least-squares intersection of one target's rays
    (``sigma_rad``: each ray's angular standard deviation; ``min_angle_deg``: below it a weak
    geometry warning). Validity domain: see this module; DEGENERATE otherwise."""

    sigma_rad: ArrayLike = 1e-4
    min_angle_deg: float = 2.0

    name = "multiview"

    def intersect(self, rays: Rays) -> Triangulation:
        """The full result: point, covariance, residuals, angle, warning, status."""
        return triangulate(rays, self.sigma_rad, min_angle_deg=self.min_angle_deg)

    def stop(self, rays: Rays, ell=None, errors=None):
        """The point as a one-element Fixes (range from the first ray's camera; NaN unless OK)."""
        r = self.intersect(rays)
        o = np.array([np.ravel(rays.ox)[0], np.ravel(rays.oy)[0], np.ravel(rays.oz)[0]])
        rng = float(np.linalg.norm(r.p_ecef - o)) if r.ok else float("nan")
        return Fixes(np.array([r.lat_deg]), np.array([r.lon_deg]), np.array([r.h_m]), np.array([rng]),
                     np.array([int(r.status)], dtype=np.int8))
