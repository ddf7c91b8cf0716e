"""An independent oracle for eoloc's stop rules. It shares no code with eoloc.

Rays come from the conventions the README states. scipy's ``Rotation`` builds the attitude and
gimbal rotations, pyproj does WGS-84 geodetic -> ECEF and pymap3d ECEF -> geodetic; the NED
axes, the gimbal axes and the pixel model are written out here. Then every answer eoloc gives
is checked against the truth:

- OK: the point is on the ray, in front of the camera, at the range eoloc reports, and on the
  rule's surface: the range (M1), the height (M3, < 1 mm), the plane (M2) or the bilinear DEM
  (M4, < 1 cm). It is also the FIRST crossing, found by a dense search along the ray: no earlier
  point lies more than the tolerance below the surface, and on a DEM none is off the grid or
  over a void.
- not OK: NaN coordinates, and a status the inputs justify. INVALID_INPUT means an input is out
  of the README's domain. OUT_OF_IMAGE means the pixel is outside the image. BELOW_SURFACE
  means the camera is not above the surface. NO_INTERSECTION means the ray never dips below the
  surface (by more than the tolerance). For M4, OUT_OF_COVERAGE means the ray leaves the grid
  below the highest post before any crossing.

Used by ``tests/unit/rules/test_oracle.py`` (small seeded runs in ``make test``) and ``bench/oracle.py``
(10^6 cases, counts for the README).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pymap3d
import pyproj
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial.transform import Rotation

_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
D2R = np.pi / 180.0

# The README's validity domain ("Validity domains"), restated here by hand.
MAX_ANGLE_RAD = 1.0e6  # |angle| past which sine and cosine are refused
MAX_ORIGIN_M = 1.0e8
MAX_RANGE_M = 1.0e7
HEIGHT_DOMAIN_M = (-1.0e5, 1.0e7)
IMAGE_MARGIN_PX = 0.5  # beyond the outer edges (-0.5, W - 0.5) of the edge pixels
M3_TOL_M = 1.0e-3  # the M3 contract: on the surface to < 1 mm
M4_TOL_M = 1.0e-2  # the M4 contract: on the bilinear DEM to < 1 cm

# status codes as the README lists them
OK, NO_INTERSECTION, OUT_OF_COVERAGE, DEM_VOID, INVALID_INPUT, NO_TELEMETRY, BELOW_SURFACE, OUT_OF_IMAGE, \
    DEGENERATE = range(9)


# ---------------------------------------------------------------- geometry, written out


def to_ecef(lat, lon, h) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        lon = (np.asarray(lon, float) + 180.0) % 360.0 - 180.0  # PROJ refuses longitudes far past +-180
    x, y, z = _ECEF.transform(lon, np.asarray(lat, float), np.asarray(h, float))
    return np.stack(np.broadcast_arrays(x, y, z), -1)


_A = 6378137.0
_E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def geodetic(p: np.ndarray):
    """ECEF -> (lat deg, lon deg, h m): pymap3d's estimate, then Newton steps in the meridian
    plane on the defining forward formula until it maps back to the point (nanometres and 1e-15
    rad at any height). Neither library alone is exact enough here: PROJ's inverse is 0.1 mm off
    in height at 100 km and 7 mm at 900 km; pymap3d's latitude 7e-8 deg off at 1000 km (measured)."""
    p = np.asarray(p, dtype=float)
    with np.errstate(all="ignore"):
        lat, lon, h = pymap3d.ecef2geodetic(p[..., 0], p[..., 1], p[..., 2])
        lat = np.radians(np.asarray(lat, dtype=float))
        h = np.asarray(h, dtype=float)
        rho = np.hypot(p[..., 0], p[..., 1])
        for _ in range(3):
            sl, cl = np.sin(lat), np.cos(lat)
            w2 = 1.0 - _E2 * sl * sl
            n = _A / np.sqrt(w2)
            m = _A * (1.0 - _E2) / (w2 * np.sqrt(w2))
            d_rho = rho - (n + h) * cl
            d_z = p[..., 2] - (n * (1.0 - _E2) + h) * sl
            lat = lat + (-sl * d_rho + cl * d_z) / (m + h)
            h = h + cl * d_rho + sl * d_z
    return np.degrees(lat), np.asarray(lon), h


def height(p: np.ndarray) -> np.ndarray:
    return geodetic(p)[2]


def r_ecef_ned(lat_deg, lon_deg) -> np.ndarray:
    """Columns: north, east, down in ECEF (README: local level NED)."""
    sl, cl = np.sin(lat_deg * D2R), np.cos(lat_deg * D2R)
    so, co = np.sin(lon_deg * D2R), np.cos(lon_deg * D2R)
    north = np.stack([-sl * co, -sl * so, cl], -1)
    east = np.stack([-so, co, np.zeros_like(so)], -1)
    down = np.stack([-cl * co, -cl * so, -sl], -1)
    return np.stack([north, east, down], -1)


def _euler(seq: str, a, b, c) -> np.ndarray:
    ang = np.stack(np.broadcast_arrays(*(np.asarray(x, float) for x in (a, b, c))), -1)
    flat = ang.reshape(-1, 3)
    out = np.full((flat.shape[0], 3, 3), np.nan)
    ok = np.isfinite(flat).all(1)
    if ok.any():
        out[ok] = Rotation.from_euler(seq, flat[ok], degrees=True).as_matrix()
    return out.reshape(*ang.shape[:-1], 3, 3)


