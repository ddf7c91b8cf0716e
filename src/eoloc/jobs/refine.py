"""The `eoloc refine` job: what the telemetry gets wrong (installation, heading bias, time offset)
estimated from the video's own pixels (:mod:`eoloc.refine`) and written back as corrected
telemetry and config.

Keyframes every ``every_s`` seconds of the frames that have a pose; which of them overlap is
predicted from the poses and the ground; tie points matched across them; the bundle adjustment
with the DEM as a soft constraint. Written into ``out``: ``refine.json`` (the estimates with their
sigma, correlations, what the geometry cannot determine, residuals, counts, timings),
``telemetry_refined.csv`` (the records with the heading bias taken out of the yaw and the time
offset out of time_s), ``config_refined.toml`` (the config with the installation estimated; its
heading bias and time offset as they were, since the CSV now carries those corrections: use the
two together), ``tiepoints.csv`` (every observation with its residuals before/after) and
``residuals.png``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import EolocError, InputError
from ..io.export import json_safe
from ..io.telemetry import ZOOM_COLUMNS
from ..io.videofile import iter_frames, probe_video
from ..refine.adjust import REFINE_GROUPS, AdjustSettings, Refinement, adjust
from ..refine.register import Reference, control_points
from ..refine.tiepoints import TiePoints, TieSettings, choose_pairs, find_tie_points, predicted_overlap
from ..rules import OnDEM
from ..sequence.calibration import GROUPS, TelemetryTrack, pose_with_biases
from ..sequence.sync import poses_at_frames
from ..terrain import DEM
from .setup import optional_budget


@dataclass
class RefineJob:
    """The refinement, its tie points, the keyframes' indices and times, the report (refine.json's
    content), the files written and the input issues."""

    refinement: Refinement
    ties: TiePoints
    keyframes: np.ndarray
    report: dict
    written: list[Path] = field(default_factory=list)
    issues: list = field(default_factory=list)


def keyframe_indices(times: np.ndarray, ok: np.ndarray, every_s: float) -> np.ndarray:
    """Frames with a pose, at least ``every_s`` apart in time (the first such frame first)."""
    chosen, last = [], -math.inf
    for i in np.flatnonzero(ok):
        if times[i] - last >= every_s - 1e-9:
            chosen.append(int(i))
            last = float(times[i])
    return np.array(chosen, dtype=np.int64)


def refine_video(video, telemetry, cfg, dem: DEM, *, config_path: str | Path | None = None, out: str | Path,
                 every_s: float = 1.0, tie: TieSettings | None = None,
                 settings: AdjustSettings | None = None, max_gap_s: float = 0.5, reference: Reference | None = None,
                 priors_from_budget: Collection[str] = (),
                 progress: Callable[[str], None] | None = None) -> RefineJob:
    """Refine the telemetry of ``video`` (a telemetry file with ``cfg``, its camera; ``telemetry``
    None: the ST 0601 KLV in the video's own transport stream, each frame's camera from its fields
    of view) on ``dem`` (``tie``/``settings``: the tie points' and the adjustment's; default their
    defaults); with a ``reference`` image the keyframes are matched to it too (control points: an
    absolute solution). ``priors_from_budget``: groups whose prior 1-sigma is taken from the
    config's [accuracy.budget] when it has one (:func:`eoloc.refine.correct.budget_priors`;
    "frame": the per-keyframe attitude sigma)."""
    import cv2

    tie = tie if tie is not None else TieSettings()
    settings = settings if settings is not None else AdjustSettings()
    from ..ground.frame import misb_frame_sensor
    from ..io.videofile import frame_times
    from .video import csv_metadata, klv_metadata

    if not isinstance(dem, DEM):
        raise InputError("refining needs the terrain: --dem FILE (the tie points' heights are held to it)")
    if not every_s > 0:
        raise InputError(f"--every-s must be > 0, got {every_s!r}")
    say = progress or (lambda _msg: None)
    clock: dict[str, float] = {}
    t_start = time.perf_counter()
    out = Path(out)
    probe_video(video)
    times = frame_times(video)
    if times.size == 0:
        raise InputError(f"{video}: the video stream has no frame with a presentation time")
    if telemetry is not None:
        meta, issues, sensor = csv_metadata(telemetry, cfg, float(times[0]), dem=dem)
    else:
        try:
            meta, issues, _ = klv_metadata(video, float(times[0]), in_video=True)
        except EolocError as exc:
            raise InputError(f"{exc} -- without its own KLV a video needs its telemetry: --telemetry FILE "
                             "--config C.toml", exc.issues) from None
        sensor = None
    budget = optional_budget(cfg)
    if budget is not None and priors_from_budget:
        settings = budget_settings(settings, budget, float(np.nanmedian(meta.pose.lat_deg)), priors_from_budget)
    poses = poses_at_frames(meta, times, max_gap_s=max_gap_s)
    usable = np.asarray(poses.ok, dtype=bool)
    if "time" in settings.estimate:  # a keyframe must keep its pose when the offset moves (2 prior sigmas)
        margin = min(1.0, 2.0 * settings.prior_sigma["time"])
        usable &= (times - margin >= poses.span_s[0]) & (times + margin <= poses.span_s[1])
    keys = keyframe_indices(times, usable, every_s)
    if keys.size < 3:
        raise InputError(f"{video}: {keys.size} frame(s) with a pose at least {every_s:g} s apart: refining needs "
                         "three or more (a lower --every-s, or telemetry covering the video)", issues)
    wanted = set(keys.tolist())
    images: dict[int, np.ndarray] = {}
    errors: list[str] = []
    say(f"decoding {keys.size} keyframes")
    change: dict[int, float] = {}  # keyframe -> mean absolute difference to the frame before it
    prev: tuple[int, np.ndarray] | None = None
    for fr in iter_frames(video, want=lambda i, _t: i in wanted or i + 1 in wanted, errors=errors):
        if fr.image is None:
            continue
        if fr.index in wanted:
            images[fr.index] = fr.image
            if prev is not None and prev[0] == fr.index - 1 and prev[1].shape == fr.image.shape:
                change[fr.index] = float(cv2.absdiff(prev[1], fr.image).mean())
        prev = (fr.index, fr.image)
    repeats = repeated_frames(change)
    for k in repeats:
        del images[k]
    if repeats:
        errors.append(f"{video}: {len(repeats)} keyframe(s) repeat the frame before them (an encoder's duplicate, its "
                      "pixels from an earlier time than its own): left out")
    keys = np.array([k for k in keys if k in images], dtype=np.int64)
    if keys.size < 3:
        raise InputError(f"{video}: only {keys.size} keyframe(s) could be decoded", [*issues, *errors])
    h, w = images[int(keys[0])].shape[:2]
    if sensor is not None and (w, h) != (sensor.camera.width, sensor.camera.height):
        raise InputError(f"{video}: frames are {w} x {h} but the config's camera is {sensor.camera.width} x "
                         f"{sensor.camera.height}: give the config of this video's camera")
    if sensor is not None:
        sensors, frame_sensor = [sensor], np.zeros(keys.size, np.int64)
    else:  # KLV: each keyframe's pinhole from its fields of view (tags 16, 17), one sensor per zoom
        fov = [(round(float(poses.values["hfov_deg"][k]), 6), round(float(poses.values["vfov_deg"][k]), 6))
               for k in keys]
        distinct = list(dict.fromkeys(fov))
        sensors = [misb_frame_sensor(w, h, *f) for f in distinct]
        if any(x is None for x in sensors):
            raise InputError(f"{video}: a keyframe's KLV has no usable field of view (tags 16, 17)", issues)
        if cfg is not None:  # the config's [installation] (eoloc klv's) is the starting value
            inst = cfg.installation
            sensors = [dataclasses.replace(s, mount_misalignment_deg=inst.mount_misalignment_deg,
                                           boresight_misalignment_deg=inst.boresight_misalignment_deg,
                                           lever_arm_m=inst.lever_arm_m) for s in sensors]
        frame_sensor = np.array([distinct.index(f) for f in fov], dtype=np.int64)
    clock["decode_s"] = time.perf_counter() - t_start
    track = TelemetryTrack(meta.clock_s, meta.pose, max_gap_s)
    key_t = times[keys]
    rule = OnDEM(dem)
    t = time.perf_counter()
    start = pose_with_biases(None, track, key_t, 0.0, 0.0)
    key_sensors = [sensors[i] for i in frame_sensor]
    overlap = predicted_overlap(key_sensors, [start.take(i) for i in range(keys.size)], rule)
    pairs = choose_pairs(overlap, tie)
    say(f"matching {len(pairs)} frame pairs")
    frames = [images[int(k)] for k in keys]
    ties = find_tie_points(frames, pairs, tie)
    clock["tie_points_s"] = time.perf_counter() - t
    control = None
    if reference is not None:
        say(f"matching {keys.size} keyframes to the reference")
        t = time.perf_counter()
        control = control_points(frames, key_sensors, [start.take(i) for i in range(keys.size)], rule, reference,
                                 tie)
        clock["control_points_s"] = time.perf_counter() - t
    del images, frames
    say(f"adjusting {len(ties)} observations of {ties.n_tracks} tie points"
        + (f" and {len(control)} control points" if control is not None else ""))
    t = time.perf_counter()
    ref = adjust(sensors, frame_sensor, track, key_t, ties, rule, dem, settings,
                 **reference_weights(reference, control))
    clock["adjust_s"] = time.perf_counter() - t
    clock["total_s"] = time.perf_counter() - t_start
    report = refine_report(ref, ties, keys, len(pairs), settings, clock)
    report["video"] = str(video)
    job = RefineJob(ref, ties, keys, report, issues=[*issues, *errors])
    if telemetry is None:  # the video's own KLV, corrected in a copy of it
        out.mkdir(parents=True, exist_ok=True)
        say("writing the refined KLV into a copy of the video")
        ts_path, report["klv_notes"] = write_refined_ts(video, out / f"{Path(video).stem}_refined.ts", meta, ref,
                                                        track, dem)
        job.written.append(ts_path)
    job.written += write_refinement(job, out, telemetry, cfg, config_path, key_t,
                                    klv=None if telemetry is not None else (meta, float(times[0]), (w, h)))
    return job


def budget_settings(settings: AdjustSettings, budget, lat_deg: float, groups: Collection[str]) -> AdjustSettings:
    """``settings`` with the prior 1-sigma of ``groups`` taken from ``budget``
    (:func:`eoloc.refine.correct.budget_priors`; "frame": the per-keyframe attitude sigma)."""
    from ..refine.correct import budget_priors

    taken = {g: v for g, v in budget_priors(budget, lat_deg).items() if g in groups}
    frame = taken.pop("frame", settings.frame_sigma_deg)
    return dataclasses.replace(settings, prior_sigma={**settings.prior_sigma, **taken}, frame_sigma_deg=frame)


def photo_span_s(times) -> float:
    """The seconds from the first photo to the last by their capture times (EXIF/XMP date-times);
    infinite when any is missing or unreadable (a time-varying error then counts whole)."""
    from datetime import datetime

    stamps = []
    for t in times:
        text = str(t or "").strip()
        if len(text) >= 10 and text[4] == ":" and text[7] == ":":  # EXIF's 2026:11:27 12:00:00
            text = text[:4] + "-" + text[5:7] + "-" + text[8:]
        try:
            stamps.append(datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp())
        except ValueError:
            return math.inf
    return max(stamps) - min(stamps) if len(stamps) >= 2 else math.inf


def repeated_frames(change: dict[int, float]) -> list[int]:
    """The frames that repeat the one before them (an encoder's duplicate: its pixels are the earlier
    frame's, up to compression noise), from each one's mean absolute difference to the frame before
    (grey levels): below 1 and below a tenth of the upper quartile of all of them (a hovering camera
    over a still scene changes little between all of its frames: none of them is a repeat)."""
    if not change:
        return []
    limit = min(1.0, 0.1 * float(np.percentile(list(change.values()), 75)))
    return [k for k, d in change.items() if d < limit]


def reference_weights(reference: Reference | None, control) -> dict:
    """adjust()'s control arguments: each point within half a reference cell, the reference's own
    georeferencing error shared by all of them."""
    if reference is None:
        return {"control": None}
    return {"control": control, "control_sigma_m": max(0.5 * reference.cell_m, 0.05),
            "control_shared_sigma_m": reference.sigma_m}


def refine_report(ref: Refinement, ties: TiePoints, keys: np.ndarray, n_pairs: int, settings: AdjustSettings,
                  clock: dict[str, float]) -> dict:
    """refine.json's content (JSON-safe)."""
    rms = ref.rms
    return json_safe({
        "parameters": ref.as_dict(), "sigma": dict(zip(ref.names, ref.sigma.tolist(), strict=True)),
        "prior_sigma": dict(zip(ref.names, ref.prior_sigma.tolist(), strict=True)),
        "correlation": ref.correlation.tolist(), "undetermined": ref.undetermined, "s0": ref.s0,
        "heading_bias_deg": ref.heading_bias_deg, "time_offset_s": ref.time_offset_s,
        "estimated": list(settings.estimate), "pixel_sigma_px": settings.pixel_sigma_px,
        "dem_sigma_m": settings.dem_sigma_m, "keyframes": int(keys.size), "pairs_matched": n_pairs,
        "pairs_verified": len(ties.pairs), "tie_points": ref.n_tracks, "observations": ref.n_observations,
        "outlier_tracks": len(ref.outlier_tracks), "control_points": ref.n_control,
        "frame_sigma_deg": settings.frame_sigma_deg, "frame_attitude_deg": ref.frame_attitude_deg.tolist(),
        "frame_attitude_sigma_deg": ref.frame_attitude_sigma_deg.tolist(),
        "absolute": ref.n_control > 0, "rms_px_control": rms(ref.control_residual_px),
        "rms_px_before": rms(ref.residual_px_before),
        "rms_px_after": rms(ref.residual_px_after), "timing_s": clock, "warnings": ref.warnings})


def write_refinement(job: RefineJob, out: Path, telemetry, cfg, config_path, key_t: np.ndarray, *,
                     klv=None) -> list[Path]:
    """The job's files (module notes); ``klv``: (metadata, first frame's time, frame size) when the
    records came from the video's own KLV: the CSV then counts time_s from the first frame and a
    config for it is written from scratch (the frames' pinhole at the first record's field of view,
    the az-el turret, the installation estimated)."""
    import json

    from ..io.config import copy_sections, write_calibration
    from ..io.writers import write_layer
    from ..refine.adjust import position_bias, shift_position
    from ..sensor import Pose
    from .inputs import job_inputs

    out.mkdir(parents=True, exist_ok=True)
    ref, ties = job.refinement, job.ties
    written = []
    records = job_inputs(cfg, telemetry).telemetry.columns if klv is None else None
    budget = None
    if config_path is not None and (given := optional_budget(cfg)) is not None:  # what refinement left unknown
        from ..refine.correct import refined_budget

        lat = records["lat_deg"] if records is not None else klv[0].pose.lat_deg
        budget, job.report["budget"] = refined_budget(given, ref, float(key_t[-1] - key_t[0]), float(np.nanmedian(lat)),
                                                      job.report["frame_sigma_deg"])
    js = out / "refine.json"
    js.write_text(json.dumps(job.report, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    written.append(js)
    if klv is None:
        # the records as eoloc read them (the config's heading bias already out of the yaw)
        c = dict(records)
        hb0 = cfg.telemetry.heading_bias_deg if cfg is not None else 0.0
    else:
        meta, t0, _ = klv
        p = meta.pose
        g = [np.broadcast_to(np.asarray(x, dtype=np.float64), meta.clock_s.shape) for x in p.gimbal_deg]
        c = {"time_s": meta.clock_s - t0, "lat_deg": p.lat_deg, "lon_deg": p.lon_deg, "h_m": p.h_m,
             "yaw_deg": p.yaw_deg, "pitch_deg": p.pitch_deg, "roll_deg": p.roll_deg, "gimbal1_deg": g[0],
             "gimbal2_deg": g[1], "sensor_roll_deg": g[2] if len(g) > 2 else np.zeros(meta.clock_s.shape),
             "hfov_deg": meta.values["hfov_deg"]}
        hb0 = 0.0
    n = len(np.atleast_1d(c["time_s"]))
    d_heading = ref.heading_bias_deg  # on top of the config's, which the reader took out
    d_time = ref.time_offset_s
    at = shift_position(Pose(c["lat_deg"], c["lon_deg"], c["h_m"]), position_bias(ref.names, ref.values))

    def col(x):
        return np.broadcast_to(np.asarray(x, dtype=np.float64), (n,))

    columns = {"time_s": col(c["time_s"]) - d_time, "lat_deg": col(at.lat_deg), "lon_deg": col(at.lon_deg),
               "h_m": col(at.h_m), "yaw_deg": (col(c["yaw_deg"]) + hb0 - d_heading) % 360.0,
               "pitch_deg": col(c["pitch_deg"]), "roll_deg": col(c["roll_deg"]), "gimbal1_deg": col(c["gimbal1_deg"]),
               "gimbal2_deg": col(c["gimbal2_deg"]), "sensor_roll_deg": np.nan_to_num(col(c["sensor_roll_deg"]))}
    columns |= {name: col(c[name]) for name in KEPT_COLUMNS  # a zoom lens' focal length, a laser's range: as they were
                if name in c and np.isfinite(col(c[name])).any()}
    rows = [dict(zip(columns, values, strict=True)) for values in zip(*(v.tolist() for v in columns.values()),
                                                                         strict=True)]
    written += write_layer(out, "telemetry_refined", rows, ["csv"])
    refined = out / "config_refined.toml"
    if klv is not None:
        _, _, (w, hgt) = klv
        hfov = col(c["hfov_deg"])
        first = float(hfov[np.isfinite(hfov)][0])
        refined.write_text(f"# eoloc refine: the camera of {Path(str(job.report.get('video', 'the video'))).name}'s "
                           "frames (from its KLV's fields of view; per record in telemetry_refined.csv's hfov_deg)\n"
                           f"[camera]\nwidth = {w}\nheight = {hgt}\nhfov_deg = {first!r}\n\n"
                           "[gimbal]\nmodel = \"az-el\"\n", encoding="utf-8")
        if config_path is not None:  # the config's lever arm and budget, its installation the start
            copy_sections(refined, config_path, ("installation", "accuracy"))
    elif config_path is not None:
        refined.write_text(Path(config_path).read_text(encoding="utf-8"), encoding="utf-8")
    note = "refined by eoloc refine (refine.json: budget)"
    if klv is not None or config_path is not None:
        s = ref.sensors[0]
        groups = ref_groups(ref)
        write_calibration(refined, mount_misalignment_deg=s.mount_misalignment_deg if "mount" in groups else None,
                          boresight_misalignment_deg=s.boresight_misalignment_deg if "boresight" in groups
                          else None, budget=budget, budget_note=note)
        written.append(refined)
    if klv is not None and config_path is not None:  # the refined TS's: its sensor angles carry the installation
        ts_config = out / f"{Path(str(job.report['video'])).stem}_refined.toml"
        ts_config.write_text(f"# eoloc refine: the config of {ts_config.stem}.ts (its packets carry the installation, "
                             "the heading bias and clock offset corrected; the budget: what refinement left "
                             "unknown)\n"
                             + Path(config_path).read_text(encoding="utf-8"), encoding="utf-8")
        write_calibration(ts_config, mount_misalignment_deg=(0.0, 0.0, 0.0),
                          boresight_misalignment_deg=(0.0, 0.0, 0.0), heading_bias_deg=0.0, time_offset_s=0.0,
                          budget=budget, budget_note=note)
        written.append(ts_config)
    obs = [{"track": int(ties.track[i]), "keyframe": int(job.keyframes[ties.frame[i]]),
            "video_time_s": float(key_t[ties.frame[i]] - key_t[0]), "u_px": float(ties.u_px[i]),
            "v_px": float(ties.v_px[i]), "du_before_px": float(ref.residual_px_before[i, 0]),
            "dv_before_px": float(ref.residual_px_before[i, 1]), "du_after_px": float(ref.residual_px_after[i, 0]),
            "dv_after_px": float(ref.residual_px_after[i, 1])} for i in range(len(ties))]
    written += write_layer(out, "tiepoints", obs, ["csv"])
    written.append(residual_plot(out / "residuals.png", ties, ref, key_t - key_t[0]))
    return written


KEPT_COLUMNS = (*ZOOM_COLUMNS, "range_m")


def write_refined_ts(video, dest: Path, meta, ref: Refinement, track: TelemetryTrack,
                     dem: DEM) -> tuple[Path, list[str]]:
    """``video`` (an MPEG-TS whose ST 0601 KLV was refined: ``meta`` its records, with each one's
    packet number) copied to ``dest`` with each refined packet's pose written in place
    (:func:`eoloc.io.klv.mux.rewrite_klv_in_ts`: every other byte as it was, the packet's length
    and time stamp unchanged): the values the platform had at the packet's time as the refinement
    corrects them (time offset, heading bias, position bias: tags 5, 6, 7, 90, 91, 13, 14, 15, 75),
    the sensor angles that carry the estimated installation (tags 18, 19, 20: no config needed to
    use them) and the frame centre and corners on the DEM through the refined camera (23, 24, 25,
    78, 26-33, 82-89). Only tags a packet sends are written. A packet whose corrected time leaves
    the telemetry gets the standard's error value in its position (and its frame centre and corners
    off-earth), so no reader takes a pose from it; one that cannot be rewritten in place (an item
    of non-standard size) is copied as it came. Returns the path and notes saying how many of each."""
    from stanag4609.st0601 import SpecialValue

    from ..ground.frame import frame_geometry, misb_sensor
    from ..io.klv import read_klv
    from ..io.klv.encode import replace_items
    from ..io.klv.mux import rewrite_klv_in_ts
    from ..io.klv.st0601 import Tag
    from ..io.klv.tables import FULL_CORNER_TAGS, OFFSET_CORNER_TAGS
    from ..refine.correct import fold_installation, refined_poses
    from ..terrain.geoid import default_geoid

    packets = {p.index: p for p in read_klv(video).packets}
    number = meta.values["packet"].astype(np.int64)
    pose = refined_poses(ref, track, meta.clock_s)
    gimbal, folded = fold_installation(ref.sensors[0], pose)
    lat, lon, h = (np.asarray(x, dtype=np.float64) for x in (pose.lat_deg, pose.lon_deg, pose.h_m))
    good = folded & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
    geo = frame_geometry(misb_sensor(), dataclasses.replace(pose, gimbal_deg=gimbal), meta.values["hfov_deg"],
                         meta.values["vfov_deg"], OnDEM(dem))
    geoid = default_geoid()
    n_sensor = geoid.undulation(lat, lon)
    fc, co = geo.centre, geo.corners
    fc_ok = good & fc.ok
    n_fc = geoid.undulation(np.where(fc_ok, fc.lat_deg, 0.0), np.where(fc_ok, fc.lon_deg, 0.0))
    off = SpecialValue.OFF_EARTH
    new: dict[int, bytes] = {}
    kept = 0
    for i, k in enumerate(number.tolist()):
        if k not in packets:
            continue
        v: dict[int, object] = {}
        if good[i]:
            v |= {Tag.SENSOR_LATITUDE: lat[i], Tag.SENSOR_LONGITUDE: lon[i],
                  Tag.SENSOR_TRUE_ALTITUDE: h[i] - n_sensor[i], Tag.SENSOR_ELLIPSOID_HEIGHT: h[i],
                  Tag.PLATFORM_HEADING_ANGLE: float(pose.yaw_deg[i]) % 360.0,
                  Tag.PLATFORM_PITCH_ANGLE: float(pose.pitch_deg[i]), Tag.PLATFORM_ROLL_ANGLE: float(pose.roll_deg[i]),
                  Tag.PLATFORM_PITCH_ANGLE_FULL: float(pose.pitch_deg[i]),
                  Tag.PLATFORM_ROLL_ANGLE_FULL: float(pose.roll_deg[i]),
                  Tag.SENSOR_RELATIVE_AZIMUTH_ANGLE: float(gimbal[0][i]) % 360.0,
                  Tag.SENSOR_RELATIVE_ELEVATION_ANGLE: (float(gimbal[1][i]) + 180.0) % 360.0 - 180.0,
                  Tag.SENSOR_RELATIVE_ROLL_ANGLE: float(gimbal[2][i]) % 360.0}
        else:  # ST 0601's error indicator: this packet has no position a reader could trust
            v |= {Tag.SENSOR_LATITUDE: SpecialValue.RESERVED, Tag.SENSOR_LONGITUDE: SpecialValue.RESERVED}
        if fc_ok[i]:
            v |= {Tag.FRAME_CENTER_LATITUDE: float(fc.lat_deg[i]), Tag.FRAME_CENTER_LONGITUDE: float(fc.lon_deg[i]),
                  Tag.FRAME_CENTER_ELEVATION: float(fc.h_m[i] - n_fc[i]),
                  Tag.FRAME_CENTER_HEIGHT_ABOVE_ELLIPSOID: float(fc.h_m[i])}
        else:
            v |= {Tag.FRAME_CENTER_LATITUDE: off, Tag.FRAME_CENTER_LONGITUDE: off}
        for c in range(4):
            both = fc_ok[i] and good[i] and bool(co.ok[i, c])
            d_lat, d_lon = (float(co.lat_deg[i, c] - fc.lat_deg[i]), float(co.lon_deg[i, c] - fc.lon_deg[i])) \
                if both else (math.inf, math.inf)
            near = abs(d_lat) <= 0.075 and abs(d_lon) <= 0.075  # the offset tags' reach
            v[OFFSET_CORNER_TAGS[2 * c]] = d_lat if near else off
            v[OFFSET_CORNER_TAGS[2 * c + 1]] = d_lon if near else off
            v[FULL_CORNER_TAGS[2 * c]] = float(co.lat_deg[i, c]) if both else off
            v[FULL_CORNER_TAGS[2 * c + 1]] = float(co.lon_deg[i, c]) if both else off
        try:
            new[k] = replace_items(packets[k].raw, v)
        except ValueError:
            kept += 1
    queue = [(packets[k].raw, new[k], int(packets[k].stream.removeprefix("PID ") or -1))
             for k in sorted(new)]
    at = 0

    def rewrite(pid: int, raw: bytes) -> bytes | None:
        nonlocal at
        for j in range(at, min(at + 64, len(queue))):  # in stream order; a packet the reader dropped is skipped
            if queue[j][2] == pid and queue[j][0] == raw:
                at = j + 1
                return queue[j][1]
        return None

    data, changed = rewrite_klv_in_ts(Path(video).read_bytes(), rewrite)
    dest.write_bytes(data)
    notes = [f"{dest.name}: {changed} ST 0601 packet(s) rewritten with the refined pose"]
    if (~good).any():
        notes.append(f"{int((~good).sum())} packet(s) whose corrected time leaves the telemetry sent without a "
                     "position (ST 0601's error value in tags 13, 14)")
    if kept:
        notes.append(f"{kept} packet(s) copied as they came: an item of non-standard size cannot be rewritten "
                     "in place")
    return dest, notes


def ref_groups(ref: Refinement) -> set[str]:
    """The groups whose parameters ``ref`` estimated."""
    return {g for g, names in REFINE_GROUPS.items() if set(names) <= set(ref.names)}


def residual_plot(path: Path, ties: TiePoints, ref: Refinement, key_t: np.ndarray) -> Path:
    """Two panels: the pixel residuals' distribution and their RMS per keyframe, before and after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    before = np.hypot(*ref.residual_px_before.T)
    after = np.hypot(*ref.residual_px_after.T)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    top = float(np.nanpercentile(before, 99)) if np.isfinite(before).any() else 1.0
    bins = np.linspace(0, max(top, 1e-3), 60)
    a.hist(before[np.isfinite(before)], bins=bins, alpha=0.6, label="telemetry as given")
    a.hist(after[np.isfinite(after)], bins=bins, alpha=0.6, label="refined")
    a.set_xlabel("tie-point residual (px)")
    a.set_ylabel("observations")
    a.legend()
    k = key_t.size
    per_b = np.full(k, np.nan)
    per_a = np.full(k, np.nan)
    for i in range(k):
        m = ties.frame == i
        if m.any():
            with np.errstate(invalid="ignore"):
                per_b[i] = np.sqrt(np.nanmean(before[m] ** 2))
                per_a[i] = np.sqrt(np.nanmean(after[m] ** 2))
    b.plot(key_t, per_b, "o-", ms=3, label="telemetry as given")
    b.plot(key_t, per_a, "o-", ms=3, label="refined")
    b.set_xlabel("video time (s)")
    b.set_ylabel("RMS residual (px)")
    b.set_yscale("log")
    b.legend()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# -- photo sets -------------------------------------------------------------------------------------

PHOTO_ESTIMATE = ("mount", "heading")  # a photo set has no clock between pictures and poses


@dataclass
class PhotoRefineJob:
    """Per photo a row (``eoloc photo --json``'s pose keys, refined, with their 1-sigma and the
    values as given), the refinement, its tie points, the report, the photos not used and the
    budget entries refinement replaced."""

    rows: list[dict]
    refinement: Refinement | None
    ties: TiePoints | None
    report: dict
    failed: list[str] = field(default_factory=list)
    budget: dict | None = None  # [accuracy.budget] entries refinement replaced (with a budget given)


def refined_camera_attitude(yaw_deg, pitch_deg, roll_deg, mount_deg, heading_bias_deg) -> np.ndarray:
    """(..., 3) yaw, pitch, roll (deg) of a photo's camera after refinement: its earth-referenced
    attitude as given (R_ned<-camera body, ZYX), the heading bias taken out about the vertical, the
    mounting angles applied about the camera body's own axes (SensorModel's R_mount)."""
    from scipy.spatial.transform import Rotation

    from ..rotation import small_angle_rotation

    R = Rotation.from_euler("ZYX", np.stack(np.broadcast_arrays(np.asarray(yaw_deg, float) - heading_bias_deg,
                                                                  pitch_deg, roll_deg), -1), degrees=True)
    R = R * Rotation.from_matrix(small_angle_rotation(mount_deg))
    ypr = R.as_euler("ZYX", degrees=True)
    ypr[..., 0] %= 360.0
    return ypr


def refine_photos(paths, dem: DEM, *, settings: AdjustSettings | None = None, tie: TieSettings | None = None,
                  out: str | Path | None = None, reference: Reference | None = None, budget=None,
                  config_path: str | Path | None = None, priors_from_budget: Collection[str] = (),
                  progress: Callable[[str], None] | None = None) -> PhotoRefineJob:
    """Refine the camera attitudes of a set of overlapping drone photos (files or folders) on
    ``dem``: a mounting error and a heading (gimbal yaw) bias shared by the set, from tie points
    between the photos whose views the poses predict overlap. Each photo's row carries its refined
    attitude under ``eoloc photo --json``'s keys with its 1-sigma (``sigma_camera_yaw`` ...).
    ``budget`` (the [accuracy.budget] of ``config_path``): the priors of ``priors_from_budget``
    taken from it, and what refinement left unknown of it (:func:`eoloc.refine.correct.refined_budget`,
    over the photos' capture span) in the job's ``budget`` and, with ``out``, in
    ``config_refined.toml`` (the config with that budget: for the fixes made with the refined poses)."""
    import cv2

    from ..io.photo import read_photo
    from ..io.sources.photos import photo_files
    from ..sensor import Pose
    from .photo import photo_sensor_pose

    settings = settings if settings is not None else AdjustSettings(estimate=PHOTO_ESTIMATE)
    tie = tie if tie is not None else TieSettings()
    if "time" in settings.estimate:
        raise InputError("--estimate time: photos have no clock offset to estimate (each photo carries its own "
                         "pose); choose from mount, boresight, heading")
    if not isinstance(dem, DEM):
        raise InputError("refining needs the terrain: --dem FILE (the tie points' heights are held to it)")
    say = progress or (lambda _msg: None)
    t_start = time.perf_counter()
    files: list[Path] = []
    for p in paths:
        files += photo_files(Path(p)) if Path(p).is_dir() else [Path(p)]
    poses, images, failed = [], [], []
    for f in files:
        try:
            pose = read_photo(f)
        except EolocError as exc:
            failed.append(str(exc))
            continue
        image = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)
        if image is None or image.shape[:2] != (pose.height, pose.width):
            failed.append(f"{f}: its pixels cannot be read as a {pose.width} x {pose.height} image")
            continue
        poses.append(pose)
        images.append(image)
    if len(poses) < 3:
        raise InputError(f"{len(poses)} usable photo(s): refining needs three or more that overlap", failed)
    lat = float(np.nanmedian([p.lat_deg for p in poses]))
    if budget is not None and priors_from_budget:
        settings = budget_settings(settings, budget, lat, priors_from_budget)
    cameras: list = []
    frame_sensor = []
    sensors = []
    for p in poses:
        s, _ = photo_sensor_pose(p)
        key = (p.camera, p.width, p.height)
        if key not in cameras:
            cameras.append(key)
            sensors.append(s)
        frame_sensor.append(cameras.index(key))
    frame_sensor = np.array(frame_sensor, dtype=np.int64)
    k = len(poses)
    col = {n: np.array([getattr(p, n) for p in poses], dtype=np.float64)
           for n in ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg")}
    # each photo its own instant: a "clock" of photo numbers, the poses taken at their own numbers
    track = TelemetryTrack(np.arange(k, dtype=np.float64),
                           Pose(col["lat_deg"], col["lon_deg"], col["h_m"], col["yaw_deg"], col["pitch_deg"],
                                col["roll_deg"], (np.zeros(k), np.zeros(k))), max_gap_s=1.5)
    rule = OnDEM(dem)
    start = [photo_sensor_pose(p)[1] for p in poses]
    say(f"predicting the overlap of {k} photos")
    overlap = predicted_overlap([sensors[i] for i in frame_sensor], start, rule)
    pairs = choose_pairs(overlap, tie)
    say(f"matching {len(pairs)} photo pairs")
    ties = find_tie_points(images, pairs, tie)
    control = None
    if reference is not None:
        say(f"matching {k} photos to the reference")
        control = control_points(images, [sensors[i] for i in frame_sensor], start, rule, reference, tie)
    del images
    say(f"adjusting {len(ties)} observations of {ties.n_tracks} tie points"
        + (f" and {len(control)} control points" if control is not None else ""))
    ref = adjust(sensors, frame_sensor, track, np.arange(k, dtype=np.float64), ties, rule, dem, settings,
                 **reference_weights(reference, control))
    clock = {"total_s": time.perf_counter() - t_start}
    rows = photo_rows(poses, ref)
    report = refine_report(ref, ties, np.arange(k), len(pairs), settings, clock)
    job = PhotoRefineJob(rows, ref, ties, report, failed)
    if budget is not None:
        from ..refine.correct import refined_budget

        job.budget, report["budget"] = refined_budget(budget, ref, photo_span_s([p.time for p in poses]), lat,
                                                      settings.frame_sigma_deg)
    if out is not None:
        import json

        from ..io.writers import write_layer

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "refine.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        write_layer(out, "photos_refined", rows, ["csv"])
        write_odm_geo(out / "geo.txt", rows)
        job.failed += write_sidecars(out / "xmp", rows)
        residual_plot(out / "residuals.png", ties, ref, np.arange(k, dtype=np.float64))
        if job.budget and config_path is not None:
            from ..io.config import write_calibration

            refined = out / "config_refined.toml"
            refined.write_text(Path(config_path).read_text(encoding="utf-8"), encoding="utf-8")
            write_calibration(refined, budget=job.budget, budget_note="refined by eoloc refine (refine.json: budget)")
    return job


def write_sidecars(folder: Path, rows: list[dict]) -> list[str]:
    """Each photo's XMP sidecar with its refined pose (``folder``/NAME.xmp: its own XMP packet, the
    pose's values changed; :func:`eoloc.io.xmpsidecar.refined_sidecar`); the notes of what could
    not be written."""
    from ..io.xmpsidecar import refined_sidecar

    folder.mkdir(parents=True, exist_ok=True)
    notes = []
    for r in rows:
        moved = r.get("sigma_camera_lat_m") is not None
        shift = ((r["camera_lat"] - r["given_camera_lat"], r["camera_lon"] - r["given_camera_lon"],
                  r["camera_h"] - r["given_camera_h"]) if moved else None)
        try:
            text, more = refined_sidecar(r["file"], r["camera_yaw"], r["camera_pitch"], r["camera_roll"], shift)
        except EolocError as exc:
            notes.append(f"{exc}: no sidecar")
            continue
        (folder / f"{Path(r['file']).stem}.xmp").write_text(text, encoding="utf-8")
        notes += more
    return notes


def write_odm_geo(path: Path, rows: list[dict]) -> Path:
    """OpenDroneMap's image geolocation file (its docs, "Image Geolocation Files"): EPSG:4326, then
    per photo its name, longitude, latitude, height (ellipsoidal), yaw, pitch, roll (eoloc photo's
    camera attitude, deg) and, where refinement estimated the position, its horizontal and vertical
    1-sigma (m). ODM reads a geo.txt in the project folder, or --geo PATH."""
    lines = ["EPSG:4326"]
    for r in rows:
        acc = ""
        if r.get("sigma_camera_lat_m") is not None:
            acc = (f" {math.hypot(r['sigma_camera_lat_m'], r['sigma_camera_lon_m']):.3f}"
                   f" {r['sigma_camera_h']:.3f}")
        lines.append(f"{Path(r['file']).name} {r['camera_lon']:.9f} {r['camera_lat']:.9f} {r['camera_h']:.3f} "
                     f"{r['camera_yaw']:.6f} {r['camera_pitch']:.6f} {r['camera_roll']:.6f}{acc}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def photo_rows(poses, ref: Refinement) -> list[dict]:
    """One row per photo: the refined camera attitude under ``eoloc photo --json``'s keys, its
    1-sigma by first-order propagation of the estimates' covariance, and the values as given."""
    names = list(ref.names)
    mount_idx = [names.index(n) if n in names else -1 for n in GROUPS["mount"]]
    hb_idx = names.index("heading_bias_deg") if "heading_bias_deg" in names else -1

    def attitude(p, x, e):  # e: the photo's own correction (roll, pitch, yaw)
        mount = [x[i] if i >= 0 else m for i, m in zip(mount_idx, ref.sensors[0].mount_misalignment_deg,
                                                         strict=True)]
        hb = x[hb_idx] if hb_idx >= 0 else ref.heading_bias_deg
        return refined_camera_attitude(p.yaw_deg + e[2], p.pitch_deg + e[1], p.roll_deg + e[0], mount, hb)

    from ..refine.adjust import position_bias, shift_position
    from ..sensor import Pose

    bias = position_bias(ref.names, ref.values)
    pos_sigma = [float(ref.sigma[names.index(n)]) if n in names else None for n in REFINE_GROUPS["position"]]
    own = ref.frame_attitude_deg if ref.frame_attitude_deg.size else np.zeros((len(poses), 3))
    own_sigma = ref.frame_attitude_sigma_deg if ref.frame_attitude_sigma_deg.size else np.zeros((len(poses), 3))
    rows = []
    for p, e, es in zip(poses, own, own_sigma, strict=True):
        moved = shift_position(Pose(p.lat_deg, p.lon_deg, p.h_m), bias)
        ypr = attitude(p, ref.values, e)
        J = np.empty((3, len(names)))
        for j in range(len(names)):
            step = np.zeros(len(names))
            step[j] = 1e-6
            d = attitude(p, ref.values + step, e) - ypr
            d[0] = (d[0] + 180.0) % 360.0 - 180.0
            J[:, j] = d / 1e-6
        # the shared estimates' part, and the photo's own correction's (yaw, pitch, roll; its cross
        # terms with the shared ones left out)
        sig = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", J, ref.cov, J), 0.0) + es[::-1] ** 2)
        rows.append(json_safe({
            "file": p.path, "camera_lat": float(moved.lat_deg), "camera_lon": float(moved.lon_deg),
            "camera_h": float(moved.h_m),
            "camera_yaw": float(ypr[0]), "camera_pitch": float(ypr[1]), "camera_roll": float(ypr[2]),
            "sigma_camera_lat_m": pos_sigma[1], "sigma_camera_lon_m": pos_sigma[0], "sigma_camera_h": pos_sigma[2],
            "sigma_camera_yaw": float(sig[0]), "sigma_camera_pitch": float(sig[1]), "sigma_camera_roll": float(sig[2]),
            "given_camera_yaw": p.yaw_deg, "given_camera_pitch": p.pitch_deg, "given_camera_roll": p.roll_deg,
            "given_camera_lat": p.lat_deg, "given_camera_lon": p.lon_deg, "given_camera_h": p.h_m,
            "refined": "attitude and position" if pos_sigma[0] is not None else
                       "attitude (the position as given: not estimated)"}))
    return rows
