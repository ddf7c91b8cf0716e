"""Coverage of eoloc's uncertainties: simulated passes with known errors, truth made without eoloc.

Each pass is one aircraft flying a straight line past one ground target (a point chosen first:
that is the truth), its turret following the target with a pointing jitter. The aircraft's
position, attitude and gimbal angles and the target's pixel are computed with the oracle's
independent geometry (pyproj, scipy ``Rotation``, the README's conventions written out in
:mod:`oracle_lib`); eoloc never takes part in making the truth. The telemetry eoloc is then given
is that truth plus errors drawn from the error budget the way the budget says they behave in
time: a **bias** once per pass, **noise** anew every frame, a **Gauss–Markov** error as the
stationary first-order process exp(-dt / tau) (started from its stationary law).

Every path that gives an uncertainty is then asked where the target is and how sure it is, and
the truth is compared with the regions it predicts: the share of truths inside the 50 % and 90 %
horizontal circles (CEP50, CE90) and inside the 90 % vertical interval (LE90). For an honest
uncertainty the shares are 50 %, 90 %, 90 % within the binomial band of the number of targets.
Targets whose covariance is flagged non-linear, or whose fixes are flagged INCONSISTENT, are
counted apart.

Used by ``tests/integration/test_coverage.py`` (seeded, ~10^3 targets per path) and
``bench/bench_coverage.py`` (-n for big runs; the README's table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import oracle_lib as O

# the budget of the simulated flights: every kind of behaviour in time, every group of source
BUDGET = {
    "lat_deg": {"normal": 2.0e-5, "kind": "markov", "tau_s": 60.0},
    "lon_deg": {"normal": 2.5e-5, "kind": "markov", "tau_s": 60.0},
    "h_m": {"normal": 3.0, "kind": "markov", "tau_s": 60.0},
    "yaw_deg": {"normal": 0.05, "kind": "markov", "tau_s": 120.0},
    "pitch_deg": {"normal": 0.02, "kind": "noise"},
    "roll_deg": {"normal": 0.02, "kind": "noise"},
    "gimbal1_deg": {"normal": 0.02, "kind": "bias"},
    "gimbal2_deg": {"normal": 0.02, "kind": "bias"},
    "u_px": {"normal": 1.0, "kind": "noise"},
    "v_px": {"normal": 1.0, "kind": "noise"},
}
RULE_SOURCE = {"height": ("terrain_m", {"normal": 3.0, "kind": "bias"}),
               "range": ("range_m", {"normal": 2.0, "kind": "noise"})}
WIDTH, HEIGHT, HFOV_DEG = 1280, 720, 20.0
ACCEL_PSD = 0.1  # m^2/s^3: the moving targets' white acceleration, as eoloc's TrackerConfig assumes


def budget_for(rule: str) -> dict:
    name, law = RULE_SOURCE[rule]
    return {**BUDGET, name: law}


def oracle_camera() -> O.Camera:
    f = (WIDTH / 2.0) / math.tan(math.radians(HFOV_DEG) / 2.0)
    return O.Camera(WIDTH, HEIGHT, f, f, (WIDTH - 1) / 2.0, (HEIGHT - 1) / 2.0)


def draw_errors(rng: np.random.Generator, budget: dict, time_s: np.ndarray, k: int) -> dict[str, np.ndarray]:
    """(F, K) errors per source for K passes at the frame times ``time_s`` (F,), each drawn as
    the budget says it behaves in time (normal laws)."""
    f = time_s.size
    out = {}
    for name, spec in budget.items():
        sigma = spec["normal"]
        kind = spec["kind"]
        if kind == "bias":
            e = np.broadcast_to(rng.normal(0.0, sigma, k), (f, k)).copy()
        elif kind == "noise":
            e = rng.normal(0.0, sigma, (f, k))
        else:
            e = np.empty((f, k))
            e[0] = rng.normal(0.0, sigma, k)
            for i in range(1, f):
                rho = math.exp(-(time_s[i] - time_s[i - 1]) / spec["tau_s"])
                e[i] = rho * e[i - 1] + math.sqrt(1.0 - rho * rho) * rng.normal(0.0, sigma, k)
        out[name] = e
    return out


@dataclass
class Passes:
    """K simulated passes of F frames: the truth and what eoloc is told."""

    time_s: np.ndarray  # (F,)
    target: np.ndarray  # (K, 3) lat, lon, h of each pass's target (a moving one: where it is last)
    target_at: np.ndarray  # (F, K, 3) the target at each frame
    true_pose: dict  # (F, K) each: lat, lon, h, yaw, pitch, roll, az, el
    true_pixel: tuple  # (F, K) u, v
    true_range_m: np.ndarray  # (F, K)
    measured: dict  # (F, K) each: the pose, pixel, range and surface height eoloc is given
    errors: dict


def simulate(rng: np.random.Generator, k: int, frames: int, rule: str, *, dt_s: float = 1.0,
             spread_deg: float | None = None, speed_mps: float = 0.0) -> Passes:
    """K passes of ``frames`` frames ``dt_s`` apart, stop rule "height" or "range"; the targets
    anywhere between 60 S and 60 N, or within ``spread_deg`` of one such place; static, or driving
    on the local level at up to ``speed_mps`` with a white acceleration of :data:`ACCEL_PSD` (the
    model the tracker declares: its covariance is held to the truth of that model)."""
    cam = oracle_camera()
    t = np.arange(frames) * dt_s
    if spread_deg is None:
        lat_t = rng.uniform(-60.0, 60.0, k)
        lon_t = rng.uniform(-180.0, 180.0, k)
    else:
        lat_t = rng.uniform(-60.0, 60.0) + rng.uniform(-spread_deg, spread_deg, k)
        lon_t = rng.uniform(-180.0, 180.0) + rng.uniform(-spread_deg, spread_deg, k)
    h_t = rng.uniform(0.0, 2500.0, k)
    T0 = O.to_ecef(lat_t, lon_t, h_t)  # (K, 3) the target at the middle of the pass
    # the aircraft: 2-6 km up, 4-12 km off the target, flying straight at 40-80 m/s
    up = rng.uniform(2000.0, 6000.0, k)
    off = rng.uniform(4000.0, 12000.0, k)
    bearing = rng.uniform(0.0, 360.0, k)  # from the target to the middle of the pass
    heading = (bearing + 90.0 + rng.normal(0.0, 20.0, k)) % 360.0
    speed = rng.uniform(40.0, 80.0, k)
    R_en = O.r_ecef_ned(lat_t, lon_t)  # (K, 3, 3) at the target
    moved = np.zeros((frames, k, 3))
    if speed_mps > 0:  # driving on the local level: the tracker's model, white acceleration of ACCEL_PSD
        course = np.radians(rng.uniform(0.0, 360.0, k))
        v = (rng.uniform(0.3, 1.0, k) * speed_mps)[:, None] * np.stack([np.cos(course), np.sin(course)], -1)
        sub = 20  # integration steps per frame
        h_s = dt_s / sub
        pos = np.zeros((k, 2))
        for i in range(1, frames):
            for _ in range(sub):
                a = rng.normal(0.0, math.sqrt(ACCEL_PSD / h_s), (k, 2))  # white noise of PSD q, held for h
                pos += v * h_s + 0.5 * a * h_s * h_s
                v += a * h_s
            moved[i, :, :2] = pos
        moved[..., :2] -= moved[frames // 2, :, :2]  # the middle of the pass at T0
    T = T0[None] + np.einsum("kij,fkj->fki", R_en, moved)  # (F, K, 3)
    along = (t - t.mean())[:, None] * speed[None, :]  # (F, K)
    b, hd = np.radians(bearing), np.radians(heading)
    north = off * np.cos(b) + along * np.cos(hd)
    east = off * np.sin(b) + along * np.sin(hd)
    ned = np.stack([north, east, np.broadcast_to(-up, north.shape)], -1)  # (F, K, 3)
    P = T0[None] + np.einsum("kij,fkj->fki", R_en, ned)
    lat, lon, h = O.geodetic(P)
    yaw = np.broadcast_to(heading, lat.shape) + rng.normal(0.0, 2.0, lat.shape)
    pitch = rng.normal(2.0, 1.0, lat.shape)
    roll = rng.normal(0.0, 3.0, lat.shape)
    # the turret points near the target (a jitter of up to a quarter of the field of view)
    R_eb = O.r_ecef_ned(lat, lon) @ O._euler("ZYX", yaw, pitch, roll)
    los_b = np.einsum("fkji,fkj->fki", R_eb, T - P)
    az0 = np.degrees(np.arctan2(los_b[..., 1], los_b[..., 0]))
    el0 = np.degrees(np.arctan2(-los_b[..., 2], np.hypot(los_b[..., 0], los_b[..., 1])))
    az = az0 + rng.uniform(-HFOV_DEG / 4, HFOV_DEG / 4, lat.shape)
    el = el0 + rng.uniform(-HFOV_DEG / 8, HFOV_DEG / 8, lat.shape)
    u, v = project(cam, lat, lon, h, yaw, pitch, roll, az, el, T)
    rng_true = np.linalg.norm(T - P, axis=-1)
    target_at = np.stack(O.geodetic(T), -1)
    budget = budget_for(rule)
    e = draw_errors(rng, budget, t, k)
    m = {"lat_deg": lat + e["lat_deg"], "lon_deg": lon + e["lon_deg"], "h_m": h + e["h_m"],
         "yaw_deg": yaw + e["yaw_deg"], "pitch_deg": pitch + e["pitch_deg"], "roll_deg": roll + e["roll_deg"],
         "az_deg": az + e["gimbal1_deg"], "el_deg": el + e["gimbal2_deg"], "u_px": u + e["u_px"], "v_px": v + e["v_px"]}
    if rule == "height":
        m["height_m"] = target_at[..., 2] + e["terrain_m"]
    else:
        m["range_m"] = rng_true + e["range_m"]
    true = {"lat_deg": lat, "lon_deg": lon, "h_m": h, "yaw_deg": yaw, "pitch_deg": pitch, "roll_deg": roll,
            "az_deg": az, "el_deg": el}
    return Passes(t, target_at[-1], target_at, true, (u, v), rng_true, m, e)


def project(cam: O.Camera, lat, lon, h, yaw, pitch, roll, az, el, T) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (u, v) of ECEF point T seen from the pose: the oracle's rotations, a pinhole."""
    R_ec = O.r_ecef_ned(lat, lon) @ O._euler("ZYX", yaw, pitch, roll) @ O.r_body_cam("az-el", az, el, 0.0)
    c = np.einsum("...ji,...j->...i", R_ec, T - O.to_ecef(lat, lon, h))
    return cam.fx * c[..., 0] / c[..., 2] + cam.cx, cam.fy * c[..., 1] / c[..., 2] + cam.cy


