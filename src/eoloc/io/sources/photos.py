"""Drone photos as telemetry: one photo, or a folder of them (:func:`eoloc.io.photo.read_photo`).

One record per photo (sorted by file name; ``frame`` its index, ``line`` too), the camera's
earth-referenced attitude as the pose, the laser range (DJI LRF) as ``range_m``, and the camera the
photos carry — all of them must share one (the same model, size and intrinsics); a photo that
cannot be read costs its own record, named. Told apart by content: JPEG or TIFF magic bytes, or a
folder holding at least one such file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import TableError
from .base import SourceData

IMAGE_MAGIC = (b"\xff\xd8\xff", b"II*\x00", b"MM\x00*")


def is_image(head: bytes) -> bool:
    return head.startswith(IMAGE_MAGIC)


def photo_files(folder: Path) -> list[Path]:
    """The folder's image files (by content), sorted by name."""
    out = []
    for p in sorted(folder.iterdir()):
        if p.is_file():
            try:
                with open(p, "rb") as f:
                    if is_image(f.read(4)):
                        out.append(p)
            except OSError:
                continue
    return out


class DronePhotos:
    name = "photos"
    summary = "drone photos with EXIF/XMP pose (a JPEG/TIFF, or a folder of them)"

    def sniff(self, path: Path, head: bytes) -> bool:
        if path.is_dir():
            return bool(photo_files(path))
        return is_image(head)

    def read(self, path: Path, *, geoid=None, dem=None) -> SourceData:
        return read_photos(path, geoid=geoid, dem=dem)


def read_photos(path: str | Path, *, geoid=None, dem=None) -> SourceData:
    """The photos' poses as telemetry, their shared camera, and the photos that failed as issues."""
    from ...errors import InputError
    from ..photo import read_photo
    from ..table import Issue, Table
    from .heights import below_ground

    path = Path(path)
    files = photo_files(path) if path.is_dir() else [path]
    poses, issues = [], []
    for k, f in enumerate(files):
        try:
            poses.append((k, read_photo(f, geoid=geoid)))
        except InputError as exc:
            issues.append(Issue(str(f), 0, f"{exc}; photo skipped"))
    if not poses:
        raise TableError(f"{path}: no photo there could be read" + (f" (the first: {issues[0].message})" if issues
                                                                      else ""))
    camera = poses[0][1].camera
    kept = []
    for k, p in poses:
        if p.camera != camera:
            issues.append(Issue(p.path, 0, f"its camera ({p.make} {p.model}, {p.width}x{p.height}, {p.camera_source}) "
                                f"is not the first photo's ({poses[0][1].path}): photo skipped (give each camera's "
                                "photos on their own)"))
            continue
        kept.append((k, p))
    src = str(path)
    line = np.array([k for k, _ in kept], dtype=np.int64)
    ps = [p for _, p in kept]

    def arr(attr: str) -> np.ndarray:
        return np.array([np.nan if getattr(p, attr) is None else getattr(p, attr) for p in ps], dtype=np.float64)

    n = len(ps)
    lat, lon, h = arr("lat_deg"), arr("lon_deg"), arr("h_m")
    issues += below_ground(src, line, lat, lon, h, dem, ps[0].height_rule.split(" ")[0])
    cols = {"time_s": np.full(n, np.nan), "frame": line.astype(np.float64), "lat_deg": lat, "lon_deg": lon,
            "h_m": h, "yaw_deg": arr("yaw_deg"), "pitch_deg": arr("pitch_deg"), "roll_deg": arr("roll_deg"),
            "gimbal1_deg": np.zeros(n), "gimbal2_deg": np.zeros(n), "sensor_roll_deg": np.zeros(n),
            "range_m": arr("lrf_range_m"), "h_rel_m": arr("relative_altitude_m")}
    table = Table(src, cols, line, issues)
    table.columns["file"] = np.array([p.path for p in ps], dtype=object)
    notes = [f"camera: {ps[0].make} {ps[0].model} ({ps[0].camera_source}); heights: {ps[0].height_rule}"]
    return SourceData(table, DronePhotos.name, camera=camera, camera_attitude=True, notes=notes)


def with_poses(table, poses: dict[str, dict[str, float]], poses_from: str) -> list:
    """The photos' records of ``table`` (read by :func:`read_photos`) given the poses of ``poses``
    ({file name: camera_lat ... camera_roll}, :func:`eoloc.io.photo.read_photo_poses`, read from
    ``poses_from``) in place of their own; returns an issue for each photo not among them (it keeps
    its own pose)."""
    from ..photo import POSE_FIELDS
    from ..table import Issue

    names = [Path(str(f)).name for f in table.columns["file"]]
    found = np.array([n in poses for n in names], dtype=bool)
    for key, column in POSE_FIELDS.items():
        values = np.array(table.columns[column], dtype=np.float64)  # a copy: the reader's arrays stay as read
        values[found] = [poses[n][key] for n, ok in zip(names, found.tolist(), strict=True) if ok]
        table.columns[column] = values
    return [Issue(table.path, int(line), f"{name}: not in {poses_from}: located with its own pose")
            for name, line, ok in zip(names, table.line.tolist(), found.tolist(), strict=True) if not ok]