def r_body_cam(kind: str, g1, g2, g3, R_fixed=None) -> np.ndarray:
    """The README's gimbal models as scipy rotations (intrinsic sequences)."""
    if kind == "az-el":  # G = Rz(az) Ry(el) Rx(sensor roll); camera x, y, z = G y, G z, G x
        G = _euler("ZYX", g1, g2, g3)
        return G[..., :, [1, 2, 0]]
    if kind == "roll-pitch":  # S = Rx(roll) Ry(pitch) Rz(sensor roll); camera (x, y, z) is S (y, -x, z)
        S = _euler("XYZ", g1, g2, g3)
        C = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        return S @ C
    Rz = _euler("ZYX", g3, 0.0, 0.0)  # fixed mount, then a roll about the boresight
    return np.asarray(R_fixed) @ Rz


@dataclass
class Camera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float


def pixel_outside(cam: Camera, u, v) -> np.ndarray:
    m = 0.5 + IMAGE_MARGIN_PX
    with np.errstate(invalid="ignore"):
        inside = (u >= -m) & (u <= cam.width - 1 + m) & (v >= -m) & (v <= cam.height - 1 + m)
    return np.isfinite(u) & np.isfinite(v) & ~inside


def rays(cam: Camera, kind: str, lat, lon, h, yaw, pitch, roll, g1, g2, g3, u, v, lever=(0.0, 0.0, 0.0),
         R_fixed=None):
    """(origin (N, 3), unit direction (N, 3), R_ecef_cam) of pixel (u, v) for the poses (degrees, m)."""
    with np.errstate(all="ignore"):
        R_en = r_ecef_ned(lat, lon)
        R_nb = _euler("ZYX", yaw, pitch, roll)
        R_bc = r_body_cam(kind, g1, g2, g3, R_fixed)
        R_ec = R_en @ R_nb @ R_bc
        los = np.stack(np.broadcast_arrays((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)), -1)
        los = los / np.linalg.norm(los, axis=-1, keepdims=True)
        d = np.einsum("...ij,...j->...i", R_ec, los)
        o = to_ecef(lat, lon, h) + np.einsum("...ij,j->...i", R_en @ R_nb, np.asarray(lever, float))
    return o, d, R_ec


# ---------------------------------------------------------------- searches along a ray


def min_height_gap(o, d, s0, s1, surface, n=96, iters=48):
    """Lowest value of surface(point) over s in [s0, s1] on each ray (coarse grid + golden section
    around the lowest sample; surface(points (..., 3)) -> height gap, e.g. h - ht)."""
    s = s0[:, None] + (s1 - s0)[:, None] * np.linspace(0.0, 1.0, n)[None, :]
    g = surface(o[:, None, :] + s[..., None] * d[:, None, :])
    g = np.where(np.isfinite(g), g, np.inf)
    k = np.argmin(g, axis=1)
    best = g[np.arange(len(k)), k]
    lo = s[np.arange(len(k)), np.maximum(k - 1, 0)]
    hi = s[np.arange(len(k)), np.minimum(k + 1, n - 1)]
    r = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    c = b - r * (b - a)
    e = a + r * (b - a)
    gc = surface(o + c[:, None] * d)
    ge = surface(o + e[:, None] * d)
    for _ in range(iters):
        left = gc < ge
        b = np.where(left, e, b)
        a = np.where(left, a, c)
        e2 = np.where(left, c, e)
        ge2 = np.where(left, gc, ge)
        c = b - r * (b - a)
        e = a + r * (b - a)
        new = np.where(left, c, e)
        gnew = surface(o + new[:, None] * d)
        c, gc = np.where(left, new, e2), np.where(left, gnew, ge2)
        e, ge = np.where(left, e2, new), np.where(left, ge2, gnew)
        best = np.fmin(best, np.fmin(gc, ge))
    return best


def far_end(o, d):
    """A ray parameter past which the ray only climbs away from the Earth (closest approach to the
    centre, doubled, plus 200 km)."""
    s_close = -np.einsum("ij,ij->i", o, d)
    return 2.0 * np.maximum(s_close, 0.0) + 2.0e5


# ---------------------------------------------------------------- checks


@dataclass
class Report:
    """Counts of one oracle run: cases, statuses, and what was found wrong (with examples)."""

    name: str
    cases: int = 0
    statuses: Counter = field(default_factory=Counter)
    wrong: Counter = field(default_factory=Counter)
    examples: list = field(default_factory=list)

    def fail(self, what: str, mask: np.ndarray, detail=None) -> None:
        n = int(np.count_nonzero(mask))
        if n:
            self.wrong[what] += n
            if len(self.examples) < 12:
                i = int(np.flatnonzero(mask)[0])
                self.examples.append((what, i, None if detail is None else detail(i)))

    def add_statuses(self, st) -> None:
        self.cases += int(np.size(st))
        self.statuses.update(int(x) for x in np.ravel(st))

    def merge(self, other: Report) -> None:
        self.cases += other.cases
        self.statuses.update(other.statuses)
        self.wrong.update(other.wrong)
        self.examples += other.examples[: max(0, 12 - len(self.examples))]

    @property
    def n_wrong(self) -> int:
        return sum(self.wrong.values())

    def line(self) -> str:
        names = ["OK", "NO_INTERSECTION", "OUT_OF_COVERAGE", "DEM_VOID", "INVALID_INPUT", "NO_TELEMETRY",
                 "BELOW_SURFACE", "OUT_OF_IMAGE", "DEGENERATE"]
        st = ", ".join(f"{names[k]} {v}" for k, v in sorted(self.statuses.items()))
        wrong = ", ".join(f"{k} {v}" for k, v in sorted(self.wrong.items())) or "none"
        return f"{self.name}: {self.cases} cases ({st}); wrong: {wrong}"


