"""odometry.kdtree: pykdtree's tree answers as scipy's cKDTree, including its edge cases."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from odometry.kdtree import KDTree


@pytest.mark.parametrize("k", [1, 5])
@pytest.mark.parametrize("bound", [np.inf, 0.8])
def test_same_distances_and_indices_as_ckdtree(k, bound):
    rng = np.random.default_rng(3)
    cloud = rng.uniform(-20, 20, size=(3000, 3))
    points = rng.uniform(-21, 21, size=(2000, 3))
    d_ref, i_ref = cKDTree(cloud).query(points, k=k, distance_upper_bound=bound)
    d, i = KDTree(cloud).query(points, k=k, distance_upper_bound=bound)
    assert d.shape == d_ref.shape and i.dtype == np.intp
    np.testing.assert_allclose(d, d_ref, rtol=1e-12)
    np.testing.assert_array_equal(i, i_ref)
    if np.isfinite(bound):  # the bound left some without a neighbour: (inf, n) as scipy
        assert (i == len(cloud)).any() and np.all(np.isinf(d[i == len(cloud)]))


def test_more_neighbours_than_points_and_empty_inputs():
    cloud = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    d, i = KDTree(cloud).query(np.array([[0.1, 0, 0]]), k=4)
    np.testing.assert_array_equal(i, [[0, 1, 2, 2]])
    np.testing.assert_allclose(d[0, :2], [0.1, 0.9])
    assert np.all(np.isinf(d[0, 2:]))
    d, i = KDTree(np.zeros((0, 3))).query(np.ones((2, 3)), k=1)
    assert np.all(np.isinf(d)) and np.all(i == 0)
    d, i = KDTree(cloud).query(np.zeros((0, 3)), k=3)
    assert d.shape == (0, 3) and i.shape == (0, 3)
