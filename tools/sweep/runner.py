"""Run a sweep: plan against the store (skip, redo), execute, rebuild the table, summarise.

Resume semantics: a run whose ``result.json`` says "ok" is skipped; a run
folder without ``result.json`` (killed half-way) is removed and redone; a
failed run is redone unless ``retry_failed=False``; ``rerun=True`` redoes
everything (cached sequences are still reused: they depend only on their
parameters and the simulator).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from simlidar.formats.atomic import atomic_write_text

from .executors import Executor, InlineExecutor
from .spec import RunParams, SweepSpec
from .store import Store, flatten
from .tasks import RunJob, SimJob

log = logging.getLogger(__name__)


@dataclass
class SweepPlan:
    """What a sweep will do: ``todo`` runs to execute, ``skipped`` already done, ``partial`` half-written
    folders found (redone), ``sims`` sequences to simulate, ``cached`` sequences found in the store."""

    runs: list[RunParams]
    todo: list[RunParams]
    skipped: int
    partial: int
    retried_failed: int
    sims: list[str]
    cached: list[str]


@dataclass
class SweepResult:
    """A finished sweep: the rows of every run of the spec (spec order), and what happened this time.

    rows: flattened results (``store.TABLE_COLUMNS``); failures: the rows with
    status "failed"; executed: runs done this time; seconds: wall time.
    """

    store: Store
    plan: SweepPlan
    rows: list[dict]
    executed: int
    seconds: float
    outputs: dict[str, Path] = field(default_factory=dict)

    @property
    def failures(self) -> list[dict]:
        return [r for r in self.rows if r["status"] != "ok"]

    @property
    def runs_per_minute(self) -> float:
        return 60.0 * self.executed / self.seconds if self.seconds > 0 else float("nan")


def plan_sweep(spec: SweepSpec, store: Store, rerun: bool = False, retry_failed: bool = True) -> SweepPlan:
    """Compare the spec's runs with the store (reads only)."""
    runs = spec.runs()
    todo, states = [], Counter()
    for run in runs:
        state = store.state(run.key)
        states[state] += 1
        if rerun or state in ("new", "partial") or (state == "failed" and retry_failed):
            todo.append(run)
    sim_keys = list(dict.fromkeys(r.sim_key for r in todo))
    cached = [k for k in sim_keys if store.sequence_ready(k)]
    return SweepPlan(runs, todo, len(runs) - len(todo), states["partial"],
                     states["failed"] if retry_failed or rerun else 0,
                     [k for k in sim_keys if k not in cached], cached)


def run_sweep(
    spec: SweepSpec,
    out_dir: str | Path,
    executor: Executor | None = None,
    *,
    rerun: bool = False,
    retry_failed: bool = True,
    on_plan: Callable[[SweepPlan], None] | None = None,
    on_result: Callable[[dict], None] | None = None,
    command_timeout_s: float | None = None,
    report: bool = True,
) -> SweepResult:
    """Run ``spec`` into the store at ``out_dir`` and return every run's row.

    executor: ``InlineExecutor`` (default), ``LocalExecutor(n)`` or ``DaskExecutor``.
    on_plan(plan) is called once before any work; on_result(row) after each
    finished run (progress bars). report: write the summary table and plots.
    Raises ``store.StoreBusy`` if another sweep is writing into ``out_dir``.
    """
    executor = executor or InlineExecutor()
    store = Store(Path(out_dir).resolve())  # absolute: workers may run elsewhere
    t0 = time.perf_counter()
    with store.lock():
        removed = store.clean_partials()
        if removed:
            log.info("removed %d half-written sequence folders", removed)
        atomic_write_text(store.root / "spec.yaml", yaml.safe_dump(spec.to_dict(), sort_keys=False))
        plan = plan_sweep(spec, store, rerun=rerun, retry_failed=retry_failed)
        if on_plan is not None:
            on_plan(plan)
        for run in plan.todo:
            store.clear_run(run.key)  # half-written, failed or forced: start from an empty folder

        sims = _sim_jobs(plan, store, in_memory=spec.sequences == "memory")
        ready = {k: {"sim_key": k, "ok": True, "cached": True, "path": str(store.sequence_dir(k)),
                     "simulate_s": store.sequence_info(k).get("simulate_s")} for k in plan.cached}
        jobs = [_run_job(r, store, command_timeout_s) for r in plan.todo]
        remaining = Counter(j.sim_key for j in jobs)

        def done(result: dict) -> None:
            if store.read_result(result["key"]) is None:  # the task died before committing it
                store.write_result(result)
            remaining[result["sim_key"]] -= 1
            if not spec.keep_sequences and remaining[result["sim_key"]] == 0:
                store.remove_sequence(result["sim_key"])
            if on_result is not None:
                on_result(flatten(result))

        try:
            executor.execute(sims, ready, jobs, done)
        finally:  # interrupted too: the table shows every run finished so far
            rows = store.write_table(r.key for r in plan.runs)
        missing = len(plan.runs) - len(rows)
        if missing:  # cannot happen unless a worker could not write to the store
            log.warning("%d runs have no result in %s (do the workers share its filesystem?)", missing, store.root)
        outputs = {"table": store.table_path}
        if report:
            from .summary import write_report

            outputs.update(write_report(rows, store.root))
    return SweepResult(store, plan, rows, len(jobs), time.perf_counter() - t0, outputs)


def _sim_jobs(plan: SweepPlan, store: Store, in_memory: bool = False) -> list[SimJob]:
    """The sequences to make; in memory unless asked for disk (an external command gets its own staged copy
    of a sequence in memory, ``tools.staging``: nothing of the truth is written for it)."""
    first = {}
    for run in plan.todo:
        first.setdefault(run.sim_key, run.sim)
    return [SimJob(str(store.root), k, first[k].scene, first[k].seed, first[k].scene_overrides, first[k].sensor_model,
                   first[k].frames, first[k].start_s, first[k].motion_distortion, in_memory=in_memory)
            for k in plan.sims]


def _run_job(run: RunParams, store: Store, command_timeout_s: float | None) -> RunJob:
    extra = {"command_timeout_s": command_timeout_s} if command_timeout_s is not None else {}
    # workdir None: a command runs in its stage's own folder, not in the caller's (tools.isolation)
    return RunJob(str(store.root), run.key, run.sim_key, run.describe(), run.config, run.command,
                  method=run.method, fields=run.fields, **extra)


__all__ = ["SweepPlan", "SweepResult", "plan_sweep", "run_sweep"]
