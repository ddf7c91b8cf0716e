"""Monte Carlo error analysis: perturb the inputs, run the SAME geolocation chain, measure the scatter.

Delta y = f(x + Delta x) - f(x) (SPEC §4.1): the nominal observation is located once without
errors (the truth), then n perturbed copies of it go through ``SensorModel.camera_frame`` /
``rays_from`` and the stop rule's kernel, exactly as real-time fixes do. Samples are drawn and
located in chunks (bounded memory); chunk i always uses the i-th child of
``numpy.random.SeedSequence(seed)``, so a run is reproducible and gives identical samples
wherever its chunks are computed (locally or on a cluster).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..result import Fixes, Status
from ..rules import StopRule
from ..sensor.gimbal import GimbalKind
from ..sensor.model import Pose, SensorModel
from .budget import ErrorBudget
from .cep import cep_bivariate, drms, error_ellipse
from .runners import Mapper, local_map

DEFAULT_CHUNK = 200_000


@dataclass(frozen=True)
class Scenario:
    """A nominal observation and its error budget.

    pose: one aircraft pose (scalars); rule: the stop rule (:class:`eoloc.AtRange`,
    :class:`eoloc.AtHeight` or :class:`eoloc.OnDEM`; its own error source, range_m or terrain_m,
    is perturbed by the budget); pixels: (K, 2) target pixels (default: the principal point);
    velocity_ned_mps: the aircraft's velocity, used by the time-offset source.
    """

    name: str
    sensor: SensorModel
    pose: Pose
    budget: ErrorBudget
    rule: StopRule
    pixels: np.ndarray | None = None
    velocity_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    description: str = ""

    def __post_init__(self) -> None:
        usable_rule(self.rule)
        px = np.array([self.sensor.camera.centre_px]) if self.pixels is None else np.asarray(self.pixels, float)
        object.__setattr__(self, "pixels", px.reshape(-1, 2))

    @property
    def n_targets(self) -> int:
        return int(self.pixels.shape[0])

    def with_budget(self, budget: ErrorBudget) -> Scenario:
        return replace(self, budget=budget)


def usable_rule(rule) -> StopRule:
    """``rule`` if the error analysis takes it (every single-ray stop rule: AtRange, AtHeight,
    OnDEM, FlatGround), else an :class:`~eoloc.errors.InputError` that says why and what to use."""
    if isinstance(rule, StopRule):
        return rule
    if getattr(rule, "name", None) == "multiview":
        raise InputError("MultiView intersects several rays of one target, so there is no single fix to perturb: "
                         "its uncertainty comes from its own geometry (MultiView(...).intersect(rays).cov_enu, "
                         "`eoloc triangulate`), from each ray's angular sigma")
    raise InputError(f"the error analysis needs a stop rule (AtRange, AtHeight, OnDEM, FlatGround), got {rule!r}")


def perturbed_fixes(scn: Scenario, d: dict[str, np.ndarray], n: int) -> Fixes:
    """Fixes (n, K) of the scenario's K targets with the errors ``d`` (name -> (n,) draws) applied."""
    return chain_fixes(scn.sensor, scn.pose, scn.pixels[:, 0], scn.pixels[:, 1], scn.rule, d, n,
                       velocity_ned_mps=scn.velocity_ned_mps)


