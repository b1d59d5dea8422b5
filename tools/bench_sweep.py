"""Sweep throughput on this machine: runs per minute with 1 and 2 local workers, and Dask's overhead.

    .venv/bin/python -m tools.bench_sweep                 # 8 runs: city x 2 seeds x 2 noise x bl/salo, VLP-16
    .venv/bin/python -m tools.bench_sweep --frames 40 --sensor salo32

Every configuration sweeps the same small spec into a fresh folder (nothing
cached), so each one simulates its sequences and runs every odometry. The
Dask figure uses a ``LocalCluster`` with as many single-threaded worker
processes as the local executor it is compared with; its start-up time is
printed apart (a real cluster is started once, not per sweep).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from tools.sweep import DaskExecutor, InlineExecutor, LocalExecutor, run_sweep, spec_from_dict


def _sweep(spec, executor, root: Path, name: str) -> float:
    t0 = time.perf_counter()
    result = run_sweep(spec, root / name, executor, report=False)
    seconds = time.perf_counter() - t0
    if result.failures:
        raise SystemExit(f"{name}: {len(result.failures)} runs failed, e.g. {result.failures[0]['error']}")
    return seconds


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=20, help="frames per sequence (default 20)")
    p.add_argument("--sensor", default="vlp16", help="sensor preset (default vlp16)")
    p.add_argument("--scene", default="city", help="scene (default city)")
    p.add_argument("--no-dask", action="store_true", help="skip the Dask measurement")
    args = p.parse_args(argv)

    spec = spec_from_dict({"name": "bench", "scenes": [args.scene], "seeds": [0, 1], "sensors": [args.sensor],
                           "noise_std_m": [0.01, 0.03], "variants": ["bl", "salo"], "frames": args.frames})
    runs = len(spec.runs())
    print(f"sweep: {runs} runs ({args.scene}, 2 seeds x 2 noise levels x bl/salo, {args.sensor}, "
          f"{args.frames} frames, 4 sequences simulated)")
    print(f"{'executor':28s} {'seconds':>8s} {'runs/min':>9s}")
    times = {}
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as tmp:
        root = Path(tmp)
        configs = [("in-process (no pool)", InlineExecutor()), ("local, 1 worker", LocalExecutor(1)),
                   ("local, 2 workers", LocalExecutor(2))]
        for name, executor in configs:
            times[name] = _sweep(spec, executor, root, name.replace(" ", "_").replace(",", ""))
            print(f"{name:28s} {times[name]:8.1f} {60 * runs / times[name]:9.1f}", flush=True)
        if not args.no_dask:
            from distributed import LocalCluster

            t0 = time.perf_counter()
            with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
                startup = time.perf_counter() - t0
                name = "dask LocalCluster, 2 workers"
                times[name] = _sweep(spec, DaskExecutor(cluster.scheduler_address), root, "dask")
            print(f"{name:28s} {times[name]:8.1f} {60 * runs / times[name]:9.1f}")
            local = times["local, 2 workers"]
            print(f"\nDask overhead against the local executor (2 workers each): {times[name] - local:+.1f} s "
                  f"({(times[name] / local - 1) * 100:+.0f} %) per sweep of {runs} runs; "
                  f"cluster start-up {startup:.1f} s (not included)")
    speedup = times["local, 1 worker"] / times["local, 2 workers"]
    print(f"2 workers against 1: {speedup:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
