"""Transformation estimation: uniformly weighted, linearised point-to-plane least squares.

For a source point p (already moved by the current estimate) matched to a
target point q with unit normal n, the residual ``r = n . (p - q)`` changes
under a small motion ``(rho, omega)`` (translation, rotation vector) as
``r + n . rho + (p x n) . omega``. Stacking ``J_i = [n_i^T, (p_i x n_i)^T]``
gives the 6 x 6 normal equations ``H x = -J^T r`` with ``H = J^T J``; the
increment is ``exp(x)`` (``simlidar.se3`` ordering), applied on the left.
Directions the matches constrain too weakly can be left at the prior
(``odometry.constraints.remapped_step``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simlidar import se3

from .constraints import remapped_step
from .kernels.plane_system import plane_normal_equations


@dataclass
class PlaneStep:
    """One Gauss-Newton step.

    increment: (4, 4) transform to apply on the left of the current estimate.
    xi: (6,) its twist (rho m, omega rad).
    H: (6, 6) information matrix J^T J of this step's matches.
    rank: numerical rank of H (6 unless the geometry leaves a motion unconstrained).
    remapped: directions left at the prior because they were weakly constrained.
    rms_m: RMS point-to-plane residual before the step.
    """

    increment: np.ndarray
    xi: np.ndarray
    H: np.ndarray
    rank: int
    rms_m: float
    remapped: int = 0


def point_to_plane_step(source: np.ndarray, target: np.ndarray, target_normals: np.ndarray,
                        rcond: float = 1e-10, min_eigenvalue: float = 0.0,
                        rotation_scale_m: float = 10.0, mode: str = "remap",
                        deviation: np.ndarray | None = None) -> PlaneStep:
    """Solve the linearised point-to-plane problem for (N, 3) matched points and normals.

    A rank-deficient system (fewer than 6 constrained directions) is solved in the
    least-squares minimum-norm sense, leaving unconstrained directions unchanged;
    so are directions whose scaled information per match is below ``min_eigenvalue``
    (``odometry.constraints``; 0 = only the numerically unconstrained ones), or, with
    ``mode="prior"``, held to the prior by a motion prior of that information per match
    (``deviation``: the current estimate's offset from it, (6,) twist).
    """
    H, g, sum_r2 = plane_normal_equations(*(np.ascontiguousarray(a, dtype=np.float64)
                                            for a in (source, target, target_normals)))
    return plane_step(H, g, sum_r2, len(source), rcond, min_eigenvalue, rotation_scale_m, mode, deviation)


def plane_step(H: np.ndarray, g: np.ndarray, sum_r2: float, n: int, rcond: float = 1e-10,
               min_eigenvalue: float = 0.0, rotation_scale_m: float = 10.0, mode: str = "remap",
               deviation: np.ndarray | None = None) -> PlaneStep:
    """``point_to_plane_step`` from its system: H (6, 6) ``J^T J``, g (6,) ``J^T r`` and the sum of r^2
    (m^2) of n matches (``odometry.kernels.plane_system.plane_normal_equations``)."""
    solve = remapped_step(H, g, n, rotation_scale_m, min_eigenvalue, rcond, mode, deviation)
    return PlaneStep(se3.exp(solve.xi), solve.xi, H, solve.rank, float(np.sqrt(sum_r2 / n)) if n else 0.0,
                     solve.remapped)
