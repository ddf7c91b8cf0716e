"""Tie points: the same ground feature found in several frames (SIFT, ratio test, RANSAC), joined
into tracks over many frames.

Which frames to match is predicted, not tried: each frame's grid of pixels is put on the ground
by the job's stop rule with the current poses and projected into every other frame
(:func:`predicted_overlap`); a frame is matched only with frames that share at least
``min_overlap`` of its view, at most ``partners`` of them, spread over the pass so that the
baselines are long as well as short (the bundle adjustment needs the geometry to differ). No
all-pairs matching: for K frames about K * partners pairs instead of K^2 / 2.

Matching is OpenCV's: SIFT on the frames shrunk to ``work_px`` columns, Lowe's ratio test both
ways (mutual best), then RANSAC on the fundamental matrix (a 3-D scene: no homography). Tracks are
the connected components of the matches (union-find over (frame, keypoint)); a component that
holds two different keypoints of one frame is a mismatch and dropped whole.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel

SIFT_OFFSET_PX = 0.25


@dataclass(frozen=True)
class TieSettings:
    """work_px: frames are shrunk to at most this many columns for features; features: SIFT
    keypoints per frame; ratio: Lowe's ratio test; ransac_px: RANSAC threshold in work pixels;
    min_inliers: a pair with fewer verified matches gives none; min_overlap: the predicted share
    of a frame's view another must see to be matched with it; partners: at most this many frames
    matched with each frame (spread over the frames it overlaps)."""

    work_px: int = 960
    features: int = 1500
    ratio: float = 0.8
    ransac_px: float = 1.0
    min_inliers: int = 15
    min_overlap: float = 0.3
    partners: int = 6

    def __post_init__(self) -> None:
        if not (self.work_px >= 64 and self.features >= 20 and 0 < self.ratio < 1 and self.ransac_px > 0
                and self.min_inliers >= 8 and 0 < self.min_overlap <= 1 and self.partners >= 1):
            raise InputError(f"tie-point settings out of range: {self}")


@dataclass(frozen=True)
class TiePoints:
    """Observations of tracked ground features: ``frame`` (N,) the frame's position in the list
    matched, ``track`` (N,) the feature's id (0..n_tracks-1), ``u_px``/``v_px`` (N,) its pixel in
    the full-size frame; ``pairs`` the frame pairs matched and ``verified`` their verified matches."""

    frame: np.ndarray
    track: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    pairs: list[tuple[int, int]]
    verified: list[int]

    @property
    def n_tracks(self) -> int:
        return int(self.track.max()) + 1 if self.track.size else 0

    def __len__(self) -> int:
        return int(self.frame.size)

    def keep_tracks(self, keep: np.ndarray) -> TiePoints:
        """Only the tracks where ``keep`` (n_tracks,) is True, renumbered 0.. in order."""
        keep = np.asarray(keep, dtype=bool)
        rows = keep[self.track]
        new = np.cumsum(keep) - 1
        return TiePoints(self.frame[rows], new[self.track[rows]], self.u_px[rows], self.v_px[rows], self.pairs,
                         self.verified)


def predicted_overlap(sensors: Sequence[SensorModel], poses: Sequence[Pose], rule: StopRule,
                      grid: tuple[int, int] = (9, 6)) -> np.ndarray:
    """(K, K) share of frame i's view (a grid of its pixels put on the ground by ``rule``) that
    frame j sees inside its image (each frame's sensor and pose), by the current poses; 0 where i
    sees no ground."""
    gx, gy = np.meshgrid(np.linspace(0.05, 0.95, grid[0]), np.linspace(0.05, 0.95, grid[1]))
    k = len(poses)
    ground = np.full((k, gx.size, 3), np.nan)
    for i, (s, p) in enumerate(zip(sensors, poses, strict=True)):
        w, h = s.camera.width, s.camera.height
        f = rule.locate(s, p, np.stack([gx.ravel() * (w - 1), gy.ravel() * (h - 1)], -1))
        ground[i] = np.where(f.ok[:, None], f.p_ecef(), np.nan)
    share = np.zeros((k, k))
    for j, (s, p) in enumerate(zip(sensors, poses, strict=True)):
        w, h = s.camera.width, s.camera.height
        u, v = s.ground_to_image(p, ground)
        with np.errstate(invalid="ignore"):
            inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
        share[:, j] = inside.mean(axis=1)
    return share


def choose_pairs(overlap: np.ndarray, settings: TieSettings) -> list[tuple[int, int]]:
    """Frame pairs (i < j) to match: for each frame, up to ``partners`` later frames among those
    sharing ``min_overlap`` of its view (both ways), evenly spread over them in time (the
    nearest and the farthest first)."""
    k = overlap.shape[0]
    both = np.minimum(overlap, overlap.T) >= settings.min_overlap
    pairs: set[tuple[int, int]] = set()
    for i in range(k):
        later = np.flatnonzero(both[i, i + 1:]) + i + 1
        if later.size == 0:
            continue
        take = later if later.size <= settings.partners else later[
            np.unique(np.round(np.linspace(0, later.size - 1, settings.partners)).astype(int))]
        pairs.update((i, int(j)) for j in take)
    return sorted(pairs)


def keypoints(image: np.ndarray, settings: TieSettings | None = None,
              sift=None) -> tuple[np.ndarray, np.ndarray | None]:
    """SIFT keypoints (n, 2) of ``image`` in its own pixels (u, v; the top-left pixel's centre is
    (0, 0)) and their descriptors (None when there are none)."""
    settings = settings if settings is not None else TieSettings()
    sift = sift if sift is not None else cv2.SIFT_create(nfeatures=settings.features)
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if grey.dtype != np.uint8:
        lo, hi = np.percentile(grey, (0.1, 99.9))
        grey = np.clip((grey - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).astype(np.uint8)
    scale = min(1.0, settings.work_px / grey.shape[1])
    small = grey if scale == 1.0 else cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    kps, desc = sift.detectAndCompute(small, None)
    if not kps:
        return np.zeros((0, 2)), None
    # OpenCV's SIFT reports points a quarter pixel down and right of where they are (its first
    # octave is the image enlarged twice, and the point is halved back without the half-pixel
    # shift): measured by mirroring an image, which moves the points by twice that
    xy = np.array([k.pt for k in kps], dtype=np.float64) - SIFT_OFFSET_PX
    # the shrunk image's pixel centres on the full-size image's (centre of top-left pixel = 0)
    return (xy + 0.5) / scale - 0.5, desc


def mutual_matches(d1: np.ndarray, d2: np.ndarray, ratio: float) -> np.ndarray:
    """Mutual nearest neighbours (L2) passing Lowe's ratio test both ways: (m, 2) indices into the
    descriptor rows d1, d2. All distances at once by one matrix product (BLAS), which is 4x faster
    here than OpenCV's brute-force matcher asked both ways."""
    a, b = np.asarray(d1, np.float32), np.asarray(d2, np.float32)
    if len(a) < 2 or len(b) < 2:
        return np.zeros((0, 2), np.int64)
    sq = np.einsum("ij,ij->i", a, a)[:, None] + np.einsum("ij,ij->i", b, b)[None, :] - 2.0 * (a @ b.T)
    np.maximum(sq, 0.0, out=sq)
    r2 = ratio * ratio

    def best(m: np.ndarray) -> np.ndarray:  # per row: the nearest column if it passes the ratio test, else -1
        j = np.argmin(m, axis=1)
        rows = np.arange(m.shape[0])
        d0 = m[rows, j].copy()
        m[rows, j] = np.inf
        d1_ = m.min(axis=1)
        m[rows, j] = d0
        return np.where(d0 < r2 * d1_, j, -1)

    ab = best(sq)
    ba = best(sq.T)
    i = np.flatnonzero(ab >= 0)
    keep = ba[ab[i]] == i
    return np.stack([i[keep], ab[i[keep]]], -1).astype(np.int64)


def find_tie_points(images: Sequence[np.ndarray], pairs: Sequence[tuple[int, int]],
                    settings: TieSettings = TieSettings()) -> TiePoints:
    """Tie points of ``images`` (full-size frames, RGB or grey) over the frame ``pairs``."""
    sift = cv2.SIFT_create(nfeatures=settings.features)
    wanted = sorted({i for p in pairs for i in p})
    feats = {i: keypoints(images[i], settings, sift) for i in wanted}
    scale = min(1.0, settings.work_px / images[wanted[0]].shape[1]) if wanted else 1.0
    offsets = {}
    n = 0
    for i in wanted:
        offsets[i] = n
        n += feats[i][0].shape[0]
    parent = np.arange(n)

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    used_pairs, verified = [], []
    for i, j in pairs:
        (xy1, d1), (xy2, d2) = feats[i], feats[j]
        if d1 is None or d2 is None or len(xy1) < settings.min_inliers or len(xy2) < settings.min_inliers:
            continue
        m = mutual_matches(d1, d2, settings.ratio)
        if len(m) < settings.min_inliers:
            continue
        _, mask = cv2.findFundamentalMat(xy1[m[:, 0]], xy2[m[:, 1]], cv2.FM_RANSAC,
                                         settings.ransac_px / scale, 0.999)
        if mask is None:
            continue
        m = m[mask.ravel().astype(bool)]
        if len(m) < settings.min_inliers:
            continue
        used_pairs.append((i, j))
        verified.append(len(m))
        for a, b in m:
            ra, rb = root(offsets[i] + int(a)), root(offsets[j] + int(b))
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    frame_of = np.concatenate([np.full(feats[i][0].shape[0], i) for i in wanted]) if wanted else np.zeros(0, int)
    xy = np.concatenate([feats[i][0] for i in wanted]) if wanted else np.zeros((0, 2))
    roots = np.array([root(a) for a in range(n)], dtype=np.int64)
    sizes = np.bincount(roots, minlength=n)
    member = sizes[roots] >= 2
    # a component holding two keypoints of one frame joins different ground points: drop it
    key = roots[member] * (max(len(images), 1)) + frame_of[member]
    uniq, counts = np.unique(key, return_counts=True)
    bad_roots = np.unique(uniq[counts > 1] // max(len(images), 1))
    member &= ~np.isin(roots, bad_roots)
    idx = np.flatnonzero(member)
    _, track = np.unique(roots[idx], return_inverse=True)
    order = np.lexsort((frame_of[idx], track))
    idx, track = idx[order], track[order]
    return TiePoints(frame_of[idx].astype(np.int64), track.astype(np.int64), xy[idx, 0], xy[idx, 1],
                     used_pairs, verified)
