"""``salo evaluate``: trajectory error metrics of an estimate against ground truth.

A thin command over ``tools.evaluate`` and ``odometry.metrics``: read two KITTI
pose files, evaluate, print a table (or JSON), optionally plot.
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
        description="Compare an estimated trajectory with ground truth, both KITTI pose files "
        "(12 numbers per line, one line per frame, same number of frames). Reports the KITTI "
        "devkit's relative error (segments of 100..800 m along the ground-truth path, first "
        "frames every 10th frame; translation in %%, rotation in deg/100 m), the SALO paper's "
        "100 m variant (mean and standard deviation in m per 100 m), the absolute trajectory "
        "error (RMSE, m; as given and after a rigid SE(3) alignment) and the frame-to-frame "
        "relative pose error.",
    )
    p.add_argument("gt", type=Path, metavar="GT", help="ground-truth poses (KITTI format)")
    p.add_argument("est", type=Path, metavar="EST", help="estimated poses (KITTI format)")
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


def cmd_evaluate(args) -> int:
    from odometry.metrics import evaluate_trajectory
    from tools.evaluate import evaluation_notes, format_table, load_pair, plot_evaluation

    if args.plot is not None and args.plot.suffix.lower() != ".png":
        raise DatasetError(f"{args.plot}: the plot is written as PNG; give a .png file name")
    T_gt, T_est = load_pair(args.gt, args.est)
    metrics = evaluate_trajectory(T_gt, T_est, rpe_delta_frames=args.rpe_delta)
    notes = evaluation_notes(T_gt, T_est, metrics)
    if args.json:
        out = {"gt": str(args.gt), "est": str(args.est), **metrics.to_dict(), "notes": notes}
        text = json.dumps(out, indent=2, allow_nan=False) + "\n"
    else:
        text = format_table(metrics, args.gt, args.est, notes)
    if args.plot is not None:
        title = f"estimate {args.est} vs ground truth {args.gt}"
        plot_evaluation(args.plot, T_gt, T_est, metrics, plane=args.plane, title=title)
        if not args.json:
            text += f"\nplot: {args.plot}\n"
    print(text, end="")
    return 0
