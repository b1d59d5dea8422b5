"""Nearest neighbours proven without a search (``odometry.icp.match``; reference: the k-d tree's search).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def reusable_matches(points: np.ndarray, searched_at: np.ndarray, nearest: np.ndarray, clear_m: np.ndarray,
                     target_points: np.ndarray, bound_m: float, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Which nearest neighbours found earlier still hold: ((M,) their distances, inf elsewhere; rows to search).

    points: (M, 3) the query points now; searched_at: (M, 3) where each was last searched from;
    nearest: (M,) the nearest target row found there (``len(target_points)``: none within the bound);
    clear_m: (M,) no other target point was within this of ``searched_at``. A point moved by s from
    where its nearest lay at d keeps it while ``d + s + margin < clear`` and ``d + margin < bound``
    (``odometry.icp.match``); d is computed as ``sqrt((dx^2 + dy^2) + dz^2)``, as the k-d tree does.
    """
    m = points.shape[0]
    n = target_points.shape[0]
    dist = np.full(m, np.inf)
    redo = np.empty(m, dtype=np.int64)
    count = 0
    for i in range(m):
        j = nearest[i]
        if j < n:
            sx, sy, sz = points[i, 0] - searched_at[i, 0], points[i, 1] - searched_at[i, 1], \
                points[i, 2] - searched_at[i, 2]
            shift = math.sqrt(sx * sx + sy * sy + sz * sz)
            dx, dy, dz = points[i, 0] - target_points[j, 0], points[i, 1] - target_points[j, 1], \
                points[i, 2] - target_points[j, 2]
            d = math.sqrt((dx * dx + dy * dy) + dz * dz)
            if d + shift + margin_m < clear_m[i] and d + margin_m < bound_m:
                dist[i] = d
                continue
        redo[count] = i
        count += 1
    return dist, redo[:count]
