"""k-nearest-neighbour surface normals by principal component analysis (PCA / SVD).

For a query point q with neighbours p_0 .. p_{k-1} (its k nearest points in the
raw scan), the centred data matrix is ``D = P - 1 m^T`` (k x 3, m the mean of
the neighbours). With the SVD ``D = U S V^T`` (numpy's convention: the columns
of V are the right singular vectors, singular values s_0 >= s_1 >= s_2), the
normal is the last right singular vector v_2. The same V and ``s_l^2`` are the
eigenvectors and eigenvalues of the 3 x 3 scatter matrix ``D^T D``; this module
computes them that way: a 3 x 3 symmetric eigenproblem per point, solved in
closed form for all points at once (``symmetric_eigh_descending``), is an order
of magnitude cheaper than a batched k x 3 SVD, and in float64 the squared
condition number is harmless at lidar scales.

Conventions used here and by ``odometry.ncf``:

- ``axes[m]`` is V (3 x 3, columns v_0, v_1, v_2, a right-handed rotation) and
  ``axes[m][:, 2]`` is the normal, oriented towards the viewpoint (the sensor
  origin by default): ``n . (q - viewpoint) <= 0``.
- ``scatter_eigenvalues`` are ``s_l^2`` (m^2), descending; ``eigenvalues`` are
  those of the neighbourhood covariance ``D^T D / k`` (PCL's
  ``computeMeanAndCovarianceMatrix``), also descending, so index 2 is the
  smallest in both, as the paper's ``V_2``.
- ``curvature = lambda_min / (lambda_0 + lambda_1 + lambda_2)`` as PCL's
  ``solvePlaneParameters`` returns it: 0 on a plane, at most 1/3 (isotropic
  scatter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kdtree import KDTree
from .kernels.normals import eigh3_closed_form, neighbourhood_scatter


@dataclass(frozen=True)
class NormalEstimate:
    """PCA of each query point's neighbourhood.

    Attributes:
        normals: (M, 3) unit normals, oriented towards the viewpoint.
        axes: (M, 3, 3) right singular vectors as columns (v_0, v_1, v_2 = normal).
        scatter_eigenvalues: (M, 3) ``s_l^2`` of the centred data matrix, descending, m^2.
        mean: (M, 3) neighbourhood centroids, m.
        k: neighbours per point.
        neighbour_indices: (M, k) int rows of the searched cloud, nearest first
            (None when the PCA was computed from given neighbourhoods).
    """

    normals: np.ndarray
    axes: np.ndarray
    scatter_eigenvalues: np.ndarray
    mean: np.ndarray
    k: int
    neighbour_indices: np.ndarray | None = None

    @property
    def singular_values(self) -> np.ndarray:
        """(M, 3) singular values s_0 >= s_1 >= s_2 of the centred data matrix, m."""
        return np.sqrt(np.maximum(self.scatter_eigenvalues, 0.0))

    @property
    def eigenvalues(self) -> np.ndarray:
        """(M, 3) eigenvalues of the neighbourhood covariance ``D^T D / k``, descending, m^2."""
        return self.scatter_eigenvalues / self.k

    @property
    def curvature(self) -> np.ndarray:
        """(M,) PCL surface curvature ``lambda_min / sum(lambda)`` in [0, 1/3] (nan if all zero)."""
        lam = np.maximum(self.scatter_eigenvalues, 0.0)
        total = lam.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, lam[:, 2] / total, np.nan)

    def __len__(self) -> int:
        return len(self.normals)


# Below this relative gap lambda_1 - lambda_2 the closed form loses digits (its
# arccos is ill-conditioned where two eigenvalues meet: the normal's error grows
# like eps (lambda_0 / gap)^2); those few matrices go to LAPACK instead.
_CLOSED_FORM_MIN_REL_GAP = 1e-3


def symmetric_eigh_descending(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition of (M, 3, 3) symmetric matrices, eigenvalues descending.

    Returns (w (M, 3), V (M, 3, 3)) with ``A = V diag(w) V^T``, columns of V the
    eigenvectors, ``det V = +1``; nan for matrices with non-finite entries.

    Closed form, compiled (``odometry.kernels.normals.eigh3_closed_form``; several times faster
    than a LAPACK call per matrix): the eigenvalues from the trigonometric solution of the
    characteristic cubic; v_2 (smallest) as the longest cross product of two
    rows of ``A - lambda_2 I``; v_0, v_1 from the 2 x 2 problem in the plane
    orthogonal to v_2. Matrices whose two smallest eigenvalues are closer than
    ``_CLOSED_FORM_MIN_REL_GAP * lambda_0`` are passed to ``numpy.linalg.eigh``.
    """
    A = np.ascontiguousarray(A, dtype=np.float64)
    w, V, redo = eigh3_closed_form(A, _CLOSED_FORM_MIN_REL_GAP)
    if redo.any():
        finite = np.isfinite(A).all(axis=(1, 2))
        lap = redo & finite
        w[redo] = np.nan
        V[redo] = np.nan
        if np.any(lap):
            w_l, V_l = np.linalg.eigh(A[lap])  # ascending
            V_l = V_l[..., ::-1].copy()
            V_l[..., :, 0] = np.cross(V_l[..., :, 1], V_l[..., :, 2])  # right-handed
            w[lap] = w_l[..., ::-1]
            V[lap] = V_l
    return w, V


