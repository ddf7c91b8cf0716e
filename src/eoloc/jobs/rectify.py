"""The `eoloc rectify` job: one frame orthorectified (M5) with its footprint, ground grid and the
error of the bounds shortcut."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..io.table import Issue
from ..rules import StopRule
from .inputs import job_inputs


@dataclass
class RectifyJob:
    ortho: object
    footprint: object
    grid: object
    shortcut: dict
    telemetry_line: int
    grid_pixels: int
    issues: list[Issue] = field(default_factory=list)


def record_of(tel, telemetry, frame: int | None, time_s: float | None) -> int:
    """The telemetry record of --frame N, or nearest --time T (refused outside the telemetry); a
    telemetry of one record (a photo rectified with its own pose) needs neither."""
    if frame is None and time_s is None and len(tel) == 1:
        return 0
    if (frame is None) == (time_s is None):
        raise InputError("choose the frame's telemetry record: --frame N or --time T")
    if frame is not None:
        hit = np.flatnonzero(tel.columns["frame"] == frame)
        if hit.size == 0:
            raise InputError(f"{telemetry}: no record of frame {frame}")
        return int(hit[0])
    dt = np.abs(tel.columns["time_s"] - time_s)
    if not np.isfinite(dt).any():
        raise InputError(f"{telemetry}: no time_s column to find --time in")
    t0, t1 = float(np.nanmin(tel.columns["time_s"])), float(np.nanmax(tel.columns["time_s"]))
    if not t0 - 0.5 <= time_s <= t1 + 0.5:  # the nearest record would be a pose from another moment
        raise InputError(f"--time {time_s:g} s is outside the telemetry of {telemetry} ({t0:g} to {t1:g} s): give a "
                         "time inside it (or --frame N)")
    return int(np.nanargmin(dt))


def rectify_job(cfg, image, telemetry, ground: StopRule, *, frame: int | None = None, time_s: float | None = None,
                crs: str = "utm", gsd_m: float | None = None, resampling: str = "bilinear", nodata: float = 0,
                occlusion: bool = True, grid_step_px: float = 32) -> RectifyJob:
    from ..ground import rectify
    from ..ground.footprint import footprints
    from ..io.raster import read_image
    from ..io.telemetry import telemetry_pose

    inputs = job_inputs(cfg, telemetry, dem=ground.terrain)
    tel = inputs.telemetry
    k = record_of(tel, telemetry, frame, time_s)
    sensor = inputs.sensor(cfg)
    pose = telemetry_pose(tel, k, sensor.camera)
    img = read_image(image)
    try:
        ortho = rectify.orthorectify(img, sensor, pose, ground, crs=crs, gsd_m=gsd_m, resampling=resampling,
                                     nodata=nodata, occlusion=occlusion)
    except InputError as exc:
        raise InputError(f"{image}: {exc}") from None
    grid = rectify.ground_grid(sensor, pose, ground, step_px=grid_step_px)
    ok = grid.fixes.ok.ravel()
    px = np.c_[grid.u_px.ravel(), grid.v_px.ravel()][ok]
    short = rectify.shortcut_error(ortho, sensor, pose, ground, px).summary()
    fp = footprints(sensor, pose, ground)[0]
    return RectifyJob(ortho, fp, grid, short, int(tel.line[k]), int(px.shape[0]), inputs.issues)


