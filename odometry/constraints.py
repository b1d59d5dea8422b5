"""How well a set of point-to-plane constraints pins down each direction of motion.

For a point p with unit normal n, a small motion (rho, omega) changes the
point-to-plane residual by ``n . rho + (p x n) . omega``: the row
``J = [n, p x n]``. The information of a set of points is ``H = sum J^T J``
(6 x 6); a direction u of motion is constrained by ``u^T H u``. Translation (m)
and rotation (rad) differ in unit, so directions are compared in scaled
coordinates ``(rho, L omega)`` with a length L (``degeneracy.rotation_scale_m``, about the
distance of the points that constrain rotation): the rows become
``[n, (p x n) / L]``, dimensionless, and ``H / N`` (per point) has eigenvalues
in [0, 1] for the translation part: a direction with eigenvalue 1/3 is as well
constrained as a direction can be among three, a tunnel's axis has about 1e-3.

Two uses, one threshold (``min_eigenvalue``, per point):

- ``remapped_step``: the degeneracy-aware Gauss-Newton step (solution remapping,
  Zhang, Kaess and Singh, ICRA 2016): directions of H whose eigenvalue per match
  is below the threshold get no update, so the estimate keeps the motion
  prior there (the ICP starts at the constant-velocity prediction); the
  well-constrained directions are solved as usual.
- ``restore_constraints``: a point filter (the NCF) must not remove the last
  evidence for a direction. A direction that the filtered points constrain
  below the threshold, and the unfiltered points better, gets back the rejected
  points that carry most of it, until it reaches the threshold or all it had.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simlidar.degeneracy import plane_jacobian

from .kernels.plane_system import constraint_information


def constraint_rows(points: np.ndarray, normals: np.ndarray, rotation_scale_m: float) -> np.ndarray:
    """(N, 6) scaled rows ``[n, (p x n) / L]`` of (N, 3) points and unit normals."""
    J = np.ascontiguousarray(plane_jacobian(points, normals).T)
    J[:, 3:] /= rotation_scale_m
    return J


def scale_matrix(rotation_scale_m: float) -> np.ndarray:
    """(6,) diagonal D mapping scaled coordinates (rho, L omega) back to (rho, omega): x = D y."""
    return np.array([1.0, 1.0, 1.0, 1.0 / rotation_scale_m, 1.0 / rotation_scale_m, 1.0 / rotation_scale_m])


@dataclass
class Solve:
    """A Gauss-Newton solve of ``H x = -g``.

    xi: (6,) the increment (rho m, omega rad). rank: directions solved numerically.
    remapped: well-determined directions left at the prior because they were weak.
    eigenvalues: (6,) ascending eigenvalues of the scaled per-match information.
    """

    xi: np.ndarray
    rank: int
    remapped: int
    eigenvalues: np.ndarray


def remapped_step(H: np.ndarray, g: np.ndarray, n: int, rotation_scale_m: float,
                  min_eigenvalue: float = 0.0, rcond: float = 1e-10, mode: str = "remap",
                  deviation: np.ndarray | None = None) -> Solve:
    """Solve ``H x = -g`` in the scaled eigenbasis, with weak directions held to the prior.

    H: (6, 6) ``J^T J`` in (rho, omega); g: (6,) ``J^T r``; n: number of matches.
    Numerically zero directions (``rcond`` of the largest eigenvalue) get no update. Then,
    with ``min_eigenvalue`` = lambda > 0 (scaled, per match):

    - ``mode="remap"``: directions below lambda get no update (solution remapping: the
      estimate keeps the prior there, whatever the data say, frame after frame);
    - ``mode="prior"``: a Gaussian motion prior of information lambda per match in every
      direction (maximum a posteriori): minimise ``|J x + r|^2 + n lambda |dev + x|^2`` in
      scaled coordinates, ``deviation`` (6,) being the current estimate's offset from the
      prior (the ICP's initial guess). A direction of information w ends at the blend
      ``(w data + lambda prior) / (w + lambda)``: below lambda it follows the prior, far above
      it the data, and a weak but consistent signal (an acceleration along a tunnel-like
      road) still moves the estimate, which the next frame's prediction carries on.

    ``Solve.remapped`` counts the directions below lambda.
    """
    d = scale_matrix(rotation_scale_m)
    Hs = H * d[:, None] * d[None, :] / max(n, 1)
    gs = g * d / max(n, 1)
    w, V = np.linalg.eigh(Hs)
    numeric = w > rcond * max(w[-1], 1e-300)
    weak = numeric & (w < min_eigenvalue)
    if mode == "prior" and min_eigenvalue > 0:
        dev = np.zeros(6) if deviation is None else deviation / d
        b = V[:, numeric].T @ (gs + min_eigenvalue * dev)
        y = -(V[:, numeric] @ (b / (w[numeric] + min_eigenvalue)))
    else:
        solved = numeric & ~weak
        y = -(V[:, solved] @ ((V[:, solved].T @ gs) / w[solved]))
    return Solve(d * y, int(numeric.sum()), int(weak.sum()), w)


def weakest_translation(H: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """((3,) ascending eigenvalues of the per-match translation block, (3,) unit eigenvector of the smallest).

    The vector's sign is fixed so that its largest component is positive (a direction, not an arrow).
    """
    w, V = np.linalg.eigh(H[:3, :3] / max(n, 1))
    v = V[:, 0]
    return w, v if v[np.argmax(np.abs(v))] > 0 else -v


def restore_constraints(points: np.ndarray, normals: np.ndarray, candidates: np.ndarray, kept: np.ndarray,
                        min_eigenvalue: float, rotation_scale_m: float) -> np.ndarray:
    """Keep-mask ``kept`` with rejected candidates restored where a direction would be lost.

    points, normals: (M, 3) in the scan's frame; candidates: (M,) bool, points the
    filter judged (finite normals); kept: (M,) bool subset, what it kept.
    Information is per candidate point (``H / n_candidates``), so a filter that
    keeps half the points of a well-constrained direction still leaves it at half.
    Returns the (M,) keep mask (a superset of ``kept``).
    """
    n_all = int(candidates.sum())
    kept = kept & candidates
    if n_all == 0 or min_eigenvalue <= 0:
        return kept
    H_kept = constraint_information(np.ascontiguousarray(points, dtype=np.float64),
                                    np.ascontiguousarray(normals, dtype=np.float64), np.flatnonzero(kept),
                                    float(rotation_scale_m))
    w, V = np.linalg.eigh(H_kept / n_all)
    if w[0] >= min_eigenvalue:  # (the usual case: nothing to restore, and no need for every row's J)
        return kept
    J = constraint_rows(points, normals, rotation_scale_m)
    H_all = J[candidates].T @ J[candidates] / n_all
    out = kept.copy()
    for lam, u in zip(w, V.T, strict=True):
        if lam >= min_eigenvalue:
            break
        goal = min(min_eigenvalue, float(u @ H_all @ u))
        have = float(u @ (J[out].T @ J[out]) @ u) / n_all  # earlier restorations count
        if have >= goal:
            continue
        rejected = np.flatnonzero(candidates & ~out)
        gain = (J[rejected] @ u) ** 2 / n_all
        order = np.argsort(-gain)
        reach = np.searchsorted(np.cumsum(gain[order]), goal - have) + 1
        out[rejected[order[:reach]]] = True
    return out

