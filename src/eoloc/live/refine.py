"""Targets refined across packets, as they arrive: each VMTI target id of a stream is filtered by
the same steps as the batch commands — recursive least squares (:class:`eoloc.sequence.rls.RLSState`,
as `eoloc track --static`) and the constant-velocity Kalman filter
(:class:`eoloc.sequence.track.Tracker`, as `eoloc track`) — one packet at a time. The RLS step
takes all the targets of a packet in one vectorised update (each target in the ENU frame of its
own first fix, as the batch); the Kalman step runs only when a model needs it.

Each target's estimate says which model it is. ``model="static"`` (the default): RLS. With an
error budget its uncertainty is that of the budget's sources over the packets so far — biases
kept whole, noise averaged down, Gauss–Markov errors by their correlation in time
(:class:`eoloc.sequence.rls.RLSState`) — and a target whose fixes do not agree with one point
(the chi-square test of :meth:`~eoloc.sequence.rls.RLSState.consistent`: it moves, or its fixes
jump between a summit and the slope behind it) gets status INCONSISTENT and no point.
``"moving"``: the Kalman track, each fix weighed by its noise and the budget's biases and
Gauss–Markov errors carried as consider parameters (:mod:`eoloc.sequence.track`). ``"auto"``: the
Kalman track once it is confirmed and its speed is significant (over 3 sigma and over
``MOVING_MPS``), else RLS. A bias that drifts with the geometry (attitude errors as the aircraft
turns) makes the fixes of a fixed target walk too, and "auto" then calls it moving: that is why
static is the default. Without an error budget the fixes are weighted alike (as if each had
``UNWEIGHTED_SIGMA_M``, which also sets the speed's sigma for the moving test) and no uncertainty
is claimed (null CEP), as for the fixes themselves.

A packet late within its stream is not filtered (the filters only go forward in time); a stream
whose time goes back (an encoder restart) starts its filters again.
"""

from __future__ import annotations

import math

import numpy as np

from .. import geodesy
from ..accuracy.cep import cep_ce_le
from ..result import Status
from ..sequence.rls import SCATTER_LIMIT, RLSState, random_part, scatter_inflation, weights
from .update import PacketUpdate

MODELS = ("static", "moving", "auto")
MOVING_MPS = 1.0  # below this a target is static whatever its sigma says
UNWEIGHTED_SIGMA_M = 10.0  # the weight of a fix without a covariance (all alike: only ratios matter)


class _Stream:
    def __init__(self, forgetting: float, tracker) -> None:
        self.slot: dict[str, int] = {}  # target id -> its place in the arrays below
        self.origin_ecef = np.zeros((0, 3))  # each target's RLS frame: ENU at its first fix (origin, ECEF m)
        self.R_ecef_enu = np.zeros((0, 3, 3))  # and axes
        self.first_sigma_h = np.zeros(0)
        self.rls = RLSState.empty(0, forgetting)
        self.tracker = tracker  # a sequence.track.Tracker in one ENU frame, or None (static)
        self.track_origin: tuple[float, float, float] | None = None
        self.time_s = -math.inf


