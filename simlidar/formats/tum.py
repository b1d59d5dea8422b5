"""TUM trajectories: ``timestamp tx ty tz qx qy qz qw`` per line (what evo reads)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import atomic_write_text


def format_tum(poses: np.ndarray, times_s: np.ndarray) -> str:
    """(N, 4, 4) poses and (N,) times, s -> TUM trajectory text (``%.9f`` numbers, quaternion x y z w)."""
    from scipy.spatial.transform import Rotation  # not at import: `salo --help` loads the export's formats

    q = Rotation.from_matrix(poses[:, :3, :3]).as_quat()  # x y z w
    rows = np.column_stack([times_s, poses[:, :3, 3], q])
    return "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in rows)


def write_tum(path: str | Path, poses: np.ndarray, times_s: np.ndarray) -> None:
    """Write ``format_tum`` atomically."""
    atomic_write_text(path, format_tum(poses, times_s))


__all__ = ["format_tum", "write_tum"]
