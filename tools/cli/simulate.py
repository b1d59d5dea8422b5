"""``salo simulate``: a lidar sequence along a scene's path, or through your own mesh along your poses."""

from __future__ import annotations

import dataclasses
import sys
from contextlib import contextmanager
from pathlib import Path

from simlidar.imu import IMU_GRADES, imu_of_grade
from simlidar.sensor import load_sensor, preset_names

from .common import CommandError, parse_overrides, progress_bar, real_number, split_seed, whole_number


def add_commands(sub) -> None:
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
    p.add_argument("--reflectance", action="append", default=[], metavar="KEY=VALUE",
                   help="reflectance in [0, 1] of the objects of a label (road=0.1) or of one object id (12=0.9), "
                   "for the intensity (repeatable; default: by label)")
    p.add_argument("--sensor", default="salo32", help=f"preset ({', '.join(preset_names())}) or YAML file")
    p.add_argument("--frames", type=whole_number(1),
                   help="number of sweeps (default: as many as the poses cover, one per pose without --times; "
                   "100 along a scene)")
    p.add_argument("--seed", type=whole_number(0),
                   help="seed of the noise, and of a --scene (default 0, or the scene parameters' seed)")
    p.add_argument("--noise-std", type=real_number(0.0),
                   help="range noise standard deviation, m (overrides the sensor)")
    p.add_argument("--sensor-set", action="append", default=[], metavar="KEY=VALUE",
                   help="change a key of the sensor (repeatable; `salo sensors --keys`), sections' keys dotted: "
                   "--sensor-set receiver.enabled=true --sensor-set weather.fog.enabled=true "
                   "--sensor-set weather.fog.mor_m=60 (docs/weather.md)")
    p.add_argument(
        "--no-motion-distortion",
        dest="motion_distortion",
        action="store_false",
        help="fire every ray of a sweep from the sweep's start pose",
    )
    p.add_argument("--imu", nargs="?", const="sensor", choices=("sensor", *IMU_GRADES), metavar="GRADE",
                   help="simulate the sensor's IMU too (imu.csv, imu_truth.csv; its keys from the sensor file's imu "
                   f"section, else the defaults: docs/imu.md), or one of a grade ({', '.join(IMU_GRADES)}: its noise "
                   "keys, the file's mounting); along a scene's path only")
    p.add_argument("--compress-truth", action="store_true",
                   help="zlib the per-return truth files: a third of their size, slower to write")
    p.add_argument("--out", type=Path, required=True, help="output sequence folder")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.set_defaults(func=cmd_simulate)


def _sensor_from_args(args):
    from paramspec import ParamError, assignments, build, schema
    from simlidar.sensor import LidarModel, SensorError

    sensor = load_sensor(args.sensor)
    if getattr(args, "noise_std", None) is not None:
        sensor = sensor.with_overrides(range_noise_std_m=args.noise_std)
    if getattr(args, "imu", None) == "sensor":
        sensor = sensor.with_overrides(imu=dataclasses.replace(sensor.imu, enabled=True))
    elif getattr(args, "imu", None):
        sensor = sensor.with_overrides(imu=imu_of_grade(args.imu, sensor.imu))
    if getattr(args, "sensor_set", None):
        try:
            values = schema(LidarModel).read(assignments(args.sensor_set, "--sensor-set"), "--sensor-set",
                                             coerce=True, partial=True, error=SensorError)
            sensor = build(LidarModel, values, sensor, "--sensor-set")
        except ParamError as exc:
            raise CommandError(str(exc)) from None
    return sensor


def _reflectance(args) -> dict:
    """``--reflectance KEY=VALUE`` arguments as {key: value}; a one-line error for a malformed one."""
    out = {}
    for text in args.reflectance:
        key, sep, value = text.partition("=")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not key.strip():
            raise CommandError(f"--reflectance {text!r}: expected LABEL=VALUE or OBJECT_ID=VALUE, e.g. road=0.1")
    return out


