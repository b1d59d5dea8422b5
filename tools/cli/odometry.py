"""``salo odometry``: BL / NCF / SALO odometry over a sequence folder or a ROS 2 bag."""

from __future__ import annotations

from pathlib import Path

from .common import CommandError, frames_selected, parse_config_set, parse_frames, progress_bar


def add_commands(sub) -> None:
    p = sub.add_parser(
        "odometry",
        help="run BL / NCF / SALO odometry (scan-to-scan or scan-to-map) over a sequence folder",
        description="ICP odometry (the SALO paper's Alg. 1, scan-to-scan, or against a local map) over a "
        "simulated sequence, a real KITTI sequence (sensor hdl64e unless --sensor), a folder of .bin/.ply or "
        ".pcd scans (salo export writes both) or a ROS 2 bag. Writes KITTI "
        "poses (lidar frame, first = identity), optionally TUM, and a per-frame diagnostics CSV; prints the "
        "degenerate stretches and their direction. --keys lists the parameters (of --config and --set).",
    )
    p.add_argument("sequence", type=Path, nargs="?", help="sequence folder, or a ROS 2 bag (folder, .mcap or .db3)")
    p.add_argument("--keys", action="store_true",
                   help="list the odometry's parameters by stage (type, default, unit, range, meaning) and the "
                   "variants, and exit")
    p.add_argument("--topic", help="PointCloud2 topic of a bag with several (default: the only one, or /points)")
    from odometry.config import DEFAULT_VARIANT, VARIANTS

    p.add_argument("--variant", default=DEFAULT_VARIANT, choices=list(VARIANTS),
                   help=f"method (default {DEFAULT_VARIANT}: chosen on the generalisation suite's tuning seeds; "
                   "bl, ncf, salo: the paper's scan-to-scan variants; -map: against a local map)")
    p.add_argument("--sensor", help="preset or YAML (default: the folder's sensor.yaml; hdl64e for a KITTI folder "
                   "without one)")
    p.add_argument("--config", type=Path, help="YAML with odometry parameters overriding the variant's")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one parameter (repeatable), a dotted key: e.g. --set filter.voxel_size_m=0.4, "
                   "--set deskew.enabled=false (--keys lists them)")
    p.add_argument("--frames", help="frame range A:B (Python slice, e.g. 0:100)")
    p.add_argument("--poses", type=Path, help="ground truth for a real KITTI sequence (camera-frame poses file)")
    p.add_argument("--out", type=Path, help="output poses file (default: out/<sequence name>/<variant>/poses.txt)")
    p.add_argument("--tum", action="store_true", help="also write poses in TUM format (poses.tum)")
    p.add_argument("--force", action="store_true", help="replace an existing output (the poses file and those "
                   "beside it)")
    p.add_argument("--kitti-correction", action="store_true",
                   help="correct KITTI HDL-64E's 0.205 deg vertical-angle error on reading")
    p.set_defaults(func=cmd_odometry)


def print_keys() -> None:
    """The odometry's parameters, as declared, and each variant's changes to their defaults."""
    from odometry.config import DEFAULT_VARIANT, OdometryConfig, variant_changes
    from paramspec import help_text, value_text

    print("The odometry's parameters, by stage: a config file (--config) holds a mapping per stage\n"
          "(ncf: {max_normal_std_deg: 3}), --set a dotted key (--set ncf.max_normal_std_deg=3).")
    print(help_text(OdometryConfig.schema(), header=True))
    print("\nVariants (--variant): the defaults above are salo's; the others change")
    for name, changes in variant_changes().items():
        text = ", ".join(f"{k}: {value_text(v)}" for k, v in changes.items()) or "(nothing)"
        print(f"  {name:9s} {text}{'   [the default variant]' if name == DEFAULT_VARIANT else ''}")


