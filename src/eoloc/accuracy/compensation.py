"""Learned error prediction and compensation at large oblique angles ([P], SPEC §4.3).

At large oblique angles the systematic errors of the installation (gimbal encoder offsets, mount
and boresight misalignment, heading bias, a telemetry time offset, a DEM datum offset) grow fast:
an elevation error d on the ray moves the ground point by H d sec^2(theta) along the look
direction, an azimuth error by H d tan(theta) across it, a DEM height error dh by dh tan(theta).
[P] reduces the attitude and gimbal factors to a few geometric features and learns the error
vector from calibration flights over surveyed points; new fixes get the predicted error
subtracted.

Features (:func:`error_features`, computed from the same pose chain as the fix):

- ``oblique``: angle between the line of sight and the local vertical (down) at the aircraft, deg;
- ``azimuth``: the line of sight's horizontal direction, clockwise from true north, deg;
- ``height``: the aircraft's ellipsoidal height minus the fix's, m;
- ``bearing`` (optional, not in [P]): azimuth minus the aircraft heading, deg. Errors fixed in the
  aircraft body (mount misalignment, pitch/roll biases) depend on it; [P]'s three features cannot
  tell a forward look from a sideways one at the same azimuth.

Model family (``physical``): the error is predicted in the look frame (along, across the look
direction, and up) as a linear combination of the ground-error shapes above,
``{H sec^2, H sec, H tan, H, tan, 1} x {1, cos az, sin az[, cos brg, sin brg]}``, fitted by ridge
regression with the ridge chosen by cross-validation that holds out whole flights. It is linear
in its coefficients (microseconds per fix), it extrapolates the way the physics does, and it
is stored as plain JSON. :func:`cross_validate` also scores a gradient-boosted tree ensemble on
the same folds (scikit-learn) so the choice is made on numbers, not on faith.

Every prediction is checked against the trained range: a fix whose oblique angle or height lies
outside what was trained, or whose (oblique band, direction sector) cell had too few training
samples, is flagged (``flags`` bitmask, ``reason`` text) and left uncorrected.
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..errors import InputError, ModelFileError
from ..result import Fixes
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel
from .cep import cep_empirical

FORMAT = "eoloc-compensation-model"
VERSION = 1
FEATURE_SETS = {"p": ("oblique", "azimuth", "height"), "p+bearing": ("oblique", "azimuth", "height", "bearing")}
OUTPUTS = ("along", "across", "up")
RADIAL = ("H_sec2", "H_sec", "H_tan", "H", "tan", "one")
RIDGES = (1e-8, 1e-6, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e6)  # 1e6: no correction at all, when nothing generalises
DEFAULT_BANDS = (0.0, 30.0, 45.0, 60.0, 70.0, 90.0)

# per-fix flags (bitmask); a flagged fix is not corrected
OUT_OBLIQUE = 1
OUT_HEIGHT = 2
UNCOVERED_CELL = 4
NOT_LOCATED = 8


@dataclass(frozen=True)
class ErrorFeatures:
    """[P]'s geometric features of fixes (arrays of one shape). Degrees and metres."""

    oblique_deg: np.ndarray
    azimuth_deg: np.ndarray
    height_m: np.ndarray
    bearing_deg: np.ndarray

    def take(self, index) -> ErrorFeatures:
        return ErrorFeatures(*(np.ravel(a)[index] for a in (self.oblique_deg, self.azimuth_deg, self.height_m,
                                                            self.bearing_deg)))

    def columns(self) -> dict[str, np.ndarray]:
        return {"oblique_deg": self.oblique_deg, "azimuth_deg": self.azimuth_deg,
                "height_above_target_m": self.height_m, "bearing_deg": self.bearing_deg}


