"""Benchmark of the scenes: build time, size, and simulator speed in each default scene.

    python -m tools.bench_scenes                  # every scene, salo32, 20 sweeps each
    python -m tools.bench_scenes --scenes city tunnel --sweeps 50 --sensor hdl64e

Per scene: build time (best of ``--repeat``), triangles, objects, path length,
trajectory duration and 10 Hz frames, BVH build time, sweeps per second along
the trajectory (motion distortion on, as ``salo simulate`` runs), and the mean
share of rays that return. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import scenes
from simlidar.sensor import load_sensor
from simlidar.sweep import SweepSimulator
from tools.worlds import world_of_scene


def bench_scene(name: str, sensor_name: str, sweeps: int, repeat: int, seed: int) -> dict:
    builds = []
    for _ in range(repeat):
        t = time.perf_counter()
        scene = scenes.build_scene(name, seed=seed)
        builds.append(time.perf_counter() - t)
    world = world_of_scene(scene, name)
    sensor = load_sensor(sensor_name)
    t = time.perf_counter()
    sim = SweepSimulator(world, sensor, seed=seed)
    bvh_s = time.perf_counter() - t
    traj = scene.trajectory
    starts = np.linspace(0.05, 0.95, sweeps) * (traj.duration_s - sensor.sweep_period_s)
    sim.sweep(traj, float(starts[0]))  # warm-up (thread pool, caches)
    points = 0
    t = time.perf_counter()
    for k, t0 in enumerate(starts):
        points += len(sim.sweep(traj, float(t0), frame_index=k))
    sweep_s = time.perf_counter() - t
    return {
        "scene": name,
        "build_s": min(builds),
        "triangles": scene.n_triangles,
        "objects": len(scene.object_labels),
        "path_m": float(np.linalg.norm(np.diff(scene.path, axis=0), axis=1).sum()),
        "duration_s": traj.duration_s,
        "frames": int(traj.duration_s * sensor.rotation_hz),
        "bvh_s": bvh_s,
        "sweeps_per_s": sweeps / sweep_s,
        "return_share": points / (sweeps * sensor.rays_per_sweep),
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=list(scenes.SCENES), help="scenes (default: all)")
    ap.add_argument("--sensor", default="salo32", help="sensor preset (default salo32)")
    ap.add_argument("--sweeps", type=int, default=20, help="sweeps timed per scene (default 20)")
    ap.add_argument("--repeat", type=int, default=2, help="builds timed per scene, best kept (default 2)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows = [bench_scene(n, args.sensor, args.sweeps, args.repeat, args.seed) for n in args.scenes]
    header = (f"{'scene':8s} {'build s':>8s} {'triangles':>10s} {'objects':>8s} {'path m':>8s} "
              f"{'traj s':>7s} {'frames':>7s} {'bvh s':>6s} {args.sensor + ' sweeps/s':>16s} {'returns':>8s}")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['scene']:8s} {r['build_s']:8.2f} {r['triangles']:10d} {r['objects']:8d} {r['path_m']:8.0f} "
              f"{r['duration_s']:7.1f} {r['frames']:7d} {r['bvh_s']:6.2f} {r['sweeps_per_s']:16.1f} "
              f"{r['return_share']:8.2f}")


if __name__ == "__main__":
    main()
