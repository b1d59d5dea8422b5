"""Text files of whitespace-separated numbers, a fixed count per line (KITTI poses, TUM trajectories)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..sequence import DatasetError


def read_number_lines(path: str | Path, count: int, line_meaning: str, file_kind: str = "file") -> np.ndarray:
    """The numbers of ``path`` as an (N, count) float64 array; ``#`` comments and blank lines skipped.

    line_meaning: what a line holds, for the error (e.g. "a KITTI pose line needs 12 numbers
    (3x4 row-major)"). Raises DatasetError naming the file and line of a line with another
    count or a word that is not a number, an unreadable or empty file, or non-finite numbers.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read {file_kind} ({exc.strerror})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split()
        if len(parts) != count:
            raise DatasetError(f"{path}:{lineno}: {line_meaning}, found {len(parts)}")
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise DatasetError(f"{path}:{lineno}: not a number in {line.strip()!r}") from None
    if not rows:
        raise DatasetError(f"{path}: no poses in the file")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        raise DatasetError(f"{path}: the {file_kind} holds non-finite numbers")
    return data


__all__ = ["read_number_lines"]
