"""De-skew: per-point screw motions ``exp(s_i xi)`` of points and normals (``odometry.deskew``; numpy
reference: ``simlidar.se3.exp`` per point).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


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
