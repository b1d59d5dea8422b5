"""The point-to-plane information of a scan (``simlidar.degeneracy``) in one pass over its returns."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def information_sums(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(6, 6) ``sum J^T J`` of (N, 3) points and unit normals, ``J = [n, p x n]`` (translation, rotation).

    numpy: ``simlidar.degeneracy.information_matrix`` (equal to rounding: the sums' order differs).
    """
    acc = np.zeros(21)
    J = np.empty(6)
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        J[0], J[1], J[2] = nx, ny, nz
        J[3] = py * nz - pz * ny
        J[4] = pz * nx - px * nz
        J[5] = px * ny - py * nx
        k = 0
        for a in range(6):
            ja = J[a]
            for b in range(a, 6):
                acc[k] += ja * J[b]
                k += 1
    H = np.empty((6, 6))
    k = 0
    for a in range(6):
        for b in range(a, 6):
            H[a, b] = acc[k]
            H[b, a] = acc[k]
            k += 1
    return H


__all__ = ["information_sums"]
