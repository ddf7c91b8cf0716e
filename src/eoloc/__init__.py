"""eoloc — geolocation of ground targets seen by airborne electro-optical sensors.

Conventions (one per concept, everywhere in the library):

- Ellipsoid WGS-84 (a = 6 378 137 m, f = 1/298.257223563). Geodetic latitude/longitude in
  **degrees** at the API (radians inside), heights **ellipsoidal** in metres; metres everywhere.
- ECEF: WGS-84 Earth-centred Earth-fixed. Local level: NED at the aircraft (ENU as a conversion).
- Body: FRD (x nose, y right wing, z down). Attitude: yaw (heading, clockwise from true north),
  pitch (nose up +), roll (right wing down +); R_ned_body = Rz(yaw) Ry(pitch) Rx(roll).
- All rotation matrices are **active**: ``v_a = R_a_b @ v_b``.
- Camera: x right in the image, y down, z along the boresight. Pixels: u = column, v = row, the
  centre of the top-left pixel is (0, 0).
- Results: :class:`Fixes` with a per-target :class:`Status`; NaN coordinates where not OK.
"""

from .errors import EolocError
from .kernels.backend import available_backends, get_backend, set_backend, threads, use_backend, use_threads
from .util.lazy import lazy_attributes

_WHERE = {  # the rest of the API, loaded on first use (so that `eoloc --help` loads no kernels)
    "WGS84": "geodesy", "Ellipsoid": "geodesy", "ecef_to_geodetic": "geodesy", "geodetic_to_ecef": "geodesy",
    "Fixes": "result", "Status": "result",
    **dict.fromkeys(("AtHeight", "AtRange", "FlatGround", "MultiView", "OnDEM", "StopRule", "locate", "locate_dem",
                     "locate_ellipsoid", "locate_flat", "locate_range", "stop_at_dem", "stop_at_ellipsoid",
                     "stop_at_range"), "rules"),
    **dict.fromkeys(("AzElGimbal", "Camera", "FixedMount", "Pose", "Rays", "RollPitchGimbal", "SensorModel"),
                    "sensor"),
    "BrownConrady": "sensor.distortion", "DistortionRatio": "sensor.distortion",
    "DEM": "terrain", "open_dem": "terrain",
}


__getattr__ = lazy_attributes(__name__, _WHERE)


def __dir__() -> list[str]:
    return sorted(__all__)


__version__ = "0.1.0"

__all__ = [
    "DEM",
    "WGS84",
    "AtHeight",
    "AtRange",
    "AzElGimbal",
    "BrownConrady",
    "Camera",
    "DistortionRatio",
    "Ellipsoid",
    "EolocError",
    "FixedMount",
    "Fixes",
    "FlatGround",
    "MultiView",
    "OnDEM",
    "Pose",
    "Rays",
    "RollPitchGimbal",
    "SensorModel",
    "Status",
    "StopRule",
    "__version__",
    "available_backends",
    "ecef_to_geodetic",
    "geodetic_to_ecef",
    "get_backend",
    "locate",
    "locate_dem",
    "locate_ellipsoid",
    "locate_flat",
    "locate_range",
    "open_dem",
    "set_backend",
    "stop_at_dem",
    "stop_at_ellipsoid",
    "stop_at_range",
    "threads",
    "use_backend",
    "use_threads",
]
