"""Movers: the motion detector's blobs located on the ground and tracked there.

Each blob's reference pixel is located with its frame's pose by the job's stop rule (the same
rays and kernels as every fix). The fixes go to constant-velocity Kalman tracks in local ENU
(:class:`eoloc.sequence.track.Tracker`, gated global nearest neighbour on the ground: the
camera's motion plays no part in the association). A fix's sigma per axis is the telemetry's
frame-to-frame error (``tracker.meas_sigma_m``) and a quarter of the blob's size on the ground, together
(half of it for a blob found from one side only, at the ends of a target's time in view; a blob
the image's edge cuts, whose centroid is not the target's, EDGE_SIGMA_M). The
tracks of the movers are smoothed at the end (Rauch–Tung–Striebel: each position, speed and
heading given all of the track's fixes).

A track is a mover when it was updated at least ``tracker.confirm_hits`` times over at least
``min_track_s`` seconds, in at least ``min_hit_ratio`` of the frames it spans (a target is seen
in most frames; stray false blobs strung together are not), and its median smoothed speed is
at least ``min_speed_mps``; a track that goes ``tracker.max_coast_s`` without a blob ends
(shorter occlusions keep its id). Blobs of tracks that are not movers (parallax, noise) are
dropped, and counted.

With an error budget each detection's fix also carries its absolute uncertainty (sigma_e/n/u_m,
CEP50, CE90, LE90, the ellipse): the telemetry's errors through the ray
(:func:`eoloc.accuracy.covariance.locate_with_covariance`, as every other fix) and, on top, the
blob's own centroid error on the ground (the same quarter of its size as above, EDGE_SIGMA_M for
a blob the edge cuts) in east and north; CoT's ce/le come from them.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .. import geodesy
from ..accuracy.budget import ErrorBudget
from ..accuracy.covariance import covariance_columns, locate_with_covariance
from ..result import Status
from ..rules import StopRule, locate
from ..sensor.model import Pose, SensorModel
from ..sequence.track import Track, Tracker, TrackerConfig, TrackSet, smooth_track
from .motion import Blobs

EDGE_SIGMA_M = 30.0  # the position sigma of a blob the image's edge cuts
RECENT = 64  # the online decision's speed: the median over a track's last this many updates
FRAMES_KEPT = 1 << 17  # frame times a live tracker keeps (over an hour at 30 frames/s)
SIDES = {0: "both", -1: "before", 1: "after"}  # which reference frames a detection differs from


def mover_tracker_config() -> TrackerConfig:
    """The tracker's settings for movers: frame-to-frame fix noise 3 m per axis, manoeuvring
    vehicles (white acceleration 1 m^2/s^3), confirmed after 5 updates, ended after 1.5 s unseen."""
    return TrackerConfig(accel_psd=1.0, meas_sigma_m=3.0, init_speed_sigma_mps=40.0, confirm_hits=5, max_coast_s=1.5)


@dataclass(frozen=True)
class MoverSettings:
    """What makes a track a mover (see the module notes): min_speed_mps (m/s, 0 keeps standing
    targets), min_track_s (s), min_hit_ratio (its detections / the frames it spans); ``tracker``:
    the Kalman tracker's own settings (its meas_sigma_m is the fixes' frame-to-frame noise)."""

    min_speed_mps: float = 2.0
    min_track_s: float = 1.0
    min_hit_ratio: float = 0.5
    tracker: TrackerConfig = field(default_factory=mover_tracker_config)

    def __post_init__(self) -> None:
        if not self.min_speed_mps >= 0:
            raise ValueError(f"MoverSettings.min_speed_mps must be >= 0, got {self.min_speed_mps!r}")
        if not self.min_track_s > 0:
            raise ValueError(f"MoverSettings.min_track_s must be > 0, got {self.min_track_s!r}")
        if not 0 < self.min_hit_ratio <= 1:
            raise ValueError(f"MoverSettings.min_hit_ratio must be in (0, 1], got {self.min_hit_ratio!r}")


@dataclass
class Movers:
    """The result: one row per detection of a mover (frame, time, track id, pixel, box, area,
    ground point, filtered speed and heading), the tracks (confirmed movers, ids 1..n in order of
    appearance), their ENU origin, and what was dropped."""

    rows: list[dict]
    tracks: list[Track]
    origin: tuple[float, float, float] | None
    blobs: int = 0
    not_located: int = 0
    dropped_tracks: int = 0
    dropped_blobs: int = 0

    def track_set(self) -> TrackSet:
        return TrackSet(self.tracks, np.zeros(0, dtype=object), self.origin or (0.0, 0.0, 0.0))


@dataclass
class MoverTracker:
    """Blobs of each frame in time order (:meth:`add`), the movers at the end (:meth:`result`)."""

    rule: StopRule
    settings: MoverSettings = field(default_factory=MoverSettings)
    budget: ErrorBudget | None = None  # each fix's absolute uncertainty (see the module notes)
    history: bool = True  # keep every row and track for :meth:`result` (False: a live stream)

    def __post_init__(self) -> None:
        s = self.settings
        self.tracker = Tracker(s.tracker, associate=True)
        self.origin: tuple[float, float, float] | None = None
        self.rows: list[dict] = []
        self.by_track: dict[str, list[int]] = {}
        self.n_blobs = 0
        self.not_located = 0
        self.frame_times: list[float] | deque[float] = [] if self.history else deque(maxlen=FRAMES_KEPT)

    def add(self, blobs: Blobs, sensor: SensorModel, pose: Pose) -> list[dict]:
        """Locate the blobs of one frame with its sensor and pose, and update the tracks; the rows
        of this frame's located blobs (each with its track's key, ``track``). Without ``history``
        (a live stream) neither the rows nor the ended tracks are kept: memory stays bounded."""
        self.n_blobs += len(blobs)
        self.frame_times.append(blobs.time_s)
        new: list[dict] = []
        if not self.history:
            self.tracker.done.clear()
        if not len(blobs):
            self.tracker.frame(blobs.time_s, np.zeros(0, np.intp), np.zeros((0, 3)), np.zeros((0, 2, 2)), None)
            return []
        share = np.where(blobs.side == 0, 1 / 16, 1 / 4)
        centroid2 = np.where(blobs.at_edge, EDGE_SIGMA_M**2, share * blobs.area_m2)
        if self.budget is None:
            f, sigma = locate(sensor, pose, self.rule, (blobs.u_px, blobs.v_px)), None
        else:
            f, cov = locate_with_covariance(sensor, pose, self.budget, (blobs.u_px, blobs.v_px), self.rule)
            sigma = covariance_columns(dataclasses.replace(
                cov, cov_enu=cov.cov_enu + centroid2[:, None, None] * np.diag([1.0, 1.0, 0.0])), f.ok)
        ok = np.asarray(f.ok)
        if self.origin is None and ok.any():
            i = int(np.flatnonzero(ok)[0])
            self.origin = (float(f.lat_deg[i]), float(f.lon_deg[i]), float(f.h_m[i]))
        self.not_located += int((~ok).sum())
        if self.origin is None:
            return new
        z = geodesy.ecef_to_enu(f.p_ecef(), *self.origin)
        # a blob's centroid: within about a quarter of its size
        # (half of it for a blob found from one side only, at the ends of a target's time in view);
        # a blob the image's edge cuts tells where the target is to EDGE_SIGMA_M only
        sig2 = self.settings.tracker.meas_sigma_m**2 + centroid2
        R = sig2[:, None, None] * np.eye(2)
        here = np.flatnonzero(ok)
        for key, j in self.tracker.frame(blobs.time_s, here, z, R, None):
            row = {"frame": blobs.index, "time_s": round(blobs.time_s, 6), "track": key,
                   "u_px": round(float(blobs.u_px[j]), 2), "v_px": round(float(blobs.v_px[j]), 2),
                   **{k: int(b) for k, b in zip(("bbox_u0", "bbox_v0", "bbox_u1", "bbox_v1"), blobs.box[j],
                                                  strict=True)},
                   "area_m2": round(float(blobs.area_m2[j]), 1), "contrast": round(float(blobs.contrast[j]), 1),
                   "compared": SIDES[int(blobs.side[j])],
                   "at_edge": bool(blobs.at_edge[j]),
                   **({} if blobs.label is None else {"class": str(blobs.label[j]),
                                                       "score": round(float(blobs.score[j]), 3)}),
                   "lat_deg": float(f.lat_deg[j]), "lon_deg": float(f.lon_deg[j]), "h_m": round(float(f.h_m[j]), 3),
                   "status": Status(int(f.status[j])).name,
                   **({} if sigma is None else {k: _num(v[j]) for k, v in sigma.items()})}
            new.append(row)
            if self.history:
                self.by_track.setdefault(key, []).append(len(self.rows))
                self.rows.append(row)
        return new

    def is_mover(self, key: str) -> bool:
        """Whether track ``key``, as it stands now, is a mover by the same tests as :meth:`result`
        with what is known so far: confirmed, ``min_track_s`` long, seen in ``min_hit_ratio`` of
        the frames it spans, and its filtered speed (the median over its updates since it was
        confirmed, the Kalman filter's, not yet smoothed) at least ``min_speed_mps``. The online
        decision of a live stream (:mod:`eoloc.live.movers`); :meth:`result` decides again at the
        end with the smoothed tracks."""
        s = self.settings
        lv = self.tracker.live.get(key)
        if lv is None or not lv.track.confirmed:
            return False
        tr = lv.track
        t0, t1 = tr.time_s[0], tr.time_s[-1]
        times = self.frame_times  # in time order
        spanned = bisect.bisect_right(times, t1 + 1e-9) - bisect.bisect_left(times, t0 - 1e-9)
        if t1 - t0 < s.min_track_s - 1e-9 or len(tr.time_s) < s.min_hit_ratio * spanned:
            return False
        n = len(tr.state) - s.tracker.confirm_hits + 1  # since confirmed, the last RECENT updates
        recent = Track(key, [], tr.state[-min(n, RECENT):]) if n > 0 else None
        return recent is not None and float(np.median(recent.speed_mps)) >= s.min_speed_mps

    def now(self, key: str) -> dict[str, float]:
        """Track ``key``'s filtered speed (m/s), its 1-sigma and heading (degrees from north) at
        its last update."""
        tr = self.tracker.live[key].track
        last = Track(key, tr.time_s[-1:], tr.state[-1:], tr.cov[-1:])
        return {"speed_mps": round(float(last.speed_mps[0]), 2),
                "speed_sigma_mps": _num(last.speed_sigma_mps[0]),
                "heading_deg": round(float(last.heading_deg[0]), 1)}

    def result(self) -> Movers:
        s = self.settings
        movers, dropped = [], 0
        times = np.sort(np.asarray(self.frame_times))
        for tr in self.tracker.tracks():
            t0, t1 = tr.time_s[0], tr.time_s[-1]
            spanned = int(np.searchsorted(times, t1 + 1e-9) - np.searchsorted(times, t0 - 1e-9))
            if not (tr.confirmed and t1 - t0 >= s.min_track_s - 1e-9 and len(tr.time_s) >= s.min_hit_ratio * spanned):
                dropped += 1
                continue
            states, covs = smooth_track(tr, s.tracker.accel_psd)
            if np.median(np.hypot(states[:, 2], states[:, 3])) < s.min_speed_mps:
                dropped += 1
                continue
            tr.state, tr.cov = list(states), list(covs)
            movers.append(tr)
        movers.sort(key=lambda tr: tr.time_s[0])
        rows, kept = [], 0
        for n, tr in enumerate(movers, start=1):
            old = tr.track_id
            tr.track_id = str(n)
            speed, hdg, sig = tr.speed_mps, tr.heading_deg, tr.speed_sigma_mps
            for k, i in enumerate(self.by_track[old]):
                r = dict(self.rows[i])
                r.pop("track")
                r = {"frame": r.pop("frame"), "time_s": r.pop("time_s"), "track_id": n, **r,
                     "speed_mps": round(float(speed[k]), 2), "speed_sigma_mps": round(float(sig[k]), 2),
                     "heading_deg": round(float(hdg[k]), 1)}
                rows.append(r)
                kept += 1
        rows.sort(key=lambda r: (r["frame"], r["track_id"]))
        located = len(self.rows)
        return Movers(rows, movers, self.origin, self.n_blobs, self.not_located, dropped, located - kept)


def _num(x) -> float | None:
    """A column's value for a row: 4 decimals, None where there is none."""
    x = float(x)
    return round(x, 4) if math.isfinite(x) else None