def error_features(sensor: SensorModel, pose: Pose, fixes: Fixes, pixels=None) -> ErrorFeatures:
    """Features of each fix: the line of sight through its pixel (default: the principal point,
    i.e. the optical axis), in the local NED frame at the aircraft, and the height of the aircraft
    above the fix (NaN where the fix failed)."""
    rays = sensor.rays(pose, pixels)
    shape = np.broadcast_shapes(rays.shape, fixes.shape)
    lat, lon = (np.broadcast_to(x, shape) for x in (pose.lat_deg, pose.lon_deg))
    d_ecef = np.stack(np.broadcast_arrays(rays.dx, rays.dy, rays.dz), -1)
    d_ned = np.einsum("...ji,...j->...i", geodesy.R_ecef_ned(lat, lon), np.broadcast_to(d_ecef, (*shape, 3)))
    oblique = np.degrees(np.arccos(np.clip(d_ned[..., 2], -1.0, 1.0)))
    azimuth = np.degrees(np.arctan2(d_ned[..., 1], d_ned[..., 0])) % 360.0
    height = np.broadcast_to(pose.h_m, shape) - np.broadcast_to(fixes.h_m, shape)
    bearing = (azimuth - np.broadcast_to(pose.yaw_deg, shape)) % 360.0
    return ErrorFeatures(oblique, azimuth, height, bearing)


def error_enu(fixes: Fixes, truth_lat_lon_h: ArrayLike) -> np.ndarray:
    """(..., 3) error of each fix (fix minus truth) in east, north, up metres at the truth
    (:func:`eoloc.accuracy.evaluation.error_enu` of the fixes' positions)."""
    from .evaluation import error_enu as enu_of

    t = np.asarray(truth_lat_lon_h, dtype=np.float64)
    return enu_of(fixes.lat_deg, fixes.lon_deg, fixes.h_m, t[..., 0], t[..., 1], t[..., 2])


@dataclass(frozen=True)
class Observed:
    """Fixes of calibration observations with their features and errors (fix minus truth, ENU m)."""

    fixes: Fixes
    features: ErrorFeatures
    errors_enu: np.ndarray
    groups: np.ndarray


def observation_pose(columns: dict[str, np.ndarray]) -> tuple[Pose, tuple[np.ndarray, np.ndarray]]:
    """The reported pose (fields (N,)) and the pixels (u, v) of calibration observations."""
    c = columns
    g3 = c.get("sensor_roll_deg")
    g3 = np.zeros_like(c["u_px"]) if g3 is None else np.nan_to_num(g3, nan=0.0)
    pose = Pose(c["lat_deg"], c["lon_deg"], c["h_m"], c["yaw_deg"], c["pitch_deg"], c["roll_deg"],
                (c["gimbal1_deg"], c["gimbal2_deg"], g3))
    return pose, (c["u_px"], c["v_px"])


def observation_truth(columns: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 3) surveyed lat, lon, h of each observation's point."""
    return np.stack([columns["gcp_lat_deg"], columns["gcp_lon_deg"], columns["gcp_h_m"]], -1)


def observation_rule(columns: dict[str, np.ndarray], rule: StopRule | None = None) -> StopRule:
    """The stop rule observations are located with: ``rule`` as given (the one used in operation),
    or None: each point's own surveyed height (M3)."""
    from ..rules import AtHeight

    return AtHeight(columns["gcp_h_m"]) if rule is None else rule


def locate_observations(sensor: SensorModel, columns: dict[str, np.ndarray], rule: StopRule | None = None) -> Observed:
    """Locate every calibration observation (columns of the observations CSV: pose, pixel,
    gcp_lat/lon/h) with stop ``rule`` (the one used in operation, e.g. ``OnDEM(dem)``), or None:
    each GCP's own surveyed height (M3), which isolates the angular errors."""
    c = columns
    pose, uv = observation_pose(c)
    fixes = observation_rule(c, rule).locate(sensor, pose, uv)
    truth = observation_truth(c)
    groups = c.get("flight", np.full(c["u_px"].shape, "all", dtype=object))
    return Observed(fixes, error_features(sensor, pose, fixes, uv), error_enu(fixes, truth), np.asarray(groups))


