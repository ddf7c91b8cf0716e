"""numba backend: compiled twins of :mod:`eoloc._kernels` and the loops that drive them.

Each kernel function is recompiled for scalars with ``pick`` turned into a branch and ``sincos`` /
``atan2`` into the kernels' branch-free polynomials, so this module holds no math of its own, only
drivers. A driver takes the element count, its inputs (each a flat array of that length or a
scalar: ``_at`` specialises at compile time) and its output arrays, and is one loop that LLVM
vectorises (see :func:`_driver` and ``_INLINE`` for what that takes). Plain loops are used rather
than gufuncs: gufunc dispatch halved the throughput (measured).
Compiled code is cached per hash of the kernel source (numba only watches the file that defines
a function, not the files it calls, so a plain cache could serve stale kernels).
"""

from __future__ import annotations

import hashlib
import os
import types as pytypes
from pathlib import Path

import numba
import numpy as np
from numba import njit, types
from numba.extending import overload

from . import _kernels as K
from . import _march as M

_JIT = {"cache": True, "error_model": "numpy", "nogil": True}


def _cache_dir() -> str:
    root = os.environ.get("EOLOC_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "eoloc"
    )
    digest = hashlib.sha256()
    for mod in (K.__file__, M.__file__, __file__):
        digest.update(Path(mod).read_bytes())
    return os.path.join(root, f"numba-{numba.__version__}-{digest.hexdigest()[:16]}")


def _pick_scalar(cond, a, b):
    return a if cond else b


def _floor_index_scalar(x, hi):
    return min(max(int(np.floor(x)), 0), hi)


def _at(x, i):
    """Element i of a flat array, or the scalar itself (resolved at compile time)."""


@overload(_at, jit_options={"forceinline": True})
def _at_impl(x, i):
    if isinstance(x, types.Array):
        return lambda x, i: x[i]
    return lambda x, i: x


@njit(forceinline=True, **_JIT)
def _at9(a0, a1, a2, a3, a4, a5, a6, a7, a8, i):
    """Element i of a rotation given as 9 flat arrays (or scalars), as a 9-tuple."""
    return (_at(a0, i), _at(a1, i), _at(a2, i), _at(a3, i), _at(a4, i), _at(a5, i), _at(a6, i), _at(a7, i),
            _at(a8, i))


_KERNELS = (
    "_finite", "mat_mul", "mat_vec", "mat_t_vec", "rot_x", "rot_y", "rot_z", "r_ned_body",
    "r_ecef_ned", "r_body_cam_azel", "r_body_cam_rollpitch", "geodetic_to_ecef", "bowring", "ecef_to_geodetic",
    "pose_frame", "ray_direction", "project_point", "ray_valid", "stop_at_range", "_height_slope",
    "_m3_domain", "ellipsoid_fast", "ellipsoid_classify", "ellipsoid_exact",
    "r_body_cam", "camera_frame", "_tuple9", "params_camera_frame", "locate_one", "grid_height", "inflated_roots",
    "cell_first_root", "distort_brown", "undistort_brown", "ppoly_eval", "distortion_ratio", "undistort", "distort",
    "flat_plane", "flat_target", "pixel_in_image", "undistort_ok",
)

# Marked always-inline for LLVM (``forceinline``): numba compiles each function into a library of
# its own, so LLVM's inliner does not otherwise reach into them, and one call left in a driver's
# loop body stops the loop from vectorising. Numba's own IR-level inlining (``inline="always"``)
# also works but compiles ~3x slower (it copies the IR at every call site) and, where it meets a
# tuple of mixed array and scalar elements, leaves instructions LLVM cannot vectorise.
_INLINE = frozenset({
    "_finite", "mat_mul", "mat_vec", "mat_t_vec", "rot_x", "rot_y", "rot_z", "r_ned_body", "r_ecef_ned",
    "r_body_cam_azel", "r_body_cam_rollpitch", "geodetic_to_ecef", "bowring", "ecef_to_geodetic", "pose_frame",
    "ray_direction", "project_point", "ray_valid", "stop_at_range", "inflated_roots",
    "_height_slope", "_m3_domain", "ellipsoid_fast", "flat_target",
    "r_body_cam", "camera_frame",
})


