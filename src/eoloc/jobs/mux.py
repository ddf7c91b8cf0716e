"""The `eoloc mux` job: a drone video with its telemetry (a DJI .SRT, a flight log, any source)
into an MPEG-TS with a MISB ST 0601 KLV stream, so that drone footage enters `eoloc video`, the
player, `eoloc live` and other tools (QGIS FMV, Esri, jMISB).

One ST 0601 packet per video frame, carried as MISB ST 1402 says (:func:`eoloc.io.klv.mux.add_klv`),
right after its frame's video data: asynchronously (stream_type 0x06, 'KLVA', PES stream_id 0xBD
without PTS: timed by the frame before it) or synchronously (stream_type 0x15 with the metadata
descriptors, one metadata access unit per video access unit with the frame's PTS). The frame's pose is the
telemetry interpolated at its time (:func:`eoloc.sequence.interp.interpolate_poses`; the records'
time_s are the video's clock, a DJI SRT's subtitle times). An aircraft's telemetry with an az-el
turret is written as it is (platform attitude 5-7, turret angles 18-20). Drone telemetry gives the
camera's own attitude, so the packet says so the way ST 0601 can: platform heading = the camera's yaw, platform
pitch and roll 0, sensor relative azimuth 0, relative elevation = the camera's pitch, relative roll
= its roll (the same rotation, Rz(yaw) Ry(pitch) Rx(roll)). Tags: 2 (UNIX time), 5-7, 13, 14, 15
(MSL, EGM96) and 75 (ellipsoidal), 16/17 (fields of view of the configured camera), 18-20, 65;
with a ground (a DEM or a height) also the frame centre 21, 23, 24, 25. A frame the telemetry does
not cover (before, after, or in a gap) gets no packet, and the count is said.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.table import Issue
from ..rules import StopRule


@dataclass
class MuxJob:
    path: Path
    frames: int
    packets: int
    carriage: str
    issues: list[Issue] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _st0601_attitude(inputs, sensor, p) -> dict[int, np.ndarray]:
    """ST 0601 attitude tags of the interpolated poses: the camera's own attitude (drones) as
    platform heading + relative elevation/roll (5, 6, 7 = yaw, 0, 0; 18, 19, 20 = 0, pitch, roll), an
    aircraft with an az-el turret as it is (5-7 the platform, 18-20 the turret); pitch and roll past
    ST 0601's short ranges (+-20, +-50 deg) in the full-range tags 90 and 91."""
    from ..sensor import AzElGimbal

    zero = np.zeros_like(p.yaw_deg)
    if inputs.source is not None and inputs.source.camera_attitude:
        return {5: p.yaw_deg % 360.0, 6: zero, 7: zero, 18: zero, 19: p.pitch_deg, 20: p.roll_deg % 360.0}
    if not isinstance(sensor.gimbal, AzElGimbal):
        raise InputError(f"{inputs.telemetry.path}: ST 0601 describes an az-el turret; telemetry for a "
                         f"{sensor.gimbal.name} gimbal cannot be written as its relative angles")
    az, el, *rest = (np.broadcast_to(np.asarray(g, dtype=np.float64), p.yaw_deg.shape) for g in p.gimbal_deg)
    roll_s = rest[0] if rest else zero
    pitch_tag = 6 if np.nanmax(np.abs(p.pitch_deg), initial=0.0) <= 20.0 else 90
    roll_tag = 7 if np.nanmax(np.abs(p.roll_deg), initial=0.0) <= 50.0 else 91
    return {5: p.yaw_deg % 360.0, pitch_tag: p.pitch_deg, roll_tag: p.roll_deg, 18: az % 360.0, 19: el,
            20: roll_s % 360.0}


