"""A pool of spawned worker processes that share the machine's cores instead of each taking them all.

The odometry's k-d tree queries run on OpenMP threads (pykdtree), one per core by
default. N workers on N cores then run N x N threads, and OpenMP's waiting threads
spin: two workers on this 2-core machine registered 3.8 frames/s each with two
threads apiece and 6.3 each with one (60 city frames, ``salo32``, the default
configuration). A worker therefore gets ``cores // workers`` OpenMP threads (at least
one), unless the user has set ``OMP_NUM_THREADS`` themselves. For the same reason a
worker with fewer than two cores prepares no scans ahead on threads of its own
(``SALO_PREFETCH_SCANS=0``, ``odometry.pipeline.register_frames``), unless the user
has set that variable: the other workers keep the cores busy (the city and canyon
evaluation sequences with 2 workers took 166 s without and 170 s with it).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager


def openmp_threads_per_worker(workers: int, cores: int | None = None) -> int:
    """OpenMP threads for each of ``workers`` processes on ``cores`` cores (default: this machine's)."""
    cores = (os.cpu_count() or 1) if cores is None else cores
    return max(1, cores // max(1, workers))


@contextmanager
def spawned_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """``ProcessPoolExecutor(workers)`` with spawned processes (no state inherited from the driver).

    Workers are started as tasks are submitted, and read ``OMP_NUM_THREADS`` when
    their OpenMP runtime loads (and ``SALO_PREFETCH_SCANS`` when they register scans):
    both are set in the environment they inherit for the pool's whole life, then
    restored (this process's own runtime, if loaded, keeps its threads). On leaving,
    the pool waits for its tasks; on an exception (an interrupt) it cancels the
    pending ones and does not wait.
    """
    from odometry.pipeline import PREFETCH_ENV

    threads = openmp_threads_per_worker(workers)
    limits = {"OMP_NUM_THREADS": str(threads)}
    if threads < 2:
        limits[PREFETCH_ENV] = "0"
    saved = {name: os.environ.get(name) for name in limits}
    for name, value in limits.items():
        if saved[name] is None:
            os.environ[name] = value
    try:
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
        try:
            yield pool
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
