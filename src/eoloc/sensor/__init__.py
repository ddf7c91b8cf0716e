"""Sensor model: camera intrinsics, gimbal models, misalignment and lever arm -> rays."""

from .camera import Camera
from .distortion import BrownConrady, DistortionRatio, FisheyePix4D
from .gimbal import AzElGimbal, FixedMount, Gimbal, GimbalKind, RollPitchGimbal, gimbal_from_name
from .model import Pose, Rays, SensorModel

__all__ = [
    "AzElGimbal",
    "BrownConrady",
    "Camera",
    "DistortionRatio",
    "FisheyePix4D",
    "FixedMount",
    "Gimbal",
    "GimbalKind",
    "Pose",
    "Rays",
    "RollPitchGimbal",
    "SensorModel",
    "gimbal_from_name",
]
