"""[P]'s learned compensation on synthetic calibration flights: the per-band table (SPEC §4.3).

    .venv/bin/python examples/compensation_study.py [--flights 8] [--test-flights 4] [--looks 400]

Trains on one set of flights and tests on flights drawn with another seed (their own INS
alignments, GPS biases and noise), both located on the ground station's DEM; prints CEP50 by
oblique band before and after for [P]'s three features, with the look bearing, and a
gradient-boosted tree ensemble; then the held-out-band cross-validation (extrapolation) and a
control with no installation error at all (nothing to learn: the model must cost nothing).
"""

from __future__ import annotations

import argparse

import numpy as np

from eoloc import AzElGimbal, Camera, OnDEM, SensorModel
from eoloc.accuracy import compensation as C
from eoloc.accuracy.calflight import InstallationErrors, calibration_flights
from eoloc.cli.render import print_bands


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=8)
    ap.add_argument("--test-flights", type=int, default=4)
    ap.add_argument("--looks", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    sensor = SensorModel(Camera.from_focal_mm(50.0, 5.5, 1024, 768), AzElGimbal())
    tr = calibration_flights(sensor, n_flights=a.flights, looks_per_flight=a.looks, seed=a.seed)
    te = calibration_flights(sensor, n_flights=a.test_flights, looks_per_flight=a.looks, seed=a.seed + 1000,
                             first_flight=a.flights)
    o_tr = C.locate_observations(sensor, tr.columns, OnDEM(tr.dem))
    o_te = C.locate_observations(sensor, te.columns, OnDEM(te.dem))
    print(f"{len(tr)} training looks on {a.flights} flights, {len(te)} test looks on {a.test_flights} other flights; "
          f"installation errors {InstallationErrors()}")

    before = o_te.errors_enu[:, :2]
    after = {}
    for fs in C.FEATURE_SETS:
        m = C.fit(o_tr.features, o_tr.errors_enu, feature_set=fs, groups=o_tr.groups)
        after[fs] = before + m.predict(o_te.features).correction_enu[:, :2]
    from sklearn.ensemble import HistGradientBoostingRegressor

    def tree_x(f):
        az, br = np.radians(f.azimuth_deg), np.radians(f.bearing_deg)
        return np.c_[f.oblique_deg, f.height_m, np.cos(az), np.sin(az), np.cos(br), np.sin(br)]

    trees = np.empty_like(before)
    for c in range(2):
        reg = HistGradientBoostingRegressor(max_iter=300, learning_rate=0.08, random_state=0)
        reg.fit(tree_x(o_tr.features), o_tr.errors_enu[:, c])
        trees[:, c] = before[:, c] - reg.predict(tree_x(o_te.features))
    after["trees"] = trees
    print_bands(C.band_table(o_te.features.oblique_deg, before, after), "independent test flights: CEP50 by band")

    cv = C.cross_validate(o_tr.features, o_tr.errors_enu, o_tr.groups, by="band")
    print_bands(cv.table(), "training flights, each oblique band held out in turn (extrapolation)")

    zero = InstallationErrors((0, 0), (0, 0, 0), (0, 0, 0), 0.0, 0.0, 0.0)
    z = calibration_flights(sensor, n_flights=a.flights, looks_per_flight=a.looks, errors=zero, seed=a.seed + 7)
    oz = C.locate_observations(sensor, z.columns, OnDEM(z.dem))
    cv = C.cross_validate(oz.features, oz.errors_enu, oz.groups, by="flight", trees=False)
    print_bands(cv.table(), "control, no installation error (held-out flights): nothing to learn")


if __name__ == "__main__":
    main()
