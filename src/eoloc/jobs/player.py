"""What the player page (``player.html`` beside `eoloc video`'s outputs) needs from the job.

- **Every frame** of the video: its time since the first frame, whether it has a pose, the pose
  itself and its camera (so the page can ask ``POST /v1/locate`` for a click on any frame when
  `eoloc serve --player` serves it), and the ground height when the stop rule is a height.
- **Every rectified frame**: its footprint and frame centre, the rectified image warped to Web
  Mercator to drape on the map, and a ground grid for offline clicks: the ground point of every
  ``step``-th pixel, with each grid cell's interpolation error measured at its centre (the exact
  ray there against the bilinear value of its corners). A cell whose error is over its limit (a
  terrain edge inside it) or with a corner off the ground is refused by the page, never guessed.
- **VMTI**: the located detections (see :func:`eoloc.jobs.video.locate_video_vmti`).

The files are written by :mod:`eoloc.io.player`; this module computes.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.export import json_column
from ..result import Status
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel
from ..sequence.sync import FramePoses

#: an offline click is refused where a grid cell's interpolation error is over this many of the
#: cell's ground pixels (and over 1 m): a terrain edge inside the cell, where bilinear would mislead
CELL_LIMIT_PX = 0.5
CELL_ERROR_FLOOR_M = 1.0


@dataclass(frozen=True)
class OfflineGrid:
    """A frame's ground grid for the page: node pixels ``u_px`` (C,), ``v_px`` (R,), node points
    (R, C) (NaN off the ground), and per cell (R-1, C-1) the largest interpolation error of its
    checks (m; NaN where a corner or a check has no ground, -1 where the cell is refused: a terrain
    edge) and the ground size of one image pixel there (m)."""

    u_px: np.ndarray
    v_px: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    cell_error_m: np.ndarray
    cell_px_m: np.ndarray


def grid_step_px(width: int, height: int) -> int:
    """About 45 cells across the frame's short side (6 px for 480 x 270, 16 px for 1280 x 720).
    Measured on the demo's mountain pass (random pixels against their exact rays): 6 px refuses
    11 % of the ground pixels (terrain edges) and keeps the others within 0.75 of the pixel's
    ground extent, 99.5 % within 0.32; 8 px refuses 18 %, 4 px 6 % for 2.2 times the rays."""
    return max(3, round(min(width, height) / 45))


def _local_m(lat: np.ndarray, lon: np.ndarray, lat_ref: float, lon_ref: float):
    """East, north (m) from (lat_ref, lon_ref) on a sphere of the equatorial radius: for
    comparing points a cell apart, not for positions."""
    from .. import geodesy

    n = np.radians(lat - lat_ref) * geodesy.WGS84.a
    e = np.radians(lon - lon_ref) * geodesy.WGS84.a * np.cos(np.radians(lat_ref))
    return e, n


def offline_grid(sensor: SensorModel, pose: Pose, ground: StopRule, step_px: int, hidden_px=None) -> OfflineGrid:
    """The ground grid of one frame with every cell's interpolation check: the exact rays at the
    cell's centre and edge midpoints against the bilinear value of its corners (the worst is
    the cell's error; over max(CELL_LIMIT_PX ground pixels, 1 m) refuses the cell). ``hidden_px``:
    (u, v) where hidden ground projects into the frame (rectification's hidden cells): cells there
    and around hold a terrain edge and are refused whatever the checks say."""
    from ..ground.rectify import ground_grid

    g = ground_grid(sensor, pose, ground, step_px=step_px)
    ok = g.fixes.status == Status.OK
    lat = np.where(ok, g.fixes.lat_deg, np.nan)
    lon = np.where(ok, g.fixes.lon_deg, np.nan)
    h = np.where(ok, g.fixes.h_m, np.nan)
    us, vs = g.u_px[0], g.v_px[:, 0]
    R, C = lat.shape
    lat_ref = float(np.nanmean(lat)) if ok.any() else 0.0
    lon_ref = float(np.nanmean(lon)) if ok.any() else 0.0
    cell_err = np.zeros((R - 1, C - 1))
    exact_ok = np.ones((R - 1, C - 1), bool)
    u0, v0 = np.meshgrid(us[:-1], vs[:-1])  # each cell's first and last node pixels
    u1, v1 = np.meshgrid(us[1:], vs[1:])
    with np.errstate(invalid="ignore"):
        for a, b in ((0.5, 0.5), (0.5, 0.0), (0.0, 0.5), (1.0, 0.5), (0.5, 1.0)):  # centre, edge midpoints
            fx = ground.locate(sensor, pose, (u0 + a * (u1 - u0), v0 + b * (v1 - v0)))
            interp = [(1 - a) * (1 - b) * x[:-1, :-1] + a * (1 - b) * x[:-1, 1:] + (1 - a) * b * x[1:, :-1]
                      + a * b * x[1:, 1:] for x in (lat, lon, h)]
            e1, n1 = _local_m(interp[0], interp[1], lat_ref, lon_ref)
            e2, n2 = _local_m(fx.lat_deg, fx.lon_deg, lat_ref, lon_ref)
            err = np.sqrt((e1 - e2) ** 2 + (n1 - n2) ** 2 + (interp[2] - fx.h_m) ** 2)
            cell_err = np.fmax(cell_err, err)
            exact_ok &= (fx.status == Status.OK) & np.isfinite(err)
        # the cell's ground size per image pixel: its diagonals' ground lengths over their pixel lengths
        ea, na = _local_m(lat[:-1, :-1], lon[:-1, :-1], lat_ref, lon_ref)
        eb, nb = _local_m(lat[1:, 1:], lon[1:, 1:], lat_ref, lon_ref)
        px_m = np.hypot(eb - ea, nb - na) / np.hypot(u1 - u0, v1 - v0)
        limit = np.maximum(CELL_LIMIT_PX * px_m, CELL_ERROR_FLOOR_M)
        edge = np.zeros((R - 1, C - 1), bool)
        if hidden_px is not None and np.size(hidden_px[0]):
            hu, hv = (np.asarray(x, dtype=np.float64).ravel() for x in hidden_px)
            j = np.clip(np.searchsorted(us, hu, side="right") - 1, 0, C - 2)
            k = np.clip(np.searchsorted(vs, hv, side="right") - 1, 0, R - 2)
            edge[k, j] = True
            grown = edge.copy()  # the silhouette may lie in the neighbouring cell
            grown[1:] |= edge[:-1]
            grown[:-1] |= edge[1:]
            grown[:, 1:] |= edge[:, :-1]
            grown[:, :-1] |= edge[:, 1:]
            edge = grown
        cell = np.where(exact_ok & np.isfinite(cell_err), np.where((cell_err > limit) | edge, -1.0, cell_err), np.nan)
    return OfflineGrid(us.copy(), vs.copy(), lat, lon, h, cell, px_m)


@dataclass
class PlayerData:
    """The page's data, gathered as the job runs (:meth:`add_frame` per rectified frame) and
    finished by :meth:`as_dict` once the writes it started are done."""

    out: Path
    width: int
    height: int
    fps: float
    frame_time_s: np.ndarray
    poses: FramePoses
    gimbal: str
    camera: dict | None  # fixed intrinsics (KLV: cx, cy, size; fx, fy per frame) or None: the config's
    stop: dict
    serve_command: str
    title: str
    ground_h_m: np.ndarray | None = None
    rectified: dict[int, dict] = field(default_factory=dict)
    pending: list[tuple[int, Future]] = field(default_factory=list)

    def add_frame(self, index: int, sensor: SensorModel, pose: Pose, ground: StopRule, footprint: dict,
                  image: np.ndarray, seen: np.ndarray, grid, submit: Callable[..., Future], hidden_px=None) -> None:
        """A rectified frame: its footprint feature, its ground grid (computed here, written by the
        writer thread; ``hidden_px``: the pixels of its hidden ground) and its drape (warped and
        written by the writer thread)."""
        from ..io.player import write_drape, write_grid_script

        og = offline_grid(sensor, pose, ground, grid_step_px(sensor.camera.width, sensor.camera.height), hidden_px)
        geom = footprint.get("geometry")
        p = footprint["properties"]
        rings = ([geom["coordinates"][0]] if geom["type"] == "Polygon" else [q[0] for q in geom["coordinates"]]) \
            if geom else []
        latlon = [[[c[1], c[0]] for c in r] for r in rings]  # a MultiPolygon (cut at ±180°): Leaflet's nested form
        entry = {"footprint": (latlon[0] if len(latlon) == 1 else latlon) if geom else None,
                 "centre": [p["centre_lat_deg"], p["centre_lon_deg"], p["centre_h_m"]]
                 if p.get("centre_lat_deg") is not None else None,
                 "grid": f"player/grid/{index:06d}.js", "drape": f"player/drape/{index:06d}.webp"}
        self.rectified[index] = entry
        submit(write_grid_script, self.out / entry["grid"], index, og)
        self.pending.append((index, submit(write_drape, self.out / entry["drape"], image, seen, grid.transform,
                                           grid.crs)))

    def as_dict(self) -> dict:
        """Everything the page reads, JSON-ready (NaN as null)."""
        for index, fut in self.pending:
            bounds = fut.result()
            if bounds is None:
                self.rectified[index]["drape"] = None
            self.rectified[index]["bounds"] = bounds
        self.pending.clear()
        pose = self.poses.pose
        g = [np.broadcast_to(np.asarray(a, dtype=np.float64), self.frame_time_s.shape) for a in pose.gimbal_deg]
        frames = {"t": self.frame_time_s, "lat": pose.lat_deg, "lon": pose.lon_deg, "h": pose.h_m, "yaw": pose.yaw_deg,
                  "pitch": pose.pitch_deg, "roll": pose.roll_deg, **{f"g{k + 1}": a for k, a in enumerate(g)}}
        if self.camera is not None and "hfov_deg" in self.poses.values:  # KLV: each frame's own pinhole
            from ..ground.frame import misb_frame_sensor

            cams = [misb_frame_sensor(self.width, self.height, hf, vf) for hf, vf in
                    zip(self.poses.values["hfov_deg"], self.poses.values["vfov_deg"], strict=True)]
            frames |= {"fx": [c.camera.fx if c else np.nan for c in cams],
                       "fy": [c.camera.fy if c else np.nan for c in cams]}
        if self.ground_h_m is not None:
            frames["ground_h"] = self.ground_h_m
        ok = self.poses.ok & np.isfinite(pose.lat_deg)
        return {"title": self.title, "video": "player/video.mp4", "width": self.width, "height": self.height,
                "fps": self.fps, "frames": {"ok": self.poses.ok.astype(int).tolist(),
                                            **{k: json_column(np.broadcast_to(v, self.frame_time_s.shape))
                                               for k, v in frames.items()}},
                "gimbal": self.gimbal, "camera": self.camera, "stop": self.stop, "serve": self.serve_command,
                "rectified": {str(k): v for k, v in sorted(self.rectified.items())},
                "track": [[float(a), float(b)] for a, b in zip(pose.lat_deg[ok], pose.lon_deg[ok], strict=True)]}
