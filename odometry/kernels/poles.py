"""Poles: foreground runs of a range image and the offset votes of the cold start (``odometry.poles``;
numpy references in the tests).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def foreground_runs(image: np.ndarray, points: np.ndarray, times: np.ndarray, azimuth_step_rad: float,
                    max_width_m: float, min_gap_m: float, gap_fraction: float, run_tol_m: float,
                    run_tol_fraction: float, max_column_gap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Narrow runs of returns standing in front of what lies on both sides of them, ring by ring.

    image: (R, C) int rows of ``points`` per (ring, azimuth column), -1 where none
    (``odometry.scan_lines.range_image``); points: (N, 3) as measured, m; times: (N,) firing
    times, s (nan: none). Along a ring, consecutive returns (columns at most ``max_column_gap``
    apart) whose ranges differ by less than ``run_tol_m + run_tol_fraction * r`` form a run. A
    run is kept when it spans at most ``max_width_m`` across the beam (mean range x columns x
    azimuth step) and the returns beside it on both sides (each at most ``max_column_gap``
    columns away; a run at the sweep's seam or beside a gap is not judged) lie farther than its
    farthest return by more than ``min_gap_m + gap_fraction * r``.

    Returns (K, 3) the kept runs' centroids, m, (K,) their numbers of returns, (K,) their mean times, s.
    """
    n_rings, n_columns = image.shape
    centroids = np.empty((points.shape[0], 3))
    counts = np.empty(points.shape[0], dtype=np.int64)
    mean_times = np.empty(points.shape[0])
    cols = np.empty(n_columns, dtype=np.int64)
    rows = np.empty(n_columns, dtype=np.int64)
    ranges = np.empty(n_columns)
    k = 0
    for ring in range(n_rings):
        n = 0
        for c in range(n_columns):
            row = image[ring, c]
            if row >= 0:
                cols[n], rows[n] = c, row
                ranges[n] = math.sqrt(points[row, 0] ** 2 + points[row, 1] ** 2 + points[row, 2] ** 2)
                n += 1
        i = 0
        while i < n:
            j = i
            while (j + 1 < n and cols[j + 1] - cols[j] <= max_column_gap
                   and abs(ranges[j + 1] - ranges[j]) < run_tol_m + run_tol_fraction * ranges[j]):
                j += 1
            if i > 0 and j < n - 1 and cols[i] - cols[i - 1] <= max_column_gap \
                    and cols[j + 1] - cols[j] <= max_column_gap:
                r_max, r_sum = 0.0, 0.0
                for a in range(i, j + 1):
                    r_max = max(r_max, ranges[a])
                    r_sum += ranges[a]
                r_mean = r_sum / (j - i + 1)
                gap = min_gap_m + gap_fraction * r_mean
                width = r_mean * (cols[j] - cols[i] + 1) * azimuth_step_rad
                if width <= max_width_m and ranges[i - 1] > r_max + gap and ranges[j + 1] > r_max + gap:
                    sx, sy, sz, st = 0.0, 0.0, 0.0, 0.0
                    for a in range(i, j + 1):
                        sx += points[rows[a], 0]
                        sy += points[rows[a], 1]
                        sz += points[rows[a], 2]
                        st += times[rows[a]]
                    m = j - i + 1
                    centroids[k, 0], centroids[k, 1], centroids[k, 2] = sx / m, sy / m, sz / m
                    counts[k] = m
                    mean_times[k] = st / m
                    k += 1
            i = j + 1
    return centroids[:k], counts[:k], mean_times[:k]


@njit(cache=True, nogil=True, error_model="numpy")
def consensus_votes(offsets: np.ndarray, starts: np.ndarray, radius: float) -> np.ndarray:
    """(K,) for each of (K, 2) ``offsets``, how many groups hold an offset within ``radius`` of it.

    Group g is rows ``starts[g]:starts[g + 1]``, sorted by x within the group (so only a band of
    x is tested). numpy: ``[sum(np.any(np.hypot(*(offsets[s:e] - o).T) <= radius) for s, e in
    zip(starts[:-1], starts[1:])) for o in offsets]``.
    """
    band = radius * (1.0 + 1e-9)  # (a hair wider than the test: the band only skips rows)
    votes = np.zeros(offsets.shape[0], dtype=np.int64)
    for k in range(offsets.shape[0]):
        x, y = offsets[k, 0], offsets[k, 1]
        n = 0
        for g in range(len(starts) - 1):
            lo, hi = starts[g], starts[g + 1]
            end = hi
            while lo < hi:  # the group's first row with x >= x - band
                mid = (lo + hi) // 2
                if offsets[mid, 0] < x - band:
                    lo = mid + 1
                else:
                    hi = mid
            j = lo
            while j < end and offsets[j, 0] <= x + band:
                if math.hypot(offsets[j, 0] - x, offsets[j, 1] - y) <= radius:
                    n += 1
                    break
                j += 1
        votes[k] = n
    return votes
