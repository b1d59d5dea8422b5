"""``salo evaluate``: trajectory error metrics of an estimate against ground truth.

A thin command over ``tools.evaluate`` and ``odometry.metrics``: read two
trajectories (KITTI or TUM), evaluate, print a table (or JSON) and the weakly
constrained frames, optionally plot.
"""

from __future__ import annotations

import json
from pathlib import Path

from simlidar.sequence import DatasetError
from tools.evaluate import PLANES

from .common import whole_number


def add_commands(subparsers) -> None:
    """Register ``evaluate`` on an argparse sub-parsers object."""
    p = subparsers.add_parser(
        "evaluate",
        help="error metrics of estimated poses against ground truth (KITTI, 100 m, ATE, RPE)",
        description="Compare an estimated trajectory with ground truth: pose files in KITTI (12 numbers a line, "
        "one line per frame) or TUM (timestamp tx ty tz qx qy qz qw) format, each read as what it is (and "
        "said which). Poses pair line by line (one estimated pose per ground-truth frame); two TUM files of "
        "different lengths pair by time stamp. Reports the KITTI "
        "devkit's relative error (segments of 100..800 m along the ground-truth path, first "
        "frames every 10th frame; translation in percent, rotation in deg/100 m), the SALO paper's "
        "100 m variant (mean and standard deviation in m per 100 m), the absolute trajectory "
        "error (RMSE, m; as given and after a rigid SE(3) alignment) and the frame-to-frame "
        "relative pose error. Prints the weakly constrained frame "
        "ranges of the truth and of the estimate's own diagnostics when they are known, and warns when the "
        "first motions disagree in a way that a lidar / camera frame mix-up explains.",
    )
    p.add_argument("gt", type=Path, metavar="GT", help="ground-truth poses: KITTI (12 numbers a line) or TUM")
    p.add_argument("est", type=Path, metavar="EST", help="estimated poses: KITTI or TUM")
    p.add_argument("--calib", type=Path, metavar="CALIB.txt",
                   help="KITTI calib.txt: convert camera-frame ground truth (KITTI's poses/NN.txt) to the lidar "
                   "frame with its Tr")
    p.add_argument("--degeneracy", type=Path, metavar="FILE",
                   help="the truth's degeneracy.csv (or its sequence folder): print and shade its weak frames "
                   "(default: degeneracy.csv beside GT, when there)")
    p.add_argument("--diagnostics", type=Path, metavar="CSV",
                   help="the estimate's diagnostics CSV (salo odometry's): print and shade its own weak frames "
                   "(default: beside EST, when there)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON instead of a table")
    p.add_argument("--plot", type=Path, metavar="FILE.png", help="write trajectories and error plots (PNG)")
    p.add_argument(
        "--plane",
        choices=("auto", *PLANES),
        default="auto",
        help="top-down plane of the trajectory plot (default: the two axes of largest "
        "ground-truth extent, i.e. xy for lidar poses, xz for KITTI camera poses)",
    )
    p.add_argument(
        "--rpe-delta",
        type=whole_number(1),
        default=1,
        metavar="FRAMES",
        help="frame spacing of the relative pose error pairs (default 1: consecutive frames)",
    )
    p.set_defaults(func=cmd_evaluate)


def _beside(path: Path, names: list[str]) -> Path | None:
    for name in names:
        candidate = path.with_name(name)
        if candidate.is_file():
            return candidate
    return None


def cmd_evaluate(args) -> int:
    from odometry.metrics import evaluate_trajectory
    from tools.degenerate import describe_stretches, diagnostics_constraints, truth_constraints
    from tools.evaluate import evaluation_notes, format_table, load_pair, plot_evaluation

    if args.plot is not None and args.plot.suffix.lower() != ".png":
        raise DatasetError(f"{args.plot}: the plot is written as PNG; give a .png file name")
    T_gt, T_est, said = load_pair(args.gt, args.est, args.calib)
    metrics = evaluate_trajectory(T_gt, T_est, rpe_delta_frames=args.rpe_delta)
    notes = evaluation_notes(T_gt, T_est, metrics)
    truth_file = args.degeneracy or _beside(args.gt, ["degeneracy.csv"])
    own_file = args.diagnostics or _beside(args.est, ["diagnostics.csv", f"{args.est.stem}_diagnostics.csv"])
    truth = truth_constraints(truth_file) if truth_file is not None else None
    own = diagnostics_constraints(own_file) if own_file is not None else None
    for found, origin in ((truth, truth_file), (own, own_file)):
        if found is not None and len(found.weak) != len(T_gt):
            notes.append(f"{origin} has {len(found.weak)} frames, the trajectories {len(T_gt)}: its weak frames "
                         "are not shown")
    truth = truth if truth is not None and len(truth.weak) == len(T_gt) else None
    own = own if own is not None and len(own.weak) == len(T_gt) else None
    weak_lines = []
    for what, found, origin in (("the truth", truth, truth_file), ("the estimate's own diagnostics", own, own_file)):
        if found is None:
            continue
        stretches = found.stretches()
        weak_lines.append(f"weakly constrained frames, by {what} ({origin}):"
                          + ("" if stretches else " none"))
        weak_lines += describe_stretches(stretches, indent="  ")
    if args.json:
        out = {"gt": str(args.gt), "est": str(args.est), "read": said, **metrics.to_dict(), "notes": notes,
               "weak_frames": {what: [[st.first, st.last] for st in found.stretches()]
                               for what, found in (("truth", truth), ("estimate", own)) if found is not None}}
        text = json.dumps(out, indent=2, allow_nan=False) + "\n"
    else:
        text = "\n".join(said) + "\n\n" + format_table(metrics, args.gt, args.est, notes)
        if weak_lines:
            text += "\n" + "\n".join(weak_lines) + "\n"
    if args.plot is not None:
        title = f"estimate {args.est} vs ground truth {args.gt}"
        plot_evaluation(args.plot, T_gt, T_est, metrics, plane=args.plane, title=title,
                        truth_weak=None if truth is None else truth.weak, own_weak=None if own is None else own.weak)
        if not args.json:
            text += f"\nplot: {args.plot}\n"
    print(text, end="")
    return 0
