"""Executors: who runs a sweep's tasks. In-process, local processes, or a Dask cluster.

All three run the same two functions (``tasks.simulate_task`` then
``tasks.run_task`` for each run of that sequence) and report each finished
run to the driver through ``on_done(result)``; they differ only in where the
work happens. A sequence's runs start as soon as it is simulated (simulations
are queued first, so sequences are made early and their runs fill the
workers). A task that dies without returning (a killed worker, a crash in
native code) is reported as a failed run with the reason; its result is then
written by the driver, and the next sweep redoes it.
"""

from __future__ import annotations

import logging
import os
import uuid
from collections import defaultdict
from collections.abc import Callable, Sequence
from typing import Protocol

from .tasks import RunJob, SimJob, failed_result, run_task, simulate_task

log = logging.getLogger(__name__)

OnDone = Callable[[dict], None]


class Executor(Protocol):
    """Runs simulations and runs; calls ``on_done(result)`` in the caller's process for every run."""

    name: str

    def execute(self, sims: Sequence[SimJob], ready: dict[str, dict], runs: Sequence[RunJob],
                on_done: OnDone) -> None:
        """``ready`` maps sim keys already in the store to their outcome; every run's sequence is
        either there or among ``sims``."""
        ...


def _by_sim(runs: Sequence[RunJob]) -> dict[str, list[RunJob]]:
    out: dict[str, list[RunJob]] = defaultdict(list)
    for job in runs:
        out[job.sim_key].append(job)
    return out


def _died(kind: str, exc: BaseException) -> str:
    return (f"the {kind} task died without a result ({type(exc).__name__}: {exc}); "
            "a worker was killed or crashed; the next sweep redoes this run")


class InlineExecutor:
    """Everything in this process, one task at a time (debugging, tests, tiny sweeps)."""

    name = "inline"

    def execute(self, sims, ready, runs, on_done) -> None:
        by_sim = _by_sim(runs)
        for key, outcome in ready.items():
            for job in by_sim.pop(key, []):
                on_done(run_task(job, outcome))
        for sim in sims:
            outcome = simulate_task(sim)
            for job in by_sim.pop(sim.sim_key, []):
                on_done(run_task(job, outcome))


class LocalExecutor:
    """``workers`` local processes (``tools.worker_pool.spawned_pool``: spawned, no state inherited
    from the driver). Each simulation gets cores / workers Embree threads, each worker as many
    OpenMP threads for the odometry's k-d tree queries."""

    name = "local"

    def __init__(self, workers: int):
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers
        self.sim_threads = max(1, (os.cpu_count() or 1) // workers)

    def execute(self, sims, ready, runs, on_done) -> None:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        from tools.worker_pool import spawned_pool

        by_sim = _by_sim(runs)
        pending: dict = {}
        # (on an interrupt the pool cancels what has not started and does not wait)
        with spawned_pool(self.workers) as pool:

            def submit_runs(key: str, outcome: dict) -> None:
                for job in by_sim.pop(key, []):
                    try:
                        pending[pool.submit(run_task, job, outcome)] = ("run", job)
                    except BrokenProcessPool as exc:  # the pool broke earlier: nothing more runs here
                        on_done(failed_result(job, _died("run", exc)))

            for key, outcome in ready.items():
                submit_runs(key, outcome)
            for sim in sims:
                pending[pool.submit(simulate_task, sim, self.sim_threads)] = ("sim", sim)
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    kind, job = pending.pop(future)
                    try:
                        result = future.result()
                    except Exception as exc:
                        if kind == "run":
                            on_done(failed_result(job, _died("run", exc)))
                        else:
                            submit_runs(job.sim_key, {"sim_key": job.sim_key, "ok": False, "cached": False,
                                                      "error": _died("simulation", exc)})
                        continue
                    if kind == "sim":
                        submit_runs(job.sim_key, result)
                    else:
                        on_done(result)


class DaskExecutor:
    """A Dask distributed cluster: ``Client(address)`` (or a given client) runs the same task functions.

    Workers need this package installed and the sweep's output folder on a
    shared filesystem (they write the sequences and run folders). A run task
    depends on its sequence's task, so Dask starts it as soon as that is done.
    sim_threads: Embree threads per simulation; 1 by default because a cluster's
    parallelism is its worker threads (one per core, usually), None for all cores.
    """

    name = "dask"

    def __init__(self, address: str | None = None, client=None, sim_threads: int | None = 1):
        if address is None and client is None:
            raise ValueError("give the scheduler's address or a dask.distributed Client")
        self.address = address
        self.client = client
        self.sim_threads = sim_threads

    def execute(self, sims, ready, runs, on_done) -> None:
        from distributed import Client, as_completed

        client = self.client if self.client is not None else Client(self.address)
        token = uuid.uuid4().hex[:8]  # unique task keys per sweep: a finished key would be reused otherwise
        sim_futures: dict = {}
        run_futures: dict = {}
        try:
            sim_futures = {s.sim_key: client.submit(simulate_task, s, self.sim_threads, pure=False, priority=1,
                                                    key=f"simulate-{s.sim_key}-{token}") for s in sims}
            for job in runs:
                dep = sim_futures[job.sim_key] if job.sim_key in sim_futures else ready[job.sim_key]
                future = client.submit(run_task, job, dep, pure=False, key=f"run-{job.key}-{token}")
                run_futures[future] = job
            for future in as_completed(run_futures):
                job = run_futures[future]
                try:
                    result = future.result()
                except Exception as exc:  # KilledWorker, a dead sequence task, a lost connection
                    result = failed_result(job, _died("run", exc))
                on_done(result)
        except BaseException:
            for future in [*sim_futures.values(), *run_futures]:
                future.cancel()
            raise
        finally:
            if self.client is None:
                client.close()


def make_executor(workers: int | None = None, scheduler: str | None = None) -> Executor:
    """The executor the command line asks for: Dask at ``scheduler``, else ``workers`` local processes
    (0: in this process; None: one per core)."""
    if scheduler:
        return DaskExecutor(scheduler)
    if workers is None:
        workers = os.cpu_count() or 1
    return InlineExecutor() if workers == 0 else LocalExecutor(workers)


__all__ = ["DaskExecutor", "Executor", "InlineExecutor", "LocalExecutor", "make_executor"]