def check_common(rep: Report, fix, o, d, domain_bad, outside):
    """Every rule: NaN where not OK; INVALID_INPUT only out of the domain; OUT_OF_IMAGE only for a
    pixel outside; no OK out of the domain or outside the image; OK points on the ray in front of
    the camera at the reported range. Returns (OK mask, the OK points (N, 3), their parameter t)."""
    lat, lon, h, rng, st = (np.asarray(x).ravel() for x in fix)
    st = st.astype(int)
    rep.add_statuses(st)
    ok = st == OK
    coords = np.stack([lat, lon, h, rng], -1)
    rep.fail("non-OK with finite coordinates", ~ok & np.isfinite(coords).any(1))
    rep.fail("OK with non-finite coordinates", ok & ~np.isfinite(coords).all(1))
    rep.fail("OK outside the domain", ok & domain_bad)
    rep.fail("OK for a pixel outside the image", ok & outside)
    rep.fail("INVALID_INPUT inside the domain", (st == INVALID_INPUT) & ~domain_bad)
    rep.fail("OUT_OF_IMAGE for a pixel inside", (st == OUT_OF_IMAGE) & ~outside)
    ok &= np.isfinite(coords).all(1)
    p = np.full(o.shape, np.nan)
    t = np.full(len(st), np.nan)
    if ok.any():
        p[ok] = to_ecef(lat[ok], lon[ok], h[ok])
        t[ok] = np.einsum("ij,ij->i", p[ok] - o[ok], d[ok])
        perp = np.linalg.norm(p[ok] - (o[ok] + t[ok, None] * d[ok]), axis=1)
        tol = 1e-4 + 1e-9 * np.abs(t[ok]) + 1e-12 * np.linalg.norm(o[ok], axis=1)
        bad = np.zeros(len(st), bool)
        bad[ok] = perp > tol
        rep.fail("OK point off the ray", bad, lambda i: float(perp[np.searchsorted(np.flatnonzero(ok), i)]))
        bad = np.zeros(len(st), bool)
        bad[ok] = (t[ok] <= -tol) | (np.abs(t[ok] - rng[ok]) > tol)
        rep.fail("OK point behind the camera or at another range", bad)
    return ok, p, t


def check_at_range(rep, fix, o, d, r, domain_bad, outside):
    ok, p, t = check_common(rep, fix, o, d, domain_bad, outside)
    st = np.asarray(fix[4]).ravel().astype(int)
    bad = np.zeros(len(ok), bool)
    bad[ok] = np.abs(t[ok] - r[ok]) > 1e-4 + 1e-9 * np.abs(r[ok])
    rep.fail("M1 point not at the measured range", bad)
    # a range along a ray always ends somewhere: inside the domain, with the pixel in the image,
    # nothing but OK is justified
    rep.fail("M1 status the rule can never give", ~np.isin(st, (OK, INVALID_INPUT, OUT_OF_IMAGE)))
    sane = ~domain_bad & ~outside & np.isfinite(o).all(1) & np.isfinite(d).all(1)
    rep.fail("M1 expected OK (a valid range on a valid ray) but got another status", sane & (st != OK))


def check_at_height(rep, fix, o, d, ht, domain_bad, outside):
    ok, p, t = check_common(rep, fix, o, d, domain_bad, outside)
    st = np.asarray(fix[4]).ravel().astype(int)
    n = len(st)
    with np.errstate(all="ignore"):
        h_cam = height(o)
    if ok.any():
        idx = np.flatnonzero(ok)
        off = np.abs(height(p[idx]) - ht[idx])
        bad = np.zeros(n, bool)
        bad[idx] = off > M3_TOL_M
        rep.fail("M3 OK point off the height surface", bad, lambda i: float(height(p[i:i + 1])[0] - ht[i]))
        first = min_height_gap(o[idx], d[idx], np.zeros(idx.size), t[idx], lambda q, hh=ht[idx]: _gap(q, hh))
        bad = np.zeros(n, bool)
        bad[idx] = first < -M3_TOL_M
        rep.fail("M3 OK point is not the first crossing", bad)
    sane = ~domain_bad & ~outside & np.isfinite(o).all(1) & np.isfinite(d).all(1)
    rep.fail("M3 status the rule can never give (an ellipsoid has no coverage edge, no void)",
             ~np.isin(st, (OK, NO_INTERSECTION, BELOW_SURFACE, INVALID_INPUT, OUT_OF_IMAGE)))
    rep.fail("BELOW_SURFACE with the camera above the surface",
             (st == BELOW_SURFACE) & sane & (h_cam - ht > M3_TOL_M))
    rep.fail("M3 expected BELOW_SURFACE (the camera under the surface) but got another status",
             sane & (h_cam - ht < -M3_TOL_M) & (st != BELOW_SURFACE))
    rep.fail("M3 OK with the camera below the surface", ok & (h_cam - ht <= 0.0))
    # misses and hits the oracle decides: the ray's lowest point against the surface
    look = np.flatnonzero(sane & (h_cam - ht > M3_TOL_M) & ((st == NO_INTERSECTION) | (st == OK)))
    if look.size:
        low = min_height_gap(o[look], d[look], np.zeros(look.size), far_end(o[look], d[look]),
                             lambda q, hh=ht[look]: _gap(q, hh))
        bad = np.zeros(n, bool)
        bad[look] = (st[look] == NO_INTERSECTION) & (low < -M3_TOL_M)
        rep.fail("M3 hit missed (NO_INTERSECTION on a ray that crosses the surface)", bad)


def _gap(q, ht):
    return height(q) - (ht[:, None] if q.ndim == 3 else ht)


