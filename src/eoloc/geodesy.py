"""WGS-84 geodesy: geodetic <-> ECEF, the local NED/ENU frames, offsets between points.

Units: degrees at the API (``degrees=False`` for radians), metres everywhere; heights are
ellipsoidal (h above WGS-84). ECEF is WGS-84 Earth-centred Earth-fixed.
Accuracy: geodetic <-> ECEF agrees with PROJ to < 1 micrometre from -10 km to +100 km height
at every latitude including the poles (tests/unit/test_geodesy.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from .kernels import core as kernels
from .kernels.backend import run

__all__ = [
    "WGS84",
    "Ellipsoid",
    "R_ecef_enu",
    "R_ecef_ned",
    "ecef_to_enu",
    "ecef_to_geodetic",
    "ecef_to_ned",
    "enu_to_ecef",
    "from_frame",
    "geodetic_to_ecef",
    "geodetic_to_ned",
    "look_angles",
    "ned_to_ecef",
    "to_frame",
]


@dataclass(frozen=True)
class Ellipsoid:
    """A reference ellipsoid given by semi-major axis ``a`` (m) and flattening ``f``."""

    a: float
    f: float
    name: str = ""

    def __post_init__(self) -> None:
        if not (self.a > 0 and 0 <= self.f < 1):
            raise ValueError(f"ellipsoid needs a > 0 and 0 <= f < 1, got a={self.a!r}, f={self.f!r}")

    @cached_property
    def b(self) -> float:
        """Semi-minor axis (m), computed from a and f, never rounded."""
        return self.a * (1.0 - self.f)

    @cached_property
    def e2(self) -> float:
        """First eccentricity squared."""
        return self.f * (2.0 - self.f)

    @cached_property
    def ep2(self) -> float:
        """Second eccentricity squared."""
        return self.e2 / (1.0 - self.e2)

    @property
    def constants(self) -> tuple[float, float, float, float]:
        """(a, b, e2, ep2), the form the kernels take."""
        return (self.a, self.b, self.e2, self.ep2)


WGS84 = Ellipsoid(6378137.0, 1.0 / 298.257223563, "WGS-84")
"""The WGS-84 ellipsoid (a = 6 378 137 m, f = 1/298.257223563): every function's default."""


def _out(values: tuple[np.ndarray, ...]):
    """Scalar in, scalar out: 0-d arrays become numpy floats."""
    return tuple(v[()] if v.ndim == 0 else v for v in values)


def geodetic_to_ecef(lat: ArrayLike, lon: ArrayLike, h: ArrayLike, *, degrees: bool = True,
                     ell: Ellipsoid = WGS84):
    """Geodetic latitude, longitude (deg, or rad with ``degrees=False``) and ellipsoidal height (m)
    to ECEF x, y, z (m). Inputs broadcast."""
    lat = np.asarray(lat, dtype=np.float64)
    lon = np.asarray(lon, dtype=np.float64)
    if degrees:
        lat, lon = np.radians(lat), np.radians(lon)
    return _out(run("geodetic_to_ecef", lat, lon, h, ell.a, ell.e2))


def ecef_to_geodetic(x: ArrayLike, y: ArrayLike, z: ArrayLike, *, degrees: bool = True,
                     ell: Ellipsoid = WGS84):
    """ECEF x, y, z (m) to geodetic latitude, longitude (deg, or rad) and ellipsoidal height (m).

    Longitude is in (-180, 180]; on the polar axis it is 0. The Earth's centre gives NaN.
    """
    lat, lon, h = run("ecef_to_geodetic", x, y, z, *ell.constants)
    if degrees:
        lat, lon = np.degrees(lat), np.degrees(lon)
    return _out((lat, lon, h))


def as_matrix(t: tuple) -> np.ndarray:
    """9-tuple of broadcastable components -> (..., 3, 3)."""
    comps = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in t))
    return np.stack(comps, axis=-1).reshape((*comps[0].shape, 3, 3))


