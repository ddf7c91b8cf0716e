"""Learned compensation ([P]) in real time, and orthorectification (M5).

Per-target cost of applying a compensation model (features from the pose chain + prediction +
range flags) next to the fix itself, with a gradient-boosted tree ensemble (scikit-learn
HistGradientBoostingRegressor, the peer family) predicting the same errors in the same run.
(Orthorectification moved to bench/bench_ortho.py, with orthority and GDAL's GCP warp as peers.)

    python bench/bench_compensation.py [--n 1000000]
"""

from __future__ import annotations

import numpy as np

from _common import best_time, row, script
from eoloc import AzElGimbal, Camera, OnDEM, Pose, SensorModel, locate_ellipsoid
from eoloc.accuracy import compensation as C
from eoloc.accuracy.calflight import calibration_flights


def main(n: int) -> list[str]:
    sensor = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())
    tr = calibration_flights(sensor, n_flights=8, looks_per_flight=400, seed=0)
    obs = C.locate_observations(sensor, tr.columns, OnDEM(tr.dem))
    model = C.fit(obs.features, obs.errors_enu, groups=obs.groups)
    rng = np.random.default_rng(1)
    pose = Pose(35.1 + rng.uniform(-0.1, 0.1, n), 112.7, 400.0 + rng.uniform(1000, 4500, n), rng.uniform(0, 360, n),
                1.0, 0.0, (rng.uniform(-180, 180, n), rng.uniform(-88, -15, n)))
    fixes = locate_ellipsoid(sensor, pose, 400.0)
    t_fix = best_time(lambda: locate_ellipsoid(sensor, pose, 400.0), repeat=3)
    t_feat = best_time(lambda: C.error_features(sensor, pose, fixes), repeat=3)
    feats = C.error_features(sensor, pose, fixes)
    t_pred = best_time(lambda: model.predict(feats), repeat=3)
    t_all = best_time(lambda: C.compensate(model, sensor, pose, fixes), repeat=3)

    from sklearn.ensemble import HistGradientBoostingRegressor

    def tree_x(f):
        az, br = np.radians(f.azimuth_deg), np.radians(f.bearing_deg)
        return np.c_[f.oblique_deg, f.height_m, np.cos(az), np.sin(az), np.cos(br), np.sin(br)]

    regs = [HistGradientBoostingRegressor(max_iter=300, random_state=0).fit(tree_x(obs.features), obs.errors_enu[:, c])
            for c in range(2)]
    X = tree_x(feats)
    t_tree = best_time(lambda: [r.predict(X) for r in regs], repeat=3)
    ns = 1e9 / n
    lines = [
        row(f"compensation predict + flags, {n:.0e} fixes", f"{t_pred * ns:.0f} ns/fix",
            f"trees predict {t_tree * ns:.0f} ns/fix", t_tree / t_pred),
        row(f"features + predict + corrected fix (compensate), {n:.0e}",
            f"{t_all * ns:.0f} ns/fix ({t_all / t_fix:.1f}x the fix alone)",
            f"the fix itself (M3) {t_fix * ns:.0f} ns/fix", None),
        row("  of which features (rays again, NED, heights)", f"{t_feat * ns:.0f} ns/fix", "", None),
    ]
    return lines


if __name__ == "__main__":
    script(main, __doc__)