def enu_error(lat, lon, h, target: np.ndarray) -> np.ndarray:
    """(..., 3) east/north/up error (m) of points (lat, lon, h) from the target (lat, lon, h) (...,
    3), in the target's local frame (pyproj ECEF)."""
    d = O.to_ecef(lat, lon, h) - O.to_ecef(target[..., 0], target[..., 1], target[..., 2])
    R = O.r_ecef_ned(target[..., 0], target[..., 1])  # columns N, E, D
    ned = np.einsum("...ji,...j->...i", R, d)
    return np.stack([ned[..., 1], ned[..., 0], -ned[..., 2]], -1)


def band(n: int, p: float) -> tuple[float, float]:
    """The binomial 99 % band of the share of n draws inside a region of probability p (normal
    approximation, z = 2.576, with a continuity half-count)."""
    half = 2.5758293035489 * math.sqrt(p * (1.0 - p) / n) + 0.5 / n
    return p - half, p + half


@dataclass
class Coverage:
    path: str
    n: int  # targets compared (consistent and linear)
    apart: int  # counted apart (non-linear or inconsistent)
    in50: float
    in90: float
    in_le90: float

    def within(self) -> dict[str, bool]:
        return {"CE50": band(self.n, 0.5)[0] <= self.in50 <= band(self.n, 0.5)[1],
                "CE90": band(self.n, 0.9)[0] <= self.in90 <= band(self.n, 0.9)[1],
                "LE90": math.isnan(self.in_le90) or band(self.n, 0.9)[0] <= self.in_le90 <= band(self.n, 0.9)[1]}

    def row(self) -> str:
        lo50, hi50 = band(self.n, 0.5)
        lo90, hi90 = band(self.n, 0.9)
        le = "—" if math.isnan(self.in_le90) else f"{100 * self.in_le90:.1f} %"
        return (f"| {self.path} | {self.n:,} | {self.apart:,} | {100 * self.in50:.1f} % ({100 * lo50:.1f}–"
                f"{100 * hi50:.1f}) | {100 * self.in90:.1f} % ({100 * lo90:.1f}–{100 * hi90:.1f}) | {le} |")


