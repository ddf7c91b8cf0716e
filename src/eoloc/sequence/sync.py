"""Video frames paired with their metadata by presentation time.

A frame is shown at its presentation time; the metadata records (KLV packets, telemetry rows)
carry times on some clock. Once the records are put on the frames' clock (:class:`Metadata`:
for KLV in the same transport stream that is the PES presentation time itself, for metadata beside
the video its own time stamps shifted by an offset), each frame's pose is interpolated at its own
time with :func:`eoloc.sequence.interp.interpolate_poses` (position by a spline in ECEF, attitude
by slerp, gimbal angles unwrapped), and every other per-record value (fields of view, the frame
centre's height, UNIX time) linearly. Synchronous carriage (ST 1402: one metadata access unit per
frame, same PTS) gives each frame its own record exactly; asynchronous carriage gives a pose
between the packets around it. A frame outside the records, or in a gap longer than
``max_gap_s``, gets no pose (``ok`` False) and a reason, never a guess.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..sensor.model import Pose
from .interp import Gap, interpolate_poses


@dataclass(frozen=True)
class Metadata:
    """Records on the frames' clock: ``clock_s`` (N,) seconds, ``pose`` (N,), ``values``: other
    per-record numbers (N,) interpolated linearly (e.g. hfov_deg, unix_s), and how the records
    were put on the clock (``source``, said in reports)."""

    clock_s: np.ndarray
    pose: Pose
    values: dict[str, np.ndarray]
    source: str


@dataclass(frozen=True)
class FramePoses:
    """Per frame (F,): presentation time, pose, the linear values, ``ok``, ``reason`` (0 ok, 1
    outside the records, 2 in a gap: :class:`eoloc.sequence.interp.InterpolatedPoses`), the record
    at or before the frame (-1 where not ok), the records' span and gaps (on the frames' clock)."""

    pts_s: np.ndarray
    pose: Pose
    values: dict[str, np.ndarray]
    ok: np.ndarray
    reason: np.ndarray
    record: np.ndarray
    span_s: tuple[float, float]
    gaps: list[Gap]

    def take(self, i: int) -> tuple[Pose, dict[str, float]]:
        """Frame ``i``'s pose (scalars) and values."""
        return self.pose.take(i), {k: float(v[i]) for k, v in self.values.items()}


def poses_at_frames(meta: Metadata, pts_s: ArrayLike, *, max_gap_s: float = 0.5) -> FramePoses:
    """Each frame's pose and values at its presentation time ``pts_s`` (s, the frames' clock)."""
    q = np.asarray(pts_s, dtype=np.float64)
    ip = interpolate_poses(meta.clock_s, meta.pose, q, max_gap_s=max_gap_s)
    values = {}
    for name, v in meta.values.items():
        v = np.asarray(v, dtype=np.float64)
        good = np.isfinite(v) & np.isfinite(meta.clock_s)
        if not good.any():
            values[name] = np.full(q.shape, np.nan)
            continue
        order = np.argsort(meta.clock_s[good], kind="stable")
        t, x = meta.clock_s[good][order], v[good][order]
        keep = np.r_[True, np.diff(t) > 0]  # a repeated time: the first record stands, as for the pose
        values[name] = np.where(ip.ok, np.interp(q, t[keep], x[keep]), np.nan)
    return FramePoses(q, ip.pose, values, ip.ok, ip.reason, ip.record, ip.span_s, ip.gaps)
