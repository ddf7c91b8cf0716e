"""Component-wise numerical kernels: the single implementation of eoloc's math.

Every function here takes floats or numpy arrays that broadcast, works component by component
(a vector is three values ``x, y, z``; a rotation is a 9-tuple in row-major order) and uses only
arithmetic, numpy ufuncs and :func:`pick` / :func:`_finite`.  Angles are radians, lengths metres.

Two backends run these *same* functions:

- numpy: called directly on arrays (the reference path, always available);
- numba: :mod:`eoloc.kernels.compiled` compiles each function for scalars (``pick`` becomes a branch, sine,
  cosine and atan2 become the polynomials below) inside element loops that LLVM vectorises, and
  the single-target fast path calls them directly.

So the real-time path, batches and Monte Carlo never have a second implementation of the math.
Rotations are *active*: ``mat_vec(R_a_b, v_b)`` gives the vector expressed in frame ``a``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..status import Status

# Status codes: eoloc.status.Status's, defined there once; here as plain ints, which numba compiles
# to constants (an IntEnum member is a Python object it cannot).
OK = int(Status.OK)
NO_INTERSECTION = int(Status.NO_INTERSECTION)
OUT_OF_COVERAGE = int(Status.OUT_OF_COVERAGE)
DEM_VOID = int(Status.DEM_VOID)
INVALID_INPUT = int(Status.INVALID_INPUT)
BELOW_SURFACE = int(Status.BELOW_SURFACE)
OUT_OF_IMAGE = int(Status.OUT_OF_IMAGE)
UNDECIDED = -1  # internal: the fast M3 path could not certify its answer; the exact path decides



class GimbalKind(IntEnum):
    """The gimbal models (:func:`r_body_cam`); the classes of :mod:`eoloc.sensor.gimbal` carry
    one each. The kernels compare plain ints, which numba compiles to constants."""

    AZ_EL = 0
    ROLL_PITCH = 1
    FIXED = 2


GIMBAL_AZEL = int(GimbalKind.AZ_EL)
GIMBAL_ROLLPITCH = int(GimbalKind.ROLL_PITCH)
GIMBAL_FIXED = int(GimbalKind.FIXED)


def compiled(inline: bool = False):
    """Mark a kernel for the numba backend, which compiles every marked function of a module for
    scalars (:mod:`eoloc.kernels.compiled`); ``inline``: always inlined by LLVM (a call left in a driver's loop
    stops it from vectorising). The function itself is returned unchanged for numpy."""

    def mark(fn):
        fn.eoloc_compiled = "inline" if inline else "call"
        return fn

    return mark



def pick(cond, a, b):
    """``a`` where ``cond`` else ``b`` (numpy: np.where; numba: a branch)."""
    return np.where(cond, a, b)


@compiled(inline=True)
def _finite(s):
    """True where ``s`` is finite: ``inf - inf`` and ``nan - nan`` are NaN, which is not 0."""
    return (s - s) == 0.0


# ---------------------------------------------------------------- trigonometry
#
# Every sine, cosine and atan2 of the kernels goes through ``sincos`` and ``atan2``. The numpy
# backend runs numpy's own ufuncs. The numba backend swaps in ``sincos_poly`` and ``atan2_poly``
# below: the fdlibm polynomials of the C library, written without calls or branches so that LLVM
# vectorises the compiled loops (a libm call per element blocks that: 17 ns against 1 ns per
# sin+cos, measured). Tested against CPython's libm: 1 ulp (sin, cos of any angle up to 1000 rad),
# 2 ulp (atan2, and sin, cos up to SINCOS_MAX); C's signed-zero, infinity and NaN rules. In numpy
# they would be 2-45x slower than numpy's ufuncs, so that path keeps those.

SINCOS_MAX = 1.0e6  # |t| (rad) past which sincos_poly gives NaN (its pi/2 reduction needs |q| < 2^20)

_INVPIO2 = 6.36619772367581382433e-01
# pi/2 as three 33-bit parts and a tail (fdlibm's pio2_1, pio2_2, pio2_3, pio2_3t): each q * part
# is exact for |q| < 2^20, and the four carry ~150 bits, so r keeps full relative precision even
# next to a multiple of pi/2 (without the tail: 1e-25 rad absolute, millions of ulp of a tiny sine).
_PIO2_1 = 1.57079632673412561417e+00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_PIO2_3T = 8.47842766036889956997e-32
_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
      2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
      -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)
_AT = (3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01,
       -1.11111104054623557880e-01, 9.09088713343650656196e-02, -7.69187620504482999495e-02,
       6.66107313738753120669e-02, -5.83357013379057348645e-02, 4.97687799461593236017e-02,
       -3.65315727442169155270e-02, 1.62858201153657823623e-02)
_ATAN_HALF = (4.63647609000806093515e-01, 2.26987774529616870924e-17)  # atan(0.5), hi + lo
_ATAN_ONE = (7.85398163397448278999e-01, 3.06161699786838301793e-17)  # pi/4
_PIO2 = (1.57079632679489655800e+00, 6.12323399573676603587e-17)
_PI = (3.14159265358979311600e+00, 1.22464679914735317723e-16)


def sincos(t):
    """(sin t, cos t) of ``t`` in radians; NaN past SINCOS_MAX, as the numba backend's polynomial."""
    t = np.where(np.abs(t) <= SINCOS_MAX, t, np.nan)
    return np.sin(t), np.cos(t)


def atan2(y, x):
    """The angle of (x, y) in radians, (-pi, pi], with IEEE signed-zero rules."""
    return np.arctan2(y, x)


def sincos_poly(t):
    """(sin t, cos t) by fdlibm's kernels on [-pi/4, pi/4] after reducing by the nearest multiple
    of pi/2 (Cody-Waite): within 1 ulp of CPython's math.sin/cos for |t| <= 1000 rad and 2 ulp up
    to SINCOS_MAX, next to multiples of pi/2 too (tested); NaN past it (an angle of 57 million
    degrees is corrupt input, not a direction), and NaN for NaN or infinite t."""
    q = np.rint(t * _INVPIO2)
    r = (((t - q * _PIO2_1) - q * _PIO2_2) - q * _PIO2_3) - q * _PIO2_3T
    z = r * r
    s = r + r * z * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5]))))))
    k = q - 4.0 * np.floor(0.25 * q)  # quadrant 0..3
    odd = (k == 1.0) | (k == 3.0)
    sn = pick(odd, c, s)
    cs = pick(odd, s, c)
    sn = pick(k >= 2.0, -sn, sn)
    cs = pick((k == 1.0) | (k == 2.0), -cs, cs)
    sn = pick(t == 0.0, t, sn)  # sin(-0) = -0, as in C: the reduction above turns -0 into +0
    ok = np.abs(t) <= SINCOS_MAX
    return pick(ok, sn, np.nan), pick(ok, cs, np.nan)


