"""The shape every stop rule shares: a frozen value that stops rays and reports Fixes.

A stop rule says where a ray ends: at a slant range, on a surface of constant height, on a DEM,
on the flat ground through a ranged main target. Each rule is a frozen dataclass in a file of its
own in this package. It states its validity domain in its docstring, runs its kernel(s) in
:meth:`StopRule.stop` and knows which error sources perturb it (Monte Carlo and covariance pass
them in ``errors``). Every caller (pipeline, Monte Carlo, covariance, compensation, footprints,
rectification, KLV, CLI) holds a rule object and calls it, never branching on its kind.

Adding a rule: one file here with a ``StopRule`` subclass, its kernel in ``eoloc.kernels.core``,
and its row in :data:`eoloc.rules.spec.SPECS` (how users name it: every front end reads that
table; docs/architecture.md "Everyday changes, counted").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ..geodesy import WGS84, Ellipsoid
from ..kernels.backend import run
from ..result import Fixes, Status, mask_invalid
from ..sensor.model import Pose, Rays, SensorModel

if TYPE_CHECKING:
    from ..terrain.dem import DEM

Errors = Callable[[str], "np.ndarray | float"]  # error source name -> its draws (or 0.0)


def no_errors(name: str) -> float:
    return 0.0


class StopRule:
    """Base of the stop rules. ``name``: the rule's name in config files and on the command line;
    ``error_sources``: the budget sources (eoloc.accuracy) that perturb the rule itself."""

    name: ClassVar[str] = ""
    error_sources: ClassVar[tuple[str, ...]] = ()

    def stop(self, rays: Rays, ell: Ellipsoid = WGS84, errors: Errors = no_errors) -> Fixes:
        """Where each ray ends, with the rule's own error sources perturbed by ``errors``."""
        raise NotImplementedError

    def stop_in_frame(self, sensor: SensorModel, frame, xn, yn, outside, ell: Ellipsoid = WGS84,
                      errors: Errors = no_errors, normalize: Callable | None = None) -> Fixes:
        """Where the rays of normalised image points (xn, yn) of camera ``frame`` end, with the
        rule's own error sources perturbed by ``errors``: the form the error analysis calls
        (Monte Carlo, first-order covariance, sensitivity), so that every rule takes part in it.
        ``normalize(u, v)``: pixels to normalised points with the same camera errors (for a rule
        that needs a pixel of its own, e.g. FlatGround's main target). Default: the rays, then
        :meth:`stop`."""
        return self.stop(sensor.rays_from(frame, xn, yn, outside), ell, errors=errors)

    def locate(self, sensor: SensorModel, pose: Pose, pixels: ArrayLike | None = None,
               pose_index: ArrayLike | None = None) -> Fixes:
        """Pixels (default: the principal point) of ``pose`` to the ground by this rule
        (``pose_index``: each pixel's element of ``pose``, see :meth:`SensorModel.rays`)."""
        return self.stop(sensor.rays(pose, pixels, pose_index), sensor.ellipsoid)

    @property
    def terrain(self) -> DEM | None:
        """The terrain map (DEM) this rule stops rays on; None for rules without one."""
        return None

    def terrain_height(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> np.ndarray | None:
        """Heights (ellipsoidal m) of the terrain map this rule stops on, at (lat, lon); None for
        rules without a map (a corrected fix is then left at its own height)."""
        return None if self.terrain is None else self.terrain.height(lat_deg, lon_deg)

    def ground_height(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> np.ndarray:
        """Heights (ellipsoidal m) of the surface this rule stops rays on, at (lat, lon): what
        footprints' neighbours, ground grids and orthorectification stand on. InputError for a
        rule that stops rays somewhere else than on a surface (a range, other rays)."""
        raise InputError(f"the {self.name} rule does not stop rays on a ground surface: give the ground as a target "
                         "height (AtHeight, --target-height) or a DEM (OnDEM, --dem)")

    @property
    def value_shape(self) -> tuple[int, ...]:
        """The shape the rule's own value adds to the broadcast (a range or height per target)."""
        return ()

    def scalar_stop(self) -> tuple[int, float] | None:
        """(stop kind, value) for the compiled single-target kernel
        (:meth:`eoloc.SensorModel.locate_one`); None: the rule has none, and one target goes
        through :meth:`locate` instead."""
        return None

    def describe(self) -> str:
        """One line for reports: the rule and its value."""
        return self.name


def locate(sensor: SensorModel, pose: Pose, rule: StopRule, pixels: ArrayLike | None = None) -> Fixes:
    """Pixels (an (..., 2) array or a (u, v) pair; default: the principal point) of ``pose`` to
    the ground by stop ``rule`` -> :class:`eoloc.Fixes` with a status per target."""
    if not isinstance(rule, StopRule):
        raise TypeError(f"rule must be a stop rule (AtRange, AtHeight, OnDEM, FlatGround), got {rule!r}")
    return rule.locate(sensor, pose, pixels)


class KernelRule(StopRule):
    """A rule that is one stop kernel with one value per ray: the dataclass field ``value_field``
    (a range, a height), perturbed by the rule's one error source."""

    kernel: ClassVar[str] = ""
    value_field: ClassVar[str] = ""
    unit: ClassVar[str] = "m"
    scalar_kind: ClassVar[int | None] = None  # its stop kind in the single-target kernel (kernels.core.STOP_*)

    def __post_init__(self) -> None:
        object.__setattr__(self, self.value_field, f64(getattr(self, self.value_field)))

    def stop(self, rays: Rays, ell: Ellipsoid = WGS84, errors: Errors = no_errors) -> Fixes:
        value = getattr(self, self.value_field) + errors(self.error_sources[0])
        return run_stop(self.kernel, rays, value, ell)

    @property
    def value_shape(self) -> tuple[int, ...]:
        return np.shape(getattr(self, self.value_field))

    def scalar_stop(self) -> tuple[int, float] | None:
        value = getattr(self, self.value_field)
        return None if self.scalar_kind is None or np.ndim(value) else (self.scalar_kind, float(value))

    def describe(self) -> str:
        value = getattr(self, self.value_field)
        return self.name if np.ndim(value) else f"{self.name} {float(value):g} {self.unit}"


def run_stop(kernel: str, rays: Rays, value, ell: Ellipsoid) -> Fixes:
    """Run stop-rule ``kernel`` with its parameter ``value`` (range, height, ...) on ``rays``."""
    out = run(kernel, rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz, value, *ell.constants)
    return to_fixes(out, rays.invalid, rays.out_of_image)


def to_fixes(out, invalid, out_of_image=False) -> Fixes:
    """Kernel outputs (lat rad, lon rad, h, range, status) -> Fixes, INVALID_INPUT where ``invalid``
    (the pose could not be used), OUT_OF_IMAGE where ``out_of_image`` (the pixel is not in the image)."""
    lat, lon, h, t, st = (np.asarray(x) for x in out)
    arrays = (np.degrees(lat), np.degrees(lon), h, t, st.astype(np.int8, copy=False))
    for flag, status in ((out_of_image, Status.OUT_OF_IMAGE), (invalid, Status.INVALID_INPUT)):
        if np.any(flag):  # (tested before broadcasting: a scalar False costs nothing)
            arrays = mask_invalid(arrays, np.broadcast_to(flag, st.shape), status)
    lat, lon, h, t, st = arrays
    return Fixes(*(a[()] if a.ndim == 0 else a for a in (lat, lon, h, t, st)))


def f64(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)
