"""Backend selection and the one dispatcher every public function goes through.

``numba`` (compiled, vectorised loops) or ``numpy`` (chunked array code, the reference path); both
run the same kernels from :mod:`eoloc.kernels.core`. They differ only in the last bits of sine, cosine
and atan2 (numba evaluates them by the fdlibm polynomials of :mod:`.core`, numpy by its own
ufuncs), so results agree to 1e-8 m, times the geometry's own amplification of a last-bit change
(1/sin of the grazing angle for a ray meeting a surface; tested). ``auto``, the default, is numba
where it is installed. Choose with ``EOLOC_BACKEND`` or :func:`use_backend`.

Loading numba costs a process 0.7-1.5 s (its import, its target's set-up, the cached kernels;
minutes when the cache is cold), more than a million targets take on numpy. So under ``auto``
the kernels of :func:`run` rent numpy until numba is worth buying, as in the ski-rental problem:
while numba is not loaded, a call runs on numpy if the numpy work counted so far plus this call's
(its elements times the kernel's measured ``numpy_ns``) stays under :data:`NUMBA_LOAD_NS`; the
first call that would pass it loads numba, and from then on everything runs on numba. The count
is of work, not of time, so the same calls make the same choices on every run (results do not
depend on the machine's load). A one-shot command on a million targets at a height never loads
numba; a process that keeps computing loads it within its first half second of work, and pays at
most about twice the cheaper of the two. Work done in pieces (Monte Carlo, sweeps, batches), the
service and live sessions load it up front (:func:`load_compiled`), and the compiled-only paths
(the terrain march, orthorectification) load it directly.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import sys
from collections.abc import Callable, Iterator

import numpy as np

from . import core as kernels

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
    if name not in (*BACKENDS, "auto"):  # only from the environment: set_backend checks its argument
        from ..errors import ConfigError

        raise ConfigError(f"EOLOC_BACKEND={name!r} is not a backend: set it to one of {(*BACKENDS, 'auto')} "
                          "or unset it")
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


_state["name"] = (os.environ.get("EOLOC_BACKEND", "") or "auto").strip().lower()  # checked on first use


class Backend:
    """One backend's versions of the functions that differ by backend, by the same names
    (scipy's backend objects' shape): ``backend().terrain_march(...)`` is the numba or the numpy
    one, whichever is in force. Each version is registered where it is written, next to its
    twin, with :func:`implements`; nothing outside this module asks which backend runs."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.functions: dict[str, Callable] = {}

    def add(self, function: str, fn: Callable) -> None:
        """Register ``fn`` as this backend's ``function`` (an attribute: found at a dict's speed)."""
        self.functions[function] = fn
        setattr(self, function, fn)

    def __repr__(self) -> str:
        return f"<eoloc backend {self.name}: {', '.join(sorted(self.functions))}>"


BACKEND_OBJECTS = {name: Backend(name) for name in BACKENDS}


def implements(function: str, name: str) -> Callable[[Callable], Callable]:
    """Decorator: the decorated function is backend ``name``'s ``function``."""
    def register(fn: Callable) -> Callable:
        BACKEND_OBJECTS[name].add(function, fn)
        return fn

    return register


def backend() -> Backend:
    """The backend in force, as the object holding its versions of the functions."""
    return BACKEND_OBJECTS[get_backend()]


def compiled_version(function: str) -> Callable:
    """The numba backend's ``function``: ``eoloc.kernels.compiled.<function>``, loaded (with
    numba) on its first call, which then registers the compiled function itself."""
    def first_call(*args):
        from . import compiled

        fn = getattr(compiled, function)
        BACKEND_OBJECTS["numba"].add(function, fn)
        return fn(*args)

    return first_call


@implements("locate_one", "numpy")
def _locate_one_numpy(*args) -> tuple[float, float, float, float, int]:
    """One pose, one pixel: :func:`eoloc.kernels.core.locate_one` run as numpy scalars."""
    with np.errstate(all="ignore"):
        lat, lon, h, t, st = kernels.locate_one(*args)
    return float(lat), float(lon), float(h), float(t), int(st)


implements("locate_one", "numba")(compiled_version("locate_one"))


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


def default_threads() -> int:
    """``EOLOC_THREADS`` when set, else the CPUs this process may run on."""
    text = os.environ.get("EOLOC_THREADS", "").strip()
    if text:
        try:
            return max(1, int(text))
        except ValueError:
            from ..errors import ConfigError

            raise ConfigError(f"EOLOC_THREADS={text!r}: give a whole number of threads (1: no threads) or "
                              "unset it") from None
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


_threads = {"n": 0}


def threads() -> int:
    """How many threads a large compiled batch is split over."""
    if not _threads["n"]:
        _threads["n"] = default_threads()
    return _threads["n"]


@contextlib.contextmanager
def use_threads(n: int) -> Iterator[None]:
    """Context manager: large batches split over ``n`` threads (1: none) in the enclosed code."""
    previous = _threads["n"]
    _threads["n"] = max(1, int(n))
    try:
        yield
    finally:
        _threads["n"] = previous


