"""Targets refined across packets, as they arrive: each VMTI target id of a stream is filtered by
the same steps as the batch commands — recursive least squares (:class:`eoloc.sequence.rls.RLSState`,
as `eoloc track --static`) and the constant-velocity Kalman filter
(:class:`eoloc.sequence.track.Tracker`, as `eoloc track`) — one packet at a time.

Each target's estimate says which model it is. With ``model="auto"``: "moving (Kalman)" once its
track is confirmed and its speed is significant (over 3 sigma and over ``MOVING_MPS``), else
"static (RLS)". A bias that drifts with the geometry (attitude errors as the aircraft turns) makes
the fixes of a fixed target walk too, and "auto" then calls it moving: when the targets are known
to be fixed (or known to move), say so with ``model="static"`` (``"moving"``). The static
estimate's uncertainty keeps the share of the error that does not average out (the RLS module's
correlated fraction) and is widened when the fixes scatter more than their sigma allows
(:func:`eoloc.sequence.rls.scatter_inflation`, with the batch's warning). Without an error budget
the fixes are weighted alike (as if each had ``UNWEIGHTED_SIGMA_M``, which also sets the speed's
sigma for the moving test) and no uncertainty is claimed (null CEP), as for the fixes themselves.

A packet late within its stream is not filtered (the filters only go forward in time); a stream
whose time goes back (an encoder restart) starts its filters again.
"""

from __future__ import annotations

import math

import numpy as np

from .. import geodesy
from ..accuracy.cep import cep_zero_mean, error_ellipses
from ..sequence.rls import SCATTER_LIMIT, RLSState, scatter_inflation, weights
from ..sequence.track import Tracker, TrackerConfig
from .update import PacketUpdate

MODELS = ("auto", "static", "moving")
MOVING_MPS = 1.0  # below this a target is static whatever its sigma says
UNWEIGHTED_SIGMA_M = 10.0  # the weight of a fix without a covariance (all alike: only ratios matter)


class _Stream:
    def __init__(self, origin: tuple[float, float, float], config: TrackerConfig) -> None:
        self.origin = origin
        self.tracker = Tracker(config, associate=False)
        self.rls: dict[str, RLSState] = {}
        self.rls_origin: dict[str, tuple[float, float, float]] = {}  # each target's own first fix (as the batch)
        self.first_sigma_h: dict[str, float] = {}
        self.time_s = -math.inf


class TargetFilters:
    """Feed each :class:`PacketUpdate` to :meth:`update`; it fills ``update.estimates``."""

    def __init__(self, model: str = "static", config: TrackerConfig | None = None, forgetting: float = 1.0) -> None:
        if model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        self.model = model
        self.config = config or TrackerConfig()
        self.forgetting = forgetting
        self.streams: dict[str, _Stream] = {}
        self.restarts = 0

    def update(self, u: PacketUpdate) -> list[dict]:
        rows = u.fixes
        ok = np.array([r["status"] == "OK" for r in rows], dtype=bool)
        if u.late or not ok.any() or not math.isfinite(u.time_s):
            return u.estimates
        key = u.key
        st = self.streams.get(key)
        if st is not None and u.time_s < st.time_s:
            self.restarts += 1
            st = None
        idx = np.flatnonzero(ok)
        lat, lon, h = (np.array([rows[i][k] for i in idx], dtype=np.float64) for k in ("lat_deg", "lon_deg", "h_m"))
        ids = np.array([str(rows[i].get("target_id")) for i in idx])
        if st is None:
            st = self.streams[key] = _Stream((float(lat[0]), float(lon[0]), float(h[0])), self.config)
        st.time_s = u.time_s
        known = u.cov_enu is not None
        R = u.cov_enu[idx] if known else np.broadcast_to(UNWEIGHTED_SIGMA_M**2 * np.eye(3), (idx.size, 3, 3))
        use = np.all(np.isfinite(R), axis=(-1, -2))
        if not use.all():  # a fix whose covariance is unknown does not enter the filters
            lat, lon, h, ids, R, idx = lat[use], lon[use], h[use], ids[use], R[use], idx[use]
        if idx.size == 0:
            return u.estimates
        z = geodesy.ecef_to_enu(np.stack(geodesy.geodetic_to_ecef(lat, lon, h), -1), *st.origin)
        st.tracker.frame(u.time_s, np.arange(idx.size), z, R[:, :2, :2], ids)
        one = np.ones(1, dtype=bool)
        for j, tid in enumerate(ids):
            state = st.rls.get(tid)
            if state is None:
                state = st.rls[tid] = RLSState.empty(1, self.forgetting)
                st.rls_origin[tid] = (float(lat[j]), float(lon[j]), float(h[j]))
                st.first_sigma_h[tid] = float(np.sqrt(R[j, 0, 0] + R[j, 1, 1]))
            zj = geodesy.ecef_to_enu(np.stack(geodesy.geodetic_to_ecef(lat[j:j + 1], lon[j:j + 1], h[j:j + 1]), -1),
                                     *st.rls_origin[tid])
            state.update(zj, R[j:j + 1], weights(R[j:j + 1], one), one)
            u.estimates.append(self._estimate(u, st, tid, state, float(z[j, 2]), known))
        return u.estimates

    def _estimate(self, u: PacketUpdate, st: _Stream, tid: str, state: RLSState, up_m: float, known: bool) -> dict:
        lv = st.tracker.live[tid]
        speed = float(np.hypot(lv.x[2], lv.x[3]))
        g = lv.x[2:] / max(speed, 1e-300)
        speed_sigma = float(np.sqrt(g @ lv.P[2:, 2:] @ g)) if speed > 0 else math.nan
        moving = self.model == "moving" or (self.model == "auto" and lv.track.confirmed and speed > MOVING_MPS
                                             and speed > 3.0 * speed_sigma)
        props = {"what": "estimate", "stream": u.stream, "packet": u.index, "time_utc": u.time_utc,
                 "target_id": tid, "n_fixes": int(lv.hits if moving else state.n[0])}
        if moving:
            origin = st.origin
            enu = np.array([[lv.x[0], lv.x[1], up_m]])
            cov_h = lv.P[:2, :2]
            heading = math.degrees(math.atan2(lv.x[2], lv.x[3])) % 360.0
            props |= {"model": "moving (Kalman)", "speed_mps": speed, "heading_deg": heading,
                      "speed_sigma_mps": speed_sigma if known else None}
            inflate = 1.0
        else:
            origin = st.rls_origin[tid]
            enu = state.x
            cov = state.covariance()[0]
            cov_h = cov[:2, :2]
            ratio = float(state.scatter_ratio()[0])
            inflate = scatter_inflation(ratio, st.first_sigma_h[tid], float(np.mean(np.sqrt(np.diag(cov_h)))))
            props |= {"model": "static (RLS)", "scatter_ratio": ratio if math.isfinite(ratio) else None,
                      "speed_mps": speed}
            if inflate > 1.0:
                props["warning"] = (f"the fixes scatter {ratio:.1f}x more than their sigma allows "
                                    f"(> {SCATTER_LIMIT:g}): the target moves, or the sigma is optimistic; the "
                                    "uncertainty is their scatter")
        p = geodesy.enu_to_ecef(enu, *origin)
        la, lo, hh = (float(np.ravel(a)[0]) for a in geodesy.ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2]))
        cep = None
        if known:
            e = error_ellipses(cov_h[None])[0]
            cep = float(cep_zero_mean(e[0], e[1], 0.5)) * inflate
        props |= {"cep50_m": cep if cep is not None and math.isfinite(cep) else None}
        return {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lo, la, hh]}, "properties": props}
