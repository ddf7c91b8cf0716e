"""Synthetic calibration flights over surveyed points, with errors that depend on geometry the way
real ones do ([P]'s training data, before anyone flies).

The platform carries systematic errors that repeat on every flight (:class:`InstallationErrors`):
gimbal encoder offsets, mount and boresight misalignment, an INS heading bias, a telemetry time
offset, and a ground-station DEM that sits off the true terrain. On top come errors that change
from flight to flight (INS re-alignment, GPS bias) and from look to look (jitter, detector
noise, DEM noise) (:class:`FlightNoise`): compensation can learn the first kind, never the second.

Each observation is one look at one surveyed point (GCP): the aircraft is placed so that the
line of sight meets the GCP at a drawn oblique angle and azimuth from a drawn height, flying one
of its legs' headings; the turret is aimed near the GCP, and the GCP's pixel comes from the TRUE
sensor's ground -> image projection at the TRUE pose. The telemetry reports the pose with the
errors. Observations come out as the columns of the calibration-observations CSV
(:data:`eoloc.io.telemetry.OBSERVATION_COLUMNS`), ready for ``eoloc compensate train``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import geodesy
from ..errors import InputError
from ..sensor.gimbal import AzElGimbal
from ..sensor.model import Pose, SensorModel
from ..terrain.dem import DEM


@dataclass(frozen=True)
class InstallationErrors:
    """Systematic errors of one platform (degrees, seconds, metres): the same on every flight.

    gimbal_bias_deg: (azimuth, elevation) encoder offsets (measured = true + bias);
    mount/boresight_misalignment_deg: the true installation (the located sensor assumes zero);
    heading_bias_deg: INS yaw bias; time_offset_s: the telemetry describes the aircraft this long
    before its time stamp; dem_bias_m: the ground-station DEM minus the true terrain.
    """

    gimbal_bias_deg: tuple[float, float] = (0.10, -0.25)
    mount_misalignment_deg: tuple[float, float, float] = (0.12, -0.08, 0.06)
    boresight_misalignment_deg: tuple[float, float, float] = (0.0, 0.05, -0.04)
    heading_bias_deg: float = 0.08
    time_offset_s: float = 0.05
    dem_bias_m: float = -5.0


@dataclass(frozen=True)
class FlightNoise:
    """Errors that change: per flight (``*_flight``) and per observation (``*_white``), 1-sigma.

    dem_sigma_m: the DEM's own random error (smooth, a few kilometres of correlation) — not
    learnable from geometry.
    """

    heading_flight_deg: float = 0.02
    attitude_flight_deg: float = 0.01
    position_flight_m: float = 1.5
    attitude_white_deg: float = 0.01
    gimbal_white_deg: float = 0.008
    position_white_m: float = 1.0
    height_white_m: float = 2.0
    pixel_white_px: float = 0.7
    dem_sigma_m: float = 2.0


@dataclass(frozen=True)
class CalibrationFlights:
    """Observations as CSV columns, the true terrain and the DEM the ground station uses."""

    columns: dict[str, np.ndarray]
    true_dem: DEM
    dem: DEM

    def __len__(self) -> int:
        return int(self.columns["u_px"].size)


def relief(centre: tuple[float, float], *, sigma_m: float = 60.0, base_m: float = 350.0):
    """A smooth analytic terrain f(lat, lon) -> ellipsoidal m around ``centre`` (hills of a few km)."""
    lat0, lon0 = centre
    k = np.cos(np.radians(lat0))

    def f(lat, lon):
        y = (np.asarray(lat) - lat0) * 111.0
        x = (np.asarray(lon) - lon0) * 111.0 * k
        z = (np.sin(x / 3.1 + 0.4) * np.cos(y / 4.3 - 0.2) + 0.6 * np.sin((x + y) / 7.7)
             + 0.4 * np.cos(x / 1.9 - y / 2.6))
        return base_m + sigma_m * z / 0.9

    return f


def calibration_flights(sensor: SensorModel, *, n_flights: int = 8, looks_per_flight: int = 400,
                        heights_agl_m=(1000.0, 2000.0, 3000.0, 4500.0), oblique_max_deg: float = 78.0,
                        errors: InstallationErrors | None = None, noise: FlightNoise | None = None,
                        centre: tuple[float, float] = (35.1, 112.7), n_gcps: int = 40, field_km: float = 8.0,
                        speed_mps: float = 60.0, seed: int = 0, first_flight: int = 0) -> CalibrationFlights:
    """Draw ``n_flights`` flights of ``looks_per_flight`` observations each over a field of
    ``n_gcps`` surveyed points. Flight i flies at ``heights_agl_m[i % len]`` above the field, on
    four legs (its base heading + 0/90/180/270°); oblique angles are uniform in
    [0, ``oblique_max_deg``], azimuths uniform. ``sensor`` is the NOMINAL sensor (what the ground
    station assumes); the true one adds ``errors``' misalignments. Flight ids are
    ``F{first_flight + i:02d}`` (so a second call with another seed and ``first_flight`` gives
    independent test flights)."""
    if sensor.gimbal.kind != AzElGimbal.kind:
        raise InputError("calibration_flights points an az-el turret; give the sensor an AzElGimbal")
    errors = errors or InstallationErrors()
    noise = noise or FlightNoise()
    rng = np.random.default_rng(seed)
    lat0, lon0 = centre
    terrain = relief(centre)
    span = 0.5 * field_km / 111.0 + (max(heights_agl_m) * np.tan(np.radians(oblique_max_deg)) + 5000) / 1.0e5
    bounds = (lon0 - span / np.cos(np.radians(lat0)), lat0 - span, lon0 + span / np.cos(np.radians(lat0)), lat0 + span)
    true_dem = DEM.from_function(terrain, bounds, 0.002, source="synthetic relief (truth)")
    g = true_dem.grid
    smooth = _smooth_noise(rng, g.z.shape, corr_posts=15) * noise.dem_sigma_m
    dem = DEM.from_array(g.z + errors.dem_bias_m + smooth, lat0=g.lat0, lon0=g.lon0, dlat=g.dlat, dlon=g.dlon,
                         source="synthetic ground-station DEM")
    true_sensor = dataclasses.replace(sensor, mount_misalignment_deg=errors.mount_misalignment_deg,
                                      boresight_misalignment_deg=errors.boresight_misalignment_deg)
    half = 0.5 * field_km * 1000.0
    gcp_en = rng.uniform(-half, half, (n_gcps, 2))
    gcp_ll = geodesy.ecef_to_geodetic(*np.moveaxis(geodesy.enu_to_ecef(np.c_[gcp_en, np.zeros(n_gcps)],
                                                                       lat0, lon0, 0.0), -1, 0))
    gcp_lat, gcp_lon = gcp_ll[0], gcp_ll[1]
    gcp_h = true_dem.height(gcp_lat, gcp_lon)
    cam = sensor.camera
    half_fov = np.degrees(np.arctan(0.5 * cam.width / cam.fx)), np.degrees(np.arctan(0.5 * cam.height / cam.fy))
    out: dict[str, list] = {k: [] for k in _COLUMNS}
    for fi in range(n_flights):
        n = looks_per_flight * 2  # some looks leave the image; draw spares
        H = float(heights_agl_m[fi % len(heights_agl_m)])
        base = rng.uniform(0, 360)
        k = rng.integers(0, n_gcps, n)
        theta = rng.uniform(0.0, oblique_max_deg, n)
        alpha = rng.uniform(0.0, 360.0, n)
        yaw = (base + 90.0 * rng.integers(0, 4, n) + rng.uniform(-3, 3, n)) % 360.0
        pitch, roll = rng.uniform(-1.0, 4.0, n), rng.uniform(-8.0, 8.0, n)
        # aircraft on the far side of the look, H above the GCP
        d = H * np.tan(np.radians(theta))
        a = np.radians(alpha)
        off = np.c_[-d * np.sin(a), -d * np.cos(a), np.full(n, H)]
        p_ac = geodesy.enu_to_ecef(off, gcp_lat[k], gcp_lon[k], gcp_h[k])
        lat, lon, h = geodesy.ecef_to_geodetic(p_ac[:, 0], p_ac[:, 1], p_ac[:, 2])
        p_gcp = np.stack(geodesy.geodetic_to_ecef(gcp_lat[k], gcp_lon[k], gcp_h[k]), -1)
        az, el, _ = AzElGimbal.pointing(lat, lon, h, yaw, pitch, roll, p_gcp)
        az = az + rng.uniform(-0.8, 0.8, n) * half_fov[0]
        el = el + rng.uniform(-0.8, 0.8, n) * half_fov[1]
        pose_true = Pose(lat, lon, h, yaw, pitch, roll, (az, el))
        u, v = true_sensor.ground_to_image(pose_true, p_gcp)
        seen = np.isfinite(u) & (u >= 0) & (u <= cam.width - 1) & (v >= 0) & (v <= cam.height - 1)
        idx = np.flatnonzero(seen)[:looks_per_flight]
        m = idx.size
        # telemetry errors: per flight, then per look
        dyaw = errors.heading_bias_deg + rng.normal(0, noise.heading_flight_deg)
        dpitch, droll = rng.normal(0, noise.attitude_flight_deg, 2)
        dpos = rng.normal(0, noise.position_flight_m, 2)
        ya = np.radians(yaw[idx])
        lag = -speed_mps * errors.time_offset_s  # the record describes the aircraft time_offset_s earlier
        de = dpos[0] + lag * np.sin(ya) + rng.normal(0, noise.position_white_m, m)
        dn = dpos[1] + lag * np.cos(ya) + rng.normal(0, noise.position_white_m, m)
        du = rng.normal(0, noise.height_white_m, m)
        p_meas = geodesy.enu_to_ecef(np.c_[de, dn, du], lat[idx], lon[idx], h[idx])
        mlat, mlon, mh = geodesy.ecef_to_geodetic(p_meas[:, 0], p_meas[:, 1], p_meas[:, 2])
        wa = noise.attitude_white_deg
        out["flight"].append(np.full(m, f"F{first_flight + fi:02d}", dtype=object))
        out["time_s"].append(np.arange(m) * 2.0)
        out["lat_deg"].append(mlat)
        out["lon_deg"].append(mlon)
        out["h_m"].append(mh)
        out["yaw_deg"].append((yaw[idx] + dyaw + rng.normal(0, wa, m)) % 360.0)
        out["pitch_deg"].append(pitch[idx] + dpitch + rng.normal(0, wa, m))
        out["roll_deg"].append(roll[idx] + droll + rng.normal(0, wa, m))
        out["gimbal1_deg"].append(az[idx] + errors.gimbal_bias_deg[0] + rng.normal(0, noise.gimbal_white_deg, m))
        out["gimbal2_deg"].append(el[idx] + errors.gimbal_bias_deg[1] + rng.normal(0, noise.gimbal_white_deg, m))
        out["u_px"].append(u[idx] + rng.normal(0, noise.pixel_white_px, m))
        out["v_px"].append(v[idx] + rng.normal(0, noise.pixel_white_px, m))
        out["gcp_id"].append(np.array([f"G{j:03d}" for j in k[idx]], dtype=object))
        out["gcp_lat_deg"].append(gcp_lat[k[idx]])
        out["gcp_lon_deg"].append(gcp_lon[k[idx]])
        out["gcp_h_m"].append(gcp_h[k[idx]])
    cols = {name: np.concatenate(v) for name, v in out.items()}
    return CalibrationFlights(cols, true_dem, dem)


_COLUMNS = ("flight", "time_s", "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg",
            "gimbal2_deg", "u_px", "v_px", "gcp_id", "gcp_lat_deg", "gcp_lon_deg", "gcp_h_m")


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], corr_posts: int) -> np.ndarray:
    """Unit-variance Gaussian noise with a correlation length of about ``corr_posts`` posts."""
    from scipy.ndimage import gaussian_filter

    z = gaussian_filter(rng.normal(size=shape), corr_posts, mode="reflect")
    return z / z.std()


__all__ = ["CalibrationFlights", "FlightNoise", "InstallationErrors", "calibration_flights", "relief"]
