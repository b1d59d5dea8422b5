"""Returns alone on their ring: the weather's false points, kept out of the surfaces.

A surface crossed by a spinning lidar's ring is hit by consecutive beams at ranges that change
smoothly (a road along a ring keeps its range; a wall's changes by about r dphi tan(incidence)
a column). Fog's backscatter, a raindrop or a snowflake returns on one beam, at a range drawn
independently of the beams beside it. So a return with fewer than two neighbours on its ring (up to
``columns`` azimuth columns either side) within a range tolerance of it is alone (two: one weather
return in ten finds one neighbour by chance in light fog; a surface's edge still has two on its side): in fog,
where most beams end in the air a few metres out, such returns are the false ones. Dropped from
the points the voxel grid, the normals and the map are made of, their random neighbourhoods can no
longer pass as planes that ride with the sensor. (The poles are found in the full scan: a post
one column wide is alone on its ring too, and the poles stage has its own weather filter.)

The tolerance, m, is ``max(min_m, fraction * range)``: the range noise at the least, and the
change a surface seen at up to about 80 deg incidence makes over a column of a 0.2 deg sensor at
the most (``clean.isolation_*``).
"""

from __future__ import annotations

import numpy as np

from .scan_lines import azimuth_columns


def isolated_returns(points: np.ndarray, rings: np.ndarray, n_rings: int, n_columns: int, columns: int,
                     neighbours: int, min_m: float, fraction: float) -> np.ndarray:
    """(N,) bool: the returns with fewer than ``neighbours`` neighbours on their ring within the range tolerance.

    points: (N, 3) as measured, sensor frame, m. rings: (N,) int in [0, n_rings). n_columns: the
    sensor's azimuth columns per sweep. columns: how many columns either side are looked at. min_m,
    fraction: the tolerance ``max(min_m, fraction * range)``, m. A cell holding two returns (a column
    finer than the sensor's) keeps one; the other still finds its neighbours.
    """
    n = len(points)
    if n == 0 or columns < 1:
        return np.zeros(n, dtype=bool)
    rings = np.asarray(rings, dtype=np.int64)
    ranges = np.sqrt(np.einsum("ij,ij->i", points, points))
    cols = azimuth_columns(points, n_columns)
    image = np.full((n_rings, n_columns), np.nan)
    image[rings, cols] = ranges
    tolerance = np.maximum(min_m, fraction * ranges)
    found = np.zeros(n, dtype=np.int64)
    for step in range(1, columns + 1):
        for side in (-step, step):
            neighbour = image[rings, (cols + side) % n_columns]
            # (nan, no return there, compares False: an empty cell is no neighbour)
            found += np.abs(neighbour - ranges) <= tolerance
    return found < neighbours
