"""The `eoloc video` job: a video's frames paired with their metadata by presentation time,
orthorectified one by one (each a Cloud-Optimised GeoTIFF with its visibility), pasted into a
mosaic of the pass (the finest ground sample wins; a raster names each cell's source frame) and
cut into XYZ tiles for a map.

Metadata comes from the video's own KLV (MPEG-TS: ST 0601 packets on a KLV PID, synchronous or
asynchronous carriage, paired by PTS), from a KLV file beside it (``klv``: its ST 0601 time
stamps, the first packet at the first frame unless ``time_offset_s`` says otherwise), or from a
telemetry CSV with a camera config (``telemetry`` + ``cfg``: its time_s, 0 at the first frame
unless ``time_offset_s``). ``time_offset_s`` is always the metadata clock minus the video clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError, KLVError
from ..ground.frame import FrameSensors
from ..io.videofile import VideoInfo, iter_frames, probe_video
from ..sensor.model import Pose, SensorModel
from ..sequence.sync import FramePoses, Metadata, poses_at_frames

if TYPE_CHECKING:
    from ..detect.learned import LearnedDetector
    from ..detect.motion import MotionSettings
    from ..detect.movers import Movers, MoverSettings
from ..rules import AtHeight, StopRule

VISIBILITY = {"unseen": 0, "hidden": 1, "seen": 2}
VISIBILITY_BAND = "visibility: 0 unseen (outside the frame or no ground), 1 hidden by terrain, 2 seen"


@dataclass(frozen=True)
class FrameSelection:
    """Which frames to rectify: every ``every``-th frame (by index) whose time since the first
    frame is within [start_s, end_s]."""

    every: int = 1
    start_s: float = 0.0
    end_s: float = math.inf

    def __call__(self, index: int, t_since_first_s: float) -> bool:
        return index % self.every == 0 and self.start_s - 1e-9 <= t_since_first_s <= self.end_s + 1e-9


@dataclass
class VideoJob:
    """What `eoloc video` did: the video, the metadata and how it was paired, one row per
    selected frame, the footprints, the mosaic (or None), the files written and the issues."""

    info: VideoInfo
    metadata: Metadata
    rows: list[dict]
    footprints: list[dict]
    mosaic: object | None
    tiles: object | None
    written: list[Path]
    issues: list = field(default_factory=list)
    decode_errors: list[str] = field(default_factory=list)
    vmti: list[dict] = field(default_factory=list)
    movers: Movers | None = None
    player: Path | None = None
    video_for_browser: str = ""

    @property
    def n_rectified(self) -> int:
        return sum(r["status"] == "OK" for r in self.rows)


# -- metadata on the frames' clock ---------------------------------------------------------------


@dataclass(frozen=True)
class VMTISource:
    """The VMTI detections (ST 0903 in tag 74) of the chosen KLV stream, the telemetry rows of
    their packets and each packet's time on the frames' clock (by packet index)."""

    telemetry: object
    detections: object
    clock_by_packet: dict[int, float]


def klv_metadata(path, first_pts_s: float, *, in_video: bool, klv_stream: str | None = None,
                 time_offset_s: float | None = None, strict: bool = False) -> tuple[Metadata, list, VMTISource | None]:
    """ST 0601 packets of ``path`` as records on the frames' clock. ``in_video``: the KLV is in the
    video's own transport stream, so its PES times are the frames' clock (minus ``time_offset_s``,
    default 0); otherwise tag 2's UNIX times, the first packet at the first frame unless
    ``time_offset_s`` is given (UNIX time of the first frame). Also the stream's VMTI detections
    (None when it has none)."""
    from ..ground.frame import packet_pose
    from ..io.klv import klv_telemetry, read_klv, vmti_detections

    stream = read_klv(path, strict=strict)
    if not stream.packets:
        raise KLVError(f"{path}: no KLV packet could be decoded, so no frame has a pose",
                       [str(i) for i in stream.issues])
    tel = klv_telemetry(stream)
    names = list(dict.fromkeys(tel.columns["stream"].tolist()))
    issues = [*(str(i) for i in stream.issues), *tel.issues]
    c = tel.columns
    posed = [n for n in names if np.isfinite(c["lat_deg"][c["stream"] == n]).any()]
    if klv_stream is not None:
        if klv_stream not in names:
            raise InputError(f"{path}: no KLV stream {klv_stream!r}; it has {', '.join(repr(n) for n in names)}")
        name = klv_stream
    elif posed:
        name = posed[0]
    else:
        raise InputError(f"{path}: no KLV stream carries a position (tags 13, 14): no frame has a pose", issues)
    rows = c["stream"] == name
    sub = {k: v[rows] for k, v in c.items()}
    label = f" [{name}]" if name else ""
    if in_video:
        pts = sub["pts_s"]
        if not np.isfinite(pts).any():
            raise InputError(f"{path}{label}: the KLV packets carry no presentation time to pair them with frames")
        offset = 0.0 if time_offset_s is None else float(time_offset_s)
        clock = pts - offset
        how = (f"KLV{label} paired by presentation time (PTS)" + (f", offset {offset:+.3f} s" if offset else ""))
    else:
        unix = sub["time_s"]
        if not np.isfinite(unix).any():
            raise InputError(f"{path}{label}: the KLV packets carry no time stamp (tag 2) to pair them with frames")
        offset = float(np.nanmin(unix)) if time_offset_s is None else float(time_offset_s)
        clock = unix - offset + first_pts_s
        how = (f"KLV file {Path(path).name}{label} by its time stamps, " +
               ("its first packet at the first frame" if time_offset_s is None else
                f"UNIX {offset:.3f} s at the first frame"))

    values = {"hfov_deg": sub["hfov_deg"], "vfov_deg": sub["vfov_deg"], "fc_h_m": sub["fc_h_m"],
              "unix_s": sub["time_s"], "packet": tel.line[rows].astype(np.float64)}  # each record's packet number
    meta = Metadata(clock, packet_pose(SimpleNamespace(columns=sub)), values, how)
    det = vmti_detections(stream)
    issues += [str(i) for i in det.issues]
    det = det.keep(det.columns["stream"] == name)
    vmti = None
    if len(det):
        lines = tel.line[rows]
        vmti = VMTISource(tel.keep(rows), det, dict(zip(lines.tolist(), clock.tolist(), strict=True)))
    return meta, issues, vmti


def locate_video_vmti(vmti: VMTISource, ground: StopRule | None, first_pts_s: float) -> list[dict]:
    """Each VMTI detection located with its own packet's pose (as `eoloc klv` does) on the ``ground``
    rule (OnDEM, AtHeight, or None: the packet's frame-centre elevation): one row per
    detection with its time since the first frame, box (px), point and status."""
    from ..io.export import STATUS_NAMES, json_column
    from ..result import Status
    from .klvframes import locate_vmti

    d = vmti.detections.columns
    f = locate_vmti(vmti.telemetry, vmti.detections, ground).fixes
    status = np.asarray(f.status).astype(np.intp)
    ok = status == Status.OK
    packets = d["frame"].astype(np.int64)
    clock = np.array([vmti.clock_by_packet.get(int(p), math.nan) for p in packets])
    cols = {"packet": packets.tolist(), "video_time_s": json_column(np.round(clock - first_pts_s, 6)),
            "target_id": d["target_id"].astype(str).tolist(),
            **{k: json_column(d[k]) for k in ("u_px", "v_px", "bbox_u0", "bbox_v0", "bbox_u1", "bbox_v1")},
            **{k: json_column(getattr(f, k), ok) for k in ("lat_deg", "lon_deg", "h_m", "range_m")},
            "status": STATUS_NAMES[status].tolist()}
    return [dict(zip(cols, vals, strict=True)) for vals in zip(*cols.values(), strict=True)]


def csv_metadata(telemetry, cfg, first_pts_s: float, *, time_offset_s: float | None = None,
                 dem=None) -> tuple[Metadata, list, object]:
    """A telemetry file's records (any source: a CSV, a DJI SRT, a flight log) on the frames'
    clock: time_s minus ``time_offset_s`` (default: the config's [telemetry] time_offset_s) is the
    time since the first frame. Also the sensor to use (the config's, as the source needs it)."""
    from ..io.telemetry import telemetry_pose
    from .inputs import job_inputs

    inputs = job_inputs(cfg, telemetry, dem=dem)
    tel = inputs.telemetry
    t = tel.columns["time_s"]
    if not np.isfinite(t).any():
        raise InputError(f"{telemetry}: no time_s column: a video's frames are paired with telemetry by time")
    offset = float((cfg.telemetry.time_offset_s if cfg is not None else 0.0) if time_offset_s is None
                   else time_offset_s)
    sensor = inputs.sensor(cfg)
    pose = telemetry_pose(tel, slice(None), sensor.camera)
    how = f"telemetry {Path(telemetry).name} by time_s" + (f", offset {offset:+.3f} s" if offset else "")
    return (Metadata(t - offset + first_pts_s, pose, {"unix_s": np.full(t.shape, np.nan)}, how), inputs.issues,
            sensor)


# -- the job ---------------------------------------------------------------------------------------


def frame_visibility(px, width: int, height: int) -> np.ndarray:
    """Per cell: 2 seen, 1 in the image but hidden by terrain, 0 outside the image or no ground."""
    with np.errstate(invalid="ignore"):
        inside = ((px.u_px >= -0.5) & (px.u_px <= width - 0.5) & (px.v_px >= -0.5) & (px.v_px <= height - 0.5)
                  & (px.range_m > 0))
    vis = np.where(inside, VISIBILITY["hidden"], VISIBILITY["unseen"]).astype(np.uint8)
    vis[px.valid] = VISIBILITY["seen"]
    return vis


def video_job(video, *, out: str | Path, klv=None, telemetry=None, cfg=None, ground: StopRule | None = None,
              crs: str = "utm",
              gsd_m: float | None = None, resampling: str = "bilinear", nodata: float = 0, occlusion: bool = True,
              select: FrameSelection = FrameSelection(), klv_stream: str | None = None,
              time_offset_s: float | None = None, max_gap_s: float = 0.5, write_frames: bool = True,
              mosaic: bool = True, tiles: bool = True, player: bool = True, dem_name: str = "dem",
              serve_command: str = "", strict: bool = False, detect: MotionSettings | LearnedDetector | None = None,
              movers: MoverSettings | None = None, progress: Callable[[int, int], None] | None = None,
              detect_progress: Callable[[int, int], None] | None = None) -> VideoJob:
    """Rectify the selected frames of ``video`` (see the module notes for the metadata) onto
    the ``ground`` rule (OnDEM or AtHeight; None: each packet's frame-centre elevation, KLV
    only), each onto the pass's grid (``crs``; cell ``gsd_m``, default the first rectified frame's
    native GSD), writing ``out``/frames/frame_NNNNNN.tif, the mosaic and the tiles, and with
    ``player`` the player page (its clicks ask `eoloc serve` for the DEM named ``dem_name``;
    ``serve_command`` is what the page tells its user to run for that). The VMTI detections of
    the KLV are located with their own packets' poses. ``detect``: find the targets in every
    frame with a pose (:mod:`eoloc.detect`: what moves, with these motion settings, or the boxes of
    a learned detector; needs a DEM or a height), tracked by ``movers``.
    ``progress(done, total)`` after each rectified frame, ``detect_progress`` after each frame
    searched."""
    from ..ground import rectify
    from ..ground.footprint import footprint_features, footprints
    from ..ground.mosaic import Mosaic, ground_sample_m
    from ..io.raster import write_cog
    from ..io.videofile import frame_times

    out = Path(out)
    info = probe_video(video)
    times = frame_times(video)
    if times.size == 0:
        raise InputError(f"{video}: the video stream has no frame with a presentation time")
    t0 = float(times[0])
    vmti_source = None
    if telemetry is not None:
        meta, issues, base_sensor = csv_metadata(telemetry, cfg, t0, time_offset_s=time_offset_s,
                                                 dem=None if ground is None else ground.terrain)
    else:
        src = klv if klv is not None else video
        meta, issues, vmti_source = klv_metadata(src, t0, in_video=klv is None, klv_stream=klv_stream,
                                                 time_offset_s=time_offset_s, strict=strict)
        base_sensor = None
    if detect is not None and ground is None:
        raise InputError("finding movers needs the ground as one surface: --dem FILE or --target-height H")
    if ground is None and "fc_h_m" not in meta.values:
        raise InputError("choose the ground: --target-height H or --dem FILE (a telemetry CSV has no frame-centre "
                         "elevation)")
    poses = poses_at_frames(meta, times, max_gap_s=max_gap_s)
    page = _player_data(out, info, times, poses, base_sensor, ground, dem_name, serve_command) if player else None
    chosen = [i for i, t in enumerate(times) if select(i, float(t) - t0)]
    total = len(chosen)
    if total == 0:
        raise InputError(f"no frame of {video} is selected: {info.n_frames or times.size} frames over "
                         f"{float(times[-1] - t0):.2f} s; check --every, --start and --end")
    pass_grid: dict = {}
    mos: Mosaic | None = None
    rows, feats, written = [], [], []
    decode_errors: list[str] = []
    pending: list[Future] = []
    by_pts = {round(float(t) * 90_000): i for i, t in enumerate(times)}
    wanted = set(chosen)
    done = 0
    with ThreadPoolExecutor(max_workers=1) as writer:  # GDAL writes while the next frame is rectified
        def submit(fn, *args, **kwargs) -> Future:
            f = writer.submit(fn, *args, **kwargs)
            pending.append(f)
            return f

        frame_sensors = FrameSensors()
        for fr in iter_frames(video, want=lambda i, t: i in wanted, errors=decode_errors):
            if fr.image is None:
                continue
            j = by_pts.get(round(fr.pts_s * 90_000), -1)
            pose, vals, ok, reason = _frame_pose(poses, meta, j, fr.pts_s, max_gap_s)
            row = {"frame": fr.index, "pts_s": round(fr.pts_s, 6), "video_time_s": round(fr.pts_s - t0, 6),
                   "time_s": vals.get("unix_s", math.nan)}
            row.update(_pose_columns(pose))
            row.update({"hfov_deg": vals.get("hfov_deg", math.nan), "vfov_deg": vals.get("vfov_deg", math.nan)})
            status, note = "OK", ""
            sensor = base_sensor
            if not ok:
                status = "NO_TELEMETRY"
                note = ("outside the metadata's time span" if reason == 1 else
                        f"in a metadata gap longer than {max_gap_s:g} s")
            elif sensor is None:
                h, w = fr.image.shape[:2]
                sensor = frame_sensors.get(w, h, vals["hfov_deg"], vals["vfov_deg"])
                if sensor is None:
                    status, note = "INVALID_INPUT", "no usable field of view (tags 16, 17)"
            frame_ground = ground if ground is not None else AtHeight(vals.get("fc_h_m", math.nan))
            if status == "OK" and ground is None and not math.isfinite(vals.get("fc_h_m", math.nan)):
                status, note = "INVALID_INPUT", "no frame-centre elevation (tags 78 or 25) for the ground"
            result = None
            if status == "OK":
                try:
                    if gsd_m is None and "res" not in pass_grid:  # the pass's cell: the first frame's GSD, rounded
                        gsd_m = round_gsd(rectify.native_gsd_m(sensor, pose, frame_ground))
                    fp = footprints(sensor, pose, frame_ground)[0]  # the grid's extent, and a layer of its own
                    grid = rectify.output_grid(sensor, pose, frame_ground, crs=pass_grid.get("crs", crs),
                                               gsd_m=gsd_m, res=pass_grid.get("res"), footprint=fp)
                    result = _rectify_frame(fr.image, sensor, pose, frame_ground, grid, resampling, nodata, occlusion)
                except InputError as exc:
                    status, note = "NOT_RECTIFIED", str(exc)
            if result is not None:
                data, px, vis = result
                pass_grid.setdefault("crs", grid.crs)
                pass_grid.setdefault("res", grid.res)
                gsd_cells = ground_sample_m(px, grid)
                seen = px.valid
                row.update({"seen_cells": int(seen.sum()), "hidden_cells": int((vis == VISIBILITY["hidden"]).sum()),
                            "gsd_median_m": float(np.nanmedian(gsd_cells)) if seen.any() else math.nan})
                if mosaic and seen.any():
                    if mos is None:
                        mos = Mosaic(grid.crs, grid.res, data.shape[0], data.dtype, nodata)
                    mos.add(fr.index, grid, data, seen, gsd_cells)
                if write_frames:
                    path = out / "frames" / f"frame_{fr.index:06d}.tif"
                    stack = np.concatenate([data, vis[None].astype(data.dtype)])
                    names = [*(f"band {b + 1}" for b in range(data.shape[0])), VISIBILITY_BAND]
                    submit(write_cog, path, stack, grid.transform, grid.crs, nodata=nodata, mask=seen,
                           band_names=names, tags={"EOLOC_FRAME": fr.index, "EOLOC_PTS_S": fr.pts_s,
                                                   "EOLOC_METADATA": meta.source})
                    row["file"] = str(path.relative_to(out))
                    written.append(path)
                feats += footprint_features([fp], [{"frame": fr.index, "video_time_s": row["video_time_s"]}])
                if page is not None:
                    hidden = vis == VISIBILITY["hidden"]
                    page.add_frame(fr.index, sensor, pose, frame_ground, feats[-1], data, seen, grid, submit,
                                   (px.u_px[hidden], px.v_px[hidden]))
            row.update({"status": status, "note": note})
            rows.append(row)
            done += 1
            if progress is not None:
                progress(done, total)
            _reap(pending)
        for f in pending:
            f.result()
        page_data = page.as_dict() if page is not None else None  # waits for the drapes
    missing = wanted - {r["frame"] for r in rows}
    if missing:
        decode_errors.append(f"{video}: {len(missing)} selected frame(s) could not be decoded (first: frame "
                             f"{min(missing)})")
    mres, tileset = None, None
    if mos is not None:
        from ..ground.mosaic import cell_size_m
        from ..io.tiles import write_xyz_tiles

        mres = mos.result()
        g = mres.grid
        written.append(write_cog(out / "mosaic.tif", mres.data, g.transform, g.crs, nodata=nodata, mask=mres.valid,
                                 band_names=[f"band {b + 1}" for b in range(mres.data.shape[0])],
                                 tags={"EOLOC_SOURCE": Path(video).name, "EOLOC_METADATA": meta.source}))
        written.append(write_cog(out / "mosaic_source.tif", np.stack([mres.frame.astype(np.float32), mres.gsd_m]),
                                 g.transform, g.crs, nodata=None, mask=mres.valid,
                                 band_names=["source frame index (-1: none)", "ground sample distance (m)"]))
        if tiles:
            cx, cy = cell_size_m(g)
            tileset = write_xyz_tiles(out / "tiles", mres.data, mres.valid, g.transform, g.crs,
                                      cell_m=math.sqrt(cx * cy))
    vmti_rows = locate_video_vmti(vmti_source, ground, t0) if vmti_source is not None else []
    job = VideoJob(info, meta, rows, feats, mres, tileset, written, issues, decode_errors, vmti_rows)
    if detect is not None:
        from .detect import detect_movers

        unix: dict[int, float] = {}
        frames = posed_frames(video, times, poses, meta, base_sensor, max_gap_s, decode_errors, unix)
        from ..detect.motion import MotionSettings

        motion = detect if isinstance(detect, MotionSettings) else None
        learned = None if motion is not None else detect
        from .setup import optional_budget

        job.movers = detect_movers(frames, ground, motion, movers, learned=learned,
                                   budget=optional_budget(cfg),  # each mover fix's absolute uncertainty
                                   total=int(times.size), progress=detect_progress)
        for r in job.movers.rows:  # the metadata's own clock (ST 0601 tag 2), where it has one
            u = unix.get(r["frame"], math.nan)
            r["time_utc"] = (datetime.fromtimestamp(u, UTC).isoformat(timespec="milliseconds")
                             if math.isfinite(u) else None)
    if page_data is not None:
        from ..io.player import write_player
        from ..io.videofile import browser_video

        mp4, job.video_for_browser = browser_video(video, out / "player" / "video.mp4", first_pts_s=t0)
        page_data["vmti"] = vmti_rows
        if job.movers is not None:
            page_data["movers"] = job.movers.rows
        page_data["vmti_hold_s"] = max_gap_s
        if tileset is not None:
            page_data["mosaic"] = {"url": tileset.url, "min_zoom": tileset.min_zoom, "max_zoom": tileset.max_zoom,
                                   "bounds": [[tileset.bounds[1], tileset.bounds[0]],
                                              [tileset.bounds[3], tileset.bounds[2]]]}
        pages = write_player(out, page_data)
        job.player = pages[0]
        written += [*pages, mp4]
    return job


def posed_frames(video, times: np.ndarray, poses: FramePoses, meta: Metadata, base_sensor: SensorModel | None,
                 max_gap_s: float, errors: list[str], unix: dict[int, float] | None = None):
    """Every frame of ``video`` that has a pose: (index, seconds since the first frame, image,
    sensor, pose), in order (the input of :func:`eoloc.jobs.detect.detect_movers`); ``unix``
    gets each frame's UNIX time from its metadata (NaN where it has none)."""
    t0 = float(times[0])
    by_pts = {round(float(t) * 90_000): i for i, t in enumerate(times)}
    sensors = FrameSensors()
    for fr in iter_frames(video, errors=errors):
        if fr.image is None:
            continue
        j = by_pts.get(round(fr.pts_s * 90_000), -1)
        pose, vals, ok, _ = _frame_pose(poses, meta, j, fr.pts_s, max_gap_s)
        sensor = base_sensor
        if ok and sensor is None:
            h, w = fr.image.shape[:2]
            sensor = sensors.get(w, h, vals["hfov_deg"], vals["vfov_deg"])
        if ok and sensor is not None:
            if unix is not None:
                unix[fr.index] = vals.get("unix_s", math.nan)
            yield fr.index, fr.pts_s - t0, fr.image, sensor, pose


def _player_data(out: Path, info: VideoInfo, times: np.ndarray, poses: FramePoses, base_sensor, ground,
                 dem_name: str, serve_command: str):
    """The player's data for this video: the camera and gimbal the page sends to /v1/locate, and
    the stop rule (the DEM by name, the target height, or each frame's frame-centre elevation)."""
    from ..ground.rectify import level_height
    from .player import PlayerData

    if base_sensor is None:  # KLV: a pinhole per frame from its fields of view, az-el turret
        camera = {"width": info.width, "height": info.height, "cx": (info.width - 1) / 2.0,
                  "cy": (info.height - 1) / 2.0}
        gimbal = "az-el"
    else:  # the config's camera (with its distortion) and installation: the server needs --config
        camera, gimbal = None, base_sensor.gimbal.name
    ground_h = None
    if ground is not None and ground.terrain is not None:
        stop = {"dem": dem_name}
    elif ground is not None:
        stop = {"target_height_m": level_height(ground)}
    else:
        stop = {"frame_centre": True}
        ground_h = poses.values["fc_h_m"]
    return PlayerData(out, info.width, info.height, info.fps, times - times[0], poses, gimbal, camera, stop,
                      serve_command, Path(info.path).name, ground_h)


def round_gsd(gsd_m: float) -> float:
    """A cell size for people: two significant digits (4.5155 -> 4.5 m, 0.2349 -> 0.23 m)."""
    if not (gsd_m > 0 and math.isfinite(gsd_m)):
        return gsd_m
    return float(f"{gsd_m:.2g}")


def _reap(pending: list[Future], most: int = 6) -> None:
    """Raise a finished write's error now; keep at most ``most`` writes queued (bounded memory)."""
    keep = []
    for f in pending:
        if f.done():
            f.result()
        else:
            keep.append(f)
    while len(keep) > most:
        keep.pop(0).result()
    pending[:] = keep


def _frame_pose(poses: FramePoses, meta: Metadata, j: int, pts_s: float, max_gap_s: float):
    """Frame ``j``'s pose from the table made from the container's packet times; a frame whose
    time was not among them (a damaged packet) gets its own interpolation."""
    if j < 0:
        poses = poses_at_frames(meta, np.array([pts_s]), max_gap_s=max_gap_s)
        j = 0
    pose, vals = poses.take(j)
    return pose, vals, bool(poses.ok[j]), int(poses.reason[j])


def _pose_columns(pose: Pose) -> dict[str, float]:
    g = [float(np.ravel(a)[0]) for a in pose.gimbal_deg]
    cols = {"lat_deg": pose.lat_deg, "lon_deg": pose.lon_deg, "h_m": pose.h_m, "yaw_deg": pose.yaw_deg,
            "pitch_deg": pose.pitch_deg, "roll_deg": pose.roll_deg}
    out = {k: float(np.ravel(v)[0]) for k, v in cols.items()}
    out.update({f"gimbal{k + 1}_deg": x for k, x in enumerate(g[:2])})
    if len(g) > 2:
        out["sensor_roll_deg"] = g[2]
    return out


def _rectify_frame(image: np.ndarray, sensor: SensorModel, pose: Pose, ground: StopRule, grid, resampling: str,
                   nodata: float, occlusion: bool):
    from ..ground import rectify

    img = image[None] if image.ndim == 2 else np.moveaxis(image, -1, 0)
    px = rectify.frame_pixels(sensor, pose, ground, grid, occlusion=occlusion)
    data = rectify.resample(img, px, resampling=resampling, nodata=nodata)
    return data, px, frame_visibility(px, sensor.camera.width, sensor.camera.height)
