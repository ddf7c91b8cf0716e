"""Many frames: telemetry at frame times, multi-view triangulation (M8)."""

from .interp import Gap, InterpolatedPoses, interpolate_poses
from .triangulate import Triangulation, triangulate

__all__ = ["Gap", "InterpolatedPoses", "Triangulation", "interpolate_poses", "triangulate"]
