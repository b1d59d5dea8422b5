"""What the ``salo`` commands share: the command error, progress bars, argument types and parsers.

Only the command-line modules (``tools.cli``) import this; library code raises
its own errors (ValueError and subclasses) and takes plain values.

Checked number types refuse a bad value (``--frames 0``, ``--noise-std -1``,
``--workers two``) while the arguments are parsed, with argparse's usage line
and exit code 2, instead of failing later inside the work with a traceback.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from paramspec import ParamError, assignments


class CommandError(Exception):
    """A command cannot proceed; the message says why."""


# ---------------------------------------------------------------- progress
def progress_bar(total: int, unit: str, desc: str):
    """A tqdm bar on stderr (stdout stays the commands' report)."""
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, dynamic_ncols=True, file=sys.stderr)


def run_counter(desc: str):
    """A run counter on stderr and the two callbacks that drive it (plan, then each result); and close."""
    from tqdm import tqdm

    state = {"bar": None, "failed": 0}

    def on_plan(plan) -> None:
        state["bar"] = tqdm(total=len(plan.runs), initial=plan.skipped, unit="run", desc=desc, dynamic_ncols=True,
                            file=sys.stderr)

    def on_result(row) -> None:
        if row["status"] != "ok":
            state["failed"] += 1
            state["bar"].set_postfix(failed=state["failed"])
        state["bar"].update(1)

    def close() -> None:
        if state["bar"] is not None:
            state["bar"].close()

    return on_plan, on_result, close


# ---------------------------------------------------------------- argument types
def whole_number(minimum: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def real_number(minimum: float = -math.inf, above: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite float >= ``minimum`` (> it with ``above``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if value < minimum or (above and value == minimum):
            raise argparse.ArgumentTypeError(f"must be {'above' if above else 'at least'} {minimum:g}, got {value:g}")
        return value

    return parse


# ---------------------------------------------------------------- parsers
def parse_frames(text: str | None, n: int | None = None, where: str = "the sequence") -> slice | None:
    """``--frames A:B`` or ``A:B:STEP`` (a Python slice; ``N`` alone is frame N) -> a slice, or None for all.

    n: the sequence's frame count, when known: a range that selects none of them is refused,
    naming ``where``. Raises CommandError (one line) for text that is not a range or a zero step.
    """
    if not text:
        return None
    try:
        parts = [int(x) if x.strip() else None for x in text.split(":")]
    except ValueError:
        raise CommandError(f"--frames {text!r}: expected A:B (or A:B:STEP) with whole numbers") from None
    if len(parts) > 3:
        raise CommandError(f"--frames {text!r}: expected A:B (or A:B:STEP) with whole numbers")
    if len(parts) == 3 and parts[2] == 0:
        raise CommandError(f"--frames {text!r}: the step must not be zero")
    frames = slice(parts[0], parts[0] + 1 if parts[0] != -1 else None) if len(parts) == 1 else slice(*parts)
    if n is not None and frames_selected(n, frames) == 0:
        raise CommandError(f"--frames {text!r}: selects no frame of {where} (frames 0..{n - 1})")
    return frames


def frames_selected(n: int, frames: slice | None) -> int:
    """How many of ``n`` frames a ``parse_frames`` slice selects."""
    return len(range(*(frames or slice(None)).indices(n)))


def parse_config_set(pairs: list[str]) -> dict:
    """Odometry ``--set KEY=VALUE`` pairs -> the overrides, nested by stage as a config YAML holds them.

    A key is dotted, ``STAGE.KEY`` (``ncf.max_normal_std_deg=3``, ``deskew.enabled=false``;
    ``salo odometry --keys`` lists them); each value is text, converted and checked by the key's
    declaration (``odometry.config``, ``paramspec``). Overlay the result on a config with
    ``config_from_dict(changes, base=..., origin="--set")``. Raises CommandError naming the key;
    an old flat key names its new one ("key 'voxel_size_m' is unknown; did you mean 'filter.voxel_size_m'?").
    """
    from odometry.config import changes_from_assignments

    try:
        return changes_from_assignments(pairs)
    except ParamError as exc:
        raise CommandError(str(exc)) from None


def parse_overrides(pairs: list[str] | None, yaml_file: Path | None = None) -> dict[str, Any]:
    """Scene parameter overrides from a YAML file, then ``key=value`` pairs (which win).

    The YAML file holds a mapping ``parameter: value`` (a section's keys as a mapping). Values from pairs stay
    strings (the scene's parameter types convert them). Errors (ValueError) name the file or pair.
    """
    out: dict[str, Any] = {}
    if yaml_file is not None:
        from simlidar.yaml_file import read_yaml

        path = Path(yaml_file)
        data = read_yaml(path, ValueError, "parameter file")
        if data is None:
            data = {}
        if not isinstance(data, dict) or not all(isinstance(k, str) for k in data):
            raise ValueError(f"{path}: expected a mapping of parameter names to values")
        for key, value in data.items():
            if isinstance(value, list):  # (a mapping is a section's keys: traffic)
                raise ValueError(f"{path}: parameter {key}: expected a single value")
            out[key] = value
    try:
        out.update(assignments(pairs or [], what="override"))
    except ParamError as exc:
        raise ValueError(f"{exc} (e.g. length_m=800)") from None
    return out


def split_seed(overrides: dict[str, Any], cli_seed: int | None, pairs: list[str] | None = None,
               yaml_file: Path | None = None) -> tuple[int, dict[str, Any]]:
    """The scene seed and the other overrides.

    A ``seed`` among the overrides (a parameter file's ``seed:``, as ``salo scenes
    NAME --yaml`` writes it, or ``--set seed=N``) and ``--seed`` (``cli_seed``) are
    one setting: either gives it (default 0); if both are given they must agree.
    ``pairs`` and ``yaml_file`` (what ``parse_overrides`` read) only name the
    seed's origin in messages. Raises ValueError naming the origin of a bad value
    (not a whole number >= 0) or both seeds when they differ.
    """
    from scenes.params import CommonParams, resolve

    rest = dict(overrides)
    if "seed" not in rest:
        return (0 if cli_seed is None else int(cli_seed)), rest
    value = rest.pop("seed")
    set_pairs = [p.strip() for p in pairs or [] if p.partition("=")[0].strip() == "seed"]
    origin = f"--set {set_pairs[-1]}" if set_pairs else f"{yaml_file}" if yaml_file is not None else "seed"
    seed = resolve(CommonParams, {"seed": value}, origin=origin).seed
    if cli_seed is not None and int(cli_seed) != seed:
        where = origin if set_pairs else f"seed: {seed} in {origin}"
        raise ValueError(f"--seed {cli_seed} and {where} differ: both set the scene seed, give one")
    return seed, rest


def command_line() -> list[str]:
    """This process's command as typed (recorded in run folders)."""
    return ["salo", *sys.argv[1:]]


__all__ = ["CommandError", "command_line", "frames_selected", "parse_config_set", "parse_frames",
           "parse_overrides", "progress_bar", "real_number", "run_counter", "split_seed", "whole_number"]
