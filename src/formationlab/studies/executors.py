"""Where chunks run: in this process, in a pool of processes, or on dask.distributed.

Each executor takes the chunks to run and yields ``(task, trials)`` pairs as
chunks finish, in whatever order they finish; the caller saves and collects
them. Worker processes run the numba kernel on one thread each (one process per
core): numba's ``set_num_threads(1)`` in each worker of a pool (the environment variable
``NUMBA_NUM_THREADS`` would have to be set before numba loads, which unpickling the
worker's first call already does; numba reads it again whenever it compiles, and refuses a
value other than the threads it launched), ``NUMBA_NUM_THREADS=1`` in the environment of
a dask worker, which starts before anything is imported.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context

import numba
import pandas as pd

from ..errors import ParameterError
from .chunks import ChunkTask, run_chunk

__all__ = ["run_in_process", "run_on_dask"]


def _worker_init() -> None:  # pragma: no cover - runs in the pool's processes
    numba.set_num_threads(1)  # one process per core: each kernel on one thread


def run_in_process(
    tasks: list[ChunkTask], workers: int
) -> Iterator[tuple[ChunkTask, pd.DataFrame]]:
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            yield t, run_chunk(t)
        return
    ctx = get_context("spawn")
    with ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=_worker_init
    ) as pool:
        futures = {pool.submit(run_chunk, t): t for t in tasks}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def run_on_dask(
    tasks: list[ChunkTask], scheduler: str, workers: int | None
) -> Iterator[tuple[ChunkTask, pd.DataFrame]]:
    try:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed
    except ImportError:  # pragma: no cover - depends on the installation
        raise ParameterError(
            "--scheduler needs dask.distributed: pip install 'formationlab[distributed]'"
        ) from None
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            # a free port: with None the scheduler's HTTP server still takes 8787, and a
            # second cluster at the same time (another study, another test) fails to start
            dashboard_address=":0",
            env={"NUMBA_NUM_THREADS": "1"},
        )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ParameterError(
                f"cannot reach the dask scheduler at {scheduler!r} ({exc}); check the address "
                '(e.g. "tcp://host:8786") or use --scheduler local'
            ) from None
    run = uuid.uuid4().hex[:8]
    try:
        futures = {}
        for t in tasks:
            fut = client.submit(run_chunk, t, key=f"formationlab-{run}-{t.id}", pure=False)
            futures[fut.key] = (fut, t)
        for fut in dask_completed([f for f, _ in futures.values()]):
            yield futures[fut.key][1], fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