def R_ecef_ned(lat: ArrayLike, lon: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Rotation (..., 3, 3) whose columns are the north, east and down unit vectors in ECEF at
    geodetic (lat, lon): ``v_ecef = R_ecef_ned @ v_ned``."""
    lat = np.asarray(lat, dtype=np.float64)
    lon = np.asarray(lon, dtype=np.float64)
    if degrees:
        lat, lon = np.radians(lat), np.radians(lon)
    return as_matrix(kernels.r_ecef_ned(lat, lon))


_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def R_ecef_enu(lat: ArrayLike, lon: ArrayLike, *, degrees: bool = True) -> np.ndarray:
    """Rotation (..., 3, 3) whose columns are east, north, up in ECEF."""
    return R_ecef_ned(lat, lon, degrees=degrees) @ _NED_TO_ENU


def enu_turn(R_to: ArrayLike, lat: ArrayLike, lon: ArrayLike) -> np.ndarray:
    """(..., 3, 3) the rotation taking vectors in the ENU axes at (lat, lon) (deg; NaN taken as 0)
    into the axes ``R_to`` (..., 3, 3), columns in ECEF (e.g. :func:`R_ecef_enu` at an origin):
    ``R_to^T R_ecef_enu(lat, lon)``. A covariance C turns as ``T C T^T``."""
    return np.swapaxes(np.asarray(R_to, dtype=np.float64), -1, -2) @ R_ecef_enu(np.nan_to_num(lat),
                                                                                 np.nan_to_num(lon))


def to_frame(p_ecef: ArrayLike, origin_ecef: ArrayLike, R: ArrayLike) -> np.ndarray:
    """ECEF points (..., 3) in the local frame with origin ``origin_ecef`` (..., 3) whose axes are
    the columns of ``R`` (..., 3, 3), e.g. :func:`R_ecef_enu`: R^T (p - o). For frames kept
    from call to call (a target's first fix); :func:`ecef_to_enu` builds them each time."""
    return np.einsum("...ji,...j->...i", R, np.asarray(p_ecef, dtype=np.float64) - origin_ecef)


def from_frame(v: ArrayLike, origin_ecef: ArrayLike, R: ArrayLike) -> np.ndarray:
    """The inverse of :func:`to_frame`: local vectors (..., 3) back to ECEF points, R v + o."""
    return np.einsum("...ij,...j->...i", R, np.asarray(v, dtype=np.float64)) + origin_ecef


def _origin(lat0, lon0, h0, degrees, ell) -> np.ndarray:
    return np.stack(np.broadcast_arrays(*geodetic_to_ecef(lat0, lon0, h0, degrees=degrees, ell=ell)), -1)


def _local(p_ecef, lat0, lon0, h0, degrees, ell, R_fn):
    return to_frame(p_ecef, _origin(lat0, lon0, h0, degrees, ell), R_fn(lat0, lon0, degrees=degrees))


def _from_local(v, lat0, lon0, h0, degrees, ell, R_fn):
    return from_frame(v, _origin(lat0, lon0, h0, degrees, ell), R_fn(lat0, lon0, degrees=degrees))


def ecef_to_ned(p_ecef: ArrayLike, lat0, lon0, h0, *, degrees: bool = True, ell: Ellipsoid = WGS84):
    """ECEF points (..., 3) to NED offsets (..., 3) in metres from the origin (lat0, lon0, h0)."""
    return _local(p_ecef, lat0, lon0, h0, degrees, ell, R_ecef_ned)


def ned_to_ecef(v_ned: ArrayLike, lat0, lon0, h0, *, degrees: bool = True, ell: Ellipsoid = WGS84):
    """NED offsets (..., 3) in metres from (lat0, lon0, h0) to ECEF points (..., 3)."""
    return _from_local(v_ned, lat0, lon0, h0, degrees, ell, R_ecef_ned)


def ecef_to_enu(p_ecef: ArrayLike, lat0, lon0, h0, *, degrees: bool = True, ell: Ellipsoid = WGS84):
    """ECEF points (..., 3) to ENU offsets (..., 3) in metres from the origin (lat0, lon0, h0)."""
    return _local(p_ecef, lat0, lon0, h0, degrees, ell, R_ecef_enu)


def enu_to_ecef(v_enu: ArrayLike, lat0, lon0, h0, *, degrees: bool = True, ell: Ellipsoid = WGS84):
    """ENU offsets (..., 3) in metres from (lat0, lon0, h0) to ECEF points (..., 3)."""
    return _from_local(v_enu, lat0, lon0, h0, degrees, ell, R_ecef_enu)


def geodetic_to_ned(lat, lon, h, lat0, lon0, h0, *, degrees: bool = True, ell: Ellipsoid = WGS84):
    """NED offsets (..., 3) in metres of geodetic points from the origin (lat0, lon0, h0)."""
    p = np.stack(np.broadcast_arrays(*geodetic_to_ecef(lat, lon, h, degrees=degrees, ell=ell)), -1)
    return ecef_to_ned(p, lat0, lon0, h0, degrees=degrees, ell=ell)


def look_angles(lat0_deg: float, lon0_deg: float, h0_m: float, lat_deg: float, lon_deg: float, h_m: float,
                ell: Ellipsoid = WGS84) -> tuple[float, float]:
    """Azimuth (degrees from true north, [0, 360)) and elevation (degrees, negative below the
    horizon) of one point seen from another, both geodetic (degrees, ellipsoidal m): the line of
    sight in the observer's local NED frame. Plain floats, for one point at a time (a live
    packet's look at its frame centre: no array set-up); :func:`geodetic_to_ned` for arrays. The
    kernels' own formulas (:mod:`eoloc.kernels.core`), evaluated on the two points."""
    K = kernels
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    x0, y0, z0 = K.geodetic_to_ecef(lat0, lon0, h0_m, ell.a, ell.e2)
    x, y, z = K.geodetic_to_ecef(math.radians(lat_deg), math.radians(lon_deg), h_m, ell.a, ell.e2)
    north, east, down = (float(c) for c in K.mat_t_vec(K.r_ecef_ned(lat0, lon0), x - x0, y - y0, z - z0))
    return math.degrees(math.atan2(east, north)) % 360.0, math.degrees(math.atan2(-down, math.hypot(north, east)))


def horizontal_distance_m(lat1: ArrayLike, lon1: ArrayLike, lat2: ArrayLike, lon2: ArrayLike) -> np.ndarray:
    """Geodesic distance on WGS-84 (m) between points (pyproj.Geod; NaN where an input is NaN)."""
    from pyproj import Geod

    a = [np.asarray(x, dtype=np.float64) for x in np.broadcast_arrays(lat1, lon1, lat2, lon2)]
    ok = np.all([np.isfinite(x) for x in a], axis=0)
    out = np.full(a[0].shape, np.nan)
    if ok.any():
        _, _, d = Geod(ellps="WGS84").inv(a[1][ok], a[0][ok], a[3][ok], a[2][ok])
        out[ok] = d
    return out
