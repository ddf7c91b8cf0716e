"""M4 ray ∩ DEM: the first crossing of a ray with the bilinear terrain surface.

The algorithm, per ray (see docs/SPEC.md "M4"):

1. Band: the ray can only meet the terrain between the DEM's lowest and highest (ellipsoidal)
   heights. March from where it enters the top of the band (or from the camera, if the camera is
   inside the band) to where it reaches the bottom (or leaves the band upward). Along the ray,
   grid coordinates come from exact knots every 4 km and cubic Hermite interpolation (< 1 µm).
2. Coarse steps (about 8 cells): grid coordinates at both ends; the step is skipped
   when the ray's lowest height over it (minus a margin for the linearisation, >= 5 cm) is
   above the highest post of every 8 x 8 block its bounding box touches.
3. Fine steps (about 2 cells): grid coordinates at both ends, linear in between
   (< 0.1 mm off); a grid walk visits every cell the step crosses, and in each cell the
   ray-minus-bilinear-surface quadratic is solved exactly (``core.cell_first_root``), so the
   first crossing is found however thin the peak or ridge.
4. Polish: one Newton step on the exact surface (geodetic height of the ray point minus the
   bilinear DEM height there).

Statuses: a cell outside the grid on the way: OUT_OF_COVERAGE; a cell with a void corner on the
way: DEM_VOID (nothing is known of the ground there, so no later hit can be called the first);
camera on or below the terrain: BELOW_SURFACE; no crossing in the band: NO_INTERSECTION.

``march_ray`` is scalar code that numba compiles (eoloc.kernels.compiled) with the kernels' compiled twins;
``march_numpy`` runs the same cell solver over all rays at once, stepping every ray in lockstep
(no coarse skipping: slower, and the reference the numba path is tested against).
"""

from __future__ import annotations

import numpy as np

from .core import (
    BELOW_SURFACE,
    DEM_VOID,
    INVALID_INPUT,
    NO_INTERSECTION,
    OK,
    OUT_OF_COVERAGE,
    atan2,
    bowring,
    cell_first_root,
    compiled,
    ecef_to_geodetic,
    grid_height,
    inflated_roots,
    pick,
    ray_valid,
    stop_at_ellipsoid,
)

ON_SURFACE_M = 1.0e-6  # a camera this close to the terrain (or under it) is on it: BELOW_SURFACE
# a void cell or the grid's edge stops a ray only where the ray is more than this below the highest
# post (no ground is known to be higher): above that, nothing there could be hit; the margin covers
# the < 1 µm of the knots' interpolation, so that both backends call a grazing ray alike
EDGE_MARGIN_M = 1.0e-5
BLOCK = 8  # cells per side of a coarse block
_KNOT_M = 4000.0  # longest distance between exact geodetic knots along a ray (m)
_R_EARTH = 6_371_000.0
_D2R = np.pi / 180.0


