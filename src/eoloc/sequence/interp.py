"""Telemetry at frame times: the pose interpolated between GPS/INS records.

Video and telemetry run at different rates and on different clocks. A frame taken at video time
t is matched to telemetry time ``t + time_offset_s`` and the pose there is interpolated:

- position: a cubic spline through the records' ECEF positions (exact for motion with constant
  acceleration, so for a constant-velocity leg it is [Z15]'s dead reckoning);
- attitude: spherical linear interpolation (scipy ``Slerp``) of R_ecef_body between the two
  records, so the heading goes 359° -> 0° the short way and a path through ±90° pitch stays a
  rotation, never an average of Euler angles; R_ned_body is then taken at the interpolated
  position (the local level frame turns as the aircraft moves);
- gimbal angles: linear, unwrapped (an azimuth 359° -> 1° passes through 0°).

No extrapolation and no bridging of gaps: a frame outside the records, or between two records
more than ``max_gap_s`` apart, gets no pose (``ok`` False) and a :class:`Gap` names the two
records, so nothing plausible-but-wrong is produced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from .. import geodesy
from ..errors import InputError
from ..rotation import R_ned_body, euler_from_R_ned_body
from ..sensor.model import Pose


@dataclass(frozen=True)
class Gap:
    """Two consecutive telemetry records (by time) too far apart: their indices in the input."""

    before: int
    after: int
    t_before: float
    t_after: float

    @property
    def length_s(self) -> float:
        return self.t_after - self.t_before


@dataclass(frozen=True)
class InterpolatedPoses:
    """Poses at the query times (NaN where ``ok`` is False), the reason per query (0 ok, 1 outside
    the records, 2 in a gap), the input index of the record at or before each query (-1 where
    not ok), the time span of the usable records (s, telemetry clock), and the gaps among them."""

    pose: Pose
    ok: np.ndarray
    reason: np.ndarray
    record: np.ndarray
    span_s: tuple[float, float]
    gaps: list[Gap]

    OUTSIDE = 1
    IN_GAP = 2


def _unwrap_deg(a: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(np.radians(a)))


def interpolate_poses(time_s: ArrayLike, pose: Pose, t_query: ArrayLike, *, time_offset_s: float = 0.0,
                      max_gap_s: float = 0.5) -> InterpolatedPoses:
    """Pose at each video time ``t_query`` (s) from telemetry records at ``time_s`` (s, any order;
    the pose fields arrays of the same length). ``time_offset_s``: telemetry clock minus video clock."""
    t = np.asarray(time_s, dtype=np.float64)
    q = np.asarray(t_query, dtype=np.float64) + float(time_offset_s)
    if t.ndim != 1:
        raise ValueError(f"time_s must be 1-D, got shape {t.shape}")
    fields = [np.broadcast_to(np.asarray(x, dtype=np.float64), t.shape)
              for x in (pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg, pose.roll_deg,
                        *pose.gimbal_deg, pose.focal_scale)]
    good = np.isfinite(t)
    for f in fields:
        good &= np.isfinite(f)
    order = np.flatnonzero(good)[np.argsort(t[good], kind="stable")]
    ts = t[order]
    keep = np.r_[True, np.diff(ts) > 0]  # a repeated time stamp: the first record stands
    order, ts = order[keep], ts[keep]
    if ts.size < 2:
        raise InputError(f"pose interpolation needs at least two usable telemetry records, got {ts.size}")
    lat, lon, h, yaw, pitch, roll, *gim, zoom = (f[order] for f in fields)
    gaps = [Gap(int(order[i]), int(order[i + 1]), float(ts[i]), float(ts[i + 1]))
            for i in np.flatnonzero(np.diff(ts) > max_gap_s)]

    pos = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
    R_ecef_body = geodesy.R_ecef_ned(lat, lon) @ R_ned_body(yaw, pitch, roll)
    slerp = Slerp(ts, Rotation.from_matrix(R_ecef_body))
    spline = CubicSpline(ts, pos, axis=0)

    inside = (q >= ts[0]) & (q <= ts[-1]) & np.isfinite(q)
    seg = np.clip(np.searchsorted(ts, q, side="right") - 1, 0, ts.size - 2)
    at_record = (q == ts[seg]) | (q == ts[seg + 1])  # a frame at a record's own time needs no bridging
    in_gap = inside & (ts[seg + 1] - ts[seg] > max_gap_s) & ~at_record
    ok = inside & ~in_gap
    qq = np.where(ok, q, ts[0])
    p = spline(qq)
    lat_q, lon_q, h_q = geodesy.ecef_to_geodetic(p[..., 0], p[..., 1], p[..., 2])
    R_ned = np.swapaxes(geodesy.R_ecef_ned(lat_q, lon_q), -1, -2) @ slerp(qq.ravel()).as_matrix().reshape(
        (*qq.shape, 3, 3))
    yaw_q, pitch_q, roll_q = euler_from_R_ned_body(R_ned, warn_gimbal_lock=False)  # ±90°: the same rotation
    g_q = tuple(np.interp(qq, ts, _unwrap_deg(g)) for g in gim)
    zoom_q = np.interp(qq, ts, zoom)  # a zoom lens's focal length, linear between records
    nan = np.float64("nan")
    out = [np.where(ok, x, nan) for x in (lat_q, lon_q, h_q, yaw_q, pitch_q, roll_q, *g_q, zoom_q)]
    reason = np.where(ok, 0, np.where(in_gap, InterpolatedPoses.IN_GAP, InterpolatedPoses.OUTSIDE)).astype(np.int8)
    record = np.where(ok, order[seg], -1)
    return InterpolatedPoses(Pose(*out[:6], tuple(out[6:-1]), out[-1]), ok, reason, record,
                             (float(ts[0]), float(ts[-1])), gaps)
