"""The point-to-plane information of a scan (``simlidar.degeneracy``) in one pass over its returns."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def information_sums(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(6, 6) ``sum J^T J`` of (N, 3) points and unit normals, ``J = [n, p x n]`` (translation, rotation).

    numpy: ``simlidar.degeneracy.information_matrix`` (equal to rounding: the sums' order differs).
    The 21 sums of the upper triangle are named scalars, which the compiler keeps in registers (an
    array of them was stored and loaded at every point: twice the time); each is summed over the
    points in order, as before.
    """
    s00 = s01 = s02 = s03 = s04 = s05 = 0.0
    s11 = s12 = s13 = s14 = s15 = 0.0
    s22 = s23 = s24 = s25 = 0.0
    s33 = s34 = s35 = 0.0
    s44 = s45 = 0.0
    s55 = 0.0
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        j0, j1, j2 = normals[i, 0], normals[i, 1], normals[i, 2]
        j3 = py * j2 - pz * j1
        j4 = pz * j0 - px * j2
        j5 = px * j1 - py * j0
        s00 += j0 * j0
        s01 += j0 * j1
        s02 += j0 * j2
        s03 += j0 * j3
        s04 += j0 * j4
        s05 += j0 * j5
        s11 += j1 * j1
        s12 += j1 * j2
        s13 += j1 * j3
        s14 += j1 * j4
        s15 += j1 * j5
        s22 += j2 * j2
        s23 += j2 * j3
        s24 += j2 * j4
        s25 += j2 * j5
        s33 += j3 * j3
        s34 += j3 * j4
        s35 += j3 * j5
        s44 += j4 * j4
        s45 += j4 * j5
        s55 += j5 * j5
    return np.array([
        (s00, s01, s02, s03, s04, s05),
        (s01, s11, s12, s13, s14, s15),
        (s02, s12, s22, s23, s24, s25),
        (s03, s13, s23, s33, s34, s35),
        (s04, s14, s24, s34, s44, s45),
        (s05, s15, s25, s35, s45, s55),
    ])


__all__ = ["information_sums"]
