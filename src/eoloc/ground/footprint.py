"""Frame footprints: the ground outline of what a frame sees, on the ellipsoid or on a DEM.

The outline follows the image border (``edge_samples`` points per side, clockwise from the
top-left corner), each point located with the same stop rule as the targets (M3 on a constant
ellipsoidal height, or M4 on a DEM). Where a border ray misses the ground (above the horizon,
off the DEM, into a void), the outline is clipped instead of invented:

- the border point is replaced by the last ray that still meets the ground on the image segment
  from an *anchor* (the principal point, or the border point with the shortest range when the
  principal point misses) to it;
- where the border passes from ground to miss, the crossing point on the border is added.

Both are found by bisection on the ray's hit/miss status to 1e-9 of the segment (pixels), so the
vertices on the horizon are the grazing rays themselves. On the ellipsoid the image region that
sees the ground is convex (the rays meeting a convex body form a convex cone), so this outline is
exact; on a DEM the seen region need not be star-shaped from the anchor, and the outline is the
one visible from the anchor's direction (documented limitation).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..result import Fixes, Status
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel

_BISECTIONS = 26  # 2^-26 of a segment: below 1e-4 px on images up to 6000 px


@functools.cache
def _geod():
    import pyproj  # here, not at import: pyproj costs 60 ms of every command's start-up

    return pyproj.Geod(ellps="WGS84")


@dataclass(frozen=True)
class Footprint:
    """The ground outline of one frame (vertices in order, not closed).

    lat_deg, lon_deg, h_m: vertices (WGS-84 degrees, ellipsoidal m); u_px, v_px: the image point
    of each; clipped: True where the vertex is on the horizon / DEM edge / void edge rather than
    the image border's own ray; clip_status: why (NO_INTERSECTION: horizon, OUT_OF_COVERAGE: DEM
    edge, DEM_VOID), OK for unclipped vertices. status: OK, NO_INTERSECTION (no ground in view)
    or INVALID_INPUT (unusable pose). centre: the principal point's fix (NaN if it misses).
    """

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    clipped: np.ndarray
    clip_status: np.ndarray
    status: Status
    centre: tuple[float, float, float]

    def __len__(self) -> int:
        return int(self.lat_deg.size)

    @property
    def area_m2(self) -> float:
        """Geodesic area on the WGS-84 ellipsoid (pyproj), m^2; 0 without an outline."""
        if len(self) < 3:
            return 0.0
        area, _ = _geod().polygon_area_perimeter(self.lon_deg, self.lat_deg)
        return abs(float(area))

    def geojson_geometry(self) -> dict | None:
        """RFC 7946 Polygon (lon, lat, h), exterior ring closed and counter-clockwise."""
        if len(self) < 3:
            return None
        return polygon_geometry(self.lon_deg, self.lat_deg, self.h_m)


def polygon_geometry(lon_deg, lat_deg, h_m) -> dict:
    """An RFC 7946 Polygon from one ring of vertices (lon, lat, h): closed and counter-clockwise,
    whichever way the vertices came (image borders run clockwise on the ground). A ring that
    crosses the antimeridian is cut there into a MultiPolygon (RFC 7946 §3.1.9), each part within
    [-180, 180] and counter-clockwise, the cut edges on ±180 exactly (latitude and height
    interpolated linearly in unwrapped longitude)."""
    ring = np.column_stack([lon_deg, lat_deg, h_m]).astype(np.float64)
    area, _ = _geod().polygon_area_perimeter(ring[:, 0], ring[:, 1])
    if area < 0:  # pyproj: positive = counter-clockwise
        ring = ring[::-1]
    lon = np.asarray(ring[:, 0])
    unwrapped = lon[0] + np.concatenate([[0.0], np.cumsum((np.diff(lon) + 180.0) % 360.0 - 180.0)])
    closing = (lon[0] - lon[-1] + 180.0) % 360.0 - 180.0
    if abs(unwrapped[-1] + closing - unwrapped[0]) > 1e-9:  # the ring winds round a pole: not cut here
        unwrapped = lon
    shift = 360.0 * np.round(np.mean(unwrapped) / 360.0)
    u = np.column_stack([unwrapped - shift, ring[:, 1:]])
    if u[:, 0].max() <= 180.0 and u[:, 0].min() >= -180.0:
        return {"type": "Polygon", "coordinates": [_closed(u)]}
    edge = 180.0 if u[:, 0].max() > 180.0 else -180.0
    inside = _clip(u, edge, keep_below=edge > 0)
    outside = _clip(u, edge, keep_below=edge < 0)
    outside[:, 0] -= 2.0 * edge
    parts = [_closed(p) for p in (inside, outside) if len(p) >= 3]
    return {"type": "MultiPolygon", "coordinates": [[p] for p in parts]}


def _closed(ring: np.ndarray) -> list:
    ring = np.vstack([ring, ring[:1]])
    return [[round(float(c), 10) for c in p] for p in ring]


def _clip(ring: np.ndarray, x0: float, *, keep_below: bool) -> np.ndarray:
    """Sutherland–Hodgman: the part of a ring with x <= x0 (``keep_below``) or x >= x0, the points
    on the line interpolated linearly (the other columns too)."""
    def inside(p):
        return p[0] <= x0 if keep_below else p[0] >= x0

    out = []
    for i in range(len(ring)):
        a, b = ring[i - 1], ring[i]
        if inside(b):
            if not inside(a):
                out.append(a + (b - a) * (x0 - a[0]) / (b[0] - a[0]))
            out.append(b)
        elif inside(a):
            out.append(a + (b - a) * (x0 - a[0]) / (b[0] - a[0]))
    pts = np.array(out) if out else np.zeros((0, ring.shape[1]))
    if len(pts):
        pts[:, 0] = np.where(np.abs(pts[:, 0] - x0) < 1e-12, x0, pts[:, 0])
    return pts


def border_pixels(camera, edge_samples: int) -> np.ndarray:
    """(4 * edge_samples, 2) points on the image's outer border, clockwise from the top-left corner."""
    if edge_samples < 1:
        raise InputError(f"edge_samples must be >= 1, got {edge_samples}")
    corners = camera.corners_px()
    s = np.arange(edge_samples)[:, None] / edge_samples
    return np.vstack([corners[k] + s * (corners[(k + 1) % 4] - corners[k]) for k in range(4)])


