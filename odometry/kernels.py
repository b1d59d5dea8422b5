"""Compiled inner loops of the odometry (numba): one pass over the rows where numpy needs a dozen.

The odometry's per-frame arrays are thousands of rows, not millions: a numpy
expression over them costs more in its calls and temporaries than in its
arithmetic (a frame of the default made about 12,000 numpy calls before them). These
kernels fuse the few hottest chains into one loop each; each one's docstring
names the numpy expression it computes (the tests compare them). Compiled on
first use and cached beside this file (``cache=True``), so a process pays the
compilation once per machine, not per run.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _add_plane_row(H: np.ndarray, g: np.ndarray, J: np.ndarray, px: float, py: float, pz: float, qx: float,
                   qy: float, qz: float, nx: float, ny: float, nz: float) -> float:
    """Add one match's ``J^T J`` to H (upper triangle) and ``J^T r`` to g; returns its r^2."""
    r = nx * (px - qx) + ny * (py - qy) + nz * (pz - qz)
    J[0], J[1], J[2] = nx, ny, nz
    J[3], J[4], J[5] = py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx
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
    J[0], J[1], J[2] = nx, ny, nz
    J[3], J[4], J[5] = (py * nz - pz * ny) * inv_L, (pz * nx - px * nz) * inv_L, (px * ny - py * nx) * inv_L
    for a in range(6):
        for b in range(a, 6):
            H[a, b] += J[a] * J[b]


