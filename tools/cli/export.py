"""``salo export``: a sequence as a ROS 2 bag, PLY / PCD scans or a TUM trajectory (over ``tools.export``)."""

from __future__ import annotations

from pathlib import Path

from .common import CommandError, frames_selected, parse_frames, progress_bar, real_number


def add_commands(subparsers) -> None:
    """Register ``export`` on an argparse sub-parsers object."""
    from tools.export import DEFAULT_EPOCH_S, FORMATS, STORAGES

    p = subparsers.add_parser(
        "export",
        help="export a sequence as a ROS 2 bag, PLY / PCD scans or a TUM trajectory",
        description="Export a sequence (simulated, real KITTI, a scan folder or a ROS 2 bag) for other tools. "
        "rosbag: a rosbag2 folder with sensor_msgs/PointCloud2 on /points (x y z intensity ring time, the "
        "Velodyne driver's layout, plus the simulator's per-point ground truth), nav_msgs/Odometry on "
        "/ground_truth/odometry and /tf (map -> lidar); needs the optional 'rosbags' package. ply / pcd: a "
        "folder of one file per frame with the same fields, sensor.yaml, poses.txt and times.txt. tum: the "
        "ground-truth trajectory (timestamp tx ty tz qx qy qz qw), readable by evo.",
    )
    p.add_argument("sequence", type=Path, help="sequence folder, or ROS 2 bag (folder, .mcap or .db3)")
    p.add_argument("--format", required=True, choices=FORMATS, help="what to write")
    p.add_argument("--out", type=Path, required=True, help="output bag folder, scan folder or TUM file")
    p.add_argument("--frames", help="frame range A:B (Python slice, e.g. 0:100)")
    p.add_argument("--sensor", help="preset or YAML overriding the sequence's sensor.yaml")
    p.add_argument("--topic", help="PointCloud2 topic when SEQUENCE is a bag with several")
    p.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default mcap)")
    p.add_argument("--epoch", type=real_number(0.0), default=DEFAULT_EPOCH_S, metavar="SECONDS",
                   help=f"ROS time of the sequence's t = 0, s since 1970 (default {DEFAULT_EPOCH_S}, 2020-01-01)")
    p.add_argument("--no-truth", dest="truth", action="store_false",
                   help="leave out the simulator's per-point ground-truth fields (bag, ply, pcd)")
    p.add_argument("--ascii", action="store_true", help="PCD in ASCII instead of binary")
    p.add_argument("--force", action="store_true", help="replace an existing output")
    p.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    from simlidar.dataset import open_sequence
    from tools.export import export

    if args.ascii and args.format != "pcd":
        raise CommandError("--ascii applies to --format pcd only")
    seq = open_sequence(args.sequence, sensor=args.sensor, topic=args.topic)
    frames = parse_frames(args.frames, len(seq), str(args.sequence))
    options: dict = {"force": args.force}
    if args.format == "rosbag":
        options.update(storage=args.storage, epoch_s=args.epoch, truth=args.truth)
    elif args.format in ("ply", "pcd"):
        options.update(binary=not args.ascii, truth=args.truth)
    if args.format == "tum":
        result = export(seq, args.format, args.out, frames, **options)
    else:
        n = frames_selected(len(seq), frames)
        bar = progress_bar(n, "frame", f"export {args.format}")
        try:
            result = export(seq, args.format, args.out, frames, on_frame=lambda k: bar.update(1), **options)
        finally:
            bar.close()
    print(f"wrote {len(result.frames)} frames of {args.sequence} as {result.format} to {result.path}")
    for topic, count in result.messages.items():
        print(f"  {topic}: {count} messages")
    return 0