def assert_covers(cv: Coverage, n: int, *, apart_max: float = 0.02, check50: bool = True) -> None:
    """The path's 90 % circle and interval (and its 50 % circle unless ``check50`` is off) hold
    their share of the ``n`` truths within the binomial band, nearly every target located."""
    ok = cv.within()
    assert cv.n >= 0.95 * n and cv.apart <= apart_max * n, cv
    assert ok["CE90"] and ok["LE90"] and (ok["CE50"] or not check50), cv.row()


def coverage(path: str, err_enu: np.ndarray, cep50: np.ndarray, ce90: np.ndarray, le90: np.ndarray | None,
             keep: np.ndarray) -> Coverage:
    """Shares of truths inside the predicted regions, over the targets ``keep`` marks."""
    r = np.hypot(err_enu[..., 0], err_enu[..., 1])[keep]
    n = int(keep.sum())
    in_le = math.nan if le90 is None else float(np.mean(np.abs(err_enu[..., 2][keep]) <= le90[keep]))
    return Coverage(path, n, int(keep.size - n), float(np.mean(r <= cep50[keep])), float(np.mean(r <= ce90[keep])),
                    in_le)


# ---------------------------------------------------------------- the paths


def eoloc_inputs(p: Passes, rule: str):
    import eoloc
    from eoloc.accuracy import ErrorBudget

    sensor = eoloc.SensorModel(eoloc.Camera.from_hfov(HFOV_DEG, WIDTH, HEIGHT), eoloc.AzElGimbal())
    m = p.measured
    pose = eoloc.Pose(m["lat_deg"], m["lon_deg"], m["h_m"], m["yaw_deg"], m["pitch_deg"], m["roll_deg"],
                      (m["az_deg"], m["el_deg"]))
    r = eoloc.AtHeight(m["height_m"]) if rule == "height" else eoloc.AtRange(m["range_m"])
    return sensor, pose, r, ErrorBudget.from_mapping(budget_for(rule))