def atan2_poly(y, x):
    """atan2 by fdlibm's atan polynomial on |y|/|x| or |x|/|y| (whichever is <= 1), then the
    octant: within 2 ulp of the C library, same signed-zero, infinity and NaN rules."""
    ax = np.abs(x)
    ay = np.abs(y)
    swap = ay > ax
    num = np.minimum(ax, ay)
    den = np.maximum(ax, ay)
    t = pick(den == 0.0, 0.0, pick(ax == ay, 1.0, num / den))  # 0/0 and inf/inf
    t = pick((ax == ax) & (ay == ay), t, np.nan)  # a NaN in gives NaN out
    # fdlibm atan on [0, 1]: reduce about 0 (t < 7/16), 0.5 (t < 11/16) or 1
    mid = t >= 0.4375
    top = t >= 0.6875
    tr = pick(top, (t - 1.0) / (t + 1.0), pick(mid, (2.0 * t - 1.0) / (2.0 + t), t))
    hi = pick(top, _ATAN_ONE[0], pick(mid, _ATAN_HALF[0], 0.0))
    lo = pick(top, _ATAN_ONE[1], pick(mid, _ATAN_HALF[1], 0.0))
    z = tr * tr
    w = z * z
    s1 = z * (_AT[0] + w * (_AT[2] + w * (_AT[4] + w * (_AT[6] + w * (_AT[8] + w * _AT[10])))))
    s2 = w * (_AT[1] + w * (_AT[3] + w * (_AT[5] + w * (_AT[7] + w * _AT[9]))))
    a = hi - ((tr * (s1 + s2) - lo) - tr)
    a = pick(swap, (_PIO2[0] - a) + _PIO2[1], a)
    a = pick(np.signbit(x), (_PI[0] - a) + _PI[1], a)
    a = pick(swap & (t == 0.0), _PIO2[0], a)  # x = ±0 or |y| = inf with x finite: exactly ±pi/2
    return np.copysign(a, y)


# ---------------------------------------------------------------- 3x3 algebra on 9-tuples