# -- the physical basis ------------------------------------------------------------------------


def _design(f: ErrorFeatures, bearing: bool) -> np.ndarray:
    """(N, n_basis) design matrix of the look-frame error shapes."""
    th = np.radians(np.ravel(f.oblique_deg))
    H = np.ravel(f.height_m) / 1000.0  # km keeps the columns of comparable size
    sec = 1.0 / np.cos(th)
    tan = np.tan(th)
    radial = (H * sec * sec, H * sec, H * tan, H, tan, np.ones_like(th))
    az = np.radians(np.ravel(f.azimuth_deg))
    angular = [np.ones_like(az), np.cos(az), np.sin(az)]
    if bearing:
        b = np.radians(np.ravel(f.bearing_deg))
        angular += [np.cos(b), np.sin(b)]
    return np.stack([r * a for r in radial for a in angular], -1)


def _to_look(e_enu: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    az = np.radians(azimuth_deg)
    s, c = np.sin(az), np.cos(az)
    return np.stack([e_enu[..., 0] * s + e_enu[..., 1] * c, e_enu[..., 0] * c - e_enu[..., 1] * s, e_enu[..., 2]], -1)


def _from_look(e_look: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    az = np.radians(azimuth_deg)
    s, c = np.sin(az), np.cos(az)
    a, x = e_look[..., 0], e_look[..., 1]
    return np.stack([a * s + x * c, a * c - x * s, e_look[..., 2]], -1)


def _ridge(X: np.ndarray, Y: np.ndarray, lam: float) -> np.ndarray:
    """Ridge coefficients (n_basis, n_out) on standardised columns, mapped back to raw columns."""
    scale = np.sqrt(np.mean(X**2, axis=0))
    scale[scale == 0] = 1.0
    Xs = X / scale
    A = Xs.T @ Xs + lam * X.shape[0] * np.eye(X.shape[1])
    return np.linalg.solve(A, Xs.T @ Y) / scale[:, None]


@dataclass(frozen=True)
class Prediction:
    """Predicted corrections (east, north, up m; minus the predicted error) and per-fix flags."""

    correction_enu: np.ndarray
    flags: np.ndarray

    @property
    def applied(self) -> np.ndarray:
        return self.flags == 0

    def reasons(self, f: ErrorFeatures, model: CompensationModel) -> list[str]:
        """Why each fix was left uncorrected ('' where it was corrected)."""
        out = []
        ob, h = np.ravel(f.oblique_deg), np.ravel(f.height_m)
        for i, fl in enumerate(np.ravel(self.flags)):
            why = []
            if fl & NOT_LOCATED:
                why.append("no fix")
            if fl & OUT_OBLIQUE:
                why.append(f"oblique {ob[i]:.1f}° outside the trained {model.oblique_range[0]:.1f}–"
                           f"{model.oblique_range[1]:.1f}°")
            if fl & OUT_HEIGHT:
                why.append(f"height {h[i]:.0f} m outside the trained {model.height_range[0]:.0f}–"
                           f"{model.height_range[1]:.0f} m")
            if fl & UNCOVERED_CELL:
                why.append("too few training samples at this oblique angle and direction")
            out.append("; ".join(why))
        return out


@dataclass(frozen=True)
class CompensationModel:
    """A fitted error model. ``coef`` (n_basis, n_outputs) maps the basis to along/across[/up]
    errors (m); ``coverage`` counts training samples per (oblique band, direction sector)."""

    features: tuple[str, ...]
    outputs: tuple[str, ...]
    coef: np.ndarray
    ridge: float
    oblique_range: tuple[float, float]
    height_range: tuple[float, float]
    oblique_edges: tuple[float, ...]
    sector_deg: float
    coverage: np.ndarray
    min_cell: int = 5
    info: dict = field(default_factory=dict)

    @property
    def bearing(self) -> bool:
        return "bearing" in self.features

    @property
    def direction_feature(self) -> str:
        return "bearing" if self.bearing else "azimuth"

    def _cells(self, f: ErrorFeatures) -> tuple[np.ndarray, np.ndarray]:
        return _cells(f, self.bearing, self.oblique_edges, self.sector_deg)

    def flags(self, f: ErrorFeatures) -> np.ndarray:
        """Per-fix flag bitmask (0: inside the trained range, corrected)."""
        ob, h = np.ravel(f.oblique_deg), np.ravel(f.height_m)
        fl = np.zeros(ob.shape, dtype=np.int8)
        bad = ~(np.isfinite(ob) & np.isfinite(h) & np.isfinite(np.ravel(f.azimuth_deg)))
        with np.errstate(invalid="ignore"):
            fl |= np.where(bad, NOT_LOCATED, 0).astype(np.int8)
            fl |= np.where(~bad & ((ob < self.oblique_range[0]) | (ob > self.oblique_range[1])), OUT_OBLIQUE,
                           0).astype(np.int8)
            fl |= np.where(~bad & ((h < self.height_range[0]) | (h > self.height_range[1])), OUT_HEIGHT,
                           0).astype(np.int8)
        i, j = self._cells(f)
        fl |= np.where(~bad & (self.coverage[i, j] < self.min_cell), UNCOVERED_CELL, 0).astype(np.int8)
        return fl.reshape(np.shape(f.oblique_deg))

    def predict_error(self, f: ErrorFeatures) -> np.ndarray:
        """(..., 3) predicted error (east, north, up m) of fixes with features ``f``; up is 0 for a
        model without the up output. No range check: see :meth:`predict`."""
        X = _design(f, self.bearing)
        look = np.zeros((X.shape[0], 3))
        with np.errstate(invalid="ignore"):
            look[:, : self.coef.shape[1]] = X @ self.coef
        return _from_look(look, np.ravel(f.azimuth_deg)).reshape((*np.shape(f.oblique_deg), 3))

    def predict(self, f: ErrorFeatures) -> Prediction:
        """Corrections (minus the predicted error) where the fix is inside the trained range, zero
        (and flagged) elsewhere."""
        fl = self.flags(f)
        corr = -self.predict_error(f)
        corr = np.where((fl == 0)[..., None], corr, 0.0)
        return Prediction(corr, fl)

    # -- persistence ----------------------------------------------------------------------------

    def to_dict(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "family": "physical", "features": list(self.features),
                "outputs": list(self.outputs), "basis": {"radial": list(RADIAL), "height_unit": "km"},
                "coef": self.coef.tolist(), "ridge": self.ridge, "oblique_range_deg": list(self.oblique_range),
                "height_range_m": list(self.height_range), "oblique_edges_deg": list(self.oblique_edges),
                "sector_deg": self.sector_deg, "coverage": self.coverage.astype(int).tolist(),
                "min_cell": self.min_cell, "info": self.info}

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1), encoding="utf-8")
        return path

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "model", features: tuple[str, ...] | None = None) -> CompensationModel:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ModelFileError(f"{source}: not an eoloc compensation model (format {d.get('format')!r} where "
                                 f"{FORMAT!r} was expected); make one with `eoloc compensate train`")
        if d.get("version") != VERSION:
            raise ModelFileError(f"{source}: model file version {d.get('version')!r}, this eoloc reads version "
                                 f"{VERSION}; retrain it with this eoloc (`eoloc compensate train`)")
        feats = tuple(d.get("features", ()))
        if feats not in FEATURE_SETS.values():
            raise ModelFileError(f"{source}: unknown feature set {list(feats)}; known: "
                                 f"{[list(v) for v in FEATURE_SETS.values()]}")
        if features is not None and tuple(features) != feats:
            raise ModelFileError(f"{source}: the model was trained on features {list(feats)} but "
                                 f"{list(features)} were asked for; retrain with --features or use another model")
        n_basis = len(RADIAL) * (5 if "bearing" in feats else 3)
        coef = np.asarray(d.get("coef"), dtype=np.float64)
        outputs = tuple(d.get("outputs", ()))
        if coef.shape != (n_basis, len(outputs)) or outputs not in (OUTPUTS[:2], OUTPUTS):
            raise ModelFileError(f"{source}: coefficients of shape {coef.shape} for outputs {list(outputs)} do not "
                                 f"fit the basis of features {list(feats)} ({n_basis} terms); the file is damaged")
        return cls(feats, outputs, coef, float(d["ridge"]), tuple(d["oblique_range_deg"]), tuple(d["height_range_m"]),
                   tuple(d["oblique_edges_deg"]), float(d["sector_deg"]), np.asarray(d["coverage"], dtype=np.int64),
                   int(d.get("min_cell", 5)), dict(d.get("info", {})))

    @classmethod
    def load(cls, path: str | Path, *, features: tuple[str, ...] | None = None) -> CompensationModel:
        """Read a model file; ``features``: the feature set the caller expects (checked)."""
        path = Path(path)
        try:
            d = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ModelFileError(f"{path}: no such model file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ModelFileError(f"{path}: not a JSON model file ({exc})") from None
        try:
            return cls.from_dict(d, source=str(path), features=features)
        except (KeyError, TypeError) as exc:
            raise ModelFileError(f"{path}: model file lacks or mangles {exc}; retrain it") from None


def compensate(model: CompensationModel, sensor: SensorModel, pose: Pose, fixes: Fixes, pixels=None, *,
               rule: StopRule | None = None) -> tuple[Fixes, dict[str, np.ndarray]]:
    """Apply ``model`` to ``fixes`` (of ``pixels`` seen from ``pose``): -> (corrected fixes, per-fix
    columns: the features, the correction east/north/up (m), whether it was applied, why not, and
    the uncorrected position). Flagged fixes keep their uncorrected position. Where the stop
    ``rule`` has a terrain map (a DEM) the corrected point is put back on it."""
    flat = fixes.flat()
    f = error_features(sensor, pose, fixes, pixels).take(slice(None))
    pred = model.predict(f)
    corr = pred.correction_enu.reshape(-1, 3)
    p = flat.p_ecef() + np.einsum("nij,nj->ni", geodesy.R_ecef_enu(flat.lat_deg, flat.lon_deg), corr)
    lat, lon, h = geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    applied = pred.applied.ravel()
    terrain = None if rule is None or not applied.any() else rule.terrain_height(lat, lon)
    if terrain is not None:
        h = np.where(applied, terrain, h)
    out = Fixes(*(np.where(applied, new, old).reshape(fixes.shape) for new, old in
                  ((lat, flat.lat_deg), (lon, flat.lon_deg), (h, flat.h_m))), np.reshape(flat.range_m, fixes.shape),
                np.reshape(flat.status, fixes.shape))
    cols = {**f.columns(), "comp_e_m": np.where(applied, corr[:, 0], np.nan),
            "comp_n_m": np.where(applied, corr[:, 1], np.nan), "comp_u_m": np.where(applied, corr[:, 2], np.nan),
            "comp_applied": applied, "comp_flag": np.array(pred.reasons(f, model), dtype=object),
            "raw_lat_deg": flat.lat_deg, "raw_lon_deg": flat.lon_deg, "raw_h_m": flat.h_m}
    return out, cols


# -- training -----------------------------------------------------------------------------------


def _cells(f: ErrorFeatures, bearing: bool, edges, sector_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(oblique band, direction sector) of each fix; the direction is the bearing when the model
    uses it (the errors it learns turn with the airframe), else the azimuth."""
    ob = np.ravel(f.oblique_deg)
    d = np.ravel(f.bearing_deg if bearing else f.azimuth_deg)
    i = oblique_band(ob, edges)
    j = np.clip((np.nan_to_num(d) // sector_deg).astype(int), 0, round(360.0 / sector_deg) - 1)
    return i, j


def _valid(f: ErrorFeatures, e: np.ndarray) -> np.ndarray:
    cols = (f.oblique_deg, f.azimuth_deg, f.height_m, e[..., 0], e[..., 1], e[..., 2])
    return np.all([np.isfinite(np.ravel(c)) for c in cols], axis=0)


def fit(features: ErrorFeatures, errors_enu: ArrayLike, *, feature_set: str = "p+bearing", up: bool = False,
        ridge: float | None = None, groups: ArrayLike | None = None, oblique_edges=DEFAULT_BANDS,
        sector_deg: float = 30.0, min_cell: int = 5, info: dict | None = None) -> CompensationModel:
    """Fit the physical model to N training fixes: ``features`` (N,) and ``errors_enu`` (N, 3)
    (fix minus truth). ``ridge`` None: chosen from :data:`RIDGES` by cross-validation over
    ``groups`` (flight ids; whole flights held out), else by 5 interleaved folds."""
    if feature_set not in FEATURE_SETS:
        raise ValueError(f"feature_set {feature_set!r}: choose from {sorted(FEATURE_SETS)}")
    feats = FEATURE_SETS[feature_set]
    e = np.asarray(errors_enu, dtype=np.float64).reshape(-1, 3)
    f = features.take(slice(None))
    ok = _valid(f, e)
    if ok.sum() < 20:
        raise InputError(f"{int(ok.sum())} usable training fixes: at least 20 are needed (more than 100 spread "
                         "over heights, oblique angles and directions to be useful)")
    f, e = f.take(ok), e[ok]
    g = None if groups is None else np.asarray(groups)[ok]
    bearing = "bearing" in feats
    X = _design(f, bearing)
    Y = _to_look(e, f.azimuth_deg)[:, : (3 if up else 2)]
    if ridge is None:
        # the best held-out score, unless no correction at all (the last ridge) is within one
        # standard error of it: when the flights share nothing, correct nothing
        folds = _folds(g, X.shape[0])
        scores = np.array([[np.mean((Y[t] - X[t] @ _ridge(X[~t], Y[~t], lam))[:, :2] ** 2) for t in folds]
                           for lam in RIDGES])
        mean = scores.mean(1)
        best = int(np.argmin(mean))
        se = scores[best].std(ddof=1) / np.sqrt(len(folds)) if len(folds) > 1 else 0.0
        ridge = RIDGES[-1] if mean[-1] <= mean[best] + se else RIDGES[best]
    coef = _ridge(X, Y, ridge)
    edges = tuple(float(x) for x in oblique_edges)
    i, j = _cells(f, bearing, edges, sector_deg)
    cov = np.zeros((len(edges) - 1, round(360.0 / sector_deg)), dtype=np.int64)
    np.add.at(cov, (i, j), 1)
    lo = float(f.oblique_deg.min())
    lo = 0.0 if lo < 2.0 else lo  # trained down to near nadir: nadir itself is inside
    meta = {"trained": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"), "n_samples": int(X.shape[0]),
            "n_flights": None if g is None else len(np.unique(g)), **(info or {})}
    return CompensationModel(feats, OUTPUTS[: Y.shape[1]], coef, float(ridge),
                             (lo, float(f.oblique_deg.max())),
                             (float(f.height_m.min()), float(f.height_m.max())), edges, float(sector_deg), cov,
                             int(min_cell), meta)


def oblique_band(oblique_deg: ArrayLike, edges=DEFAULT_BANDS) -> np.ndarray:
    """The index of each oblique angle's band between ``edges`` (degrees)."""
    return np.clip(np.searchsorted(edges, oblique_deg, side="right") - 1, 0, len(edges) - 2)


def _folds(groups: np.ndarray | None, n: int, k: int = 5) -> list[np.ndarray]:
    """Boolean test masks: whole groups held out (up to k folds), else interleaved rows."""
    if groups is None or len(np.unique(groups)) < 2:
        idx = np.arange(n) % k
        return [idx == i for i in range(k)]
    u = np.unique(groups)
    fold_of = {gid: i % min(k, u.size) for i, gid in enumerate(u)}
    lab = np.array([fold_of[x] for x in groups])
    return [lab == i for i in range(min(k, u.size))]


def select_bins(features: ErrorFeatures, *, height_edges: ArrayLike, oblique_edges: ArrayLike = DEFAULT_BANDS,
                sector_deg: float = 30.0, per_cell: int = 20, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """[P]'s sample selection: at most ``per_cell`` fixes (at random) from every cell of height x
    oblique band x azimuth sector. -> (indices chosen, counts per cell (H, O, S) before selection)."""
    h = np.ravel(features.height_m)
    ob = np.ravel(features.oblique_deg)
    az = np.ravel(features.azimuth_deg)
    he, oe = np.asarray(height_edges, float), np.asarray(oblique_edges, float)
    n_s = round(360.0 / sector_deg)
    i = np.searchsorted(he, h, side="right") - 1
    j = np.searchsorted(oe, ob, side="right") - 1
    k = np.clip((np.nan_to_num(az) // sector_deg).astype(int), 0, n_s - 1)
    inside = (i >= 0) & (i < he.size - 1) & (j >= 0) & (j < oe.size - 1) & np.isfinite(h + ob + az)
    cell = np.where(inside, (i * (oe.size - 1) + j) * n_s + k, -1)
    counts = np.bincount(cell[inside], minlength=(he.size - 1) * (oe.size - 1) * n_s)
    rng = np.random.default_rng(seed)
    chosen = []
    for c in np.unique(cell[inside]):
        members = np.flatnonzero(cell == c)
        chosen.append(rng.choice(members, size=min(per_cell, members.size), replace=False))
    idx = np.sort(np.concatenate(chosen)) if chosen else np.zeros(0, int)
    return idx, counts.reshape(he.size - 1, oe.size - 1, n_s)


# -- evaluation ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class BandRow:
    """CEP50 (m) of the horizontal errors of the fixes in one oblique band, before and after."""

    lo_deg: float
    hi_deg: float
    n: int
    cep_before_m: float
    cep_after_m: dict[str, float]
    summary: bool = False  # the '> 60°' row spanning several bands

    def reduction(self, family: str) -> float:
        """Fractional CEP reduction (0.6 = 60 % smaller); negative when compensation hurts."""
        return 1.0 - self.cep_after_m[family] / self.cep_before_m


def band_table(oblique_deg: ArrayLike, before_en: ArrayLike, after_en: dict[str, ArrayLike],
               edges=DEFAULT_BANDS) -> list[BandRow]:
    """CEP50 by oblique band (plus a '> 60°' row when the edges allow) before and after."""
    ob = np.ravel(oblique_deg)
    b = np.asarray(before_en).reshape(-1, 2)
    rows = []
    spans = [(edges[i], edges[i + 1]) for i in range(len(edges) - 1)]
    n_bands = len(spans)
    if 60.0 in edges and edges[-1] > 60.0 and (60.0, edges[-1]) not in spans:
        spans.append((60.0, edges[-1]))
    for k, (lo, hi) in enumerate(spans):
        m = (ob >= lo) & (ob < hi) & np.isfinite(b).all(-1)
        if not m.any():
            continue
        after = {k: cep_empirical(*np.asarray(v).reshape(-1, 2)[m].T) for k, v in after_en.items()}
        rows.append(BandRow(float(lo), float(hi), int(m.sum()), cep_empirical(*b[m].T), after, k >= n_bands))
    return rows


@dataclass(frozen=True)
class CrossValidation:
    """Held-out errors (N, 2 east/north) of each family, the fold of every fix and how folds were made."""

    oblique_deg: np.ndarray
    before_en: np.ndarray
    after_en: dict[str, np.ndarray]
    by: str
    n_folds: int

    def table(self, edges=DEFAULT_BANDS) -> list[BandRow]:
        return band_table(self.oblique_deg, self.before_en, self.after_en, edges)


def cross_validate(features: ErrorFeatures, errors_enu: ArrayLike, groups: ArrayLike | None = None, *,
                   by: str = "flight", feature_sets=("p", "p+bearing"), trees: bool = True,
                   oblique_edges=DEFAULT_BANDS, seed: int = 0) -> CrossValidation:
    """Held-out CEP of each model family. ``by="flight"``: whole flights held out (needs
    ``groups``); ``by="band"``: each oblique band held out in turn (the model must extrapolate to
    angles it has not seen). Families: the physical model on each feature set (keyed by the
    set's name) and, with ``trees``, a scikit-learn gradient-boosted ensemble on the same inputs
    as ``p+bearing`` (keyed ``trees``)."""
    e = np.asarray(errors_enu, dtype=np.float64).reshape(-1, 3)
    f = features.take(slice(None))
    ok = _valid(f, e)
    f, e = f.take(ok), e[ok]
    ob = f.oblique_deg
    if by == "flight":
        if groups is None:
            raise ValueError("cross-validation by flight needs the flight of every fix (groups)")
        g = np.asarray(groups)[ok]
        folds = _folds(g, e.shape[0])
    elif by == "band":
        g = None
        bands = oblique_band(ob, oblique_edges)
        folds = [bands == b for b in np.unique(bands)]
    else:
        raise ValueError(f"by={by!r}: use 'flight' or 'band'")
    short = [int((~t).sum()) for t in folds if (~t).sum() < 20]
    if short:
        what = (f"holds out each oblique band in turn, but the {e.shape[0]} fixes lie in "
                f"{'one band' if len(folds) == 1 else f'{len(folds)} bands'} "
                f"(oblique {np.min(ob):.1f}–{np.max(ob):.1f}°, "
                f"band edges {', '.join(f'{x:g}' for x in oblique_edges)})" if by == "band" else
                f"holds out whole flights, but the {e.shape[0]} fixes come from {len(np.unique(g))} flight(s)")
        raise InputError(f"cross-validation by {by} {what}: holding one out leaves {min(short)} fixes to train on "
                         "(at least 20 are needed); fly or simulate a wider spread of oblique angles"
                         + (", or give finer --bands" if by == "band" else " and give each its flight id"))
    after: dict[str, np.ndarray] = {}
    for fs in feature_sets:
        out = np.full((e.shape[0], 2), np.nan)
        for test in folds:
            gtrain = None if g is None else g[~test]
            m = fit(f.take(~test), e[~test], feature_set=fs, groups=gtrain, oblique_edges=oblique_edges, min_cell=0)
            out[test] = e[test, :2] - m.predict_error(f.take(test))[:, :2]
        after[fs] = out
    if trees:
        from sklearn.ensemble import HistGradientBoostingRegressor

        def tree_x(ft: ErrorFeatures) -> np.ndarray:
            a, b = np.radians(ft.azimuth_deg), np.radians(ft.bearing_deg)
            return np.c_[ft.oblique_deg, ft.height_m, np.cos(a), np.sin(a), np.cos(b), np.sin(b)]

        X = tree_x(f)
        out = np.full((e.shape[0], 2), np.nan)
        for test in folds:
            for c in range(2):
                reg = HistGradientBoostingRegressor(max_iter=300, learning_rate=0.08, random_state=seed)
                reg.fit(X[~test], e[~test, c])
                out[test, c] = e[test, c] - reg.predict(X[test])
        after["trees"] = out
    return CrossValidation(ob, e[:, :2], after, by, len(folds))


__all__ = [
    "DEFAULT_BANDS",
    "FEATURE_SETS",
    "BandRow",
    "CompensationModel",
    "CrossValidation",
    "ErrorFeatures",
    "ModelFileError",
    "Prediction",
    "band_table",
    "compensate",
    "cross_validate",
    "error_enu",
    "error_features",
    "fit",
    "locate_observations",
    "select_bins",
]
