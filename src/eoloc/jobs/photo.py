"""The `eoloc photo` job: drone photos located from their own EXIF/XMP pose (:mod:`eoloc.io.photo`).

Each photo's camera is a pinhole (or the database's lens model) whose attitude is the one the photo
gives, earth-referenced: the pose's yaw/pitch/roll are the camera's, with a zero az-el gimbal
(camera z along the body's x axis). The image centre is located by the laser range when the photo
has one; every other pixel (and the centre of a photo without a range) on the DEM or the target
height given. Every photo is its own row or rows; one that cannot be read is a row with its
reason, and the others are still located. With an error budget every fix also gets its
first-order uncertainty (:func:`eoloc.accuracy.covariance.locate_with_covariance`: the budget's
``yaw_deg``/``pitch_deg``/``roll_deg`` are the camera attitude's errors here, ``lat_deg``/
``lon_deg``/``h_m`` the position's, ``range_m`` the laser's, ``terrain_m`` the surface's).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.photo import POSE_FIELDS, PhotoPose, read_photo
from ..result import Status
from ..rules import StopRule

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".dng")


@dataclass
class PhotoJob:
    rows: list[dict]
    photos: list[PhotoPose] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)  # one line per photo that could not be located
    footprints: list[dict] = field(default_factory=list)  # GeoJSON features, one per photo (with a ground)
    orthos: list[Path] = field(default_factory=list)  # the orthorectified photos written (ortho_dir)


@dataclass(frozen=True)
class OrthoSettings:
    """How each photo is orthorectified (`eoloc rectify`'s options): output CRS, cell size (m;
    None: the native GSD at the centre), resampling, nodata value, terrain occlusion."""

    crs: str = "utm"
    gsd_m: float | None = None
    resampling: str = "bilinear"
    nodata: float = 0
    occlusion: bool = True


def photo_sensor_pose(p: PhotoPose):
    """(SensorModel, Pose) of a photo: its camera with the photo's earth-referenced attitude."""
    from ..sensor import AzElGimbal, Pose, SensorModel

    return SensorModel(p.camera, AzElGimbal()), Pose(p.lat_deg, p.lon_deg, p.h_m, p.yaw_deg, p.pitch_deg, p.roll_deg,
                                                      (0.0, 0.0))


def photo_job(paths, *, pixels=(), ground: StopRule | None = None, geoid=None,
              budget=None, ortho_dir: Path | None = None, ortho: OrthoSettings = OrthoSettings(),
              poses: dict[str, dict[str, float]] | None = None, poses_from: str = "") -> PhotoJob:
    """Every photo of ``paths`` (files, or folders standing for the photos in them) located at
    ``pixels`` ((u, v) pairs; none: the image centre); ``budget`` (an ErrorBudget): each fix's
    covariance columns (sigma_e_m ... ce90_m, le90_m). With a ``ground`` (a stop rule on a
    surface: ``OnDEM(dem)`` or ``AtHeight(h)``) each photo's footprint too; with ``ortho_dir``
    each photo orthorectified onto that ground as ``<ortho_dir>/<photo name>.tif`` (a
    Cloud-Optimised GeoTIFF), written as it is made (one photo's pixels in memory at a time).
    ``poses`` ({photo file name: camera_lat ... camera_roll},
    :func:`eoloc.io.photo.read_photo_poses`, read from ``poses_from``): each named
    photo's camera pose replaced (a refined one); a photo it does not name keeps its own, and is
    said."""
    from ..ground.footprint import footprint_features, footprints
    from ..io.sources.photos import photo_files

    job = PhotoJob([])
    expanded = []
    for path in paths:
        if Path(path).is_dir():
            found = photo_files(Path(path))
            if not found:
                job.failed.append(f"{path}: a folder with no photo in it")
                job.rows.append({"file": str(path), "status": "UNREADABLE", "reason": "a folder with no photo in it"})
            # named like a photo but not one inside (photos are told by content): said, not skipped in silence
            for odd in sorted(set(Path(path).glob("*")) - set(found)):
                if odd.is_file() and odd.suffix.lower() in PHOTO_SUFFIXES:
                    msg = f"{odd}: named like a photo but its bytes are not a JPEG or TIFF (damaged, or not a photo)"
                    job.failed.append(msg)
                    job.rows.append({"file": str(odd), "status": "UNREADABLE", "reason": msg})
            expanded += found
        else:
            expanded.append(path)
    used: set[str] = set()
    for path in expanded:
        try:
            p = read_photo(path, geoid=geoid)
        except InputError as exc:  # PhotoError, or a camera that cannot be made
            job.failed.append(str(exc))
            job.rows.append({"file": str(path), "status": "UNREADABLE", "reason": str(exc)})
            continue
        if poses is not None:
            q = poses.get(Path(path).name)
            if q is None:
                job.failed.append(f"{path}: not in {poses_from or 'the poses given'}: located with its own pose")
            else:
                p = dataclasses.replace(p, **{name: q[key] for key, name in POSE_FIELDS.items()},
                                        height_rule=f"from {poses_from or 'the poses'}",
                                        notes=[*p.notes, f"pose from {poses_from or 'the poses given'}"])
        job.photos.append(p)
        rows = locate_photo(p, pixels=pixels, ground=ground, budget=budget)
        job.rows += rows
        job.failed += [r["reason"] for r in rows if r["status"] in ("SUSPECT_ALTITUDE", "NO_SURFACE")]
        if ground is None or any(r["status"] == "SUSPECT_ALTITUDE" for r in rows):
            continue
        sensor, pose = photo_sensor_pose(p)
        job.footprints += footprint_features(footprints(sensor, pose, ground), [{"file": str(path)}])
        if ortho_dir is not None:
            job.orthos.append(_write_ortho(p, sensor, pose, ground, ortho, Path(ortho_dir), used))
    return job


