"""Targets from the pixels: moving-target indication with the camera's motion removed
(:mod:`eoloc.detect.motion`), its blobs located on the ground and tracked
(:mod:`eoloc.detect.movers`)."""

from .motion import Blobs, MotionDetector, MotionSettings

__all__ = ["Blobs", "MotionDetector", "MotionSettings"]
