"""The ``salo`` command line: thin commands over library calls.

Heavy imports (Embree, matplotlib, pyvista) happen inside the commands that
need them, so ``salo --help`` is instant.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from simlidar.sensor import SensorError, load_sensor, preset_names
from simlidar.sequence import DatasetError
from tools.argtypes import real_number, whole_number

# Errors that are the user's input, reported in one line without a traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (SensorError, DatasetError, FileExistsError)


class CommandError(Exception):
    """A command cannot proceed; the message says why."""


def _progress(total: int, unit: str, desc: str):
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, dynamic_ncols=True, file=sys.stderr)


# ---------------------------------------------------------------- simulate
def _add_simulate(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a lidar sequence (KITTI layout + ground-truth sidecar)",
        description="Simulate consecutive sweeps of a spinning lidar along a path through a "
        "world, and write them as a sequence folder (KITTI odometry layout, sensor.yaml, "
        "manifest and per-point ground truth).",
    )
    p.add_argument("--scene", help="procedural scene (see `salo scenes`); or give --mesh and --poses")
    p.add_argument("--set", dest="scene_overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene parameter (repeatable); --set seed=N is the seed")
    p.add_argument("--scene-params", type=Path,
                   help="YAML file of scene parameters (as `salo scenes NAME --yaml` writes; its seed is the seed)")
    p.add_argument("--speed", type=real_number(0.0, above=True), help="cruise speed along the scene's path, m/s")
    p.add_argument("--start", type=real_number(0.0),
                   help="time along the scene's path of the first sweep, s (default 0)")
    world = p.add_argument_group("your own world and path (instead of --scene)")
    world.add_argument("--mesh", type=Path, help="world mesh: PLY, OBJ, GLB or STL")
    world.add_argument(
        "--poses",
        type=Path,
        help="KITTI-format lidar poses in the mesh's frame, one per sweep start "
        "(interpolated on SE(3) in between)",
    )
    world.add_argument("--times", type=Path, help="times of the --poses lines, s (default: 1/rate apart)")
    world.add_argument(
        "--extrapolate",
        action="store_true",
        help="allow --frames beyond the last pose: continue the last pose interval's velocity "
        "(recorded in the manifest); without it that is an error",
    )
    world.add_argument(
        "--strict-inside-check",
        action="store_true",
        help="refuse a pose whose probe rays mostly hit back faces, as for a procedural scene (by default a "
        "--mesh only warns: rooms with outward normals and meshes with inconsistent normals look like that)",
    )
    p.add_argument("--sensor", default="salo32", help=f"preset ({', '.join(preset_names())}) or YAML file")
    p.add_argument("--frames", type=whole_number(1),
                   help="number of sweeps (default: as many as the poses cover, one per pose without --times; "
                   "100 along a scene)")
    p.add_argument("--seed", type=whole_number(0),
                   help="seed of the noise, and of a --scene (default 0, or the scene parameters' seed)")
    p.add_argument("--noise-std", type=real_number(0.0),
                   help="range noise standard deviation, m (overrides the sensor)")
    p.add_argument(
        "--no-motion-distortion",
        dest="motion_distortion",
        action="store_false",
        help="fire every ray of a sweep from the sweep's start pose",
    )
    p.add_argument("--out", type=Path, required=True, help="output sequence folder")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.set_defaults(func=cmd_simulate)


def _sensor_from_args(args):
    sensor = load_sensor(args.sensor)
    if getattr(args, "noise_std", None) is not None:
        sensor = sensor.with_overrides(range_noise_std_m=args.noise_std)
    return sensor


def cmd_simulate(args) -> int:
    if args.scene is not None:
        if args.mesh is not None or args.poses is not None:
            raise CommandError("give either --scene or --mesh/--poses, not both")
        for flag, given in (("--times", args.times is not None), ("--extrapolate", args.extrapolate)):
            if given:
                raise CommandError(f"{flag} applies to --mesh/--poses, not to --scene")
        return _simulate_scene(args, _sensor_from_args(args))
    if args.mesh is None or args.poses is None:
        raise CommandError("give --scene NAME, or --mesh FILE and --poses FILE")
    for flag, given in (("--set", bool(args.scene_overrides)), ("--scene-params", args.scene_params is not None),
                        ("--speed", args.speed is not None), ("--start", args.start is not None)):
        if given:
            raise CommandError(f"{flag} applies to --scene, not to --mesh/--poses")
    return _simulate_mesh(args, _sensor_from_args(args))


def _simulate_mesh(args, sensor) -> int:
    import numpy as np

    from simlidar.formats.atomic import sha256_file
    from simlidar.formats.kitti import read_kitti_poses, read_times
    from simlidar.trajectory import SampledTrajectory
    from simlidar.world import load_world

    world = load_world(args.mesh)
    poses = read_kitti_poses(args.poses)
    if args.times is not None:
        times = read_times(args.times)
        if len(times) != len(poses):
            raise DatasetError(f"{args.times}: {len(times)} times for {len(poses)} poses in {args.poses}")
    else:
        times = sensor.sweep_period_s * np.arange(len(poses))
    try:
        trajectory = SampledTrajectory(times, poses)
    except ValueError as exc:
        raise DatasetError(f"{args.times or args.poses}: {exc}") from None
    fit = _sweeps_covered(times, sensor)
    frames = args.frames if args.frames is not None else fit
    info = {
        "command": "simulate",
        "mesh": str(args.mesh.resolve()),
        "mesh_sha256": sha256_file(args.mesh),
        "poses_file": str(args.poses.resolve()),
    }
    if args.times is not None:
        info["times_file"] = str(args.times.resolve())
    beyond = _beyond_last_pose(times, sensor, frames)
    if beyond > 0:
        need = times[0] + (frames - 1) * sensor.sweep_period_s
        numbers = (f"{len(poses)} poses cover {times[-1] - times[0]:.1f} s; "
                   f"{frames} frames need {need - times[0]:.1f} s")
        if not args.extrapolate:
            raise CommandError(f"{args.poses}: {numbers} (at most {fit} frames fit: lower --frames, give more "
                               "poses, or --extrapolate to continue the last pose interval's velocity)")
        print(f"extrapolating {beyond:.1f} s beyond the last pose ({numbers})", file=sys.stderr)
        info["extrapolated"] = {"poses_cover_s": round(float(times[-1] - times[0]), 9),
                                "frames_need_s": round(float(need - times[0]), 9),
                                "beyond_last_pose_s": round(float(beyond), 9),
                                "method": "constant velocity of the last pose interval"}
    return _run_simulation(world, trajectory, sensor, args, frames, info, where=str(args.poses),
                           t_start=float(times[0]), seed=0 if args.seed is None else args.seed,
                           strict_inside=True if args.strict_inside_check else None)


def _sweeps_covered(times, sensor) -> int:
    """How many sweeps, one period apart from ``times[0]``, start within the pose times (N,) s."""
    return int((times[-1] - times[0]) / sensor.sweep_period_s + 1e-9) + 1


def _beyond_last_pose(times, sensor, frames: int) -> float:
    """How far the last sweep's start lies beyond the last pose time, s (0 when the poses cover every frame).

    times: (N,) pose times, s; the first sweep starts at ``times[0]``. The last
    sweep's own firings run one sweep period past its start; the last pose
    interval's velocity carries them (as it does with one frame per pose).
    """
    need = times[0] + (frames - 1) * sensor.sweep_period_s
    beyond = float(need - times[-1])
    return beyond if beyond > 1e-9 * max(1.0, abs(float(times[-1]))) else 0.0


def _simulate_scene(args, sensor) -> int:
    from tools.cli_scenes import build_world_and_trajectory, parse_overrides, split_seed

    try:
        overrides = parse_overrides(args.scene_overrides, args.scene_params)
        seed, overrides = split_seed(overrides, args.seed, args.scene_overrides, args.scene_params)
        if args.speed is not None:
            overrides["speed_m_s"] = args.speed
        world, trajectory, info = build_world_and_trajectory(args.scene, seed, overrides)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    info["scene_seed"] = info.pop("seed")
    start = 0.0 if args.start is None else args.start
    available = int((trajectory.duration_s - start) / sensor.sweep_period_s)
    frames = args.frames if args.frames is not None else min(available, 100)
    if frames > available:
        raise CommandError(
            f"scene {args.scene}: its path lasts {trajectory.duration_s:.1f} s, room for {available} sweeps "
            f"after --start {start:g} s, not {frames} (lower --frames, or raise --speed or the path length)"
        )
    return _run_simulation(world, trajectory, sensor, args, frames, {**info, "command": "simulate"},
                           where=f"scene {args.scene}", t_start=start, seed=seed)


def _run_simulation(world, trajectory, sensor, args, frames, info, where, t_start: float, seed: int,
                    strict_inside: bool | None = None) -> int:
    from simlidar.simulate import simulate_sequence
    from simlidar.sweep import SensorInsideGeometry

    bar = None

    def advance(k, scan) -> None:  # the bar starts with the first sweep, after the checks have spoken
        nonlocal bar
        if bar is None:
            bar = _progress(frames, "sweep", "simulate")
        bar.update(1)

    try:
        simulate_sequence(
            world,
            trajectory,
            sensor,
            args.out,
            frames=frames,
            seed=seed,
            t_start=t_start,
            motion_distortion=args.motion_distortion,
            info={**info, "noise_std_m": sensor.range_noise_std_m},
            force=args.force,
            on_frame=advance,
            strict_inside=strict_inside,
        )
    except SensorInsideGeometry as exc:
        raise CommandError(f"{where}: {exc}") from None
    finally:
        if bar is not None:
            bar.close()
    print(f"wrote {frames} frames to {args.out}")
    return 0


# ---------------------------------------------------------------- odometry
def _add_odometry(sub) -> None:
    p = sub.add_parser(
        "odometry",
        help="run BL / NCF / SALO odometry (scan-to-scan or scan-to-map) over a sequence folder",
        description="ICP odometry (the SALO paper's Alg. 1, scan-to-scan, or against a local map) over a "
        "simulated sequence, a real KITTI sequence, a folder of .bin/.ply scans or a ROS 2 bag. Writes KITTI "
        "poses (lidar frame, first = identity), optionally TUM, and a per-frame diagnostics CSV; prints the "
        "degenerate stretches and their direction.",
    )
    p.add_argument("sequence", type=Path, help="sequence folder, or a ROS 2 bag (folder, .mcap or .db3)")
    p.add_argument("--topic", help="PointCloud2 topic of a bag with several (default: the only one, or /points)")
    from odometry.config import DEFAULT_VARIANT, VARIANTS

    p.add_argument("--variant", default=DEFAULT_VARIANT, choices=list(VARIANTS),
                   help=f"method (default {DEFAULT_VARIANT}: chosen on the generalisation suite's tuning seeds; "
                   "bl, ncf, salo: the paper's scan-to-scan variants; -map: against a local map)")
    p.add_argument("--sensor", help="preset or YAML (default: the folder's sensor.yaml)")
    p.add_argument("--config", type=Path, help="YAML with odometry parameters overriding the variant's")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one parameter (repeatable), e.g. --set voxel_size_m=0.4")
    p.add_argument("--frames", help="frame range A:B (Python slice, e.g. 0:100)")
    p.add_argument("--poses", type=Path, help="ground truth for a real KITTI sequence (camera-frame poses file)")
    p.add_argument("--out", type=Path, help="output poses file (default: out/<sequence name>/<variant>/poses.txt)")
    p.add_argument("--tum", action="store_true", help="also write poses in TUM format (poses.tum)")
    p.add_argument("--kitti-correction", action="store_true",
                   help="correct KITTI HDL-64E's 0.205 deg vertical-angle error on reading")
    p.set_defaults(func=cmd_odometry)


def parse_frames(text: str | None) -> slice | None:
    if not text:
        return None
    try:
        parts = [int(x) if x else None for x in text.split(":")]
    except ValueError:
        raise CommandError(f"--frames {text!r}: expected A:B with integers") from None
    if len(parts) == 1:
        return slice(parts[0], parts[0] + 1)
    return slice(*parts[:3])


def parse_assignments(pairs: list[str]) -> dict:
    import yaml

    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise CommandError(f"--set {pair!r}: expected KEY=VALUE")
        try:
            out[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise CommandError(f"--set {pair!r}: not a YAML value ({exc.problem or exc})") from None
    return out


def cmd_odometry(args) -> int:
    from odometry.config import ConfigError, config_from_dict, load_config, variant
    from odometry.pipeline import OdometryError, run_sequence, write_diagnostics_csv
    from simlidar.dataset import open_sequence
    from simlidar.formats.atomic import atomic_write_text
    from simlidar.formats.kitti import write_kitti_poses
    from simlidar.formats.tum import write_tum
    from simlidar.sequence import frame_times

    try:
        config = variant(args.variant)
        if args.config:
            config = load_config(args.config, base=config)
        changes = parse_assignments(args.set)
        if args.kitti_correction:
            changes["kitti_vertical_correction_deg"] = 0.205
        if changes:
            config = config_from_dict(changes, base=config, origin="--set")
    except ConfigError as exc:
        raise CommandError(str(exc)) from None
    seq = open_sequence(args.sequence, sensor=args.sensor, poses=args.poses, topic=args.topic)
    frames = parse_frames(args.frames)
    n = len(range(*(frames or slice(None)).indices(len(seq))))
    out = args.out or Path("out") / args.sequence.resolve().name / config.name / "poses.txt"
    bar = _progress(n, "frame", f"odometry {config.name}")
    try:
        run = run_sequence(seq, config, frames=frames, on_frame=lambda k, d: bar.update(1))
    except OdometryError as exc:
        raise CommandError(f"{args.sequence}: {exc}") from None
    finally:
        bar.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    write_kitti_poses(out, run.poses)
    diagnostics_csv = out.with_name(out.stem + "_diagnostics.csv")
    write_diagnostics_csv(diagnostics_csv, run.diagnostics)
    atomic_write_text(out.with_name(out.stem + "_config.yaml"), config.to_yaml())
    if args.tum:
        times = run.times_s if run.times_s is not None else frame_times(len(run.poses), seq.sensor)
        write_tum(out.with_suffix(".tum"), run.poses, times)
    from odometry.pipeline import degenerate_stretches

    flagged = sum(d.extrapolated for d in run.diagnostics)
    stretches = degenerate_stretches(run.diagnostics)
    print(f"{len(run.poses)} frames at {run.frames_per_second:.1f} frames/s -> {out}")
    if flagged:
        print(f"  {flagged} frames extrapolated (too few points, singular system or an estimate far from the "
              f"constant-velocity prediction): see {diagnostics_csv}")
    if stretches:
        print(f"  weakly constrained (translational eigenvalue per match < {config.degenerate_eigenvalue:g}"
              + (f", or the prior kept below {config.min_constraint_eigenvalue:g}"
                 if config.min_constraint_eigenvalue else "") + "):")
        for st in stretches[:20]:
            print("    " + st.describe())
        if len(stretches) > 20:
            print(f"    ... {len(stretches) - 20} more stretches in {diagnostics_csv}")
    return 0


# ---------------------------------------------------------------- sensors
def _add_sensors(sub) -> None:
    p = sub.add_parser("sensors", help="list sensor presets, or print one as YAML")
    p.add_argument("name", nargs="?", help="preset to print")
    p.set_defaults(func=cmd_sensors)


def cmd_sensors(args) -> int:
    if args.name:
        print(load_sensor(args.name).to_yaml(), end="")
        return 0
    for name in preset_names():
        m = load_sensor(name)
        print(
            f"{name:8s} {m.rings:3d} rings  phi {m.azimuth_step_deg:.4f} deg  "
            f"{m.rotation_hz:g} Hz  {m.rays_per_sweep:6d} rays/sweep  {m.description}"
        )
    return 0


# ---------------------------------------------------------------- demo
def _add_demo(sub) -> None:
    from tools.demo import DEMO_FRAMES

    p = sub.add_parser("demo", help="the README's demo: simulate, run the odometry, plot")
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    p.add_argument("--frames", type=whole_number(2), default=DEMO_FRAMES,
                   help="frames to simulate (default 150: >= 100 m of path)")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    from tools.demo import run_demo

    run_demo(args.out, frames=args.frames)
    return 0


# ---------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="salo",
        description="Lidar simulator with known noise, and a Sensor Aware Lidar Odometry test bench.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in (_add_simulate, _add_odometry, _add_sensors, _add_demo):
        add(sub)
    from tools import cli_evaluate, cli_experiment, cli_export, cli_scenes, cli_sweep

    for module in (cli_evaluate, cli_scenes, cli_experiment, cli_sweep, cli_export):
        module.add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    from simlidar.world import WorldError

    try:
        return int(args.func(args) or 0)
    except (*USER_ERRORS, WorldError, CommandError) as exc:
        print(f"salo {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = " (run it again to resume)" if args.command in ("sweep", "regress") else ""
        print(f"salo {args.command}: interrupted{resume}", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
