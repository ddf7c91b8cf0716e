"""Error budgets as data: each input with its law (normal sigma or uniform +-max) in its own unit,
and how it behaves in time over a pass.

Time matters as soon as fixes are combined (a static target's estimate over many frames, a track):
an error that is the same in every frame does not average down, one that is new in every frame
does. Each source is one of

- ``"bias"``: fixed over a pass (installation and calibration: mounting, boresight, focal length,
  principal point, the gimbal's zero, a time offset, the terrain model's error at one place);
- ``"noise"``: new in every frame (pixel measurement, isolator vibration, laser range noise);
- ``"markov"``: first-order Gauss–Markov, correlated in time with ``tau_s`` (correlation
  exp(-|dt| / tau_s)): the errors of an aided navigation solution (GNSS/INS position and
  attitude), which wander over minutes.

The defaults below (:data:`DEFAULT_KIND`) are what a source usually is when the budget does not
say; they lean to the side that does not average away. Sources: P. D. Groves, *Principles of GNSS,
Inertial, and Multisensor Integrated Navigation Systems* (2nd ed., Artech House, 2013), where
navigation errors are modelled as first-order Gauss–Markov processes with correlation times of
minutes; J. Sun et al. 2013 and Qiao et al. (SPEC's [Z15], [Q]) for the split between fixed
installation errors and per-frame measurement noise. Say what your system does in the config,
e.g. ``yaw_deg = {normal = 0.03, kind = "markov", tau_s = 120}``.
"""

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


KINDS = ("bias", "noise", "markov")
NAV_TAU_S = 300.0  # correlation time of GNSS/INS position and attitude errors (Groves 2013: minutes)

# what each source is when the budget does not say (see the module notes)
DEFAULT_KIND: dict[str, tuple[str, float]] = {
    **{k: ("markov", NAV_TAU_S) for k in ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg")},
    **{k: ("noise", 0.0) for k in ("vibration_yaw_deg", "vibration_pitch_deg", "vibration_roll_deg", "range_m",
                                  "u_px", "v_px")},
    **{k: ("bias", math.inf) for k in ("gimbal1_deg", "gimbal2_deg", "sensor_roll_deg", "gimbal_skew_deg",
                                      "boresight_x_deg", "boresight_y_deg", "mount_x_deg", "mount_y_deg",
                                      "mount_z_deg", "focal_px", "cx_px", "cy_px", "terrain_m", "time_s")},
}


@dataclass(frozen=True)
class ErrorSource:
    """One input's error: ``law`` "normal" (``value`` = sigma) or "uniform" (``value`` = max, so
    the draw is in [-max, +max]), in the source's unit (SOURCES); ``kind`` how it behaves in time
    ("bias", "noise", "markov"; None: the source's default, :data:`DEFAULT_KIND`) and ``tau_s`` the
    Gauss–Markov correlation time (s; "markov" only, None: the default)."""

    name: str
    law: Literal["normal", "uniform"]
    value: float
    kind: Literal["bias", "noise", "markov"] | None = None
    tau_s: float | None = None

    def __post_init__(self) -> None:
        if self.name not in SOURCES:
            raise ValueError(f"unknown error source {self.name!r}; known: {', '.join(SOURCES)}")
        if self.law not in ("normal", "uniform"):
            raise ValueError(f"error source {self.name}: law must be 'normal' or 'uniform', got {self.law!r}")
        if not (math.isfinite(self.value) and self.value >= 0):
            raise ValueError(f"error source {self.name}: value must be a finite number >= 0, got {self.value!r}")
        kind, tau = DEFAULT_KIND[self.name]
        if self.kind is None:
            object.__setattr__(self, "kind", kind)
        elif self.kind not in KINDS:
            raise ValueError(f"error source {self.name}: kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.kind == "markov":
            t = (tau if kind == "markov" else NAV_TAU_S) if self.tau_s is None else self.tau_s
            if not (isinstance(t, (int, float)) and math.isfinite(t) and t > 0):
                raise ValueError(f"error source {self.name}: tau_s (the Gauss–Markov correlation time) must be a "
                                 f"number of seconds > 0, got {self.tau_s!r}")
            object.__setattr__(self, "tau_s", float(t))
        else:
            own = 0.0 if self.kind == "noise" else math.inf  # what the kind means: no memory, or for ever
            if self.tau_s is not None and self.tau_s != own:
                raise ValueError(f"error source {self.name}: tau_s applies to kind = 'markov' only, not {self.kind!r}")
            object.__setattr__(self, "tau_s", own)

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
        when = f"Gauss–Markov τ {self.tau_s:g} s" if self.kind == "markov" else self.kind
        return f"{'σ' if self.law == 'normal' else '±'}{self.value:g} {self.unit} ({when})"


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

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(s.kind for s in self.sources)

    @property
    def tau_s(self) -> np.ndarray:
        """(S,) each source's correlation time: 0 noise, inf bias, tau_s Gauss–Markov."""
        return np.array([s.tau_s for s in self.sources], dtype=np.float64)

    def of_kind(self, *kinds: str) -> ErrorBudget:
        """The budget with the sources of these kinds only."""
        return ErrorBudget(tuple(s for s in self.sources if s.kind in kinds))

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Mapping[str, float | str]]) -> ErrorBudget:
        """From {"yaw_deg": {"normal": 0.02, "kind": "markov", "tau_s": 120},
        "gimbal1_deg": {"uniform": 0.0015}, ...} (kind and tau_s optional)."""
        out = []
        for name, spec in raw.items():
            law = {k: v for k, v in spec.items() if k not in ("kind", "tau_s")} if isinstance(spec, Mapping) else spec
            if not isinstance(spec, Mapping) or len(law) != 1:
                raise ValueError(f"error source {name}: give exactly one law, e.g. {{normal = 0.02}} or "
                                 f"{{uniform = 0.0015}} (and optionally kind = \"bias\"|\"noise\"|\"markov\", "
                                 f"tau_s = seconds), got {spec!r}")
            (kind, value), = law.items()
            if isinstance(value, str) or isinstance(spec.get("tau_s"), str):
                raise ValueError(f"error source {name}: the law's value and tau_s are numbers, got {spec!r}")
            tau = spec.get("tau_s")
            out.append(ErrorSource(name, kind, float(value), spec.get("kind"), None if tau is None else float(tau)))
        return cls(tuple(out))