def chain_fixes(sensor: SensorModel, pose: Pose, u, v, rule: StopRule, d: dict[str, np.ndarray], n: int,
                *, velocity_ned_mps=(0.0, 0.0, 0.0)) -> Fixes:
    """The geolocation chain with input errors ``d`` (source name -> (n,) values) added.

    pose fields, pixels (u, v) and the rule's value (a range or height per target) broadcast to
    the targets' shape T; the result has shape (n, *T): row i holds every target with error row i.
    This is the one place the error sources of :data:`SOURCES` enter the chain (Monte Carlo and
    first-order covariance both go through it).
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    shapes = [np.shape(x) for x in (pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg,
                                     pose.roll_deg, *pose.gimbal_deg, u, v)]
    shapes.append(rule.value_shape)
    lead = (n,) + (1,) * len(np.broadcast_shapes(*shapes))

    def z(name: str):  # (n,) draws: one per row; (n, *T) draws: one per row and target
        x = d.get(name)
        if x is None:
            return 0.0
        x = np.asarray(x, dtype=np.float64)
        return x.reshape(lead) if x.ndim == 1 else x

    lat = pose.lat_deg + z("lat_deg")
    lon = pose.lon_deg + z("lon_deg")
    h = pose.h_m + z("h_m")
    dt = z("time_s")
    vel = np.asarray(velocity_ned_mps, dtype=np.float64)
    if np.any(vel != 0.0) and not np.isscalar(dt):
        m_lat, m_lon = metres_per_degree(pose.lat_deg, pose.h_m, sensor.ellipsoid)
        lat = lat + vel[..., 0] * dt / m_lat
        lon = lon + vel[..., 1] * dt / m_lon
        h = h - vel[..., 2] * dt
    g = list(pose.gimbal_deg)
    if sensor.gimbal.kind == GimbalKind.FIXED:  # fixed mount: the tuple holds the sensor roll only
        g = [(g[0] if g else 0.0) + z("sensor_roll_deg")]
    else:
        g = g + [0.0] * (3 - len(g))
        g = [g[0] + z("gimbal1_deg"), g[1] + z("gimbal2_deg"), g[2] + z("sensor_roll_deg")]
    perturbed = Pose(lat, lon, h, pose.yaw_deg + z("yaw_deg") + z("vibration_yaw_deg"),
                     pose.pitch_deg + z("pitch_deg") + z("vibration_pitch_deg"),
                     pose.roll_deg + z("roll_deg") + z("vibration_roll_deg"), tuple(g), pose.focal_scale)
    mount = _angles(sensor.mount_misalignment_deg, d, "mount", ("x", "y", "z"), lead)
    bore = _angles(sensor.boresight_misalignment_deg, d, "boresight", ("x", "y"), lead)
    frame = sensor.camera_frame(perturbed, mount_misalignment_deg=mount, boresight_misalignment_deg=bore,
                                gimbal_skew_deg=z("gimbal_skew_deg"))
    def normalize(uu, vv):  # pixels to normalised points with the camera's perturbed intrinsics
        return sensor.camera.pixel_to_normalized(uu + z("u_px"), vv + z("v_px"), focal_error_px=z("focal_px"),
                                                 principal_point_error_px=(z("cx_px"), z("cy_px")),
                                                 focal_scale=pose.focal_scale)

    xn, yn = normalize(u, v)
    # the nominal pixel decides whether a target is in the image (as eoloc.locate): a pixel outside
    # is OUT_OF_IMAGE in every row, never a point with an uncertainty
    xn0, yn0 = sensor.camera.pixel_to_normalized(u, v, focal_scale=pose.focal_scale)
    outside = sensor.camera.outside(u, v, xn0, yn0, focal_scale=pose.focal_scale)
    f = usable_rule(rule).stop_in_frame(sensor, frame, xn, yn, outside, sensor.ellipsoid, errors=z,
                                        normalize=normalize)
    shape = np.broadcast_shapes(lead, f.shape)  # rows even when no source varies
    return Fixes(*(np.broadcast_to(x, shape) for x in (f.lat_deg, f.lon_deg, f.h_m, f.range_m, f.status)))


def _angles(nominal, d, prefix, axes, lead):
    names = [f"{prefix}_{a}_deg" for a in axes]
    if not any(k in d for k in names):
        return None
    draws = {k: (np.reshape(d[k], lead) if np.ndim(d[k]) == 1 else np.asarray(d[k])) for k in names if k in d}
    shape = np.broadcast_shapes(lead, *(x.shape for x in draws.values()))
    out = np.broadcast_to(np.asarray(nominal, dtype=np.float64), (*shape, 3)).copy()
    for i, k in enumerate(names):
        if k in draws:
            out[..., i] += draws[k]
    return out


def metres_per_degree(lat_deg, h, ell):
    """Metres per degree of latitude and of longitude at (lat_deg, h) (arrays broadcast)."""
    s = np.sin(np.radians(lat_deg))
    w = np.sqrt(1.0 - ell.e2 * s * s)
    m = ell.a * (1.0 - ell.e2) / w**3
    n_ = ell.a / w
    return np.radians(1.0) * (m + h), np.radians(1.0) * (n_ + h) * np.cos(np.radians(lat_deg))


# ---------------------------------------------------------------- statistics


@dataclass(frozen=True)
class TargetStats:
    """Scatter of one target's fixes around its true (error-free) position.

    Metric errors in the local east/north/up frame at the truth (m); lat/lon/h sigmas in degrees
    and metres. bias = mean error (the systematic part), sigma = standard deviation (n - 1; the
    random part). cep50: empirical median radius around the truth; cep50_parametric: the
    bivariate-normal CEP of (bias, sigma, rho); ce90 / le90: 90 % horizontal radius / vertical
    error; drms: sqrt(sigma_e^2 + sigma_n^2) (what [Q] calls CEP); ellipse: 1-sigma (semi-major,
    semi-minor, azimuth of the major axis deg).
    """

    n: int
    n_failed: int
    truth: tuple[float, float, float]
    bias_enu: tuple[float, float, float]
    sigma_enu: tuple[float, float, float]
    rho_en: float
    sigma_lat_deg: float
    sigma_lon_deg: float
    sigma_h_m: float
    cep50: float
    cep50_parametric: float
    ce90: float
    le90: float
    drms: float
    ellipse: tuple[float, float, float]

    @classmethod
    def from_summary(cls, truth, s: ChunkSummary, k: int) -> TargetStats:
        """Statistics of target k from a (combined) chunk summary."""
        count = int(s.count[k])
        n_failed = int(s.n - count)
        if count < 2:
            nan = float("nan")
            return cls(count, n_failed, truth, (nan,) * 3, (nan,) * 3, nan, nan, nan, nan, nan, nan, nan,
                       nan, nan, (nan,) * 3)
        mean = s.mean[k]
        cov = s.m2[k] / (count - 1)  # (e, n, u, dlat, dlon, dh), n - 1 in the denominators
        sd = np.sqrt(np.maximum(np.diagonal(cov), 0.0))
        bias = tuple(float(x) for x in mean[:3])
        sig = tuple(float(x) for x in sd[:3])
        rho = float(cov[0, 1] / (sd[0] * sd[1])) if sd[0] > 0 and sd[1] > 0 else 0.0
        rho = min(max(rho, -1.0), 1.0)  # one error source alone: perfectly correlated, up to rounding
        radius = np.concatenate(s.radius[k])
        return cls(
            n=count, n_failed=n_failed, truth=truth, bias_enu=bias, sigma_enu=sig, rho_en=rho,
            sigma_lat_deg=float(sd[3]), sigma_lon_deg=float(sd[4]), sigma_h_m=float(sd[5]),
            cep50=float(np.quantile(radius, 0.5)),
            cep50_parametric=cep_bivariate(bias[0], bias[1], sig[0], sig[1], rho),
            ce90=float(np.quantile(radius, 0.9)), le90=float(np.quantile(np.concatenate(s.abs_up[k]), 0.9)),
            drms=drms(sig[0], sig[1]), ellipse=error_ellipse(cov[:2, :2]),
        )


@dataclass
class ChunkSummary:
    """What a chunk of samples contributes to the statistics, per target k (mergeable exactly in
    chunk order, so a run gives the same figures wherever its chunks were computed; and only
    16 bytes per sample travel from a worker instead of the samples).

    n: samples; count[k]: located ones; mean[k] / m2[k]: mean and co-moment matrix (sum of
    outer products of deviations) of (east, north, up m, dlat, dlon deg, dh m); radius[k] /
    abs_up[k]: lists of arrays of the horizontal radius and |up| (for the quantiles).
    """

    n: int
    count: np.ndarray
    mean: np.ndarray
    m2: np.ndarray
    radius: list[list[np.ndarray]]
    abs_up: list[list[np.ndarray]]

    @classmethod
    def of(cls, enu: np.ndarray, dllh: np.ndarray, status: np.ndarray) -> ChunkSummary:
        """From samples enu / dllh (n, K, 3) and status (n, K)."""
        n, K = status.shape
        count = np.zeros(K, dtype=np.int64)
        mean = np.zeros((K, 6))
        m2 = np.zeros((K, 6, 6))
        radius, abs_up = [], []
        for k in range(K):
            ok = status[:, k] == Status.OK
            x = np.concatenate([enu[ok, k], dllh[ok, k]], axis=1)
            count[k] = x.shape[0]
            if count[k]:
                mean[k] = x.mean(axis=0)
                dev = x - mean[k]
                m2[k] = dev.T @ dev
            radius.append([np.hypot(x[:, 0], x[:, 1])])
            abs_up.append([np.abs(x[:, 2])])
        return cls(n, count, mean, m2, radius, abs_up)

    def merge(self, other: ChunkSummary) -> ChunkSummary:
        """Pairwise combination (Chan, Golub & LeVeque): exact up to rounding, no cancellation."""
        count = self.count + other.count
        with np.errstate(invalid="ignore", divide="ignore"):
            wb = np.where(count > 0, other.count / count, 0.0)
        delta = other.mean - self.mean
        mean = self.mean + delta * wb[:, None]
        m2 = self.m2 + other.m2 + np.einsum("ki,kj->kij", delta, delta) * (self.count * wb)[:, None, None]
        return ChunkSummary(self.n + other.n, count, mean, m2,
                            [a + b for a, b in zip(self.radius, other.radius, strict=True)],
                            [a + b for a, b in zip(self.abs_up, other.abs_up, strict=True)])


@dataclass
class MonteCarloResult:
    """Per-target statistics and (optionally) the error samples: enu (n, K, 3) metres and the
    geodetic differences dlat/dlon (deg) and dh (m), NaN where a sample failed (status kept)."""

    scenario: Scenario
    n: int
    seed: int
    stats: list[TargetStats]
    enu: np.ndarray | None = None
    dllh: np.ndarray | None = None
    status: np.ndarray | None = None
    meta: dict = field(default_factory=dict)


def truth_fixes(scn: Scenario) -> Fixes:
    """The error-free fixes of the scenario's targets (shape (K,))."""
    f = perturbed_fixes(scn, {}, 1)
    return f.flat()