def check_flat(rep, fix, o, d, o0, d0, r0, domain_bad, outside):
    """M2: the plane through the main target (o0 + r0 d0), perpendicular to the local vertical there."""
    ok, p, t = check_common(rep, fix, o, d, domain_bad, outside)
    st = np.asarray(fix[4]).ravel().astype(int)
    with np.errstate(all="ignore"):
        main = o0 + r0[:, None] * d0
        lat, lon, _ = geodetic(main)
        down = r_ecef_ned(lat, lon)[..., :, 2]
        H = np.einsum("ij,ij->i", main - o0, down)
        c = np.einsum("ij,ij->i", d, down)
        s = H / c
    bad = np.zeros(len(st), bool)
    bad[ok] = np.abs(t[ok] - s[ok]) > 1e-6 * np.abs(s[ok]) + 1e-4
    rep.fail("M2 OK point not on the plane", bad)
    sane = ~domain_bad & ~outside & np.isfinite(s) & np.isfinite(H)
    rep.fail("M2 NO_INTERSECTION for a ray that meets the plane ahead",
             (st == NO_INTERSECTION) & sane & (H > 0) & (c > 1e-6) & (s < 0.5 * MAX_RANGE_M))
    rep.fail("M2 BELOW_SURFACE with the camera above the plane", (st == BELOW_SURFACE) & sane & (H > 1e-6))


@dataclass
class Grid:
    """A lat/lon post grid: z[i, j] at (lat0 + i dlat, lon0 + j dlon), NaN voids."""

    z: np.ndarray
    lat0: float
    lon0: float
    dlat: float
    dlon: float

    def __post_init__(self):
        nr, nc = self.z.shape
        lats = self.lat0 + self.dlat * np.arange(nr)
        lons = self.lon0 + self.dlon * np.arange(nc)
        zz = self.z
        if self.dlat < 0:
            lats, zz = lats[::-1], zz[::-1]
        self._interp = RegularGridInterpolator((lats, lons), zz, method="linear", bounds_error=False,
                                               fill_value=np.nan)
        self._void = RegularGridInterpolator((lats, lons), np.isnan(zz).astype(float), method="linear",
                                             bounds_error=False, fill_value=0.0)
        self.hmax = float(np.nanmax(self.z))
        self.lat_range = (lats.min(), lats.max())
        self.lon_range = (lons.min(), lons.max())
        self.cell_m = abs(self.dlat) * 111_000.0

    def sample(self, lat, lon):
        """(bilinear height, on the grid, touches a void) at points (degrees)."""
        lon = (lon - self.lon_range[0]) % 360.0 + self.lon_range[0]
        on = (lat >= self.lat_range[0]) & (lat <= self.lat_range[1]) & (lon >= self.lon_range[0]) & \
            (lon <= self.lon_range[1])
        pts = np.stack([lat, lon], -1)
        return self._interp(pts), on, on & (self._void(pts) > 0.0)


M4_CLEAR_M = 0.5  # the oracle's own verdicts on a failed ray: a crossing, or a miss, by more than this


def dem_first_event(o, d, grid: Grid, step: float | None = None, block: int = 256):
    """The oracle's own walk along each ray (N,) from its camera, by steps of a quarter cell (no
    eoloc code): (event, s) with event 0 = the ray dips more than M4_CLEAR_M under the terrain
    (a crossing the rule must find), 1 = it is below the highest post off the grid, 2 = below the
    highest post over a void, 3 = none of them before it climbs away (far_end); s the parameter
    of the first such sample. A crossing within M4_CLEAR_M of the surface is not an event (too
    close to call at this step)."""
    step = step or grid.cell_m / 4.0
    n = len(o)
    event = np.full(n, 3)
    s_at = np.full(n, np.inf)
    end = far_end(o, d)
    live = np.flatnonzero(np.isfinite(o).all(1) & np.isfinite(d).all(1))
    s0 = np.zeros(n)
    while live.size:
        s = s0[live, None] + step * np.arange(block)[None, :]
        q = o[live, None, :] + s[..., None] * d[live, None, :]
        with np.errstate(all="ignore"):
            la, lo, hh = geodetic(q)
        zt, on, void = grid.sample(la, lo)
        low = hh <= grid.hmax
        cross = on & ~void & (hh - zt < -M4_CLEAR_M)
        off = low & ~on
        hole = low & void
        kinds = np.stack([cross, off, hole], -1)  # (rays, samples, 3)
        first = np.where(kinds.any(-1), np.arange(block)[None, :], block).min(1)
        hit = first < block
        for j in np.flatnonzero(hit):
            k = first[j]
            event[live[j]] = int(np.flatnonzero(kinds[j, k])[0])
            s_at[live[j]] = s[j, k]
        s0[live] += step * block
        live = live[~hit & (s0[live] < end[live])]
    return event, s_at


