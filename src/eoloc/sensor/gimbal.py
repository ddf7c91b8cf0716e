"""Gimbal models: each maps gimbal angles to R_body_cam (camera frame -> body FRD frame).

- :class:`AzElGimbal` — two-axis turret ([S13], [Z15]): azimuth about body z (positive to the
  right of the nose), then elevation about the new y (positive up, negative looks down); an
  optional third angle rolls the sensor about its boresight. Boresight in body =
  (cos el cos az, cos el sin az, -sin el); camera x = turret y, camera y = turret z.
- :class:`RollPitchGimbal` — framed reconnaissance camera ([Q]): outer frame rolls about body x,
  inner frame pitches about the rolled y; at zero the boresight is body +z (nadir). Boresight in
  body = (sin p, -sin r cos p, cos r cos p): a positive roll looks LEFT, a positive pitch looks
  forward. Pixel layout is [Q]'s: image rows grow toward the nose, columns toward the left wing
  (sensor ray of pixel (row i, col j) is -T_S' = (a(i - (M+1)/2), a((N+1)/2 - j), f)).
- :class:`FixedMount` — any R_body_cam given as a matrix or a quaternion (w, x, y, z), plus an
  optional sensor roll about the boresight (the first gimbal angle).

The kernels live in :mod:`eoloc.kernels.core` (``r_body_cam``); these classes name the angles and
carry the constant part.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..kernels.core import GimbalKind

_IDENTITY9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Gimbal:
    """Base of the gimbal models: ``kind`` selects the kernel, ``angle_names`` the angles' order."""

    kind: ClassVar[int] = -1
    name: ClassVar[str] = ""
    angle_names: ClassVar[tuple[str, ...]] = ()

    @property
    def R_fixed9(self) -> tuple[float, ...]:
        """The constant rotation of a fixed mount, row-major (identity for moving gimbals)."""
        return _IDENTITY9

    def angles(self, gimbal_deg: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Three gimbal angles in radians from the pose's gimbal tuple (missing ones are 0)."""
        n = len(self.angle_names)
        if not 0 <= len(gimbal_deg) <= n + 1:
            raise ValueError(
                f"{self.name} gimbal takes {n} angles ({', '.join(self.angle_names) or 'none'}) and an optional "
                f"sensor roll, got {len(gimbal_deg)} values: {gimbal_deg!r}"
            )
        padded = [np.asarray(a, dtype=np.float64) for a in gimbal_deg] + [np.float64(0.0)] * (3 - len(gimbal_deg))
        if self.kind == GimbalKind.FIXED:  # fixed mount: the only angle is the sensor roll, kernel reads it third
            padded = [np.float64(0.0), np.float64(0.0), padded[0]]
        return tuple(np.radians(a) for a in padded)


@dataclass(frozen=True)
class AzElGimbal(Gimbal):
    """Azimuth-elevation turret. Angles: (azimuth, elevation[, sensor_roll]) in degrees."""

    kind: ClassVar[GimbalKind] = GimbalKind.AZ_EL
    name: ClassVar[str] = "az-el"
    angle_names: ClassVar[tuple[str, ...]] = ("azimuth", "elevation")

    @staticmethod
    def pointing(lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike, yaw_deg: ArrayLike, pitch_deg: ArrayLike,
                 roll_deg: ArrayLike, p_ecef: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Turret angles that put ECEF point(s) ``p_ecef`` (..., 3) on the boresight of a perfect
        turret at the INS point (no lever arm or misalignment): (azimuth deg, elevation deg,
        slant range m). The inverse of the boresight formula above; cueing a turret to a coordinate."""
        from ..geodesy import R_ecef_ned, geodetic_to_ecef
        from ..rotation import R_ned_body

        p0 = np.stack(geodetic_to_ecef(lat_deg, lon_deg, h_m), -1)
        los_ned = np.einsum("...ji,...j->...i", R_ecef_ned(lat_deg, lon_deg), np.asarray(p_ecef) - p0)
        los_body = np.einsum("...ji,...j->...i", R_ned_body(yaw_deg, pitch_deg, roll_deg), los_ned)
        rng = np.linalg.norm(los_body, axis=-1)
        return (np.degrees(np.arctan2(los_body[..., 1], los_body[..., 0])),
                -np.degrees(np.arcsin(los_body[..., 2] / rng)), rng)


@dataclass(frozen=True)
class RollPitchGimbal(Gimbal):
    """Roll-pitch framed camera ([Q]). Angles: (frame_roll, frame_pitch[, sensor_roll]) in degrees."""

    kind: ClassVar[GimbalKind] = GimbalKind.ROLL_PITCH
    name: ClassVar[str] = "roll-pitch"
    angle_names: ClassVar[tuple[str, ...]] = ("frame_roll", "frame_pitch")


@dataclass(frozen=True)
class FixedMount(Gimbal):
    """A camera fixed to the body: R_body_cam from ``matrix`` (3x3) or ``quaternion`` (w, x, y, z).

    Angles: (sensor_roll,) optional, degrees, about the boresight. The default (identity) makes the
    camera axes the body axes: boresight down (nadir), image x toward the nose, image y toward
    the right wing.
    """

    kind: ClassVar[GimbalKind] = GimbalKind.FIXED
    name: ClassVar[str] = "fixed"
    matrix: tuple[tuple[float, ...], ...] | None = None
    quaternion: tuple[float, float, float, float] | None = None
    _R9: tuple[float, ...] = field(init=False, repr=False, default=_IDENTITY9)

    def __post_init__(self) -> None:
        from ..rotation import matrix_from_quaternion

        if self.matrix is not None and self.quaternion is not None:
            raise ValueError("give FixedMount a matrix or a quaternion, not both")
        if self.quaternion is not None:
            R = matrix_from_quaternion(self.quaternion)
        elif self.matrix is not None:
            R = np.asarray(self.matrix, dtype=np.float64)
            if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ValueError(f"FixedMount matrix must be a proper 3x3 rotation, got {R.tolist()}")
        else:
            R = np.eye(3)
        object.__setattr__(self, "_R9", tuple(float(x) for x in R.ravel()))

    @property
    def R_fixed9(self) -> tuple[float, ...]:
        return self._R9


_BY_NAME = {"az-el": AzElGimbal, "azel": AzElGimbal, "roll-pitch": RollPitchGimbal,
            "rollpitch": RollPitchGimbal, "fixed": FixedMount}


def gimbal_from_name(name: str, **kwargs: ArrayLike) -> Gimbal:
    """'az-el', 'roll-pitch' or 'fixed' (with matrix= or quaternion=) -> a gimbal model."""
    try:
        cls = _BY_NAME[name.strip().lower()]
    except KeyError:
        raise ValueError(f"unknown gimbal model {name!r}; expected one of 'az-el', 'roll-pitch', 'fixed'") from None
    return cls(**kwargs)
