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
        help="CI regression: a suite's errors against a committed baseline, ours or per method",
        description="Run a small fixed suite (short sequences in city, forest and highway) and compare each "
        "run's error figures with a baseline file. Fails (exit 1), naming the run, the figure and both values, "
        "when a figure grows past baseline + max(relative x baseline, floor); the tolerance is stored in the "
        "baseline file. --update writes the baseline from this run. Without --method: this project's variants "
        "against tools/regress_baseline.json. With --method NAME (repeatable): each method against a baseline "
        "of its own, DIR/SUITE/NAME.json (--baseline-dir; --baseline FILE for one method). A method is one of "
        "ours (bl, ncf, salo, bl-map, ncf-map, salo-map, default; --set changes them), a peer (kiss-icp, "
        "genz-icp, small-gicp), an installed plug-in (entry-point group salo.methods), or your program: "
        "--odometry-command with {scans} (the folder of .bin scans), {sensor} (sensor.yaml), {times} "
        "(times.txt), {fields} (per-point fields, --fields), {sequence} (the folder of all four) and {out} "
        "(the KITTI poses file to write). Every method gets a copy of the sensor data only: the ground "
        "truth is not in the folder it is handed.",
    )
    p.add_argument("--method", action="append", default=[], metavar="NAME",
                   help="guard this method against its own baseline (repeatable); with --odometry-command, the "
                   "name of your program's method")
    p.add_argument("--name", dest="method", action="append", help=argparse.SUPPRESS)  # the old flag of --method
    p.add_argument("--odometry-command", metavar="CMD",
                   help='your odometry, e.g. "my_odometry {scans} {sensor} {out}" (run through the shell); '
                   "needs --method NAME")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="change our configurations' parameters (with --method; dotted keys, `salo odometry --keys`)")
    p.add_argument("--fields", metavar="F,G",
                   help="per-point fields the methods are handed: of ring, time_s, azimuth_index, range_m, or "
                   "none (default: the suite's, ring,time_s)")
    p.add_argument("--baseline", type=Path,
                   help="baseline JSON (default: tools/regress_baseline.json; with --method, "
                   "BASELINE_DIR/SUITE/METHOD.json)")
    p.add_argument("--baseline-dir", type=Path, default=Path("regress-baselines"),
                   help="folder of the per-method baselines (default regress-baselines)")
    p.add_argument("--update", action="store_true", help="write the baseline(s) from this run's figures")
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

    from tools.methods import MethodError, check_command
    from tools.staging import StagingError, parse_fields
    from tools.sweep import SpecError, load_spec
    from tools.sweep.regress import (
        DEFAULT_BASELINE,
        BaselineError,
        check_suite,
        method_baseline_path,
        method_suite_spec,
        read_baseline,
        regress,
        regress_methods,
        suite_spec,
    )

    from .common import parse_config_set

    methods = list(dict.fromkeys(args.method))
    if args.odometry_command is not None:
        if len(methods) != 1:
            raise CommandError("--odometry-command needs one --method NAME: the name your method's baseline is "
                               f"kept under ({len(methods)} given)")
        try:
            check_command(args.odometry_command, "--odometry-command")
        except MethodError as exc:
            raise CommandError(str(exc)) from None
    if not methods and (args.set or args.fields):
        raise CommandError(f"{'--set' if args.set else '--fields'} applies to --method runs (this project's own "
                           "suite runs as its baseline was written)")
    if args.baseline is not None and len(methods) > 1:
        raise CommandError("--baseline names one method's file; with several --method, use --baseline-dir")
    try:
        suite = load_spec(args.suite) if args.suite else None
        if methods:
            commands = {methods[0]: args.odometry_command} if args.odometry_command else {}
            fields = parse_fields(args.fields) if args.fields is not None else None
            spec = method_suite_spec(methods, suite, commands, parse_config_set(args.set), fields)
        else:
            spec = suite_spec(suite)
        # regress simulates in memory and leaves no truth behind unless asked, whatever the suite's spec says
        spec = replace(spec, keep_sequences=args.keep_sequences,
                       sequences="disk" if args.keep_sequences else "memory")
        if methods:
            baselines = {m: args.baseline or method_baseline_path(m, spec.name, args.baseline_dir) for m in methods}
            documents = {}
            if not args.update:
                for m, path in baselines.items():  # fail before the work: missing, of another method or suite
                    documents[m] = read_baseline(path, m)
                    check_suite(documents[m], spec, str(path), m)
            with _sweeping(args, "regress") as (executor, callbacks):
                done = regress_methods(spec, args.out, executor, baselines, update=args.update,
                                       documents=documents, command_timeout_s=args.timeout, **callbacks)
            return _report_methods(done, baselines, args)
        baseline_path = args.baseline or DEFAULT_BASELINE
        baseline = None
        if not args.update:
            baseline = read_baseline(baseline_path)  # fail before the work: missing, or for another suite
            check_suite(baseline, spec, str(baseline_path))
        with _sweeping(args, "regress") as (executor, callbacks):
            done = regress(spec, args.out, executor, baseline_path, update=args.update, baseline=baseline,
                           command_timeout_s=args.timeout, **callbacks)
    except (SpecError, BaselineError, MethodError, StagingError) as exc:
        raise CommandError(str(exc)) from None
    print()
    if args.update:
        _print_figures(done.result.rows, None, done.tolerance)
        print(f"\nwrote the baseline {baseline_path}: {len(done.result.rows)} runs ({done.result.seconds:.0f} s)")
        return 0
    return 0 if _print_report(done.result.rows, baseline, done.report, str(baseline_path), done.result.seconds,
                              args.out) else 1


def _report_methods(done, baselines: dict, args) -> int:
    """Print each method's comparison (or the baselines written); the exit status."""
    ok = True
    for method, path in baselines.items():
        rows = [r for r in done.result.rows if r["variant"] == method]
        print(f"\n== method {method} (baseline {path})")
        if args.update:
            _print_figures(rows, None, done.tolerances[method])
            print(f"wrote the baseline {path}: {len(rows)} runs")
            continue
        report = done.reports[method]
        ok &= _print_report(rows, report.baseline, report, str(path), done.result.seconds, args.out, method)
    return 0 if ok else 1


def _print_report(rows, baseline, report, baseline_name: str, seconds: float, out, method: str | None = None) -> bool:
    """Print the figures and the verdict of one comparison; True when it passed."""
    _print_figures(rows, baseline, report.tolerance)
    what = f"regress {method}" if method else "regress"
    improved = [f for f in report.findings if f.kind == "improved"]
    if improved:
        print(f"\nimproved beyond the tolerance ({len(improved)}; consider `salo regress --update`):")
        for f in improved:
            print(f"  {f.message()}")
    figures = len(report.tolerance.floors)
    if report.passed:
        print(f"\n{what} PASSED: {len(rows)} runs x {figures} figures within tolerance of {baseline_name} "
              f"({seconds:.0f} s)")
        return True
    print(f"\n{what} FAILED against {baseline_name} ({len(report.failures)} problems):")
    for f in report.failures:
        print(f"  {f.message()}")
    print(f"(tolerance: baseline + max({report.tolerance.relative:.0%} of it, floor); run folders in {out}/runs)")
    return False


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
