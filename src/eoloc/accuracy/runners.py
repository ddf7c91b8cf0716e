"""Where the pieces of a Monte Carlo run or a sweep are computed: here, or on a Dask cluster.

A *mapper* is ``mapper(fn, args_list, on_done=None) -> [fn(*args) for args in args_list]`` (in
order); ``on_done(i)`` is called as item i finishes (progress bars). Monte Carlo chunks and sweep
points are independent and seeded by their index, and every mapper runs them on the compiled
kernels (:func:`eoloc.kernels.backend.load_compiled`), so every mapper gives identical results.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

from ..kernels.backend import load_compiled


class Mapper(Protocol):
    def __call__(self, fn: Callable, args_list: Sequence[tuple], on_done: Callable[[int], None] | None = None
                 ) -> list: ...


def local_map(fn: Callable, args_list: Sequence[tuple], on_done: Callable[[int], None] | None = None) -> list:
    """Compute every item in this process, in order."""
    load_compiled()
    out = []
    for i, args in enumerate(args_list):
        out.append(fn(*args))
        if on_done is not None:
            on_done(i)
    return out


class DaskMapper:
    """Items as tasks on a ``dask.distributed`` client. An argument shared by every item (the
    scenario, its DEM) is sent to the workers once (scatter, broadcast) instead of with each task."""

    def __init__(self, client: Any) -> None:
        self.client = client

    def __call__(self, fn: Callable, args_list: Sequence[tuple], on_done: Callable[[int], None] | None = None
                 ) -> list:
        from distributed import as_completed

        if not args_list:
            return []
        args_list = [tuple(a) for a in args_list]
        width = len(args_list[0])
        shared = {j for j in range(width) if len(args_list) > 1 and all(a[j] is args_list[0][j] for a in args_list)}
        # hash=False: a key of its own per call (two calls scattering the same value would share one
        # key, which the first call's release can take away from the second: 'lost dependencies')
        # (the value goes in a list: scatter takes a dict's keys as data keys, which would collide too)
        sent = {j: self.client.scatter([args_list[0][j]], broadcast=True, hash=False)[0] for j in shared}
        futures = [self.client.submit(compiled_item, fn, *(sent.get(j, a[j]) for j in range(width)), pure=False)
                   for a in args_list]
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in as_completed(futures):
            if fut.status == "error":
                fut.result()  # raises the task's exception here, with its traceback
            if on_done is not None:
                on_done(index[fut.key])
        return self.client.gather(futures)


def compiled_item(fn: Callable, *args) -> Any:
    """One item on a worker, on the compiled kernels as in :func:`local_map`."""
    load_compiled()
    return fn(*args)


@contextlib.contextmanager
def dask_mapper(address: str) -> Iterator[DaskMapper]:
    """A DaskMapper on the scheduler at ``address`` (e.g. tcp://10.0.0.5:8786), or on a new local
    cluster for ``"local"`` / ``"local:N"`` (N worker processes, one thread each; default 2)."""
    from ..util.extras import require

    require("distributed")  # (the batch extra)
    from distributed import Client, LocalCluster

    if address == "local" or address.startswith("local:"):
        workers = int(address.split(":", 1)[1]) if ":" in address else 2
        # the worker processes are the parallelism: their kernels stay on one thread each
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          env={"EOLOC_THREADS": "1"}) as cluster, \
                Client(cluster) as client:
            yield DaskMapper(client)
        return
    with Client(address, timeout="20s") as client:
        yield DaskMapper(client)