def check_on_dem(rep, fix, o, d, grid: Grid, domain_bad, outside):
    ok, p, t = check_common(rep, fix, o, d, domain_bad, outside)
    st = np.asarray(fix[4]).ravel().astype(int)
    n = len(st)
    rep.fail("M4 status the rule can never give", st == DEGENERATE)
    # every failed ray justified by the oracle's own walk along it
    sane = ~domain_bad & ~outside & np.isfinite(o).all(1) & np.isfinite(d).all(1)
    with np.errstate(all="ignore"):
        lat_c, lon_c, h_c = geodetic(o)
    z_c, on_c, void_c = grid.sample(lat_c, lon_c)
    under = sane & on_c & ~void_c & (h_c - z_c < -M4_CLEAR_M)
    rep.fail("M4 expected BELOW_SURFACE (the camera under the terrain) but got another status",
             under & (st != BELOW_SURFACE))
    rep.fail("M4 BELOW_SURFACE with the camera above the terrain or off it",
             sane & (st == BELOW_SURFACE) & ~(on_c & ~void_c & (h_c - z_c < M4_CLEAR_M)))
    look = np.flatnonzero(sane & ~under & np.isin(st, (NO_INTERSECTION, OUT_OF_COVERAGE, DEM_VOID)))
    if look.size:
        event, s_at = dem_first_event(o[look], d[look], grid)
        got = st[look]
        # a ray may clip the corner of a void or the grid's edge between two samples: where the walk
        # says "crossing first" against eoloc's void / edge, walk again 64 times finer up to it
        again = np.flatnonzero((event == 0) & (got != NO_INTERSECTION))
        if again.size:
            fine, _ = dem_first_event(o[look[again]], d[look[again]], grid, step=grid.cell_m / 256.0, block=2048)
            event[again] = fine
        bad = np.zeros(n, bool)
        bad[look] = event == 0
        rep.fail("M4 expected OK (the ray crosses the terrain first) but got a failure", bad)
        for status, what in ((OUT_OF_COVERAGE, "OUT_OF_COVERAGE"), (DEM_VOID, "DEM_VOID")):
            bad = np.zeros(n, bool)
            bad[look] = (got == status) & (event == 3)
            rep.fail(f"M4 {what} for a ray that never goes below the highest post off the grid or over a void",
                     bad)
        bad = np.zeros(n, bool)
        bad[look] = (got == NO_INTERSECTION) & np.isin(event, (1, 2))
        rep.fail("M4 NO_INTERSECTION for a ray that goes below the highest post off the grid or over a void", bad)
    if ok.any():
        idx = np.flatnonzero(ok)
        lat, lon, h = geodetic(p[idx])
        zt, on, void = grid.sample(lat, lon)
        bad = np.zeros(n, bool)
        bad[idx] = ~(np.abs(h - zt) <= M4_TOL_M)
        gap = h - zt
        rep.fail("M4 OK point off the DEM surface", bad, lambda i: float(gap[np.searchsorted(idx, i)]))
        # dense search before the hit: never under the terrain, never off the grid or over a void below hmax
        step = grid.cell_m / 4.0
        idx = idx[np.argsort(t[idx])]  # batches of rays of similar length
        for j in range(0, idx.size, 256):
            sub = idx[j:j + 256]
            m = int(np.ceil(np.max(t[sub]) / step)) + 2
            frac = np.linspace(0.0, 1.0, m)[None, :]
            s = t[sub, None] * frac * (1.0 - 1e-6)
            q = o[sub, None, :] + s[..., None] * d[sub, None, :]
            la, lo, hh = geodetic(q)
            zt, on, void = grid.sample(la, lo)
            low = hh <= grid.hmax
            under = on & ~void & (hh - zt < -M4_TOL_M)
            blocked = low & (~on | void)
            bad = np.zeros(n, bool)
            bad[sub] = under.any(1)
            rep.fail("M4 OK point is not the first crossing", bad)
            bad = np.zeros(n, bool)
            bad[sub] = blocked.any(1)
            rep.fail("M4 OK after the ray left the grid or met a void", bad)


# ---------------------------------------------------------------- hostile inputs

CAMERA = Camera(1280, 960, 1400.0, 1400.0, 639.5, 479.5)
KINDS = ("az-el", "roll-pitch", "fixed")
R_FIXED = Rotation.from_euler("ZYX", [30.0, -60.0, 10.0], degrees=True).as_matrix()
_BAD_ANGLES = (np.nan, np.inf, -np.inf, 1e9, -1e9, 1e4, -7e3, 89.9, -89.9, 90.0, 180.0, -180.0, 359.99)
_BAD = {
    "lat": (np.nan, np.inf, 90.0, -90.0, 90.0 + 1e-9, -90.5, 89.9999999, 1e9),
    "lon": (np.nan, -np.inf, 180.0, -180.0, 359.9, 720.5, -540.25, 1e9, 1e4),
    "h": (np.nan, np.inf, -20_000.0, 0.0, 1.0e6, 1.0e9, -1.0e5),
    "yaw": _BAD_ANGLES, "pitch": _BAD_ANGLES, "roll": _BAD_ANGLES, "g1": _BAD_ANGLES, "g2": _BAD_ANGLES,
    "g3": _BAD_ANGLES,
    "u": (np.nan, np.inf, -1e6, 1e6, 1e154, -1e160, -1.0001, 1280.0001, -50.0, 1330.0, -1.0, 1280.0),
    "v": (np.nan, -np.inf, -1e6, 1e6, 1e154, 1e160, -1.0001, 960.0001, -50.0, 1010.0, -1.0, 960.0),
}


def hostile_poses(rng: np.random.Generator, n: int, kind: str, hostile: float = 0.35) -> dict:
    """n poses and pixels for gimbal ``kind``: sane values, and in a ``hostile`` share of rows one
    or two fields replaced by a hostile value (NaN, inf, poles, +-180, longitudes past 360,
    heights -20 km..+1000 km, angles +-1e9 deg, grazing 89.9 deg, pixels far outside)."""
    c = {
        "lat": rng.uniform(-89.9, 89.9, n), "lon": rng.uniform(-180.0, 180.0, n),
        "h": np.where(rng.random(n) < 0.9, rng.uniform(50.0, 20_000.0, n), rng.uniform(-20_000.0, 1.0e6, n)),
        "yaw": rng.uniform(0.0, 360.0, n), "pitch": rng.uniform(-15.0, 15.0, n), "roll": rng.uniform(-30.0, 30.0, n),
        "u": rng.uniform(-0.5, CAMERA.width - 0.5, n), "v": rng.uniform(-0.5, CAMERA.height - 0.5, n),
        "g3": np.where(rng.random(n) < 0.5, 0.0, rng.uniform(-10.0, 10.0, n)),
    }
    if kind == "az-el":
        c["g1"], c["g2"] = rng.uniform(-180.0, 180.0, n), rng.uniform(-90.0, 10.0, n)
    elif kind == "roll-pitch":
        c["g1"], c["g2"] = rng.uniform(-85.0, 85.0, n), rng.uniform(-45.0, 45.0, n)
    else:
        c["g1"], c["g2"] = np.zeros(n), np.zeros(n)
    names = list(_BAD)
    for rows in (rng.random(n) < hostile, rng.random(n) < hostile / 3):
        for i in np.flatnonzero(rows):
            name = names[rng.integers(len(names))]
            pool = _BAD[name]
            c[name][i] = pool[rng.integers(len(pool))]
    return c


