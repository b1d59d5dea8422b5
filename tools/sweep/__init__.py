"""Sweeps over scenes x seeds x sensors x noise levels x odometry variants, and the regression suite.

    from tools.sweep import load_spec, run_sweep, LocalExecutor
    result = run_sweep(load_spec("noise.yaml"), "out/sweeps/noise", LocalExecutor(2))
    result.rows        # one dict per run: parameters, status, metrics, timings, versions, error

Modules: ``spec`` (YAML -> validated ``SweepSpec`` -> runs with stable keys),
``store`` (the output folder: per-run result JSON, results.csv), ``tasks`` (the
simulate / run functions every executor runs), ``executors`` (in-process,
local processes, Dask), ``runner`` (plan, resume, execute), ``summary`` (table,
plots), ``regress`` (the CI regression suite against a committed baseline).
"""

from .executors import DaskExecutor, InlineExecutor, LocalExecutor, make_executor
from .runner import SweepPlan, SweepResult, plan_sweep, run_sweep
from .spec import RunParams, SpecError, SweepSpec, load_spec, spec_from_dict
from .store import Store, StoreBusy, read_table

__all__ = [
    "DaskExecutor",
    "InlineExecutor",
    "LocalExecutor",
    "RunParams",
    "SpecError",
    "Store",
    "StoreBusy",
    "SweepPlan",
    "SweepResult",
    "SweepSpec",
    "load_spec",
    "make_executor",
    "plan_sweep",
    "read_table",
    "run_sweep",
    "spec_from_dict",
]