def per_fix(p: Passes, rule: str, frame: int = -1):
    """Covariance per fix (one frame of each pass): fixes, their covariance, the coverage."""
    from eoloc.accuracy import locate_with_covariance

    sensor, pose, r, budget = eoloc_inputs(p, rule)
    m = p.measured
    one = type(pose)(*(np.asarray(a)[frame] for a in (pose.lat_deg, pose.lon_deg, pose.h_m, pose.yaw_deg,
                                                       pose.pitch_deg, pose.roll_deg)),
                     tuple(np.asarray(g)[frame] for g in pose.gimbal_deg))
    rule_one = type(r)(np.asarray(m["height_m" if rule == "height" else "range_m"])[frame])
    fixes, cov = locate_with_covariance(sensor, one, budget, (m["u_px"][frame], m["v_px"][frame]), rule_one)
    err = enu_error(fixes.lat_deg, fixes.lon_deg, fixes.h_m, p.target_at[frame])
    keep = fixes.ok & cov.linear(0.1)
    return fixes, cov, coverage(f"covariance per fix, {rule} rule", err, cov.cep(0.5), cov.cep(0.9), cov.le90, keep)


def movers(p: Passes, rule: str, frame: int = -1, blob_m: float = 0.0):
    """The movers' fixes: in one frame of each pass a blob at the target's measured pixel (of
    ``blob_m`` x ``blob_m`` m on the ground, its centroid off by the quarter of its size eoloc
    allows for, drawn here), through eoloc's MoverTracker with the budget: each row's stated
    CEP50/CE90/LE90 against the truth."""
    from eoloc.detect.motion import Blobs
    from eoloc.detect.movers import MoverTracker

    sensor, pose, r, budget = eoloc_inputs(p, rule)
    m = p.measured
    value = np.asarray(m["height_m" if rule == "height" else "range_m"])[frame]
    rng = np.random.default_rng(53)
    err, c50, c90, le, keep = [], [], [], [], []
    for i in range(np.shape(m["u_px"])[-1]):
        one = type(pose)(*(float(np.asarray(a)[frame, i]) for a in (pose.lat_deg, pose.lon_deg, pose.h_m,
                                                                     pose.yaw_deg, pose.pitch_deg, pose.roll_deg)),
                         tuple(float(np.asarray(g)[frame, i]) for g in pose.gimbal_deg))
        tracker = MoverTracker(type(r)(float(np.ravel(value)[i] if np.ndim(value) else value)), budget=budget)
        u, v = float(m["u_px"][frame][i]), float(m["v_px"][frame][i])
        blob = Blobs(0, 0.0, np.array([u]), np.array([v]), np.array([[u - 2, v - 2, u + 2, v + 2]]), np.array([16.0]),
                     np.array([blob_m**2]), np.array([30.0]), np.array([0]), np.array([False]), np.zeros((2, 2)), 1.0)
        tracker.add(blob, sensor, one)
        row = tracker.rows[0]
        off = rng.normal(0.0, blob_m / 4.0, 2)  # the centroid's own error, east and north
        target = p.target_at[frame][i]
        e = enu_error(row["lat_deg"], row["lon_deg"], row["h_m"], target)
        err.append(np.r_[np.ravel(e)[:2] + off, np.ravel(e)[2]])
        c50.append(row["cep50_m"] if row["cep50_m"] is not None else np.nan)
        c90.append(row["ce90_m"] if row["ce90_m"] is not None else np.nan)
        le.append(row["le90_m"] if row["le90_m"] is not None else np.nan)
        keep.append(row["status"] == "OK" and row["nonlinearity"] is not None and row["nonlinearity"] <= 0.1)
    return coverage(f"movers' fixes, {rule} rule" + (f", {blob_m:g} m blobs" if blob_m else ""), np.array(err),
                    np.array(c50), np.array(c90), np.array(le), np.array(keep))