def block_max(z: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Highest post of each block of ``block`` x ``block`` cells (posts on the shared edges
    included); +inf where the block holds a void, so a ray is never skipped over unknown ground."""
    nr, nc = z.shape
    nbr = (nr - 2) // block + 1
    nbc = (nc - 2) // block + 1
    out = np.empty((nbr, nbc))
    for i in range(nbr):
        rows = z[i * block: min(i * block + block + 1, nr)]
        for j in range(nbc):
            patch = rows[:, j * block: min(j * block + block + 1, nc)]
            out[i, j] = np.inf if np.isnan(patch).any() else patch.max()
    return out


def march_params(dem) -> tuple[float, float, float]:
    """(fine step, coarse step, coarse margin) in metres along the ray for a DEM."""
    cell = dem.spacing_m
    fine = 2.0 * cell
    coarse = BLOCK * cell
    margin = 0.05 + coarse * coarse / (4.0 * _R_EARTH)  # >= twice the chord sag of a coarse step
    return fine, coarse, margin


def _band(ox, oy, oz, dx, dy, dz, hmin, hmax, a, b, e2, ep2):
    """(t_start, t_end, camera height) of the part of the ray inside the terrain height band."""
    lat, lon, h_cam = ecef_to_geodetic(ox, oy, oz, a, b, e2, ep2)
    _, _, _, t_top, _ = stop_at_ellipsoid(ox, oy, oz, dx, dy, dz, hmax, a, b, e2, ep2)
    _, _, _, t_bottom, _ = stop_at_ellipsoid(ox, oy, oz, dx, dy, dz, hmin, a, b, e2, ep2)
    _, t_top_exit = inflated_roots(ox, oy, oz, dx, dy, dz, hmax + 1.0, a, b)  # leaving the band upward
    t_start = pick(h_cam <= hmax, 0.0, t_top)
    t_end = pick(t_bottom == t_bottom, t_bottom + 1.0, t_top_exit)
    return t_start, t_end, h_cam


def _grid_point(x, y, z, a, b, e2, ep2, lat0, lon0, dlat, dlon):
    """(fractional row, fractional column, geodetic height) of an ECEF point."""
    lat, lon, h = ecef_to_geodetic(x, y, z, a, b, e2, ep2)
    return (lat / _D2R - lat0) / dlat, (lon / _D2R - lon0) / dlon, h


@compiled()
def _surface_gap(ox, oy, oz, dx, dy, dz, t, z, a, b, e2, ep2, lat0, lon0, dlat, dlon):
    """Geodetic height of the ray point at t minus the bilinear DEM height below it."""
    lat, lon, h = ecef_to_geodetic(ox + t * dx, oy + t * dy, oz + t * dz, a, b, e2, ep2)
    hz, _ = grid_height(z, lat0, lon0, dlat, dlon, lat / _D2R, lon / _D2R)
    return h - hz


@compiled()
def _walk_cells(z, fr_a, fc_a, h_a, fr_b, fc_b, h_b, hmax):
    """Grid walk from a to b (fractional row/col, linear): (status, s) of the first crossing.

    status -1: none in this step; OK: crossing at s in [0, 1]; OUT_OF_COVERAGE / DEM_VOID. A cell
    off the grid or with a void corner stops the walk only where the ray is lower than ``hmax``
    (the DEM's highest post) by EDGE_MARGIN_M, as in the numpy march.
    """
    nr = z.shape[0]
    nc = z.shape[1]
    dfr = fr_b - fr_a
    dfc = fc_b - fc_a
    dh = h_b - h_a
    r = int(np.floor(fr_a))
    c = int(np.floor(fc_a))
    step_r = 1 if dfr > 0 else -1
    step_c = 1 if dfc > 0 else -1
    inv_r = 1.0 / abs(dfr) if dfr != 0.0 else np.inf
    inv_c = 1.0 / abs(dfc) if dfc != 0.0 else np.inf
    next_r = ((r + 1 - fr_a) if dfr > 0 else (fr_a - r)) * inv_r if dfr != 0.0 else np.inf
    next_c = ((c + 1 - fc_a) if dfc > 0 else (fc_a - c)) * inv_c if dfc != 0.0 else np.inf
    s_lo = 0.0
    while True:
        s_hi = min(next_r, next_c, 1.0)
        low = min(h_a + dh * s_lo, h_a + dh * s_hi)  # the ray's lowest point in this cell
        if r < 0 or r > nr - 2 or c < 0 or c > nc - 2:
            if low <= hmax - EDGE_MARGIN_M:
                return OUT_OF_COVERAGE, s_lo
        else:
            z00 = z[r, c]
            z01 = z[r, c + 1]
            z10 = z[r + 1, c]
            z11 = z[r + 1, c + 1]
            if not (z00 == z00 and z01 == z01 and z10 == z10 and z11 == z11):  # a void corner
                if low <= hmax - EDGE_MARGIN_M:
                    return DEM_VOID, s_lo
            elif low <= max(max(z00, z01), max(z10, z11)):  # else the ray is above every corner here
                s = cell_first_root(h_a, dh, fr_a - r, dfr, fc_a - c, dfc, z00, z01, z10, z11, s_lo, s_hi)
                if s == s:
                    return OK, s
        if s_hi >= 1.0:
            return -1, 1.0
        if next_r < next_c:
            r += step_r
            next_r += inv_r
        else:
            c += step_c
            next_c += inv_c
        s_lo = s_hi


@compiled()
def _coarse_clear(bmax, nr_cells, nc_cells, fr_a, fc_a, fr_b, fc_b, h_low):
    """True when the step's bounding box lies on the grid (``nr_cells`` x ``nc_cells`` cells) and
    every block under it is lower than h_low."""
    nbr = bmax.shape[0]
    nbc = bmax.shape[1]
    lo_r = min(fr_a, fr_b)
    hi_r = max(fr_a, fr_b)
    lo_c = min(fc_a, fc_b)
    hi_c = max(fc_a, fc_b)
    # off the grid (the last block reaches past the last post): the cells must be walked
    if not (lo_r >= 0.0 and lo_c >= 0.0 and hi_r <= nr_cells and hi_c <= nc_cells):
        return False
    r0 = int(np.floor(lo_r)) // BLOCK
    r1 = int(np.floor(hi_r)) // BLOCK
    c0 = int(np.floor(lo_c)) // BLOCK
    c1 = int(np.floor(hi_c)) // BLOCK
    if r1 >= nbr or c1 >= nbc:
        return False
    for i in range(r0, r1 + 1):
        for j in range(c0, c1 + 1):
            if bmax[i, j] >= h_low:
                return False
    return True


@compiled()
def _band_fast(ox, oy, oz, dx, dy, dz, hmin, hmax, a, b):
    """(t_start, t_end, camera inside the band) from inflated ellipsoids only (no trigonometry).

    The inflated ellipsoid (a + H, b + H) is within 2 cm of the surface of geodetic height H at
    10 km; padding the band by 1 m + 1e-4 |H| keeps it a superset of the true band.
    """
    pad_top = 1.0 + 1e-4 * abs(hmax)
    pad_bottom = 1.0 + 1e-4 * abs(hmin)
    t_top_in, t_top_out = inflated_roots(ox, oy, oz, dx, dy, dz, hmax + pad_top, a, b)
    t_bottom, _ = inflated_roots(ox, oy, oz, dx, dy, dz, hmin - pad_bottom, a, b)
    inside = t_top_in <= 0.0 and t_top_out >= 0.0
    t_start = 0.0 if inside else t_top_in
    if t_top_out < 0.0:  # the whole band is behind the camera
        t_start = np.nan
    t_end = t_bottom if t_bottom > 0.0 else t_top_out
    return t_start, t_end, inside


@compiled()
def _knot(ox, oy, oz, dx, dy, dz, t, a, b, e2, ep2, lat0, lon0, dlat, dlon, fc_near):
    """Exact grid coordinates of the ray point at t and their derivatives per metre along the ray.

    -> (fractional row, fractional column, geodetic height, d row/dt, d column/dt, dh/dt, p), the
    column unwrapped by whole turns to lie within half a turn of ``fc_near``; p is the distance
    from the polar axis (it sets how far apart knots may be).
    """
    x = ox + t * dx
    y = oy + t * dy
    z = oz + t * dz
    sl, cl, p, h = bowring(x, y, z, a, b, e2, ep2, 2)
    fr = (atan2(sl, cl) / _D2R - lat0) / dlat
    fc = (atan2(y, x) / _D2R - lon0) / dlon
    turn = 360.0 / abs(dlon)
    fc = fc - turn * np.floor((fc - fc_near) / turn + 0.5)
    inv_p = 1.0 / p if p > 0.0 else 0.0
    cn = x * inv_p if p > 0.0 else 1.0  # cos and sin of the longitude
    sn = y * inv_p
    d_north = -sl * (cn * dx + sn * dy) + cl * dz
    d_east = -sn * dx + cn * dy
    d_up = cl * (cn * dx + sn * dy) + sl * dz
    w2 = 1.0 - e2 * sl * sl
    m_plus_h = a * (1.0 - e2) / (w2 * np.sqrt(w2)) + h  # meridian radius of curvature + h
    return fr, fc, h, d_north / m_plus_h / _D2R / dlat, d_east * inv_p / _D2R / dlon, d_up, p


@compiled()
def _knot_length(p):
    """Knot spacing (m): cubic Hermite between exact knots is then < 1 µm off (docs/SPEC.md "M4")."""
    return min(_KNOT_M, max(0.002 * p, 1.0))


@compiled()
def _hermite(t, tk, length, k0, k1):
    """(fr, fc, h) at t by cubic Hermite interpolation between knots k0 (at tk) and k1 (tk + length)."""
    s = (t - tk) / length
    s2 = s * s
    s3 = s2 * s
    w00 = 2.0 * s3 - 3.0 * s2 + 1.0
    w10 = (s3 - 2.0 * s2 + s) * length
    w01 = 3.0 * s2 - 2.0 * s3
    w11 = (s3 - s2) * length
    return (w00 * k0[0] + w10 * k0[3] + w01 * k1[0] + w11 * k1[3],
            w00 * k0[1] + w10 * k0[4] + w01 * k1[1] + w11 * k1[4],
            w00 * k0[2] + w10 * k0[5] + w01 * k1[2] + w11 * k1[5])


@compiled()
def march_ray(ox, oy, oz, dx, dy, dz, z, bmax, lat0, lon0, dlat, dlon, hmin, hmax, fine, coarse, margin,
              a, b, e2, ep2):
    """First crossing of one ray with the DEM -> (lat rad, lon rad, h, t, status).

    Grid coordinates along the ray come from exact knots every few km (``_knot``) and cubic
    Hermite interpolation between them, so a coarse or fine step costs a few multiplications
    instead of an exact geodetic conversion; the hit is then polished on exact coordinates.
    """
    if not ray_valid(ox, oy, oz, dx, dy, dz):
        return np.nan, np.nan, np.nan, np.nan, INVALID_INPUT
    t_start, t_end, inside = _band_fast(ox, oy, oz, dx, dy, dz, hmin, hmax, a, b)
    if not t_start == t_start:
        return np.nan, np.nan, np.nan, np.nan, NO_INTERSECTION
    if inside:
        gap = _surface_gap(ox, oy, oz, dx, dy, dz, 0.0, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
        if gap <= ON_SURFACE_M:
            return np.nan, np.nan, np.nan, np.nan, BELOW_SURFACE
    if not t_end == t_end:
        t_end = t_start + 2.0e6  # never leaves the band (grazing from inside): bounded by coverage
    t = t_start
    k0 = _knot(ox, oy, oz, dx, dy, dz, t, a, b, e2, ep2, lat0, lon0, dlat, dlon, 0.5 * z.shape[1])
    tk = t
    length = _knot_length(k0[6])
    k1 = _knot(ox, oy, oz, dx, dy, dz, tk + length, a, b, e2, ep2, lat0, lon0, dlat, dlon, k0[1])
    fr_a, fc_a, h_a = k0[0], k0[1], k0[2]
    while t < t_end:
        t_b = min(t + coarse, t_end)
        while t_b > tk + length:  # next knot interval (fine steps below may extrapolate < 1 step back)
            tk = tk + length
            k0 = k1
            length = _knot_length(k0[6])
            k1 = _knot(ox, oy, oz, dx, dy, dz, tk + length, a, b, e2, ep2, lat0, lon0, dlat, dlon, k0[1])
        fr_b, fc_b, h_b = _hermite(t_b, tk, length, k0, k1)
        if not _coarse_clear(bmax, z.shape[0] - 1.0, z.shape[1] - 1.0, fr_a, fc_a, fr_b, fc_b,
                             min(h_a, h_b) - margin):
            tf = t
            fr_f, fc_f, h_f = fr_a, fc_a, h_a
            while tf < t_b:
                tf_b = min(tf + fine, t_b)
                fr_g, fc_g, h_g = _hermite(tf_b, tk, length, k0, k1)
                status, s = _walk_cells(z, fr_f, fc_f, h_f, fr_g, fc_g, h_g, hmax)
                if status == OK:
                    return _polish(ox, oy, oz, dx, dy, dz, tf + s * (tf_b - tf), (h_g - h_f) / (tf_b - tf), z,
                                   a, b, e2, ep2, lat0, lon0, dlat, dlon)
                if status != -1:
                    return np.nan, np.nan, np.nan, np.nan, status
                tf = tf_b
                fr_f, fc_f, h_f = fr_g, fc_g, h_g
        t = t_b
        fr_a, fc_a, h_a = fr_b, fc_b, h_b
    return np.nan, np.nan, np.nan, np.nan, NO_INTERSECTION


@compiled()
def _polish(ox, oy, oz, dx, dy, dz, t, dhdt, z, a, b, e2, ep2, lat0, lon0, dlat, dlon):
    """One secant step on the exact gap around the linearised root, then the point."""
    eps = 0.01
    g0 = _surface_gap(ox, oy, oz, dx, dy, dz, t, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
    g1 = _surface_gap(ox, oy, oz, dx, dy, dz, t - eps, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
    slope = (g0 - g1) / eps
    if slope < 0.0 and g0 == g0:
        t = t - g0 / slope
    lat, lon, h = ecef_to_geodetic(ox + t * dx, oy + t * dy, oz + t * dz, a, b, e2, ep2)
    return lat, lon, h, t, OK


# ---------------------------------------------------------------- numpy: every ray in lockstep


def march_numpy(ox, oy, oz, dx, dy, dz, z, lat0, lon0, dlat, dlon, hmin, hmax, fine, a, b, e2, ep2):
    """The same first-crossing search on flat arrays of rays, stepping all rays together.

    Steps of ``fine`` metres (about 2 cells) with exact end points; within a step every cell the
    step touches (at most 3 x 3 around its ends) is solved with the same cell kernel.
    """
    n = ox.size
    nr, nc = z.shape
    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    h = np.full(n, np.nan)
    tt = np.full(n, np.nan)
    st = np.full(n, NO_INTERSECTION, dtype=np.int8)
    with np.errstate(all="ignore"):
        valid = ray_valid(ox, oy, oz, dx, dy, dz)
        t0, t_end, h_cam = _band(ox, oy, oz, dx, dy, dz, hmin, hmax, a, b, e2, ep2)
        gap0 = _surface_gap(ox, oy, oz, dx, dy, dz, 0.0, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
        under = (h_cam <= hmax + ON_SURFACE_M) & (gap0 <= ON_SURFACE_M)
        st[under] = BELOW_SURFACE
        st[~valid] = INVALID_INPUT
        active = valid & ~under & np.isfinite(t0)
        t_end = np.where(np.isfinite(t_end), t_end, t0 + 2.0e6)
        t = np.where(active, t0, 0.0)
        pa = _grid_point(ox + t * dx, oy + t * dy, oz + t * dz, a, b, e2, ep2, lat0, lon0, dlat, dlon)
        while active.any():
            idx = np.flatnonzero(active)
            tb = np.minimum(t[idx] + fine, t_end[idx])
            fa, ca, ha = (p[idx] for p in pa)
            fb, cb, hb = _grid_point(ox[idx] + tb * dx[idx], oy[idx] + tb * dy[idx], oz[idx] + tb * dz[idx],
                                     a, b, e2, ep2, lat0, lon0, dlat, dlon)
            best = np.full(idx.size, np.nan)
            blocked = np.zeros(idx.size, dtype=np.int8)  # first obstacle: OUT_OF_COVERAGE / DEM_VOID
            blocked_s = np.full(idx.size, np.inf)
            # where the step leaves the grid (or 0 if it starts off it): the first obstacle
            g_in, g_out = _box_interval(fa, ca, fb, cb, 0.0, nr - 1.0, 0.0, nc - 1.0)
            off = np.where((g_in > 0.0) | (g_in > g_out), 0.0, np.where(g_out < 1.0, g_out, np.inf))
            deep = hmax - EDGE_MARGIN_M  # an edge or a void stops only a ray lower than this there
            dh = hb - ha
            off = np.where(np.minimum(ha + dh * np.where(np.isfinite(off), off, 1.0), hb) <= deep, off, np.inf)
            blocked = np.where(np.isfinite(off), OUT_OF_COVERAGE, blocked).astype(np.int8)
            blocked_s = off
            # the grid cells the step touches (clamped to the grid, so a step near a pole, whose
            # columns may span thousands of cells, stays cheap)
            r_lo = np.clip(np.floor(np.minimum(fa, fb)), 0, nr - 2).astype(np.int64)
            c_lo = np.clip(np.floor(np.minimum(ca, cb)), 0, nc - 2).astype(np.int64)
            span_r = np.clip(np.floor(np.maximum(fa, fb)), 0, nr - 2).astype(np.int64) - r_lo
            span_c = np.clip(np.floor(np.maximum(ca, cb)), 0, nc - 2).astype(np.int64) - c_lo
            for kr in range(int(span_r.max(initial=0)) + 1):
                for kc in range(int(span_c.max(initial=0)) + 1):
                    r = np.minimum(r_lo + kr, nr - 2)  # past a ray's own span: not used
                    c = np.minimum(c_lo + kc, nc - 2)
                    use = (kr <= span_r) & (kc <= span_c)
                    s_in, s_out = _box_interval(fa, ca, fb, cb, r, r + 1.0, c, c + 1.0)
                    use &= s_in <= s_out
                    z00, z01, z10, z11 = z[r, c], z[r, c + 1], z[r + 1, c], z[r + 1, c + 1]
                    void = np.isnan(z00 + z01 + z10 + z11)
                    s = cell_first_root(ha, hb - ha, fa - r, fb - fa, ca - c, cb - ca, z00, z01, z10, z11, s_in, s_out)
                    best = np.fmin(best, np.where(use & ~void, s, np.nan))
                    low = np.minimum(ha + dh * np.clip(s_in, 0.0, 1.0), ha + dh * np.clip(s_out, 0.0, 1.0))
                    first = use & void & (s_in < blocked_s) & (low <= deep)
                    blocked = np.where(first, DEM_VOID, blocked)
                    blocked_s = np.where(first, s_in, blocked_s)
            hit = np.isfinite(best) & ~(blocked_s <= best)  # a void or the edge at the same place wins
            stop = (blocked > 0) & ~hit
            hit_idx = idx[hit]
            if hit_idx.size:
                ts = t[hit_idx] + best[hit] * (tb[hit] - t[hit_idx])
                out = _polish_numpy(ox[hit_idx], oy[hit_idx], oz[hit_idx], dx[hit_idx], dy[hit_idx], dz[hit_idx], ts,
                                    z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
                lat[hit_idx], lon[hit_idx], h[hit_idx], tt[hit_idx] = out
                st[hit_idx] = OK
            st[idx[stop]] = blocked[stop]
            done = hit | stop | (tb >= t_end[idx])
            active[idx[done]] = False
            t[idx] = tb
            for p, q in zip(pa, (fb, cb, hb), strict=True):
                p[idx] = q
    return lat, lon, h, tt, st


def _box_interval(fa, ca, fb, cb, r0, r1, c0, c1):
    """The s-interval (within [0, 1]) where the straight step from a to b lies in the box of
    fractional rows [r0, r1] and columns [c0, c1] (empty when s_in > s_out)."""
    s_in = np.zeros(fa.shape)
    s_out = np.ones(fa.shape)
    for p0, p1, lo_k, hi_k in ((fa, fb, r0, r1), (ca, cb, c0, c1)):
        d = p1 - p0
        with np.errstate(divide="ignore", invalid="ignore"):
            s_a = (lo_k - p0) / d
            s_b = (hi_k - p0) / d
        inside = (p0 >= lo_k) & (p0 <= hi_k)
        lo = np.where(d != 0, np.minimum(s_a, s_b), np.where(inside, -np.inf, np.inf))
        hi = np.where(d != 0, np.maximum(s_a, s_b), np.where(inside, np.inf, -np.inf))
        s_in = np.maximum(s_in, lo)
        s_out = np.minimum(s_out, hi)
    return s_in, s_out


def _polish_numpy(ox, oy, oz, dx, dy, dz, t, z, a, b, e2, ep2, lat0, lon0, dlat, dlon):
    eps = 0.01
    g0 = _surface_gap(ox, oy, oz, dx, dy, dz, t, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
    g1 = _surface_gap(ox, oy, oz, dx, dy, dz, t - eps, z, a, b, e2, ep2, lat0, lon0, dlat, dlon)
    slope = (g0 - g1) / eps
    t = np.where((slope < 0.0) & np.isfinite(g0), t - g0 / slope, t)
    lat, lon, h = ecef_to_geodetic(ox + t * dx, oy + t * dy, oz + t * dz, a, b, e2, ep2)
    return lat, lon, h, t


# ---------------------------------------------------------------- [Q]'s descent iteration


def descent_numpy(ox, oy, oz, dx, dy, dz, z, lat0, lon0, dlat, dlon, hmin, hmax, eps_h, a, b, e2, ep2):
    """[Q] §2.3: locate on the ellipsoid at H0 = the highest terrain, read the DEM there, lower H by
    eps_h while H - h_dem > 0; stop at the first H_n - h_n < 0. Height error <= eps_h, and it
    can report a LATER crossing than the first (it samples the ray only where it is at H_n)."""
    n = ox.size
    out = [np.full(n, np.nan) for _ in range(4)]
    st = np.full(n, NO_INTERSECTION, dtype=np.int8)
    active = np.ones(n, dtype=bool)
    H = hmax
    with np.errstate(all="ignore"):
        while active.any() and H >= hmin - eps_h:
            idx = np.flatnonzero(active)
            la, lo, hh, t, s = stop_at_ellipsoid(ox[idx], oy[idx], oz[idx], dx[idx], dy[idx], dz[idx], H, a, b, e2, ep2)
            hz, inside = grid_height(z, lat0, lon0, dlat, dlon, la / _D2R, lo / _D2R)
            found = (s == OK) & inside & (H - hz < 0.0)
            gone = (s != OK) | ~inside | np.isnan(hz)
            code = np.where(s != OK, s, np.where(~inside, OUT_OF_COVERAGE, DEM_VOID))
            fin = idx[found]
            for arr, val in zip(out, (la, lo, hh, t), strict=True):
                arr[fin] = val[found]
            st[fin] = OK
            st[idx[gone & ~found]] = code[gone & ~found]
            active[idx[found | gone]] = False
            H = H - eps_h
    return out[0], out[1], out[2], out[3], st


__all__ = ["block_max", "descent_numpy", "march_numpy", "march_params", "march_ray"]