def footprints(sensor: SensorModel, pose: Pose, ground: StopRule, *, edge_samples: int = 16) -> list[Footprint]:
    """Footprint of every pose element (a frame each; pose fields scalars or 1-D arrays) on the
    ``ground`` rule's surface: ``AtHeight(h)`` (M3) or ``OnDEM(dem)`` (M4)."""
    n = _n_frames(pose)
    frames = pose.take(np.arange(n))
    border = border_pixels(sensor.camera, edge_samples)
    S = border.shape[0]
    fb = _stop(sensor, frames.take(np.repeat(np.arange(n), S)), np.tile(border, (n, 1)), ground)
    ok_b = (fb.status == Status.OK).reshape(n, S)
    centre_px = np.array(sensor.camera.centre_px)
    fc = _stop(sensor, frames, np.tile(centre_px, (n, 1)), ground)
    anchor = np.tile(centre_px, (n, 1))
    has_anchor = fc.status == Status.OK
    rng_b = np.where(ok_b, np.reshape(fb.range_m, (n, S)), np.inf)
    use_border = ~has_anchor & ok_b.any(axis=1)
    anchor[use_border] = border[np.argmin(rng_b[use_border], axis=1)]
    has_anchor |= use_border
    # segments to bisect: anchor -> missing border point, and across each hit/miss change on the border
    f_miss, i_miss = np.nonzero(~ok_b & has_anchor[:, None])
    nxt = np.roll(ok_b, -1, axis=1)
    f_tr, i_tr = np.nonzero((ok_b != nxt) & has_anchor[:, None])
    j_tr = (i_tr + 1) % S
    a_tr = np.where(ok_b[f_tr, i_tr][:, None], border[i_tr], border[j_tr])
    b_tr = np.where(ok_b[f_tr, i_tr][:, None], border[j_tr], border[i_tr])
    seg_f = np.concatenate([f_miss, f_tr])
    seg_a = np.concatenate([anchor[f_miss], a_tr]).reshape(-1, 2)
    seg_b = np.concatenate([border[i_miss], b_tr]).reshape(-1, 2)
    hit, px, why = _bisect(sensor, frames.take(seg_f), seg_a, seg_b, ground)
    n_miss = f_miss.size
    clip_at = {(int(f), int(i)): k for k, (f, i) in enumerate(zip(f_miss, i_miss, strict=True))}
    trans_at = {(int(f), int(i)): n_miss + k for k, (f, i) in enumerate(zip(f_tr, i_tr, strict=True))}
    lat_b, lon_b, h_b = (np.reshape(x, (n, S)) for x in (fb.lat_deg, fb.lon_deg, fb.h_m))
    invalid = np.reshape(fb.status == Status.INVALID_INPUT, (n, S)).all(axis=1)
    below = np.reshape(fb.status == Status.BELOW_SURFACE, (n, S)).all(axis=1)  # the camera under the surface
    out = []
    for f in range(n):
        rows = []  # (lat, lon, h, u, v, clipped, clip_status)
        for i in range(S):
            if ok_b[f, i]:
                rows.append((lat_b[f, i], lon_b[f, i], h_b[f, i], *border[i], False, Status.OK))
            elif (f, i) in clip_at:
                k = clip_at[(f, i)]
                rows.append((hit.lat_deg[k], hit.lon_deg[k], hit.h_m[k], *px[k], True, why[k]))
            if (f, i) in trans_at:
                k = trans_at[(f, i)]
                rows.append((hit.lat_deg[k], hit.lon_deg[k], hit.h_m[k], *px[k], True, why[k]))
        cols = list(zip(*rows, strict=True)) if rows else [()] * 7
        status = (Status.INVALID_INPUT if invalid[f] else Status.BELOW_SURFACE if below[f]
                  else Status.OK if rows else Status.NO_INTERSECTION)
        out.append(Footprint(*(np.asarray(c, dtype=np.float64) for c in cols[:5]), np.asarray(cols[5], dtype=bool),
                             np.asarray(cols[6], dtype=np.int8), status,
                             (float(np.ravel(fc.lat_deg)[f]), float(np.ravel(fc.lon_deg)[f]),
                              float(np.ravel(fc.h_m)[f]))))
    return out


