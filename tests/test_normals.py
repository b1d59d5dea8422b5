"""kNN PCA normals: exact on analytic surfaces, oriented to the sensor, equal to the SVD, fast eigen-solver exact."""

from __future__ import annotations

import numpy as np
import pytest

from odometry.normals import (
    angle_between_normals_rad,
    estimate_normals,
    knn,
    local_pca,
    symmetric_eigh_descending,
)


def plane_cloud(normal, offset_m, n_points=4000, half=3.0, seed=0):
    """Points on the plane n . x = offset, around its point closest to the origin."""
    rng = np.random.default_rng(seed)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    uv = rng.uniform(-half, half, size=(n_points, 2))
    return offset_m * n + uv[:, :1] * e1 + uv[:, 1:] * e2


def test_plane_normals_exact_and_oriented_towards_the_sensor():
    for normal, offset in (((1.0, 0.2, 0.1), 10.0), ((0.0, 0.0, 1.0), -1.9), ((-0.3, 1.0, 0.4), -7.0)):
        cloud = plane_cloud(normal, offset)
        est = estimate_normals(cloud, k=15)
        n_true = np.asarray(normal) / np.linalg.norm(normal)
        assert angle_between_normals_rad(est.normals, np.broadcast_to(n_true, cloud.shape)).max() < 1e-9
        # Towards the sensor at the origin: n . p <= 0.
        assert np.all(np.einsum("ij,ij->i", est.normals, cloud) <= 0)
        assert np.abs(est.curvature).max() < 1e-12
        assert np.abs(est.eigenvalues[:, 2]).max() < 1e-20 + 1e-12 * est.eigenvalues[:, 0].max()


def test_viewpoint_orientation():
    cloud = plane_cloud((0.0, 0.0, 1.0), 0.0)
    up = estimate_normals(cloud, k=10, viewpoint=np.array([0.0, 0.0, 5.0]))
    down = estimate_normals(cloud, k=10, viewpoint=np.array([0.0, 0.0, -5.0]))
    assert np.all(up.normals[:, 2] > 0.999) and np.all(down.normals[:, 2] < -0.999)


def test_pca_equals_svd_of_the_centred_neighbourhood():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(500, 12, 3)) * np.array([1.0, 0.4, 0.05]) + rng.normal(size=(500, 1, 3)) * 20
    est = local_pca(P)
    D = P - P.mean(axis=1, keepdims=True)
    _, s, Vh = np.linalg.svd(D, full_matrices=False)
    np.testing.assert_allclose(est.singular_values, s, rtol=1e-9)
    np.testing.assert_allclose(est.eigenvalues, s**2 / 12, rtol=1e-9)
    assert angle_between_normals_rad(est.normals, Vh[:, 2, :]).max() < 1e-9
    # V is a rotation with the normal as its last column.
    np.testing.assert_allclose(np.linalg.det(est.axes), 1.0, atol=1e-12)
    np.testing.assert_allclose(est.axes[:, :, 2], est.normals)
    # PCL's curvature from the covariance eigenvalues.
    lam = np.linalg.eigvalsh(np.einsum("mki,mkj->mij", D, D) / 12)
    np.testing.assert_allclose(est.curvature, lam[:, 0] / lam.sum(axis=1), rtol=1e-8)


def test_curvature_range():
    rng = np.random.default_rng(2)
    iso = local_pca(rng.normal(size=(2000, 200, 3)))  # isotropic blob: close to 1/3
    assert 0.28 < np.median(iso.curvature) <= 1 / 3
    assert np.all(iso.curvature <= 1 / 3 + 1e-12)


def test_query_points_off_the_cloud_get_their_true_neighbours():
    rng = np.random.default_rng(3)
    cloud = rng.uniform(-5, 5, size=(3000, 3))
    q = rng.uniform(-4, 4, size=(200, 3))  # e.g. voxel centroids
    est = estimate_normals(cloud, k=8, query_points=q)
    assert est.neighbour_indices.shape == (200, 8)
    d = np.linalg.norm(q[:, None, :] - cloud[None, :, :], axis=2)
    brute = np.sort(d, axis=1)[:, :8]
    got = np.linalg.norm(cloud[est.neighbour_indices] - q[:, None, :], axis=2)
    np.testing.assert_allclose(got, brute, rtol=1e-12)
    assert np.all(np.einsum("ij,ij->i", est.normals, q) <= 0)  # oriented at the query point
    np.testing.assert_array_equal(knn(cloud, q, 8), est.neighbour_indices)


def test_bad_arguments():
    with pytest.raises(ValueError):
        estimate_normals(np.zeros((10, 3)), k=2)
    with pytest.raises(ValueError):
        estimate_normals(np.zeros((5, 3)), k=8)
    with pytest.raises(ValueError):
        local_pca(np.zeros((4, 2, 3)))


def test_closed_form_eigensolver_matches_lapack():
    """Random, flat, disk-like, line-like and exactly planar scatter matrices, and bad input."""
    rng = np.random.default_rng(4)
    X = rng.normal(size=(3000, 20, 3))
    for scale in ((1, 1, 1), (1, 0.5, 1e-4), (1, 1, 1e-3), (1, 1e-3, 1e-3), (1, 0.3, 0.0), (1, 1, 1e-7)):
        R = np.linalg.qr(rng.normal(size=(3000, 3, 3)))[0]
        D = np.einsum("mki,mji->mkj", X * np.asarray(scale), R) * 7.0
        A = np.einsum("mki,mkj->mij", D, D)
        w, V = symmetric_eigh_descending(A)
        w_ref = np.linalg.eigvalsh(A)[:, ::-1]
        np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-12 * np.abs(w_ref).max())
        np.testing.assert_allclose(np.einsum("mij,mj,mkj->mik", V, w, V), A, atol=1e-12 * np.abs(A).max())
        np.testing.assert_allclose(np.einsum("mji,mjk->mik", V, V), np.broadcast_to(np.eye(3), A.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(V), 1.0, atol=1e-12)
        # The normal itself to ~1e-9 rad wherever it is defined.
        gap = (w_ref[:, 1] - w_ref[:, 2]) / w_ref[:, 0]
        ok = gap > 1e-6
        v_ref = np.linalg.eigh(A[ok])[1][:, :, 0]
        assert angle_between_normals_rad(V[ok, :, 2], v_ref).max() < 1e-9
    bad = np.zeros((3, 3, 3))
    bad[1, 0, 0] = np.nan
    bad[2] = np.eye(3) * 2.0
    w, V = symmetric_eigh_descending(bad)
    assert np.all(np.isnan(w[1])) and np.allclose(w[0], 0) and np.allclose(w[2], 2.0)
