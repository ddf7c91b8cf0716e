"""Stop rules as values: where a ray ends. One file per rule, one entry point.

    fixes = eoloc.locate(sensor, pose, AtHeight(1500.0), pixels)

=============  =================================================  =====================
rule           stops the ray                                      method
=============  =================================================  =====================
AtRange        at a measured slant range                          M1 ([S13], [Z15])
FlatGround     on the flat ground through a ranged main target    M2 ([Z15])
AtHeight       on the surface of constant ellipsoidal height      M3 ([Q])
OnDEM          at its first crossing with a DEM                   M4 ([Q])
MultiView      at the intersection of several rays                M8
=============  =================================================  =====================

Each rule states its validity domain in its docstring (docs/uncertainty.md "Validity domains"); outside it
the status says why and the coordinates are NaN. ``locate_range`` & co. are thin wrappers.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from ..errors import InputError
from ..result import Fixes
from ..sensor.model import Pose, SensorModel
from ..terrain.dem import DEM
from .at_height import AtHeight, locate_ellipsoid, stop_at_ellipsoid
from .at_range import AtRange, RangeFromRecords, locate_range, stop_at_range
from .base import StopRule
from .flat import FlatGround, locate_flat
from .multiview import MultiView
from .on_dem import OnDEM, locate_dem, stop_at_dem

RULES: dict[str, type[StopRule]] = {r.name: r for r in (AtRange, AtHeight, OnDEM, FlatGround)}


def locate(sensor: SensorModel, pose: Pose, rule: StopRule, pixels: ArrayLike | None = None) -> Fixes:
    """Pixels (an (..., 2) array or a (u, v) pair; default: the principal point) of ``pose`` to
    the ground by stop ``rule`` -> :class:`eoloc.Fixes` with a status per target."""
    if not isinstance(rule, StopRule):
        raise TypeError(f"rule must be a stop rule (AtRange, AtHeight, OnDEM, FlatGround), got {rule!r}")
    return rule.locate(sensor, pose, pixels)


def surface_rule(surface: float | DEM | StopRule) -> StopRule:
    """The ground of footprints, ground grids and rectification: a DEM (M4), a constant
    ellipsoidal height in metres (M3), or a rule given as it is."""
    if isinstance(surface, StopRule):
        return surface
    if isinstance(surface, DEM):
        return OnDEM(surface)
    return AtHeight(surface)


def rule_from_options(*, range_m: ArrayLike | None = None, height_m: ArrayLike | None = None,
                      dem: DEM | None = None) -> StopRule:
    """The one rule named by keyword (a range, a target height or a DEM); ValueError for none or
    several. The adapter for callers that take the rule as options (config files, the CLI)."""
    given = [(cls, v) for cls, v in ((AtRange, range_m), (AtHeight, height_m), (OnDEM, dem)) if v is not None]
    if len(given) != 1:
        raise InputError("choose one stop rule: a range (range_m), a target height (height_m) or a DEM (dem)")
    cls, value = given[0]
    return cls(value)


__all__ = [
    "RULES",
    "AtHeight",
    "AtRange",
    "FlatGround",
    "MultiView",
    "OnDEM",
    "RangeFromRecords",
    "StopRule",
    "locate",
    "locate_dem",
    "locate_ellipsoid",
    "locate_flat",
    "locate_range",
    "rule_from_options",
    "stop_at_dem",
    "stop_at_ellipsoid",
    "stop_at_range",
    "surface_rule",
]
