"""The hostile-input oracle in CI: every answer of every stop rule, on both backends, checked by
``oracle_lib`` (scipy Rotation + pyproj + pymap3d, no eoloc code). Seeded; the same checks run at
10^6 cases from ``python bench/oracle.py``. Each test also asserts that the hostile mix really
produced the statuses it is meant to exercise, so a run that located nothing cannot pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import eoloc
import oracle_lib as O
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
