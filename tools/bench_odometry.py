"""Benchmark of the odometry against the peers: frames/s, time per stage, peak memory, accuracy.

    python -m tools.bench_odometry                           # 100 frames of the city, salo32 and hdl32e
    python -m tools.bench_odometry --frames 200 --scene suburb --sensors hdl32e
    python -m tools.bench_odometry --methods kiss-icp,salo,default --set map.min_point_spacing_m=0
    python -m tools.bench_odometry --methods kiss-icp,default,salo --repeat 3   # 3 interleaved rounds, medians
    python -m tools.bench_odometry --prefetch both   # ours also on one thread (no scan prepared ahead)

For each sensor the sequence is simulated once into memory (``simlidar.in_memory``,
motion distortion on, per-point times given) and its sensor's view (``tools.staging.sensor_view``:
no truth) is what every method gets, through the one interface (``tools.methods.run_method``);
every variant of ours (the paper's scan-to-scan BL / NCF / SALO, their scan-to-map
twins, and the default configuration) and every installed peer (KISS-ICP,
GenZ-ICP, small_gicp s2m; ``pip install -e '.[peer]'``) runs over the same frames
in this process (after an untimed warm-up of three frames that loads our compiled
kernels), one after the other (``--repeat N``: N rounds of that, interleaved,
and the medians). Printed per method: frames/s, its time against KISS-ICP's in the
same round (the ratio: below 1 is faster), ms per stage, peak traced
memory over ``--memory-frames`` frames, and KITTI t_err (over 10-50 m segments on a
path shorter than 100 m, marked *) so that a speed-up that costs accuracy shows.
Speed is a ratio measured in the same run: this machine is shared and its
absolute figures drift. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import tracemalloc

import numpy as np

from odometry.config import DEFAULT_VARIANT, ConfigError, changes_from_assignments, config_from_dict, variant
from odometry.diagnostics import STAGES
from odometry.metrics import evaluate_trajectory
from tools.methods import OursMethod, PeerMethod, run_method
from tools.peers import PEERS

OURS = ("bl", "ncf", "salo", "bl-map", "ncf-map", "salo-map")
REFERENCE_PEER = "kiss-icp"
# --prefetch: which ways each of ours runs (``odometry.pipeline.register_frames``)
PREFETCH_CHOICES = {"on": (None,), "off": (0,), "both": (None, 0)}


def simulate(scene: str, sensor: str, frames: int, seed: int = 0, start_s: float = 5.0):
    """The benchmark's frames in memory: scene ``scene`` (seed 0) from ``start_s`` along its path."""
    from scenes import build_scene
    from simlidar.in_memory import simulate_in_memory
    from simlidar.sensor import load_sensor
    from tools.worlds import world_of_scene

    s = build_scene(scene, seed=seed)
    world = world_of_scene(s, f"scene:{scene}")
    return simulate_in_memory(world, s.trajectory, load_sensor(sensor), frames, seed=seed, t_start=start_s,
                              name=f"{scene}-{sensor}")


# Segment lengths for a path shorter than KITTI's shortest segment (100 m), m.
SHORT_SEGMENTS_M = (10.0, 20.0, 30.0, 40.0, 50.0)


def t_err_pct(T_gt: np.ndarray, T_est: np.ndarray) -> tuple[float, bool]:
    """(KITTI t_err %, short): over KITTI's 100-800 m segments, or, on a path too short for
    them (short True), over 10-50 m segments (``SHORT_SEGMENTS_M``): not comparable with a
    KITTI figure, but a speed-up that costs accuracy still shows. T_gt, T_est: (F, 4, 4)."""
    t_err = evaluate_trajectory(T_gt, T_est).t_err_pct
    if np.isfinite(t_err):
        return t_err, False
    return evaluate_trajectory(T_gt, T_est, lengths_m=SHORT_SEGMENTS_M).t_err_pct, True


def run_ours(view, name: str, frames: int | None = None, changes: dict | None = None,
             prefetch: int | None = None) -> tuple[np.ndarray, float, dict]:
    """Poses (F, 4, 4), seconds and mean ms per stage of variant ``name`` over the first ``frames`` frames of
    ``view`` (default all; a sensor's view, read as it is). changes: parameters changed (``--set``), nested
    by stage as a config YAML holds them. prefetch: scans prepared ahead (``OursMethod``).

    The clock runs over the frame loop, reading each frame and working out its per-point times included,
    as it does for the peers (``tools.peers.run_frames``)."""
    method = OursMethod(name, config_from_dict(changes or {}, base=variant(name)), prefetch=prefetch)
    run = run_method(method, view, stage=False, frames=None if frames is None else slice(0, frames))
    stages = {s: 1000 * np.mean([d.seconds.get(s, 0.0) for d in run.diagnostics[1:]]) for s in STAGES}
    return run.poses, run.seconds, stages


def peak_memory_mb(view, name: str, frames: int, changes: dict | None = None, prefetch: int | None = None) -> float:
    """Peak traced allocation (numpy included) while registering ``frames`` frames (slows the run: apart)."""
    tracemalloc.start()
    run_ours(view, name, frames, changes, prefetch)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 1e6


