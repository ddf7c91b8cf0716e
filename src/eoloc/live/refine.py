"""Targets refined across packets, as they arrive: each VMTI target id of a stream is filtered by
the same steps as the batch commands — recursive least squares (:class:`eoloc.sequence.rls.RLSState`,
as `eoloc track --static`) and the constant-velocity Kalman filter
(:class:`eoloc.sequence.track.Tracker`, as `eoloc track`) — one packet at a time. The RLS step
takes all the targets of a packet in one vectorised update (each target in the ENU frame of its
own first fix, as the batch); the Kalman step runs only when a model needs it.

Each target's estimate says which model it is. ``model="static"`` (the default): RLS. Its
uncertainty keeps the share of the error that does not average out (the RLS module's correlated
fraction) and is widened when the fixes scatter more than their sigma allows
(:func:`eoloc.sequence.rls.scatter_inflation`, with the batch's warning). ``"moving"``: the
Kalman track. ``"auto"``: the Kalman track once it is confirmed and its speed is significant
(over 3 sigma and over ``MOVING_MPS``), else RLS. A bias that drifts with the geometry (attitude
errors as the aircraft turns) makes the fixes of a fixed target walk too, and "auto" then calls
it moving: that is why static is the default. Without an error budget the fixes are weighted
alike (as if each had ``UNWEIGHTED_SIGMA_M``, which also sets the speed's sigma for the moving
test) and no uncertainty is claimed (null CEP), as for the fixes themselves.

A packet late within its stream is not filtered (the filters only go forward in time); a stream
whose time goes back (an encoder restart) starts its filters again.
"""

from __future__ import annotations

import math

import numpy as np

from .. import geodesy
from ..accuracy.cep import cep_zero_mean, error_ellipses
from ..sequence.rls import SCATTER_LIMIT, RLSState, scatter_inflation, weights
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
        RK = np.broadcast_to(np.eye(3), (n_slots, 3, 3)).copy()
        RK[k] = R
        use = np.zeros(n_slots, dtype=bool)
        use[k] = True
        st.rls.update(z, RK, weights(RK, use), use)
        moving = np.zeros(idx.size, dtype=bool)
        kalman = None
        if st.tracker is not None:
            kalman = self._track(st, u.time_s, p, R, ids, known)
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
        e = geodesy.from_frame(rls.x[k], st.origin_ecef[k], st.R_ecef_enu[k])
        lat, lon, h = geodesy.ecef_to_geodetic(e[:, 0], e[:, 1], e[:, 2])
        sig = error_ellipses(cov[:, :2, :2])
        cep = cep_zero_mean(sig[:, 0], sig[:, 1], 0.5)
        mean_sigma = np.mean(np.sqrt(np.diagonal(cov[:, :2, :2], axis1=-2, axis2=-1)), axis=-1)
        inflate = scatter_inflation(ratio, st.first_sigma_h[k], mean_sigma)
        cep = np.where(np.isfinite(cep * inflate), cep * inflate, np.nan)
        columns = zip(ids.tolist(), lon.tolist(), lat.tolist(), h.tolist(), rls.n[k].tolist(), ratio.tolist(),
                      cep.tolist(), inflate.tolist(), strict=True)
        out = []
        for tid, lo, la, hh, n, r, c, wide in columns:
            props = {"model": "static (RLS)", "n_fixes": n, "scatter_ratio": r if math.isfinite(r) else None,
                     "cep50_m": c if known and math.isfinite(c) else None}
            if wide > 1.0:
                props["warning"] = (f"the fixes scatter {r:.1f}x more than their sigma allows "
                                    f"(> {SCATTER_LIMIT:g}): the target moves, or the sigma is optimistic; the "
                                    "uncertainty is their scatter")
            out.append(_estimate(u, tid, lo, la, hh, props))
        return out

    def _track(self, st: _Stream, t: float, p: np.ndarray, R: np.ndarray, ids: np.ndarray, known: bool) -> dict:
        """One Kalman frame for the packet's targets, in the stream's ENU frame (its first fix)."""
        if st.track_origin is None:
            st.track_origin = tuple(float(v) for v in geodesy.ecef_to_geodetic(*p[0]))
        z = geodesy.ecef_to_enu(p, *st.track_origin)
        st.tracker.frame(t, np.arange(len(ids)), z, R[:, :2, :2], ids)
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
        sig = error_ellipses(P[:, :2, :2])
        cep = cep_zero_mean(sig[:, 0], sig[:, 1], 0.5)
        heading = np.degrees(np.arctan2(x[:, 2], x[:, 3])) % 360.0
        hits = np.asarray(kal["hits"])[moving]
        out = []
        for j, tid in enumerate(ids[moving]):
            props = {"model": "moving (Kalman)", "n_fixes": int(hits[j]), "speed_mps": float(speed[j]),
                     "heading_deg": float(heading[j]), "speed_sigma_mps": _finite(speed_sigma[j]) if known else None,
                     "cep50_m": _finite(cep[j]) if known else None}
            out.append(_estimate(u, tid, float(lon[j]), float(lat[j]), float(h[j]), props))
        return out


def _finite(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _estimate(u: PacketUpdate, tid: str, lon: float, lat: float, h: float, props: dict) -> dict:
    return {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, h]},
            "properties": {"what": "estimate", "stream": u.stream, "packet": u.index, "time_utc": u.time_utc,
                           "target_id": tid, **props}}