def _with_reflectance(world, args, info: dict):
    values = _reflectance(args)
    if not values:
        return world
    info["reflectance"] = values
    return world.with_reflectance(values)


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
    from simlidar.simulate import simulate_sequence
    from tools.worlds import load_mesh_world

    built = load_mesh_world(args.mesh, args.poses, args.times, sensor)
    fit = built.sweeps_covered(sensor)
    frames = args.frames if args.frames is not None else fit
    info = {"command": "simulate", **built.info}
    world = _with_reflectance(built.world, args, info)
    beyond = built.beyond_last_pose_s(sensor, frames)
    if beyond > 0:
        times = built.times
        need = times[0] + (frames - 1) * sensor.sweep_period_s
        numbers = (f"{len(times)} poses cover {times[-1] - times[0]:.1f} s; "
                   f"{frames} frames need {need - times[0]:.1f} s")
        if not args.extrapolate:
            raise CommandError(f"{args.poses}: {numbers} (at most {fit} frames fit: lower --frames, give more "
                               "poses, or --extrapolate to continue the last pose interval's velocity)")
        print(f"extrapolating {beyond:.1f} s beyond the last pose ({numbers})", file=sys.stderr)
        info["extrapolated"] = {"poses_cover_s": round(float(times[-1] - times[0]), 9),
                                "frames_need_s": round(float(need - times[0]), 9),
                                "beyond_last_pose_s": round(float(beyond), 9),
                                "method": "constant velocity of the last pose interval"}
    with _simulating(frames, str(args.poses)) as on_frame:
        simulate_sequence(world, built.trajectory, sensor, args.out, frames=frames,
                          seed=0 if args.seed is None else args.seed, t_start=float(built.times[0]),
                          motion_distortion=args.motion_distortion,
                          info={**info, "noise_std_m": sensor.range_noise_std_m}, force=args.force,
                          on_frame=on_frame, strict_inside=True if args.strict_inside_check else None,
                          compress_truth=args.compress_truth)
    print(f"wrote {frames} frames to {args.out}")
    _print_weak_frames(args.out)
    return 0


def _print_weak_frames(out: Path) -> None:
    """The frame ranges the truth finds weakly constrained, with their direction (``degeneracy.csv``)."""
    from tools.degenerate import TRUTH_THRESHOLD, describe_stretches, truth_constraints

    stretches = truth_constraints(out).stretches()
    if not stretches:
        print(f"no weakly constrained frame (smallest translational eigenvalue per return >= {TRUTH_THRESHOLD:g} "
              "everywhere, from the true normals)")
        return
    print(f"weakly constrained frames (smallest translational eigenvalue per return < {TRUTH_THRESHOLD:g}, "
          f"from the true normals; {out / 'degeneracy.csv'}):")
    for line in describe_stretches(stretches):
        print(line)


def _simulate_scene(args, sensor) -> int:
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    try:
        overrides = parse_overrides(args.scene_overrides, args.scene_params)
        seed, overrides = split_seed(overrides, args.seed, args.scene_overrides, args.scene_params)
        if args.speed is not None:
            overrides["speed_m_s"] = args.speed
        scene = build_scene_world(args.scene, seed, overrides)
        info = {"command": "simulate"}
        scene = dataclasses.replace(scene, world=_with_reflectance(scene.world, args, info))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    start = 0.0 if args.start is None else args.start
    available = scene.sweeps_available(sensor, start)
    frames = args.frames if args.frames is not None else min(available, 100)
    if frames > available:
        raise CommandError(
            f"scene {args.scene}: its path lasts {scene.trajectory.duration_s:.1f} s, room for {available} sweeps "
            f"after --start {start:g} s, not {frames} (lower --frames, or raise --speed or the path length)"
        )
    with _simulating(frames, f"scene {args.scene}") as on_frame:
        simulate_scene(scene, sensor, args.out, frames, seed=seed, start_s=start,
                       motion_distortion=args.motion_distortion, info=info, force=args.force,
                       on_frame=on_frame, compress_truth=args.compress_truth)
    print(f"wrote {frames} frames to {args.out}")
    _print_weak_frames(args.out)
    return 0


@contextmanager
def _simulating(frames: int, where: str):
    """The ``on_frame`` of a progress bar that starts with the first sweep (after the checks have spoken);
    a sensor pose inside geometry becomes a one-line error naming ``where``."""
    from simlidar.sweep import SensorInsideGeometry

    bar = None

    def advance(k, scan) -> None:
        nonlocal bar
        if bar is None:
            bar = progress_bar(frames, "sweep", "simulate")
        bar.update(1)

    try:
        yield advance
    except SensorInsideGeometry as exc:
        raise CommandError(f"{where}: {exc}") from None
    finally:
        if bar is not None:
            bar.close()
