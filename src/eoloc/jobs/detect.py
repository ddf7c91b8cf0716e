"""Moving targets found in a video's frames (:mod:`eoloc.detect`): the frames with their poses
through the motion detector, its blobs located and tracked on the ground."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from ..detect.motion import MotionDetector, MotionSettings
from ..detect.movers import Movers, MoverSettings, MoverTracker
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel

PosedFrame = tuple[int, float, np.ndarray, SensorModel, Pose]


def detect_movers(frames: Iterable[PosedFrame], rule: StopRule, motion: MotionSettings | None = None,
                  movers: MoverSettings | None = None, *, total: int | None = None,
                  progress: Callable[[int, int], None] | None = None) -> Movers:
    """Frames (index, time s, image uint8, sensor, pose) in time order -> the movers. A frame
    without a pose is left out of ``frames`` (it is neither searched nor a reference)."""
    detector = MotionDetector(rule, motion)
    tracker = MoverTracker(rule, movers or MoverSettings())
    posed: dict[int, tuple[SensorModel, Pose]] = {}
    done = 0

    def take(blobs_list) -> None:
        for b in blobs_list:
            sensor, pose = posed.pop(b.index)
            tracker.add(b, sensor, pose)

    for index, t, image, sensor, pose in frames:
        posed[index] = (sensor, pose)
        take(detector.push(index, t, image, sensor, pose))
        done += 1
        if progress is not None:
            progress(done, total or done)
    take(detector.flush())
    return tracker.result()