def cmd_odometry(args) -> int:
    from odometry.config import ConfigError, config_from_dict, load_config, variant
    from odometry.diagnostics import degenerate_stretches
    from simlidar.dataset import open_sequence
    from tools.methods import MethodError, OursMethod, run_method
    from tools.runners import RunFiles, write_run_files

    if args.keys:
        print_keys()
        return 0
    if args.sequence is None:
        raise CommandError("give a SEQUENCE folder or bag (or --keys to list the parameters)")
    try:
        config = variant(args.variant)
        if args.config:
            config = load_config(args.config, base=config)
        config = config_from_dict(parse_config_set(args.set), base=config, origin="--set")
        if args.kitti_correction:
            config = config.replace(clean={"kitti_vertical_correction_deg": 0.205})
    except ConfigError as exc:
        raise CommandError(str(exc)) from None
    seq = open_sequence(args.sequence, sensor=args.sensor, poses=args.poses, topic=args.topic)
    if seq.kind == "kitti" and args.sensor is None and not (args.sequence / "sensor.yaml").is_file():
        from simlidar.formats.scan_folders import KITTI_SENSOR

        print(f"sensor: {KITTI_SENSOR} (KITTI's; --sensor to change)")
    frames = parse_frames(args.frames, len(seq), str(args.sequence))
    out = args.out or Path("out") / args.sequence.resolve().name / config.name / "poses.txt"
    files = RunFiles.beside(out, tum=args.tum)
    existing = [p for p in (files.poses, files.diagnostics, files.config, files.tum) if p is not None and p.exists()]
    if existing and not args.force:
        raise CommandError(f"{existing[0]}: already exists (use --force to replace it"
                           + (f" and {len(existing) - 1} more beside it" if len(existing) > 1 else "") + ")")
    bar = progress_bar(frames_selected(len(seq), frames), "frame", f"odometry {config.name}")
    try:  # the user's own data, read as given (--sensor, --poses): nothing to stage
        result = run_method(OursMethod(config.name, config), seq, stage=False, frames=frames,
                            on_frame=lambda k, d: bar.update(1))
    except MethodError as exc:
        text = str(exc)  # the odometry's errors name the sequence already, most of them
        raise CommandError(text if text.startswith(str(args.sequence)) else f"{args.sequence}: {text}") from None
    finally:
        bar.close()
    write_run_files(files, result.poses, result.diagnostics, config, result.odometry_run.times_s, seq.sensor)
    stretches = degenerate_stretches(result.diagnostics)
    print(f"{len(result.poses)} frames at {result.frames_per_second:.1f} frames/s -> {out}")
    if result.flags.extrapolated:
        print(f"  {result.flags.extrapolated} frames extrapolated (too few points, singular system or an estimate "
              f"far from the constant-velocity prediction): see {files.diagnostics}")
    if stretches:
        print(f"  weakly constrained (translational eigenvalue per match < {config.degeneracy.degenerate_eigenvalue:g}"
              + (f", or the prior kept below {config.degeneracy.min_constraint_eigenvalue:g}"
                 if config.degeneracy.min_constraint_eigenvalue else "") + "):")
        for st in stretches[:20]:
            print("    " + flagged_by(st, result.diagnostics, config.degeneracy.degenerate_eigenvalue))
        if len(stretches) > 20:
            print(f"    ... {len(stretches) - 20} more stretches in {files.diagnostics}")
    return 0


def flagged_by(stretch, diagnostics, threshold: float) -> str:
    """A stretch's line, saying which clause flagged its frames: the eigenvalue below ``threshold``, the prior
    kept (``remapped``), or both (so a stretch whose smallest eigenvalue is above the threshold reads right)."""
    mine = [d for d in diagnostics if stretch.first <= d.frame <= stretch.last]
    low = sum(bool(d.degenerate) for d in mine)
    kept = sum(d.remapped > 0 for d in mine)
    clauses = ([f"{low} frames below {threshold:g}"] if low else []) + ([f"prior kept on {kept}"] if kept else [])
    span, _, rest = stretch.describe().partition(": ")
    rest = rest.replace(f"; prior kept on {stretch.remapped} frames", "")
    return f"{span} ({', '.join(clauses) or 'flagged'}): {rest}"
