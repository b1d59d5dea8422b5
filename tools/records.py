"""Run folders: what was run, how, and with what; and the writers the experiments and the demo share.

Every experiment writes into one folder and starts by writing ``run.json``:
the experiment's name, the command line, the resolved parameters (seeds
included), the package version, the git commit of the checkout (and whether
it had uncommitted changes), Python / numpy versions, the host and the start
time. At the end ``run.json`` is rewritten with the end time, the duration,
the files written and ``"status": "complete"``; an interrupted run keeps
``"status": "running"``. Re-running the recorded command with the recorded
version reproduces the folder (every random draw is seeded).

JSON has no NaN: a figure that does not exist is written as ``null``.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from simlidar.formats.atomic import atomic_write_text

RUN_FILE = "run.json"
SUMMARY_FILE = "summary.md"


def package_version() -> str:
    """The installed salo-bench version (the source tree's when not installed)."""
    try:
        from importlib.metadata import PackageNotFoundError, version

        return version("salo-bench")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        from simlidar import __version__

        return __version__


def git_state(repo_dir: str | Path | None = None) -> dict | None:
    """The checkout holding this package: commit, whether tracked files differ from it, which, and the
    sha256 of that difference (``git diff HEAD``), so a run made on uncommitted code can still be matched
    to the code it ran. None outside git."""
    repo = Path(repo_dir) if repo_dir is not None else Path(__file__).resolve().parents[1]

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True, timeout=20,
                              check=True).stdout

    try:
        commit = git("rev-parse", "HEAD").strip()
        changed = [line[3:] for line in git("status", "--porcelain", "--untracked-files=no").splitlines()]
        diff = git("diff", "HEAD") if changed else ""
    except (OSError, subprocess.SubprocessError):
        return None
    out = {"commit": commit, "dirty": bool(changed)}
    if changed:
        out.update(changed_files=changed, diff_sha256=hashlib.sha256(diff.encode()).hexdigest())
    return out


def to_jsonable(value: Any) -> Any:
    """Numpy, paths, dataclasses, tuples to plain JSON values; NaN and inf to None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_jsonable(dataclasses.asdict(value))
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON (atomically); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n")
    return path


def write_csv(path: str | Path, rows: Iterable[dict], columns: Sequence[str]) -> Path:
    """Write dict rows as CSV with the given column order (missing keys empty, NaN empty)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        out = []
        for c in columns:
            v = to_jsonable(row.get(c))
            out.append("" if v is None else (f"{v:.6g}" if isinstance(v, float) else v))
        w.writerow(out)
    atomic_write_text(path, buf.getvalue())
    return path


def fmt(x: Any, spec: str = ".2f") -> str:
    """A number for a table; ``n/a`` for None / NaN."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return format(x, spec)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]], align: str | None = None) -> str:
    """A GitHub-flavoured Markdown table; ``align`` is one of l/r/c per column (default: l then r)."""
    header = [str(h) for h in header]
    align = align or ("l" + "r" * (len(header) - 1))
    marks = {"l": ":---", "r": "---:", "c": ":---:"}
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(marks[a] for a in align) + " |"]
    for row in rows:
        lines.append("| " + " | ".join(str(c) for c in row) + " |")
    return "\n".join(lines) + "\n"


class RunRecord:
    """The ``run.json`` of one run folder.

    Args:
        out_dir: the run folder (created).
        experiment: "table", "rejectors", "ncf", "demo".
        params: the resolved parameters (JSON-able), seeds included.
        command: the command line (default: ``sys.argv``).
    """

    def __init__(self, out_dir: str | Path, experiment: str, params: dict, command: Sequence[str] | None = None):
        self.out_dir = Path(out_dir)
        self.experiment = experiment
        self.params = params
        self.command = list(command) if command is not None else list(sys.argv)
        self.files: list[str] = []
        self._t0 = time.time()
        self._info = {
            "experiment": experiment,
            "status": "running",
            "command": self.command,
            "cwd": os.getcwd(),
            "params": params,
            "package": "salo-bench",
            "version": package_version(),
            "git": git_state(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "host": platform.node(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(self._t0)),
        }

    def start(self) -> RunRecord:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        write_json(self.out_dir / RUN_FILE, self._info)
        return self

    def path(self, relative: str) -> Path:
        """A file of the run folder (its parent created), listed in ``run.json``."""
        p = self.out_dir / relative
        p.parent.mkdir(parents=True, exist_ok=True)
        if relative not in self.files:
            self.files.append(relative)
        return p

    def write_text(self, relative: str, text: str) -> Path:
        """Write a text file of the run folder atomically (see ``path``)."""
        path = self.path(relative)
        atomic_write_text(path, text)
        return path

    def write_run(self, stem: str, run) -> None:
        """A method's run (``tools.runners.MethodRun``) into the folder: its KITTI poses at ``STEM.txt`` and,
        for ours, its per-frame diagnostics at ``STEM_diagnostics.csv``."""
        from tools.runners import RunFiles, write_run_files

        diagnostics = self.path(f"{stem}_diagnostics.csv") if run.diagnostics is not None else None
        write_run_files(RunFiles(self.path(f"{stem}.txt"), diagnostics), run.poses, run.diagnostics)

    def finish(self, **extra: Any) -> None:
        t1 = time.time()
        self._info.update(
            status="complete",
            finished=time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(t1)),
            seconds=round(t1 - self._t0, 1),
            files=sorted(self.files),
            **extra,
        )
        write_json(self.out_dir / RUN_FILE, self._info)


def read_run(folder: str | Path) -> dict:
    """The ``run.json`` of a run folder."""
    return json.loads((Path(folder) / RUN_FILE).read_text())
