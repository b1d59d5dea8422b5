"""odometry.kdtree_query: a query split across the process's threads answers as one cKDTree query."""

import numpy as np
from scipy.spatial import cKDTree

from odometry import kdtree_query


def test_split_query_equals_one_query():
    rng = np.random.default_rng(0)
    cloud = rng.uniform(-20, 20, size=(5000, 3))
    points = rng.uniform(-21, 21, size=(3 * kdtree_query.MIN_CHUNK_POINTS + 7, 3))
    tree = cKDTree(cloud)
    for k, bound in ((1, 0.5), (1, np.inf), (12, np.inf)):
        d, i = kdtree_query.query(tree, points, k=k, distance_upper_bound=bound)
        d_ref, i_ref = tree.query(points, k=k, distance_upper_bound=bound)
        assert d.shape == d_ref.shape and i.shape == i_ref.shape
        np.testing.assert_array_equal(d, d_ref)
        np.testing.assert_array_equal(i, i_ref)


def test_small_and_empty_queries():
    cloud = np.random.default_rng(1).normal(size=(100, 3))
    tree = cKDTree(cloud)
    d, i = kdtree_query.query(tree, cloud[:3], k=1)
    np.testing.assert_array_equal(i, [0, 1, 2])
    d, i = kdtree_query.query(tree, np.zeros((0, 3)), k=4)
    assert d.shape == (0, 4) and i.shape == (0, 4)
