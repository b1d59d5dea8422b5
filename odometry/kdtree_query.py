"""k-d tree queries on every core, through threads started once per process.

scipy's ``cKDTree.query(..., workers=-1)`` starts and joins new threads on every
call. The odometry queries a few dozen times per frame (the ICP's matches, the
map's normals), often for a few thousand points, and on a busy machine a new
thread waits milliseconds to be scheduled: measured on 2 shared cores, the
thread starts took more time than the searches. Here the query points are split
into one chunk per core; the calling thread answers the first and a pool kept
for the process the others (the searches release the GIL). Each point's answer
depends only on the point, so the result is that of one query.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.spatial import cKDTree

# A chunk smaller than this is not worth handing to another thread.
MIN_CHUNK_POINTS = 512

_pools: dict[int, tuple[int, ThreadPoolExecutor]] = {}


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not on every platform)
        return os.cpu_count() or 1


def _pool() -> tuple[int, ThreadPoolExecutor]:
    """(cores, this process's query threads: one fewer than the cores); a forked child gets its own."""
    pid = os.getpid()
    if pid not in _pools:
        n = cores()
        _pools[pid] = (n, ThreadPoolExecutor(max_workers=max(n - 1, 1), thread_name_prefix="kdquery"))
    return _pools[pid]


def query(tree: cKDTree, points: np.ndarray, k: int = 1,
          distance_upper_bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """``tree.query(points, k, distance_upper_bound=...)`` on every core: (distances, indices).

    points: (M, 3) m. Returns, as ``cKDTree.query``: for k = 1 (M,) distances (m) and
    indices, else (M, k) each, nearest first; a neighbour beyond the bound has distance
    inf and index ``tree.n``.
    """
    n_cores, pool = _pool()
    chunks = min(n_cores, len(points) // MIN_CHUNK_POINTS)
    if chunks <= 1:
        return tree.query(points, k=k, distance_upper_bound=distance_upper_bound)
    edges = np.linspace(0, len(points), chunks + 1).astype(int)
    others = [pool.submit(tree.query, points[a:b], k=k, distance_upper_bound=distance_upper_bound)
              for a, b in zip(edges[1:-1], edges[2:], strict=True)]
    parts = [tree.query(points[:edges[1]], k=k, distance_upper_bound=distance_upper_bound)]
    parts += [f.result() for f in others]
    return np.concatenate([d for d, _ in parts]), np.concatenate([i for _, i in parts])
