"""Shared fixtures: every test that computes runs on both backends unless it says otherwise."""

from __future__ import annotations

import pytest

import eoloc


@pytest.fixture(params=eoloc.available_backends())
def backend(request):
    """Run the test under each available backend (numba and numpy)."""
    with eoloc.use_backend(request.param):
        yield request.param