@compiled(inline=True)
def mat_mul(A, B):
    """Product of two rotations given as row-major 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (
        a0 * b0 + a1 * b3 + a2 * b6,
        a0 * b1 + a1 * b4 + a2 * b7,
        a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6,
        a3 * b1 + a4 * b4 + a5 * b7,
        a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6,
        a6 * b1 + a7 * b4 + a8 * b7,
        a6 * b2 + a7 * b5 + a8 * b8,
    )


@compiled(inline=True)
def mat_vec(A, x, y, z):
    """``A @ (x, y, z)``."""
    return (
        A[0] * x + A[1] * y + A[2] * z,
        A[3] * x + A[4] * y + A[5] * z,
        A[6] * x + A[7] * y + A[8] * z,
    )


@compiled(inline=True)
def mat_t_vec(A, x, y, z):
    """``A.T @ (x, y, z)`` (the inverse rotation)."""
    return (
        A[0] * x + A[3] * y + A[6] * z,
        A[1] * x + A[4] * y + A[7] * z,
        A[2] * x + A[5] * y + A[8] * z,
    )


@compiled(inline=True)
def rot_x(t):
    """Active rotation by ``t`` about x (y turns toward z)."""
    s, c = sincos(t)
    o = 0.0 * t
    return (o + 1.0, o, o, o, c, -s, o, s, c)


@compiled(inline=True)
def rot_y(t):
    """Active rotation by ``t`` about y (z turns toward x)."""
    s, c = sincos(t)
    o = 0.0 * t
    return (c, o, s, o, o + 1.0, o, -s, o, c)


@compiled(inline=True)
def rot_z(t):
    """Active rotation by ``t`` about z (x turns toward y)."""
    s, c = sincos(t)
    o = 0.0 * t
    return (c, -s, o, s, c, o, o, o, o + 1.0)


@compiled(inline=True)
def r_ned_body(yaw, pitch, roll):
    """R_ned_body = Rz(yaw) Ry(pitch) Rx(roll), written out (ZYX, active)."""
    sy, cy = sincos(yaw)
    sp, cp = sincos(pitch)
    sr, cr = sincos(roll)
    return (
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )


@compiled(inline=True)
def r_ecef_ned(lat, lon):
    """R_ecef_ned: columns are the north, east and down unit vectors in ECEF."""
    sl, cl = sincos(lat)
    so, co = sincos(lon)
    return (-sl * co, -so, -cl * co, -sl * so, co, -cl * so, cl, 0.0 * lat, -sl)


@compiled(inline=True)
def r_body_cam_azel(az, el, sensor_roll, skew):
    """Azimuth-elevation turret: G = Rz(az) Rx(skew) Ry(el) Rx(sensor_roll); camera z = G x, x = G y,
    y = G z. ``skew``: non-orthogonality of the elevation axis to the azimuth axis (0 for a perfect turret)."""
    g = mat_mul(mat_mul(rot_z(az), rot_x(skew)), mat_mul(rot_y(el), rot_x(sensor_roll)))
    return (g[1], g[2], g[0], g[4], g[5], g[3], g[7], g[8], g[6])


@compiled(inline=True)
def r_body_cam_rollpitch(frame_roll, frame_pitch, sensor_roll, skew):
    """Roll-pitch framed camera ([Q]): S = Rx(roll) Rz(skew) Ry(pitch) Rz(sensor_roll), camera = S C
    (``skew``: non-orthogonality of the pitch axis to the roll axis, 0 for a perfect gimbal).

    C maps the computer-vision camera frame into [Q]'s sensor frame S: the ray of pixel (u, v) in S
    is (v - cy, -(u - cx), f), i.e. image rows grow toward S +x and columns toward S -y.
    """
    s = mat_mul(mat_mul(rot_x(frame_roll), rot_z(skew)), mat_mul(rot_y(frame_pitch), rot_z(sensor_roll)))
    return (-s[1], s[0], s[2], -s[4], s[3], s[5], -s[7], s[6], s[8])


# ---------------------------------------------------------------- geodesy


@compiled(inline=True)
def geodetic_to_ecef(lat, lon, h, a, e2):
    """Geodetic (rad, rad, m ellipsoidal) to ECEF metres."""
    sl, cl = sincos(lat)
    so, co = sincos(lon)
    n = a / np.sqrt(1.0 - e2 * sl * sl)
    r = (n + h) * cl
    return r * co, r * so, (n * (1.0 - e2) + h) * sl


@compiled(inline=True)
def bowring(x, y, z, a, b, e2, ep2, steps):
    """Sine and cosine of the geodetic latitude, p = sqrt(x² + y²) and h, without any atan2.

    Bowring's formula from the reduced latitude of the point's projection. Two steps: 2 nm
    worst case from -10 km to 100 km (one step: latitude 0.09 mm off at 100 km, but h still
    within 5 nm, enough where only h matters). No division by p, so the poles are exact; h from
    sin/cos of the latitude stays exact there too.
    """
    p = np.sqrt(x * x + y * y)
    su = a * z
    cu = b * p
    for _ in range(steps):
        k = 1.0 / np.sqrt(su * su + cu * cu)
        su = su * k
        cu = cu * k
        num = z + ep2 * b * su * su * su  # (num, den) is parallel to (sin lat, cos lat)
        den = p - e2 * a * cu * cu * cu
        su = b * num  # tan(reduced lat) = (b / a) tan(lat)
        cu = a * den
    k = 1.0 / np.sqrt(num * num + den * den)
    sl = num * k
    cl = den * k
    h = p * cl + z * sl - a * np.sqrt(1.0 - e2 * sl * sl)
    return sl, cl, p, h


@compiled(inline=True)
def ecef_to_geodetic(x, y, z, a, b, e2, ep2):
    """ECEF metres to geodetic (rad, rad, m ellipsoidal); longitude 0 on the polar axis."""
    sl, cl, p, h = bowring(x, y, z, a, b, e2, ep2, 2)
    return atan2(sl, cl), atan2(y, x), h


# ---------------------------------------------------------------- pose and rays


@compiled(inline=True)
def pose_frame(lat, lon, h, yaw, pitch, roll, R_body_cam, lx, ly, lz, a, e2):
    """Camera pose in ECEF: (R_ecef_cam 9-tuple, camera origin x, y, z).

    ``R_body_cam`` already includes gimbal angles and misalignments; (lx, ly, lz) is the lever
    arm from the INS reference point to the camera, body frame, metres.
    """
    R_ecef_ned = r_ecef_ned(lat, lon)
    R_ecef_body = mat_mul(R_ecef_ned, r_ned_body(yaw, pitch, roll))
    R_ecef_cam = mat_mul(R_ecef_body, R_body_cam)
    px, py, pz = geodetic_to_ecef(lat, lon, h, a, e2)
    dx, dy, dz = mat_vec(R_ecef_body, lx, ly, lz)
    return R_ecef_cam, px + dx, py + dy, pz + dz


@compiled(inline=True)
def ray_direction(R_ecef_cam, xn, yn):
    """Unit ECEF direction of the ray through normalised image point (xn, yn) = ((u-cx)/fx, (v-cy)/fy)."""
    k = 1.0 / np.sqrt(xn * xn + yn * yn + 1.0)
    return mat_vec(R_ecef_cam, xn * k, yn * k, k)


@compiled(inline=True)
def project_point(R_ecef_cam, ox, oy, oz, px, py, pz):
    """Ground to image: normalised image point (xn, yn) and depth along the boresight (m)."""
    cx, cy, cz = mat_t_vec(R_ecef_cam, px - ox, py - oy, pz - oz)
    zs = pick(cz > 0.0, cz, np.nan)
    return cx / zs, cy / zs, cz


# ---------------------------------------------------------------- lens distortion

# Distortion model codes and their packed parameters ``dp`` (eoloc.sensor.distortion):
# DIST_BROWN: (k1, k2, p1, p2, k3), OpenCV's order; DIST_RATIO: (w0, n, n breakpoints of the
# normalised field, then 4 cubic coefficients per interval, highest power first); DIST_FISHEYE:
# Pix4D's fisheye (p0 .. p4 of the polynomial in theta = 2/pi atan(r), then the affine a, b, c, d
# that takes its (xh, yh) to distorted normalised coordinates).
DIST_NONE, DIST_BROWN, DIST_RATIO, DIST_FISHEYE = 0, 1, 2, 3
_BROWN_NEWTON_STEPS = 12
_RATIO_FIXED_POINT_STEPS = 30
_FISHEYE_NEWTON_STEPS = 30
_TWO_OVER_PI = 0.6366197723675814


@compiled()
def distort_brown(x, y, k1, k2, p1, p2, k3):
    """OpenCV's Brown-Conrady model: ideal normalised (x, y) -> distorted normalised."""
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy = x * y
    return (x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy)


@compiled()
def undistort_brown(xd, yd, k1, k2, p1, p2, k3):
    """Inverse of :func:`distort_brown` by Newton's method on the 2x2 Jacobian (to ~1e-15)."""
    x = xd
    y = yd
    for _ in range(_BROWN_NEWTON_STEPS):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
        fx, fy = distort_brown(x, y, k1, k2, p1, p2, k3)
        fx = fx - xd
        fy = fy - yd
        jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        jxy = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = jxx * jyy - jxy * jxy
        x = x - (jyy * fx - jxy * fy) / det
        y = y - (jxx * fy - jxy * fx) / det
    return x, y


@compiled()
def ppoly_eval(x, dp, i0, n):
    """Piecewise cubic at x: breakpoints dp[i0 : i0 + n], then 4 coefficients per interval
    (highest power first, in powers of x - breakpoint); the end pieces extrapolate."""
    idx = 0
    for j in range(1, n - 1):
        idx = idx + pick(x >= dp[i0 + j], 1, 0)
    c = i0 + n + 4 * idx
    s = x - dp[i0 + idx]
    return ((dp[c] * s + dp[c + 1]) * s + dp[c + 2]) * s + dp[c + 3]


