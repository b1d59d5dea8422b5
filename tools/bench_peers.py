"""The peers on given sequences, in one process: KITTI error, per-frame RPE and frames/s of each.

    salo simulate --scene city --seed 3 --frames 150 --sensor hdl32e --out /tmp/city3
    salo simulate --scene city --seed 3 --frames 150 --sensor hdl32e --no-motion-distortion --out /tmp/city3-nd
    python -m tools.bench_peers /tmp/city3 /tmp/city3-nd

Every installed peer (``tools.peers``) runs over each sequence's frames, read into
memory first (the peers are timed, not the disk), through the one interface
(``tools.methods.run_method``: the sensor's view, no truth) with the odometry's
default range limits; its sweep-start poses are scored against the sequence's
ground truth (``odometry.metrics``). A sequence simulated with motion distortion
gives the peers per-point times; one simulated without (or without times) does not
(``tools.peers.scan_times``). Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from odometry.metrics import evaluate_trajectory
from simlidar.dataset import open_sequence
from tools.methods import PeerMethod, run_method
from tools.peers import PEERS


def read_into_memory(seq):
    """A sequence's frames read once into memory (``simlidar.in_memory.InMemorySequence``: points, per-point
    fields, poses, times, manifest), so that a method's clock measures the method, not the disk."""
    from simlidar.in_memory import InMemorySequence

    frames = [seq[k] for k in range(len(seq))]
    return InMemorySequence(seq.path, seq.sensor, [f.points for f in frames], [f.fields for f in frames],
                            seq.poses, seq.times, [], dict(getattr(seq, "manifest", None) or {}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequences", nargs="+", type=Path, help="sequence folders with ground truth")
    ap.add_argument("--peers", default=",".join(PEERS), help="comma-separated (default: %(default)s)")
    args = ap.parse_args()
    names = [n.strip() for n in args.peers.split(",") if n.strip()]
    unknown = [n for n in names if n not in PEERS]
    if unknown:
        ap.error(f"unknown peer {unknown[0]!r} (known: {', '.join(PEERS)})")
    print(f"{'sequence':12s} {'input':9s} {'peer':15s} {'instants':>9s} {'t_err %':>8s} {'r_err':>7s} "
          f"{'RPE t, cm':>9s} {'RPE r, deg':>10s} {'ATE, m':>7s} {'frames/s':>8s}")
    for folder in args.sequences:
        seq = open_sequence(folder)
        frames = read_into_memory(seq)
        for name in names:
            label, peer = PEERS[name].label, PeerMethod(name)
            reason = peer.unavailable()
            if reason is not None:
                print(f"{folder.name:12s} {'':9s} {label:15s} {reason}")
                continue
            run = run_method(peer, frames)
            m = evaluate_trajectory(seq.poses, run.poses)
            kind = "times" if run.settings["frames_with_times"] else "no times"
            print(f"{folder.name:12s} {kind:9s} {label:15s} {np.median(run.instants):9.2f} {m.t_err_pct:8.3f} "
                  f"{m.r_err_deg_per_100m:7.3f} {100 * np.mean(m.rpe.t_err_m):9.2f} "
                  f"{np.degrees(np.mean(m.rpe.r_err_rad)):10.4f} {np.sqrt(np.mean(m.ate_errors_m ** 2)):7.3f} "
                  f"{run.frames_per_second:8.1f}")
    print("\n(instants: the median pose instant, sweep periods after the sweep start; r_err: deg per 100 m; "
          "RPE: consecutive frames, mean; ATE: RMSE, unaligned)")


if __name__ == "__main__":
    main()
