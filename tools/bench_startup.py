"""Whole-command time of ``salo odometry`` against KISS-ICP's own command, on the same frames, interleaved.

    python -m tools.bench_startup SEQUENCE --frames 3,220 --repeat 5

A short run is mostly start-up (imports, the compiled kernels' loading from their cache); a long
one mostly registration. Each round runs every command once, in turn, on the first N frames of a
sequence folder (KITTI layout: KISS-ICP's generic loader reads its ``velodyne/*.bin``), so a
slow moment of the machine falls on all of them; the figure is each command's median wall time
over the rounds and its ratio to KISS-ICP's (below 1: faster). Also timed: ``salo --help`` and
``python -c "import odometry.pipeline"`` (what every run pays before its first scan).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def commands(sequence: Path, frames: int, out: Path) -> dict[str, list[str]]:
    """The commands timed for ``frames`` frames of ``sequence``, by name."""
    bin_dir = Path(sys.executable).parent
    kiss = shutil.which("kiss_icp_pipeline", path=str(bin_dir)) or shutil.which("kiss_icp_pipeline")
    out_cmds = {
        "salo odometry (default)": [sys.executable, "-m", "tools.cli", "odometry", str(sequence), "--frames",
                                    f"0:{frames}", "--out", str(out)],
    }
    if kiss:
        out_cmds["KISS-ICP (kiss_icp_pipeline)"] = [kiss, str(sequence / "velodyne"), "--n-scans", str(frames)]
    return out_cmds


def time_command(cmd: list[str], env: dict) -> float:
    """Wall time of one run, s; raises with its output when it fails."""
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return seconds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_startup", description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path, help="a sequence folder (KITTI layout) with enough frames")
    ap.add_argument("--frames", default="3,220", help="comma-separated frame counts (default 3,220)")
    ap.add_argument("--repeat", type=int, default=5, help="interleaved rounds (default 5)")
    args = ap.parse_args(argv)
    env = dict(os.environ)
    # (KISS-ICP writes its results under the working directory unless told otherwise)
    tmp = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    env["kiss_icp_out_dir"] = str(tmp / "kiss")
    try:
        fixed = {"salo --help": [sys.executable, "-m", "tools.cli", "--help"],
                 "import odometry.pipeline": [sys.executable, "-c", "import odometry.pipeline"]}
        times: dict[str, list[float]] = {name: [] for name in fixed}
        for _ in range(args.repeat):
            for name, cmd in fixed.items():
                times[name].append(time_command(cmd, env))
        print(f"{'command':32s} {'frames':>6s} {'median s':>9s} {'min s':>7s} {'x KISS-ICP':>10s}")
        for name in fixed:
            print(f"{name:32s} {'':>6s} {statistics.median(times[name]):9.2f} {min(times[name]):7.2f}")
        for n in (int(x) for x in args.frames.split(",")):
            runs: dict[str, list[float]] = {}
            for r in range(args.repeat):
                cmds = commands(args.sequence, n, tmp / f"salo-{n}-{r}")  # (a fresh output folder each run)
                for name, cmd in cmds.items():
                    runs.setdefault(name, []).append(time_command(cmd, env))
            kiss = runs.get("KISS-ICP (kiss_icp_pipeline)")
            ref = statistics.median(kiss) if kiss else float("nan")
            for name, t in runs.items():
                med = statistics.median(t)
                print(f"{name:32s} {n:6d} {med:9.2f} {min(t):7.2f} {med / ref:10.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
