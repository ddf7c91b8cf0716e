"""Shared fixtures: every test that computes runs on both backends unless it says otherwise.

The test processes load numba up front, as a long-running process does within its first half
second of work: ``auto`` is then numba for every test, whatever ran before it in the worker
(a fresh process rents numpy first: tests/unit/test_geodesy.py tests that in a process of its own)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent / "helpers"))  # the tests' shared helpers: import oracle_lib, served, ...

import eoloc

if "numba" in eoloc.available_backends():
    importlib.import_module("eoloc.kernels.compiled")


@pytest.fixture(params=eoloc.available_backends())
def backend(request):
    """Run the test under each available backend (numba and numpy)."""
    with eoloc.use_backend(request.param):
        yield request.param


# What each marker needs (README "Tests"): the markers follow the folders and what a test calls.
NEEDS = {"tak": "a TAK server (FreeTAKServer and taky, installed by `make test`)",
         "network": "sockets on loopback (UDP, TCP, HTTP servers started by the test)",
         "browser": "Debian's chromium and chromium-driver", "slow": "a minute or more"}


def pytest_collection_modifyitems(items) -> None:
    """Markers by where a test lives and what it calls: integration/live and integration/service
    open sockets (network); the TAK tests start a TAK server (tak); a test that calls the
    browser helpers (chromium, page_state) drives Chromium (browser)."""
    for item in items:
        path = Path(str(item.fspath)).as_posix()
        if "/integration/live/" in path or "/integration/service/" in path:
            item.add_marker(pytest.mark.network)
        if path.endswith(("test_live_tak.py", "test_tak_tls.py")):
            item.add_marker(pytest.mark.tak)
        if _drives_chromium(getattr(item, "function", None), getattr(item, "module", None)):
            item.add_marker(pytest.mark.browser)


def _drives_chromium(fn, module, depth: int = 2) -> bool:
    """Whether ``fn`` calls the browser helpers (chromium, page_state), itself or through the
    functions of its module it calls (two levels down)."""
    code = getattr(fn, "__code__", None)
    if code is None:
        return False
    names = {*code.co_names, *code.co_varnames}
    if {"chromium", "page_state"} & names:
        return True
    return depth > 0 and any(_drives_chromium(getattr(module, n, None), module, depth - 1) for n in code.co_names
                             if callable(getattr(module, n, None)) and n.startswith("_"))
