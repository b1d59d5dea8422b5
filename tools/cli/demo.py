"""``salo demo``: the README's demo (simulate, run the odometry, plot)."""

from __future__ import annotations

from pathlib import Path

from .common import whole_number


def add_commands(sub) -> None:
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
