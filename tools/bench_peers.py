"""The peers on given sequences, in one process: KITTI error, per-frame RPE and frames/s of each.

    salo simulate --scene city --seed 3 --frames 150 --sensor hdl32e --out /tmp/city3
    salo simulate --scene city --seed 3 --frames 150 --sensor hdl32e --no-motion-distortion --out /tmp/city3-nd
    python -m tools.bench_peers /tmp/city3 /tmp/city3-nd

Every installed peer (``tools.experiments.peer``) runs over each sequence's frames,
read into memory first, with the odometry's default range limits; its sweep-start
poses are scored against the sequence's ground truth (``odometry.metrics``). A
sequence simulated with motion distortion gives the peers per-point times; one
simulated without (or without times) does not (``peer.scan_times``). Prints
figures; asserts nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from odometry.config import variant
from odometry.metrics import evaluate_trajectory
from simlidar.dataset import open_sequence
from tools.experiments.peer import PEERS, peer_unavailable_reason, run_peer


class FramesInMemory:
    """A sequence's frames read once, so that the peers' times exclude reading (what their runners read:
    ``len``, ``[k]``, ``sensor``, ``poses``, ``times``, ``manifest``, ``path``)."""

    def __init__(self, seq, frames: list):
        self.frames = frames
        self.sensor, self.poses, self.times, self.manifest, self.path = (seq.sensor, seq.poses, seq.times,
                                                                        seq.manifest, seq.path)

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, k: int):
        return self.frames[k]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequences", nargs="+", type=Path, help="sequence folders with ground truth")
    ap.add_argument("--peers", default=",".join(PEERS), help="comma-separated (default: %(default)s)")
    args = ap.parse_args()
    names = [n.strip() for n in args.peers.split(",") if n.strip()]
    unknown = [n for n in names if n not in PEERS]
    if unknown:
        ap.error(f"unknown peer {unknown[0]!r} (known: {', '.join(PEERS)})")
    cfg = variant("salo")
    print(f"{'sequence':12s} {'input':9s} {'peer':15s} {'instants':>9s} {'t_err %':>8s} {'r_err':>7s} "
          f"{'RPE t, cm':>9s} {'RPE r, deg':>10s} {'ATE, m':>7s} {'frames/s':>8s}")
    for folder in args.sequences:
        seq = open_sequence(folder)
        frames = FramesInMemory(seq, [seq[k] for k in range(len(seq))])  # read once: time the methods
        for name in names:
            label = PEERS[name].label
            reason = peer_unavailable_reason(name)
            if reason is not None:
                print(f"{folder.name:12s} {'':9s} {label:15s} {reason}")
                continue
            run = run_peer(name, frames, min_range_m=cfg.clean.min_range_m, max_range_m=cfg.clean.max_range_m)
            m = evaluate_trajectory(seq.poses, run.poses)
            kind = "times" if run.config["frames_with_times"] else "no times"
            print(f"{folder.name:12s} {kind:9s} {label:15s} {np.median(run.instants):9.2f} {m.t_err_pct:8.3f} "
                  f"{m.r_err_deg_per_100m:7.3f} {100 * np.mean(m.rpe.t_err_m):9.2f} "
                  f"{np.degrees(np.mean(m.rpe.r_err_rad)):10.4f} {np.sqrt(np.mean(m.ate_errors_m ** 2)):7.3f} "
                  f"{run.frames_per_second:8.1f}")
    print("\n(instants: the median pose instant, sweep periods after the sweep start; r_err: deg per 100 m; "
          "RPE: consecutive frames, mean; ATE: RMSE, unaligned)")


if __name__ == "__main__":
    main()
