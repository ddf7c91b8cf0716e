"""Backend selection and the one dispatcher every public function goes through.

``numba`` (compiled, vectorised loops) or ``numpy`` (chunked array code, the reference path); both
run the same kernels from :mod:`eoloc._kernels`. They differ only in the last bits of sine, cosine
and atan2 (numba evaluates them by the fdlibm polynomials of ``_kernels``, numpy by its own
ufuncs), so results agree to 1e-8 m, times the geometry's own amplification of a last-bit change
(1/sin of the grazing angle for a ray meeting a surface; tested). ``auto``, the default, is numba
where it is installed. Choose with ``EOLOC_BACKEND`` or :func:`use_backend`.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
from collections.abc import Iterator

import numpy as np

from . import _kernels

BACKENDS = ("numba", "numpy")
_state = {"name": "auto", "resolved": ""}


@functools.cache
def available_backends() -> tuple[str, ...]:
    """The backends that can run here (numba only where it is installed)."""
    has_numba = importlib.util.find_spec("numba") is not None
    return BACKENDS if has_numba else ("numpy",)


def get_backend() -> str:
    """The backend in force for scalar and small work: 'numba' or 'numpy'."""
    return _state["resolved"] or _resolve()


def _resolve() -> str:
    name = _state["name"]
    if name == "auto":
        name = available_backends()[0]
    elif name not in available_backends():
        raise ValueError(
            f"eoloc backend {name!r} is not available here; choose one of {available_backends()} "
            "(set EOLOC_BACKEND or call eoloc.use_backend)"
        )
    _state["resolved"] = name
    return name


def set_backend(name: str) -> None:
    """Select 'numba', 'numpy' or 'auto' for the rest of the process."""
    name = name.strip().lower()
    if name != "auto" and name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; expected one of {(*BACKENDS, 'auto')}")
    _state["name"], _state["resolved"] = name, ""
    _resolve()


set_backend(os.environ.get("EOLOC_BACKEND", "auto") or "auto")


@contextlib.contextmanager
def use_backend(name: str) -> Iterator[None]:
    """Context manager running the enclosed code on backend ``name``."""
    previous = _state["name"]
    set_backend(name)
    try:
        yield
    finally:
        set_backend(previous)


@contextlib.contextmanager
def few_targets() -> Iterator[None]:
    """For work on a handful of targets (one observation on the command line): the numpy backend
    unless one was chosen explicitly, so that numba and its compiled kernels are never loaded (1.2 s
    of start-up for microseconds of work). The results agree to 1e-8 m either way."""
    if _state["name"] != "auto":
        yield
        return
    with use_backend("numpy"):
        yield


# The numba drivers take a rotation as 9 flat arguments; the numpy kernels take it as one 9-tuple.
_NUMPY_FLAT = {
    "camera_frame": lambda *a: _kernels.camera_frame(int(a[0]), *a[1:4], a[4:13], a[13:22], a[22:31], *a[31:]),
    "ray_direction": lambda *a: _kernels.ray_direction(a[:9], *a[9:]),
    "project_point": lambda *a: _kernels.project_point(a[:9], *a[9:]),
    "flat_target": lambda *a: _kernels.flat_target(a[:9], *a[9:]),
}


# Outputs of each kernel as the drivers see them (rotations flattened); the last of a stop rule
# is its int8 status.
N_OUT = {"geodetic_to_ecef": 3, "ecef_to_geodetic": 3, "camera_frame": 12, "ray_direction": 3,
         "project_point": 3, "stop_at_range": 5, "stop_at_ellipsoid": 5, "flat_target": 5}
STATUS_OUT = frozenset({"stop_at_range", "stop_at_ellipsoid", "flat_target"})
CHUNK = 16384  # numpy path: temporaries of this many elements stay in cache (2x faster than whole arrays)


def run(name: str, *args):
    """Run kernel ``name`` on inputs that broadcast; returns a tuple of arrays of the broadcast shape.

    Both backends see flat inputs: a scalar stays a scalar, an array is broadcast to the full
    shape and flattened (a copy only where it really broadcasts).
    """
    arrays = [np.asarray(a, dtype=np.float64) for a in args]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    n = int(np.prod(shape))
    flat_in = [
        float(a) if a.ndim == 0 else np.ascontiguousarray(np.broadcast_to(a, shape)).reshape(-1)
        for a in arrays
    ]
    outs = [np.empty(n) for _ in range(N_OUT[name])]
    if name in STATUS_OUT:
        outs[-1] = np.empty(n, dtype=np.int8)
    if get_backend() == "numba":
        from . import _nb

        getattr(_nb, name)(n, *flat_in, *outs)
    else:
        _run_numpy(name, n, flat_in, outs)
    return tuple(o.reshape(shape) for o in outs)


def _run_numpy(name: str, n: int, flat_in: list, outs: list[np.ndarray]) -> None:
    fn = _NUMPY_FLAT.get(name) or getattr(_kernels, name)
    with np.errstate(all="ignore"):
        for i in range(0, n, CHUNK):
            part = fn(*(x if isinstance(x, float) else x[i:i + CHUNK] for x in flat_in))
            flat = []
            for o in part:  # numpy kernels return rotations as nested 9-tuples
                flat.extend(o if isinstance(o, tuple) else (o,))
            for out, value in zip(outs, flat, strict=True):
                out[i:i + CHUNK] = value
