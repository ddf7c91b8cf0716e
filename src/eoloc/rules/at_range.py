"""M1 — ranged geolocation ([S13], [Z15]): the target is at the laser slant range along the ray."""

from __future__ import annotations

from dataclasses import dataclass

from numpy.typing import ArrayLike

from ..errors import InputError
from ..geodesy import WGS84
from ..kernels.core import STOP_RANGE
from ..result import Fixes
from ..sensor.model import Pose, Rays, SensorModel
from .base import KernelRule, StopRule


@dataclass(frozen=True)
class AtRange(KernelRule):
    """M1: the point at slant range ``range_m`` (m) from the camera along each ray.

    Validity domain: 0 < range <= 10 000 km (``MAX_RANGE_M``), a finite pose and a pixel in the
    image; otherwise INVALID_INPUT (OUT_OF_IMAGE for the pixel), never a point. The range is
    measured from the camera origin (lever arm applied) along the pixel's ray; a laser range
    finder boresighted with the camera gives the range of the image centre. Monte Carlo perturbs
    it by the budget's ``range_m`` source.
    """

    range_m: ArrayLike

    name = "range"
    error_sources = ("range_m",)
    kernel = "stop_at_range"
    value_field = "range_m"
    scalar_kind = STOP_RANGE


@dataclass(frozen=True)
class RangeFromRecords(StopRule):
    """M1 with each target's own slant range, taken from its record (the ``range_m`` column of
    the telemetry or detections; ``--range`` given without a value). A value like the other rules,
    but one that needs the records: :func:`eoloc.jobs.tables.locate_tables` turns it into
    :class:`AtRange` with the column (:meth:`with_ranges`); used on its own it refuses."""

    name = "range"
    error_sources = AtRange.error_sources

    @staticmethod
    def with_ranges(range_m: ArrayLike) -> AtRange:
        """The rule with the records' ranges in hand."""
        return AtRange(range_m)

    def stop(self, rays: Rays, ell=WGS84, errors=None) -> Fixes:
        raise InputError("the range comes from each target's record (range_m): locate the records with "
                         "eoloc.jobs.tables.locate_tables, or give the ranges as AtRange(range_m)")


def stop_at_range(rays: Rays, range_m: ArrayLike, *, sensor: SensorModel | None = None) -> Fixes:
    """Point at ``range_m`` (m, > 0) along each ray. NaN/negative/zero range -> INVALID_INPUT."""
    return AtRange(range_m).stop(rays, WGS84 if sensor is None else sensor.ellipsoid)


def locate_range(sensor: SensorModel, pose: Pose, range_m: ArrayLike, pixels: ArrayLike | None = None) -> Fixes:
    """M1: pixels (default: principal point) of ``pose`` to ground with a measured slant range (m)."""
    return AtRange(range_m).locate(sensor, pose, pixels)