def bench(scene: str, sensor: str, frames: int, memory_frames: int, only: set[str] | None = None,
          changes: dict | None = None, repeat: int = 1, prefetch: tuple[int | None, ...] = (None,)) -> None:
    """Run every method over the same frames ``repeat`` times, interleaved (one round runs each
    method once), and print one row per method: median frames/s, median over rounds of its time
    over KISS-ICP's in the same round (a machine whose speed drifts moves both alike), t_err and
    stage times (ms per frame, median over rounds). prefetch: each of ours runs once per value, with
    that many scans prepared ahead on threads of their own (``register_frames``; 0: one thread; None:
    as ``salo odometry`` runs it)."""
    from tools.staging import sensor_view

    seq = simulate(scene, sensor, frames)
    view = sensor_view(seq)  # what every method gets: the sensor's data, made once
    points = np.mean([len(p) for p in seq.points])
    path_m = float(evaluate_trajectory(seq.poses, seq.poses).path_length_m)
    print(f"\n## {scene}, {sensor}: {len(seq)} frames, {points:,.0f} points per scan, {path_m:.0f} m"
          + (f", {repeat} interleaved rounds" if repeat > 1 else ""))
    methods = []  # (label, run() -> (poses, seconds, stages or None))
    ahead = {}  # label -> scans prepared ahead (ours)
    for name, spec in PEERS.items():
        if only and name not in only:
            continue
        peer = PeerMethod(name)  # on our default configuration's range limits
        reason = peer.unavailable()
        if reason is not None:
            print(f"{spec.label}: {reason}")
            continue

        def run_a_peer(peer=peer):
            run = run_method(peer, view, stage=False)
            return run.poses, run.seconds, None

        methods.append((spec.label, name, run_a_peer))
    for name in (*OURS, "default"):
        if only and name not in only:
            continue
        v = DEFAULT_VARIANT if name == "default" else name
        for p in prefetch:
            how = "" if p is None else ", 1 thread" if p == 0 else f", {p} ahead"
            label = (f"default ({v})" if name == "default" else name) + how
            methods.append((label, v, lambda v=v, p=p: run_ours(view, v, changes=changes, prefetch=p)))
            ahead[label] = p
        # (a warm-up on three frames, untimed: the compiled kernels are loaded, or compiled on a
        # fresh install, before the clock runs, as the peers' code is compiled ahead)
        run_ours(view, v, frames=min(3, len(seq)), changes=changes)
    seconds = {label: [] for label, _, _ in methods}
    stages, errors = {}, {}
    for _ in range(repeat):
        for label, _, run in methods:
            poses, spent, per_stage = run()
            seconds[label].append(spent)
            errors[label] = t_err_pct(seq.poses, poses)
            if per_stage is not None:
                stages.setdefault(label, []).append(per_stage)
    reference = next((label for label, name, _ in methods if name == REFERENCE_PEER), None)
    header = (f"{'method':18s} {'frames/s':>8s} {'/KISS':>6s} {'t_err %':>8s} {'peak MB':>8s} "
              + " ".join(f"{s:>8s}" for s in (*STAGES, "other")))
    print(header)
    for label, v, _ in methods:
        spent = float(np.median(seconds[label]))
        ratio = (f"{np.median(np.array(seconds[label]) / np.array(seconds[reference])):6.2f}" if reference
                 else "   n/a")
        t_err = errors[label]
        line = f"{label:18s} {len(seq) / spent:8.1f} {ratio} {t_err[0]:7.3f}{'*' if t_err[1] else ' '} "
        if label not in stages:
            print(line + f"{'':>8s}")
            continue
        per_stage = {s: float(np.median([r[s] for r in stages[label]])) for s in STAGES}
        mem = peak_memory_mb(view, v, memory_frames, changes, ahead[label]) if memory_frames > 0 else float("nan")
        other = 1000 * spent / len(seq) - sum(per_stage.values())
        print(line + f"{mem:8.0f} " + " ".join(f"{per_stage[s]:8.1f}" for s in STAGES) + f" {other:8.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="city")
    ap.add_argument("--sensors", default="salo32,hdl32e", help="comma-separated presets (default salo32,hdl32e)")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=1, help="rounds, each running every method once (interleaved); "
                    "medians are printed (default 1)")
    ap.add_argument("--memory-frames", type=int, default=20, help="frames of the peak-memory run (0: none)")
    ap.add_argument("--methods", default="", help="comma-separated subset of the methods (default: all); "
                    "kiss-icp is the ratios' reference")
    ap.add_argument("--prefetch", choices=PREFETCH_CHOICES, default="on",
                    help="ours with the next scans prepared ahead on threads of their own (on, as salo "
                    "odometry runs), on one thread (off), or a row of each (both)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="an odometry parameter changed for every variant of ours (dotted, repeatable)")
    args = ap.parse_args()
    try:
        changes = changes_from_assignments(args.set)
    except ConfigError as exc:
        ap.error(str(exc))
    if args.memory_frames < 0 or args.frames < 2 or args.repeat < 1:
        ap.error("--frames must be at least 2, --memory-frames at least 0 and --repeat at least 1")
    only = {m.strip() for m in args.methods.split(",") if m.strip()} or None
    known = {*PEERS, *OURS, "default"}
    if only and only - known:
        ap.error(f"unknown method(s) {', '.join(sorted(only - known))} (known: {', '.join(sorted(known))})")
    for sensor in args.sensors.split(","):
        bench(args.scene, sensor.strip(), args.frames, args.memory_frames, only, changes, args.repeat,
              PREFETCH_CHOICES[args.prefetch])
    print("\n(/KISS: the method's time over KISS-ICP's on the same frames in this run, below 1 = faster; stage "
          "columns: ms per frame, 'other' the rest (cleaning, waiting for a k-d tree; negative when the next "
          "scans' voxel grid, normals and NCF, prepared ahead on other threads, took longer than the wait for them); "
          "', 1 thread': without that prefetch; the de-skew includes "
          "the refinements; peak MB: traced allocation peak over the first --memory-frames frames; t_err %: "
          "KITTI's, over 100-800 m segments; *: the path is shorter than 100 m, over 10-50 m segments)")


if __name__ == "__main__":
    main()
