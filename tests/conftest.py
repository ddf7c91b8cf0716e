"""Shared fixtures: every test that computes runs on both backends unless it says otherwise.

The test processes load numba up front, as a long-running process does within its first half
second of work: ``auto`` is then numba for every test, whatever ran before it in the worker
(a fresh process rents numpy first: tests/test_geodesy.py tests that in a process of its own)."""

from __future__ import annotations

import importlib

import pytest

import eoloc

if "numba" in eoloc.available_backends():
    importlib.import_module("eoloc.kernels.compiled")


@pytest.fixture(params=eoloc.available_backends())
def backend(request):
    """Run the test under each available backend (numba and numpy)."""
    with eoloc.use_backend(request.param):
        yield request.param