@compiled()
def distortion_ratio(r, dp):
    """[Z15]'s distortion ratio D at distorted normalised image height r (field w = atan(r) / w0)."""
    return ppoly_eval(np.arctan(r) / dp[0], dp, 2, int(dp[1]))


@compiled()
def fisheye_rho(t, dp):
    """Pix4D's fisheye polynomial rho(theta) and its derivative."""
    rho = dp[0] + t * (dp[1] + t * (dp[2] + t * (dp[3] + t * dp[4])))
    drho = dp[1] + t * (2.0 * dp[2] + t * (3.0 * dp[3] + t * 4.0 * dp[4]))
    return rho, drho


@compiled()
def distort_fisheye(x, y, dp):
    """Pix4D's fisheye: ideal normalised (x, y) = (X/Z, Y/Z) -> distorted normalised: theta =
    2/pi atan(r), rho(theta), (xh, yh) = rho (x, y) / r, then the affine (a b; c d)."""
    r = np.sqrt(x * x + y * y)
    t = _TWO_OVER_PI * np.arctan(r)
    rho, _ = fisheye_rho(t, dp)
    s = pick(r > 1e-12, rho / pick(r > 1e-12, r, 1.0), dp[1] * _TWO_OVER_PI)
    xh = s * x
    yh = s * y
    return dp[5] * xh + dp[6] * yh, dp[7] * xh + dp[8] * yh


@compiled()
def undistort_fisheye(xd, yd, dp):
    """Inverse of :func:`distort_fisheye`: the affine inverted, rho(theta) = |(xh, yh)| solved by
    Newton from theta = rho / p1, r = tan(pi/2 theta)."""
    det = dp[5] * dp[8] - dp[6] * dp[7]
    xh = (dp[8] * xd - dp[6] * yd) / det
    yh = (dp[5] * yd - dp[7] * xd) / det
    rho = np.sqrt(xh * xh + yh * yh)
    t = rho / dp[1]
    for _ in range(_FISHEYE_NEWTON_STEPS):
        f, df = fisheye_rho(t, dp)
        t = t - (f - rho) / df
    r = np.tan(t / _TWO_OVER_PI)
    s = pick(rho > 1e-12, r / pick(rho > 1e-12, rho, 1.0), 1.0 / (dp[1] * _TWO_OVER_PI))
    return s * xh, s * yh


@compiled()
def undistort(kind, dp, xd, yd):
    """Distorted normalised image coordinates -> ideal ones, for distortion model ``kind``."""
    if kind == DIST_BROWN:
        return undistort_brown(xd, yd, dp[0], dp[1], dp[2], dp[3], dp[4])
    if kind == DIST_RATIO:
        k = 1.0 + distortion_ratio(np.sqrt(xd * xd + yd * yd), dp)
        return xd / k, yd / k
    if kind == DIST_FISHEYE:
        return undistort_fisheye(xd, yd, dp)
    return xd, yd


# A pixel is located only inside the image: from the outer edge of the edge pixels (-0.5 and
# width - 0.5) out to this margin, and only where the lens model maps it to one ray.
IMAGE_MARGIN_PX = 0.5


@compiled()
def pixel_in_image(u, v, width, height):
    """True where pixel (u, v) lies in a width x height image, IMAGE_MARGIN_PX beyond its outer edges included."""
    m = 0.5 + IMAGE_MARGIN_PX
    return (u >= -m) & (u <= width - 1.0 + m) & (v >= -m) & (v <= height - 1.0 + m)


@compiled()
def undistort_ok(kind, dp, xd, yd, x, y):
    """True where ideal (x, y) is THE undistortion of distorted (xd, yd): the model maps it back
    (to 1e-9) on the branch where the model is one-to-one (Brown-Conrady: positive Jacobian, so
    past the fold of a barrel lens a pixel is not inverted), and the ratio model's 1 + D > 0
    (seen as no change of sign between (xd, yd) and (x, y), without evaluating D again)."""
    if kind == DIST_BROWN:
        k1 = dp[0]
        k2 = dp[1]
        p1 = dp[2]
        p2 = dp[3]
        k3 = dp[4]
        fx, fy = distort_brown(x, y, k1, k2, p1, p2, k3)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        jxy = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        back = np.abs(fx - xd) + np.abs(fy - yd) <= 1e-9 * (1.0 + np.abs(xd) + np.abs(yd))
        return back & (jxx * jyy - jxy * jxy > 0.0) & (jxx > 0.0)
    if kind == DIST_RATIO:  # x = xd / (1 + D): 1 + D > 0 exactly where no sign flips (and all finite)
        return ((x - x) == 0.0) & ((y - y) == 0.0) & (x * xd >= 0.0) & (y * yd >= 0.0)
    if kind == DIST_FISHEYE:  # in front of the lens (theta < 1: under 90 deg off axis), on the rising branch
        fx, fy = distort_fisheye(x, y, dp)
        t = _TWO_OVER_PI * np.arctan(np.sqrt(x * x + y * y))
        _, drho = fisheye_rho(t, dp)
        back = np.abs(fx - xd) + np.abs(fy - yd) <= 1e-9 * (1.0 + np.abs(xd) + np.abs(yd))
        return back & (t < 1.0) & (drho > 0.0)
    return (x - x) == 0.0


@compiled()
def distort(kind, dp, x, y):
    """Ideal normalised image coordinates -> distorted ones, for distortion model ``kind``."""
    if kind == DIST_BROWN:
        return distort_brown(x, y, dp[0], dp[1], dp[2], dp[3], dp[4])
    if kind == DIST_FISHEYE:
        return distort_fisheye(x, y, dp)
    if kind == DIST_RATIO:
        zeta = np.sqrt(x * x + y * y)
        eta = zeta
        for _ in range(_RATIO_FIXED_POINT_STEPS):  # a contraction: |dD/deta| zeta << 1
            eta = zeta * (1.0 + distortion_ratio(eta, dp))
        k = 1.0 + distortion_ratio(eta, dp)
        return x * k, y * k
    return x, y


# ---------------------------------------------------------------- stop rules