def pose_domain_bad(c: dict, kind: str = "az-el") -> np.ndarray:
    """Out of the README's domain: a non-finite field, |lat| > 90, an angle past MAX_ANGLE_RAD, the
    camera farther than MAX_ORIGIN_M from the Earth's centre. (A fixed mount has no g1, g2.)"""
    c = dict(c, g1=np.zeros_like(c["g1"]), g2=np.zeros_like(c["g2"])) if kind == "fixed" else c
    fields = ("lat", "lon", "h", "yaw", "pitch", "roll", "g1", "g2", "g3", "u", "v")
    with np.errstate(all="ignore"):
        bad = ~np.isfinite(np.stack([c[k] for k in fields])).all(0)
        bad |= np.abs(c["lat"]) > 90.0
        for k in ("lat", "lon", "yaw", "pitch", "roll", "g1", "g2", "g3"):
            bad |= np.abs(c[k] * D2R) > MAX_ANGLE_RAD
        o = to_ecef(np.clip(c["lat"], -90, 90), c["lon"], c["h"])
        bad |= ~(np.linalg.norm(o, axis=-1) <= MAX_ORIGIN_M)
    return bad


def _oracle_rays(c: dict, kind: str):
    if kind == "fixed":
        c = dict(c, g1=np.zeros_like(c["g1"]), g2=np.zeros_like(c["g2"]))
    o, d, _ = rays(CAMERA, kind, c["lat"], c["lon"], c["h"], c["yaw"], c["pitch"], c["roll"], c["g1"], c["g2"],
                   c["g3"], c["u"], c["v"], R_fixed=R_FIXED)
    return o, d


def _gimbal_tuple(c: dict, kind: str):
    return (c["g3"],) if kind == "fixed" else (c["g1"], c["g2"], c["g3"])


def _fix_tuple(f):
    return (f.lat_deg, f.lon_deg, f.h_m, f.range_m, f.status)


def _sensor(eoloc, kind: str):
    cam = eoloc.Camera(CAMERA.width, CAMERA.height, CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy)
    gimbal = {"az-el": eoloc.AzElGimbal(), "roll-pitch": eoloc.RollPitchGimbal(),
              "fixed": eoloc.FixedMount(matrix=tuple(map(tuple, R_FIXED)))}[kind]
    return eoloc.SensorModel(cam, gimbal)


def _pose(eoloc, c: dict, kind: str):
    return eoloc.Pose(c["lat"], c["lon"], c["h"], c["yaw"], c["pitch"], c["roll"], _gimbal_tuple(c, kind))