def chunk_sizes(n: int, chunk: int) -> list[int]:
    return [min(chunk, n - i) for i in range(0, n, chunk)]


def run_chunk(scn: Scenario, seed_seq: np.random.SeedSequence, size: int, truth: Fixes, keep_samples: bool = False):
    """Draw and locate one chunk -> (ChunkSummary, samples): samples = (enu (size, K, 3) m,
    dllh (size, K, 3) deg/deg/m, status (size, K)) when ``keep_samples``, else None."""
    rng = np.random.default_rng(seed_seq)
    d = scn.budget.draw(rng, size)
    f = perturbed_fixes(scn, d, size)
    lat, lon, h = (np.broadcast_to(x, (size, scn.n_targets)) for x in (f.lat_deg, f.lon_deg, f.h_m))
    p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h, ell=scn.sensor.ellipsoid), -1)
    enu = np.empty(p.shape)
    for k in range(scn.n_targets):
        enu[:, k] = geodesy.ecef_to_enu(p[:, k], truth.lat_deg[k], truth.lon_deg[k], truth.h_m[k],
                                        ell=scn.sensor.ellipsoid)
    dlon = (lon - truth.lon_deg + 180.0) % 360.0 - 180.0
    dllh = np.stack([lat - truth.lat_deg, dlon, h - truth.h_m], -1)
    status = np.broadcast_to(f.status, (size, scn.n_targets))
    return ChunkSummary.of(enu, dllh, status), ((enu, dllh, np.array(status)) if keep_samples else None)


