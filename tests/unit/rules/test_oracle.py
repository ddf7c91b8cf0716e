"""The hostile-input oracle in CI: every answer of every stop rule, on both backends, checked by
``oracle_lib`` (scipy Rotation + pyproj + pymap3d, no eoloc code). Seeded; the same checks run at
10^6 cases from ``python bench/oracle.py``. Each test also asserts that the hostile mix really
produced the statuses it is meant to exercise, so a run that located nothing cannot pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import oracle_lib as O
import pytest

import eoloc
from eoloc.rules.multiview import triangulate

TILE = Path(eoloc.__file__).parent / "data" / "demo" / "mountain" / "longs_peak_srtmgl3.tif"


def _run(method: str, n: int, seed: int, *args) -> O.Report:
    runner = O.Runner(eoloc)
    getattr(runner, method)(np.random.default_rng(seed), n, *args)
    for rep in runner.reports.values():
        assert rep.n_wrong == 0, f"{rep.line()}\nexamples: {rep.examples}"
    merged = O.Report(method)
    for rep in runner.reports.values():
        merged.merge(rep)
    return merged


def _saw(rep: O.Report, *codes: int) -> None:
    for code in codes:
        assert rep.statuses[code] > 0, f"the hostile mix produced no status {code}: {rep.line()}"


@pytest.mark.parametrize(("method", "n", "seed", "expected"), [
    ("m1", 3000, 11, (O.OK, O.INVALID_INPUT, O.OUT_OF_IMAGE)),
    ("m3", 2500, 12, (O.OK, O.NO_INTERSECTION, O.BELOW_SURFACE, O.INVALID_INPUT, O.OUT_OF_IMAGE)),
    ("m3_tangent", 6000, 13, (O.OK, O.NO_INTERSECTION, O.BELOW_SURFACE)),
    ("m2", 3000, 14, (O.OK, O.NO_INTERSECTION, O.BELOW_SURFACE, O.INVALID_INPUT, O.OUT_OF_IMAGE)),
], ids=["M1 range", "M3 height", "M3 exact-tangent family", "M2 flat ground"])
def test_oracle_every_answer_on_hostile_input(method, n, seed, expected):
    _saw(_run(method, n, seed), *expected)


def test_oracle_M4_real_tile_with_voids_and_every_edge():
    z, lat0, lon0, dlat, dlon = O.real_tile(TILE, voids=12, seed=0)
    dem = eoloc.DEM.from_array(z, lat0=lat0, lon0=lon0, dlat=dlat, dlon=dlon)
    rep = _run("m4", 2000, 15, dem, O.Grid(z, lat0, lon0, dlat, dlon))
    _saw(rep, O.OK, O.NO_INTERSECTION, O.OUT_OF_COVERAGE, O.DEM_VOID, O.BELOW_SURFACE, O.INVALID_INPUT)


def test_oracle_multiview():
    rep = _run("multiview", 800, 16, triangulate)
    _saw(rep, O.OK, O.DEGENERATE)


class _HalfWrong:
    """eoloc with its locate functions wrapped so that every other OK answer becomes ``status``
    with NaN coordinates: a defect both backends would share, which only the oracle's own
    judgement of each status can see (issue 55's experiment)."""

    WRAPPED = ("locate_range", "locate_ellipsoid", "stop_at_ellipsoid", "locate_dem")

    def __init__(self, status: int) -> None:
        self.status = status
        self.turned = 0

    def __getattr__(self, name):
        fn = getattr(eoloc, name)
        if name not in self.WRAPPED:
            return fn

        def wrapped(*args, **kwargs):
            f = fn(*args, **kwargs)
            arrays = [np.array(np.broadcast_to(a, np.shape(f.status)), dtype=float) for a in
                      (f.lat_deg, f.lon_deg, f.h_m, f.range_m)]
            st = np.array(f.status, copy=True)
            flat = st.reshape(-1)
            turn = np.flatnonzero(flat == 0)[::2]
            flat[turn] = self.status
            for a in arrays:
                a.reshape(-1)[turn] = np.nan
            self.turned += turn.size
            return eoloc.Fixes(*arrays, st)

        return wrapped


@pytest.mark.parametrize(("method", "status"), [("m1", O.NO_INTERSECTION), ("m3", O.OUT_OF_COVERAGE),
                                                ("m4", O.NO_INTERSECTION)], ids=["M1", "M3", "M4"])
def test_oracle_judges_every_status_a_shared_defect_is_seen(method, status):
    """Half of the OK answers turned into a plausible failure on both backends alike: the oracle
    must report them (M1 "NO_INTERSECTION" at a valid range, M3 "OUT_OF_COVERAGE" on an
    ellipsoid, M4 "NO_INTERSECTION" for rays its own walk sees cross the terrain)."""
    fake = _HalfWrong(status)
    runner = O.Runner(fake, backends=["numpy"])
    args = ()
    if method == "m4":
        z, lat0, lon0, dlat, dlon = O.real_tile(TILE, voids=12, seed=0)
        args = (eoloc.DEM.from_array(z, lat0=lat0, lon0=lon0, dlat=dlat, dlon=dlon), O.Grid(z, lat0, lon0, dlat, dlon))
    getattr(runner, method)(np.random.default_rng(55), 600, *args)
    wrong = sum(rep.n_wrong for rep in runner.reports.values())
    assert fake.turned > 100
    assert wrong >= 0.9 * fake.turned, [rep.line() for rep in runner.reports.values()]