# Validity domain shared by the stop rules (docs/uncertainty.md "Validity domains"): outside it the input is
# INVALID_INPUT, never a point. Beyond these magnitudes squares and products in the kernels lose
# the precision a millimetre needs, and no airborne sensor is there.
MAX_ORIGIN_M = 1.0e8  # |camera origin| (ECEF m): 100 000 km from the Earth's centre
MAX_RANGE_M = 1.0e7  # M1 slant range (m)
MIN_HEIGHT_M = -1.0e5  # M3 target surface height (m, ellipsoidal): -100 km ...
MAX_HEIGHT_M = 1.0e7  # ... +10 000 km
UNIT_TOL = 1.0e-6  # a ray direction must be a unit vector to this (a zero or overflowed one is not)
_EXACT_TOL_M = 1.0e-6  # M3: an OK point is this close to the surface (the contract says < 1 mm) ...
SURFACE_TOL_M = 1.0e-4  # ... but at an exact tangent, where Newton steps crawl: then this close
_EXACT_STEPS = 60  # exact M3: Newton steps from the left (4 suffice but at a near-tangent double root)
_PAD_REL = 2.0e-6  # the inflated ellipsoid (a+H, b+H) is within 1.42e-6 |H| of the surface of
# geodetic height H (measured against pyproj from -20 km to +2000 km): padded by this, it bounds it


@compiled(inline=True)
def ray_valid(ox, oy, oz, dx, dy, dz):
    """True where a ray is usable: finite, a unit direction, an origin within MAX_ORIGIN_M."""
    dd = dx * dx + dy * dy + dz * dz
    oo = ox * ox + oy * oy + oz * oz
    return _finite(oo + dd) & (np.abs(dd - 1.0) <= UNIT_TOL) & (oo <= MAX_ORIGIN_M * MAX_ORIGIN_M)


@compiled(inline=True)
def stop_at_range(ox, oy, oz, dx, dy, dz, rng, a, b, e2, ep2):
    """M1: the point at slant range ``rng`` (m, 0 < rng <= MAX_RANGE_M) along the ray
    -> (lat, lon, h, range, status)."""
    valid = ray_valid(ox, oy, oz, dx, dy, dz) & (rng > 0.0) & (rng <= MAX_RANGE_M)
    r = pick(valid, rng, np.nan)
    lat, lon, h = ecef_to_geodetic(ox + r * dx, oy + r * dy, oz + r * dz, a, b, e2, ep2)
    return lat, lon, h, r, pick(valid, OK, INVALID_INPUT)


@compiled(inline=True)
def inflated_roots(ox, oy, oz, dx, dy, dz, ht, a, b):
    """Both ray parameters (t1 <= t2, NaN if none) where the ray meets the inflated ellipsoid
    (a + ht, b + ht): within 1.42e-6 |ht| of the surface of geodetic height ht."""
    A = a + ht
    B = b + ht
    ia = 1.0 / (A * A)
    ib = 1.0 / (B * B)
    qa = (dx * dx + dy * dy) * ia + dz * dz * ib
    qb = (ox * dx + oy * dy) * ia + oz * dz * ib
    qc = (ox * ox + oy * oy) * ia + oz * oz * ib - 1.0
    disc = qb * qb - qa * qc
    sq = np.sqrt(pick(disc >= 0.0, disc, np.nan))
    return (-qb - sq) / qa, (-qb + sq) / qa


@compiled(inline=True)
def _height_slope(x, y, z, dx, dy, dz, a, b, e2, ep2, steps):
    """(geodetic height of (x, y, z), its derivative along the unit direction d = up . d, sin lat,
    cos lat) by ``steps`` Bowring steps: the gradient of geodetic height is the unit ellipsoid normal."""
    sl, cl, p, h = bowring(x, y, z, a, b, e2, ep2, steps)
    cl_p = pick(p > 0.0, cl / p, 0.0)  # cos(lat) / p: up = (cl_p x, cl_p y, sl)
    return h, cl_p * (x * dx + y * dy) + sl * dz, sl, cl


@compiled(inline=True)
def _m3_domain(ox, oy, oz, dx, dy, dz, ht):
    return ray_valid(ox, oy, oz, dx, dy, dz) & _finite(ht) & (ht >= MIN_HEIGHT_M) & (ht <= MAX_HEIGHT_M)


@compiled(inline=True)
def ellipsoid_fast(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2):
    """M3, the certified fast path -> (lat, lon, h, range, status), status UNDECIDED where it
    cannot prove its answer.

    Geodetic height along a straight line, g(t) = h(o + t d) - ht, is convex (the signed distance
    to a convex body; normals do not cross within 6 000 km of the surface). So a crossing where g
    falls (g'(t) < 0) is the first one, and the camera is above the surface. One Newton step from
    [Q]'s inflated-ellipsoid root, and the answer is certified when the point is within 1 µm of
    the surface and g clearly falls there; every other valid ray is UNDECIDED, for
    :func:`ellipsoid_classify` (misses, cameras below) and then :func:`ellipsoid_exact`.
    """
    # the products every quadric below shares (numpy: each is one pass over the arrays)
    dd_xy = dx * dx + dy * dy
    dd_z = dz * dz
    od_xy = ox * dx + oy * dy
    od_z = oz * dz
    oo_xy = ox * ox + oy * oy
    oo_z = oz * oz
    dd = dd_xy + dd_z
    valid = (_finite(oo_xy + oo_z + dd + ht) & (np.abs(dd - 1.0) <= UNIT_TOL)
             & (oo_xy + oo_z <= MAX_ORIGIN_M * MAX_ORIGIN_M) & (ht >= MIN_HEIGHT_M) & (ht <= MAX_HEIGHT_M))
    # [Q]'s inflated ellipsoid: its near root starts the Newton step
    ia = 1.0 / ((a + ht) * (a + ht))
    ib = 1.0 / ((b + ht) * (b + ht))
    qa = dd_xy * ia + dd_z * ib
    qb = od_xy * ia + od_z * ib
    qc = oo_xy * ia + oo_z * ib - 1.0
    disc = qb * qb - qa * qc
    t1 = (-qb - np.sqrt(pick(disc >= 0.0, disc, np.nan))) / qa
    t = pick(t1 > 0.0, t1, np.nan)
    h, s, sl, cl = _height_slope(ox + t * dx, oy + t * dy, oz + t * dz, dx, dy, dz, a, b, e2, ep2, 1)
    t = t - (h - ht) / s
    x = ox + t * dx
    y = oy + t * dy
    h, s, sl, cl = _height_slope(x, y, oz + t * dz, dx, dy, dz, a, b, e2, ep2, 2)
    # by convexity g(0) >= g(t) - t g'(t): the last term proves the camera is above the surface
    ok = valid & (np.abs(h - ht) <= _EXACT_TOL_M) & (s <= -UNIT_TOL) & (t * s < -2.0 * _EXACT_TOL_M)
    st = pick(ok, OK, pick(valid, UNDECIDED, INVALID_INPUT))
    return (pick(ok, atan2(sl, cl), np.nan), pick(ok, atan2(y, x), np.nan), pick(ok, h, np.nan),
            pick(ok, t, np.nan), st)


