"""The normal covariance filter's sums: noise moments along beams or ranges in the PCA frame, and the
tangent covariance (``odometry.ncf``; its numpy formulas are the references).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _in_axes(V: np.ndarray, i: int, x: float, y: float, z: float) -> tuple[float, float, float]:
    """The vector (x, y, z) in the axes of ``V[i]`` (its columns): ``V[i]^T (x, y, z)``."""
    return (x * V[i, 0, 0] + y * V[i, 1, 0] + z * V[i, 2, 0],
            x * V[i, 0, 1] + y * V[i, 1, 1] + z * V[i, 2, 1],
            x * V[i, 0, 2] + y * V[i, 1, 2] + z * V[i, 2, 2])


@njit(cache=True, nogil=True, inline="always")
def beam_moments(points: np.ndarray, beams: np.ndarray, rows: np.ndarray, mean: np.ndarray, V: np.ndarray,
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
        s00, s01, s11, q0, q1, q2 = beam_moments(P[i], beams[i], every, mean, V, i)
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
