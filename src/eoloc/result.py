"""The one result type of every stop rule: per-target fixes with a status code each."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .status import Status


@dataclass(frozen=True)
class Fixes:
    """Geolocated targets, all arrays of one broadcast shape (scalars for a single target).

    lat_deg, lon_deg: WGS-84 geodetic degrees; h_m: ellipsoidal height (m); range_m: slant range
    from the camera (m); status: :class:`Status` codes (int8). NaN where status != OK.
    """

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    range_m: np.ndarray
    status: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of located targets."""
        return np.asarray(self.status) == Status.OK

    @property
    def shape(self) -> tuple[int, ...]:
        return np.shape(self.lat_deg)

    def __len__(self) -> int:
        return int(np.size(self.lat_deg))

    def p_ecef(self) -> np.ndarray:
        """ECEF positions (..., 3) in metres (NaN where not OK)."""
        from .geodesy import geodetic_to_ecef

        return np.stack(np.broadcast_arrays(*geodetic_to_ecef(self.lat_deg, self.lon_deg, self.h_m)), -1)

    def flat(self, index=slice(None)) -> Fixes:
        """The fixes as one flat batch (broadcast, raveled), optionally only those at ``index``."""
        arrays = np.broadcast_arrays(self.lat_deg, self.lon_deg, self.h_m, self.range_m, self.status)
        return Fixes(*(np.ravel(a)[index] for a in arrays))

    def status_counts(self) -> dict[str, int]:
        """How many targets ended with each status (only those that occur)."""
        counts = np.bincount(np.asarray(self.status).ravel().astype(np.intp), minlength=len(Status))  # no sort
        return {Status(int(c)).name: int(counts[c]) for c in np.flatnonzero(counts)}


def mask_invalid(fixes_arrays: tuple, invalid: np.ndarray, status: Status = Status.INVALID_INPUT) -> tuple:
    """Set ``status`` and NaN coordinates where ``invalid`` (checks made outside the kernels)."""
    lat, lon, h, rng, st = fixes_arrays
    if not np.any(invalid):
        return fixes_arrays
    nan = np.float64("nan")
    return (np.where(invalid, nan, lat), np.where(invalid, nan, lon), np.where(invalid, nan, h),
            np.where(invalid, nan, rng), np.where(invalid, np.int8(status), st).astype(np.int8))


def with_status(fixes: Fixes, where: np.ndarray, status: Status) -> Fixes:
    """``fixes`` with ``status`` and NaN coordinates wherever ``where`` holds."""
    out = mask_invalid((fixes.lat_deg, fixes.lon_deg, fixes.h_m, fixes.range_m, fixes.status), where, status)
    return Fixes(*(np.asarray(a)[()] if np.ndim(a) == 0 else a for a in out))
