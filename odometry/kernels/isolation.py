"""The isolation's look along a return's own ring in the range image (``odometry.isolation``), in one pass."""

from __future__ import annotations

import numpy as np
from numba import njit

# A smooth run: this many consecutive columns of a ring, the return's among them, whose range's second
# differences all lie within the return's tolerance.
SMOOTH_RUN = 4


@njit(cache=True, nogil=True, error_model="numpy")
def alone_on_ring(rings: np.ndarray, cols: np.ndarray, ranges: np.ndarray, tolerance: np.ndarray, n_rings: int,
                  n_columns: int, columns: int, neighbours: int) -> np.ndarray:
    """(N,) bool: the returns their own ring does not support.

    rings, cols: (N,) int64 row and azimuth column of each return in the (n_rings, n_columns) range image;
    ranges, tolerance: (N,) m. A return is supported when at least ``neighbours`` of the ``columns`` cells
    either side on its ring hold a range within its tolerance of its own, or when it lies in a smooth run of
    ``SMOOTH_RUN`` filled cells (every second difference of their ranges within its tolerance): a surface
    seen at grazing incidence changes range by metres a column, steadily; a particle or fog's backscatter,
    at a range drawn apart from its neighbours', lies on no such run. A cell holding two returns keeps the
    last one's range; the other is judged against it like any neighbour.
    """
    n = ranges.shape[0]
    image = np.full((n_rings, n_columns), np.nan)
    for i in range(n):
        image[rings[i], cols[i]] = ranges[i]
    alone = np.zeros(n, dtype=np.bool_)
    run = np.empty(SMOOTH_RUN)
    for i in range(n):
        row, c, r, tol = rings[i], cols[i], ranges[i], tolerance[i]
        found = 0
        for step in range(1, columns + 1):
            for side in (-step, step):
                if abs(image[row, (c + side) % n_columns] - r) <= tol:  # (nan: no return there, no neighbour)
                    found += 1
        if found >= neighbours:
            continue
        smooth = False
        for start in range(c - SMOOTH_RUN + 1, c + 1):
            filled = True
            for j in range(SMOOTH_RUN):
                column = start + j
                run[j] = r if column == c else image[row, column % n_columns]
                if np.isnan(run[j]):
                    filled = False
                    break
            if not filled:
                continue
            smooth = True
            for j in range(SMOOTH_RUN - 2):
                if abs(run[j] - 2.0 * run[j + 1] + run[j + 2]) > tol:
                    smooth = False
                    break
            if smooth:
                break
        alone[i] = not smooth
    return alone