@functools.cache
def _pool():
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max(1, threads() - 1), thread_name_prefix="eoloc kernel")


MIN_CHUNK = 8192  # elements: below this a batch is not worth a thread


def in_chunks(n: int, work: Callable[[int, int], None]) -> None:
    """``work(start, stop)`` over [0, n) in contiguous chunks (2 per thread, so an uneven chunk
    does not hold the rest up) taken in turn by :func:`threads` threads, the calling thread
    among them; one call when the batch is small or one thread is wanted. ``work`` must only
    write its own slice (the compiled drivers, which release the GIL, and the numpy kernels,
    whose loops do: the chunks run at once)."""
    k = min(2 * threads(), n // MIN_CHUNK) if threads() > 1 else 1
    if k <= 1:
        work(0, n)
        return
    import itertools
    import threading

    chunks = itertools.pairwise([n * i // k for i in range(k + 1)])
    lock = threading.Lock()

    def take_turns() -> None:
        while True:
            with lock:
                chunk = next(chunks, None)
            if chunk is None:
                return
            work(*chunk)

    helpers = [_pool().submit(take_turns) for _ in range(min(threads(), k) - 1)]
    try:
        take_turns()
    finally:
        for f in helpers:
            f.result()


class Gathered:
    """``values[index]`` not made yet: a kernel of :func:`run` on the numpy backend gathers it
    chunk by chunk, next to the chunk's other inputs, instead of reading a whole gathered copy.
    Many targets per pose (10^6 targets of 10^5 poses) then read the per-pose values from cache,
    and the copy (72 MB for a rotation's 9 components) is never written. Anywhere else it is the
    array it stands for (``np.asarray`` makes it)."""

    __slots__ = ("index", "values")

    def __init__(self, values: np.ndarray, index: np.ndarray) -> None:
        self.values, self.index = values, index  # values 1-D; index integers (negative from the end)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.index.shape

    @property
    def ndim(self) -> int:
        return self.index.ndim

    def __len__(self) -> int:
        return len(self.index)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        if copy is False:
            raise ValueError("a Gathered array is made on request: it cannot be had without a copy")
        out = self.values.take(self.index)
        return out if dtype is None else out.astype(dtype, copy=False)


def flat_index(index, n: int) -> np.ndarray:
    """An integer index into ``n`` elements, flat and counted from the start (negative counts from
    the end); out of range: IndexError, as numpy raises it. Checked once here, the takes that use
    it then skip the per-element check (``mode="clip"``)."""
    flat = np.asarray(index).reshape(-1)
    if flat.size:
        lo, hi = int(flat.min()), int(flat.max())
        if lo < -n or hi >= n:
            raise IndexError(f"index {lo if lo < -n else hi} is out of bounds for axis 0 with size {n}")
        if lo < 0:
            flat = np.where(flat < 0, flat + n, flat)
    return flat


def take_all(arrays: list[np.ndarray], index: np.ndarray) -> list[np.ndarray]:
    """``[a[index] for a in arrays]`` for 1-D arrays of one length and an integer index (negative
    counts from the end; out of range: IndexError), the index cut into slices taken in turn by
    the threads: numpy's take releases the GIL, and all the arrays are gathered at one slice
    while its indices are in cache (13 arrays of 10^5 at 10^6 indices: 11-14 ms, 23-41 ms as
    13 fancy indexings)."""
    index = np.asarray(index)
    flat = flat_index(index, len(arrays[0]) if arrays else 0)
    outs = [np.empty(flat.size, dtype=a.dtype) for a in arrays]

    def part(i: int, j: int) -> None:
        for a, out in zip(arrays, outs, strict=True):
            np.take(a, flat[i:j], out=out[i:j], mode="clip")  # in range (checked above): no per-element check

    in_chunks(flat.size, part)
    return [o.reshape(index.shape) for o in outs]


CHUNK = 16384  # numpy path: temporaries of this many elements stay in cache (2x faster than whole arrays)
NUMBA_LOAD_NS = 5e8  # numpy work (ns) a process does under auto before it loads numba (see the module doc)
_rent = {"spent_ns": 0.0}


def numba_loaded() -> bool:
    """Whether this process has loaded eoloc's compiled kernels (numba)."""
    return "eoloc.kernels.compiled" in sys.modules


def load_compiled() -> None:
    """Under ``auto``, load numba now where it is installed: for work done in pieces (Monte Carlo
    chunks, sweep points, batch files), which is large, and whose pieces must run the same
    kernels in this process and on any Dask worker; and for long-running processes (the service,
    live sessions), so that the load is not paid in a request's or a packet's time."""
    if _state["name"] == "auto" and get_backend() == "numba":
        from . import compiled  # noqa: F401


def _rents(sig, n: int) -> bool:
    """Under auto with numba not loaded: whether this call runs on numpy (and is counted)."""
    if _state["name"] != "auto" or numba_loaded():
        return False
    cost = n * sig.numpy_ns
    if _rent["spent_ns"] + cost > NUMBA_LOAD_NS:
        return False
    _rent["spent_ns"] += cost
    return True


def run(name: str, *args):
    """Run kernel ``name`` (declared in ``eoloc.kernels.core.SIGNATURES``) on inputs that broadcast;
    returns its outputs as arrays of the broadcast shape (a rotation as a 9-tuple of them).

    A rotation argument is a 9-tuple or an array with 9 in its first axis; constants (the
    ellipsoid, the gimbal kind) are scalars. Both backends see flat inputs: a scalar stays a
    scalar, an array is broadcast to the full shape and flattened (a copy only where it really
    broadcasts).
    """
    sig = kernels.SIGNATURES[name]
    if len(args) != len(sig.params):
        raise TypeError(f"{name} takes {len(sig.params)} arguments ({', '.join(sig.params)}), got {len(args)}")
    flat_args: list = []
    for param, a in zip(sig.params, args, strict=True):
        if param in sig.ints:
            flat_args.append(int(a))
        elif param in sig.constants:
            flat_args.append(float(a))
        elif sig.width(param) == 9:
            if len(a) != 9:
                raise ValueError(f"{name}: rotation {param} needs 9 components, got {len(a)}")
            flat_args.extend(_array(c) for c in a)
        else:
            flat_args.append(_array(a))
    arrays = [a for a in flat_args if isinstance(a, (np.ndarray, Gathered))]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    n = int(np.prod(shape))
    indexes: dict = {}  # each Gathered index checked and flattened once
    flat_in = [_flat(a, shape, indexes) for a in flat_args]
    outs = []
    for o in sig.outputs:
        outs.extend(np.empty(n, dtype=np.int8 if o == "status" else np.float64) for _ in range(sig.width(o)))
    if get_backend() == "numpy" or _rents(sig, n):
        _run_numpy(sig, n, flat_in, outs)
    else:
        from . import compiled

        compiled.DRIVERS[name](n, *_gather_all(flat_in), *outs)
    shaped = iter([o.reshape(shape) for o in outs])
    return tuple(tuple(next(shaped) for _ in range(9)) if sig.width(o) == 9 else next(shaped) for o in sig.outputs)


def _array(a):
    """A kernel input as float64: an array, or a :class:`Gathered` of float64 values."""
    if isinstance(a, Gathered):
        return Gathered(np.ascontiguousarray(a.values, dtype=np.float64).reshape(-1), a.index)
    return np.asarray(a, dtype=np.float64)


def _flat(a, shape: tuple[int, ...], indexes: dict):
    """An input as the backends see it: a scalar, or a flat array of the broadcast ``shape`` (a
    copy only where it really broadcasts); a :class:`Gathered` of that shape stays one, its index
    flat, non-negative and in range (checked once per index, in ``indexes``: the chunks take with
    ``clip``)."""
    if isinstance(a, Gathered):
        if a.shape != shape:
            return _flat(np.asarray(a), shape, indexes)
        key = (id(a.index), len(a.values))
        if key not in indexes:
            indexes[key] = flat_index(a.index, len(a.values))
        return Gathered(a.values, indexes[key])
    if not isinstance(a, np.ndarray):
        return a
    if a.ndim == 0:
        return float(a)
    if a.shape == shape and a.flags.c_contiguous:  # no copy, no broadcast
        return a.reshape(-1)
    return np.ascontiguousarray(np.broadcast_to(a, shape)).reshape(-1)


def _gather_all(flat_in: list) -> list:
    """The inputs with every :class:`Gathered` made (those of one index together, on the threads)."""
    groups: dict[int, list[int]] = {}
    for k, x in enumerate(flat_in):
        if isinstance(x, Gathered):
            groups.setdefault((id(x.index), len(x.values)), []).append(k)
    out = list(flat_in)
    for ks in groups.values():
        for k, made in zip(ks, take_all([flat_in[k].values for k in ks], flat_in[ks[0]].index), strict=True):
            out[k] = made
    return out


def _run_numpy(sig, n: int, flat_in: list, outs: list[np.ndarray]) -> None:
    """The kernel itself on chunks of the flat inputs, rotations regrouped as 9-tuples; a large
    batch split over :func:`threads` threads (the kernels are element-wise: the same results
    however it is split; 1.3-1.6x on two cores, measured on ray_direction at 10^6)."""
    fn = getattr(kernels, sig.name)

    def work(start: int, stop: int) -> None:
        with np.errstate(all="ignore"):  # per thread
            for i in range(start, stop, CHUNK):
                j = min(i + CHUNK, stop)
                part = [x[i:j] if isinstance(x, np.ndarray) else x.values.take(x.index[i:j], mode="clip")
                        if isinstance(x, Gathered) else x for x in flat_in]
                args, k = [], 0
                for param in sig.params:
                    w = sig.width(param) if param not in sig.constants else 1
                    args.append(tuple(part[k:k + 9]) if w == 9 else part[k])
                    k += w
                flat = []
                for o in fn(*args):
                    flat.extend(o if isinstance(o, tuple) else (o,))
                for out, value in zip(outs, flat, strict=True):
                    out[i:j] = value

    in_chunks(n, work)
