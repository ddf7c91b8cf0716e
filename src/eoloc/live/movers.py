"""Movers found in a live stream's own video (`eoloc live --detect motion|MODEL.onnx`).

The session hands over, as they arrive, the transport packets of the stream's video PID and each
ST 0601 packet's pose with its presentation time (:meth:`LiveMovers.video`, :meth:`LiveMovers.pose`);
a worker thread does the rest, so that the KLV path keeps its latency:

1. the video PES packets put together and decoded (:mod:`eoloc.live.video`);
2. each frame given its pose at its presentation time, interpolated between the KLV packets
   around it (:func:`eoloc.sequence.sync.poses_at_frames`, as `eoloc video` pairs them: a frame
   outside the packets or in a gap longer than ``max_gap_s`` has no pose and is not searched);
   its camera a pinhole whose fields of view (tags 16, 17) span the picture, on ST 0601's turret;
3. the motion detector (:class:`eoloc.detect.MotionDetector`: each frame against frames up to
   ``window_s`` before and after it, warped through the poses and the ground), or a learned
   detector's boxes, located and tracked on the ground (:class:`eoloc.detect.movers.MoverTracker`);
4. a track is sent once it is a mover by the batch's own tests, decided online
   (:meth:`~eoloc.detect.movers.MoverTracker.is_mover`: confirmed, ``min_track_s`` long, seen in
   half the frames it spans, its filtered speed at least ``min_speed_mps``) — its detections until
   then (up to EARLIER_KEPT) in that update, before the newest — and from then on with every
   detection: an update whose ``movers`` are GeoJSON features (``what`` "mover": the
   ground point, id, filtered speed and heading, box, and with an error budget its sigmas, CE90
   and LE90), drawn on the live map, written to NDJSON and sent as CoT.

A mover's latency: its frame is searched once the frames ``window_s`` after it have come, so
movers trail the video by ``window_s`` plus the work (:meth:`LiveMovers.summary` measures it from
the frame's arrival to its update). A worker that falls behind a live source skips the frames
that arrived more than ``max_lag_s`` before it reaches them rather than lag (``frames_skipped``),
and drops video bytes past ``max_queue_bytes`` waiting (``video_dropped``); a file read as fast as
it can be (``wait=True``) is searched whole.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections import deque
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..detect.learned import LearnedDetector
from ..detect.motion import MotionDetector, MotionSettings
from ..detect.movers import MoverSettings, MoverTracker
from ..ground.frame import FrameSensors, misb_sensor, packet_pose
from ..io.export import utc_times
from ..rules import StopRule
from ..sequence.sync import Metadata, poses_at_frames
from .update import PacketUpdate
from .video import PesAssembler, VideoDecoder

POSE_COLUMNS = ("lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg",
                "sensor_roll_deg")
VALUES = ("hfov_deg", "vfov_deg", "time_s")
RECORDS_KEPT = 4096  # KLV packets kept to pose frames at most (over 2 minutes at 30 packets/s)
RECORDS_S = 10.0  # and only those of the last 10 s of presentation time (each frame looks at them all)
EARLIER_KEPT = 256  # detections of a track kept until it is known to move (sent then, before its newest)
FRAMES_WAITING = 32  # decoded frames waiting for the KLV after them (beyond: posed with what there is; ~1 s)
END = object()


@dataclass(frozen=True)
class Record:
    """One ST 0601 packet's pose and view on the video's clock."""

    pts_s: float
    values: tuple  # POSE_COLUMNS then VALUES
    name: str
    stream: str
    packet: int


class LiveMovers:
    """The movers of one live stream's video (see the module notes). ``rule``: the ground (a DEM);
    ``motion``: the motion detector's settings, or ``learned``: an ONNX detector instead;
    ``settings``: what makes a mover (default: 2 m/s, 0 for a learned detector); ``budget``: each
    mover fix's uncertainty; ``sensor``: the installation (misalignments) frames are seen with;
    ``wait``: block the feeder instead of dropping (a file read as fast as it can be); ``max_gap_s``:
    the longest KLV gap a frame's pose is interpolated across; ``max_lag_s``: see the module notes."""

    def __init__(self, rule: StopRule, *, motion: MotionSettings | None = None, learned: LearnedDetector | None = None,
                 settings: MoverSettings | None = None, budget=None, sensor=None, wait: bool = False,
                 max_gap_s: float = 0.5, max_lag_s: float = 1.0, max_queue_bytes: int = 64 << 20,
                 source: str = "") -> None:
        self.rule, self.learned, self.budget = rule, learned, budget
        self.motion = motion or MotionSettings()
        self.settings = settings or MoverSettings(min_speed_mps=0.0 if learned is not None else 2.0)
        self.base = sensor or misb_sensor()
        self.wait, self.max_gap_s, self.max_lag_s, self.max_queue_bytes = wait, max_gap_s, max_lag_s, max_queue_bytes
        self.source = source
        self.inbox: queue.Queue = queue.Queue()
        self.queued_bytes = 0
        self.lock = threading.Lock()
        self.room = threading.Condition(self.lock)
        self.outbox: queue.Queue = queue.Queue()
        self.counts = {"video_frames": 0, "frames_posed": 0, "frames_unposed": 0, "frames_searched": 0,
                       "frames_skipped": 0, "video_dropped": 0, "pes_dropped": 0, "decode_errors": 0,
                       "detections": 0, "movers": 0, "mover_updates": 0}
        self.latency_s: deque[float] = deque(maxlen=10_000)
        self.failure: BaseException | None = None
        self.stream_type: int | None = None
        self.thread = threading.Thread(target=self._work, name="eoloc-movers", daemon=True)
        self.thread.start()

    # -- the session's side ---------------------------------------------------------------------

    def video(self, stream_type: int, cells: bytes, arrived: float) -> None:
        """The video PID's transport packets of one datagram (whole 188-byte cells)."""
        n = len(cells)
        with self.lock:
            if self.queued_bytes + n > self.max_queue_bytes:
                if not self.wait:
                    self.counts["video_dropped"] += 1
                    return
                while self.queued_bytes + n > self.max_queue_bytes and self.thread.is_alive():
                    self.room.wait(0.5)
            self.queued_bytes += n
        self.inbox.put(("video", stream_type, cells, arrived))

    def pose(self, pts_s: float | None, view: dict, name: str, stream: str, packet: int) -> None:
        """One ST 0601 packet's view (:func:`eoloc.io.klv.tables.packet_view`) at its presentation
        time (s; None: it has none, so it cannot be put on the video's clock and is left out)."""
        if pts_s is None or not math.isfinite(pts_s):
            return
        values = tuple(float(view[k]) for k in POSE_COLUMNS + VALUES)
        self.inbox.put(("pose", Record(pts_s, values, name, stream, packet)))

    def updates(self) -> list[PacketUpdate]:
        """The movers' updates ready now (each: one frame's movers)."""
        self._raise()
        out = []
        while True:
            try:
                out.append(self.outbox.get_nowait())
            except queue.Empty:
                return out

    def finish(self, timeout_s: float = 120.0) -> list[PacketUpdate]:
        """The end of the source: the frames still waiting searched, their updates."""
        self.inbox.put((END,))
        self.thread.join(timeout_s)
        return self.updates()

    def close(self) -> None:
        if self.thread.is_alive():
            self.inbox.put((END,))

    def summary(self) -> dict:
        lat = np.asarray(self.latency_s) * 1e3
        return {"movers": dict(self.counts) | {
            "latency_ms_median": float(np.median(lat)) if lat.size else None,
            "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else None,
            "window_s": self.motion.window_s if self.learned is None else 0.0}}

    def _raise(self) -> None:
        if self.failure is not None:  # a bug in the worker: shown, not swallowed
            failure, self.failure = self.failure, None
            raise failure

    # -- the worker -----------------------------------------------------------------------------

    def _work(self) -> None:
        try:
            self._run()
        except BaseException as exc:  # handed to the session's thread (updates() raises it)
            self.failure = exc

    def _run(self) -> None:
        self.records: deque[Record] = deque(maxlen=RECORDS_KEPT)
        self.waiting: deque[tuple[int, float, np.ndarray, float]] = deque()  # frames waiting for their pose
        self.assembler = PesAssembler()
        self.decoder: VideoDecoder | None = None
        self.detector = None if self.learned is not None else MotionDetector(self.rule, self.motion)
        self.tracker = MoverTracker(self.rule, self.settings, self.budget, history=False)
        self.posed: dict[int, tuple] = {}  # frame index -> (sensor, pose, record, unix s, arrival)
        self.ids: dict[str, int] = {}  # track key -> the mover's id (1, 2, ... as each is declared)
        self.earlier: dict[str, deque] = {}  # a track not (yet) a mover -> its detections so far
        self.sensors = FrameSensors(self.base)  # each frame's: its size and the packet's fields of view
        while True:
            item = self.inbox.get()
            if item[0] is END:
                break
            if item[0] == "pose":
                rec = item[1]
                while self.records and self.records[0].pts_s < rec.pts_s - RECORDS_S:  # what no frame to come needs
                    self.records.popleft()
                self.records.append(rec)
                self._pose_waiting(final=False)
                continue
            _, stream_type, cells, arrived = item
            with self.lock:
                self.queued_bytes -= len(cells)
                self.room.notify_all()
            self._decode(stream_type, cells, arrived)
        for pes in self.assembler.flush():
            self._frames(self.decoder.decode(pes) if self.decoder else [], time.perf_counter())
        if self.decoder is not None:
            self._frames(self.decoder.flush(), time.perf_counter())
        self._pose_waiting(final=True)
        if self.detector is not None:
            self._take(self.detector.flush())
        self.counts["pes_dropped"] = self.assembler.dropped
        self.counts["decode_errors"] = self.decoder.errors if self.decoder else 0

    def _decode(self, stream_type: int, cells: bytes, arrived: float) -> None:
        if self.decoder is None or stream_type != self.stream_type:
            self.decoder, self.stream_type = VideoDecoder(stream_type), stream_type
        for k in range(0, len(cells), 188):
            for pes in self.assembler.feed(cells[k:k + 188]):
                self._frames(self.decoder.decode(pes), arrived)

    def _frames(self, frames, arrived: float) -> None:
        for fr in frames:
            self.counts["video_frames"] += 1
            self.waiting.append((self.counts["video_frames"] - 1, fr.pts_s, fr.image, arrived))  # (its number)
        self._pose_waiting(final=False)

    def _pose_waiting(self, *, final: bool) -> None:
        """Pose the frames the KLV now reaches past (or every one, at the end or when too many wait)."""
        while self.waiting:
            newest = self.records[-1].pts_s if self.records else -math.inf
            index, pts_s, image, arrived = self.waiting[0]
            if pts_s > newest and not final and len(self.waiting) <= FRAMES_WAITING:
                return  # the packet after this frame has not come yet
            self.waiting.popleft()
            posed = self._pose_of(pts_s)
            if posed is None:
                self.counts["frames_unposed"] += 1
                continue
            pose, vals, rec = posed
            sensor = self.sensors.get(image.shape[1], image.shape[0], vals["hfov_deg"], vals["vfov_deg"])
            if sensor is None:
                self.counts["frames_unposed"] += 1
                continue
            self.counts["frames_posed"] += 1
            self._search(index, pts_s, image, sensor, pose, rec, vals["time_s"], arrived)

    def _pose_of(self, pts_s: float):
        """(pose, values, the record at or before) of a frame at ``pts_s``: the packet of the same
        presentation time (synchronous metadata), else interpolated between the packets around
        it; None outside them or across a gap longer than ``max_gap_s``."""
        recs = [r for r in self.records if abs(r.pts_s - pts_s) <= self.max_gap_s + 1.0]
        same = [r for r in recs if abs(r.pts_s - pts_s) < 0.5 / 90_000]
        if same:
            recs = same[-1:]
        elif len(recs) < 2:
            return None
        c = dict(zip(POSE_COLUMNS + VALUES, np.array([r.values for r in recs]).T, strict=True))
        poses = packet_pose(SimpleNamespace(columns=c))
        if same:
            return poses.take(0), {k: float(c[k][0]) for k in VALUES}, recs[0]
        fp = poses_at_frames(Metadata(np.array([r.pts_s for r in recs]), poses, {k: c[k] for k in VALUES}, "PTS"),
                             np.array([pts_s]), max_gap_s=self.max_gap_s)
        if not fp.ok[0]:
            return None
        pose, vals = fp.take(0)
        return pose, vals, recs[int(fp.record[0])]

    def _search(self, index: int, pts_s: float, image: np.ndarray, sensor, pose, rec: Record, unix_s: float,
                arrived: float) -> None:
        if not self.wait and time.perf_counter() - arrived > self.max_lag_s:  # the work fell behind the source
            self.counts["frames_skipped"] += 1
            return
        self.counts["frames_searched"] += 1
        self.posed[index] = (sensor, pose, rec, unix_s, arrived)
        if self.learned is not None:
            self._take([self.learned.detect(index, pts_s, image, sensor, pose)])
        else:
            self._take(self.detector.push(index, pts_s, image, sensor, pose))

    def _take(self, blobs_list) -> None:
        for blobs in blobs_list:
            sensor, pose, rec, unix_s, arrived = self.posed.pop(blobs.index)
            rows = self.tracker.add(blobs, sensor, pose)
            self.counts["detections"] += len(rows)
            when = utc_times(np.array([unix_s]), "unix")[0] if math.isfinite(unix_s) else None
            movers = []
            for row in rows:
                key = row.pop("track")
                row = self._feature(row, key, rec, when)
                if key not in self.ids:
                    if not self.tracker.is_mover(key):
                        earlier = self.earlier.setdefault(key, deque(maxlen=EARLIER_KEPT))
                        earlier.append(row)
                        continue
                    self.ids[key] = len(self.ids) + 1
                    self.counts["movers"] += 1
                    for f in self.earlier.pop(key, ()):  # what it was seen doing before it was known to move
                        f["properties"]["track_id"] = self.ids[key]
                        movers.append(f)
                    row["properties"]["track_id"] = self.ids[key]
                movers.append(row)
            for key in [k for k in self.earlier if k not in self.tracker.tracker.live]:  # ended as no mover
                del self.earlier[key]
            if movers:
                u = PacketUpdate(self.source, rec.stream, rec.packet, math.nan, False, None, None, None, None,
                                 time_utc=when, name=rec.name, movers=movers)
                self.counts["mover_updates"] += 1
                self.latency_s.append(time.perf_counter() - arrived)
                self.outbox.put(u)

    def _feature(self, row: dict, key: str, rec: Record, time_utc: str | None) -> dict:
        """A detection as a mover feature (``track_id`` None until its track is a mover): like every
        live feature with ``what``, ``stream``, ``packet`` (the KLV packet at or before its frame)
        and ``time_utc`` (its frame's, from the KLV's time stamps); ``frame``: the video frame's
        number since the session began (0-based, every decoded frame counted), ``pts_s`` its
        presentation time."""
        props = {"what": "mover", "stream": rec.stream, "packet": rec.packet, "time_utc": time_utc,
                 "track_id": self.ids.get(key), "frame": row.pop("frame"), "pts_s": row.pop("time_s"),
                 **self.tracker.now(key)}
        lon, lat, h = row.pop("lon_deg"), row.pop("lat_deg"), row.pop("h_m")
        return {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, h]},
                "properties": props | row}