def _driver(fn, **options):
    """Compile an element loop whose array arguments never overlap in memory.

    Every driver writes into outputs that :func:`eoloc._backend.run` has just allocated, so no
    output can share memory with an input. Telling LLVM so (``noalias`` on the array pointers,
    the flag numba's parallel loops set) lets it vectorise the loop: otherwise it needs a runtime
    overlap check per pair of input and output arrays, and past a few dozen pairs it gives up and
    runs scalar code (pose_frame: 57 -> 9 ns per element, measured). So a driver must never be
    handed an output that overlaps an input. Where a numba release lacks the hook the driver
    compiles as an ordinary loop: the same results, slower.
    """
    dispatcher = njit(**{**_JIT, **options})(fn)
    compiler = getattr(dispatcher, "_compiler", None)
    customize = getattr(compiler, "_customize_flags", None)
    if customize is not None:
        def _noalias(flags, _base=customize):
            flags = _base(flags)
            flags.noalias = True
            return flags

        compiler._customize_flags = _noalias
    return dispatcher


_saved_cache_dir = numba.config.CACHE_DIR
numba.config.CACHE_DIR = _cache_dir()
try:
    _g = dict(vars(K))
    _g["pick"] = njit(forceinline=True, **_JIT)(_pick_scalar)
    _g["_floor_index"] = njit(**_JIT)(_floor_index_scalar)
    # call- and branch-free trigonometry (the fdlibm polynomials), so that LLVM vectorises the loops
    _g["sincos"] = njit(forceinline=True, **_JIT)(pytypes.FunctionType(K.sincos_poly.__code__, _g, "sincos"))
    _g["atan2"] = njit(forceinline=True, **_JIT)(pytypes.FunctionType(K.atan2_poly.__code__, _g, "atan2"))
    for _name in _KERNELS:
        _f = getattr(K, _name)
        _opts = {"forceinline": True} if _name in _INLINE else {}
        _g[_name] = njit(**_opts, **_JIT)(pytypes.FunctionType(_f.__code__, _g, _name, _f.__defaults__))
    # one ray at a time: the fast path, and the exact one where it is undecided (a branch)
    _g["stop_at_ellipsoid"] = njit(**_JIT)(
        pytypes.FunctionType(K.stop_at_ellipsoid_scalar.__code__, _g, "stop_at_ellipsoid"))
    # the M4 march: its helpers compiled with the kernels' twins in their globals
    _gm = dict(vars(M))
    _gm.update({name: _g[name] for name in (*_KERNELS, "pick", "_floor_index", "sincos", "atan2")})
    for _name in ("_band_fast", "_knot", "_knot_length", "_hermite", "_surface_gap", "_walk_cells",
                  "_coarse_clear", "_polish", "march_ray"):
        _f = getattr(M, _name)
        _gm[_name] = njit(**_JIT)(pytypes.FunctionType(_f.__code__, _gm, _name, _f.__defaults__))
    _march_ray = _gm["march_ray"]

    @_driver
    def terrain_march(n, ox, oy, oz, dx, dy, dz, z, bmax, lat0, lon0, dlat, dlon, hmin, hmax, fine, coarse, margin,
                      a, b, e2, ep2, lat, lon, h, t, st):
        for i in range(n):
            lat[i], lon[i], h[i], t[i], st[i] = _march_ray(
                _at(ox, i), _at(oy, i), _at(oz, i), _at(dx, i), _at(dy, i), _at(dz, i), z, bmax, lat0, lon0, dlat,
                dlon, hmin, hmax, fine, coarse, margin, a, b, e2, ep2)

    # Explicit signature: compiled once (cached), and ints are converted at dispatch instead of
    # compiling a specialisation per mix of int and float arguments.
    locate_one = njit((types.float64[::1], *[types.float64] * 11, types.int64, types.float64), **_JIT)(
        pytypes.FunctionType(K.locate_one.__code__, _g, "locate_one_sig")
    )
    _geo2ecef = _g["geodetic_to_ecef"]
    _ecef2geo = _g["ecef_to_geodetic"]
    _ray_direction = _g["ray_direction"]
    _project_point = _g["project_point"]
    _stop_range = _g["stop_at_range"]
    _ellipsoid_fast = _g["ellipsoid_fast"]
    _ellipsoid_exact = _g["ellipsoid_exact"]
    _ellipsoid_classify = _g["ellipsoid_classify"]

    _flat_plane = _g["flat_plane"]
    _flat_target = _g["flat_target"]
    _undistort = _g["undistort"]
    _undistort_ok = _g["undistort_ok"]
    _pixel_in_image = _g["pixel_in_image"]
    _camera_frame = _g["camera_frame"]
    _params_camera_frame = _g["params_camera_frame"]
    _finite = _g["_finite"]

    @_driver
    def camera_frame(n, kind, g1, g2, g3, m0, m1, m2, m3, m4, m5, m6, m7, m8, f0, f1, f2, f3, f4, f5, f6, f7, f8,
                     b0, b1, b2, b3, b4, b5, b6, b7, b8, skew, lat, lon, h, yaw, pitch, roll, lx, ly, lz, a, e2,
                     o0, o1, o2, o3, o4, o5, o6, o7, o8, ox, oy, oz):
        k = int(kind)
        for i in range(n):
            R, ox[i], oy[i], oz[i] = _camera_frame(
                k, _at(g1, i), _at(g2, i), _at(g3, i), _at9(m0, m1, m2, m3, m4, m5, m6, m7, m8, i),
                _at9(f0, f1, f2, f3, f4, f5, f6, f7, f8, i), _at9(b0, b1, b2, b3, b4, b5, b6, b7, b8, i),
                _at(skew, i), _at(lat, i), _at(lon, i), _at(h, i), _at(yaw, i), _at(pitch, i), _at(roll, i),
                _at(lx, i), _at(ly, i), _at(lz, i), a, e2)
            o0[i], o1[i], o2[i], o3[i], o4[i], o5[i], o6[i], o7[i], o8[i] = R

    @_driver
    def flat_target(n, r0, r1, r2, r3, r4, r5, r6, r7, r8, ox, oy, oz, nx, ny, nz, H, xn, yn, a, b, e2, ep2,
                    lat, lon, h, t, st):
        for i in range(n):
            R = _at9(r0, r1, r2, r3, r4, r5, r6, r7, r8, i)
            lat[i], lon[i], h[i], t[i], st[i] = _flat_target(R, _at(ox, i), _at(oy, i), _at(oz, i), _at(nx, i),
                                                             _at(ny, i), _at(nz, i), _at(H, i), _at(xn, i),
                                                             _at(yn, i), a, b, e2, ep2)

    @njit(**_JIT)
    def flat_frame(params, dist_kind, dist_params, width, height, pose, main_px, main_range, u, v, lat, lon, h, t,
                   st):
        """M2 for one frame in one call: pose = (lat, lon, h, yaw, pitch, roll, g1, g2, g3) in
        radians/metres; main_px = (u0, v0); pixels u, v distorted (OUT_OF_IMAGE outside the
        width x height image); outputs in radians/metres."""
        fx = params[K.P_FX]
        fy = params[K.P_FY]
        cx = params[K.P_CX]
        cy = params[K.P_CY]
        a = params[K.P_ELL]
        b = params[K.P_ELL + 1]
        e2 = params[K.P_ELL + 2]
        ep2 = params[K.P_ELL + 3]
        R, ox, oy, oz = _params_camera_frame(params, pose[0], pose[1], pose[2], pose[3], pose[4], pose[5], pose[6],
                                             pose[7], pose[8])
        xn0, yn0 = _undistort(dist_kind, dist_params, (main_px[0] - cx) / fx, (main_px[1] - cy) / fy)
        nx, ny, nz, H = _flat_plane(R, ox, oy, oz, xn0, yn0, main_range, a, b, e2, ep2)
        bad = not (np.abs(pose[0]) <= 0.5 * np.pi and _finite(pose.sum()))
        for i in range(u.size):
            xd = (u[i] - cx) / fx
            yd = (v[i] - cy) / fy
            xn, yn = _undistort(dist_kind, dist_params, xd, yd)
            lat[i], lon[i], h[i], t[i], st[i] = _flat_target(R, ox, oy, oz, nx, ny, nz, H, xn, yn, a, b, e2, ep2)
            if _finite(u[i] + v[i]) and not (_pixel_in_image(u[i], v[i], width, height)
                                             and _undistort_ok(dist_kind, dist_params, xd, yd, xn, yn)):
                lat[i] = lon[i] = h[i] = t[i] = np.nan
                st[i] = K.OUT_OF_IMAGE
            if bad:
                lat[i] = lon[i] = h[i] = t[i] = np.nan
                st[i] = K.INVALID_INPUT

    @_driver
    def geodetic_to_ecef(n, lat, lon, h, a, e2, x, y, z):
        for i in range(n):
            x[i], y[i], z[i] = _geo2ecef(_at(lat, i), _at(lon, i), _at(h, i), a, e2)

    @_driver
    def ecef_to_geodetic(n, x, y, z, a, b, e2, ep2, lat, lon, h):
        for i in range(n):
            lat[i], lon[i], h[i] = _ecef2geo(_at(x, i), _at(y, i), _at(z, i), a, b, e2, ep2)

    @_driver
    def ray_direction(n, r0, r1, r2, r3, r4, r5, r6, r7, r8, xn, yn, dx, dy, dz):
        for i in range(n):
            R = _at9(r0, r1, r2, r3, r4, r5, r6, r7, r8, i)
            dx[i], dy[i], dz[i] = _ray_direction(R, _at(xn, i), _at(yn, i))

    @_driver
    def project_point(n, r0, r1, r2, r3, r4, r5, r6, r7, r8, ox, oy, oz, px, py, pz, xn, yn, depth):
        for i in range(n):
            R = _at9(r0, r1, r2, r3, r4, r5, r6, r7, r8, i)
            xn[i], yn[i], depth[i] = _project_point(R, _at(ox, i), _at(oy, i), _at(oz, i),
                                                    _at(px, i), _at(py, i), _at(pz, i))

    @_driver
    def stop_at_range(n, ox, oy, oz, dx, dy, dz, rng, a, b, e2, ep2, lat, lon, h, t, st):
        for i in range(n):
            lat[i], lon[i], h[i], t[i], st[i] = _stop_range(_at(ox, i), _at(oy, i), _at(oz, i), _at(dx, i),
                                                            _at(dy, i), _at(dz, i), _at(rng, i), a, b, e2, ep2)

    @_driver
    def stop_at_ellipsoid(n, ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2, lat, lon, h, t, st):
        for i in range(n):  # vectorised: the certified fast path
            lat[i], lon[i], h[i], t[i], st[i] = _ellipsoid_fast(_at(ox, i), _at(oy, i), _at(oz, i), _at(dx, i),
                                                                _at(dy, i), _at(dz, i), _at(ht, i), a, b, e2, ep2)
        for i in range(n):  # the rays it did not certify: misses, cameras below, and the few left
            if st[i] == K.UNDECIDED:
                st[i] = _ellipsoid_classify(_at(ox, i), _at(oy, i), _at(oz, i), _at(dx, i), _at(dy, i), _at(dz, i),
                                            _at(ht, i), a, b)
                if st[i] == K.UNDECIDED:
                    lat[i], lon[i], h[i], t[i], st[i] = _ellipsoid_exact(
                        _at(ox, i), _at(oy, i), _at(oz, i), _at(dx, i), _at(dy, i), _at(dz, i), _at(ht, i), a, b, e2,
                        ep2)

finally:
    numba.config.CACHE_DIR = _saved_cache_dir