def _bisect(sensor: SensorModel, pose: Pose, a: np.ndarray, b: np.ndarray,
            ground) -> tuple[Fixes, np.ndarray, np.ndarray]:
    """On each segment a (ray hits) -> b (ray misses): the last hit. -> (its fix, its pixel, the
    status just beyond it)."""
    lo = np.zeros(a.shape[0])
    hi = np.ones(a.shape[0])
    why = np.full(a.shape[0], Status.NO_INTERSECTION, dtype=np.int8)
    if a.shape[0] == 0:
        return _stop(sensor, pose, a, ground), a, why
    frame = sensor.camera_frame(pose)  # the same poses each step: once
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        p = a + mid[:, None] * (b - a)
        xn, yn = sensor.camera.pixel_to_normalized(p[:, 0], p[:, 1], focal_scale=pose.focal_scale)
        f = ground.stop(sensor.rays_from(frame, xn, yn), sensor.ellipsoid)
        ok = f.status == Status.OK
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
        why = np.where(ok, why, f.status)
    px = a + lo[:, None] * (b - a)
    return _stop(sensor, pose, px, ground), px, why


def _stop(sensor: SensorModel, pose: Pose, pixels: np.ndarray, ground) -> Fixes:
    return ground.locate(sensor, pose, (pixels[..., 0], pixels[..., 1]))


def _n_frames(pose: Pose) -> int:
    fields = (pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg, pose.pitch_deg, pose.roll_deg, *pose.gimbal_deg)
    shape = np.broadcast_shapes(*(np.shape(f) for f in fields))
    if len(shape) > 1:
        raise ValueError(f"footprints takes one pose or a 1-D array of poses (one per frame), got shape {shape}")
    return int(shape[0]) if shape else 1


def footprint_features(prints: list[Footprint], properties: list[dict] | None = None) -> list[dict]:
    """GeoJSON features of footprint polygons (null geometry where a frame sees no ground), with
    status, area, vertex counts and the centre fix as properties (written by eoloc.io.writers)."""
    features = []
    for k, fp in enumerate(prints):
        props = dict(properties[k]) if properties else {}
        props.update({"status": fp.status.name, "area_m2": round(fp.area_m2, 1), "vertices": len(fp),
                      "clipped_vertices": int(fp.clipped.sum()),
                      "clipped_by": sorted({Status(int(s)).name for s in fp.clip_status[fp.clipped]}),
                      "centre_lat_deg": _none(fp.centre[0]), "centre_lon_deg": _none(fp.centre[1]),
                      "centre_h_m": _none(fp.centre[2])})
        features.append({"type": "Feature", "geometry": fp.geojson_geometry(), "properties": props})
    return features


def _none(x: float) -> float | None:
    return None if np.isnan(x) else x


__all__ = ["Footprint", "border_pixels", "footprint_features", "footprints"]
