"""The MISB ST 0601 sensor model: every packet is a pose + a field of view, and pixels are rays.

ST 0601 carries no camera matrix, only the horizontal and vertical fields of view (tags 16, 17)
spanning the whole image, so the image geometry of a packet is a pinhole with
tan(HFOV/2) = (W/2)/fx. The frame centre is the boresight (normalised (0, 0)); the corners are the
outer image corners, normalised (±tan(HFOV/2), ±tan(VFOV/2)) in ST 0601's order 1 upper-left,
2 upper-right, 3 lower-right, 4 lower-left. Everything is vectorised over packets: pose fields
(F,), per-packet points (F, K).

Pure math: the tables come from :mod:`eoloc.io.klv`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from ..result import Fixes
from ..rules import AtHeight, AtRange, StopRule
from ..sensor.camera import Camera
from ..sensor.gimbal import AzElGimbal
from ..sensor.model import Pose, Rays, SensorModel

# ST 0601 corner order in units of the half-FOV tangents (x right, y down in the image)
CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def misb_sensor(mount_misalignment_deg=(0.0, 0.0, 0.0), boresight_misalignment_deg=(0.0, 0.0, 0.0),
                lever_arm_m=(0.0, 0.0, 0.0), camera: Camera | None = None) -> SensorModel:
    """An az-el turret with sensor roll, as ST 0601 describes it (tags 18, 19, 20).

    The camera is a placeholder unless given: rays are built from per-packet normalised
    coordinates, so the intrinsics never enter. A frame's own camera (pixels, a pinhole whose
    fields of view span the image) is given for what works in pixels (orthorectification).
    Installation terms are zero unless a calibration gives them.
    """
    return SensorModel(camera or Camera(2, 2, 1.0, 1.0, 0.5, 0.5), AzElGimbal(), mount_misalignment_deg,
                       boresight_misalignment_deg, lever_arm_m)


def frame_sensor(base: SensorModel, hfov_deg: float, vfov_deg: float | None, width: int, height: int) -> SensorModel:
    """``base`` (its gimbal and installation) with the pinhole of one frame: ``width`` x ``height``
    pixels whose fields of view (degrees, in (0, 180)) span the image (a VMTI frame, a video frame;
    ``vfov_deg`` None: square pixels)."""
    return replace(base, camera=Camera.from_hfov(hfov_deg, width, height, vfov_deg=vfov_deg))


class FrameSensors:
    """The sensors of frames (:func:`frame_sensor` of ``base``, by default :func:`misb_sensor`),
    kept by frame size and fields of view: a stream's fields change now and then, not with every
    frame or packet (at most ``keep`` kept: a stream whose zoom never rests starts over)."""

    def __init__(self, base: SensorModel | None = None, *, keep: int = 64) -> None:
        self.base = base or misb_sensor()
        self.keep = keep
        self.sensors: dict[tuple, SensorModel | None] = {}

    def get(self, width: int, height: int, hfov_deg: float, vfov_deg: float) -> SensorModel | None:
        """The sensor of a ``width`` x ``height`` frame (degrees: tags 16, 17 or the VMTI set's); None
        without a usable horizontal field of view (a vertical one out of (0, 180): square pixels)."""
        key = (width, height, hfov_deg, vfov_deg)
        if key not in self.sensors:
            if len(self.sensors) >= self.keep:
                self.sensors.clear()
            v = vfov_deg if 0 < vfov_deg < 180 else None
            self.sensors[key] = frame_sensor(self.base, hfov_deg, v, width, height) if 0 < hfov_deg < 180 else None
        return self.sensors[key]


def misb_frame_sensor(width: int, height: int, hfov_deg: float, vfov_deg: float) -> SensorModel | None:
    """The ST 0601 sensor of one frame: a pinhole whose fields of view span the image (tags 16,
    17), on the az-el turret with sensor roll; None without a usable field of view."""
    if not (0 < hfov_deg < 180):
        return None
    v = vfov_deg if 0 < vfov_deg < 180 else None
    return misb_sensor(camera=Camera.from_hfov(hfov_deg, width, height, vfov_deg=v))


def packet_pose(tel) -> Pose:
    """Poses (F,) of telemetry rows read from KLV (columns of :func:`eoloc.io.klv.klv_telemetry`)."""
    c = tel.columns
    return Pose(c["lat_deg"], c["lon_deg"], c["h_m"], c["yaw_deg"], c["pitch_deg"], c["roll_deg"],
                (c["gimbal1_deg"], c["gimbal2_deg"], np.nan_to_num(c["sensor_roll_deg"], nan=0.0)))


def _half_tangents(hfov_deg: ArrayLike, vfov_deg: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    hfov, vfov = np.asarray(hfov_deg, dtype=np.float64), np.asarray(vfov_deg, dtype=np.float64)
    bad = ~((hfov > 0) & (hfov < 180) & (vfov > 0) & (vfov < 180))
    with np.errstate(invalid="ignore"):
        tx, ty = np.tan(np.radians(hfov) / 2.0), np.tan(np.radians(vfov) / 2.0)
    return np.where(bad, np.nan, tx), np.where(bad, np.nan, ty)


def packet_rays(sensor: SensorModel, pose: Pose, xn: ArrayLike, yn: ArrayLike) -> Rays:
    """Rays of normalised points (F, K) from the poses (F,) (one row of points per packet)."""
    frame = sensor.camera_frame(pose.take((slice(None), None)) if np.ndim(pose.lat_deg) else pose)
    rays = sensor.rays_from(frame, xn, yn)
    bad = ~(np.isfinite(xn) & np.isfinite(yn))
    return Rays(rays.ox, rays.oy, rays.oz, rays.dx, rays.dy, rays.dz, rays.invalid | bad)


@dataclass(frozen=True)
class FrameGeometry:
    """eoloc's frame centre (F,) and corners (F, 4) for each packet, and the surface used."""

    centre: Fixes
    corners: Fixes
    surface: str


def packet_heights(h_m: ArrayLike) -> AtHeight:
    """The ground of each packet's rays at its own ellipsoidal height (m, (F,), e.g. the encoder's
    frame-centre elevation; NaN: INVALID_INPUT for that packet's rays), for rays shaped (F, K)."""
    h = np.asarray(h_m, dtype=np.float64)
    return AtHeight(h[..., None] if h.ndim else h)


def stop_on(rays: Rays, ground: StopRule, sensor: SensorModel) -> Fixes:
    """Stop rays (…, K) on the ``ground`` rule (values broadcasting against (F, K): OnDEM, AtHeight,
    or :func:`packet_heights`)."""
    return ground.stop(rays, sensor.ellipsoid)


def frame_geometry(sensor: SensorModel, pose: Pose, hfov_deg: ArrayLike, vfov_deg: ArrayLike, ground: StopRule,
                   *, range_m: ArrayLike | None = None) -> FrameGeometry:
    """Frame centre and the four corners of each packet on the ``ground`` rule (OnDEM, or
    :func:`packet_heights` such as the encoder's own frame-centre elevation). With ``range_m`` the
    centre is placed at that slant range along the boresight instead (M1, laser)."""
    tx, ty = _half_tangents(hfov_deg, vfov_deg)
    if range_m is not None:
        centre = frame_centre(sensor, pose, ground, range_m=range_m)
        corners = stop_on(packet_rays(sensor, pose, CORNERS[:, 0] * tx[..., None], CORNERS[:, 1] * ty[..., None]),
                          ground, sensor)
    else:  # the centre and the corners as one batch of five rays per packet
        zero = np.zeros_like(tx)[..., None]
        both = stop_on(packet_rays(sensor, pose, np.concatenate([zero, CORNERS[:, 0] * tx[..., None]], -1),
                                   np.concatenate([zero, CORNERS[:, 1] * ty[..., None]], -1)), ground, sensor)
        arrays = np.broadcast_arrays(both.lat_deg, both.lon_deg, both.h_m, both.range_m, both.status)
        centre = Fixes(*(np.ascontiguousarray(a[..., 0]) for a in arrays)).flat()
        corners = Fixes(*(np.ascontiguousarray(a[..., 1:]) for a in arrays))
    kind = ("DEM" if ground.terrain is not None else "ellipsoid at the frame-centre elevation" if ground.value_shape
            else ground.describe())
    return FrameGeometry(centre, corners, kind)


def frame_centre(sensor: SensorModel, pose: Pose, ground: StopRule | None, *,
                 range_m: ArrayLike | None = None) -> Fixes:
    """Each packet's boresight (F,) stopped on the ``ground`` rule (OnDEM, or
    :func:`packet_heights`), or at ``range_m`` along it when given (then ``ground`` may be None)."""
    zero = np.zeros((*np.shape(pose.lat_deg), 1))
    rays = packet_rays(sensor, pose, zero, zero)
    if range_m is not None:
        return AtRange(np.asarray(range_m, dtype=np.float64)[..., None]).stop(rays, sensor.ellipsoid).flat()
    return stop_on(rays, ground, sensor).flat()
