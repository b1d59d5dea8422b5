"""Free space of recent scans: the nearest return per (ring, azimuth column) cell, and the test of points
against it (``odometry.dynamic``; numpy references in the tests: ``np.minimum.at``, and the same steps on arrays).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def nearest_per_cell(points: np.ndarray, times: np.ndarray, ring_mid_rad: np.ndarray, low_rad: float,
                     high_rad: float, n_columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The least range of the (N, 3) sensor-frame points in each (ring, azimuth column) cell, and their times.

    A point's ring: the nearest ring elevation (``searchsorted`` of its elevation in ``ring_mid_rad``, the (R-1,)
    midpoints between the rings' elevations); a point below ``low_rad`` or above ``high_rad`` is in no cell. Its
    column: ``floor((atan2(y, x) + pi) C / (2 pi))``, at most C - 1. times: (N,) per-point times, or (0,).

    Returns (R, C) the least range per cell, m (inf where none); (C,) the sum of the times of every point in
    each column, and (C,) their number (zeros without times).
    """
    n_rings = ring_mid_rad.shape[0] + 1
    image = np.full((n_rings, n_columns), np.inf)
    time_sums = np.zeros(n_columns)
    time_counts = np.zeros(n_columns, dtype=np.int64)
    with_times = times.shape[0] == points.shape[0]
    scale = n_columns / (2.0 * np.pi)
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        column = min(np.int64((math.atan2(y, x) + np.pi) * scale), n_columns - 1)
        if with_times:
            time_sums[column] += times[i]
            time_counts[column] += 1
        horizontal = math.sqrt(x * x + y * y)
        el = math.atan2(z, horizontal)
        if el < low_rad or el > high_rad:
            continue
        ring = np.searchsorted(ring_mid_rad, el)
        r = math.sqrt(horizontal * horizontal + z * z)
        if r < image[ring, column]:
            image[ring, column] = r
    return image, time_sums, time_counts


@njit(cache=True, nogil=True, error_model="numpy")
def seen_through(points_world: np.ndarray, R_start_world: np.ndarray, t_start_world: np.ndarray, xi: np.ndarray,
                 column_fraction: np.ndarray, nearest_m: np.ndarray, ring_mid_rad: np.ndarray, low_rad: float,
                 high_rad: float, margin_m: float, count: np.ndarray) -> None:
    """Add 1 to ``count[i]`` where one image saw through the (N, 3) world point i by more than ``margin_m``.

    The point goes into the image's sweep-start frame (``R_start_world p + t_start_world``), then into the
    sensor's frame at its column's firing time: ``exp(-s xi)`` to first order in ``s xi`` (``p - s (rho +
    omega x p)``; xi: (6,) the frame's twist (rho, omega), s: ``column_fraction`` (C,) of the column it falls
    in). Seen through: it lies within the rings' span and ``nearest_m`` (R, C) at its cell exceeds its range
    by more than the margin.
    """
    n_columns = nearest_m.shape[1]
    scale = n_columns / (2.0 * np.pi)
    moving = xi[0] != 0.0 or xi[1] != 0.0 or xi[2] != 0.0 or xi[3] != 0.0 or xi[4] != 0.0 or xi[5] != 0.0
    for i in range(points_world.shape[0]):
        p = points_world[i]
        x = R_start_world[0, 0] * p[0] + R_start_world[0, 1] * p[1] + R_start_world[0, 2] * p[2] + t_start_world[0]
        y = R_start_world[1, 0] * p[0] + R_start_world[1, 1] * p[1] + R_start_world[1, 2] * p[2] + t_start_world[1]
        z = R_start_world[2, 0] * p[0] + R_start_world[2, 1] * p[1] + R_start_world[2, 2] * p[2] + t_start_world[2]
        if moving:
            column = min(np.int64((math.atan2(y, x) + np.pi) * scale), n_columns - 1)
            s = column_fraction[column]
            dx = xi[0] + xi[4] * z - xi[5] * y
            dy = xi[1] + xi[5] * x - xi[3] * z
            dz = xi[2] + xi[3] * y - xi[4] * x
            x, y, z = x - s * dx, y - s * dy, z - s * dz
        el = math.atan2(z, math.sqrt(x * x + y * y))
        if el < low_rad or el > high_rad:
            continue
        ring = np.searchsorted(ring_mid_rad, el)
        column = min(np.int64((math.atan2(y, x) + np.pi) * scale), n_columns - 1)
        if nearest_m[ring, column] > math.sqrt(x * x + y * y + z * z) + margin_m:
            count[i] += 1
