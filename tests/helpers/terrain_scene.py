"""A flight over real terrain rendered without eoloc, with known installation and telemetry errors.

The ground is SRTM's Boulder foothills (``tests/data/dem``), its posts taken as ellipsoidal
heights and interpolated bilinearly in latitude/longitude (what a DEM reader does), painted with
smooth grey noise. The aircraft orbits a point at 50 m/s, banking and pitching a little (gusts),
its az-el turret scanning the ground around the point. A frame is the terrain seen through a
pinhole camera at the true pose: each pixel's ray is marched over a height field of the terrain
in the origin's ENU frame (pymap3d; posts every 10 m, each exactly on the DEM's surface) to its
first crossing, refined by secant steps on scipy's exact bilinear interpolation.

The telemetry is what the aircraft's INS and turret report, written with the errors the test
injects: the turret is mounted ``mount_deg`` off the body axes (the camera really points through
Rz(c) Ry(b) Rx(a) applied to the gimbal), the INS heading reads ``heading_bias_deg`` too high, and
the records are stamped on a clock ``time_offset_s`` ahead of the video's (the record stamped T
holds the state at video time T - offset). Rotations are scipy's (SPEC §2: R_ned<-body = Rz(yaw)
Ry(pitch) Rx(roll); az-el gimbal G = Rz(az) Ry(el), camera x, y, z = G's y, z, x).
The height field differs from the DEM's lat/lon bilinear surface by < 1.5 m between its posts
(where SRTM's bilinear patches kink).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
import pymap3d
import rasterio
from rasterio.transform import from_origin
from scipy.interpolate import RegularGridInterpolator
from scipy.ndimage import map_coordinates
from scipy.spatial.transform import Rotation

DEM_SOURCE = Path(__file__).resolve().parents[1] / "data" / "dem" / "SRTMGL3_boulder_front_range.asc"
ORIGIN_LL = (40.03, -105.35)
HALF_M = 4500.0  # the height field and texture span +-HALF_M east and north of the origin
CELL_M = 10.0  # height field posts
TEXEL_M = 2.0
W, H, HFOV_DEG = 640, 360, 32.0
ORBIT_R_M, ABOVE_M, SPEED_MPS = 3000.0, 2500.0, 50.0
TELEMETRY_HZ = 10.0


def K() -> np.ndarray:
    f = (W / 2) / np.tan(np.radians(HFOV_DEG) / 2)
    return np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])


@lru_cache(maxsize=1)
def _posts():
    """The DEM crop (z posts, lat0, lon0 of the first post, dlat < 0, dlon) around the origin."""
    with rasterio.open(DEM_SOURCE) as ds:
        z = ds.read(1).astype(np.float64)
        t = ds.transform
    lat0, lon0, dlat, dlon = t.f + 0.5 * t.e, t.c + 0.5 * t.a, t.e, t.a
    r0 = int((lat0 - (ORIGIN_LL[0] + 0.09)) / -dlat)
    c0 = int(((ORIGIN_LL[1] - 0.11) - lon0) / dlon)
    z = z[r0:r0 + 220, c0:c0 + 270]
    return z, lat0 + r0 * dlat, lon0 + c0 * dlon, dlat, dlon


def write_dem(path: Path, flat: bool = False) -> Path:
    """The DEM crop as a GeoTIFF (EPSG:4326, posts at pixel centres) for eoloc (--vertical ellipsoid);
    ``flat``: every post at the origin's height."""
    z, lat0, lon0, dlat, dlon = _posts()
    if flat:
        z = np.full_like(z, origin()[2])
    tr = from_origin(lon0 - dlon / 2, lat0 - dlat / 2, dlon, -dlat)
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1,
                       dtype="float32", crs="EPSG:4326", transform=tr) as ds:
        ds.write(z.astype(np.float32), 1)
    return path


