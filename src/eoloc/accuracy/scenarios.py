"""Built-in scenarios from the sources (SPEC §4.1): [S13] Table 1 and [Q] Table 1 (ellipsoid and DEM)."""

from __future__ import annotations

import numpy as np

from ..rules import AtHeight, AtRange, OnDEM
from ..sensor import AzElGimbal, Camera, Pose, RollPitchGimbal, SensorModel
from ..terrain.dem import DEM
from .budget import ErrorBudget, ErrorSource
from .montecarlo import Scenario

Q_TERRAIN_MEAN_M = 5083.0
Q_TERRAIN_SIGMA_M = 62.47
# [Q]'s reported results (Table 3 / text): sigma lat (deg), sigma lon (deg), sigma h (m)
Q_SOURCE_ELLIPSOID = (0.00048, 0.00060, 62.3)
Q_SOURCE_DEM = (0.00015, 0.00013, 3.58)


def s13() -> Scenario:
    """[S13]: aircraft 125E 42N 10 000 m, yaw 10 pitch 5 roll -2, turret az 45 el -75, laser 10 200 m.
    Budget (Table 1): lon/lat normal sigma 0.8e-7 deg; yaw/pitch/roll normal sigma 0.02 deg; gimbal
    azimuth/elevation uniform +-0.0015 deg. The paper used n = 10^6."""
    budget = ErrorBudget((
        ErrorSource("lon_deg", "normal", 0.8e-7), ErrorSource("lat_deg", "normal", 0.8e-7),
        ErrorSource("yaw_deg", "normal", 0.02), ErrorSource("pitch_deg", "normal", 0.02),
        ErrorSource("roll_deg", "normal", 0.02),
        ErrorSource("gimbal1_deg", "uniform", 0.0015), ErrorSource("gimbal2_deg", "uniform", 0.0015),
    ))
    sensor = SensorModel(Camera(1, 1, 1.0, 1.0, 0.0, 0.0), AzElGimbal())
    return Scenario("s13", sensor, Pose(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, (45.0, -75.0)), budget,
                    AtRange(10_200.0), description=s13.__doc__)


def _q_budget(terrain: bool) -> ErrorBudget:
    src = [
        ErrorSource("lat_deg", "normal", 0.0001), ErrorSource("lon_deg", "normal", 0.0001),
        ErrorSource("h_m", "normal", 5.0),
        ErrorSource("yaw_deg", "normal", 0.02), ErrorSource("pitch_deg", "normal", 0.01),
        ErrorSource("roll_deg", "normal", 0.01),
        ErrorSource("gimbal1_deg", "normal", 0.006), ErrorSource("gimbal2_deg", "normal", 0.006),
    ]
    if terrain:
        src.append(ErrorSource("terrain_m", "normal", Q_TERRAIN_SIGMA_M))
    return ErrorBudget(tuple(src))


_Q_POSE = Pose(35.48, 80.97, 18_000.0, 45.0, 3.5, 0.0, (50.0, -2.6))
_Q_SENSOR = SensorModel(Camera.from_hfov(2.0, 1000, 1000), RollPitchGimbal())


def q_ellipsoid() -> Scenario:
    """[Q] Table 1: aircraft 35.48N 80.97E 18 000 m (sigma 1e-4 deg, 1e-4 deg, 5 m), yaw 45 +- 0.02,
    pitch 3.5 +- 0.01, roll 0 +- 0.01; roll-pitch gimbal roll 50 +- 0.006, pitch -2.6 +- 0.006 deg;
    range-free on the ellipsoid at the terrain mean 5 083 m with the relief as a height error
    (sigma 62.47 m). [Q] used n = 5 000; source result sigma 0.00048 deg, 0.00060 deg, 62.3 m."""
    return Scenario("q-ellipsoid", _Q_SENSOR, _Q_POSE, _q_budget(True), AtHeight(Q_TERRAIN_MEAN_M),
                    description=q_ellipsoid.__doc__)


def relief_dem(lat_deg: float, lon_deg: float, mean_m: float, sigma_m: float, *, seed: int = 62,
               half_deg: float = 0.25, step_deg: float = 3.0 / 3600.0, correlation_posts: float = 12.0) -> DEM:
    """A synthetic DEM centred on (lat_deg, lon_deg): smooth random relief (Gaussian-filtered white
    noise, correlation ~``correlation_posts`` posts, ~1 km at 3") rescaled to exactly ``mean_m``
    and ``sigma_m`` (ellipsoidal m) over the grid. The same seed gives the same shape for every
    sigma, so sweeps over the relief compare like with like."""
    from scipy.ndimage import gaussian_filter

    n = round(2 * half_deg / step_deg) + 1
    rng = np.random.default_rng(seed)
    z = gaussian_filter(rng.normal(size=(n, n)), sigma=correlation_posts, mode="wrap")
    z = mean_m + (z - z.mean()) / z.std() * sigma_m
    return DEM.from_array(z[::-1], lat0=lat_deg + half_deg, lon0=lon_deg - half_deg, dlat=-step_deg, dlon=step_deg,
                          source=f"synthetic relief mean {mean_m:g} m sigma {sigma_m:g} m, seed {seed}")


def q_terrain(seed: int = 62) -> DEM:
    """A synthetic DEM around [Q]'s target: relief with mean 5 083 m and sigma 62.47 m (3" posts,
    correlation length ~1 km), seeded (:func:`relief_dem`)."""
    from .montecarlo import truth_fixes

    t = truth_fixes(q_ellipsoid())
    return relief_dem(float(t.lat_deg[0]), float(t.lon_deg[0]), Q_TERRAIN_MEAN_M, Q_TERRAIN_SIGMA_M, seed=seed)


def q_dem(seed: int = 62) -> Scenario:
    """[Q] with a DEM: the same budget without the terrain term, located by M4 on a synthetic
    relief of the same statistics (q_terrain). Source result sigma 0.00015 deg, 0.00013 deg, 3.58 m."""
    return Scenario("q-dem", _Q_SENSOR, _Q_POSE, _q_budget(False), OnDEM(q_terrain(seed)),
                    description=q_dem.__doc__)


SCENARIOS = {"s13": s13, "q-ellipsoid": q_ellipsoid, "q-dem": q_dem}