@compiled()
def ellipsoid_classify(ox, oy, oz, dx, dy, dz, ht, a, b):
    """M3, for a valid ray the fast path did not certify: BELOW_SURFACE where the camera is
    certainly under the surface (inside the inflated ellipsoid padded down), NO_INTERSECTION where
    the ray certainly misses it (never enters the one padded up, ahead), else UNDECIDED."""
    pad = 1.0e-3 + _PAD_REL * np.abs(ht)
    oo_xy = ox * ox + oy * oy
    oo_z = oz * oz
    below = oo_xy / ((a + ht - pad) * (a + ht - pad)) + oo_z / ((b + ht - pad) * (b + ht - pad)) < 1.0
    ia = 1.0 / ((a + ht + pad) * (a + ht + pad))
    ib = 1.0 / ((b + ht + pad) * (b + ht + pad))
    qa = (dx * dx + dy * dy) * ia + dz * dz * ib
    qb = (ox * dx + oy * dy) * ia + oz * dz * ib
    qc = oo_xy * ia + oo_z * ib - 1.0
    miss = (qb * qb - qa * qc < 0.0) | ((qb > 0.0) & (qc > 0.0))  # no real root, or both behind
    return pick(below, BELOW_SURFACE, pick(miss, NO_INTERSECTION, UNDECIDED))


@compiled()
def ellipsoid_exact(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2):
    """M3, the exact path -> (lat, lon, h, range, status): Newton steps on the convex g(t) from
    the left (from the camera, or from where the ray enters the outer inflated ellipsoid), which
    never overshoot the first crossing: a step lands at or before it. The walk ends at the surface
    (OK, within SURFACE_TOL_M) or where g stops falling with the ray still above it (a true miss,
    near-tangent rays included). The camera on or below the surface: BELOW_SURFACE."""
    valid = _m3_domain(ox, oy, oz, dx, dy, dz, ht)
    _, _, _, h0 = bowring(ox, oy, oz, a, b, e2, ep2, 2)  # the camera's own height
    pad = 1.0e-3 + _PAD_REL * np.abs(ht)
    o1, _ = inflated_roots(ox, oy, oz, dx, dy, dz, ht + pad, a, b)
    t = pick(o1 > 0.0, o1, 0.0)
    state = pick(h0 - ht <= _EXACT_TOL_M, BELOW_SURFACE, UNDECIDED)  # on (to 1 µm) or below
    for _ in range(_EXACT_STEPS):
        h, s, sl, cl = _height_slope(ox + t * dx, oy + t * dy, oz + t * dz, dx, dy, dz, a, b, e2, ep2, 2)
        g = h - ht
        state = pick(state == UNDECIDED, pick(g <= _EXACT_TOL_M, OK, pick(s >= 0.0, NO_INTERSECTION, UNDECIDED)),
                      state)
        t = pick(state == UNDECIDED, t - g / s, t)
    # still falling after every step: a (near-)double root, decided by the height reached
    h, s, sl, cl = _height_slope(ox + t * dx, oy + t * dy, oz + t * dz, dx, dy, dz, a, b, e2, ep2, 2)
    state = pick(state == UNDECIDED, pick(h - ht <= SURFACE_TOL_M, OK, NO_INTERSECTION), state)
    state = pick(valid, state, INVALID_INPUT)
    ok = state == OK
    x = ox + t * dx  # (no last Newton step: at a tangent it would leap past the touching point)
    y = oy + t * dy
    return (pick(ok, atan2(sl, cl), np.nan), pick(ok, atan2(y, x), np.nan), pick(ok, h, np.nan),
            pick(ok, t, np.nan), state)


def stop_at_ellipsoid_scalar(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2):
    """M3 for one ray: :func:`ellipsoid_fast`, then where it is undecided
    :func:`ellipsoid_classify` and, if that cannot tell either, :func:`ellipsoid_exact`.
    (The numba backend compiles this under the name ``stop_at_ellipsoid``.)"""
    lat, lon, h, t, st = ellipsoid_fast(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2)
    if st == UNDECIDED:
        st = ellipsoid_classify(ox, oy, oz, dx, dy, dz, ht, a, b)
        if st == UNDECIDED:
            return ellipsoid_exact(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2)
    return lat, lon, h, t, st


def stop_at_ellipsoid(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2):
    """M3: first point along the ray whose geodetic height is ``ht`` (m) -> (lat, lon, h, range,
    status), on arrays: :func:`ellipsoid_fast` everywhere, :func:`ellipsoid_classify` on the rays
    it could not certify (misses, cameras below), :func:`ellipsoid_exact` on the few left
    (near-tangent rays, a camera within centimetres of the surface, surfaces far above the Earth).
    A point is returned only on the surface to 1 µm (SURFACE_TOL_M at an exact tangent) and only
    at the first crossing; a camera on or below the surface gets BELOW_SURFACE, a ray that does not
    reach it NO_INTERSECTION; never the nearest point on the ray or the far crossing."""
    out = [np.asarray(v) for v in ellipsoid_fast(ox, oy, oz, dx, dy, dz, ht, a, b, e2, ep2)]
    out[4] = out[4].astype(np.int8)
    todo = np.flatnonzero(out[4] == UNDECIDED)
    if todo.size:
        shape = out[4].shape
        sub = [np.broadcast_to(v, shape).reshape(-1)[todo] for v in (ox, oy, oz, dx, dy, dz, ht)]
        st = np.asarray(ellipsoid_classify(*sub, a, b))
        out[4].reshape(-1)[todo] = st
        left = np.flatnonzero(st == UNDECIDED)
        if left.size:
            for o, v in zip(out, ellipsoid_exact(*(x[left] for x in sub), a, b, e2, ep2), strict=True):
                o.reshape(-1)[todo[left]] = v
    return tuple(o[()] if o.ndim == 0 else o for o in out)


