"""The point-to-plane system: its rows, normal equations and the rejection chain before them.

For a point p with unit normal n the residual's row is ``J = [n, p x n]`` (``plane_row``;
its numpy reference: ``simlidar.degeneracy.plane_jacobian``). ``plane_normal_equations`` and
``more_plane_rows`` sum ``J^T J`` and ``J^T r`` (``odometry.estimation.point_to_plane_step``);
``constraint_information`` sums scaled rows ``[n, (p x n) / L]`` (``odometry.constraints``);
``plane_gate`` and ``standard_rejection_system`` fuse the ICP's plane and NCF gates and its
distance / GCR / trimming chain with the system (``odometry.icp``'s one-by-one path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def plane_row(J: np.ndarray, px: float, py: float, pz: float, nx: float, ny: float, nz: float, scale: float) -> None:
    """Fill J (6,) with the row ``[n, (p x n) * scale]`` of point p and unit normal n (scale 1: the
    point-to-plane Jacobian, ``simlidar.degeneracy.plane_jacobian``; 1 / L: the scaled row)."""
    J[0], J[1], J[2] = nx, ny, nz
    J[3], J[4], J[5] = (py * nz - pz * ny) * scale, (pz * nx - px * nz) * scale, (px * ny - py * nx) * scale


@njit(cache=True, nogil=True, inline="always")
def _add_plane_row(H: np.ndarray, g: np.ndarray, J: np.ndarray, px: float, py: float, pz: float, qx: float,
                   qy: float, qz: float, nx: float, ny: float, nz: float) -> float:
    """Add one match's ``J^T J`` to H (upper triangle) and ``J^T r`` to g; returns its r^2."""
    r = nx * (px - qx) + ny * (py - qy) + nz * (pz - qz)
    plane_row(J, px, py, pz, nx, ny, nz, 1.0)
    for a in range(6):
        g[a] += J[a] * r
        for b in range(a, 6):
            H[a, b] += J[a] * J[b]
    return r * r


@njit(cache=True, nogil=True, inline="always")
def _mirror_upper(H: np.ndarray) -> None:
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]


@njit(cache=True, nogil=True, error_model="numpy")
def plane_normal_equations(source: np.ndarray, target: np.ndarray, normals: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, float]:
    """(H (6, 6), g (6,), sum of r^2) of point-to-plane matches.

    source p, target q, normals n: (N, 3) matched points (m) and unit target normals.
    With r = n . (p - q) and J = [n, p x n]: ``H = J^T J``, ``g = J^T r``
    (``odometry.estimation.point_to_plane_step``'s system).
    """
    return more_plane_rows(np.zeros((6, 6)), np.zeros(6), 0.0, source, target, normals)


