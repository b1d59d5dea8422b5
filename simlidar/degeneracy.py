"""How well a scan constrains its own pose: the point-to-plane information matrix.

For a point p with unit normal n, the linearised point-to-plane residual
``n . (R p + t - q)`` has Jacobian ``J = [n^T, (p x n)^T]`` with respect to a
small motion ``(t, omega)`` (translation first, rotation second, as in
``simlidar.se3``). The information matrix is ``H = sum_i J_i^T J_i`` (6x6).
A direction in which H is small is a motion the scan cannot see: along a
featureless tunnel, the translation block's smallest eigenvalue is near zero.

Figures are divided by the number of points so that scans of different
density compare: the translational eigenvalues are then dimensionless (mean
squared normal component, at most 1, summing to 1), the rotational ones are
in m^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels.information import information_sums


def plane_jacobian(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(6, N) the point-to-plane Jacobian ``J = [n, p x n]`` of (N, 3) points and unit normals, one row of
    the result per column of J (translation, then rotation), m."""
    p, n = np.asarray(points, dtype=np.float64), np.asarray(normals, dtype=np.float64)
    # (as contiguous rows: np.cross and np.hstack copied twice as much)
    J = np.empty((6, len(p)))
    J[:3] = n.T
    px, py, pz = p.T
    nx, ny, nz = J[0], J[1], J[2]
    np.multiply(py, nz, out=J[3])
    J[3] -= pz * ny
    np.multiply(pz, nx, out=J[4])
    J[4] -= px * nz
    np.multiply(px, ny, out=J[5])
    J[5] -= py * nx
    return J


def information_matrix(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) points and (N, 3) unit normals -> (6, 6) sum of J^T J (translation, rotation)."""
    # (summed by einsum's own loop: BLAS on (6, N) x (N, 6) took 2 to 100 times longer on a loaded
    # machine, its threads waiting for cores)
    J = plane_jacobian(points, normals)
    return np.einsum("in,jn->ij", J, J)


@dataclass
class Degeneracy:
    """Per-point information figures of one scan.

    eigenvalues: (6,) ascending eigenvalues of H / N (mixed units; see module doc).
    translation_eigenvalues: (3,) ascending eigenvalues of the translation block of H / N.
    weakest_translation: (3,) unit direction of the smallest translational eigenvalue
        (sign normalised so its largest component is positive).
    points: N.
    """

    eigenvalues: np.ndarray
    translation_eigenvalues: np.ndarray
    weakest_translation: np.ndarray
    points: int

    @property
    def translation_condition(self) -> float:
        """Largest over smallest translational eigenvalue (inf when degenerate)."""
        lo = self.translation_eigenvalues[0]
        return float(self.translation_eigenvalues[-1] / lo) if lo > 0 else float("inf")


def degeneracy(points: np.ndarray, normals: np.ndarray) -> Degeneracy:
    """Eigen-analysis of the point-to-plane information of a scan (see ``Degeneracy``)."""
    n = len(points)
    if n == 0:
        return Degeneracy(np.zeros(6), np.zeros(3), np.array([1.0, 0.0, 0.0]), 0)
    # compiled (``kernels.information``): the same sums as information_matrix to rounding, in one pass
    H = information_sums(np.asarray(points, dtype=np.float64), np.asarray(normals, dtype=np.float64)) / n
    w_t, v_t = np.linalg.eigh(H[:3, :3])
    weakest = v_t[:, 0]
    weakest = weakest * np.sign(weakest[np.argmax(np.abs(weakest))])
    return Degeneracy(np.linalg.eigvalsh(H), w_t, weakest, n)


CSV_HEADER = (
    "frame,points,"
    + ",".join(f"eig{k}" for k in range(6))
    + ",t_eig0,t_eig1,t_eig2,weak_x,weak_y,weak_z"
)


def csv_row(frame: int, d: Degeneracy) -> str:
    vals = [*d.eigenvalues, *d.translation_eigenvalues, *d.weakest_translation]
    return f"{frame},{d.points}," + ",".join(f"{v:.6e}" for v in vals)
