"""The odometry's k-d tree: pykdtree's, answering as scipy's ``cKDTree`` does.

The odometry builds a few trees a frame (the raw scan's, the scan's points', the
map's) and queries them a dozen times (the ICP's matches, the normals' k nearest
neighbours, the map's spacing check). pykdtree builds a tree in about half of
scipy's time and answers nearest-neighbour queries on every core (OpenMP) in
about half of scipy's on two threads (``python -m tools.bench_odometry`` has the
figures per stage). The answers are the same: the same distances; among points at
exactly the same distance (a real scan's duplicated returns) either may be named.
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree as _PyKDTree

# Points per leaf: 32 builds a 50k-point map's tree in 2.5 ms where pykdtree's default 16 takes 3.2,
# and answers its two-nearest and twelve-nearest queries as fast (measured on the benchmark's maps).
LEAF_SIZE = 32


class KDTree:
    """A k-d tree over (N, 3) points, m.

    ``data`` is the (N, 3) float64 points it holds, ``n`` their number. Queries answer
    as ``scipy.spatial.cKDTree.query``: a neighbour beyond the bound (or beyond N) has
    distance inf and index ``n``.
    """

    def __init__(self, points: np.ndarray):
        self.data = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        self.n = len(self.data)
        # (pykdtree cannot hold no points)
        self._tree = _PyKDTree(self.data, leafsize=LEAF_SIZE) if self.n else None

    def query(self, points: np.ndarray, k: int = 1,
              distance_upper_bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """(distances, indices) of each point's k nearest: (M,) each for k = 1, else (M, k), nearest first.

        points: (M, 3) m. distances in m (float64), indices intp.
        """
        q = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        shape = (len(q),) if k == 1 else (len(q), k)
        if self._tree is None or len(q) == 0:
            return np.full(shape, np.inf), np.full(shape, self.n, dtype=np.intp)
        bound = None if not np.isfinite(distance_upper_bound) else float(distance_upper_bound)
        dist, idx = self._tree.query(q, k=k, distance_upper_bound=bound)
        idx = idx.astype(np.intp).reshape(shape)
        dist = dist.reshape(shape)
        # pykdtree marks a missing neighbour by an index past the data (n with a bound,
        # 2**32 - 1 without, when k > n): both become cKDTree's (inf, n)
        missing = idx >= self.n
        if missing.any():
            idx[missing] = self.n
            dist[missing] = np.inf
        return dist, idx
