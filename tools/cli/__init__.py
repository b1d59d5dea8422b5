"""The ``salo`` command line: one module per command (or group), each a thin layer over library calls.

A command parses its arguments, calls a library function, prints. Shared pieces
(``CommandError``, progress bars, argument types, ``--set`` parsing) are in
``tools.cli.common``; nothing outside ``tools.cli`` imports these modules.
Heavy imports (Embree, matplotlib, pyvista) happen inside the commands that
need them, so ``salo --help`` is instant.
"""

from __future__ import annotations

import argparse
import logging
import sys

from simlidar.imu import ImuUnavailable
from simlidar.sensor import SensorError
from simlidar.sequence import DatasetError

from .common import CommandError

# Errors that are the user's input, reported in one line without a traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (SensorError, DatasetError, FileExistsError, ImuUnavailable)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="salo",
        description="Lidar simulator with known noise, and a Sensor Aware Lidar Odometry test bench.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    from . import bench, demo, evaluate, experiment, export, odometry, scenes, sensors, simulate, sweep

    for module in (simulate, odometry, sensors, demo, evaluate, scenes, experiment, sweep, bench, export):
        module.add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # the command as typed (recorded by some commands)
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


__all__ = ["USER_ERRORS", "CommandError", "build_parser", "main"]
