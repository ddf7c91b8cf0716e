"""A video of vehicles driving on flat textured ground, rendered without eoloc.

The ground is a plane in the local ENU frame of ``ORIGIN`` (pymap3d), painted with smooth colour
noise; the vehicles are rectangles driving straight at constant speed. Each frame is the ground
seen through a pinhole camera (OpenCV conventions: x right, y down, z forward, pixel centres at
integers) flying east and staring at the scene's middle: the plane's image is a homography,
drawn with ``cv2.warpPerspective``. The camera's telemetry for eoloc (position and turret angles
of a level aircraft) is derived from the same pose with pymap3d, in the aircraft's own local
frame. Against eoloc's ellipsoidal ground at the origin's height the plane differs by d^2 / 2R:
at most 0.1 m over the scene (state tolerances above that).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pymap3d

ORIGIN = (40.02, -105.27, 1600.0)
TEXEL_M = 0.5
HALF_M = 700.0  # the ground spans +-HALF_M east and north
W, H, HFOV_DEG = 640, 360, 30.0
FPS = 10.0


@dataclass(frozen=True)
class Vehicle:
    e0_m: float
    n0_m: float
    heading_deg: float
    speed_mps: float
    length_m: float = 6.0
    width_m: float = 3.0
    colour: tuple[int, int, int] = (250, 230, 40)

    def centre(self, t_s):
        h = np.radians(self.heading_deg)
        d = self.speed_mps * np.asarray(t_s, dtype=float)
        return self.e0_m + d * np.sin(h), self.n0_m + d * np.cos(h)

    def corners(self, t_s: float) -> np.ndarray:
        e, n = self.centre(t_s)
        h = np.radians(self.heading_deg)
        fwd, right = np.array([np.sin(h), np.cos(h)]), np.array([np.cos(h), -np.sin(h)])
        a, b = self.length_m / 2, self.width_m / 2
        return np.array([[e, n] + s * a * fwd + r * b * right for s, r in ((1, 1), (1, -1), (-1, -1), (-1, 1))])


CARS = [Vehicle(-100, 20, 90, 12), Vehicle(50, -80, 10, 8), Vehicle(120, 100, 225, 15)]
START_UNIX_S = 1_784_044_800.0  # 2026-07-14 16:00:00 UTC: the KLV's time stamp of t = 0


def ground_texture(seed: int = 7) -> np.ndarray:
    """Smooth colour noise (three scales), uint8 (N, N, 3); row 0 is the north edge."""
    rng = np.random.default_rng(seed)
    n = int(2 * HALF_M / TEXEL_M)
    img = np.zeros((n, n, 3), np.float32)
    for sigma_m, weight in ((40.0, 1.0), (8.0, 0.6), (2.0, 0.35)):
        noise = rng.normal(size=(n, n, 3)).astype(np.float32)
        img += weight * cv2.GaussianBlur(noise, (0, 0), sigma_m / TEXEL_M) * (sigma_m / TEXEL_M)
    img -= img.mean(axis=(0, 1))
    img /= img.std(axis=(0, 1)) * 3.5
    return np.clip(110 + 60 * img, 0, 255).astype(np.uint8)


def K() -> np.ndarray:
    f = (W / 2) / np.tan(np.radians(HFOV_DEG) / 2)
    return np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])


def camera_enu(t_s: float, *, alt_m: float = 800.0, speed_mps: float = 40.0, stand_off_m: float = 800.0):
    """The camera at time t: position (3,) in ENU and R_cam_enu (3, 3), rows the camera axes
    x right, y down, z boresight; flying east, looking at the scene's middle from the south."""
    c = np.array([-160.0 + speed_mps * t_s, -stand_off_m, alt_m])
    z = -c / np.linalg.norm(c)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return c, np.stack([x, y, z])


def paint(texture: np.ndarray, vehicles: list[Vehicle], t_s: float) -> np.ndarray:
    """The ground texture with the vehicles drawn where they are at time t (anti-aliased)."""
    tex = texture.copy()
    for v in vehicles:
        cr = v.corners(t_s)
        cols = (cr[:, 0] + HALF_M) / TEXEL_M - 0.5
        rows = (HALF_M - cr[:, 1]) / TEXEL_M - 0.5
        pts = np.round(np.stack([cols, rows], -1) * 16).astype(np.int32)
        cv2.fillConvexPoly(tex, pts, v.colour, lineType=cv2.LINE_AA, shift=4)
    return tex


def warp_texture(tex: np.ndarray, t_s: float, **cam) -> np.ndarray:
    """Frame at time t (uint8 (H, W, 3)): the painted plane through the camera (a homography)."""
    c, R = camera_enu(t_s, **cam)
    plane = K() @ np.column_stack([R[:, 0], R[:, 1], -R @ c])
    texel = np.array([[TEXEL_M, 0, -HALF_M + 0.5 * TEXEL_M], [0, -TEXEL_M, HALF_M - 0.5 * TEXEL_M], [0, 0, 1.0]])
    return cv2.warpPerspective(tex, plane @ texel, (W, H), flags=cv2.INTER_LINEAR)


def render(texture: np.ndarray, vehicles: list[Vehicle], t_s: float, **cam) -> np.ndarray:
    """Frame at time t: the textured plane with the vehicles through the camera."""
    return warp_texture(paint(texture, vehicles, t_s), t_s, **cam)