@njit(cache=True, nogil=True, error_model="numpy")
def more_plane_rows(H: np.ndarray, g: np.ndarray, sum_r2: float, source: np.ndarray, target: np.ndarray,
                    normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``plane_normal_equations`` of rows added, in order, to a system (H, g, sum of r^2) already summed:
    the same values as the one system of all the rows (new arrays; the given ones are not changed)."""
    H = H.copy()
    g = g.copy()
    J = np.empty(6)
    for i in range(source.shape[0]):
        sum_r2 += _add_plane_row(H, g, J, source[i, 0], source[i, 1], source[i, 2], target[i, 0], target[i, 1],
                                 target[i, 2], normals[i, 0], normals[i, 1], normals[i, 2])
    _mirror_upper(H)
    return H, g, sum_r2


@njit(cache=True, nogil=True, error_model="numpy")
def plane_gate(moved: np.ndarray, centre: np.ndarray, source_index: np.ndarray, target_index: np.ndarray,
               normals: np.ndarray, uncertain: np.ndarray, rotation_scale_m: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plane and NCF gates of m matches in one pass: ((m,) has a plane, (m,) has a plane the NCF is
    sure of, (6, 6) scaled information ``J^T J`` of the sure ones).

    moved: (M, 3) source points at the current pose, m; centre: (3,) m; source_index, target_index: (m,)
    rows; normals: (m, 3) the target's normal at each match (nan: no plane); uncertain: (N,) bool per
    target row (the NCF's verdict), or (0,): every plane is sure, and the information is not summed
    (zeros: no verdict, nothing to restore). The information is
    ``odometry.constraints.constraint_information`` of the rows ``moved[source_index] - centre`` and
    ``normals`` where sure, summed in row order (``odometry.icp.usable_planes``).
    """
    m = source_index.shape[0]
    plane = np.empty(m, dtype=np.bool_)
    sure = np.empty(m, dtype=np.bool_)
    with_verdicts = uncertain.shape[0] > 0
    H = np.zeros((6, 6))
    J = np.empty(6)
    inv_L = 1.0 / rotation_scale_m
    for i in range(m):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        plane[i] = not math.isnan(nx)
        sure[i] = plane[i] and not (with_verdicts and uncertain[target_index[i]])
        if sure[i] and with_verdicts:
            j = source_index[i]
            px, py, pz = moved[j, 0] - centre[0], moved[j, 1] - centre[1], moved[j, 2] - centre[2]
            _add_constraint_row(H, J, px, py, pz, nx, ny, nz, inv_L)
    _mirror_upper(H)
    return plane, sure, H


@njit(cache=True, nogil=True, error_model="numpy")
def standard_rejection_system(moved: np.ndarray, target_points: np.ndarray, normals: np.ndarray,
                              source_index: np.ndarray, target_index: np.ndarray, distance: np.ndarray,
                              keep: np.ndarray, max_distance_m: float, gcr_bound_m: np.ndarray,
                              trim_fraction: float, centre: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The standard rejection chain and the point-to-plane system of what it keeps, in one pass each:
    ((3,) matches left after the distance rejector, GCR and trimming; H (6, 6); g (6,); sum of r^2).

    The m matches where ``keep`` holds are taken, as ``odometry.rejectors`` would: ``distance <
    max_distance_m``, then ``distance < gcr_bound_m[source_index]`` (gcr_bound_m (M,), or (0,): no
    GCR), then the ``floor(trim_fraction n)`` largest distances of the n left are dropped (where
    several share the cut's distance, the first rows are kept). The system is
    ``plane_normal_equations`` of the kept rows ``moved[source_index] - centre``,
    ``target_points[target_index] - centre`` and ``normals``, in row order (``odometry.icp.register``'s
    step; ``more_plane_rows`` adds the poles' rows).
    """
    m = source_index.shape[0]
    counts = np.zeros(3, dtype=np.int64)
    left = np.empty(m, dtype=np.int64)
    n = 0
    with_gcr = gcr_bound_m.shape[0] > 0
    for i in range(m):
        if keep[i] and distance[i] < max_distance_m:
            counts[0] += 1
            if with_gcr and not distance[i] < gcr_bound_m[source_index[i]]:
                continue
            left[n] = i
            n += 1
    counts[1] = n if with_gcr else counts[0]
    n_keep = n - int(math.floor(trim_fraction * n))
    cut = np.inf
    ties = 0
    if n_keep < n:
        d = np.empty(n)
        for a in range(n):
            d[a] = distance[left[a]]
        cut = np.partition(d, max(n_keep - 1, 0))[max(n_keep - 1, 0)]
        below = 0
        for a in range(n):
            below += d[a] < cut
        ties = n_keep - below
    counts[2] = max(n_keep, 0)
    H = np.zeros((6, 6))
    g = np.zeros(6)
    J = np.empty(6)
    rr = 0.0
    for a in range(n if n_keep > 0 else 0):
        i = left[a]
        if not distance[i] < cut:
            if distance[i] > cut or ties == 0:
                continue
            ties -= 1
        j, k = source_index[i], target_index[i]
        rr += _add_plane_row(H, g, J, moved[j, 0] - centre[0], moved[j, 1] - centre[1], moved[j, 2] - centre[2],
                             target_points[k, 0] - centre[0], target_points[k, 1] - centre[1],
                             target_points[k, 2] - centre[2], normals[i, 0], normals[i, 1], normals[i, 2])
    _mirror_upper(H)
    return counts, H, g, rr


@njit(cache=True, nogil=True, error_model="numpy")
def constraint_information(points: np.ndarray, normals: np.ndarray, rows: np.ndarray, rotation_scale_m: float
                           ) -> np.ndarray:
    """(6, 6) ``J^T J`` of the scaled rows ``J = [n, (p x n) / L]`` of points ``rows`` (int (K,)).

    points, normals: (M, 3) m and unit; the sum of ``odometry.constraints.constraint_rows``' outer products.
    """
    H = np.zeros((6, 6))
    J = np.empty(6)
    inv_L = 1.0 / rotation_scale_m
    for i in rows:
        _add_constraint_row(H, J, points[i, 0], points[i, 1], points[i, 2], normals[i, 0], normals[i, 1],
                            normals[i, 2], inv_L)
    _mirror_upper(H)
    return H


@njit(cache=True, nogil=True, inline="always")
def _add_constraint_row(H: np.ndarray, J: np.ndarray, px: float, py: float, pz: float, nx: float, ny: float,
                        nz: float, inv_L: float) -> None:
    """Add one point's scaled row ``J = [n, (p x n) / L]``'s ``J^T J`` to H (upper triangle)."""
    plane_row(J, px, py, pz, nx, ny, nz, inv_L)
    for a in range(6):
        for b in range(a, 6):
            H[a, b] += J[a] * J[b]
