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

from typing import TYPE_CHECKING

from ..util.lazy import lazy_attributes
from .spec import SPECS, RuleSpec, rule_from_values

if TYPE_CHECKING:  # the same names as _WHERE, for type checkers and the API reference (read statically)
    from .at_height import AtHeight, locate_ellipsoid, stop_at_ellipsoid
    from .at_range import AtRange, RangeFromRecords, locate_range, stop_at_range
    from .base import StopRule, locate
    from .flat import FlatGround, locate_flat
    from .multiview import MultiView
    from .on_dem import OnDEM, locate_dem, stop_at_dem

_WHERE = {  # loaded on first use: reading the specs (the command line does, at start-up) loads no rule
    **dict.fromkeys(("AtHeight", "locate_ellipsoid", "stop_at_ellipsoid"), "at_height"),
    **dict.fromkeys(("AtRange", "RangeFromRecords", "locate_range", "stop_at_range"), "at_range"),
    **dict.fromkeys(("FlatGround", "locate_flat"), "flat"),
    **dict.fromkeys(("OnDEM", "locate_dem", "stop_at_dem"), "on_dem"),
    "MultiView": "multiview",
    **dict.fromkeys(("StopRule", "locate"), "base"),
}

__getattr__ = lazy_attributes(__name__, _WHERE)


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "SPECS",
    "AtHeight",
    "AtRange",
    "FlatGround",
    "MultiView",
    "OnDEM",
    "RangeFromRecords",
    "RuleSpec",
    "StopRule",
    "locate",
    "locate_dem",
    "locate_ellipsoid",
    "locate_flat",
    "locate_range",
    "rule_from_values",
    "stop_at_dem",
    "stop_at_ellipsoid",
    "stop_at_range",
]