def monte_carlo(scn: Scenario, n: int, *, seed: int = 0, chunk: int = DEFAULT_CHUNK, keep_samples: bool = False,
                progress: Callable[[int], None] | None = None, mapper: Mapper | None = None) -> MonteCarloResult:
    """Monte Carlo of ``n`` samples of the scenario; ``progress(k)`` is called after each chunk of k.

    ``mapper`` computes the chunks (default: here, in order; :class:`eoloc.accuracy.DaskMapper`
    on a cluster); the statistics are identical wherever the chunks run: chunk i draws from the
    i-th child of ``SeedSequence(seed)`` and the chunk summaries are merged in chunk order.
    ``keep_samples`` also returns every sample (memory: 56 bytes per sample and target).
    """
    if n < 2:
        raise InputError(f"Monte Carlo needs n >= 2 samples, got {n}")
    truth = truth_fixes(scn)
    bad = np.flatnonzero(truth.status != Status.OK)
    if bad.size:
        raise InputError(f"scenario {scn.name}: target(s) {bad.tolist()} cannot be located even without errors "
                         f"({', '.join(Status(int(truth.status[i])).name for i in bad)}); check the pose and pixels")
    sizes = chunk_sizes(n, chunk)
    seeds = np.random.SeedSequence(seed).spawn(len(sizes))
    done = None if progress is None else (lambda i: progress(sizes[i]))
    parts = (mapper or local_map)(run_chunk, [(scn, s, size, truth, keep_samples)
                                              for s, size in zip(seeds, sizes, strict=True)], done)
    total = parts[0][0]
    for summary, _ in parts[1:]:
        total = total.merge(summary)
    stats = [TargetStats.from_summary((float(truth.lat_deg[k]), float(truth.lon_deg[k]), float(truth.h_m[k])),
                                      total, k) for k in range(scn.n_targets)]
    if keep_samples:
        enu, dllh, status = (np.concatenate([q[1][i] for q in parts]) for i in range(3))
        ok = (status == Status.OK)[..., None]
        return MonteCarloResult(scn, n, seed, stats, np.where(ok, enu, np.nan), np.where(ok, dllh, np.nan), status)
    return MonteCarloResult(scn, n, seed, stats)


