"""Returns alone in the air: the weather's false points, kept out of the surfaces.

A surface crossed by a spinning lidar's beams is hit by neighbouring beams at ranges that change
smoothly (a road along a ring keeps its range; a wall's changes by about r dphi tan(incidence) a
column). Fog's backscatter, a raindrop or a snowflake returns on one beam, at a range drawn
independently of the beams beside it. So a return with fewer than ``neighbours`` of its neighbouring
beams ending within a range tolerance of it is alone: in fog, where most beams end in the air a few
metres out, such returns are the false ones. Dropped from the points the voxel grid, the normals and
the map are made of, their random neighbourhoods can no longer pass as planes that ride with the
sensor. (The poles are found in the full scan: a post one column wide is alone on its ring, and the
poles stage has its own weather filter.)

Two looks. First the range image: the ``columns`` azimuth columns either side on the return's own
ring; a return with ``neighbours`` of them within the tolerance is not alone, nor one on a smooth run of
four columns of its ring (every second difference of their ranges within its tolerance: a wall seen at
grazing incidence, 20-80 m along a tunnel, changes range by more than the tolerance a column, steadily;
without the run 13-36 % of those returns were alone, in clear air). Compiled, it settles most of a scan.
The rest are judged by their nearest beams in direction (a k-d tree over the
unit vectors, ``2 columns + 2`` of them: the ring's and the rings' beside it), whatever ring they
were given: rings inferred from elevations a sensor's table does not quite match (KITTI's HDL-64E)
split a laser's returns over two rows, and there 12-17 % of the returns found no neighbour on their
row (1.5-1.8 % after the second look). The tolerance, m, is ``max(min_m, fraction * range)``: the
range noise at the least, the change a surface seen at up to about 80 deg incidence makes over a
column of a 0.2 deg sensor at the most (``clean.isolation_*``).
"""

from __future__ import annotations

import numpy as np

from .kdtree import KDTree
from .kernels.isolation import alone_on_ring
from .scan_lines import azimuth_columns


def isolated_returns(points: np.ndarray, rings: np.ndarray | None, n_rings: int, n_columns: int, columns: int,
                     neighbours: int, min_m: float, fraction: float) -> np.ndarray:
    """(N,) bool: the returns with fewer than ``neighbours`` neighbouring beams ending within the tolerance.

    points: (N, 3) as measured, sensor frame, m. rings: (N,) int in [0, n_rings), or None (no range image:
    every return is judged by its nearest beams in direction). n_columns: the sensor's azimuth columns per
    sweep. columns: how many columns either side the range image's look reaches (and 2 columns + 2 nearest
    beams the second look takes). min_m, fraction: the tolerance ``max(min_m, fraction * range)``, m.
    """
    n = len(points)
    if n == 0:
        return np.zeros(n, dtype=bool)
    points = np.asarray(points, dtype=np.float64)
    ranges = np.sqrt(np.einsum("ij,ij->i", points, points))
    tolerance = np.maximum(min_m, fraction * ranges)
    candidate = np.ones(n, dtype=bool)
    if rings is not None:
        cols = azimuth_columns(points, n_columns)
        candidate = alone_on_ring(np.asarray(rings, dtype=np.int64), cols, ranges, tolerance, n_rings, n_columns,
                                  columns, neighbours)
    alone = np.zeros(n, dtype=bool)
    rows = np.flatnonzero(candidate)
    k = min(2 * columns + 2, n - 1)
    if len(rows) == 0 or k < 1:
        alone[rows] = True
        return alone
    directions = points / np.maximum(ranges, 1e-12)[:, None]
    _, idx = KDTree(directions).query(directions[rows], k=k + 1)  # (the return itself is its own nearest)
    beside = ranges[idx.reshape(len(rows), k + 1)[:, 1:]]
    near = np.count_nonzero(np.abs(beside - ranges[rows, None]) <= tolerance[rows, None], axis=1)
    alone[rows] = near < neighbours
    return alone
