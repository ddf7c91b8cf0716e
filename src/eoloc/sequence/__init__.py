"""Many frames: telemetry at frame times, static targets by RLS (M6), tracks of moving targets (M7),
multi-view triangulation (M8), the accuracy of a flight flown, synthetic flights to test them on."""

from ..rules.multiview import Triangulation, triangulate
from .flight import FlightAccuracy, flight_accuracy, flight_errors
from .interp import Gap, InterpolatedPoses, interpolate_poses
from .rls import StaticEstimate, rls_static
from .simulate import Flight, TelemetryNoise, synthetic_flight

__all__ = ["Flight", "FlightAccuracy", "Gap", "InterpolatedPoses", "StaticEstimate", "TelemetryNoise", "Triangulation",
           "flight_accuracy", "flight_errors", "interpolate_poses", "rls_static", "synthetic_flight", "triangulate"]