def mux_job(video, telemetry, cfg, dest, *, carriage: str = "async", start_utc: datetime | None = None,
            ground: StopRule | None = None, max_gap_s: float = 1.5) -> MuxJob:
    """Write ``dest`` (see the module)."""
    from ..io.klv.encode import encode_uas_packet
    from ..io.klv.mux import add_klv, remux_video
    from ..io.telemetry import telemetry_pose
    from ..io.videofile import frame_times
    from ..sequence.interp import interpolate_poses
    from ..terrain.geoid import default_geoid
    from .inputs import job_inputs

    if carriage not in ("async", "sync"):
        raise InputError(f"--carriage {carriage!r}: choose async or sync")
    times = frame_times(video)
    if times.size == 0:
        raise InputError(f"{video}: the video stream has no frame with a presentation time")
    inputs = job_inputs(cfg, telemetry, dem=None if ground is None else ground.terrain)
    sensor = inputs.sensor(cfg)
    tel = inputs.telemetry
    t_rec = tel.columns["time_s"]
    if not np.isfinite(t_rec).any():
        raise InputError(f"{tel.path}: no times: a video's frames are paired with telemetry by time")
    notes: list[str] = []
    got = interpolate_poses(t_rec, telemetry_pose(tel, camera=sensor.camera), times - times[0], max_gap_s=max_gap_s)
    if not got.ok.any():
        raise InputError(f"{tel.path}: no frame of {video} falls within the telemetry's records (its times "
                         f"{np.nanmin(t_rec):g} to {np.nanmax(t_rec):g} s; the video lasts "
                         f"{times[-1] - times[0]:.2f} s)",
                         inputs.issues)
    if start_utc is not None:
        unix0 = start_utc.timestamp()
    else:
        dates = tel.columns.get("date_s")
        k = int(np.flatnonzero(np.isfinite(dates))[0]) if dates is not None and np.isfinite(dates).any() else -1
        if k < 0:
            raise InputError(f"{tel.path} gives no date: give --start-utc (the UTC time of the video's first frame, "
                             "ISO 8601) for the packets' time stamps (tag 2)")
        unix0 = float(dates[k] - t_rec[k])
        notes.append(f"time stamps from the telemetry's dates ({datetime.fromtimestamp(unix0, UTC).isoformat()} at "
                     "the first frame), taken as UTC: DJI writes its controller's local time; give --start-utc to "
                     "set it")
    p = got.pose
    cam = sensor.camera
    hfov = math.degrees(2 * math.atan(cam.width / 2 / cam.fx))
    vfov = math.degrees(2 * math.atan(cam.height / 2 / cam.fy))
    n_geoid = default_geoid().undulation(p.lat_deg, p.lon_deg)
    attitude = _st0601_attitude(inputs, sensor, p)
    centre = n_centre = None
    if ground is not None:
        centre = ground.locate(sensor, p, (np.full(times.size, cam.cx), np.full(times.size, cam.cy)))
        n_centre = default_geoid().undulation(centre.lat_deg, centre.lon_deg)
    by_frame: dict[int, bytes] = {}
    for i in np.flatnonzero(got.ok):
        values = {2: datetime.fromtimestamp(unix0 + float(times[i] - times[0]), UTC), 13: float(p.lat_deg[i]),
                  14: float(p.lon_deg[i]), 15: float(p.h_m[i] - n_geoid[i]), 75: float(p.h_m[i]), 16: hfov,
                  17: vfov, **{tag: float(v[i]) for tag, v in attitude.items()}}
        if centre is not None and centre.ok[i]:
            values.update({21: float(centre.range_m[i]), 23: float(centre.lat_deg[i]), 24: float(centre.lon_deg[i]),
                           25: float(centre.h_m[i] - n_centre[i])})
        by_frame[int(i)] = encode_uas_packet(values)
    missing = int((~got.ok).sum())
    if missing:
        notes.append(f"{missing} of {times.size} frames lie outside the telemetry or in a gap of it (> {max_gap_s:g} "
                     "s): no packet for them")

    import tempfile

    dest = Path(dest)
    with tempfile.TemporaryDirectory() as tmp:
        ts = remux_video(video, Path(tmp) / "video.ts")
        # the transport stream's own frame times: its muxer may start them later than the source's
        # (an MP4 with B-frames: its first frame at 0.0 s, in the TS at 0.2 s); the frames are the
        # same, in the same presentation order
        ts_times = frame_times(ts)

        def packet_for(n: int, pts_s: float) -> bytes | None:
            """The packet of the frame shown at pts_s in the transport stream (its times sorted)."""
            j = int(np.clip(np.searchsorted(ts_times, pts_s), 1, max(ts_times.size - 1, 1)))
            j = j - 1 if j > 0 and abs(ts_times[j - 1] - pts_s) <= abs(ts_times[j] - pts_s) else j
            return by_frame.get(j) if abs(ts_times[j] - pts_s) < 1e-3 else None

        if ts_times.size != times.size:
            raise InputError(f"{video}: its {times.size} frames came out of the remux as {ts_times.size}: "
                             "cannot pair them with the telemetry")
        add_klv(ts, dest, packet_for, carriage=carriage)
    return MuxJob(dest, int(times.size), len(by_frame), carriage, list(inputs.issues), notes)
