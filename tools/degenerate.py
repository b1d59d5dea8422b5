"""Where a sequence is weakly constrained, from the simulator's truth and from a method's own diagnostics.

- The truth: a simulated sequence's ``degeneracy.csv`` (``simlidar.degeneracy``: per
  frame, the eigenvalues of the point-to-plane information of every return with its
  true normal, per point, and the weakest translational direction). A frame is weak
  where the smallest translational eigenvalue is below ``TRUTH_THRESHOLD``, the
  odometry's own default flag (``degeneracy.degenerate_eigenvalue``, per match: the
  same normalisation).
- A run of our odometry: its diagnostics CSV (``odometry.diagnostics.CSV_COLUMNS``),
  frames flagged ``degenerate`` or ``remapped``.

Both give ``odometry.diagnostics.DegenerateStretch`` runs of frames with their mean
weakest direction (``stretches_of``); ``salo simulate``, ``salo odometry``, ``salo
evaluate`` and ``salo bench`` print or shade them.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from odometry.config import DegeneracyParams
from simlidar.sequence import DatasetError

DEGENERACY_FILE = "degeneracy.csv"
# The odometry's own flag, per match; the truth's eigenvalues are per return: the same normalisation.
TRUTH_THRESHOLD = DegeneracyParams().degenerate_eigenvalue


@dataclass(frozen=True)
class FrameConstraints:
    """Per frame: frame numbers (N,), the smallest translational eigenvalue (N,), the weakest
    translational direction (N, 3) in the lidar frame, and the frames flagged weak (N,) bool."""

    frames: np.ndarray
    t_eig0: np.ndarray
    directions: np.ndarray
    weak: np.ndarray
    remapped: np.ndarray | None = None

    def stretches(self, min_gap: int = 1) -> list:
        """The weak frames as ``odometry.diagnostics.DegenerateStretch`` runs."""
        from odometry.diagnostics import stretches_of

        return stretches_of(self.frames, self.weak, self.directions, self.t_eig0, self.remapped, min_gap)


def _read_rows(path: Path) -> list[dict]:
    try:
        with open(path, newline="") as fh:
            return list(csv.DictReader(fh))
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read ({exc.strerror})") from None


def _column(rows: list[dict], name: str, path: Path) -> np.ndarray:
    try:
        return np.array([float(r[name]) if r[name] not in ("", None) else np.nan for r in rows])
    except (KeyError, ValueError):
        raise DatasetError(f"{path}: no numeric column {name!r}") from None


def truth_constraints(path: str | Path, threshold: float = TRUTH_THRESHOLD) -> FrameConstraints:
    """A sequence's ``degeneracy.csv`` (the folder or the file) -> ``FrameConstraints``, weak below ``threshold``."""
    path = Path(path)
    if path.is_dir():
        path = path / DEGENERACY_FILE
    rows = _read_rows(path)
    t_eig0 = _column(rows, "t_eig0", path)
    directions = np.column_stack([_column(rows, f"weak_{a}", path) for a in "xyz"]) if rows else np.zeros((0, 3))
    return FrameConstraints(_column(rows, "frame", path).astype(int), t_eig0, directions, t_eig0 < threshold)


def diagnostics_constraints(path: str | Path) -> FrameConstraints:
    """A run's diagnostics CSV (``odometry.diagnostics.write_diagnostics_csv``) -> its own ``FrameConstraints``."""
    path = Path(path)
    rows = _read_rows(path)
    remapped = _column(rows, "remapped", path) > 0
    weak = (_column(rows, "degenerate", path) > 0) | remapped
    directions = np.column_stack([_column(rows, f"weak_{a}", path) for a in "xyz"]) if rows else np.zeros((0, 3))
    return FrameConstraints(_column(rows, "frame", path).astype(int), _column(rows, "t_eig0", path), directions,
                            weak, remapped)


def describe_stretches(stretches: list, limit: int = 20, indent: str = "    ") -> list[str]:
    """Lines for a terminal: each stretch's frames and direction (``DegenerateStretch.describe``)."""
    lines = [indent + st.describe() for st in stretches[:limit]]
    if len(stretches) > limit:
        lines.append(f"{indent}... {len(stretches) - limit} more stretches")
    return lines


__all__ = ["DEGENERACY_FILE", "TRUTH_THRESHOLD", "FrameConstraints", "describe_stretches", "diagnostics_constraints",
           "truth_constraints"]