@lru_cache(maxsize=1)
def _dem_interp() -> RegularGridInterpolator:
    z, lat0, lon0, dlat, dlon = _posts()
    z32 = z.astype(np.float32).astype(np.float64)  # what the GeoTIFF holds
    lats = lat0 + dlat * np.arange(z.shape[0])
    lons = lon0 + dlon * np.arange(z.shape[1])
    return RegularGridInterpolator((lats[::-1], lons), z32[::-1], method="linear")


def dem_height(lat, lon, flat: bool = False) -> np.ndarray:
    lat, lon = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float))
    if flat:
        return np.full(lat.shape, origin()[2])
    return _dem_interp()(np.stack([lat, lon], -1)).reshape(lat.shape)


@lru_cache(maxsize=1)
def origin() -> tuple[float, float, float]:
    return ORIGIN_LL[0], ORIGIN_LL[1], float(dem_height(*ORIGIN_LL))


@lru_cache(maxsize=2)
def height_field(flat: bool = False) -> np.ndarray:
    """U[i, j]: the terrain's ENU up (m) at east = -HALF + j CELL, north = HALF - i CELL (row 0
    north). Each post is the DEM surface point whose ENU east/north are the post's (two fixed-point
    steps on the horizontal offset a vertical makes away from the origin)."""
    n = int(2 * HALF_M / CELL_M) + 1
    e = -HALF_M + CELL_M * np.arange(n)
    nn = HALF_M - CELL_M * np.arange(n)
    E, N = np.meshgrid(e, nn)
    qe, qn = E.copy(), N.copy()
    o = origin()
    for _ in range(2):
        lat, lon, _ = pymap3d.enu2geodetic(qe, qn, 0.0, *o)
        h = dem_height(lat, lon, flat)
        e2, n2, u2 = pymap3d.geodetic2enu(lat, lon, h, *o)
        qe, qn = qe + (E - e2), qn + (N - n2)
    return u2.astype(np.float64)