def local_pca(
    neighbourhoods: np.ndarray,
    query_points: np.ndarray | None = None,
    viewpoint: np.ndarray | None = None,
) -> NormalEstimate:
    """PCA normals of given neighbourhoods.

    Args:
        neighbourhoods: (M, k, 3) neighbour coordinates, m (k >= 3).
        query_points: (M, 3) the points the normals belong to, used only to orient
            them (default: the neighbourhood means).
        viewpoint: (3,) where the sensor is, m (default: the origin).

    Returns:
        ``NormalEstimate`` without ``neighbour_indices``.
    """
    P = np.asarray(neighbourhoods, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3 or P.shape[1] < 3:
        raise ValueError(f"neighbourhoods must be (M, k, 3) with k >= 3, got {P.shape}")
    k = P.shape[1]
    mean, scatter = neighbourhood_scatter(np.ascontiguousarray(P))
    lam, V = symmetric_eigh_descending(scatter)
    q = mean if query_points is None else np.asarray(query_points, dtype=np.float64)
    vp = np.zeros(3) if viewpoint is None else np.asarray(viewpoint, dtype=np.float64)
    # Orient towards the viewpoint; flipping v_2 and v_1 together keeps det V = +1.
    sign = np.where(np.einsum("mi,mi->m", V[:, :, 2], q - vp) > 0, -1.0, 1.0)
    V[:, :, 1:] *= sign[:, None, None]
    return NormalEstimate(
        normals=V[:, :, 2].copy(),
        axes=V,
        scatter_eigenvalues=lam,
        mean=mean,
        k=k,
    )


def knn(
    cloud: np.ndarray,
    query_points: np.ndarray,
    k: int,
    tree: KDTree | None = None,
) -> np.ndarray:
    """(M, k) int indices of each query point's k nearest cloud points, nearest first.

    Args:
        cloud: (N, 3) searched points, m (N >= k).
        query_points: (M, 3) m.
        tree: a k-d tree (``odometry.kdtree.KDTree``) already built on ``cloud`` (built here
            if None); its queries run on every core.
    """
    if len(cloud) < k:
        raise ValueError(f"the cloud has {len(cloud)} points, fewer than k = {k} neighbours")
    if tree is None:
        tree = KDTree(cloud)
    _, idx = tree.query(query_points, k=k)
    return np.asarray(idx, dtype=np.intp).reshape(len(query_points), k)


def estimate_normals(
    cloud: np.ndarray,
    k: int = 20,
    query_points: np.ndarray | None = None,
    viewpoint: np.ndarray | None = None,
    tree: KDTree | None = None,
) -> NormalEstimate:
    """Normals of ``query_points`` from their k nearest neighbours in the raw ``cloud``.

    Args:
        cloud: (N, 3) the raw scan, sensor frame, m.
        k: neighbours per point (>= 3). A query point that belongs to the cloud
            counts as its own first neighbour, as in PCL.
        query_points: (M, 3) points to estimate normals at, e.g. voxel centroids
            (default: every cloud point).
        viewpoint: (3,) sensor position for the orientation ``n . (q - viewpoint) <= 0``
            (default: the origin of the scan's frame).
        tree: optional k-d tree (``odometry.kdtree.KDTree``) already built on ``cloud``.

    Returns:
        ``NormalEstimate`` with ``neighbour_indices`` (M, k) into ``cloud``;
        ``cloud[result.neighbour_indices]`` are the (M, k, 3) neighbourhoods that
        ``odometry.ncf.normal_covariance`` takes.
    """
    cloud = np.asarray(cloud, dtype=np.float64)
    if k < 3:
        raise ValueError(f"k must be >= 3 to define a plane, got {k}")
    q = cloud if query_points is None else np.asarray(query_points, dtype=np.float64)
    return neighbourhood_pca(cloud, knn(cloud, q, k, tree=tree), q, viewpoint)


def neighbourhood_pca(
    cloud: np.ndarray,
    neighbour_indices: np.ndarray,
    query_points: np.ndarray,
    viewpoint: np.ndarray | None = None,
    neighbourhoods: np.ndarray | None = None,
) -> NormalEstimate:
    """``local_pca`` of the neighbourhoods ``cloud[neighbour_indices]`` (M, k, 3), keeping the indices.

    cloud: (N, 3) m; neighbour_indices: (M, k) rows of ``cloud``; query_points: (M, 3) m, to orient
    the normals towards ``viewpoint`` (default: the origin). neighbourhoods: (M, k, 3)
    ``cloud[neighbour_indices]`` when the caller has gathered them already (the NCF needs them too).
    """
    hoods = np.take(cloud, neighbour_indices, axis=0) if neighbourhoods is None else neighbourhoods
    est = local_pca(hoods, query_points=query_points, viewpoint=viewpoint)
    return NormalEstimate(
        normals=est.normals,
        axes=est.axes,
        scatter_eigenvalues=est.scatter_eigenvalues,
        mean=est.mean,
        k=neighbour_indices.shape[1],
        neighbour_indices=neighbour_indices,
    )


def angle_between_normals_rad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) unsigned angle between (N, 3) unit normals, ignoring orientation, rad in [0, pi/2]."""
    # atan2 of |a x b| and |a . b|: accurate at small angles, where arccos loses half the digits.
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.abs(np.einsum("ij,ij->i", a, b)))