# ---------------------------------------------------------------- sensitivity


@dataclass(frozen=True)
class Sensitivity:
    """One source alone ([S13]): sigma_in (its unit) and mu = sigma_out / sigma_in for the target's
    latitude and longitude (deg per unit), height (m per unit), east/north/horizontal (m per unit)."""

    source: str
    unit: str
    law: str
    sigma_in: float
    mu_lat: float
    mu_lon: float
    mu_h: float
    mu_east: float
    mu_north: float
    sigma_horizontal_m: float


def sensitivity(scn: Scenario, n: int, *, seed: int = 0, target: int = 0, chunk: int = DEFAULT_CHUNK,
                progress: Callable[[int], None] | None = None, mapper: Mapper | None = None) -> list[Sensitivity]:
    """Each error source of the budget alone: its sensitivity coefficients for target ``target``."""
    rows = []
    for src in scn.budget:
        r = monte_carlo(scn.with_budget(scn.budget.only(src.name)), n, seed=seed, chunk=chunk, progress=progress,
                        mapper=mapper)
        st = r.stats[target]
        s_in = src.sigma
        k = 1.0 / s_in if s_in > 0 else float("nan")
        rows.append(Sensitivity(src.name, src.unit, src.describe(), s_in, st.sigma_lat_deg * k, st.sigma_lon_deg * k,
                                st.sigma_h_m * k, st.sigma_enu[0] * k, st.sigma_enu[1] * k,
                                float(np.hypot(st.sigma_enu[0], st.sigma_enu[1]))))
    return rows