def rls(p: Passes, rule: str):
    """RLS static over each whole pass, with the budget's structure: all passes in one call (the
    targets of :func:`simulate` with a ``spread_deg``, in the ENU frame of one origin), each
    estimate's covariance then turned into its target's own east/north/up."""
    from eoloc.accuracy import locate_with_covariance
    from eoloc.accuracy.cep import cep_zero_mean, error_ellipses
    from eoloc.result import Status
    from eoloc.sequence.rls import rls_static

    sensor, pose, r, budget = eoloc_inputs(p, rule)
    m = p.measured
    fixes, cov = locate_with_covariance(sensor, pose, budget, (m["u_px"], m["v_px"]), r)
    origin = tuple(float(x) for x in p.target.mean(0))
    est = rls_static(fixes, covariance=cov, time_s=p.time_s, origin=origin)
    C = to_local(est.cov_enu, origin, p.target)
    err = enu_error(est.lat_deg, est.lon_deg, est.h_m, p.target)
    e = error_ellipses(C[:, :2, :2])
    keep = (est.status == Status.OK) & np.all(cov.linear(0.1), axis=0)
    le90 = 1.6448536269514722 * np.sqrt(C[:, 2, 2])
    cv = coverage(f"RLS static over {p.time_s.size} frames, {rule} rule", err, cep_zero_mean(e[:, 0], e[:, 1], 0.5),
                  cep_zero_mean(e[:, 0], e[:, 1], 0.9), le90, keep)
    return est.status, cv


def enu_axes(lat, lon) -> np.ndarray:
    """(..., 3, 3) columns east, north, up in ECEF (the oracle's N, E, D rearranged)."""
    R = O.r_ecef_ned(lat, lon)
    return np.stack([R[..., 1], R[..., 0], -R[..., 2]], -1)


