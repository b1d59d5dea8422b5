"""The default odometry with and without the IMU, against the truth, over sequences that have one.

    python -m tools.imu_odometry SEQUENCE [SEQUENCE ...] [--variant salo-map] [--frames A:B]
                                 [--lidar-only bl,ncf,salo,kiss-icp,genz-icp,small-gicp]

Runs the variant lidar-only and with ``imu.enabled=true`` on each simulated sequence folder, and
the ``--lidar-only`` methods (ours or the peers, by ``tools.methods`` name) lidar-only on the first
(through ``tools.methods.run_method``: the method gets the staged copy, scans, times, the sensor
file and ``imu.csv``, never the truth), and prints per run: the KITTI t_err (%), the ATE (m, RMSE,
unaligned: both start at the identity) and the error over the weak stretch: the longest run of
frames the simulator's degeneracy truth flags (``degeneracy.csv``), and the translation error of
the estimated motion from its first frame to its last (m; along the stretch's weakest direction
too) and the largest over its frames (each frame's motion from the stretch's first).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class StretchError:
    """The error over frames ``first``..``last`` (inclusive): ``end_m`` of the motion from first to last,
    ``along_m`` its component along ``direction`` (3,) (the stretch's mean weakest direction, first frame's
    axes), ``max_m`` the largest over the stretch's frames."""

    first: int
    last: int
    end_m: float
    along_m: float
    max_m: float
    direction: np.ndarray


def stretch_error(T_gt: np.ndarray, T_est: np.ndarray, first: int, last: int, direction: np.ndarray) -> StretchError:
    """``StretchError`` of (N, 4, 4) poses over frames first..last; ``direction`` (3,) in the lidar frame."""
    from simlidar import se3

    errs = []
    for k in range(first, last + 1):
        gt = se3.inverse(T_gt[first]) @ T_gt[k]
        est = se3.inverse(T_est[first]) @ T_est[k]
        errs.append(est[:3, 3] - gt[:3, 3])  # (in the first frame's axes, as the estimate holds them)
    errs = np.array(errs)
    u = direction / np.linalg.norm(direction)
    return StretchError(first, last, float(np.linalg.norm(errs[-1])), float(errs[-1] @ u),
                        float(np.linalg.norm(errs, axis=1).max()), u)


def weak_stretch(sequence_path: Path, frames: np.ndarray):
    """The longest run of truth-weak frames among ``frames`` (indices into the run), as (first, last, direction)."""
    from tools.degenerate import truth_constraints

    truth = truth_constraints(sequence_path)
    weak = np.zeros(len(frames), dtype=bool)
    index = {int(f): i for i, f in enumerate(truth.frames)}
    dirs = np.zeros((len(frames), 3))
    for i, f in enumerate(frames):
        j = index.get(int(f))
        if j is not None:
            weak[i], dirs[i] = bool(truth.weak[j]), truth.directions[j]
    best, start = None, None
    for i, w in enumerate([*weak, False]):
        if w and start is None:
            start = i
        elif not w and start is not None:
            if best is None or i - start > best[1] - best[0] + 1:
                best = (start, i - 1)
            start = None
    if best is None:
        return None
    d = dirs[best[0]:best[1] + 1]
    d = d * np.sign(d @ d[0])[:, None]  # (a direction, not an arrow: one sign)
    return best[0], best[1], d.mean(axis=0)


def measure(path: Path, variant: str, frames: slice | None, lidar_only: tuple[str, ...] = ()
            ) -> list[tuple[str, dict]]:
    """Lidar-only and with the IMU on one sequence folder, then each of ``lidar_only``'s methods (names of
    ``tools.methods``; their IMU unused): (label, figures) each."""
    from odometry.config import variant as variant_config
    from odometry.metrics import evaluate_trajectory
    from simlidar.dataset import open_sequence
    from tools.methods import OursMethod, method_from_name, method_label, run_method

    seq = open_sequence(path)
    if getattr(seq, "imu", None) is None:
        raise SystemExit(f"{path}: the sequence has no IMU (imu.csv): simulate it with --imu")
    idx = np.arange(len(seq))[frames or slice(None)]
    T_gt = np.asarray(seq.poses)[idx]
    T_gt = np.linalg.inv(T_gt[0]) @ T_gt
    stretch = weak_stretch(path, idx)
    base = variant_config(variant)
    runs = [("lidar only", OursMethod(variant, base)),
            ("with the IMU", OursMethod(variant, base.replace(imu={"enabled": True}))),
            *((f"{method_label(name)}, lidar only", method_from_name(name)) for name in lidar_only)]
    out = []
    for label, method in runs:
        run = run_method(method, seq, frames=frames, keep_failures=True)
        if not run.ok:
            out.append((label, {"error": run.error}))
            continue
        m = evaluate_trajectory(T_gt, run.poses)
        fig = {"t_err_pct": m.t_err_pct, "ate_m": float(np.sqrt(np.mean(m.ate_errors_m**2))),
               "seconds": run.seconds, "flagged": int(np.sum(run.degenerate)) if run.degenerate is not None else "-"}
        if stretch is not None:
            s = stretch_error(T_gt, run.poses, *stretch)
            fig.update(stretch=f"{idx[s.first]}-{idx[s.last]}", stretch_end_m=s.end_m, stretch_along_m=s.along_m,
                       stretch_max_m=s.max_m)
        out.append((label, fig))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.imu_odometry", description=__doc__.split("\n\n")[0])
    ap.add_argument("sequences", nargs="+", type=Path)
    ap.add_argument("--variant", default="salo-map")
    ap.add_argument("--frames", help="frame range A:B")
    ap.add_argument("--lidar-only", default="", help="comma-separated methods run lidar-only on the first sequence "
                    "(ours or the peers: bl, ncf, salo, kiss-icp, genz-icp, small-gicp)")
    args = ap.parse_args(argv)
    others = tuple(m.strip() for m in args.lidar_only.split(",") if m.strip())
    frames = slice(*[int(x) if x else None for x in args.frames.split(":")]) if args.frames else None
    print("| sequence | run | t_err % | ATE m | weak stretch (frames) | its end error m | along its axis m "
          "| its largest m | frames flagged |")
    print("|---|---|---|---|---|---|---|---|---|")
    for i, path in enumerate(args.sequences):
        for label, f in measure(path, args.variant, frames, others if i == 0 else ()):
            if "error" in f:
                print(f"| {path.name} | {label} | failed: {f['error']} |", flush=True)
                continue
            print(f"| {path.name} | {label} | {f['t_err_pct']:.2f} | {f['ate_m']:.2f} | {f.get('stretch', '-')} | "
                  f"{f.get('stretch_end_m', float('nan')):.2f} | {f.get('stretch_along_m', float('nan')):+.2f} | "
                  f"{f.get('stretch_max_m', float('nan')):.2f} | {f['flagged']} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
