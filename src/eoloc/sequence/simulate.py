"""Synthetic flights over static or moving ground targets, with telemetry errors that have the
time structure real ones have: a per-flight bias, a first-order Gauss-Markov drift and white
jitter. Used to show what filtering over frames can and cannot remove (RLS removes the jitter,
never the bias) and to test the trackers and the calibration against known truth.

The aircraft flies a straight, level leg; the turret keeps a scene point on the boresight
(:meth:`AzElGimbal.pointing`). Targets move on the ground plane of ellipsoidal height
``ground_h_m`` at constant velocity (zero for static ones). True pixels come from the sensor's own
ground -> image projection; measured poses and pixels add the errors.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .. import geodesy
from ..errors import InputError
from ..sensor.gimbal import AzElGimbal
from ..sensor.model import Pose, SensorModel

POSE_SOURCES = ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg")
PIXEL_SOURCES = ("u_px", "v_px")

#: [Z15] Table 1's telemetry sigmas (SPEC §5), in the error budget's units, with a 10 px pixel error.
Z15_SIGMA = {"lat_deg": 1.5e-4, "lon_deg": 2e-4, "h_m": 15.0, "yaw_deg": 1.5, "pitch_deg": 0.4, "roll_deg": 0.4,
             "gimbal1_deg": 0.2, "gimbal2_deg": 0.2, "u_px": 10.0, "v_px": 10.0}


@dataclass(frozen=True)
class TelemetryNoise:
    """Error model per source (names as in the error budget: lat_deg, yaw_deg, gimbal1_deg, u_px,
    ...; values are standard deviations in the source's unit).

    bias: a constant drawn once per flight (installation, INS alignment, DEM datum).
    markov: a first-order Gauss-Markov process with correlation time ``tau_s`` (INS drift).
    white: independent every frame (jitter, detector noise). Pixel errors are drawn per target.
    """

    bias: Mapping[str, float] = field(default_factory=dict)
    markov: Mapping[str, float] = field(default_factory=dict)
    white: Mapping[str, float] = field(default_factory=dict)
    tau_s: float = 10.0

    def __post_init__(self) -> None:
        known = set(POSE_SOURCES) | set(PIXEL_SOURCES)
        for part in ("bias", "markov", "white"):
            bad = set(getattr(self, part)) - known
            if bad:
                raise ValueError(f"TelemetryNoise.{part}: unknown source(s) {sorted(bad)}; known: {sorted(known)}")
        if not self.tau_s > 0:
            raise ValueError(f"tau_s must be > 0, got {self.tau_s!r}")

    @classmethod
    def split(cls, sigma: Mapping[str, float], bias_fraction: float, *, markov_fraction: float = 0.0,
              tau_s: float = 10.0) -> TelemetryNoise:
        """Each source's variance sigma^2 shared: ``bias_fraction`` constant, ``markov_fraction``
        Gauss-Markov, the rest white (pixel errors stay white: they are the detector's)."""
        if not (0 <= bias_fraction and 0 <= markov_fraction and bias_fraction + markov_fraction <= 1):
            raise ValueError("bias_fraction and markov_fraction must be >= 0 and sum to <= 1")
        pose = {k: v for k, v in sigma.items() if k not in PIXEL_SOURCES}
        pix = {k: v for k, v in sigma.items() if k in PIXEL_SOURCES}
        white_f = 1.0 - bias_fraction - markov_fraction
        return cls({k: v * np.sqrt(bias_fraction) for k, v in pose.items()},
                   {k: v * np.sqrt(markov_fraction) for k, v in pose.items()},
                   {**{k: v * np.sqrt(white_f) for k, v in pose.items()}, **pix}, tau_s)

    def draw_pose(self, rng: np.random.Generator, time_s: np.ndarray) -> dict[str, np.ndarray]:
        """Errors of every pose source at the frame times (F,)."""
        out = {}
        dt = np.diff(time_s, prepend=time_s[0])
        phi = np.exp(-dt / self.tau_s)
        for name in POSE_SOURCES:
            e = np.zeros(time_s.shape)
            if self.bias.get(name, 0.0):
                e += rng.normal(0.0, self.bias[name])
            s = self.markov.get(name, 0.0)
            if s:
                w = rng.normal(0.0, s, time_s.shape)
                m = np.empty(time_s.shape)
                m[0] = w[0]
                for k in range(1, m.size):  # x_k = phi x_{k-1} + sqrt(1 - phi^2) w_k: stationary, sigma s
                    m[k] = phi[k] * m[k - 1] + np.sqrt(1.0 - phi[k] ** 2) * w[k]
                e += m
            if self.white.get(name, 0.0):
                e += rng.normal(0.0, self.white[name], time_s.shape)
            out[name] = e
        return out

    def draw_pixels(self, rng: np.random.Generator, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Pixel errors (du, dv) for (F, K) detections: bias per target plus white."""
        out = []
        for name in PIXEL_SOURCES:
            e = rng.normal(0.0, self.white.get(name, 0.0), shape)
            if self.bias.get(name, 0.0):
                e += rng.normal(0.0, self.bias[name], shape[1:])
            out.append(e)
        return out[0], out[1]


@dataclass(frozen=True)
class Flight:
    """A synthetic flight: F frames, K targets.

    time_s (F,); pose_true / pose_measured: Pose of (F,) arrays; target_ecef (F, K, 3) true
    positions (m); target_enu (F, K, 3) the same in the ENU frame at ``origin`` (the scene centre,
    lat deg, lon deg, h m); velocity_enu_mps (K, 3); pixels_true / pixels_measured (F, K, 2);
    in_view (F, K) True where the true pixel is inside the image; ground_h_m: the targets'
    ellipsoidal height.
    """

    time_s: np.ndarray
    pose_true: Pose
    pose_measured: Pose
    target_ecef: np.ndarray
    target_enu: np.ndarray
    velocity_enu_mps: np.ndarray
    pixels_true: np.ndarray
    pixels_measured: np.ndarray
    in_view: np.ndarray
    origin: tuple[float, float, float]
    ground_h_m: float

    @property
    def pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Measured (u, v), (F, K) each: what a detector reports."""
        return self.pixels_measured[..., 0], self.pixels_measured[..., 1]

    def frame_pose(self, measured: bool = True) -> Pose:
        """The pose with (F, 1) fields, to broadcast against (F, K) pixels."""
        return per_frame(self.pose_measured if measured else self.pose_true)


def per_frame(pose: Pose) -> Pose:
    """A pose of (F,) fields as (F, 1) fields, to broadcast against (F, K) pixels or targets."""
    def col(a):
        return np.asarray(a)[:, None]

    return Pose(col(pose.lat_deg), col(pose.lon_deg), col(pose.h_m), col(pose.yaw_deg), col(pose.pitch_deg),
                col(pose.roll_deg), tuple(col(g) for g in pose.gimbal_deg))


def synthetic_flight(sensor: SensorModel, *, centre: tuple[float, float, float] = (35.125225, 112.680649, 400.0),
                     targets_enu_m: ArrayLike = ((0.0, 0.0),), targets_px: ArrayLike | None = None,
                     velocity_enu_mps: ArrayLike | None = None,
                     height_agl_m: float = 740.0, ground_range_m: float = 620.0, bearing_deg: float = 180.0,
                     speed_mps: float = 40.0, heading_deg: float = 90.0, pitch_deg: float = 2.1,
                     roll_deg: float = 0.0, duration_s: float = 5.0, fps: float = 30.0,
                     noise: TelemetryNoise | None = None, seed: int | np.random.SeedSequence = 0) -> Flight:
    """Fly a straight level leg past a scene and watch it.

    centre: scene centre (lat deg, lon deg, ellipsoidal h m), also the targets' ground height;
    targets_enu_m: (K, 2) east/north offsets of the targets at t = 0 from the centre (m), or
    targets_px: (K, 2) pixels (u, v) of the middle frame where the targets are (then at mid-flight);
    velocity_enu_mps: (K, 2) their ground velocities (default static). At mid-flight the
    aircraft is ``ground_range_m`` from the centre on ``bearing_deg`` (from the centre), at
    ``height_agl_m`` above it, flying ``heading_deg`` at ``speed_mps``. The defaults are [Z15]
    Table 1's geometry: 1 140 m ellipsoidal, pitch 2.1°, a target about 965 m away.
    """
    if sensor.gimbal.kind != AzElGimbal.kind:
        raise InputError("synthetic_flight points an az-el turret; give the sensor an AzElGimbal")
    lat0, lon0, h0 = (float(c) for c in centre)
    noise = noise or TelemetryNoise()
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / fps)
    b, hd = np.radians(bearing_deg), np.radians(heading_deg)
    mid = np.array([ground_range_m * np.sin(b), ground_range_m * np.cos(b), height_agl_m])
    track = np.array([np.sin(hd), np.cos(hd), 0.0])
    ac_enu = mid + (t - t.mean())[:, None] * speed_mps * track
    p_ac = geodesy.enu_to_ecef(ac_enu, lat0, lon0, h0)
    lat, lon, h = geodesy.ecef_to_geodetic(p_ac[:, 0], p_ac[:, 1], p_ac[:, 2])
    f = t.size
    yaw, pitch, roll = np.full(f, float(heading_deg)), np.full(f, float(pitch_deg)), np.full(f, float(roll_deg))
    p_centre = np.broadcast_to(np.array(geodesy.geodetic_to_ecef(lat0, lon0, h0), dtype=np.float64), (f, 3))
    az, el, _ = AzElGimbal.pointing(lat, lon, h, yaw, pitch, roll, p_centre)
    pose_true = Pose(lat, lon, h, yaw, pitch, roll, (az, el))

    if targets_px is not None:
        from ..rules import locate_ellipsoid

        k = f // 2
        mid_pose = Pose(lat[k], lon[k], h[k], yaw[k], pitch[k], roll[k], (az[k], el[k]))
        g = locate_ellipsoid(sensor, mid_pose, h0, np.asarray(targets_px, dtype=np.float64))
        targets_enu_m = geodesy.ecef_to_enu(g.p_ecef(), lat0, lon0, h0)[:, :2]
    tgt0 = np.atleast_2d(np.asarray(targets_enu_m, dtype=np.float64))
    vel = np.zeros_like(tgt0) if velocity_enu_mps is None else np.atleast_2d(np.asarray(velocity_enu_mps, float))
    vel = np.broadcast_to(vel, tgt0.shape)
    if targets_px is not None:
        tgt0 = tgt0 - t[k] * vel  # the pixels are those of the middle frame

    enu = np.zeros((f, tgt0.shape[0], 3))
    enu[..., :2] = tgt0[None] + t[:, None, None] * vel[None]
    p_tgt = geodesy.enu_to_ecef(enu, lat0, lon0, h0)
    # ENU offsets on a plane tangent at the centre; put every target back on the ground height
    tl, tn, _ = geodesy.ecef_to_geodetic(p_tgt[..., 0], p_tgt[..., 1], p_tgt[..., 2])
    p_tgt = np.stack(geodesy.geodetic_to_ecef(tl, tn, np.full(tl.shape, h0)), -1)
    enu = geodesy.ecef_to_enu(p_tgt, lat0, lon0, h0)

    u, v = sensor.ground_to_image(per_frame(pose_true), p_tgt)
    cam = sensor.camera
    in_view = np.isfinite(u) & (u >= -0.5) & (u <= cam.width - 0.5) & (v >= -0.5) & (v <= cam.height - 0.5)
    d = noise.draw_pose(rng, t)
    pose_meas = Pose(lat + d["lat_deg"], lon + d["lon_deg"], h + d["h_m"], yaw + d["yaw_deg"],
                     pitch + d["pitch_deg"], roll + d["roll_deg"], (az + d["gimbal1_deg"], el + d["gimbal2_deg"]))
    du, dv = noise.draw_pixels(rng, u.shape)
    return Flight(t, pose_true, pose_meas, p_tgt, enu, np.c_[vel, np.zeros(len(vel))], np.stack([u, v], -1),
                  np.stack([u + du, v + dv], -1), in_view, (lat0, lon0, h0), h0)


@dataclass(frozen=True)
class GCPFlight:
    """Synthetic GCP observations for calibration: N observations, each of one GCP from one leg.

    tel_time_s (M,) / tel_pose: the measured telemetry records (telemetry clock, s); obs_time_s
    (N,) the observations' video times; pixels (N, 2) measured; gcp_llh (N, 3) the GCPs (lat deg,
    lon deg, ellipsoidal h m); obs_pose: the measured telemetry at each observation (N,), and
    true_pose the truth there.
    """

    tel_time_s: np.ndarray
    tel_pose: Pose
    obs_time_s: np.ndarray
    pixels: np.ndarray
    gcp_llh: np.ndarray
    obs_pose: Pose
    true_pose: Pose


def _concat(poses: list[Pose]) -> Pose:
    cat = [np.concatenate([np.ravel(getattr(p, k)) for p in poses])
           for k in ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg")]
    gim = tuple(np.concatenate([np.ravel(p.gimbal_deg[i]) for p in poses]) for i in range(len(poses[0].gimbal_deg)))
    return Pose(*cat, gim)


def gcp_flight(true_sensor: SensorModel, n: int = 20, *, noise: TelemetryNoise | None = None, seed: int = 0,
               heading_bias_deg: float = 0.0, time_offset_s: float = 0.0, centre=(35.125225, 112.680649, 400.0),
               rate_hz: float = 10.0, speed_mps: float = 40.0, max_roll_deg: float = 25.0) -> GCPFlight:
    """A calibration flight: n short legs around a GCP field (bearings spread over 360°, slant ranges
    ~0.7-2.5 km, banked up to ``max_roll_deg``), each seeing one GCP at a random pixel with the TRUE
    sensor ``true_sensor`` (its misalignment is what calibration must find). The telemetry carries
    ``noise``, a heading bias (measured yaw = true + bias) and runs ``time_offset_s`` ahead of the
    video clock."""
    rng = np.random.default_rng(seed)
    cam = true_sensor.camera
    tel_t, tel_p, obs_t, px, llh, obs_p, true_p = [], [], [], [], [], [], []
    for i, ss in enumerate(np.random.SeedSequence(seed).spawn(n)):
        b = 360.0 * i / n + rng.uniform(-5, 5)
        target_px = rng.uniform([0.05 * cam.width, 0.05 * cam.height], [0.95 * cam.width, 0.95 * cam.height])
        fl = synthetic_flight(true_sensor, centre=centre, targets_px=target_px[None], bearing_deg=b,
                              heading_deg=(b + 90.0 * rng.choice([-1, 1])) % 360.0,
                              ground_range_m=rng.uniform(400, 2000),
                              height_agl_m=rng.uniform(600, 1500), roll_deg=rng.uniform(-max_roll_deg, max_roll_deg),
                              pitch_deg=rng.uniform(-5, 10), speed_mps=speed_mps, duration_s=1.0 + 0.5 / rate_hz,
                              fps=rate_hz, noise=noise, seed=ss)
        k = fl.time_s.size // 2
        t0 = 100.0 * i
        pm = fl.pose_measured
        tel_t.append(t0 + fl.time_s)
        tel_p.append(_add_yaw(pm, heading_bias_deg))
        obs_t.append(t0 + fl.time_s[k] - time_offset_s)
        px.append(fl.pixels_measured[k, 0])
        lat, lon, h = geodesy.ecef_to_geodetic(*fl.target_ecef[k, 0])
        llh.append((float(lat), float(lon), float(h)))
        obs_p.append(tel_p[-1].take([k]))
        true_p.append(fl.pose_true.take([k]))
    return GCPFlight(np.concatenate(tel_t), _concat(tel_p), np.array(obs_t), np.array(px), np.array(llh),
                     _concat(obs_p), _concat(true_p))


def _add_yaw(pose: Pose, bias_deg: float) -> Pose:
    """The pose with ``bias_deg`` added to its yaw (a heading bias of the INS)."""
    from dataclasses import replace

    return replace(pose, yaw_deg=np.asarray(pose.yaw_deg) + bias_deg)
