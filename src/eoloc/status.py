"""The per-target status codes, defined once: the kernels compile them as plain ints
(:mod:`eoloc.kernels.core`), everything above reads them as :class:`Status` (re-exported by
:mod:`eoloc.result`). At the bottom of the house: it imports nothing of eoloc."""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    """Per-target outcome. Coordinates are NaN wherever the status is not OK."""

    OK = 0
    NO_INTERSECTION = 1  # ray misses the surface (above the horizon) or it lies behind the camera
    OUT_OF_COVERAGE = 2  # ray leaves the terrain model's coverage before hitting it
    DEM_VOID = 3  # ray meets a no-data cell of the terrain model
    INVALID_INPUT = 4  # NaN/inf or out-of-range input (angle, range, pixel, pose)
    NO_TELEMETRY = 5  # a detection with no pose at its time/frame
    BELOW_SURFACE = 6  # the camera is on or below the surface the rule stops at (a height, a plane)
    OUT_OF_IMAGE = 7  # the pixel lies outside the image, or where the lens model cannot be inverted
    DEGENERATE = 8  # multi-view: the rays do not determine a point (near-parallel, or it is behind a camera)
    INCONSISTENT = 9  # a target's fixes over many frames do not agree with one point (no estimate is given)

    @property
    def explanation(self) -> str:
        return _EXPLAIN[self]


_EXPLAIN = {
    Status.OK: "located",
    Status.NO_INTERSECTION: "the ray does not reach the surface (above the horizon or pointing away)",
    Status.OUT_OF_COVERAGE: "the ray leaves the terrain model's coverage",
    Status.DEM_VOID: "the ray meets a void (no-data) in the terrain model",
    Status.INVALID_INPUT: "an input is NaN, infinite or out of range",
    Status.NO_TELEMETRY: "no telemetry record matches the detection's time or frame",
    Status.BELOW_SURFACE: "the camera is on or below the target surface (check the target height)",
    Status.OUT_OF_IMAGE: "the pixel is outside the image (or where the lens model cannot be inverted)",
    Status.DEGENERATE: "the rays do not determine a point (near-parallel, or it lies behind a camera)",
    Status.INCONSISTENT: ("the target's fixes do not agree with one point (it moved, they jump between a summit and "
                          "the slope behind it, or their uncertainty is too small): no estimate"),
}