@njit(cache=True, nogil=True, error_model="numpy")
def eigh3_closed_form(A: np.ndarray, min_rel_gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form eigen-decomposition of (M, 3, 3) symmetric matrices, descending.

    Returns (w (M, 3), V (M, 3, 3), columns the eigenvectors, v_0 = v_1 x v_2, and (M,) bool
    ``unsure``: the answer is not to be trusted, because the two smallest eigenvalues are closer
    than ``min_rel_gap * |lambda_0|`` (where the closed form loses digits) or a value is not finite.
    ``odometry.normals.symmetric_eigh_descending`` sends those to LAPACK.
    Method: eigenvalues from the trigonometric solution of the characteristic cubic; v_2 the
    longest cross product of two rows of ``A - lambda_2 I``; v_0, v_1 from the 2 x 2 problem in
    the plane orthogonal to v_2; lambda_2 refined as the Rayleigh quotient of v_2.
    """
    m = A.shape[0]
    w = np.empty((m, 3))
    V = np.empty((m, 3, 3))
    unsure = np.zeros(m, dtype=np.bool_)
    for i in range(m):
        a00, a01, a02 = A[i, 0, 0], A[i, 0, 1], A[i, 0, 2]
        a11, a12, a22 = A[i, 1, 1], A[i, 1, 2], A[i, 2, 2]
        q = (a00 + a11 + a22) / 3.0
        b00, b11, b22 = a00 - q, a11 - q, a22 - q
        p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0)
        det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
        r = min(max(det / (2.0 * p**3), -1.0), 1.0) if p > 0 else 0.0
        phi = math.acos(r) / 3.0
        lam2 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        # rows of A - lambda_2 I and their three cross products; the longest spans the null space
        r0x, r0y, r0z = a00 - lam2, a01, a02
        r1x, r1y, r1z = a01, a11 - lam2, a12
        r2x, r2y, r2z = a02, a12, a22 - lam2
        c0x, c0y, c0z = r0y * r1z - r0z * r1y, r0z * r1x - r0x * r1z, r0x * r1y - r0y * r1x
        c1x, c1y, c1z = r0y * r2z - r0z * r2y, r0z * r2x - r0x * r2z, r0x * r2y - r0y * r2x
        c2x, c2y, c2z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
        n0 = c0x * c0x + c0y * c0y + c0z * c0z
        n1 = c1x * c1x + c1y * c1y + c1z * c1z
        n2 = c2x * c2x + c2y * c2y + c2z * c2z
        if n0 >= n1 and n0 >= n2:
            s = math.sqrt(n0)
            v2x, v2y, v2z = c0x / s, c0y / s, c0z / s
        elif n1 >= n2:
            s = math.sqrt(n1)
            v2x, v2y, v2z = c1x / s, c1y / s, c1z / s
        else:
            s = math.sqrt(n2)
            v2x, v2y, v2z = c2x / s, c2y / s, c2z / s
        # an orthonormal basis (e1, e2) of the plane orthogonal to v_2
        if abs(v2x) > abs(v2y):
            e1x, e1y, e1z = -v2z, 0.0, v2x
        else:
            e1x, e1y, e1z = 0.0, v2z, -v2y
        s = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
        e1x, e1y, e1z = e1x / s, e1y / s, e1z / s
        e2x, e2y, e2z = v2y * e1z - v2z * e1y, v2z * e1x - v2x * e1z, v2x * e1y - v2y * e1x
        A1x = a00 * e1x + a01 * e1y + a02 * e1z
        A1y = a01 * e1x + a11 * e1y + a12 * e1z
        A1z = a02 * e1x + a12 * e1y + a22 * e1z
        A2x = a00 * e2x + a01 * e2y + a02 * e2z
        A2y = a01 * e2x + a11 * e2y + a12 * e2z
        A2z = a02 * e2x + a12 * e2y + a22 * e2z
        m00 = e1x * A1x + e1y * A1y + e1z * A1z
        m01 = e2x * A1x + e2y * A1y + e2z * A1z
        m11 = e2x * A2x + e2y * A2y + e2z * A2z
        theta = 0.5 * math.atan2(2.0 * m01, m00 - m11)
        ct, st = math.cos(theta), math.sin(theta)
        v0x, v0y, v0z = ct * e1x + st * e2x, ct * e1y + st * e2y, ct * e1z + st * e2z
        v1x, v1y, v1z = v2y * v0z - v2z * v0y, v2z * v0x - v2x * v0z, v2x * v0y - v2y * v0x
        half = 0.5 * (m00 + m11)
        rad = math.hypot(0.5 * (m00 - m11), m01)
        Avx = a00 * v2x + a01 * v2y + a02 * v2z
        Avy = a01 * v2x + a11 * v2y + a12 * v2z
        Avz = a02 * v2x + a12 * v2y + a22 * v2z
        w[i, 0], w[i, 1], w[i, 2] = half + rad, half - rad, v2x * Avx + v2y * Avy + v2z * Avz
        V[i, 0, 0], V[i, 1, 0], V[i, 2, 0] = v0x, v0y, v0z
        V[i, 0, 1], V[i, 1, 1], V[i, 2, 1] = v1x, v1y, v1z
        V[i, 0, 2], V[i, 1, 2], V[i, 2, 2] = v2x, v2y, v2z
        finite = True
        for a in range(3):
            finite &= math.isfinite(w[i, a])
            for b in range(3):
                finite &= math.isfinite(V[i, a, b])
        unsure[i] = not (finite and w[i, 1] - w[i, 2] > min_rel_gap * abs(w[i, 0]))
    return w, V, unsure


@njit(cache=True, nogil=True, inline="always")
def _mean_and_scatter(points: np.ndarray, rows: np.ndarray) -> tuple:
    """(mean x, y, z, then the scatter's xx, xy, xz, yy, yz, zz) of the (k,) ``rows`` of (N, 3) ``points``."""
    k = rows.shape[0]
    mx = my = mz = 0.0
    for j in range(k):
        r = rows[j]
        mx += points[r, 0]
        my += points[r, 1]
        mz += points[r, 2]
    mx, my, mz = mx / k, my / k, mz / k
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for j in range(k):
        r = rows[j]
        dx, dy, dz = points[r, 0] - mx, points[r, 1] - my, points[r, 2] - mz
        sxx += dx * dx
        sxy += dx * dy
        sxz += dx * dz
        syy += dy * dy
        syz += dy * dz
        szz += dz * dz
    return mx, my, mz, sxx, sxy, sxz, syy, syz, szz


@njit(cache=True, nogil=True, inline="always")
def _store_mean_and_scatter(mean: np.ndarray, S: np.ndarray, i: int, t: tuple) -> None:
    mx, my, mz, sxx, sxy, sxz, syy, syz, szz = t
    mean[i, 0], mean[i, 1], mean[i, 2] = mx, my, mz
    S[i, 0, 0], S[i, 0, 1], S[i, 0, 2] = sxx, sxy, sxz
    S[i, 1, 0], S[i, 1, 1], S[i, 1, 2] = sxy, syy, syz
    S[i, 2, 0], S[i, 2, 1], S[i, 2, 2] = sxz, syz, szz


@njit(cache=True, nogil=True, error_model="numpy")
def neighbourhood_scatter(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M, 3) mean, (M, 3, 3) scatter ``D^T D``) of (M, k, 3) neighbourhoods, D = P - mean (m, m^2)."""
    m, k = P.shape[0], P.shape[1]
    mean = np.empty((m, 3))
    S = np.empty((m, 3, 3))
    every = np.arange(k)
    for i in range(m):
        _store_mean_and_scatter(mean, S, i, _mean_and_scatter(P[i], every))
    return mean, S


@njit(cache=True, nogil=True, inline="always")
def _screw_terms(xi: np.ndarray) -> tuple:
    """The per-twist constants of ``screw_motion``: (rho, |omega|, k = omega / |omega|, k x rho, k x (k x rho))."""
    rx, ry, rz = xi[0], xi[1], xi[2]
    theta = math.sqrt(xi[3] * xi[3] + xi[4] * xi[4] + xi[5] * xi[5])
    if theta < 1e-12:
        return rx, ry, rz, theta, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    kx, ky, kz = xi[3] / theta, xi[4] / theta, xi[5] / theta
    ux, uy, uz = ky * rz - kz * ry, kz * rx - kx * rz, kx * ry - ky * rx
    vx, vy, vz = ky * uz - kz * uy, kz * ux - kx * uz, kx * uy - ky * ux
    return rx, ry, rz, theta, kx, ky, kz, ux, uy, uz, vx, vy, vz


@njit(cache=True, nogil=True, inline="always")
def _screw_scalars(theta: float, si: float) -> tuple[float, float, float, float]:
    """(cos phi, sin phi, a, b) of ``exp(si xi)`` for a twist turning by theta: phi = si theta, and the
    left Jacobian's factors a = si (1 - cos phi) / phi, b = si (phi - sin phi) / phi (their series
    below |phi| = 1e-6). They depend on theta and si only: the same for xi and -xi."""
    phi = si * theta
    c, sn = math.cos(phi), math.sin(phi)
    if abs(phi) < 1e-6:
        return c, sn, si * phi / 2.0, si * phi * phi / 6.0
    return c, sn, si * (1.0 - c) / phi, si * (phi - sn) / phi


@njit(cache=True, nogil=True, inline="always")
def _screw_one(t: tuple, si: float, scalars: tuple, x: float, y: float, z: float, nx: float, ny: float, nz: float
               ) -> tuple[float, float, float, float, float, float]:
    """``exp(si xi)`` of one point (x, y, z) and its rotation of one normal (nx, ny, nz), xi's terms ``t``,
    the point's ``_screw_scalars``."""
    rx, ry, rz, theta, kx, ky, kz, ux, uy, uz, vx, vy, vz = t
    if theta < 1e-12:
        return x + si * rx, y + si * ry, z + si * rz, nx, ny, nz
    c, sn, a, b = scalars
    w = (kx * x + ky * y + kz * z) * (1.0 - c)
    px = c * x + sn * (ky * z - kz * y) + w * kx + (si * rx + a * ux + b * vx)
    py = c * y + sn * (kz * x - kx * z) + w * ky + (si * ry + a * uy + b * vy)
    pz = c * z + sn * (kx * y - ky * x) + w * kz + (si * rz + a * uz + b * vz)
    w = (kx * nx + ky * ny + kz * nz) * (1.0 - c)
    return (px, py, pz, c * nx + sn * (ky * nz - kz * ny) + w * kx, c * ny + sn * (kz * nx - kx * nz) + w * ky,
            c * nz + sn * (kx * ny - ky * nx) + w * kz)


@njit(cache=True, nogil=True, error_model="numpy")
def screw_motion(xi: np.ndarray, s: np.ndarray, points: np.ndarray, normals: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``exp(s_i xi)`` applied to each point p_i (N, 3), and its rotation alone to each normal (N, 3) or (0, 3).

    xi: (6,) twist (rho m, omega rad) of ``simlidar.se3``; s: (N,) fractions of it. Exact (not a
    small-angle approximation): with k = omega / |omega| and phi = s |omega|, Rodrigues' formula
    ``R p = cos phi p + sin phi (k x p) + (1 - cos phi)(k . p) k`` and the SE(3) left Jacobian's
    translation ``s rho + s (1 - cos phi) / phi (k x rho) + s (phi - sin phi) / phi k x (k x rho)``
    (its series below |phi| = 1e-6). ``odometry.deskew.screw_apply`` is the caller.
    """
    none = np.zeros((0, 4))  # (no per-point scalars given or wanted)
    return rescrew_motion(np.zeros(6), xi, s, points, normals, none, none)


@njit(cache=True, nogil=True, error_model="numpy")
def rescrew_motion(xi_old: np.ndarray, xi_new: np.ndarray, s: np.ndarray, points: np.ndarray, normals: np.ndarray,
                   old_scalars: np.ndarray, new_scalars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``screw_motion(xi_new, s, *screw_motion(-xi_old, s, points, normals))`` in one pass: points (and
    normals) de-skewed with the twist ``xi_old`` as ``xi_new`` would have de-skewed them
    (``odometry.deskew.redeskew``). A zero ``xi_old`` moves nothing: ``screw_motion``.

    old_scalars: (N, 4) each point's ``_screw_scalars`` of ``xi_old`` (the previous call's
    ``new_scalars`` when that call's ``xi_new`` was this ``xi_old``, with the same s: the undo then
    takes no trigonometry), or (0, 4): computed here. new_scalars: (N, 4) filled with those of
    ``xi_new``, or (0, 4).
    """
    undo = _screw_terms(-xi_old)
    redo = _screw_terms(xi_new)
    skip_undo = xi_old[0] == 0.0 and xi_old[1] == 0.0 and xi_old[2] == 0.0 and undo[3] < 1e-12
    with_normals = normals.shape[0] > 0
    given, wanted = old_scalars.shape[0] > 0, new_scalars.shape[0] > 0
    out_p = np.empty_like(points)
    out_n = np.empty_like(normals)
    for i in range(points.shape[0]):
        si = s[i]
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        nx = ny = nz = 0.0
        if with_normals:
            nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if not skip_undo:
            if given:
                scalars = (old_scalars[i, 0], old_scalars[i, 1], old_scalars[i, 2], old_scalars[i, 3])
            else:
                scalars = _screw_scalars(undo[3], si)
            x, y, z, nx, ny, nz = _screw_one(undo, si, scalars, x, y, z, nx, ny, nz)
        scalars = _screw_scalars(redo[3], si)
        if wanted:
            new_scalars[i, 0], new_scalars[i, 1], new_scalars[i, 2], new_scalars[i, 3] = scalars
        x, y, z, nx, ny, nz = _screw_one(redo, si, scalars, x, y, z, nx, ny, nz)
        out_p[i, 0], out_p[i, 1], out_p[i, 2] = x, y, z
        if with_normals:
            out_n[i, 0], out_n[i, 1], out_n[i, 2] = nx, ny, nz
    return out_p, out_n


@njit(cache=True, nogil=True, error_model="numpy")
def reusable_matches(points: np.ndarray, searched_at: np.ndarray, nearest: np.ndarray, clear_m: np.ndarray,
                     target_points: np.ndarray, bound_m: float, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Which nearest neighbours found earlier still hold: ((M,) their distances, inf elsewhere; rows to search).

    points: (M, 3) the query points now; searched_at: (M, 3) where each was last searched from;
    nearest: (M,) the nearest target row found there (``len(target_points)``: none within the bound);
    clear_m: (M,) no other target point was within this of ``searched_at``. A point moved by s from
    where its nearest lay at d keeps it while ``d + s + margin < clear`` and ``d + margin < bound``
    (``odometry.icp.match``); d is computed as ``sqrt((dx^2 + dy^2) + dz^2)``, as the k-d tree does.
    """
    m = points.shape[0]
    n = target_points.shape[0]
    dist = np.full(m, np.inf)
    redo = np.empty(m, dtype=np.int64)
    count = 0
    for i in range(m):
        j = nearest[i]
        if j < n:
            sx, sy, sz = points[i, 0] - searched_at[i, 0], points[i, 1] - searched_at[i, 1], \
                points[i, 2] - searched_at[i, 2]
            shift = math.sqrt(sx * sx + sy * sy + sz * sz)
            dx, dy, dz = points[i, 0] - target_points[j, 0], points[i, 1] - target_points[j, 1], \
                points[i, 2] - target_points[j, 2]
            d = math.sqrt((dx * dx + dy * dy) + dz * dz)
            if d + shift + margin_m < clear_m[i] and d + margin_m < bound_m:
                dist[i] = d
                continue
        redo[count] = i
        count += 1
    return dist, redo[:count]


@njit(cache=True, nogil=True, error_model="numpy")
def packed_voxel_keys(points: np.ndarray, voxel_size_m: float, key_bits: int) -> tuple[np.ndarray, bool]:
    """((N,) int64 keys of the cubic voxels holding (N, 3) points, all inside the grid).

    A key packs the three indices ``floor(p / voxel_size_m) + 2^(key_bits - 1)``, ``key_bits``
    bits each, x highest (``odometry.voxels.voxel_keys`` is the caller and raises when one
    falls outside: the second value is False, or a coordinate is not finite).
    """
    offset = 1 << (key_bits - 1)
    mask = (1 << key_bits) - 1
    keys = np.empty(points.shape[0], dtype=np.int64)
    inside = True
    for r in range(points.shape[0]):
        key = np.int64(0)
        for c in range(3):
            x = points[r, c] / voxel_size_m
            # (checked on the float, before it becomes an integer: also false for nan)
            if not (x >= -offset and x < mask + 1 - offset):
                inside = False
                x = 0.0
            key = (key << key_bits) | (np.int64(math.floor(x)) + offset)
        keys[r] = key
    return keys, inside


@njit(cache=True, nogil=True, error_model="numpy")
def voxel_sums(slot: np.ndarray, k: int, points: np.ndarray, values: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per voxel: (k, 3) sum of the points in it, (k,) of their values, (k,) counts.

    slot: (N,) int voxel (0 .. k - 1) of each (N, 3) point; values: (N,) or (0,).
    Sums run in row order (as ``numpy.bincount`` adds).
    """
    sums = np.zeros((k, 3))
    value_sums = np.zeros(k)
    counts = np.zeros(k, dtype=np.int64)
    with_values = values.shape[0] > 0
    for r in range(slot.shape[0]):
        v = slot[r]
        sums[v, 0] += points[r, 0]
        sums[v, 1] += points[r, 1]
        sums[v, 2] += points[r, 2]
        counts[v] += 1
        if with_values:
            value_sums[v] += values[r]
    return sums, value_sums, counts


@njit(cache=True, nogil=True, inline="always")
def _table_shift(entries: int) -> tuple[int, np.uint64]:
    """(size, shift) of an open-addressing hash table for ``entries`` keys: a power of two at least
    twice as many slots (short probe runs), and the shift that maps a 64-bit hash onto them."""
    size = 2
    while size < 2 * entries:
        size *= 2
    return size, np.uint64(64 - max(int(np.log2(size)), 1))


@njit(cache=True, nogil=True, inline="always")
def _probe(table_key: np.ndarray, table_id: np.ndarray, key: np.int64, shift: np.uint64) -> int:
    """The slot of ``key`` in an open-addressing table (Fibonacci hashing, linear probing), or the
    free slot (``table_id < 0``) where it goes."""
    mask = table_key.shape[0] - 1
    h = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> shift)
    while table_id[h] >= 0 and table_key[h] != key:
        h = (h + 1) & mask
    return h


@njit(cache=True, nogil=True, inline="always")
def _key_table(keys: np.ndarray, count: int, entries: int) -> tuple[np.ndarray, np.ndarray, np.uint64]:
    """(keys, ids, shift) of an open-addressing table with room for ``entries`` keys, holding the first
    ``count`` of the distinct int64 ``keys``, each with its position among them (``_probe`` finds them)."""
    size, shift = _table_shift(entries)
    table_key = np.empty(size, dtype=np.int64)
    table_id = np.full(size, -1, dtype=np.int64)
    for i in range(count):
        h = _probe(table_key, table_id, keys[i], shift)
        table_key[h] = keys[i]
        table_id[h] = i
    return table_key, table_id, shift


@njit(cache=True, nogil=True)
def _insert_keys(keys: np.ndarray, start: int, entries: int, table_key: np.ndarray, table_id: np.ndarray,
                 shift: np.uint64, first: np.ndarray, provisional: np.ndarray, k: int) -> tuple[int, int]:
    """``group_keys``' pass from row ``start`` until the table holds ``entries`` keys: (the row where it
    stopped (N: done), the distinct keys found)."""
    for r in range(start, keys.shape[0]):
        key = keys[r]
        h = _probe(table_key, table_id, key, shift)
        if table_id[h] < 0:
            if k == entries:
                return r, k
            table_key[h] = key
            table_id[h] = k
            first[k] = key
            k += 1
        provisional[r] = table_id[h]
    return keys.shape[0], k


@njit(cache=True, nogil=True)
def group_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((K,) the distinct keys ascending, (N,) the slot of each key among them):
    ``numpy.unique(keys, return_inverse=True)`` for (N,) int64 keys.

    The keys are grouped by a hash table in one pass and only the K distinct ones are sorted
    (a scan has several points per voxel: sorting the N keys took most of a voxel grid's time).
    """
    n = keys.shape[0]
    first = np.empty(n, dtype=np.int64)  # the distinct keys, in order of first appearance
    provisional = np.empty(n, dtype=np.int64)
    # The table starts small and doubles when half full: sized by the distinct keys, not by N, it
    # stays in the cache and its memory is reused (a table of N slots, megabytes, came fresh from
    # the system every scan: a page fault per 4 kB).
    entries = min(n, 2048)
    r = k = 0
    while r < n:
        table_key, table_id, shift = _key_table(first, k, entries)
        r, k = _insert_keys(keys, r, entries, table_key, table_id, shift, first, provisional, k)
        entries *= 2
    order = np.argsort(first[:k])
    rank = np.empty(k, dtype=np.int64)
    for i in range(k):
        rank[order[i]] = i
    slot = np.empty(n, dtype=np.int64)
    for r in range(n):
        slot[r] = rank[provisional[r]]
    return first[:k][order], slot


@njit(cache=True, nogil=True)
def keys_near(keys: np.ndarray, around: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(M,) bool: which of (M,) int64 voxel keys lie within ``steps`` of one of the (K,) keys ``around``:
    ``numpy.isin(keys, numpy.unique(around[:, None] + steps))`` (steps: (S,) key differences, e.g. a
    voxel's 27 neighbours, ``odometry.voxels.neighbour_key_steps``), by a hash set of the K x S keys."""
    size, shift = _table_shift(around.shape[0] * steps.shape[0])
    table_key = np.empty(size, dtype=np.int64)
    table_id = np.full(size, -1, dtype=np.int64)
    for a in range(around.shape[0]):
        for s in range(steps.shape[0]):
            key = around[a] + steps[s]
            h = _probe(table_key, table_id, key, shift)
            table_key[h] = key
            table_id[h] = 0
    near = np.empty(keys.shape[0], dtype=np.bool_)
    for r in range(keys.shape[0]):
        near[r] = table_id[_probe(table_key, table_id, keys[r], shift)] >= 0
    return near


@njit(cache=True, nogil=True, error_model="numpy")
def within_reach_of_any(points: np.ndarray, keys: np.ndarray, reach_m: np.ndarray, others: np.ndarray,
                        other_keys: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(M,) bool: one of the (K, 3) ``others`` lies within ``reach_m`` (M,) of each (M, 3) point, m.

    Only the others in the voxels ``keys + steps`` are looked at (keys: (M,) and other_keys: (K,) the
    int64 voxel keys of both; steps: (S,) key differences): with a voxel and its 26 neighbours, the
    answer is exact for reaches up to the voxel's edge, ``k-d tree distance to the nearest other <= reach``
    (distances as ``sqrt((dx^2 + dy^2) + dz^2)``, as the k-d tree computes them).
    """
    distinct, slot = group_keys(other_keys)
    g = distinct.shape[0]
    start = np.zeros(g + 1, dtype=np.int64)  # the others of voxel v: order[start[v]:start[v + 1]]
    for c in range(slot.shape[0]):
        start[slot[c] + 1] += 1
    for v in range(g):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(slot.shape[0], dtype=np.int64)
    for c in range(slot.shape[0]):
        order[fill[slot[c]]] = c
        fill[slot[c]] += 1
    table_key, table_id, shift = _key_table(distinct, g, g)
    found = np.zeros(points.shape[0], dtype=np.bool_)
    for i in range(points.shape[0]):
        x, y, z, r = points[i, 0], points[i, 1], points[i, 2], reach_m[i]
        for s in range(steps.shape[0]):
            v = table_id[_probe(table_key, table_id, keys[i] + steps[s], shift)]
            if v < 0:
                continue
            for j in range(start[v], start[v + 1]):
                c = order[j]
                dx, dy, dz = x - others[c, 0], y - others[c, 1], z - others[c, 2]
                if math.sqrt((dx * dx + dy * dy) + dz * dz) <= r:
                    found[i] = True
                    break
            if found[i]:
                break
    return found


@njit(cache=True, nogil=True, inline="always")
def _in_axes(V: np.ndarray, i: int, x: float, y: float, z: float) -> tuple[float, float, float]:
    """The vector (x, y, z) in the axes of ``V[i]`` (its columns): ``V[i]^T (x, y, z)``."""
    return (x * V[i, 0, 0] + y * V[i, 1, 0] + z * V[i, 2, 0],
            x * V[i, 0, 1] + y * V[i, 1, 1] + z * V[i, 2, 1],
            x * V[i, 0, 2] + y * V[i, 1, 2] + z * V[i, 2, 2])


@njit(cache=True, nogil=True, inline="always")
def _beam_moments(points: np.ndarray, beams: np.ndarray, rows: np.ndarray, mean: np.ndarray, V: np.ndarray,
                  i: int) -> tuple[float, float, float, float, float, float]:
    """``beam_noise_moments``' sums for neighbourhood i, its neighbours the ``rows`` of ``points`` and ``beams``:
    (sum z_0^2, sum z_0 z_1, sum z_1^2, sum c_0^2, sum c_1^2, sum c_2^2)."""
    s00 = s01 = s11 = q0 = q1 = q2 = 0.0
    for j in range(rows.shape[0]):
        r = rows[j]
        dx, dy, dz = points[r, 0] - mean[i, 0], points[r, 1] - mean[i, 1], points[r, 2] - mean[i, 2]
        a0, a1, h = _in_axes(V, i, dx, dy, dz)
        c0, c1, c2 = _in_axes(V, i, beams[r, 0], beams[r, 1], beams[r, 2])
        z0, z1 = h * c0 + a0 * c2, h * c1 + a1 * c2
        s00 += z0 * z0
        s01 += z0 * z1
        s11 += z1 * z1
        q0 += c0 * c0
        q1 += c1 * c1
        q2 += c2 * c2
    return s00, s01, s11, q0, q1, q2


@njit(cache=True, nogil=True, error_model="numpy")
def beam_noise_moments(P: np.ndarray, mean: np.ndarray, V: np.ndarray, beams: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The sums over each neighbourhood that range noise along given beams puts into its normal.

    P, beams: (M, k, 3) neighbour points (m) and the unit beams that measured them; mean (M, 3),
    V (M, 3, 3): their PCA (columns v_0, v_1, v_2). With a_j = V^T (p_j - mean), h_j = a_j2,
    c_j = V^T b_j and z_jl = h_j c_jl + a_jl c_j2 (l = 0, 1), returns (M, 2, 2) ``sum_j z_jl z_jm``
    and (M, 3) ``sum_j c_jl^2`` (``odometry.ncf.normal_covariance_along_beams`` scales them).
    """
    m, k = P.shape[0], P.shape[1]
    zz = np.empty((m, 2, 2))
    cc = np.empty((m, 3))
    every = np.arange(k)
    for i in range(m):
        s00, s01, s11, q0, q1, q2 = _beam_moments(P[i], beams[i], every, mean, V, i)
        zz[i, 0, 0], zz[i, 0, 1], zz[i, 1, 0], zz[i, 1, 1] = s00, s01, s01, s11
        cc[i, 0], cc[i, 1], cc[i, 2] = q0, q1, q2
    return zz, cc


@njit(cache=True, nogil=True, error_model="numpy")
def range_noise_moments(P: np.ndarray, mean: np.ndarray, V: np.ndarray, range_var_m2: float,
                        angular_var_rad2: float) -> tuple[np.ndarray, np.ndarray]:
    """The sums over each neighbourhood that range (and angular) noise puts into its normal.

    P: (M, k, 3) neighbour points about the beams' origin (the sensor), m; mean (M, 3), V (M, 3, 3):
    their PCA. With PV_j = V^T p_j, a_j = V^T (p_j - mean), h_j = a_j2, r_j^2 = |p_j|^2,
    beta_j / r_j^2 = (sigma_r^2 - sigma_a^2 r_j^2) / r_j^2, alpha_j = sigma_a^2 r_j^2 and
    y_jl = a_jl PV_j2 + h_j PV_jl: returns (M, 2, 2) ``sum_j (beta_j / r_j^2) y_jl y_jm
    + alpha_j (a_jl a_jm + h_j^2 delta_lm)`` and (M, 3) ``sum_j (beta_j / r_j^2) PV_jl^2 + alpha_j``
    (``odometry.ncf.normal_covariance``'s ``RangeNoise`` terms, before its (k - 1) / k).
    """
    m, k = P.shape[0], P.shape[1]
    num = np.empty((m, 2, 2))
    diag = np.empty((m, 3))
    for i in range(m):
        s00 = s01 = s11 = d0 = d1 = d2 = 0.0
        for j in range(k):
            px, py, pz = P[i, j, 0], P[i, j, 1], P[i, j, 2]
            dx, dy, dz = px - mean[i, 0], py - mean[i, 1], pz - mean[i, 2]
            pv0, pv1, pv2 = _in_axes(V, i, px, py, pz)
            a0, a1, h = _in_axes(V, i, dx, dy, dz)
            r2 = px * px + py * py + pz * pz
            beta_r2 = (range_var_m2 - angular_var_rad2 * r2) / r2
            y0, y1 = a0 * pv2 + h * pv0, a1 * pv2 + h * pv1
            s00 += beta_r2 * y0 * y0
            s01 += beta_r2 * y0 * y1
            s11 += beta_r2 * y1 * y1
            d0 += beta_r2 * pv0 * pv0
            d1 += beta_r2 * pv1 * pv1
            d2 += beta_r2 * pv2 * pv2
            if angular_var_rad2 > 0:
                alpha = angular_var_rad2 * r2
                s00 += alpha * (a0 * a0 + h * h)
                s01 += alpha * a0 * a1
                s11 += alpha * (a1 * a1 + h * h)
                d0 += alpha
                d1 += alpha
                d2 += alpha
        num[i, 0, 0], num[i, 0, 1], num[i, 1, 0], num[i, 1, 1] = s00, s01, s01, s11
        diag[i, 0], diag[i, 1], diag[i, 2] = d0, d1, d2
    return num, diag


@njit(cache=True, nogil=True, error_model="numpy")
def tangent_covariance_in_frame(V: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A normal's (M, 2, 2) covariance C in its tangent plane (axes v_0, v_1 of V (M, 3, 3)), in the frame.

    Returns (M, 3, 3) ``V_t C V_t^T`` (V_t = [v_0, v_1]), its (M, 3) eigenvalues ascending (0, minor,
    major; the minor clamped at 0) and (M, 3, 3) eigenvectors as columns (v_2, minor axis, major axis),
    from the 2 x 2 problem in closed form (``odometry.ncf``'s ``NormalCovariance``).
    """
    m = V.shape[0]
    cov = np.empty((m, 3, 3))
    eig = np.empty((m, 3))
    Q = np.empty((m, 3, 3))
    for i in range(m):
        c00, c01, c11 = C[i, 0, 0], C[i, 0, 1], C[i, 1, 1]
        c10 = C[i, 1, 0]
        for a in range(3):
            va0, va1 = V[i, a, 0], V[i, a, 1]
            for b in range(3):
                vb0, vb1 = V[i, b, 0], V[i, b, 1]
                cov[i, a, b] = (va0 * c00 + va1 * c10) * vb0 + (va0 * c01 + va1 * c11) * vb1
        half_tr = 0.5 * (c00 + c11)
        rad = math.hypot(0.5 * (c00 - c11), c01)
        ang = 0.5 * math.atan2(2.0 * c01, c00 - c11)  # the major axis in the (v_0, v_1) plane
        ca, sa = math.cos(ang), math.sin(ang)
        for a in range(3):
            Q[i, a, 0] = V[i, a, 2]
            Q[i, a, 1] = -sa * V[i, a, 0] + ca * V[i, a, 1]
            Q[i, a, 2] = ca * V[i, a, 0] + sa * V[i, a, 1]
        minor = half_tr - rad
        eig[i, 0], eig[i, 1], eig[i, 2] = 0.0, 0.0 if minor < 0 else minor, half_tr + rad  # (nan stays nan)
    return cov, eig, Q


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


@njit(cache=True, nogil=True, error_model="numpy")
def neighbour_beam_distance_table(points: np.ndarray, normals: np.ndarray, pitch_below: np.ndarray,
                                  pitch_above: np.ndarray, azimuth_step_rad: float, offsets: np.ndarray,
                                  printed: bool) -> np.ndarray:
    """(M, 4) the GCR's neighbour beam distances d_kl of (M, 3) points with (M, 3) unit normals, m.

    pitch_below, pitch_above: (M,) the ring pitch to the ring below / above each point, rad (nan: none);
    offsets: (4, 2) int (vertical side, azimuth side) of each column. With r = |p|, rho = |p_xy|, the
    beam p^ = p / r, u = (-y, x, 0) / rho, v = p^ x u, L_h = rho phi, L_v = r pitch, |p_kl|^2 =
    L_h^2 + L_v^2 and p_kl . n = s_h L_h (u . n) + s_v L_v (v . n): ``printed`` False (the beam form)
    gives sqrt(|p_kl|^2 + (p_kl . n)^2 / (p^ . n)^2), True the paper's printed
    |p_kl|^2 / sqrt(|p_kl|^2 - (p_kl . n)^2); inf where the denominator is not positive, nan where
    the ring has no neighbour on that side (``odometry.gcr.neighbour_beam_distances`` is the caller).
    """
    m = points.shape[0]
    out = np.empty((m, 4))
    for i in range(m):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        r = math.sqrt(x * x + y * y + z * z)
        rho = math.hypot(x, y)
        bx, by, bz = x / r, y / r, z / r
        ux, uy = -y / rho, x / rho
        vx, vy, vz = -bz * uy, bz * ux, bx * uy - by * ux  # p^ x u, u having no z
        n_b = bx * nx + by * ny + bz * nz
        n_u = ux * nx + uy * ny
        n_v = vx * nx + vy * ny + vz * nz
        L_h = rho * azimuth_step_rad
        for col in range(4):
            s_v, s_h = offsets[col, 0], offsets[col, 1]
            L_v = r * (pitch_below[i] if s_v < 0 else pitch_above[i])
            len2 = L_h * L_h + L_v * L_v
            pn = s_h * L_h * n_u + s_v * L_v * n_v
            if printed:
                den2 = len2 - pn * pn
                d = len2 / math.sqrt(den2) if den2 > 0 else np.inf
            else:
                den = n_b * n_b
                d = math.sqrt(len2 + pn * pn / den) if den > 0 else np.inf
            out[i, col] = np.nan if math.isnan(L_v) else d
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def row_max_with_floor(table: np.ndarray, floor: float) -> np.ndarray:
    """(M,) ``numpy.nanmax(table, axis=1)`` of an (M, C) table, raised to at least ``floor`` (nan where a
    row has no number: stays nan). ``odometry.gcr.gcr_threshold_m``'s max over the neighbour beams."""
    out = np.empty(table.shape[0])
    for i in range(table.shape[0]):
        best = np.nan
        for c in range(table.shape[1]):
            v = table[i, c]
            if not math.isnan(v) and (math.isnan(best) or v > best):
                best = v
        out[i] = floor if best < floor else best  # (a nan compares false: it stays nan)
    return out


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


@njit(cache=True, nogil=True, error_model="numpy")
def gathered_scatter(points: np.ndarray, neighbours: np.ndarray, at: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``neighbourhood_scatter(points[neighbours])`` without gathering the (M, k, 3) neighbourhoods,
    and the (M,) distance from each of ``at`` (M, 3) to its last neighbour (the farthest), m.

    points: (N, 3) m; neighbours: (M, k) rows of ``points``, nearest first. Returns ((M, 3) mean,
    (M, 3, 3) scatter, (M,) ``norm(points[neighbours[:, -1]] - at, axis=1)``).
    """
    m, k = neighbours.shape[0], neighbours.shape[1]
    mean = np.empty((m, 3))
    S = np.empty((m, 3, 3))
    reach = np.empty(m)
    for i in range(m):
        _store_mean_and_scatter(mean, S, i, _mean_and_scatter(points, neighbours[i]))
        far = neighbours[i, k - 1]
        dx, dy, dz = points[far, 0] - at[i, 0], points[far, 1] - at[i, 1], points[far, 2] - at[i, 2]
        reach[i] = math.sqrt(dx * dx + dy * dy + dz * dz)
    return mean, S, reach


@njit(cache=True, nogil=True, error_model="numpy")
def map_normal_verdicts(points: np.ndarray, beams: np.ndarray, elevations: np.ndarray, origins: np.ndarray,
                        neighbours: np.ndarray, at: np.ndarray, mean: np.ndarray, lam: np.ndarray, V: np.ndarray,
                        min_lam1_m2: float, max_curvature: float, min_elevation_spread_rad: float,
                        min_baseline_m: float, range_var_m2: float, degenerate_gap: float,
                        gap_margin_per_m2: float) -> tuple[np.ndarray, np.ndarray]:
    """A map's target normals from their neighbourhoods' PCA, and the NCF's variance of each, in one pass.

    points, beams (N, 3): the map's points (m) and the unit beams that measured them; elevations (N,)
    those beams' elevations, rad; origins (N, 3) where from, m; neighbours (M, k) rows, nearest
    first; at (M, 3) the points the normals belong to; mean (M, 3), lam (M, 3) descending scatter
    eigenvalues (m^2), V (M, 3, 3) axes as columns (``symmetric_eigh_descending`` of the scatter;
    oriented here in place: V[:, :, 1:] flipped so that the normal faces the origin).
    Returns (M, 3) normals, nan where ``odometry.local_map.plane_normals_valid`` (with
    ``min_lam1_m2`` = (sigmas x noise)^2, ``max_curvature``) or ``spans_two_scan_lines`` says no
    plane, and (M,) the largest eigenvalue of the normal's covariance
    (``odometry.ncf.normal_covariance_along_beams(...).max_variance_rad2``, noise-free gaps: its
    ``range_var_m2``, ``degenerate_gap`` = ``ncf.DEGENERATE_GAP`` and ``gap_margin_per_m2`` =
    z sqrt(2 / (k - 1))), inf where the normal is undefined.
    """
    m, k = neighbours.shape[0], neighbours.shape[1]
    normals = np.empty((m, 3))
    variance = np.empty(m)
    noise_scale = (k - 1) / k * range_var_m2
    for i in range(m):
        # orientation (``local_pca``: towards the origin)
        if V[i, 0, 2] * at[i, 0] + V[i, 1, 2] * at[i, 1] + V[i, 2, 2] * at[i, 2] > 0:
            for a in range(3):
                V[i, a, 1] = -V[i, a, 1]
                V[i, a, 2] = -V[i, a, 2]
        l0, l1, l2 = lam[i, 0], lam[i, 1], lam[i, 2]
        # a plane: wide along its second axis, flat (PCL curvature), finite
        total = max(l0, 0.0) + max(l1, 0.0) + max(l2, 0.0)
        curvature = max(l2, 0.0) / total if total > 0 else np.nan
        ok = l1 / k > min_lam1_m2 and curvature <= max_curvature
        for a in range(3):
            ok = ok and math.isfinite(V[i, a, 2])
        # two scan lines: two rings, or one ring seen from two places
        lo = hi = elevations[neighbours[i, 0]]
        for j in range(1, k):
            e = elevations[neighbours[i, j]]
            lo, hi = min(lo, e), max(hi, e)
        if ok and not hi - lo > min_elevation_spread_rad:
            spread2 = 0.0
            for a in range(3):
                lo = hi = origins[neighbours[i, 0], a]
                for j in range(1, k):
                    o = origins[neighbours[i, j], a]
                    lo, hi = min(lo, o), max(hi, o)
                spread2 += (hi - lo) * (hi - lo)
            ok = math.sqrt(spread2) > min_baseline_m
        for a in range(3):
            normals[i, a] = V[i, a, 2] if ok else np.nan
        # the NCF (``beam_noise_moments``, the debiased gaps, the 2 x 2 covariance's major eigenvalue)
        s00, s01, s11, q0, q1, q2 = _beam_moments(points, beams, neighbours[i], mean, V, i)
        tol = degenerate_gap * l0
        g0, g1 = l0 - l2, l1 - l2
        bad = not (g1 > tol) or not (g0 > tol) or not math.isfinite(l0)
        n0, n1, n2 = noise_scale * q0, noise_scale * q1, noise_scale * q2
        g0, g1 = g0 - (n0 - n2), g1 - (n1 - n2)
        bad = bad or not (g1 > gap_margin_per_m2 * n1) or not (g1 > tol) or not (g0 > tol)
        c00 = range_var_m2 * s00 / (g0 * g0)
        c01 = range_var_m2 * s01 / (g0 * g1)
        c11 = range_var_m2 * s11 / (g1 * g1)
        major = 0.5 * (c00 + c11) + math.hypot(0.5 * (c00 - c11), c01)
        variance[i] = np.inf if bad else major
    return normals, variance
