"""Transformation estimation: uniformly weighted, linearised point-to-plane least squares.

For a source point p (already moved by the current estimate) matched to a
target point q with unit normal n, the residual ``r = n . (p - q)`` changes
under a small motion ``(rho, omega)`` (translation, rotation vector) as
``r + n . rho + (p x n) . omega``. Stacking ``J_i = [n_i^T, (p_i x n_i)^T]``
gives the 6 x 6 normal equations ``H x = -J^T r`` with ``H = J^T J``; the
increment is ``exp(x)`` (``simlidar.se3`` ordering), applied on the left.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simlidar import se3


@dataclass
class PlaneStep:
    """One Gauss-Newton step.

    increment: (4, 4) transform to apply on the left of the current estimate.
    xi: (6,) its twist (rho m, omega rad).
    H: (6, 6) information matrix J^T J of this step's matches.
    rank: numerical rank of H (6 unless the geometry leaves a motion unconstrained).
    rms_m: RMS point-to-plane residual before the step.
    """

    increment: np.ndarray
    xi: np.ndarray
    H: np.ndarray
    rank: int
    rms_m: float


def point_to_plane_step(source: np.ndarray, target: np.ndarray, target_normals: np.ndarray,
                        rcond: float = 1e-10) -> PlaneStep:
    """Solve the linearised point-to-plane problem for (N, 3) matched points and normals.

    A rank-deficient system (fewer than 6 constrained directions) is solved in the
    least-squares minimum-norm sense, leaving unconstrained directions unchanged.
    """
    r = np.einsum("ij,ij->i", target_normals, source - target)
    J = np.hstack([target_normals, np.cross(source, target_normals)])
    H = J.T @ J
    g = J.T @ r
    w, V = np.linalg.eigh(H)
    good = w > rcond * max(w[-1], 1e-300)
    xi = -(V[:, good] @ ((V[:, good].T @ g) / w[good]))
    return PlaneStep(se3.exp(xi), xi, H, int(good.sum()), float(np.sqrt(np.mean(r**2))) if len(r) else 0.0)
