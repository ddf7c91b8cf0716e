"""Targets found in a video's frames (:mod:`eoloc.detect`): the frames with their poses through
the motion detector or a learned one, the blobs or boxes located and tracked on the ground."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from ..detect.learned import LearnedDetector
from ..detect.motion import MotionDetector, MotionSettings
from ..detect.movers import Movers, MoverSettings, MoverTracker
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel

PosedFrame = tuple[int, float, np.ndarray, SensorModel, Pose]


def detect_movers(frames: Iterable[PosedFrame], rule: StopRule, motion: MotionSettings | None = None,
                  movers: MoverSettings | None = None, *, learned: LearnedDetector | None = None, budget=None,
                  total: int | None = None, progress: Callable[[int, int], None] | None = None) -> Movers:
    """Frames (index, time s, image uint8, sensor, pose) in time order -> the movers found by
    motion (``motion``'s settings) or the boxes of a ``learned`` detector, tracked. A frame
    without a pose is left out of ``frames`` (it is neither searched nor a reference). Without
    ``movers``: the defaults, standing targets kept for a learned detector (min_speed_mps 0).
    ``budget``: an ErrorBudget: each fix's absolute uncertainty (:class:`MoverTracker`)."""
    if movers is None:
        movers = MoverSettings(min_speed_mps=0.0) if learned is not None else MoverSettings()
    tracker = MoverTracker(rule, movers, budget)
    if learned is not None:
        for done, (index, t, image, sensor, pose) in enumerate(frames, start=1):
            tracker.add(learned.detect(index, t, image, sensor, pose), sensor, pose)
            if progress is not None:
                progress(done, total or done)
        return tracker.result()
    detector = MotionDetector(rule, motion)
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