def to_local(cov: np.ndarray, origin, target: np.ndarray) -> np.ndarray:
    """Covariances (K, n, n) (n = 2 or 3) in the ENU axes at ``origin`` turned into the ENU axes at
    each target (K, 3)."""
    turn = np.swapaxes(enu_axes(target[:, 0], target[:, 1]), -1, -2) @ enu_axes(origin[0], origin[1])
    n = cov.shape[-1]
    turn = turn[:, :n, :n] if n == 3 else turn[:, :2, :2]
    return turn @ cov @ np.swapaxes(turn, -1, -2)


def kalman(p: Passes, rule: str):
    """Kalman tracks of moving targets (one per pass, by id) with the budget's structure (biases
    and Gauss–Markov errors considered): the last filtered position against the target's."""
    from eoloc.accuracy import locate_with_covariance
    from eoloc.accuracy.cep import cep_zero_mean, error_ellipses
    from eoloc.sequence.track import track_fixes

    sensor, pose, r, budget = eoloc_inputs(p, rule)
    m = p.measured
    fixes, cov = locate_with_covariance(sensor, pose, budget, (m["u_px"], m["v_px"]), r)
    f_n, k = fixes.status.shape
    ids = np.broadcast_to(np.arange(k).astype(str), (f_n, k))
    times = np.broadcast_to(p.time_s[:, None], (f_n, k))
    origin = tuple(float(x) for x in p.target.mean(0))
    ts = track_fixes(times.ravel(), fixes.flat(), None, ids.ravel(), covariance=cov, origin=origin,
                     include_tentative=True)
    lat, lon, h = (np.full(k, np.nan) for _ in range(3))
    P = np.full((k, 2, 2), np.nan)
    for tr in ts.tracks:
        j = int(tr.track_id)
        if tr.time_s[-1] != p.time_s[-1]:
            continue
        la, lo, hh = ts.geodetic(tr)
        lat[j], lon[j], h[j] = la[-1], lo[-1], hh[-1]
        P[j] = tr.cov[-1][:2, :2]
    err = enu_error(lat, lon, h, p.target)
    C = to_local(P, origin, p.target)
    e = error_ellipses(C)
    keep = np.isfinite(lat) & np.all(cov.linear(0.1), axis=0)
    return coverage(f"Kalman tracks over {f_n} frames, {rule} rule", err, cep_zero_mean(e[:, 0], e[:, 1], 0.5),
                    cep_zero_mean(e[:, 0], e[:, 1], 0.9), None, keep)


def cot(fixes, cov, p: Passes, rule: str):
    """The CoT events of the per-fix path as a receiver parses them: 2.1460 ce and 1.6449 le."""

    from eoloc.accuracy.covariance import covariance_columns
    from eoloc.io.cot import cot_event
    from eoloc.io.export import fix_records

    n = fixes.lat_deg.size
    extra = {"target_id": np.arange(n).astype(str), "time_s": np.zeros(n)}
    rows = fix_records(fixes, extra, covariance_columns(cov, fixes.ok)).rows()
    ce, le = np.full(n, np.nan), np.full(n, np.nan)
    for i, row in enumerate(rows):
        if row["status"] == "OK":
            pt = cot_event(row).find("point")
            ce[i], le[i] = float(pt.get("ce")), float(pt.get("le"))
    err = enu_error(fixes.lat_deg, fixes.lon_deg, fixes.h_m, p.target_at[-1])
    keep = fixes.ok & cov.linear(0.1)
    sigma_c = ce  # the receiver's circular normal: P(r < k ce) = 1 - exp(-k^2 / 2)
    return coverage(f"CoT ce/le as parsed, {rule} rule", err, sigma_c * math.sqrt(2 * math.log(2)),
                    sigma_c * math.sqrt(-2 * math.log(0.1)), 1.6448536269514722 * le, keep)


