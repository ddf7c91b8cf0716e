"""Drone heights: which tag to trust, and the check that names a suspect one.

Small drones give their height two ways: above the take-off point (barometric: DJI ``rel_alt``,
``BAROMETER``, ``H``; Airdata ``height_above_takeoff``), good to a metre or two over a flight, and
an "absolute" altitude (DJI ``abs_alt`` / ``altitude``; Airdata ``altitude_above_seaLevel``),
nominally above mean sea level but barometric on many models and tens of metres off (the DJI
Avata 360 and Mini 5 Pro clips in our tests say -123 m over ground at 0 m). eoloc's rule:

1. with a DEM and the take-off point known: the DEM's ground there (ellipsoidal) + the height above
   take-off; the absolute altitude, when also given, is compared and named when it disagrees;
2. else the absolute altitude, taken as above the EGM96 geoid, converted to ellipsoidal, with a
   note that it is the drone's own estimate;
3. else no height: every record is named as unlocatable with the fix (give a DEM).

With a DEM, a camera below the ground under it names the tag the height came from.
"""

from __future__ import annotations

import numpy as np

from ..table import Issue

DISAGREE_M = 20.0  # absolute and take-off-referenced heights further apart: the absolute tag is named
BELOW_GROUND_M = 2.0  # a camera this far under the DEM's ground: the height tag is suspect


def resolve_heights(path: str, line: np.ndarray, lat: np.ndarray, lon: np.ndarray, *, h_msl: np.ndarray | None,
                    h_rel: np.ndarray | None, takeoff: tuple[float, float] | None, msl_tag: str, rel_tag: str,
                    takeoff_how: str, geoid=None, dem=None) -> tuple[np.ndarray, list[Issue], str]:
    """(h_m ellipsoidal per record, the issues, how the heights were made) by the module's rule."""
    from ...terrain.geoid import default_geoid

    n = lat.size
    first = int(line[0]) if n else 0
    issues: list[Issue] = []
    h = np.full(n, np.nan)
    how = ""
    geoid = geoid or default_geoid()
    h_abs = None
    if h_msl is not None and np.isfinite(h_msl).any():
        h_abs = h_msl + geoid.undulation(lat, lon)
    ground0 = np.nan
    if dem is not None and h_rel is not None and takeoff is not None and np.isfinite(h_rel).any():
        ground0 = float(dem.height(takeoff[0], takeoff[1]))
        if not np.isfinite(ground0):
            issues.append(Issue(path, first, f"the take-off point ({takeoff[0]:.6f}, {takeoff[1]:.6f}; {takeoff_how}) "
                                "is outside the DEM or in a void: heights above take-off cannot be placed"))
    if np.isfinite(ground0):
        h = ground0 + h_rel
        how = (f"{rel_tag} above the take-off point + the DEM's ground there ({ground0:.1f} m ellipsoidal; "
               f"take-off at {takeoff[0]:.6f}, {takeoff[1]:.6f}: {takeoff_how})")
        if h_abs is not None:
            with np.errstate(invalid="ignore"):
                gap = float(np.nanmedian(h_abs - h))
            if abs(gap) > DISAGREE_M:
                issues.append(Issue(path, first, f"{msl_tag} (taken as above mean sea level) is {gap:+.0f} m off "
                                    f"the DEM's take-off ground + {rel_tag}: not used (the drone's absolute "
                                    "altitude is barometric and often this far off)"))
    elif h_abs is not None:
        h = h_abs
        how = (f"{msl_tag} taken as above mean sea level (EGM96) and converted to ellipsoidal: the drone's own "
               f"estimate, often tens of metres off; give --dem for heights from the take-off ground + {rel_tag}")
    else:
        what = (f"only {rel_tag} (above the take-off point)" if h_rel is not None and np.isfinite(h_rel).any()
                else "no height at all")
        fix = ("give --dem FILE: the take-off point's ground height then places them" if h_rel is not None
               and takeoff is not None else "give the heights another way (a flight log, or an eoloc telemetry CSV)")
        issues.append(Issue(path, first, f"{what}: no record can be placed in height; {fix}"))
        how = "none"
    issues += below_ground(path, line, lat, lon, h, dem, how.split(" ")[0])
    return h, issues, how


def below_ground(path: str, line: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray, dem,
                 tag: str) -> list[Issue]:
    """With a DEM: the records whose camera is under the ground below it set to NaN height (in
    place), and one issue naming the height's tag and the count."""
    if dem is None or not lat.size:
        return []
    ground = dem.height(lat, lon)
    with np.errstate(invalid="ignore"):
        under = np.flatnonzero(h < ground - BELOW_GROUND_M)
    if not under.size:
        return []
    k = under[0]
    issue = Issue(path, int(line[k]), f"the camera would be {ground[k] - h[k]:.1f} m under the ground here and on "
                  f"{under.size - 1} more record(s): the height ({tag}) is suspect; those records are not located")
    h[under] = np.nan
    return [issue]
