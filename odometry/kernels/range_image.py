"""Range images: rings x azimuth columns, and neighbourhoods across adjacent rings
(``odometry.scan_lines``; numpy reference: its plain-numpy rule).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def fill_range_image(rings: np.ndarray, points: np.ndarray, n_rings: int, n_columns: int) -> np.ndarray:
    """(n_rings, n_columns) int64: the row of the (last) point in each (ring, azimuth column) cell, -1 where none.

    rings: (N,) int in [0, n_rings); points: (N, 3), m. A point's column is
    ``floor((atan2(y, x) + pi) n_columns / (2 pi)) mod n_columns`` (``odometry.scan_lines.azimuth_columns``).
    """
    image = np.full((n_rings, n_columns), -1, dtype=np.int64)
    scale = n_columns / (2.0 * np.pi)
    for i in range(points.shape[0]):
        column = np.int64(math.floor((math.atan2(points[i, 1], points[i, 0]) + np.pi) * scale)) % n_columns
        image[rings[i], column] = i
    return image


@njit(cache=True, nogil=True, error_model="numpy")
def adjacent_ring_neighbourhoods(cloud: np.ndarray, rings: np.ndarray, image: np.ndarray, query_points: np.ndarray,
                                 neighbour_indices: np.ndarray, max_distance_m: float
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """``odometry.scan_lines.widen_one_ring_neighbourhoods`` in one pass: ((M, k) rows, (M,) widened).

    cloud: (N, 3) m; rings: (N,) int64; image: (n_rings, n_columns) ``range_image`` of the cloud;
    query_points: (M, 3) m; neighbour_indices: (M, k) rows of the cloud, nearest first. A neighbourhood
    on one ring takes, for each adjacent ring (below, then above), its first ``k // 2`` filled cells in
    the column order 0, -1, +1, -2, +2, ... about the query's azimuth column; the ring whose farthest
    such point is nearer (strictly: below wins a tie) replaces the last ``k // 2`` neighbours, when that
    farthest point lies within ``max_distance_m`` of the query point.
    """
    m, k = neighbour_indices.shape
    half = k // 2
    n_rings, n_columns = image.shape
    out = neighbour_indices.copy()
    widened = np.zeros(m, dtype=np.bool_)
    if half == 0:
        return out, widened
    scale = n_columns / (2.0 * np.pi)
    rows = np.empty(half, dtype=np.int64)
    best = np.empty(half, dtype=np.int64)
    for i in range(m):
        ring = rings[neighbour_indices[i, 0]]
        one_ring = True
        for j in range(1, k):
            if rings[neighbour_indices[i, j]] != ring:
                one_ring = False
                break
        if not one_ring:
            continue
        qx, qy, qz = query_points[i, 0], query_points[i, 1], query_points[i, 2]
        column = np.int64(math.floor((math.atan2(qy, qx) + np.pi) * scale)) % n_columns
        best_reach = np.inf
        for step in (-1, 1):
            adjacent = ring + step
            if adjacent < 0 or adjacent >= n_rings:
                continue
            found = 0
            reach = 0.0
            for o in range(2 * half + 1):
                offset = (o + 1) // 2 if o % 2 == 0 else -((o + 1) // 2)  # 0, -1, +1, -2, +2, ...
                row = image[adjacent, (column + offset) % n_columns]
                if row < 0:
                    continue
                rows[found] = row
                found += 1
                dx, dy, dz = cloud[row, 0] - qx, cloud[row, 1] - qy, cloud[row, 2] - qz
                reach = max(reach, math.sqrt(dx * dx + dy * dy + dz * dz))
                if found == half:
                    break
            if found == half and reach < best_reach:
                best_reach = reach
                best[:] = rows
        if best_reach <= max_distance_m:
            out[i, k - half:] = best
            widened[i] = True
    return out, widened