class TargetFilters:
    """Feed each :class:`PacketUpdate` to :meth:`update`; it fills ``update.estimates``."""

    def __init__(self, model: str = "static", config=None, forgetting: float = 1.0) -> None:
        if model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        self.model, self.config, self.forgetting = model, config, forgetting
        self.streams: dict[str, _Stream] = {}
        self.restarts = 0

    def _new_stream(self) -> _Stream:
        tracker = None
        if self.model != "static":
            from ..sequence.track import Tracker, TrackerConfig

            tracker = Tracker(self.config or TrackerConfig(), associate=False)
        return _Stream(self.forgetting, tracker)

    def update(self, u: PacketUpdate) -> list[dict]:
        rows = u.fixes
        idx = np.array([i for i, r in enumerate(rows) if r["status"] == "OK"], dtype=np.intp)
        if u.late or idx.size == 0 or not math.isfinite(u.time_s):
            return u.estimates
        st = self.streams.get(u.key)
        if st is not None and u.time_s < st.time_s:
            self.restarts += 1
            st = None
        if st is None:
            st = self.streams[u.key] = self._new_stream()
        st.time_s = u.time_s
        known = u.cov_enu is not None
        R = u.cov_enu[idx] if known else np.broadcast_to(UNWEIGHTED_SIGMA_M**2 * np.eye(3), (idx.size, 3, 3))
        good = np.all(np.isfinite(R), axis=(-1, -2))  # a fix whose covariance is unknown does not enter
        idx, R = idx[good], R[good]
        effects = None if u.effects is None else u.effects[idx]
        if idx.size == 0:
            return u.estimates
        lat, lon, h = (np.array([rows[i][k] for i in idx], dtype=np.float64) for k in ("lat_deg", "lon_deg", "h_m"))
        ids = np.array([str(rows[i].get("target_id")) for i in idx])
        new = [t for t in dict.fromkeys(ids) if t not in st.slot]
        if new:
            first = np.array([int(np.flatnonzero(ids == t)[0]) for t in new])
            for t in new:
                st.slot[t] = len(st.slot)
            o = np.stack(geodesy.geodetic_to_ecef(lat[first], lon[first], h[first]), -1)
            st.origin_ecef = np.concatenate([st.origin_ecef, o])
            st.R_ecef_enu = np.concatenate([st.R_ecef_enu, geodesy.R_ecef_enu(lat[first], lon[first])])
            st.first_sigma_h = np.concatenate([st.first_sigma_h, np.sqrt(R[first, 0, 0] + R[first, 1, 1])])
            st.rls.grow(len(new))
        k = np.array([st.slot[t] for t in ids])
        p = np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1)
        n_slots = len(st.slot)
        z = np.zeros((n_slots, 3))
        z[k] = geodesy.to_frame(p, st.origin_ecef[k], st.R_ecef_enu[k])  # ENU at each target's first fix
        use = np.zeros(n_slots, dtype=bool)
        use[k] = True
        RK = np.broadcast_to(np.eye(3), (n_slots, 3, 3)).copy()
        if effects is None:
            RK[k] = R
            st.rls.update(z, RK, weights(RK, use), use)
        else:  # the error structure: each fix's covariance and source effects in its target's frame
            turn = geodesy.enu_turn(st.R_ecef_enu[k], lat, lon)
            a = np.zeros((n_slots, 3, u.tau_s.size))
            a[k] = turn @ np.nan_to_num(effects)
            RK[k] = turn @ R @ np.swapaxes(turn, -1, -2)
            st.rls.update(z, RK, weights(random_part(a, u.tau_s, RK), use), use, a=a, tau_s=u.tau_s, time_s=u.time_s)
        moving = np.zeros(idx.size, dtype=bool)
        kalman = None
        if st.tracker is not None:
            kalman = self._track(st, u, p, R, ids, lat, lon, effects)
            moving = kalman["moving"] if self.model == "auto" else np.ones(idx.size, dtype=bool)
        u.estimates += self._static(u, st, k[~moving], ids[~moving], known)
        if kalman is not None and moving.any():
            u.estimates += self._moving(u, st, kalman, moving, ids, known)
        return u.estimates

    def _static(self, u: PacketUpdate, st: _Stream, k: np.ndarray, ids: np.ndarray, known: bool) -> list[dict]:
        if k.size == 0:
            return []
        rls = st.rls
        cov = rls.covariance()[k]
        ratio = rls.scatter_ratio()[k]
        agree = rls.consistent()[k] if known else np.ones(k.size, dtype=bool)
        e = geodesy.from_frame(rls.x[k], st.origin_ecef[k], st.R_ecef_enu[k])
        lat, lon, h = geodesy.ecef_to_geodetic(e[:, 0], e[:, 1], e[:, 2])
        spread = cep_ce_le(cov)
        inflate = np.ones(k.size)
        if not rls.structured:  # a covariance without its structure: the scatter widens the CEP
            mean_sigma = np.mean(np.sqrt(np.diagonal(cov[:, :2, :2], axis1=-2, axis2=-1)), axis=-1)
            inflate = scatter_inflation(ratio, st.first_sigma_h[k], mean_sigma)
        out = []
        for j, tid in enumerate(ids.tolist()):
            r = float(ratio[j])
            props = {"model": "static (RLS)", "status": "OK" if agree[j] else Status.INCONSISTENT.name,
                     "n_fixes": int(rls.n[k[j]]), "scatter_ratio": r if math.isfinite(r) else None}
            if not agree[j]:
                props["reason"] = (f"the fixes scatter {r:.1f}x more than their uncertainty allows: "
                                   + Status.INCONSISTENT.explanation)
                out.append(_estimate(u, tid, None, None, None, props))
                continue
            if known:
                props |= {key: _finite(v[j] * (1.0 if key == "le90_m" else inflate[j])) for key, v in spread.items()}
            else:
                props["cep50_m"] = None
            if inflate[j] > 1.0:
                props["warning"] = (f"the fixes scatter {r:.1f}x more than their sigma allows "
                                    f"(> {SCATTER_LIMIT:g}): the target moves, or the sigma is optimistic; the "
                                    "uncertainty is their scatter")
            out.append(_estimate(u, tid, float(lon[j]), float(lat[j]), float(h[j]), props))
        return out

    def _track(self, st: _Stream, u: PacketUpdate, p: np.ndarray, R: np.ndarray, ids: np.ndarray, lat: np.ndarray,
               lon: np.ndarray, effects: np.ndarray | None) -> dict:
        """One Kalman frame for the packet's targets, in the stream's ENU frame (its first fix);
        with the error structure, each fix weighed by its noise and its other sources considered
        (:func:`eoloc.sequence.track.consider_update`)."""
        if st.track_origin is None:
            st.track_origin = tuple(float(v) for v in geodesy.ecef_to_geodetic(*p[0]))
        z = geodesy.ecef_to_enu(p, *st.track_origin)
        A = tau = None
        Rh = R[:, :2, :2]
        if effects is not None:
            turn = geodesy.enu_turn(geodesy.R_ecef_enu(*st.track_origin[:2]), lat, lon)
            a = (turn @ np.nan_to_num(effects))[:, :2]
            noise = u.tau_s == 0
            Rh = a[..., noise] @ np.swapaxes(a[..., noise], -1, -2)
            A, tau = a[..., ~noise], u.tau_s[~noise]
        st.tracker.frame(u.time_s, np.arange(len(ids)), z, Rh, ids, A=A, tau_s=tau)
        lives = [st.tracker.live[tid] for tid in ids]
        x = np.array([lv.x for lv in lives])
        P = np.array([lv.P for lv in lives])
        speed = np.hypot(x[:, 2], x[:, 3])
        g = x[:, 2:] / np.maximum(speed, 1e-300)[:, None]
        speed_sigma = np.where(speed > 0, np.sqrt(np.einsum("ni,nij,nj->n", g, P[:, 2:, 2:], g)), np.nan)
        confirmed = np.array([lv.track.confirmed for lv in lives])
        return {"z": z, "x": x, "P": P, "speed": speed, "speed_sigma": speed_sigma, "hits": [lv.hits for lv in lives],
                "moving": confirmed & (speed > MOVING_MPS) & (speed > 3.0 * np.nan_to_num(speed_sigma, nan=np.inf))}

    def _moving(self, u: PacketUpdate, st: _Stream, kal: dict, moving: np.ndarray, ids: np.ndarray,
                known: bool) -> list[dict]:
        x, P, speed, speed_sigma = (kal[k][moving] for k in ("x", "P", "speed", "speed_sigma"))
        e = geodesy.enu_to_ecef(np.c_[x[:, 0], x[:, 1], kal["z"][moving, 2]], *st.track_origin)
        lat, lon, h = geodesy.ecef_to_geodetic(e[:, 0], e[:, 1], e[:, 2])
        C = np.zeros((len(x), 3, 3))
        C[:, :2, :2] = P[:, :2, :2]
        spread = cep_ce_le(C, vertical=False)
        heading = np.degrees(np.arctan2(x[:, 2], x[:, 3])) % 360.0
        hits = np.asarray(kal["hits"])[moving]
        out = []
        for j, tid in enumerate(ids[moving]):
            props = {"model": "moving (Kalman)", "status": "OK", "n_fixes": int(hits[j]), "speed_mps": float(speed[j]),
                     "heading_deg": float(heading[j]), "speed_sigma_mps": _finite(speed_sigma[j]) if known else None,
                     **{key: _finite(v[j]) if known else None for key, v in spread.items()}}
            out.append(_estimate(u, tid, float(lon[j]), float(lat[j]), float(h[j]), props))
        return out


def _finite(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _estimate(u: PacketUpdate, tid: str, lon: float | None, lat: float | None, h: float | None, props: dict) -> dict:
    geometry = None if lon is None else {"type": "Point", "coordinates": [lon, lat, h]}
    return {"type": "Feature", "geometry": geometry,
            "properties": {"what": "estimate", "stream": u.stream, "packet": u.index, "time_utc": u.time_utc,
                           "target_id": tid, **props}}
