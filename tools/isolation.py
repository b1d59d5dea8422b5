"""A method's own process: where it runs, what environment it sees, and a plug-in run apart from the bench.

A method under test is handed ``tools.staging``'s folder and nothing else. Paths
reach a program in three more ways than its arguments, and each is closed here:

- its working folder: a command or a plug-in runs in the stage's empty ``work/``
  folder, not in the caller's (which may hold the run's output tree, truth included);
- its environment: ``PWD`` names that folder and ``OLDPWD`` (the caller's previous
  folder) is dropped;
- its process: a plug-in of the entry-point group ``salo.methods`` runs in a Python
  process of its own (``python -m tools.plugin_child``), so it cannot reach the bench's
  objects (the sequence with its poses, the command line naming the output folder).
  The child imports what the caller can (its ``sys.path``, less the caller's working
  folder) and returns the poses through the stage's output folder.

Our own configurations and the peers are this project's code and run in-process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

RESULT_NPZ = "plugin_result.npz"
RESULT_JSON = "plugin_result.json"
# The child's exit status for a failure it explains in its last line (a MethodError, a bad return).
EXPLAINED_FAILURE = 3


class IsolatedRunError(ValueError):
    """A plug-in's own process failed, timed out or gave no poses; the message says which."""


@dataclass(frozen=True)
class IsolatedResult:
    """What a plug-in's process gave: poses (N, 4, 4), its own weak-frame flags (N,) bool or None, its wall
    time, s, and its settings and note (``tools.runners.MethodRun``'s)."""

    poses: np.ndarray
    degenerate: np.ndarray | None
    seconds: float
    settings: dict
    note: str


def method_environment(workdir: str | Path, python_path: list[str] | None = None) -> dict[str, str]:
    """The environment of a method's process: the caller's, with ``PWD`` = ``workdir`` and no ``OLDPWD``;
    ``python_path``: the ``PYTHONPATH`` entries (None: the caller's as it is)."""
    env = dict(os.environ)
    env.pop("OLDPWD", None)
    env["PWD"] = str(workdir)
    if python_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(python_path)
    return env


def _child_python_path() -> list[str]:
    """What the caller imports from (its ``sys.path``'s folders and this project's), less its working folder."""
    here = os.path.realpath(os.getcwd())
    project = str(Path(__file__).resolve().parents[1])
    entries = [project] + [p for p in sys.path if p and os.path.isdir(p)]
    return [p for p in dict.fromkeys(entries) if os.path.realpath(p) != here or p == project]


def run_plugin_isolated(entry_point: str, name: str, staged, *, log_path: str | Path | None = None,
                        timeout_s: float = 3600.0) -> IsolatedResult:
    """Run the plug-in of the entry point ``entry_point`` (shown as ``name``) over ``staged``
    (``tools.staging.StagedInput``) in a process of its own (``tools.plugin_child``).

    log_path: the child's output (default: beside ``staged.out``). Raises IsolatedRunError (quoting
    the child's last lines) when it fails, times out or gives no poses.
    """
    log_path = Path(log_path) if log_path is not None else staged.out.with_name("plugin.log")
    result = staged.out.parent
    argv = [sys.executable, "-m", "tools.plugin_child", entry_point, str(staged.root), str(result)]
    t0 = time.perf_counter()
    with open(log_path, "w") as log_file:
        try:
            proc = subprocess.run(argv, cwd=staged.workdir, stdin=subprocess.DEVNULL, stdout=log_file,
                                  stderr=subprocess.STDOUT, timeout=timeout_s,
                                  env=method_environment(staged.workdir, _child_python_path()))
        except subprocess.TimeoutExpired:
            raise IsolatedRunError(f"plug-in {name} timed out after {timeout_s:g} s") from None
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        lines = Path(log_path).read_text().strip().splitlines()
        tail = lines[-1] if proc.returncode == EXPLAINED_FAILURE and lines else " | ".join(lines[-3:])
        raise IsolatedRunError(tail if proc.returncode == EXPLAINED_FAILURE else
                          f"plug-in {name} exited with status {proc.returncode}: {tail}")
    try:
        with np.load(result / RESULT_NPZ, allow_pickle=False) as data:
            poses = data["poses"]
            degenerate = data["degenerate"] if "degenerate" in data.files else None
        info = json.loads((result / RESULT_JSON).read_text())
    except (OSError, ValueError, KeyError) as exc:
        raise IsolatedRunError(f"plug-in {name} gave no poses ({exc})") from None
    return IsolatedResult(poses, degenerate, float(info.get("seconds", seconds)), info.get("settings", {}),
                          info.get("note", ""))
