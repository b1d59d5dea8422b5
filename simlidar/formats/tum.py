"""TUM trajectories: ``timestamp tx ty tz qx qy qz qw`` per line (what evo reads)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import atomic_write_text
from .number_lines import read_number_lines


def format_tum(poses: np.ndarray, times_s: np.ndarray) -> str:
    """(N, 4, 4) poses and (N,) times, s -> TUM trajectory text (``%.9f`` numbers, quaternion x y z w)."""
    from scipy.spatial.transform import Rotation  # not at import: `salo --help` loads the export's formats

    q = Rotation.from_matrix(poses[:, :3, :3]).as_quat()  # x y z w
    rows = np.column_stack([times_s, poses[:, :3, 3], q])
    return "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in rows)


def write_tum(path: str | Path, poses: np.ndarray, times_s: np.ndarray) -> None:
    """Write ``format_tum`` atomically."""
    atomic_write_text(path, format_tum(poses, times_s))




def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory -> (times (N,) s, poses (N, 4, 4)); ``#`` comments and blank lines skipped.

    Raises DatasetError naming the file and line of a line that is not 8 numbers, or a
    quaternion that is not a rotation (norm far from 1).
    """
    from scipy.spatial.transform import Rotation

    from ..sequence import DatasetError

    path = Path(path)
    data = read_number_lines(path, 8, "a TUM line needs 8 numbers (time tx ty tz qx qy qz qw)", "trajectory")
    norms = np.linalg.norm(data[:, 4:8], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if len(bad):
        raise DatasetError(f"{path}: the quaternion of pose {bad[0] + 1} has norm {norms[bad[0]]:.4g}, not 1")
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(data[:, 4:8]).as_matrix()
    poses[:, :3, 3] = data[:, 1:4]
    return data[:, 0].copy(), poses


__all__ = ["format_tum", "read_tum", "write_tum"]
