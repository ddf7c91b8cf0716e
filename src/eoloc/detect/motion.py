"""Moving-target indication in airborne video with the camera's own motion removed.

Each frame is compared with reference frames up to ``window_s`` before and after it, each
warped onto the frame's view through the two poses and the ground (a DEM or a height): a coarse
grid of the frame's pixels is located on the ground (the same rays and stop rules as every fix),
the ground points are projected into the reference frame, and the map is interpolated to every
pixel (:func:`cv2.remap`). What the poses get wrong, a shift of a few pixels, is measured by phase
correlation of the warped reference against the frame and taken out. Ground the reference sees
from behind a ridge (the round trip through its own ground grid lands elsewhere), or at less than
half the frame's resolution (a slope it sees edge-on), is not compared; nor are the cells of the
grid at a step of the surface (a wall or cliff in a DSM: the map interpolated across it would smear).

A pixel has *changed* against a reference where its colour differs by more than ``threshold``
(the largest of the channel differences, 0-255 scale). A mover is where the frame differs from
a reference before it **and** from one after it: the places it has just left (its ghost in the
past references) and is about to reach (in the future ones) differ from one side only, so a
target of length L at speed v is found whole once v * window_s >= L, and its middle from
v * window_s > L / 2 (the smallest speed the detector sees is L / (2 window_s)). Where only one
side sees the ground (the first and last ``window_s`` of a video, ground just entering or
leaving the view), a change is kept where the frame stands out from its surroundings (the
median over ``surround_px``) by more than ``threshold``, and by half of it more than each reference it
differs from does there: the references show
the target's ghosts, where the frame shows plain ground.

Changed pixels are joined (morphological closing, 3 x 3), grouped (connected components,
8-connected, pieces closer than ``join_m`` on the ground together) and kept as blobs whose ground
area lies within [min_area_m2, max_area_m2] (each pixel's ground footprint from the grid). Its
reference pixel is the blob's centroid: the middle
of a target lying on the ground.

What it cannot see, by construction: targets that stand still or move less than half their
length in ``window_s``, targets the colour of the ground under them. What it reports that does
not move (false-alarm sources): tall objects not in the DEM (buildings, trees, masts: their tops
are displaced by parallax as the aircraft moves, about aircraft speed x height / altitude, and
their walls come into and out of view; measured in ``bench/bench_detect.py``: over a town of 30
buildings 10-40 m tall, 17 false movers in 6 s at 40 m/s; given a surface model holding them (a
DSM as the ``rule``), none: the warp goes over the roofs, and the cells at a surface step, where
it would be interpolated across a wall, are not compared — so a target at a wall's foot is not
seen there), DEM errors on steep slopes, moving shadows and water, lighting changes between frames.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geodesy import ecef_to_enu, geodetic_to_ecef
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel

MIN_TARGET_PX = 4.0  # the automatic scale keeps the smallest target this many working pixels
RESOLUTION_RATIO = 2.0  # a reference coarser than this (per axis) where it sees the frame's ground is not used
STEP_RATIO = 0.6  # a surface step: the grid steps either side of a point differ by this share of their lengths


@dataclass(frozen=True)
class MotionSettings:
    """How the motion detector works (see the module notes).

    window_s: references reach this far before and after a frame (s); refs_per_side: how many
    on each side, spread evenly over the window; threshold: the colour difference (0-255) that
    counts as a change; min_area_m2 / max_area_m2: a blob's ground area; grid_px: spacing of
    the grid of pixels located on the ground for the warp; align: take out the residual shift
    of each warp (phase correlation against the frame) when it is at most ``max_shift_px``; occlusion_m: a ground
    point the reference sees elsewhere by more than this (or 3 ground samples) is hidden there;
    scale: work on the frames shrunk by this factor (1: full size; 0.5 quarters the work);
    None: chosen on the first frame, the most shrinking (1, 1/2, 1/4) that leaves the smallest
    target (min_area_m2) MIN_TARGET_PX working pixels at the frame's median ground sample;
    tolerance_px: compare each pixel with the range of
    the reference's neighbourhood this many pixels around (1: edges misregistered by a fraction
    of a pixel are no change, but targets 2-3 pixels wide are lost; 0: the pixel itself);
    surround_px: the box whose median is a pixel's surroundings in the one-sided test; join_m:
    pieces of change closer than this on the ground are one target."""

    window_s: float = 2.0
    refs_per_side: int = 2
    threshold: float = 40.0
    min_area_m2: float = 6.0
    max_area_m2: float = 5000.0
    grid_px: int = 8
    align: bool = True
    max_shift_px: float = 20.0
    occlusion_m: float = 10.0
    scale: float | None = None
    tolerance_px: int = 0
    join_m: float = 4.0
    surround_px: int = 15

    def __post_init__(self) -> None:
        for name in ("window_s", "threshold", "min_area_m2", "max_area_m2", "max_shift_px", "occlusion_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"MotionSettings.{name} must be > 0, got {getattr(self, name)!r}")
        if self.refs_per_side < 1 or self.grid_px < 2:
            raise ValueError("MotionSettings: refs_per_side >= 1 and grid_px >= 2")
        if self.scale is not None and not 0 < self.scale <= 1:
            raise ValueError(f"MotionSettings.scale must be in (0, 1], got {self.scale!r}")
        if self.min_area_m2 >= self.max_area_m2:
            raise ValueError("MotionSettings: min_area_m2 must be below max_area_m2")


@dataclass(frozen=True)
class Blobs:
    """The movers found in one frame: per blob the reference pixel (u_px, v_px; full-size
    image pixels), the box (u0, v0, u1, v1: its first and last pixel columns and rows), its area
    in pixels and on the ground (m^2), its mean colour difference, and which references found it
    (``side``: 0 before and after, -1 only before, +1 only after), and whether it touches the
    image's edge (``at_edge``: cut by it, its centroid is not the target's). ``shifts_px``: per
    reference, the shift (du, dv, working pixels) the poses left and the images measured (NaN:
    none measured); ``compared``: the fraction of the frame's pixels compared on both sides.
    From a learned detector: ``label`` (class names) and ``score`` per box."""

    index: int
    time_s: float
    u_px: np.ndarray
    v_px: np.ndarray
    box: np.ndarray
    area_px: np.ndarray
    area_m2: np.ndarray
    contrast: np.ndarray
    side: np.ndarray
    at_edge: np.ndarray
    shifts_px: np.ndarray
    compared: float
    label: np.ndarray | None = None
    score: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.u_px.size)


@dataclass
class _Frame:
    index: int
    time_s: float
    image: np.ndarray  # working size, uint8 (H, W, C + 1): the colours and an opaque alpha
    sensor: SensorModel
    pose: Pose
    ground: np.ndarray  # (gh, gw, 3) ENU m of the grid's ground points, NaN where none
    pixel_m2: np.ndarray  # (gh, gw) ground area of one working pixel around each grid point
    luma: np.ndarray  # (H', W') float32, shrunk for the residual's phase correlation
    grid32: np.ndarray  # (gh, gw, 4) float32: ground ENU and pixel_m2, for cv2.remap
    p_ecef: np.ndarray  # (gh, gw, 3) the grid's ground points in ECEF m (projected into each reference)
    steps: np.ndarray  # (gh, gw) bool: grid points at a step of the surface (not compared)


class MotionDetector:
    """Feed frames in order (:meth:`push`); each frame's blobs come out once the frames
    ``window_s`` after it have arrived (:meth:`push` returns them), the last ones from
    :meth:`flush`. ``rule``: the stop rule that puts a pixel on the ground (a DEM: occlusion and
    parallax of the terrain taken out). Frames may come with different sensors (zoom)."""

    def __init__(self, rule: StopRule, settings: MotionSettings | None = None) -> None:
        self.rule = rule
        self.s = settings or MotionSettings()
        self.frames: deque[_Frame] = deque()
        self.pending: deque[_Frame] = deque()  # frames still waiting for their future references
        self.origin: tuple[float, float, float] | None = None
        self._cache: dict = {}
        self._pairs: dict[tuple[int, int], tuple[float, float]] = {}  # (frame, reference) -> residual
        self._scale8: tuple[float, float] | None = None  # 16-bit frames: (offset, gain) to 8 bits
        self.scale: float | None = self.s.scale  # the working scale (chosen on the first frame when None)

    # -- the frames ---------------------------------------------------------------------------

    def push(self, index: int, time_s: float, image: np.ndarray, sensor: SensorModel, pose: Pose) -> list[Blobs]:
        """Add frame ``index`` (image (H, W) or (H, W, C) uint8 at full size, its sensor and
        pose, its time in seconds); the blobs of every frame now complete."""
        import cv2

        img = np.asarray(image)
        if img.ndim not in (2, 3) or not np.issubdtype(img.dtype, np.integer):
            raise InputError(f"frame {index}: the motion detector takes integer images (H, W) or (H, W, C), got "
                             f"{img.dtype} {img.shape}")
        if img.dtype != np.uint8:  # e.g. 16-bit thermal: one fixed mapping for the whole video (no AGC):
            if self._scale8 is None:  # the first frame's 0.1..99.9 % to 16..239, headroom for what comes
                lo, hi = (float(x) for x in np.percentile(img, [0.1, 99.9]))
                self._scale8 = (lo, 223.0 / max(hi - lo, 1.0))
            lo, k = self._scale8
            img = np.clip((img.astype(np.float32) - lo) * k + 16.0, 0, 255).astype(np.uint8)
        if self.scale is None:
            self.scale = self._choose_scale(sensor, pose, img.shape[1], img.shape[0])
        if self.scale < 1:
            h, w = img.shape[:2]
            img = cv2.resize(img, (max(2, round(w * self.scale)), max(2, round(h * self.scale))),
                             interpolation=cv2.INTER_AREA)
        luma = self._small_luma(img)
        if img.ndim == 3 and img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2RGBA)  # an opaque alpha: where a warp lands off the frame
        else:
            img = img if img.ndim == 3 else img[..., None]
            img = np.ascontiguousarray(np.concatenate([img, np.full((*img.shape[:2], 1), 255, np.uint8)], -1))
        h, w = img.shape[:2]
        ground, pixel_m2, p_ecef = self._ground_grid(sensor, pose, w, h)
        fr = _Frame(index, float(time_s), img, sensor, pose, ground, pixel_m2, luma,
                    np.dstack([ground, pixel_m2]).astype(np.float32), p_ecef, self._steps(ground))
        self.frames.append(fr)
        self.pending.append(fr)
        out = []
        while self.pending and self.pending[0].time_s + self.s.window_s <= fr.time_s + 1e-9:
            out.append(self._detect(self.pending.popleft()))
        self._forget()
        return out

    def flush(self) -> list[Blobs]:
        """The blobs of the frames still waiting (the end of the video: past references only)."""
        out = [self._detect(f) for f in self.pending]
        self.pending.clear()
        return out

    def _forget(self) -> None:
        oldest = self.pending[0].time_s if self.pending else self.frames[-1].time_s
        while len(self.frames) > 1 and self.frames[0].time_s < oldest - self.s.window_s - 1e-9:
            gone = self.frames.popleft().index
            self._pairs = {k: v for k, v in self._pairs.items() if gone not in k}

    # -- geometry -----------------------------------------------------------------------------

    def _grid(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray, int]:
        """The grid's working pixels (gh, gw) and its spacing: the centre of every block of
        step x step pixels, and a ring of blocks around the image (so that every pixel lies
        between grid points and cv2.resize interpolates the map exactly)."""
        step = max(2, round(self.s.grid_px * (self.scale or 1.0)))
        bw, bh = math.ceil(width / step), math.ceil(height / step)
        u, v = np.meshgrid((np.arange(-1, bw + 1) + 0.5) * step - 0.5, (np.arange(-1, bh + 1) + 0.5) * step - 0.5)
        return u, v, step

    def _ground_grid(self, sensor: SensorModel, pose: Pose, width: int, height: int):
        u, v, step = self._grid(width, height)
        k = self._to_full(width, sensor)
        # the grid's outer ring lies past the image: its rays are taken as they are (a locate
        # would call those pixels OUT_OF_IMAGE)
        xn, yn = sensor.normalized((u * k + (k - 1) / 2, v * k + (k - 1) / 2), focal_scale=pose.focal_scale)
        fixes = self.rule.stop(sensor.rays_from(sensor.camera_frame(pose), xn, yn), sensor.ellipsoid)
        ok = np.asarray(fixes.ok)
        if self.origin is None and ok.any():
            i = np.flatnonzero(ok.ravel())[0]
            self.origin = (float(np.ravel(fixes.lat_deg)[i]), float(np.ravel(fixes.lon_deg)[i]),
                           float(np.ravel(fixes.h_m)[i]))
        if self.origin is None:
            g, p = np.full((*u.shape, 3), np.nan), np.full((*u.shape, 3), np.nan)
        else:
            p = np.stack(geodetic_to_ecef(fixes.lat_deg, fixes.lon_deg, fixes.h_m), -1)
            g = ecef_to_enu(p.reshape(-1, 3), *self.origin).reshape((*u.shape, 3))
            g[~ok] = np.nan
            p[~ok] = np.nan
        # a working pixel's ground area: the grid cell's (cross product of its sides) / step^2
        area = np.linalg.norm(np.cross(np.gradient(g, axis=1), np.gradient(g, axis=0)), axis=-1) / float(step) ** 2
        return g, area, p

    def _steps(self, g: np.ndarray) -> np.ndarray:
        """Grid points at a step of the surface (a wall, a cliff, a ridge hiding the ground behind it):
        where the ground points' second difference along a grid row or column exceeds occlusion_m
        and half the two steps' lengths (a plane or an even slope has none): both points on either
        side of the step are found so. Between grid points the warp is interpolated, which smears
        across a step: the cells around those points are not compared."""
        step = np.zeros(g.shape[:2], bool)
        with np.errstate(invalid="ignore"):
            for axis in (0, 1):
                a, b, c = (np.take(g, range(k, g.shape[axis] - 2 + k), axis=axis) for k in range(3))
                fwd, bwd = c - b, b - a
                d2 = np.linalg.norm(fwd - bwd, axis=-1)
                # a step, not a bend: the two sides differ by more than occlusion_m and by more than
                # half their lengths (an even slope, or terrain bending gently, has nothing of it)
                jump = (d2 > self.s.occlusion_m) & (d2 > STEP_RATIO * (np.linalg.norm(fwd, axis=-1)
                                                                + np.linalg.norm(bwd, axis=-1)))
                if axis == 0:
                    step[1:-1] |= jump
                else:
                    step[:, 1:-1] |= jump
        return step

    def _choose_scale(self, sensor: SensorModel, pose: Pose, width: int, height: int) -> float:
        self.scale = 1.0
        _, pixel_m2, _ = self._ground_grid(sensor, pose, width, height)
        self.origin = None  # set again by the first frame itself
        m2 = float(np.nanmedian(pixel_m2)) if np.isfinite(pixel_m2).any() else math.nan
        for scale in (0.25, 0.5):
            if self.s.min_area_m2 / (m2 / scale**2) >= MIN_TARGET_PX:
                return scale
        return 1.0

    def _to_full(self, width: int, sensor: SensorModel) -> float:
        return sensor.camera.width / width

    def _small_luma(self, img: np.ndarray) -> np.ndarray:
        """The working image's luma, shrunk for the residual (``img``: (H, W) or (H, W, C))."""
        import cv2

        f = self._shrink(img.shape[1])
        if f > 1:
            img = cv2.resize(img, (img.shape[1] // f, img.shape[0] // f), interpolation=cv2.INTER_AREA)
        y = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 and img.shape[2] == 3 else img
        return (y if y.ndim == 2 else y[..., 0]).astype(np.float32)

    @staticmethod
    def _shrink(width: int) -> int:
        """The residual is measured on frames at most 320 pixels wide."""
        return max(1, math.ceil(width / 320))

    def _coarse_map(self, cur: _Frame, ref: _Frame) -> np.ndarray:
        """On ``cur``'s grid (gh, gw, 3) float32: where ``ref`` saw each grid point's ground (u, v
        in ref's working pixels) and whether it could tell there (1/0: both frames see the ground,
        ref not from behind a ridge nor much coarser)."""
        h, w = cur.image.shape[:2]
        _, _, step = self._grid(w, h)
        ur, vr = ref.sensor.ground_to_image(ref.pose, cur.p_ecef)
        k = self._to_full(ref.image.shape[1], ref.sensor)
        ur, vr = (ur - (k - 1) / 2) / k, (vr - (k - 1) / 2) / k
        # hidden in ref: ref's own ray through (ur, vr) lands elsewhere (bilinear in ref's grid)
        gx = ((ur + 0.5) / step + 0.5).astype(np.float32)
        gy = ((vr + 0.5) / step + 0.5).astype(np.float32)
        seen = _remap_nan(ref.grid32, gx, gy)
        tol = np.maximum(self.s.occlusion_m, 3.0 * np.sqrt(cur.pixel_m2))
        # and a reference that saw the ground much coarser than this frame cannot tell (a slope
        # seen edge-on there): its pixel's ground area at most RESOLUTION_RATIO^2 times this one's
        ref_m2 = seen[..., 3]
        gap = seen[..., :3].astype(np.float64) - cur.ground
        with np.errstate(invalid="ignore"):
            ok = ((np.einsum("...i,...i->...", gap, gap) <= tol * tol) & np.isfinite(ur) & np.isfinite(vr)
                  & (ref_m2 <= RESOLUTION_RATIO**2 * cur.pixel_m2) & ~cur.steps)
        return np.dstack([np.where(ok, ur, 0.0), np.where(ok, vr, 0.0), ok]).astype(np.float32)

    def _upsample(self, coarse: np.ndarray, width: int, height: int, shrink: int = 1):
        """The grid's map at every pixel of the working image shrunk ``shrink`` times: (height,
        width, 2) float32 (cv2.remap's map1) and where the grid could tell (float32, 1 inside the
        cells whose four corners could). Exact bilinear between grid points (cv2.warpAffine)."""
        import cv2

        step = self._grid(width * shrink, height * shrink)[2]
        a = shrink / step
        M = np.array([[a, 0.0, 0.5 * a + 0.5], [0.0, a, 0.5 * a + 0.5]])  # output pixel -> grid index
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        uv = cv2.warpAffine(np.ascontiguousarray(coarse[..., :2]), M, (width, height), flags=flags,
                            borderMode=cv2.BORDER_REPLICATE)
        ok = cv2.warpAffine(np.ascontiguousarray(coarse[..., 2]), M, (width, height), flags=flags,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if shrink > 1:
            uv = (uv + 0.5) / shrink - 0.5
        return uv, ok

    def _residual(self, cur: _Frame, ref: _Frame, coarse: np.ndarray) -> tuple[float, float]:
        """The shift (du, dv) in ``ref``'s working pixels to add to the poses' map ``coarse`` from
        ``cur`` to ``ref`` (phase correlation of the shrunk lumas over their overlap); NaN when it
        is not clear or larger than max_shift_px."""
        import cv2

        f = self._shrink(cur.image.shape[1])
        hs, ws = cur.luma.shape
        uv, ok = self._upsample(coarse, ws, hs, f)
        ok = ok > 0.9999
        # cv2.phaseCorrelate is off by half a pixel on sizes its DFT pads (e.g. 135 rows): a
        # centred crop to sizes it takes as they are
        (r0, r1), (c0, c1) = (_dft_span(n) for n in (hs, ws))
        a, uv, ok = cur.luma[r0:r1, c0:c1], np.ascontiguousarray(uv[r0:r1, c0:c1]), ok[r0:r1, c0:c1]
        hs, ws = a.shape
        if ok.mean() < 0.25:
            return math.nan, math.nan
        b = cv2.remap(ref.luma, uv, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        m = ok.astype(np.float32)
        a = (a - float(a[ok].mean())) * m
        b = (b - float(b[ok].mean())) * m
        key = ("hann", hs, ws)
        if key not in self._cache:
            self._cache[key] = cv2.createHanningWindow((ws, hs), cv2.CV_32F)
        (dx, dy), response = cv2.phaseCorrelate(b, a, self._cache[key])
        dx, dy = dx * f, dy * f
        if not (response > 0.05 and math.hypot(dx, dy) <= self.s.max_shift_px * self.scale):
            return math.nan, math.nan
        # the warp shifted by (dx, dy) is the frame: the frame's pixel x shows what the warp shows
        # at x - d, i.e. ref's pixel map(x - d) ~ map(x) - d (the map is locally a translation)
        return -float(dx), -float(dy)

    # -- the decision ---------------------------------------------------------------------------

    def _refs(self, cur: _Frame) -> tuple[list[_Frame | None], list[_Frame | None]]:
        """The references of each side, k = 1..refs_per_side: the frame nearest to
        k * window_s / refs_per_side before (after) this one, None where there is none within
        half a step of it."""
        n, w = self.s.refs_per_side, self.s.window_s
        pick = []
        for sign in (-1.0, 1.0):
            side = [f for f in self.frames if sign * (f.time_s - cur.time_s) > 1e-9]
            chosen: list[_Frame | None] = []
            for k in range(1, n + 1):
                want = cur.time_s + sign * w * k / n
                best = min(side, key=lambda f, want=want: abs(f.time_s - want)) if side else None
                ok = best is not None and abs(best.time_s - want) <= w / n / 2 + 1e-6 and best not in chosen
                chosen.append(best if ok else None)
            pick.append(chosen)
        return pick[0], pick[1]

    def _detect(self, cur: _Frame) -> Blobs:
        import cv2

        if self.origin is None:
            return _no_blobs(cur)
        past, future = self._refs(cur)
        h, w = cur.image.shape[:2]
        thr = float(self.s.threshold)
        dmax = np.zeros((h, w), np.uint8)
        box = np.ones((2 * self.s.tolerance_px + 1,) * 2, np.uint8)
        shifts: list[tuple[float, float]] = []
        def compare(ref: _Frame):
            """The frame against one reference: (lit, valid, warped), the difference, the shift."""
            coarse = self._coarse_map(cur, ref)
            shift = (math.nan, math.nan)
            if self.s.align:
                back = self._pairs.get((ref.index, cur.index))  # measured the other way: its inverse
                shift = (-back[0], -back[1]) if back is not None else self._residual(cur, ref, coarse)
                if math.isfinite(shift[0]):
                    coarse[..., 0] += np.float32(shift[0])
                    coarse[..., 1] += np.float32(shift[1])
            uv, ok = self._upsample(coarse, w, h)
            warped = cv2.remap(ref.image, uv, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            valid = (ok > 0.9999).astype(np.uint8)
            valid &= warped[..., -1] == 255
            # tolerance_px: the difference from the reference's neighbourhood (its range per
            # channel), so that a fraction of a pixel of misregistration on an edge is no change
            hi, lo = (cv2.dilate(warped, box), cv2.erode(warped, box)) if self.s.tolerance_px else (warped, warped)
            # (the alpha channel's difference is 0 wherever valid: the frame's alpha is opaque and
            # so is the reference's there, so the largest over all channels is over the colours)
            d = _largest_channel(cv2.max(cv2.subtract(cur.image, hi), cv2.subtract(lo, cur.image))) * valid
            return ((d > thr).astype(np.uint8), valid, warped), d, shift

        # one at a time: OpenCV spreads each operation over the cores already (measured: two
        # references at a time on two threads is 13 % slower)
        it = iter([compare(r) for r in (*past, *future) if r is not None])
        sides = []
        for refs in (past, future):
            per_ref = []  # (lit, valid, warped) at each offset k; None where no reference
            for ref in refs:
                if ref is None:
                    per_ref.append(None)
                    continue
                entry, d, shift = next(it)
                if self.s.align:
                    self._pairs[(cur.index, ref.index)] = shift
                    shifts.append(shift)
                np.maximum(dmax, d, out=dmax)
                per_ref.append(entry)
            sides.append(per_ref)
        zero = np.zeros((h, w), np.uint8)
        # two-sided, by offsets valid on both sides only (a side whose far references do not see
        # the ground would cut the target's far end off and bias its centroid)
        lit_p, lit_f, paired = zero.copy(), zero.copy(), zero.copy()
        unpaired = [zero.copy(), zero.copy()]
        for a, b in zip(*sides, strict=True):
            va = a[1] if a is not None else zero
            vb = b[1] if b is not None else zero
            both_k = va & vb
            paired |= both_k
            if a is not None:
                lit_p |= a[0] & vb
                unpaired[0] += va & (1 - vb)
            if b is not None:
                lit_f |= b[0] & va
                unpaired[1] += vb & (1 - va)
        mask = (lit_p & lit_f).astype(bool)
        # which references found it: 0 both sides, -1 the past only, +1 the future only
        side = np.zeros((h, w), np.int8)
        for sign, mine, other, per_ref in ((-1, unpaired[0], unpaired[1], sides[0]), (1, unpaired[1], unpaired[0],
                                                                                       sides[1])):
            one = (mine > 0) & (mine >= other)
            if not one.any():
                continue
            seen = [(r[2], r[0]) for r in per_ref if r is not None]
            any_lit = np.zeros((h, w), np.uint8)
            for _, lit in seen:
                any_lit |= lit
            one &= any_lit.astype(bool) & ~mask
            if one.any():
                one = self._stands_out(cur.image, seen, one)
                mask |= one
                side[one] = sign
        both = paired.astype(bool)
        mask = mask.astype(np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))  # no opening: it erases
        # targets 2-3 px wide. Pieces closer than join_m on the ground are one target (a target's
        # front and back, found apart): grouped on the mask grown by that much, measured on the mask
        finite = cur.pixel_m2[np.isfinite(cur.pixel_m2)]
        gsd = math.sqrt(float(np.median(finite))) if finite.size else 1.0
        r = int(min(max(round(self.s.join_m / max(gsd, 1e-6) / 2), 0), 8))
        grown = cv2.dilate(mask, np.ones((2 * r + 1, 2 * r + 1), np.uint8)) if r else mask
        n, labels = cv2.connectedComponents(grown, connectivity=8)
        k = self._to_full(w, cur.sensor)
        _, _, step = self._grid(w, h)
        keep_u, keep_v, boxes, apx, am2, con, sides, edges = [], [], [], [], [], [], [], []
        ys, xs = np.nonzero(mask)
        lab = labels[ys, xs]
        order = np.argsort(lab, kind="stable")
        ys, xs, lab = ys[order], xs[order], lab[order]
        starts = np.searchsorted(lab, np.arange(1, n + 1))
        for i in range(1, n):
            a, b = starts[i - 1], starts[i]
            if b <= a:
                continue
            py, px = ys[a:b], xs[a:b]
            area = b - a
            cu, cv_ = float(px.mean()), float(py.mean())
            at = (np.full((1, 1), (cu + 0.5) / step + 0.5, np.float32), np.full((1, 1), (cv_ + 0.5) / step + 0.5,
                                                                                   np.float32))
            pm2 = float(_remap_nan(cur.grid32, *at)[0, 0, 3])
            a_m2 = area * pm2
            if not (self.s.min_area_m2 <= a_m2 <= self.s.max_area_m2):
                continue
            keep_u.append(cu * k + (k - 1) / 2)
            keep_v.append(cv_ * k + (k - 1) / 2)
            boxes.append((px.min() * k, py.min() * k, (px.max() + 1) * k - 1, (py.max() + 1) * k - 1))
            apx.append(area * k * k)
            am2.append(a_m2)
            con.append(float(dmax[py, px].mean()))
            sides.append(int(np.sign(side[py, px].sum())))
            edges.append(bool(px.min() == 0 or py.min() == 0 or px.max() == w - 1 or py.max() == h - 1))
        return Blobs(cur.index, cur.time_s, np.array(keep_u), np.array(keep_v), np.array(boxes).reshape(-1, 4),
                     np.array(apx), np.array(am2), np.array(con), np.array(sides, dtype=np.int8),
                     np.array(edges, dtype=bool), np.array(shifts).reshape(-1, 2), float(both.mean()))


    def _stands_out(self, image: np.ndarray, seen: list, candidates: np.ndarray) -> np.ndarray:
        """Where only one side's references see the ground, a change is the target where it
        stands out from its surroundings in this frame (by more than ``threshold``) and by half
        the threshold more than in every reference it differs from: the references show the
        target elsewhere too (its ghosts), and there the frame shows plain ground. The
        surroundings: the median over ``surround_px`` (on the frame shrunk to a fifth of it: a
        background estimate, not a filter); only around the ``candidates``."""
        import cv2

        out = np.zeros(image.shape[:2], bool)
        x, y, bw, bh = cv2.boundingRect(candidates.astype(np.uint8))
        if bw == 0:
            return out
        m = self.s.surround_px
        x0, y0 = max(x - m, 0), max(y - m, 0)
        x1, y1 = min(x + bw + m, image.shape[1]), min(y + bh + m, image.shape[0])
        f = max(1, self.s.surround_px // 5)  # the median is taken on the crop shrunk f times
        k = max(3, (self.s.surround_px // f) | 1)

        def standing_out(img: np.ndarray) -> np.ndarray:  # the median: the target does not shift it
            crop = np.ascontiguousarray(img[y0:y1, x0:x1])
            size = (crop.shape[1], crop.shape[0])
            small = cv2.resize(crop, (max(1, size[0] // f), max(1, size[1] // f)), interpolation=cv2.INTER_AREA)
            around = cv2.resize(cv2.medianBlur(small, k), size, interpolation=cv2.INTER_LINEAR)
            return _channel_max(cv2.absdiff(crop, around))

        mine = standing_out(image).astype(np.float32)
        theirs = np.zeros_like(mine)
        for warped, lit in seen:
            np.maximum(theirs, standing_out(warped) * lit[y0:y1, x0:x1], out=theirs)
        out[y0:y1, x0:x1] = (mine > self.s.threshold) & (mine > theirs + self.s.threshold / 2)
        return out & candidates


def _channel_max(img: np.ndarray) -> np.ndarray:
    """The largest of the colour channels (the last, alpha, left out) per pixel."""
    import cv2

    chans = cv2.split(img)[:-1]
    d = chans[0]
    for c in chans[1:]:
        d = cv2.max(d, c)
    return d


def _largest_channel(img: np.ndarray) -> np.ndarray:
    """The largest of all the channels per pixel (cv2.reduce over the pixels' channels: ~2x
    cv2.split and cv2.max)."""
    import cv2

    h, w, c = img.shape
    return cv2.reduce(img.reshape(h * w, c), 1, cv2.REDUCE_MAX).reshape(h, w)


def _no_blobs(fr: _Frame) -> Blobs:
    e = np.zeros(0)
    return Blobs(fr.index, fr.time_s, e, e, np.zeros((0, 4)), e, e, e, np.zeros(0, np.int8), np.zeros(0, bool),
                 np.zeros((0, 2)), 0.0)


def _dft_span(n: int) -> tuple[int, int]:
    """The centred span of ``n`` samples whose length is even and a size OpenCV's DFT takes as it
    is (2^a 3^b 5^c)."""
    import cv2

    m = n - n % 2
    while m > 2 and (m % 2 or cv2.getOptimalDFTSize(m) != m):
        m -= 1
    start = (n - m) // 2
    return start, start + m


def _remap_nan(grid: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples (cv2.remap) of ``grid`` (gh, gw, C) float32 at fractional (x col, y row)
    float32 maps; NaN outside, and wherever a NaN takes part."""
    import cv2

    out = cv2.remap(grid, np.nan_to_num(x, nan=-1e6), np.nan_to_num(y, nan=-1e6), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan,) * 4)
    return out.reshape((*x.shape, grid.shape[-1]))
