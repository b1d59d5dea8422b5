"""Benchmark of the odometry: frames/s, time per stage and peak memory of each variant.

    python -m tools.bench_odometry                  # 150 frames of the city, salo32
    python -m tools.bench_odometry --frames 300 --scene highway

Simulates the sequence once (cached under out/bench/), then runs BL, NCF and SALO
over the same frames in this process, and the peers (KISS-ICP, GenZ-ICP, small_gicp
s2m; ``pip install -e '.[peer]'``) that are installed, on the same frames held in
memory, with SALO's time against each. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

from odometry.config import variant
from odometry.metrics import evaluate_trajectory
from odometry.pipeline import Odometry
from simlidar.dataset import open_sequence
from tools.experiments.peer import PEERS, peer_unavailable_reason, run_peer

STAGES = ("deskew", "voxel", "normals", "ncf_curvature", "match", "reject", "estimate")


def sequence(scene: str, frames: int, sensor: str, out: Path):
    """The benchmark's sequence (seed 0, from t = 5 s, the sensor's own noise), cached by its parameters."""
    from simlidar.sensor import load_sensor
    from tools.experiments.suite import SequenceSpec, ensure_sequence

    spec = SequenceSpec(scene, 0, frames, sensor, noise_std_m=load_sensor(sensor).range_noise_std_m, start_s=5.0)
    return open_sequence(ensure_sequence(spec, out, progress=True))


class FramesInMemory:
    """The frames of a sequence read once (what the peers' runners read: len, [k], sensor, poses, manifest)."""

    def __init__(self, seq, frames: list):
        self.frames = frames
        self.sensor, self.poses, self.manifest, self.path = seq.sensor, seq.poses, seq.manifest, seq.path

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, k: int):
        return self.frames[k]


def peak_memory_mb(seq, name: str, frames: int) -> float:
    """Peak traced allocation (numpy included) while registering ``frames`` frames."""
    frames_data = [seq[k] for k in range(frames)]
    odo = Odometry(variant(name), seq.sensor)
    tracemalloc.start()
    for k, f in enumerate(frames_data):
        odo.register_frame(f, stamp_s=float(seq.times[k]))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="city")
    ap.add_argument("--sensor", default="salo32")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--memory-frames", type=int, default=20)
    ap.add_argument("--out", type=Path, default=Path("out/bench"))
    args = ap.parse_args()
    seq = sequence(args.scene, args.frames, args.sensor, args.out)
    frames = [seq[k] for k in range(len(seq))]  # read once: time the odometry, not the disk
    print(f"{len(seq)} frames, {np.mean([len(f.points) for f in frames]):.0f} points per scan\n")
    header = f"{'variant':8s} {'frames/s':>8s} {'ms/frame':>8s} " + " ".join(f"{s:>9s}" for s in STAGES)
    print(header + f" {'peak MB':>8s} {'t_err %':>8s}")
    times = {}
    for name in ("bl", "ncf", "salo"):
        odo = Odometry(variant(name), seq.sensor)
        t = time.perf_counter()
        for k, f in enumerate(frames):
            odo.register_frame(f, stamp_s=float(seq.times[k]))
        dt = time.perf_counter() - t
        times[name] = dt
        per_stage = {s: 1000 * np.mean([d.seconds.get(s, 0.0) for d in odo.diagnostics[1:]]) for s in STAGES}
        m = evaluate_trajectory(seq.poses, np.stack(odo.poses))
        mem = peak_memory_mb(seq, name, args.memory_frames)
        print(f"{name:8s} {len(frames) / dt:8.1f} {1000 * dt / len(frames):8.1f} "
              + " ".join(f"{per_stage[s]:9.1f}" for s in STAGES) + f" {mem:8.0f} {m.t_err_pct:8.3f}")
    print("\n(stage columns: ms per frame; de-skew includes the refinements; peak MB is the traced "
          f"allocation peak over {args.memory_frames} frames)")
    # The peers, on the same frames in memory, with our range limits; sweep-start poses.
    cfg = variant("salo")
    in_memory = FramesInMemory(seq, frames)
    print()
    for name, spec in PEERS.items():
        reason = peer_unavailable_reason(name)
        if reason is not None:
            print(f"{spec.label}: {reason} - no timing")
            continue
        run = run_peer(name, in_memory, min_range_m=cfg.min_range_m, max_range_m=cfg.max_range_m)
        m = evaluate_trajectory(seq.poses, run.poses)
        print(f"{spec.label:15s} {run.frames_per_second:8.1f} frames/s, t_err {m.t_err_pct:.3f} %; "
              f"salo time / {spec.label} time = {times['salo'] / run.seconds:.2f}")


if __name__ == "__main__":
    main()
