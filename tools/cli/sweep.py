"""The sweep commands of ``salo``: ``sweep`` (a study over many runs) and ``regress`` (CI against a baseline).

Registered on the main parser by ``add_commands(subparsers)``. Thin commands
over ``tools.sweep``: parse, call the library, print.
"""

from __future__ import annotations

import argparse
import os
import textwrap
from contextlib import contextmanager
from pathlib import Path

from .common import CommandError, real_number, run_counter, whole_number


def _add_executor_args(p) -> None:
    g = p.add_argument_group("where the runs execute")
    g.add_argument("--workers", type=whole_number(0), default=os.cpu_count() or 1, metavar="N",
                   help="local worker processes (default: one per core, here %(default)s; 0: in this process)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask distributed cluster, e.g. tcp://host:8786 (needs the 'cluster' extra; "
                        "the workers must have this package and see --out on a shared filesystem)")


_SPEC_KEYS = "<the spec keys>"


class _SpecKeysFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the key table's columns, and makes it from the declarations only when help is shown.

    (``tools.sweep.spec`` loads scipy: building every parser with it would slow ``salo --help``.)
    """

    def add_text(self, text):
        if text == _SPEC_KEYS:
            from paramspec import help_text
            from tools.sweep.spec import SweepSpec

            text = "spec keys (YAML; every key is optional):\n" + help_text(SweepSpec.schema(), header=True)
        super().add_text(text)


def add_commands(subparsers) -> None:
    """Register ``sweep`` and ``regress`` on the main parser's sub-parsers."""
    description = textwrap.fill(
        "Run every combination of a sweep spec's axes: simulate each sequence (in memory by default; with "
        "the spec's sequences: disk, once into the output folder, reused next time), run each odometry variant "
        "on it, evaluate against ground truth. Results: "
        "OUT/results.csv (one row per run: parameters, metrics, timings, versions, error), OUT/runs/KEY/ "
        "(each run's poses, diagnostics and result.json), OUT/summary.md|csv and OUT/plots/SCENE.png "
        "(error against noise per variant). Re-running resumes: finished runs are skipped, half-written "
        "and failed ones redone.", width=100)
    p = subparsers.add_parser(
        "sweep",
        help="run a study: scenes x seeds x sensors x noise levels x variants",
        description=description,
        epilog=_SPEC_KEYS,
        formatter_class=_SpecKeysFormatter,
    )
    p.add_argument("spec", type=Path, metavar="SPEC.yaml", help="the sweep spec")
    p.add_argument("--out", type=Path, help="output folder (default out/sweeps/<spec name>)")
    _add_executor_args(p)
    p.add_argument("--rerun", action="store_true", help="redo every run, finished ones too (sequences are reused)")
    p.add_argument("--keep-failed", action="store_true", help="do not redo runs that failed last time")
    p.add_argument("--dry-run", action="store_true", help="print the plan and stop")
    p.add_argument("--timeout", type=real_number(0.0, above=True), metavar="S",
                   help="time limit of an external odometry command, s")
    p.set_defaults(func=cmd_sweep)

    p = subparsers.add_parser(
        "regress",
        help="CI regression: a small suite's errors against a committed baseline",
        description="Run a small fixed suite (short sequences in city, forest and highway x every variant) "
        "and compare each run's error figures with a baseline file. Fails (exit 1), naming the run, the "
        "figure and both values, when a figure grows past baseline + max(relative x baseline, floor); the "
        "tolerance is stored in the baseline file. --update rewrites the baseline from this run. With "
        "--odometry-command, your own odometry is evaluated instead: a shell command with {sequence} "
        "(a sequence folder: velodyne/*.bin, times.txt, sensor.yaml, ...) and {out} (the KITTI poses file "
        "it must write, one line per frame), against your own --baseline.",
    )
    p.add_argument("--baseline", type=Path, help="baseline JSON (default: the project's tools/regress_baseline.json)")
    p.add_argument("--update", action="store_true", help="rewrite the baseline from this run's figures")
    p.add_argument("--odometry-command", metavar="CMD",
                   help='external odometry, e.g. "my_odometry {sequence} {out}" (run through the shell)')
    p.add_argument("--name", default="external", help="variant name of --odometry-command (default external)")
    p.add_argument("--suite", type=Path, metavar="SPEC.yaml", help="a sweep spec to use as the suite instead")
    p.add_argument("--out", type=Path, default=Path("out/regress"), help="output folder (default out/regress)")
    p.add_argument("--keep-sequences", action="store_true",
                   help="write the simulated sequences into --out and reuse them next time (faster; stale if "
                        "the simulator changes); by default they are simulated in memory")
    p.add_argument("--timeout", type=real_number(0.0, above=True), default=3600.0, metavar="S",
                   help="time limit of --odometry-command per sequence, s (default 3600)")
    _add_executor_args(p)
    p.set_defaults(func=cmd_regress)


# ---------------------------------------------------------------- helpers
def _describe_plan(plan, executor) -> str:
    sequences = len({r.sim_key for r in plan.runs})
    text = (f"{len(plan.runs)} runs over {sequences} sequences: {plan.skipped} done, {len(plan.todo)} to run"
            f"{f' ({plan.partial} half-written redone)' if plan.partial else ''}"
            f"{f' ({plan.retried_failed} failed retried)' if plan.retried_failed else ''}; "
            f"{len(plan.sims)} sequences to simulate, {len(plan.cached)} cached; executor {executor.name}")
    workers = getattr(executor, "workers", None)
    return text + (f" x {workers}" if workers else "")


