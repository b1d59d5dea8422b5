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




def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory -> (times (N,) s, poses (N, 4, 4)); ``#`` comments and blank lines skipped.

    Raises DatasetError naming the file and line of a line that is not 8 numbers, or a
    quaternion that is not a rotation (norm far from 1).
    """
    from scipy.spatial.transform import Rotation

    from ..sequence import DatasetError

    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read trajectory ({exc.strerror})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 8:
            raise DatasetError(f"{path}:{lineno}: a TUM line needs 8 numbers (time tx ty tz qx qy qz qw), "
                               f"found {len(parts)}")
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise DatasetError(f"{path}:{lineno}: not a number in {line.strip()!r}") from None
    if not rows:
        raise DatasetError(f"{path}: no poses in the file")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        raise DatasetError(f"{path}: the trajectory holds non-finite numbers")
    norms = np.linalg.norm(data[:, 4:8], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if len(bad):
        raise DatasetError(f"{path}: the quaternion of pose {bad[0] + 1} has norm {norms[bad[0]]:.4g}, not 1")
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(data[:, 4:8]).as_matrix()
    poses[:, :3, 3] = data[:, 1:4]
    return data[:, 0].copy(), poses


__all__ = ["format_tum", "read_tum", "write_tum"]