@compiled()
def flat_plane(R_ecef_cam, ox, oy, oz, xn0, yn0, rng0, a, b, e2, ep2):
    """M2 ([Z15]) ground plane: through the main target at slant range ``rng0`` (m) on the ray
    through normalised (xn0, yn0), perpendicular to the local vertical there.

    -> (down x, y, z: unit ECEF normal at the main target, H: camera height above the plane
    along it, m); NaN when the range is not a positive number.
    """
    dx, dy, dz = ray_direction(R_ecef_cam, xn0, yn0)
    r = pick(_finite(rng0) & (rng0 > 0.0), rng0, np.nan)
    x = ox + r * dx
    y = oy + r * dy
    sl, cl, p, _ = bowring(x, y, oz + r * dz, a, b, e2, ep2, 2)
    cn = pick(p > 0.0, x / p, 1.0)  # cos and sin of the main target's longitude
    sn = pick(p > 0.0, y / p, 0.0)
    nx = -cl * cn
    ny = -cl * sn
    nz = -sl
    return nx, ny, nz, r * (dx * nx + dy * ny + dz * nz)


@compiled(inline=True)
def flat_target(R_ecef_cam, ox, oy, oz, nx, ny, nz, H, xn, yn, a, b, e2, ep2):
    """M2: the ray through normalised (xn, yn) to the plane of :func:`flat_plane`.

    range = H / (ray . down); rays parallel to the plane or pointing above it get
    NO_INTERSECTION. -> (lat, lon, h, range, status) like every stop rule.
    """
    dx, dy, dz = ray_direction(R_ecef_cam, xn, yn)
    c = dx * nx + dy * ny + dz * nz
    rng = H / c
    away = (c <= 0.0) | (rng > MAX_RANGE_M)  # pointing at or above the plane's horizon
    lat, lon, h, t, st = stop_at_range(ox, oy, oz, dx, dy, dz, pick(away, np.nan, rng), a, b, e2, ep2)
    known = _finite(H) & (st != OK)
    st = pick(known & away, NO_INTERSECTION, st)
    return lat, lon, h, t, pick(known & (H <= 0.0), BELOW_SURFACE, st)


# ---------------------------------------------------------------- whole chain, one call


@compiled(inline=True)
def r_body_cam(kind, g1, g2, g3, R_mount, R_fixed, R_bore, skew):
    """R_body_cam = R_mount . gimbal(g1, g2, g3) . R_bore for gimbal ``kind`` (``skew``: gimbal axes
    non-orthogonality, rad; 0 for a perfect gimbal, ignored by a fixed mount).

    kind 0: azimuth-elevation turret (g1 az, g2 el, g3 sensor roll);
    kind 1: roll-pitch framed camera (g1 frame roll, g2 frame pitch, g3 sensor roll);
    kind 2: fixed/generic mount ``R_fixed`` followed by a sensor roll g3 about the boresight.
    """
    if kind == GIMBAL_AZEL:
        G = r_body_cam_azel(g1, g2, g3, skew)
    elif kind == GIMBAL_ROLLPITCH:
        G = r_body_cam_rollpitch(g1, g2, g3, skew)
    else:
        G = mat_mul(R_fixed, rot_z(g3))
    return mat_mul(R_mount, mat_mul(G, R_bore))


@compiled(inline=True)
def camera_frame(kind, g1, g2, g3, R_mount, R_fixed, R_bore, skew, lat, lon, h, yaw, pitch, roll, lx, ly, lz, a, e2):
    """The camera's pose in ECEF from the aircraft pose and gimbal angles (radians, metres):
    :func:`r_body_cam` then :func:`pose_frame`, one pass -> (R_ecef_cam 9-tuple, origin x, y, z)."""
    R_body_cam = r_body_cam(kind, g1, g2, g3, R_mount, R_fixed, R_bore, skew)
    return pose_frame(lat, lon, h, yaw, pitch, roll, R_body_cam, lx, ly, lz, a, e2)


@compiled()
def _tuple9(p, i):
    return (p[i], p[i + 1], p[i + 2], p[i + 3], p[i + 4], p[i + 5], p[i + 6], p[i + 7], p[i + 8])


# Layout of the parameter vector built by SensorModel.kernel_params.
P_FX, P_FY, P_CX, P_CY, P_KIND, P_MOUNT, P_FIXED, P_BORE, P_LEVER, P_ELL = 0, 1, 2, 3, 4, 5, 14, 23, 32, 35
N_PARAMS = 39
STOP_RANGE = 0
STOP_ELLIPSOID = 1


@compiled()
def params_camera_frame(params, lat, lon, h, yaw, pitch, roll, g1, g2, g3):
    """:func:`camera_frame` of a pose (radians, metres) with the sensor's constants read from its
    packed parameter vector (layout above) -> (R_ecef_cam 9-tuple, origin x, y, z)."""
    return camera_frame(int(params[P_KIND]), g1, g2, g3, _tuple9(params, P_MOUNT), _tuple9(params, P_FIXED),
                        _tuple9(params, P_BORE), 0.0, lat, lon, h, yaw, pitch, roll, params[P_LEVER],
                        params[P_LEVER + 1], params[P_LEVER + 2], params[P_ELL], params[P_ELL + 2])


@compiled()
def locate_one(params, lat, lon, h, yaw, pitch, roll, g1, g2, g3, u, v, stop_kind, stop_value):
    """Pixel (u, v) of one pose to ground, everything in degrees/metres at the edges.

    Returns (lat_deg, lon_deg, h_m, range_m, status). ``params`` is SensorModel.kernel_params.
    """
    d = np.pi / 180.0
    a = params[P_ELL]
    b = params[P_ELL + 1]
    e2 = params[P_ELL + 2]
    ep2 = params[P_ELL + 3]
    R, ox, oy, oz = params_camera_frame(params, lat * d, lon * d, h, yaw * d, pitch * d, roll * d, g1 * d, g2 * d,
                                        g3 * d)
    dx, dy, dz = ray_direction(R, (u - params[P_CX]) / params[P_FX], (v - params[P_CY]) / params[P_FY])
    if stop_kind == STOP_RANGE:
        rlat, rlon, rh, t, st = stop_at_range(ox, oy, oz, dx, dy, dz, stop_value, a, b, e2, ep2)
    else:
        rlat, rlon, rh, t, st = stop_at_ellipsoid(ox, oy, oz, dx, dy, dz, stop_value, a, b, e2, ep2)
    if not np.abs(lat) <= 90.0:  # also catches NaN; out-of-range angles elsewhere just rotate
        return np.nan, np.nan, np.nan, np.nan, INVALID_INPUT
    return rlat / d, rlon / d, rh, t, st


