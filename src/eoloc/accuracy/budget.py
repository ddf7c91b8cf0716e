"""Error budgets as data: each input with its law (normal sigma or uniform +-max) in its own unit."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

# name -> (unit, what it perturbs). The names are the keys of [accuracy.budget] in the config.
SOURCES: dict[str, tuple[str, str]] = {
    "lat_deg": ("deg", "aircraft latitude"),
    "lon_deg": ("deg", "aircraft longitude"),
    "h_m": ("m", "aircraft ellipsoidal height"),
    "yaw_deg": ("deg", "aircraft yaw (heading)"),
    "pitch_deg": ("deg", "aircraft pitch"),
    "roll_deg": ("deg", "aircraft roll"),
    "vibration_yaw_deg": ("deg", "isolator angular vibration about yaw"),
    "vibration_pitch_deg": ("deg", "isolator angular vibration about pitch"),
    "vibration_roll_deg": ("deg", "isolator angular vibration about roll"),
    "gimbal1_deg": ("deg", "first gimbal angle (azimuth / frame roll)"),
    "gimbal2_deg": ("deg", "second gimbal angle (elevation / frame pitch)"),
    "sensor_roll_deg": ("deg", "sensor roll about the boresight"),
    "gimbal_skew_deg": ("deg", "gimbal axes non-orthogonality"),
    "boresight_x_deg": ("deg", "boresight collimation about camera x"),
    "boresight_y_deg": ("deg", "boresight collimation about camera y"),
    "mount_x_deg": ("deg", "installation misalignment about body x"),
    "mount_y_deg": ("deg", "installation misalignment about body y"),
    "mount_z_deg": ("deg", "installation misalignment about body z"),
    "range_m": ("m", "laser slant range"),
    "u_px": ("px", "target pixel column"),
    "v_px": ("px", "target pixel row"),
    "focal_px": ("px", "focal length"),
    "cx_px": ("px", "principal point column"),
    "cy_px": ("px", "principal point row"),
    "terrain_m": ("m", "terrain height (the stop height, or a vertical shift of the DEM)"),
    "time_s": ("s", "video-telemetry time offset (moves the aircraft by velocity x dt)"),
}


@dataclass(frozen=True)
class ErrorSource:
    """One input's error: ``law`` "normal" (``value`` = sigma) or "uniform" (``value`` = max, so
    the draw is in [-max, +max]), in the source's unit (SOURCES)."""

    name: str
    law: Literal["normal", "uniform"]
    value: float

    def __post_init__(self) -> None:
        if self.name not in SOURCES:
            raise ValueError(f"unknown error source {self.name!r}; known: {', '.join(SOURCES)}")
        if self.law not in ("normal", "uniform"):
            raise ValueError(f"error source {self.name}: law must be 'normal' or 'uniform', got {self.law!r}")
        if not (math.isfinite(self.value) and self.value >= 0):
            raise ValueError(f"error source {self.name}: value must be a finite number >= 0, got {self.value!r}")

    @property
    def unit(self) -> str:
        return SOURCES[self.name][0]

    @property
    def sigma(self) -> float:
        """Standard deviation of the law (uniform +-max: max / sqrt 3)."""
        return self.value if self.law == "normal" else self.value / math.sqrt(3.0)

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n draws of the law, in the source's unit. The same numbers as ``rng.normal(0, sigma, n)``
        or ``rng.uniform(-max, max, n)`` (which compute sigma z and -max + 2 max u), scaled in place
        instead of through temporaries: a fifth faster, and a Monte Carlo draws millions."""
        out = np.empty(n)
        if self.law == "normal":
            rng.standard_normal(out=out)
            out *= self.value
        else:
            rng.random(out=out)
            out *= 2.0 * self.value
            out -= self.value
        return out

    def describe(self) -> str:
        return f"{'σ' if self.law == 'normal' else '±'}{self.value:g} {self.unit}"


@dataclass(frozen=True)
class ErrorBudget:
    """The error sources of a scenario, in a fixed order (the order of draws from the generator)."""

    sources: tuple[ErrorSource, ...]

    def __post_init__(self) -> None:
        names = [s.name for s in self.sources]
        if len(set(names)) != len(names):
            raise ValueError(f"error budget lists a source twice: {names}")

    def __iter__(self):
        return iter(self.sources)

    def __len__(self) -> int:
        return len(self.sources)

    def only(self, name: str) -> ErrorBudget:
        """The budget with source ``name`` alone (sensitivity analysis)."""
        return ErrorBudget(tuple(s for s in self.sources if s.name == name))

    def draw(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        return {s.name: s.draw(rng, n) for s in self.sources}

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Mapping[str, float]]) -> ErrorBudget:
        """From {"yaw_deg": {"normal": 0.02}, "gimbal1_deg": {"uniform": 0.0015}, ...}."""
        out = []
        for name, law in raw.items():
            if not isinstance(law, Mapping) or len(law) != 1:
                raise ValueError(f"error source {name}: give exactly one law, e.g. {{normal = 0.02}} or "
                                 f"{{uniform = 0.0015}}, got {law!r}")
            (kind, value), = law.items()
            out.append(ErrorSource(name, kind, float(value)))
        return cls(tuple(out))