@lru_cache(maxsize=1)
def texture(seed: int = 11) -> np.ndarray:
    """Smooth grey noise (three scales) at TEXEL_M, uint8, row 0 north."""
    rng = np.random.default_rng(seed)
    n = int(2 * HALF_M / TEXEL_M)
    img = np.zeros((n, n), np.float32)
    for sigma_m, weight in ((60.0, 1.0), (20.0, 0.8), (7.0, 0.6)):
        m = int(n * TEXEL_M / (sigma_m / 3.0))  # noise blurred at a third of its scale, then enlarged
        noise = cv2.GaussianBlur(rng.normal(size=(m, m)).astype(np.float32), (0, 0), 3.0)
        img += weight * cv2.resize(noise, (n, n), interpolation=cv2.INTER_CUBIC) / noise.std()
    img -= img.mean()
    img /= img.std() * 3.0
    return np.clip(128 + 80 * img, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class Errors:
    mount_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # about body x, y, z
    heading_bias_deg: float = 0.0
    time_offset_s: float = 0.0
    position_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the GPS reads this far east, north, up


@dataclass(frozen=True)
class Flight:
    """An orbit (clockwise seen from above) or, with ``straight``, a straight pass north-east (the
    turret fixed, looking right and down); ``flat``: the ground a plane at the origin's height."""

    straight: bool = False
    flat: bool = False
    scan_m: float = 700.0  # the turret's scan about the orbit's centre
    gusts: bool = True

    def state(self, t):
        """Aircraft (lat, lon, h, yaw, pitch, roll) and the aim point (ENU (3,)) at video time t."""
        t = np.asarray(t, dtype=float)
        o = origin()
        if self.straight:
            e = -3500.0 + SPEED_MPS * t * np.sin(np.radians(45.0))
            n = -2500.0 + SPEED_MPS * t * np.cos(np.radians(45.0))
            yaw = np.full_like(t, 45.0)
            bank = np.zeros_like(t)
            aim_e = e + 2500 * np.cos(np.radians(45.0))
            aim_n = n - 2500 * np.sin(np.radians(45.0))
        else:
            w = SPEED_MPS / ORBIT_R_M
            a = np.pi / 2 - w * t  # clockwise: the angle from east decreases
            e, n = ORBIT_R_M * np.cos(a), ORBIT_R_M * np.sin(a)
            yaw = np.degrees(np.arctan2(np.sin(a), -np.cos(a))) % 360.0  # track: the tangent, clockwise
            bank = np.degrees(np.arctan(SPEED_MPS ** 2 / (9.80665 * ORBIT_R_M))) + 0 * t
            aim_e = self.scan_m * np.sin(2 * np.pi * t / 40.0)
            aim_n = 0.7 * self.scan_m * np.sin(2 * np.pi * t / 23.0 + 1.0)
        gust = 1.0 if self.gusts else 0.0
        roll = bank + gust * 3.0 * np.sin(2 * np.pi * t / 7.0)
        pitch = 2.0 + gust * 1.5 * np.sin(2 * np.pi * t / 5.0 + 0.3)
        yaw = yaw + gust * 1.0 * np.sin(2 * np.pi * t / 9.0)
        up = o[2] + ABOVE_M
        lat, lon, h = pymap3d.enu2geodetic(e, n, up - o[2], *o)
        aim_lat, aim_lon, _ = pymap3d.enu2geodetic(aim_e, aim_n, 0.0, *o)
        aim_h = dem_height(aim_lat, aim_lon, self.flat)
        return np.asarray(lat), np.asarray(lon), np.asarray(h), yaw, pitch, roll, (aim_lat, aim_lon, aim_h)


def _r_ecef_ned(lat, lon) -> np.ndarray:
    sl, cl, so, co = np.sin(np.radians(lat)), np.cos(np.radians(lat)), np.sin(np.radians(lon)), np.cos(np.radians(lon))
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


def _r_ecef_enu(lat, lon) -> np.ndarray:
    sl, cl, so, co = np.sin(np.radians(lat)), np.cos(np.radians(lat)), np.sin(np.radians(lon)), np.cos(np.radians(lon))
    return np.array([[-so, -sl * co, cl * co], [co, -sl * so, cl * so], [0.0, cl, sl]])


def true_camera(flight: Flight, err: Errors, t: float):
    """The camera at video time t: (position ECEF (3,), R_ecef_cam (3, 3)) and the turret's
    encoder angles (az, el) that point it at the aim point through the mounting error."""
    lat, lon, h, yaw, pitch, roll, (alat, alon, ah) = flight.state(t)
    c = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    a = np.array(pymap3d.geodetic2ecef(alat, alon, ah))
    R_en = _r_ecef_ned(lat, lon)
    R_nb = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()
    mx, my, mz = err.mount_deg
    R_mount = Rotation.from_euler("ZYX", [mz, my, mx], degrees=True).as_matrix()
    b = R_mount.T @ R_nb.T @ R_en.T @ (a - c)
    b /= np.linalg.norm(b)
    az, el = np.degrees(np.arctan2(b[1], b[0])), np.degrees(np.arcsin(-b[2]))
    G = Rotation.from_euler("ZYX", [az, el, 0.0], degrees=True).as_matrix()
    R_ec = R_en @ R_nb @ R_mount @ G[:, [1, 2, 0]]
    return c, R_ec, float(az), float(el)


def render(flight: Flight, err: Errors, t: float) -> np.ndarray:
    """The frame (H, W) uint8 at video time t: first crossing of each pixel's ray with the terrain."""
    c_ecef, R_ec, _, _ = true_camera(flight, err, t)
    return render_view(c_ecef, R_ec, K(), (W, H), flight.flat)


def photo_camera(lat: float, lon: float, h: float, yaw: float, pitch: float, roll: float):
    """(position ECEF, R_ecef_cam) of a drone camera whose earth-referenced attitude is yaw (the
    optical axis' azimuth), pitch (its elevation) and roll (the image's): R_ned<-camera body =
    Rz(yaw) Ry(pitch) Rx(roll), the optical axis along the body's x (camera x, y, z = body y, z, x)."""
    c = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    R_nb = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()
    return c, _r_ecef_ned(lat, lon) @ R_nb[:, [1, 2, 0]]


def render_view(c_ecef: np.ndarray, R_ec: np.ndarray, k: np.ndarray, size: tuple[int, int],
                flat: bool = False) -> np.ndarray:
    """The image (h, w) uint8 of a pinhole camera k at c_ecef with attitude R_ecef_cam."""
    o = origin()
    R_ue = _r_ecef_enu(o[0], o[1]).T  # ECEF -> origin ENU
    c = np.array(pymap3d.ecef2enu(*c_ecef, *o))
    uu, vv = np.meshgrid(np.arange(size[0], dtype=float), np.arange(size[1], dtype=float))
    los = np.stack([(uu - k[0, 2]) / k[0, 0], (vv - k[1, 2]) / k[1, 1], np.ones_like(uu)], -1)
    d = los @ (R_ue @ R_ec).T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    U = height_field(flat)
    U32 = U.astype(np.float32)
    lo, hi = float(U.min()) - 1.0, float(U.max()) + 1.0

    def col_row(p):
        return (p[..., 0] + HALF_M) / CELL_M, (HALF_M - p[..., 1]) / CELL_M

    def gap_fast(s):
        p = c + s[..., None] * d
        x, y = col_row(p)
        return p[..., 2] - cv2.remap(U32, x.astype(np.float32), y.astype(np.float32), cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REPLICATE)

    def gap(s):
        p = c + s[..., None] * d
        x, y = col_row(p)
        return p[..., 2] - map_coordinates(U, [y, x], order=1, mode="nearest")

    dz = np.minimum(d[..., 2], -1e-6)
    s0, s1 = (c[2] - hi) / -dz, (c[2] - lo) / -dz
    steps = 32
    found = np.zeros(d.shape[:2], bool)
    a_s, b_s = np.zeros(d.shape[:2]), np.zeros(d.shape[:2])
    prev_s, prev_g = s0, gap_fast(s0)
    for i in range(1, steps + 1):
        s = s0 + (s1 - s0) * i / steps
        g = gap_fast(s)
        new = ~found & (g <= 0) & (prev_g > 0)
        a_s[new], b_s[new] = prev_s[new], s[new]
        found |= new
        prev_s, prev_g = s, g
    a_s, b_s = np.where(found, a_s, s0), np.where(found, b_s, s1)
    ga, gb = gap(a_s), gap(b_s)
    s = a_s
    for _ in range(30):  # regula falsi (Illinois) on the exact surface, bracket kept
        s = a_s + (b_s - a_s) * ga / np.where(ga - gb != 0, ga - gb, 1.0)
        gs = gap(s)
        if np.nanmax(np.abs(gs[found])) < 1e-4:
            break
        low = gs <= 0
        b_s, gb, ga = np.where(low, s, b_s), np.where(low, gs, gb), np.where(low, ga * 0.5, gs)
        a_s = np.where(low, a_s, s)
        gb = np.where(low, gb, gb * 0.5)
    p = c + s[..., None] * d
    tex = texture()
    tx = ((p[..., 0] + HALF_M) / TEXEL_M - 0.5).astype(np.float32)
    ty = ((HALF_M - p[..., 1]) / TEXEL_M - 0.5).astype(np.float32)
    img = cv2.remap(tex, tx, ty, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    img[~found] = 0
    return img


def write_reference(path: Path, cell_m: float = 2.5, half_m: float = 3800.0) -> Path:
    """An orthophoto of the scene's ground as a GeoTIFF in UTM 13N (EPSG:32613), cells of cell_m
    over +-half_m around the origin: each cell centre through pyproj to latitude/longitude, onto
    the DEM's surface, into the origin's ENU (pymap3d), the texture read there."""
    from pyproj import Transformer

    o = origin()
    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32613", always_xy=True).transform(o[1], o[0])
    n = int(2 * half_m / cell_m)
    left, top = x0 - half_m, y0 + half_m
    xs = left + (np.arange(n) + 0.5) * cell_m
    ys = top - (np.arange(n) + 0.5) * cell_m
    X, Y = np.meshgrid(xs, ys)
    lon, lat = Transformer.from_crs("EPSG:32613", "EPSG:4326", always_xy=True).transform(X, Y)
    e, nn, _ = pymap3d.geodetic2enu(lat, lon, dem_height(lat, lon), *o)
    tx = ((e + HALF_M) / TEXEL_M - 0.5).astype(np.float32)
    ty = ((HALF_M - nn) / TEXEL_M - 0.5).astype(np.float32)
    img = cv2.remap(texture(), tx, ty, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="uint8", crs="EPSG:32613",
                       transform=from_origin(left, top, cell_m, cell_m)) as ds:
        ds.write(img, 1)
    return path


def telemetry_rows(flight: Flight, err: Errors, t_end_s: float) -> list[dict]:
    """The telemetry as recorded: records every 1/TELEMETRY_HZ s on the telemetry clock from
    -1 s to t_end_s + 1 s; the record stamped T is the state at video time T - offset, its yaw
    reading heading_bias too high, the turret's encoder angles."""
    rows = []
    for T in np.arange(-1.0, t_end_s + 1.0 + 1e-9, 1.0 / TELEMETRY_HZ):
        tv = T - err.time_offset_s
        lat, lon, h, yaw, pitch, roll, _ = flight.state(tv)
        _, _, az, el = true_camera(flight, err, tv)
        if any(err.position_enu_m):  # measured = true + bias, in the aircraft's own ENU
            lat, lon, h = pymap3d.enu2geodetic(*err.position_enu_m, float(lat), float(lon), float(h))
        rows.append({"time_s": round(float(T), 6), "lat_deg": float(lat), "lon_deg": float(lon), "h_m": float(h),
                     "yaw_deg": float((yaw + err.heading_bias_deg) % 360.0), "pitch_deg": float(pitch),
                     "roll_deg": float(roll), "azimuth_deg": az, "elevation_deg": el})
    return rows


def ground_truth_points(flight: Flight, err: Errors, t: float, n: int, rng: np.random.Generator):
    """n pixels of the frame at time t and the true ground points (lat, lon, h) they see."""
    c_ecef, R_ec, _, _ = true_camera(flight, err, t)
    u = rng.uniform(40, W - 40, n)
    v = rng.uniform(30, H - 30, n)
    return u, v, ground_points(c_ecef, R_ec, K(), u, v, flight.flat)


def ground_points(c_ecef: np.ndarray, R_ec: np.ndarray, k: np.ndarray, u: np.ndarray, v: np.ndarray,
                  flat: bool = False) -> np.ndarray:
    """(n, 3) lat, lon, h where pixels (u, v) of the camera see the DEM's bilinear surface: the first
    crossing of each ray by dense steps, then bisection, in geodetic terms (pymap3d); NaN: none."""
    n = len(u)
    los = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones(n)], -1)
    d = los @ R_ec.T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    s = np.linspace(50.0, 12000.0, 4800)
    out = np.full((n, 3), np.nan)
    for i in range(n):
        q = c_ecef + s[:, None] * d[i]
        lat, lon, h = pymap3d.ecef2geodetic(q[:, 0], q[:, 1], q[:, 2])
        g = h - dem_height(lat, lon, flat)
        j = np.flatnonzero(g <= 0)
        if j.size == 0 or j[0] == 0:
            continue
        a, b = s[j[0] - 1], s[j[0]]
        for _ in range(50):
            m = 0.5 * (a + b)
            la, lo, hh = pymap3d.ecef2geodetic(*(c_ecef + m * d[i]))
            if hh - dem_height(la, lo, flat) > 0:
                a = m
            else:
                b = m
        out[i] = pymap3d.ecef2geodetic(*(c_ecef + 0.5 * (a + b) * d[i]))
    return out