def _executor(args):
    from tools.sweep import make_executor

    if args.scheduler:
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise CommandError("--scheduler needs Dask: pip install 'salo-bench[cluster]'") from None
    return make_executor(args.workers, args.scheduler)


@contextmanager
def _sweeping(args, desc: str):
    """The executor ``--workers`` / ``--scheduler`` ask for, and ``run_sweep``'s callbacks: print the plan,
    then count the runs on stderr. A store another sweep holds is a one-line error."""
    from tools.sweep import StoreBusy

    executor = _executor(args)
    on_plan, on_result, close = run_counter(desc)

    def plan_then_bar(plan) -> None:
        print(f"{desc}: {_describe_plan(plan, executor)}", flush=True)
        on_plan(plan)

    try:
        yield executor, {"on_plan": plan_then_bar, "on_result": on_result}
    except StoreBusy as exc:
        raise CommandError(str(exc)) from None
    finally:
        close()


def _print_failures(rows) -> None:
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        print(f"\n{len(failed)} failed runs (errors also in results.csv and runs/KEY/result.json):")
        for r in failed:
            print(f"  {r['label']} [{r['key']}]: {r['error']}")


# ---------------------------------------------------------------- sweep
def cmd_sweep(args) -> int:
    from tools.sweep import SpecError, Store, load_spec, plan_sweep, run_sweep
    from tools.sweep.summary import format_markdown, summarize

    try:
        spec = load_spec(args.spec)
        out = args.out or Path("out") / "sweeps" / spec.name
        if args.dry_run:
            plan = plan_sweep(spec, Store(out), rerun=args.rerun, retry_failed=not args.keep_failed)
            print(f"sweep {spec.name}: {_describe_plan(plan, _executor(args))}")
            for run in plan.todo:
                print(f"  {run.key}  {run.label}")
            return 0
        with _sweeping(args, f"sweep {spec.name}") as (executor, callbacks):
            result = run_sweep(spec, out, executor, rerun=args.rerun, retry_failed=not args.keep_failed,
                               command_timeout_s=args.timeout, **callbacks)
    except SpecError as exc:
        raise CommandError(str(exc)) from None
    print()
    print(format_markdown(summarize(result.rows)), end="")
    _print_failures(result.rows)
    print(f"\n{result.executed} runs in {result.seconds:.1f} s ({result.runs_per_minute:.1f} runs/min); "
          f"{len(result.rows)} rows in {result.store.table_path}")
    plots = [str(p) for k, p in result.outputs.items() if k.startswith("plot_")]
    print(f"summary: {result.outputs.get('summary_md')}; plots: {', '.join(plots)}")
    return 1 if result.failures else 0


# ---------------------------------------------------------------- regress
def cmd_regress(args) -> int:
    from dataclasses import replace

    from tools.sweep import SpecError, load_spec
    from tools.sweep.regress import DEFAULT_BASELINE, BaselineError, check_suite, read_baseline, regress, suite_spec

    if args.odometry_command and args.baseline is None:
        raise CommandError("--odometry-command needs --baseline FILE: your odometry's own baseline "
                           "(write it once with --update)")
    baseline_path = args.baseline or DEFAULT_BASELINE
    try:
        suite = load_spec(args.suite) if args.suite else None
        spec = suite_spec(args.odometry_command, suite, variant_name=args.name)
        if args.keep_sequences:
            spec = replace(spec, keep_sequences=True, sequences="disk")
        baseline = None
        if not args.update:
            baseline = read_baseline(baseline_path)  # fail before the work: missing, or for another suite
            check_suite(baseline, spec, str(baseline_path))
        with _sweeping(args, "regress") as (executor, callbacks):
            done = regress(spec, args.out, executor, baseline_path, update=args.update, baseline=baseline,
                           command_timeout_s=args.timeout, **callbacks)
    except (SpecError, BaselineError) as exc:
        raise CommandError(str(exc)) from None
    rows, result, report = done.result.rows, done.result, done.report
    print()
    if args.update:
        _print_figures(rows, None, done.tolerance)
        print(f"\nwrote the baseline {baseline_path}: {len(rows)} runs ({result.seconds:.0f} s)")
        return 0
    _print_figures(rows, baseline, report.tolerance)
    improved = [f for f in report.findings if f.kind == "improved"]
    if improved:
        print(f"\nimproved beyond the tolerance ({len(improved)}; consider `salo regress --update`):")
        for f in improved:
            print(f"  {f.message()}")
    figures = len(report.tolerance.floors)
    if report.passed:
        print(f"\nregress PASSED: {len(rows)} runs x {figures} figures within tolerance of {baseline_path} "
              f"({result.seconds:.0f} s)")
        return 0
    print(f"\nregress FAILED against {baseline_path} ({len(report.failures)} problems):")
    for f in report.failures:
        print(f"  {f.message()}")
    print(f"(tolerance: baseline + max({report.tolerance.relative:.0%} of it, floor); run folders in {args.out}/runs)")
    return 1


def _print_figures(rows, baseline, tolerance) -> None:
    shown = [f for f in ("t_err_pct", "ate_aligned_rmse_m", "rpe_t_rmse_m") if f in tolerance.floors]
    header = f"{'run':40s} " + " ".join(f"{f:>24s}" for f in shown)
    print(header)
    for r in rows:
        base = (baseline or {}).get("runs", {}).get(r["label"], {})
        cells = []
        for f in shown:
            now, then = r.get(f), base.get(f)
            text = "failed" if r["status"] != "ok" else ("n/a" if now is None else f"{now:.4g}")
            if then is not None:
                text += f" (was {then:.4g})"
            cells.append(f"{text:>24s}")
        print(f"{r['label']:40s} " + " ".join(cells))
