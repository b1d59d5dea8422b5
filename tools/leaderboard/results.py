"""One method on one sequence: run it on the staged input, evaluate against the truth, keep the result.

Results are stored per method and sequence, so a bench adds a method without
re-running the others::

    OUT/results/<method>/<sequence>/
      poses.txt          the method's KITTI poses (NaN after a divergence)
      diagnostics.csv    our odometry's per-frame diagnostics (its own degenerate flags)
      config.yaml        our odometry's configuration of the run
      command.log        an external command's output
      result.json        written last (atomically): the method's key, the sequence's key, status,
                         figures, frames/s, the frames the method flagged, the error of a failed run

A stored result is reused while its method key (``tools.methods.Method.key``: the
configuration, command or versions) and its sequence key (the manifest's hash) are
those of the run asked for; otherwise it is redone.
"""

from __future__ import annotations

import json
import logging
import math
import shutil
import time
import traceback
from pathlib import Path

import numpy as np

from simlidar.formats.atomic import atomic_write_text

log = logging.getLogger(__name__)

RESULT_FILE = "result.json"


def result_dir(out: str | Path, method: str, sequence_id: str) -> Path:
    return Path(out) / "results" / method / sequence_id


def read_result(folder: Path) -> dict | None:
    try:
        data = json.loads((folder / RESULT_FILE).read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) else None


def is_current(result: dict | None, method, sequence) -> bool:
    """True when a stored result is of this method's settings on this very sequence."""
    return (result is not None and result.get("method_key") == method.key
            and result.get("sequence_key") == sequence.key)


def _finite(value):
    return value if isinstance(value, (int, float)) and math.isfinite(value) else None


def evaluate(gt: np.ndarray, poses: np.ndarray) -> dict:
    """The leaderboard's figures of ``poses`` against ``gt`` (both (N, 4, 4)): KITTI t_err and r_err over
    the generalisation suite's segment lengths, vertical drift, aligned ATE, RPE
    (``tools.family_suite.trajectory_figures``), and failed (diverged or t_err above its bound)."""
    from tools.family_suite import FAILURE_T_ERR_PCT, trajectory_figures

    figures = trajectory_figures(gt, poses)
    t_err = figures.get("t_err_pct")
    figures["failed"] = bool(figures.get("diverged") or (t_err is not None and math.isfinite(t_err)
                                                           and t_err > FAILURE_T_ERR_PCT))
    return {k: (_finite(v) if isinstance(v, float) else v) for k, v in figures.items()}


def run_one(method, sequence, out: str | Path, fields, *, timeout_s: float, workdir: str | Path | None = None,
            on_frame=None) -> dict:
    """Run ``method`` (``tools.methods.Method``) on ``sequence`` (``BenchSequence``), store and return the result.

    fields: the per-point fields handed over when the sequence does not fix them. A failure
    of the method is a result too (status "failed", its error), never an exception.
    """
    from simlidar.dataset import open_sequence
    from simlidar.formats.kitti import write_kitti_poses
    from tools.methods import MethodError, run_method

    folder = result_dir(out, method.name, sequence.id)
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    seq = open_sequence(sequence.path)
    result = {"method": method.name, "label": method.label, "kind": method.kind, "method_key": method.key,
              "sequence": sequence.id, "family": sequence.family, "sequence_key": sequence.key,
              "sequence_path": str(sequence.path), "frames": len(seq)}
    fields = tuple(sequence.fields if sequence.fields is not None else fields)
    result["fields"] = list(fields)
    t0 = time.perf_counter()
    try:
        output = run_method(method, seq, fields=fields, workdir=workdir, log_path=folder / "command.log",
                            timeout_s=timeout_s, on_frame=on_frame)
        write_kitti_poses(folder / "poses.txt", output.poses)
        if output.diagnostics is not None:
            from odometry.diagnostics import write_diagnostics_csv

            write_diagnostics_csv(folder / "diagnostics.csv", output.diagnostics)
        if isinstance(output.settings.get("config"), dict):  # ours: what its page recomputes the kept points by
            import yaml

            atomic_write_text(folder / "config.yaml", yaml.safe_dump(output.settings["config"], sort_keys=False))
        flagged = [] if output.degenerate is None else [int(k) for k in np.flatnonzero(output.degenerate)]
        result.update(status="ok", error=None, note=output.note, seconds=output.seconds,
                      frames_per_second=_finite(output.frames_per_second), flagged_frames=flagged,
                      has_diagnostics=output.degenerate is not None, figures=evaluate(seq.poses, output.poses))
    except MethodError as exc:
        result.update(status="failed", error=str(exc), seconds=time.perf_counter() - t0, figures={})
    except Exception as exc:  # noqa: BLE001 - one method failing must not end the bench; its row says why
        log.warning("%s on %s failed: %s", method.name, sequence.id, exc)
        atomic_write_text(folder / "error.txt", traceback.format_exc())
        result.update(status="failed", error=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0,
                      figures={})
    atomic_write_text(folder / RESULT_FILE, json.dumps(result, indent=1, sort_keys=True, allow_nan=False) + "\n")
    return result


__all__ = ["RESULT_FILE", "evaluate", "is_current", "read_result", "result_dir", "run_one"]