def telemetry(t_s: float, **cam) -> dict:
    """The camera's pose as eoloc takes it: a level aircraft at the camera (geodetic, pymap3d) with
    an az-el turret (azimuth from north, elevation below the horizon negative, sensor roll), the
    angles measured in the aircraft's own local frame."""
    c, R = camera_enu(t_s, **cam)
    lat, lon, h = pymap3d.enu2geodetic(*c, *ORIGIN)
    axes = []
    for vec in (R[2], R[0]):  # boresight and image-right, from the origin's ENU to the aircraft's
        u, v, w = pymap3d.enu2uvw(*vec, ORIGIN[0], ORIGIN[1])
        axes.append(np.array(pymap3d.uvw2enu(u, v, w, lat, lon)))
    b, right = axes
    az = np.degrees(np.arctan2(b[0], b[1]))
    el = np.degrees(np.arcsin(b[2]))
    level_right = np.array([np.cos(np.radians(az)), -np.sin(np.radians(az)), 0.0])
    y_down = np.cross(b, level_right)
    roll = np.degrees(np.arctan2(np.dot(right, y_down), np.dot(right, level_right)))
    return {"lat_deg": float(lat), "lon_deg": float(lon), "h_m": float(h), "az_deg": float(az),
            "el_deg": float(el), "roll_deg": float(roll)}


def truth_geodetic(vehicle: Vehicle, t_s) -> tuple[np.ndarray, np.ndarray]:
    e, n = vehicle.centre(t_s)
    lat, lon, _ = pymap3d.enu2geodetic(e, n, np.zeros_like(np.asarray(e, float)), *ORIGIN)
    return np.asarray(lat), np.asarray(lon)


def in_view(vehicle: Vehicle, t_s: float, margin_px: float = 8.0, **cam) -> bool:
    c, R = camera_enu(t_s, **cam)
    e, n = vehicle.centre(t_s)
    p = K() @ (R @ (np.array([e, n, 0.0]) - c))
    u, v = p[:2] / p[2]
    return bool(margin_px <= u <= W - 1 - margin_px and margin_px <= v <= H - 1 - margin_px)


def klv_packets(n: int) -> list[tuple[bytes, float]]:
    """The camera's telemetry at FPS as ST 0601 packets (eoloc's encoder; their values are checked
    against stanag4609 in tests/unit/io/klv), one per frame: (packet, time s)."""
    from datetime import UTC, datetime

    from eoloc.io.klv.encode import encode_uas_packet

    vfov = float(np.degrees(2 * np.arctan((H / 2) / K()[1, 1])))
    out = []
    for i in range(n):
        t = i / FPS
        tel = telemetry(t)
        values = {2: datetime.fromtimestamp(START_UNIX_S + t, UTC), 5: 0.0, 6: 0.0, 7: 0.0, 13: tel["lat_deg"],
                  14: tel["lon_deg"], 75: tel["h_m"], 16: HFOV_DEG, 17: vfov, 18: tel["az_deg"] % 360,
                  19: tel["el_deg"], 20: tel["roll_deg"] % 360}
        out.append((encode_uas_packet(values), t))
    return out


def draw_buildings(image: np.ndarray, buildings: list[tuple], t: float) -> np.ndarray:
    """The frame at time t with box buildings (east, north, half width m, height m) standing on the
    ground, drawn far to near (walls, then the roof): what the ground model does not know."""
    import cv2

    c, R = camera_enu(t)
    img = image.copy()

    def px(p):
        q = K() @ (R @ (np.asarray(p, float) - c))
        return q[:2] / q[2]

    for e, n, half, h in sorted(buildings, key=lambda b: -np.hypot(b[0] - c[0], b[1] - c[1])):
        base = [(e - half, n - half), (e + half, n - half), (e + half, n + half), (e - half, n + half)]
        walls = sorted(range(4), key=lambda k: -np.hypot(*(np.mean([base[k], base[(k + 1) % 4]], 0) - c[:2])))
        for k in walls:
            a, b = base[k], base[(k + 1) % 4]
            quad = np.array([px((*a, 0.0)), px((*b, 0.0)), px((*b, h)), px((*a, h))])
            cv2.fillConvexPoly(img, np.round(quad * 16).astype(np.int32), (95 + 12 * k,) * 3, cv2.LINE_AA, 4)
        roof = np.array([px((*q, h)) for q in base])
        cv2.fillConvexPoly(img, np.round(roof * 16).astype(np.int32), (200, 200, 205), cv2.LINE_AA, 4)
    return img


def surface_model(buildings: list[tuple], path):
    """A digital surface model of the scene (GeoTIFF, 1 m cells, ellipsoidal heights): the flat
    ground with the buildings standing on it (cell centres inside a footprint at its roof height),
    georeferenced through pymap3d at the scene's origin."""
    import rasterio
    from rasterio.transform import from_origin

    n = int(2 * HALF_M)
    e, nn = np.meshgrid(np.arange(n) - HALF_M + 0.5, HALF_M - 0.5 - np.arange(n))
    z = np.full((n, n), ORIGIN[2], np.float32)
    for be, bn, half, h in buildings:
        z[(np.abs(e - be) <= half) & (np.abs(nn - bn) <= half)] = ORIGIN[2] + h
    lat0, lon0, _ = pymap3d.enu2geodetic(-HALF_M, HALF_M, 0.0, *ORIGIN)
    lat1, lon1, _ = pymap3d.enu2geodetic(HALF_M, -HALF_M, 0.0, *ORIGIN)
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32", crs="EPSG:4326",
                       transform=from_origin(lon0, lat0, (lon1 - lon0) / n, (lat0 - lat1) / n)) as f:
        f.write(z[None])
    return path