def monte_carlo(p: Passes, rule: str, n: int = 2000):
    """Monte Carlo about each pass's first frame as the nominal observation: its empirical CEP50 /
    CE90 / LE90 about the error-free fix, against the fix eoloc makes from that frame's telemetry
    (errors drawn here, not by eoloc) and the truth."""
    import eoloc
    from eoloc.accuracy import Scenario
    from eoloc.accuracy import monte_carlo as run

    sensor, pose, r, budget = eoloc_inputs(p, rule)
    m = p.measured
    k = p.target.shape[0]
    cep50, ce90, le90 = (np.full(k, np.nan) for _ in range(3))
    t = p.true_pose
    fixes = eoloc.locate(sensor, type(pose)(*(np.asarray(a)[0] for a in (pose.lat_deg, pose.lon_deg, pose.h_m,
                                                                         pose.yaw_deg, pose.pitch_deg, pose.roll_deg)),
                                            tuple(np.asarray(g)[0] for g in pose.gimbal_deg)),
                         type(r)(np.asarray(m["height_m" if rule == "height" else "range_m"])[0]),
                         (m["u_px"][0], m["v_px"][0]))
    for j in range(k):
        nominal = type(pose)(t["lat_deg"][0, j], t["lon_deg"][0, j], t["h_m"][0, j], t["yaw_deg"][0, j],
                             t["pitch_deg"][0, j], t["roll_deg"][0, j], (t["az_deg"][0, j], t["el_deg"][0, j]))
        value = p.target_at[0, j, 2] if rule == "height" else p.true_range_m[0, j]
        scn = Scenario("coverage", sensor, nominal, budget, type(r)(value),
                       np.array([[p.true_pixel[0][0, j], p.true_pixel[1][0, j]]]))
        st = run(scn, n, seed=j).stats[0]
        cep50[j], ce90[j], le90[j] = st.cep50, st.ce90, st.le90
    err = enu_error(fixes.lat_deg, fixes.lon_deg, fixes.h_m, p.target_at[0])
    return coverage(f"Monte Carlo ({n:,} samples each), {rule} rule", err, cep50, ce90, le90,
                    fixes.ok & np.isfinite(ce90))


def triangulation(rng: np.random.Generator, k: int, rays: int = 8, sigma_rad: float = 2e-4):
    """Triangulation of K targets from ``rays`` cameras each, every ray's direction off by an
    angular error of ``sigma_rad`` per axis: its covariance from its own geometry."""
    from eoloc.rules.multiview import triangulate
    from eoloc.sensor.model import Rays

    lat_t, lon_t, h_t = rng.uniform(-60, 60, k), rng.uniform(-180, 180, k), rng.uniform(0, 2000, k)
    T = O.to_ecef(lat_t, lon_t, h_t)
    est = np.full((k, 3), np.nan)
    C = np.full((k, 3, 3), np.nan)
    for j in range(k):
        R = O.r_ecef_ned(lat_t[j], lon_t[j])
        bearing = np.radians(rng.uniform(0, 360) + np.linspace(0, rng.uniform(30, 120), rays))
        dist = rng.uniform(3000, 9000, rays)
        ned = np.stack([dist * np.cos(bearing), dist * np.sin(bearing), -rng.uniform(1500, 5000, rays)], -1)
        o = T[j] + ned @ R.T
        d = (T[j] - o) / np.linalg.norm(T[j] - o, axis=1, keepdims=True)
        a = np.cross(d, [0.0, 0.0, 1.0])
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b = np.cross(d, a)
        e = rng.normal(0.0, sigma_rad, (rays, 2))
        d = d + e[:, :1] * a + e[:, 1:] * b
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        tri = triangulate(Rays(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2]), sigma_rad)
        est[j] = (tri.lat_deg, tri.lon_deg, tri.h_m)
        C[j] = tri.cov_enu
    from eoloc.accuracy.cep import cep_zero_mean, error_ellipses

    err = enu_error(est[:, 0], est[:, 1], est[:, 2], np.stack([lat_t, lon_t, h_t], -1))
    el = error_ellipses(C[:, :2, :2])
    return coverage(f"triangulation, {rays} rays", err, cep_zero_mean(el[:, 0], el[:, 1], 0.5),
                    cep_zero_mean(el[:, 0], el[:, 1], 0.9), 1.6448536269514722 * np.sqrt(C[:, 2, 2]),
                    np.isfinite(est[:, 0]))
