"""Normals by PCA of neighbourhoods: 3 x 3 eigen-decompositions and scatter matrices, and the map's
normal verdicts (``odometry.normals``, ``odometry.local_map``; numpy references: ``np.linalg.eigh``,
``np.cov``-style scatter, ``local_map.plane_normals_valid`` / ``spans_two_scan_lines`` and the NCF).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .ncf import beam_moments


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
        s00, s01, s11, q0, q1, q2 = beam_moments(points, beams, neighbours[i], mean, V, i)
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