# ---------------------------------------------------------------- terrain grids


def _floor_index(x, hi):
    """floor(x) as an integer index, clamped to [0, hi] (numpy: arrays; numba: a branch)."""
    return np.clip(np.floor(x), 0, hi).astype(np.int64)


@compiled(inline=True)
def grid_height(z, lat0, lon0, dlat, dlon, lat, lon):
    """Bilinear height of a lat/lon grid at (lat, lon) in degrees -> (height, inside).

    ``z[i, j]`` is the post at (lat0 + i dlat, lon0 + j dlon). Outside the posts' extent:
    NaN and inside = False; a cell with a void (NaN) corner gives NaN with inside = True.
    """
    return grid_height_at(z, (lat - lat0) / dlat, (lon - lon0) / dlon)


@compiled(inline=True)
def grid_height_at(z, fr, fc):
    """:func:`grid_height` at fractional post indices (row fr, column fc) -> (height, inside):
    for callers that interpolate the indices themselves (they are linear in lat and lon)."""
    nrow = z.shape[0]
    ncol = z.shape[1]
    eps = 1e-9  # edge posts computed as 999.0000000001 are still edge posts
    inside = (fr >= -eps) & (fr <= nrow - 1.0 + eps) & (fc >= -eps) & (fc <= ncol - 1.0 + eps)
    r0 = _floor_index(pick(inside, fr, 0.0), nrow - 2)
    c0 = _floor_index(pick(inside, fc, 0.0), ncol - 2)
    ar = fr - r0
    ac = fc - c0
    top = (1.0 - ac) * z[r0, c0] + ac * z[r0, c0 + 1]
    bottom = (1.0 - ac) * z[r0 + 1, c0] + ac * z[r0 + 1, c0 + 1]
    h = (1.0 - ar) * top + ar * bottom
    return pick(inside, h, np.nan), inside


@compiled()
def cell_first_root(h0, dh, ar0, dar, ac0, dac, z00, z01, z10, z11, s_lo, s_hi):
    """First s in [s_lo, s_hi] where a straight ray meets one cell's bilinear surface; NaN if none.

    In the cell, local coordinates ar = ar0 + dar s (rows), ac = ac0 + dac s (columns) and the
    ray height h = h0 + dh s are linear in s; the bilinear height z00 (1-ar)(1-ac) + z01 (1-ar) ac
    + z10 ar (1-ac) + z11 ar ac is then quadratic in s, so ray minus surface is a quadratic
    c0 + c1 s + c2 s^2 solved exactly: no crossing inside the cell can be stepped over.
    A ray already at or below the surface at s_lo meets it at s_lo.
    """
    B = z10 - z00
    C = z01 - z00
    D = z00 - z01 - z10 + z11
    c0 = h0 - (z00 + B * ar0 + C * ac0 + D * ar0 * ac0)
    c1 = dh - (B * dar + C * dac + D * (ar0 * dac + ac0 * dar))
    c2 = -D * dar * dac
    g_lo = c0 + s_lo * (c1 + s_lo * c2)
    disc = c1 * c1 - 4.0 * c2 * c0
    sq = np.sqrt(pick(disc >= 0.0, disc, np.nan))
    q = -0.5 * (c1 + pick(c1 >= 0.0, sq, -sq))  # stable quadratic roots: q / c2 and c0 / q
    quad = np.abs(c2) > 1e-12 * (np.abs(c1) + np.abs(c0) + 1e-300)
    r1 = pick(quad, q / c2, -c0 / c1)
    r2 = pick(quad, c0 / q, np.nan)
    ok1 = (r1 >= s_lo) & (r1 <= s_hi)
    ok2 = (r2 >= s_lo) & (r2 <= s_hi)
    first = pick(ok1 & ok2, np.minimum(r1, r2), pick(ok1, r1, pick(ok2, r2, np.nan)))
    return pick(g_lo <= 0.0, s_lo, first)


# ---------------------------------------------------------------- declarations


@dataclass(frozen=True)
class Signature:
    """How the backends drive a kernel over many elements (:func:`eoloc.kernels.backend.run`): its
    parameters in order (read off the function), which are the same for every element
    (``constants``; ``ints`` among them are integers) and its outputs. A name starting with
    ``R_`` is a rotation: 9 numbers, given as one argument (a 9-tuple or an array with 9 in its
    first axis) and returned as a 9-tuple; a driver sees it as 9 flat arrays. An output named
    ``status`` is int8. ``numpy_ns``: the numpy path's time per element (ns, measured on the
    bench machine), which the ``auto`` backend counts against numba's loading time."""

    name: str
    params: tuple[str, ...]
    outputs: tuple[str, ...]
    constants: frozenset[str] = frozenset()
    ints: frozenset[str] = frozenset()
    numpy_ns: float = 100.0

    @staticmethod
    def width(name: str) -> int:
        return 9 if name.startswith("R_") else 1


def declare(fn, outputs: str, constants: str = "", ints: str = "", *, numpy_ns: float) -> Signature:
    code = fn.__code__
    return Signature(fn.__name__, code.co_varnames[:code.co_argcount], tuple(outputs.split()),
                     frozenset(constants.split()) | frozenset(ints.split()), frozenset(ints.split()), numpy_ns)


SIGNATURES = {s.name: s for s in (  # numpy_ns: 2^20 elements, best of 5, 2026-11-24 (bench/RESULTS.md)
    declare(geodetic_to_ecef, "x y z", "a e2", numpy_ns=50),
    declare(ecef_to_geodetic, "lat lon h", "a b e2 ep2", numpy_ns=30),
    declare(camera_frame, "R_ecef_cam ox oy oz", "a e2", ints="kind", numpy_ns=350),
    declare(ray_direction, "dx dy dz", numpy_ns=13),
    declare(project_point, "xn yn depth", numpy_ns=16),
    declare(stop_at_range, "lat lon h t status", "a b e2 ep2", numpy_ns=45),
    declare(stop_at_ellipsoid, "lat lon h t status", "a b e2 ep2", numpy_ns=90),
    declare(flat_target, "lat lon h t status", "a b e2 ep2", numpy_ns=70),
)}