class Runner:
    """Runs every rule on hostile inputs on each backend, checks each answer, and counts backend
    disagreements in status."""

    def __init__(self, eoloc, backends=None):
        self.eoloc = eoloc
        self.backends = tuple(backends or eoloc.available_backends())
        self.reports: dict[str, Report] = {}
        self.cases: list = []

    def _report(self, name: str) -> Report:
        return self.reports.setdefault(name, Report(name))

    def _each_backend(self, name: str, locate, check, inputs: dict | None = None):
        """Run ``locate`` on each backend and ``check`` its answer; keep the inputs of the first
        few wrong cases (``inputs``: arrays per case) in ``self.cases`` for the report."""
        statuses = []
        for be in self.backends:
            with self.eoloc.use_backend(be):
                f = locate()
            rep = Report(name)
            check(rep, _fix_tuple(f))
            self._report(name).merge(rep)
            statuses.append(np.asarray(f.status).ravel())
            for what, i, detail in rep.examples[:3]:
                if inputs is not None and len(self.cases) < 20:
                    self.cases.append((name, be, what, detail, {k: np.ravel(v)[i] if np.size(v) > 1 else v
                                                                for k, v in inputs.items()},
                                       [np.ravel(x)[i] for x in _fix_tuple(f)]))
        if len(statuses) > 1:
            self._report(name).fail("backend disagreement in status", statuses[0] != statuses[1])

    def m1(self, rng, n: int) -> None:
        eoloc = self.eoloc
        for kind in KINDS:
            c = hostile_poses(rng, n, kind)
            r = rng.uniform(1.0, 60_000.0, n)
            swap = rng.random(n) < 0.2
            pool = np.array([0.0, -5.0, np.nan, np.inf, 1e155, 1e-9, MAX_RANGE_M * 1.0001, 5e6, 1e300])
            r[swap] = pool[rng.integers(len(pool), size=swap.sum())]
            o, d = _oracle_rays(c, kind)
            bad = pose_domain_bad(c, kind) | ~((r > 0) & (r <= MAX_RANGE_M))
            out = pixel_outside(CAMERA, c["u"], c["v"])
            sensor, pose = _sensor(eoloc, kind), _pose(eoloc, c, kind)
            self._each_backend("M1", lambda: eoloc.locate_range(sensor, pose, r, (c["u"], c["v"])),
                               lambda rep, f: check_at_range(rep, f, o, d, r, bad, out))

    def m3(self, rng, n: int) -> None:
        eoloc = self.eoloc
        for kind in KINDS:
            c = hostile_poses(rng, n, kind)
            ht = rng.uniform(-500.0, 4000.0, n)
            k = rng.integers(0, 9, n)
            ht = np.select([k == 0, k == 1, k == 2, k == 3, k == 4],
                           [c["h"] + rng.uniform(0.0, 1000.0, n), c["h"], c["h"] - 1e-3,
                            rng.uniform(-15_000.0, 1.0e6, n), np.array([np.nan, np.inf, 1e8, -2e5])[k % 4]], ht)
            o, d = _oracle_rays(c, kind)
            bad = pose_domain_bad(c, kind) | ~((ht >= HEIGHT_DOMAIN_M[0]) & (ht <= HEIGHT_DOMAIN_M[1]))
            out = pixel_outside(CAMERA, c["u"], c["v"])
            sensor, pose = _sensor(eoloc, kind), _pose(eoloc, c, kind)
            self._each_backend("M3", lambda: eoloc.locate_ellipsoid(sensor, pose, ht, (c["u"], c["v"])),
                               lambda rep, f: check_at_height(rep, f, o, d, ht, bad, out), dict(c, ht=ht, kind=kind))
        self.m3_tangent(rng, n)

    def m3_tangent(self, rng, n: int) -> None:
        """Rays built to touch the surface ht - delta at a known point Q (delta within +-3 cm:
        just dipping under, or just missing), target heights -10 km..+1000 km, cameras 1 m..500 km
        back along the ray; and cameras at or within a millimetre of the surface."""
        eoloc = self.eoloc
        lat = rng.uniform(-89.0, 89.0, n)
        lon = rng.uniform(-180.0, 180.0, n)
        ht = np.where(rng.random(n) < 0.5, rng.uniform(-10_000.0, 20_000.0, n), rng.uniform(20_000.0, 1.0e6, n))
        delta = rng.uniform(-0.03, 0.03, n)
        q = to_ecef(lat, lon, ht - delta)
        R = r_ecef_ned(lat, lon)
        az = rng.uniform(0.0, 2 * np.pi, n)
        d = R[..., :, 0] * np.cos(az)[:, None] + R[..., :, 1] * np.sin(az)[:, None]
        back = np.exp(rng.uniform(np.log(1.0), np.log(5.0e5), n))
        o = q - back[:, None] * d
        # a share of cameras at the surface or a millimetre from it, looking slightly down
        m = rng.random(n) < 0.25
        if m.any():
            dip = rng.uniform(-0.5, 1.0, m.sum()) * D2R
            o[m] = to_ecef(lat[m], lon[m], ht[m] + rng.choice([0.0, 1e-3, -1e-3, 1e-6], m.sum()))
            d[m] = np.cos(dip)[:, None] * d[m] - np.sin(dip)[:, None] * R[m, :, 2]
        rays_ = eoloc.Rays(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2])
        none = np.zeros(n, bool)
        self._each_backend("M3 tangent", lambda: eoloc.stop_at_ellipsoid(rays_, ht),
                           lambda rep, f: check_at_height(rep, f, o, d, ht, none, none),
                           {"ox": o[:, 0], "oy": o[:, 1], "oz": o[:, 2], "dx": d[:, 0], "dy": d[:, 1], "dz": d[:, 2],
                            "ht": ht, "delta": delta})

    def m2(self, rng, n: int) -> None:
        eoloc = self.eoloc
        frames = max(1, n // 20)
        for kind in KINDS:
            c = hostile_poses(rng, frames, kind)
            r0 = np.where(rng.random(frames) < 0.85, rng.uniform(100.0, 30_000.0, frames),
                          np.array([0.0, -1.0, np.nan, 1e12])[rng.integers(4, size=frames)])
            u = rng.uniform(-0.5, CAMERA.width - 0.5, (frames, 20))
            v = rng.uniform(-0.5, CAMERA.height - 0.5, (frames, 20))
            swap = rng.random((frames, 20)) < 0.1
            u[swap] = np.array(_BAD["u"])[rng.integers(len(_BAD["u"]), size=swap.sum())]
            cc = {k: np.repeat(val[:, None], 20, 1).ravel() for k, val in c.items()}
            cc["u"], cc["v"] = u.ravel(), v.ravel()
            o, d = _oracle_rays(cc, kind)
            c0 = dict(c, u=np.full(frames, CAMERA.cx), v=np.full(frames, CAMERA.cy))
            o0, d0 = _oracle_rays(c0, kind)
            rep0 = np.repeat(r0, 20)
            bad = pose_domain_bad(cc, kind) | np.repeat(~((r0 > 0) & (r0 <= MAX_RANGE_M)), 20)
            out = pixel_outside(CAMERA, cc["u"], cc["v"])
            sensor = _sensor(eoloc, kind)
            pose = eoloc.Pose(*(c[k][:, None] for k in ("lat", "lon", "h", "yaw", "pitch", "roll")),
                              tuple(g[:, None] for g in _gimbal_tuple(c, kind)))
            self._each_backend("M2", lambda: eoloc.locate_flat(sensor, pose, r0[:, None], (u, v)),
                               lambda rep, f: check_flat(rep, f, o, d, np.repeat(o0, 20, 0), np.repeat(d0, 20, 0),
                                                         rep0, bad, out), dict(cc, r0=rep0, kind=kind))
            # one frame at a time: the compiled real-time path
            for i in range(min(frames, 5)):
                p1 = eoloc.Pose(*(c[k][i] for k in ("lat", "lon", "h", "yaw", "pitch", "roll")),
                                tuple(g[i] for g in _gimbal_tuple(c, kind)))
                sl = slice(20 * i, 20 * i + 20)
                self._each_backend("M2 one frame",
                                   lambda p1=p1, i=i: eoloc.locate_flat(sensor, p1, r0[i], (u[i], v[i])),
                                   lambda rep, f, sl=sl: check_flat(rep, f, o[sl], d[sl], np.repeat(o0[i:i + 1], 20, 0),
                                                                    np.repeat(d0[i:i + 1], 20, 0), rep0[sl], bad[sl],
                                                                    out[sl]))

    def m4(self, rng, n: int, dem, grid: Grid) -> None:
        """Rays at a DEM tile: cameras above it and beside it (outside the grid, looking in, from
        every side), obliques to 85 deg, cameras below the terrain, voids injected in ``dem``."""
        eoloc = self.eoloc
        lat_lo, lat_hi = grid.lat_range
        lon_lo, lon_hi = grid.lon_range
        span = max(lat_hi - lat_lo, lon_hi - lon_lo)
        beside = rng.random(n) < 0.25  # a quarter of the cameras off the tile, on every side
        pad = np.where(beside, 0.15 * span, -0.05 * span)
        lat = rng.uniform(lat_lo - pad, lat_hi + pad)
        lon = rng.uniform(lon_lo - pad, lon_hi + pad)
        h = grid.hmax + np.where(rng.random(n) < 0.9, rng.uniform(10.0, 3000.0, n), rng.uniform(-3000.0, 10.0, n))
        el = np.where(rng.random(n) < 0.8, -rng.uniform(15.0, 90.0, n), -rng.uniform(1.0, 15.0, n))
        c = {"lat": lat, "lon": lon, "h": h, "yaw": rng.uniform(0, 360, n), "pitch": rng.uniform(-5, 5, n),
             "roll": rng.uniform(-5, 5, n), "g1": rng.uniform(-180, 180, n), "g2": el,
             "g3": np.zeros(n), "u": rng.uniform(-0.5, CAMERA.width - 0.5, n),
             "v": rng.uniform(-0.5, CAMERA.height - 0.5, n)}
        swap = rng.random(n) < 0.1
        for name in ("g2", "u", "lat"):
            pick = swap & (rng.random(n) < 0.4)
            pool = np.array(_BAD[name])
            c[name][pick] = pool[rng.integers(len(pool), size=pick.sum())]
        o, d = _oracle_rays(c, "az-el")
        bad = pose_domain_bad(c)
        out = pixel_outside(CAMERA, c["u"], c["v"])
        sensor, pose = _sensor(eoloc, "az-el"), _pose(eoloc, c, "az-el")
        self._each_backend("M4", lambda: eoloc.locate_dem(sensor, pose, dem, (c["u"], c["v"])),
                           lambda rep, f: check_on_dem(rep, f, o, d, grid, bad, out))

    def multiview(self, rng, n: int, triangulate) -> None:
        """Targets seen by 2-5 exact rays: sane geometry, near-parallel rays (cameras a few metres
        apart at 20-200 km), a ray pointing away from the target, NaN rays. ``triangulate`` is
        eoloc's; the oracle knows the target, so an OK point must be it."""
        eoloc = self.eoloc
        rep = self._report("multi-view")
        for _ in range(n):
            k = int(rng.integers(2, 6))
            lat, lon = rng.uniform(-80.0, 80.0), rng.uniform(-180.0, 180.0)
            target = to_ecef(lat, lon, rng.uniform(-100.0, 4000.0))
            R = r_ecef_ned(lat, lon)
            kind = rng.integers(0, 5)
            dist = rng.uniform(1_000.0, 50_000.0, k)
            if kind == 1:  # near-parallel: all cameras within a few metres of each other, far away
                dist = np.full(k, rng.uniform(20_000.0, 200_000.0))
            az = rng.uniform(0.0, 2 * np.pi, k)
            el = rng.uniform(5.0, 80.0, k) * D2R
            if kind == 1:
                az, el = np.full(k, az[0]), np.full(k, el[0])
            off_ned = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], -1) * dist[:, None]
            o = target + off_ned @ R.T
            if kind == 1:
                o = o + rng.normal(0.0, rng.choice([0.1, 1.0, 10.0]), (k, 3))
            d = target - o
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            if kind == 2:  # one ray pointing away
                d[0] = -d[0]
            if kind == 3:
                d[rng.integers(k)] = np.nan
            rays_ = eoloc.Rays(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2])
            usable = np.isfinite(d).all(1)
            cos = np.clip(d[usable] @ d[usable].T, -1.0, 1.0)
            angle = np.degrees(np.arccos(cos.min())) if usable.sum() >= 2 else 0.0
            for be in self.backends:
                with eoloc.use_backend(be):
                    try:
                        r = triangulate(rays_)
                    except ValueError:
                        rep.add_statuses([DEGENERATE])
                        rep.fail("refused with enough rays", np.array([usable.sum() >= 2]))
                        continue
                st = int(r.status)
                rep.add_statuses([st])
                finite = np.isfinite([r.lat_deg, r.lon_deg, r.h_m]).any()
                rep.fail("non-OK with finite coordinates", np.array([st != OK and finite]))
                if st == OK:
                    p = to_ecef(r.lat_deg, r.lon_deg, r.h_m)
                    err = float(np.linalg.norm(p - target))
                    rep.fail("multi-view OK point is not the target", np.array([err > 1e-4 + 1e-9 * dist.max()]),
                             lambda i, e=err: e)
                    rep.fail("multi-view OK with degenerate geometry", np.array([kind == 2 or angle < 0.01]))
                else:
                    rep.fail("DEGENERATE for well-conditioned rays in front",
                             np.array([kind in (0, 4) and angle > 0.02]))

    def lines(self) -> list[str]:
        return [rep.line() for rep in self.reports.values()]

    @property
    def n_wrong(self) -> int:
        return sum(rep.n_wrong for rep in self.reports.values())


def real_tile(path, voids: int = 12, seed: int = 0):
    """(posts z with injected voids, lat0, lon0, dlat, dlon) of a real DEM tile read by rasterio:
    posts at the pixel centres (the tile's own heights taken as ellipsoidal), square voids of 1-4
    posts dropped in at random."""
    import rasterio

    with rasterio.open(path) as ds:
        z = ds.read(1).astype(np.float64)
        t = ds.transform
    rng = np.random.default_rng(seed)
    for _ in range(voids):
        r, c, k = rng.integers(0, z.shape[0] - 4), rng.integers(0, z.shape[1] - 4), rng.integers(1, 5)
        z[r:r + k, c:c + k] = np.nan
    return z, t.f + 0.5 * t.e, t.c + 0.5 * t.a, t.e, t.a