def _write_ortho(p: PhotoPose, sensor, pose, ground: StopRule, settings: OrthoSettings, folder: Path,
                 used: set[str]) -> Path:
    """One photo orthorectified (:func:`eoloc.ground.rectify.orthorectify`) and written as a COG
    named after it (two photos of one name, from two folders, get -2, -3, ...)."""
    from ..ground import rectify
    from ..io.raster import read_image, write_ortho

    result = rectify.orthorectify(read_image(p.path), sensor, pose, ground, crs=settings.crs, gsd_m=settings.gsd_m,
                                  resampling=settings.resampling, nodata=settings.nodata,
                                  occlusion=settings.occlusion)
    stem, k = Path(p.path).stem, 1
    while (stem if k == 1 else f"{stem}-{k}") in used:
        k += 1
    name = stem if k == 1 else f"{stem}-{k}"
    used.add(name)
    return write_ortho(result, folder / f"{name}.tif", tags={"EOLOC_SOURCE": Path(p.path).name,
                                                           "EOLOC_SURFACE": ground_tag(ground)})


def locate_photo(p: PhotoPose, *, pixels=(), ground: StopRule | None = None, budget=None) -> list[dict]:
    """The rows of one photo read by :func:`eoloc.io.photo.read_photo`: one per pixel (none: the
    image centre, by its laser range when it has one; else on the ``ground`` rule), each with
    its status, the camera's pose and,
    with ``budget``, its uncertainty; a single SUSPECT_ALTITUDE row when the camera would be under
    the DEM, a NO_SURFACE row for a pixel with nothing to stop its ray."""
    from .. import geodesy
    from ..rules import AtRange
    from ..sensor import dronemodels

    path = p.path
    sensor, pose = photo_sensor_pose(p)
    camera = {"camera_lat": p.lat_deg, "camera_lon": p.lon_deg, "camera_h": p.h_m, "camera_yaw": p.yaw_deg,
              "camera_pitch": p.pitch_deg, "camera_roll": p.roll_deg}
    dem = None if ground is None else ground.terrain
    if dem is not None:  # the camera must be above the ground it flies over: else its height tag is wrong
        under = float(dem.height(p.lat_deg, p.lon_deg))
        if math.isfinite(under) and p.h_m < under - 2.0:
            msg = (f"{path}: the camera would be {under - p.h_m:.1f} m below the terrain under it "
                   f"({p.height_rule}; the DEM says {under:.1f} m): the altitude tag is suspect (RelativeAltitude "
                   f"{p.relative_altitude_m} m above take-off)")
            return [{"file": str(path), "status": "SUSPECT_ALTITUDE", "reason": msg, **camera}]
    rows = []
    todo = list(pixels) or [(p.camera.cx, p.camera.cy)]
    tle = dronemodels.tle_model(p.make, p.model, p.width, p.height, thermal=p.thermal)
    for u, v in todo:
        centre = not pixels
        if centre and p.lrf_range_m is not None:
            rule, source = AtRange(p.lrf_range_m), "laser"
        elif ground is not None:
            rule, source = ground, ("dem" if dem is not None else "height")
        else:
            msg = (f"{path}: pixel ({u:g}, {v:g}) has no laser range: give --dem FILE or --target-height H to "
                   "stop its ray")
            rows.append({"file": str(path), "u": u, "v": v, "status": "NO_SURFACE", "reason": msg, **camera})
            continue
        uv = (np.array([u], float), np.array([v], float))
        if budget is not None:
            from ..accuracy.covariance import covariance_columns, locate_with_covariance

            f, cov = locate_with_covariance(sensor, pose, budget, uv, rule)
            uncertainty = {k: _f(c[0]) for k, c in covariance_columns(cov, f.ok).items()}
        else:
            f, uncertainty = rule.locate(sensor, pose, uv), {}
        st = Status(int(f.status[0]))
        row = {"file": str(path), "u": float(u), "v": float(v), "lat": _f(f.lat_deg[0]), "lon": _f(f.lon_deg[0]),
               "h": _f(f.h_m[0]), "range_m": _f(f.range_m[0]), "status": st.name, "source": source, **camera,
               "camera_model": f"{p.make} {p.model}", "intrinsics": p.camera_source, "height_rule": p.height_rule}
        if st != Status.OK:
            row["reason"] = st.explanation
        else:
            row |= {k: x for k, x in uncertainty.items() if x is not None}
            if tle is not None:  # the database's flight-test figure for this camera: a + b x slant range
                row["tle_m"] = tle[0] + tle[1] * float(f.range_m[0])
        if source == "laser" and p.lrf_target is not None:
            t = p.lrf_target
            row |= {"vendor_lat": t[0], "vendor_lon": t[1], "vendor_h": t[2]}
            if st == Status.OK:
                e, n, up = geodesy.ecef_to_enu(np.stack(geodesy.geodetic_to_ecef(*t), -1)[None],
                                               f.lat_deg[0], f.lon_deg[0], f.h_m[0])[0]
                row |= {"vendor_offset_h_m": float(math.hypot(e, n)), "vendor_offset_v_m": float(up)}
        rows.append(row)
    return rows


def ground_tag(ground: StopRule) -> str:
    """The ground an ortho stands on, for its GeoTIFF tags: "DEM", or the height ("120 m")."""
    from ..ground.rectify import level_height

    return "DEM" if ground.terrain is not None else f"{level_height(ground):g} m"


def _f(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None
