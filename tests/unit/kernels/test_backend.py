"""Backends chosen in one place: eoloc.kernels.backend's backend objects hold each backend's
version of the functions that differ, by the same names; nothing else asks which backend runs."""

from __future__ import annotations

import re

from where import ROOT

from eoloc.kernels.backend import BACKEND_OBJECTS, backend, use_backend

DIFFERING = {"locate_one", "terrain_march", "locate_flat", "frame_pixels", "sample_bands"}


def test_every_backend_has_the_same_functions():
    import eoloc.ground.rectify
    import eoloc.rules.flat
    import eoloc.rules.on_dem

    names = {b: set(obj.functions) for b, obj in BACKEND_OBJECTS.items()}
    assert names["numba"] == names["numpy"] == DIFFERING, names
    for name in eoloc.available_backends():
        with use_backend(name):
            assert backend().name == name and callable(backend().frame_pixels)


def test_no_module_but_the_backend_layer_asks_which_backend_runs():
    src = ROOT / "src" / "eoloc"
    asking = [str(p.relative_to(src)) for p in src.rglob("*.py")
              if p.name != "backend.py" and re.search(r"get_backend\(\)\s*[!=]=", p.read_text(encoding="utf-8"))]
    assert asking == []
