"""Neighbourhoods across scan lines (odometry.scan_lines), against a constructed ring pattern.

A 32-ring sensor (1.33 deg pitch, 0.2 deg azimuth step) 1.8 m above a ground plane
tilted by 2 deg: every return is computed exactly (ray and plane), then moved along
its beam by Gaussian range noise (2 cm). A query 6-12 m out has k = 12 nearest points
on its own ring only, a near-straight arc 0.3-0.5 m long: across it the points spread
only by the noise, along the beams, so their PCA normal is perpendicular to the beams,
tilted from the ground's by about the beam's depression (5-17 deg here). Widened with
the adjacent ring (0.5-2 m away), the neighbourhood spans two lines of the plane, and
the normal's error is the noise over that gap: well below a degree.
"""

from __future__ import annotations

import numpy as np
import pytest

from odometry.normals import angle_between_normals_rad, knn, local_pca
from odometry.scan_lines import azimuth_columns, range_image, widen_one_ring_neighbourhoods

RINGS, COLUMNS = 32, 1800
ELEVATIONS = np.radians(-30.67 + 1.33 * np.arange(RINGS))
TILT = np.radians(2.0)
NORMAL = np.array([np.sin(TILT), 0.0, np.cos(TILT)])  # the ground's upward normal
HEIGHT_M = 1.8


def ground_scan(columns: int = COLUMNS, noise_std_m: float = 0.02):
    """(N, 3) returns on the tilted ground plane n . p = -1.8 and (N,) their rings."""
    az = (np.arange(columns) + 0.5) * 2 * np.pi / columns - np.pi
    el, a = np.meshgrid(ELEVATIONS, az, indexing="ij")
    beams = np.stack([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)], axis=-1).reshape(-1, 3)
    rings = np.repeat(np.arange(RINGS), columns)
    along = beams @ NORMAL
    hit = along < -1e-3  # beams that meet the plane below
    r = -HEIGHT_M / along[hit] + np.random.default_rng(0).normal(0.0, noise_std_m, int(hit.sum()))
    keep = r < 60.0
    return (beams[hit] * r[:, None])[keep], rings[hit][keep]


def test_range_image_holds_every_point_in_its_cell():
    points, rings = ground_scan()
    image = range_image(rings, points, RINGS, COLUMNS)
    rows = image[image >= 0]
    assert len(rows) == len(points) and len(np.unique(rows)) == len(points)
    assert np.array_equal(image[rings, azimuth_columns(points, COLUMNS)], np.arange(len(points)))
    with pytest.raises(ValueError, match="ring 32"):
        range_image(np.full(3, 32), points[:3], RINGS, COLUMNS)


def radial_tilt_deg(normals: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(M,) tilt of upward normals from the ground's, towards the sensor (+) or away, deg."""
    n = normals * np.sign(normals[:, 2:3])
    outward = points[:, :2] / np.linalg.norm(points[:, :2], axis=1, keepdims=True)
    return -np.degrees(np.einsum("ij,ij->i", (n - NORMAL)[:, :2], outward))


def test_one_ring_neighbourhoods_get_the_plane_normal():
    points, rings = ground_scan()
    distance = np.linalg.norm(points[:, :2], axis=1)
    queries = points[(distance > 6.0) & (distance < 12.0)][::7]
    idx = knn(points, queries, 12)
    assert np.all(rings[idx] == rings[idx][:, :1])  # the premise: one ring each
    before = radial_tilt_deg(local_pca(points[idx], queries).normals, queries)
    assert abs(before.mean()) > 5.0  # a bias of about the beam's depression (12 deg measured), not noise

    wide, widened = widen_one_ring_neighbourhoods(points, rings, queries, idx, RINGS, COLUMNS, max_distance_m=4.0)
    assert widened.all()
    assert np.array_equal(wide[:, :6], idx[:, :6])  # the nearest half stays
    assert np.all(np.abs(rings[wide[:, 6:]] - rings[idx[:, :1]]) == 1)  # the rest from an adjacent ring
    after = radial_tilt_deg(local_pca(points[wide], queries).normals, queries)
    # no bias left (0.02 deg measured over 1,594 normals), and the noise over a 0.5-2 m gap (0.23 deg)
    assert abs(after.mean()) < 0.1 and after.std() < 0.5
    overall = angle_between_normals_rad(local_pca(points[wide], queries).normals, np.tile(NORMAL, (len(wide), 1)))
    assert np.degrees(np.median(overall)) < 1.5


def test_rings_as_a_driver_gives_them_uint16_widen_the_lowest_ring_too():
    points, rings = ground_scan()
    queries = points[rings == 0][::25]  # its one adjacent ring is above: ring - 1 must not wrap
    idx = knn(points, queries, 12)
    wide, widened = widen_one_ring_neighbourhoods(points, rings, queries, idx, RINGS, COLUMNS, 4.0)
    same, _ = widen_one_ring_neighbourhoods(points, rings.astype(np.uint16), queries, idx, RINGS, COLUMNS, 4.0)
    assert widened.any() and np.array_equal(same, wide)
    assert np.all(rings[wide[widened][:, 6:]] == 1)


def test_widening_keeps_two_ring_neighbourhoods_and_respects_the_distance():
    # a coarse azimuth step (1 deg): 3-4 m out, a ring's points are 5-7 cm apart and the next
    # ring 0.2 m away, so most kNN neighbourhoods already hold two rings
    points, rings = ground_scan(columns=360)
    distance = np.linalg.norm(points[:, :2], axis=1)
    near = points[(distance > 3.0) & (distance < 4.0)]
    idx = knn(points, near, 12)
    two = ~np.all(rings[idx] == rings[idx][:, :1], axis=1)
    assert two.mean() > 0.5
    wide, widened = widen_one_ring_neighbourhoods(points, rings, near, idx, RINGS, 360, max_distance_m=4.0)
    assert not widened[two].any() and np.array_equal(wide[two], idx[two])
    assert widened[~two].all()

    points, rings = ground_scan()
    distance = np.linalg.norm(points[:, :2], axis=1)

    far = points[(distance > 25.0) & (distance < 30.0)][::13]  # the next ring is metres away
    idx = knn(points, far, 12)
    gap = 0.5
    wide, widened = widen_one_ring_neighbourhoods(points, rings, far, idx, RINGS, COLUMNS, max_distance_m=gap)
    assert not widened.any() and np.array_equal(wide, idx)


def widened_by_numpy(cloud, rings, query_points, idx, n_rings, n_columns, max_distance_m):
    """The rule of ``kernels.range_image.adjacent_ring_neighbourhoods``, written with numpy arrays (the reference)."""
    idx = np.array(idx, dtype=np.intp)
    m, k = idx.shape
    half = k // 2
    own = rings[idx]
    one_ring = np.flatnonzero(np.all(own == own[:, :1], axis=1))
    widened = np.zeros(m, dtype=bool)
    if half == 0:
        return idx, widened
    image = range_image(rings, cloud, n_rings, n_columns)
    q = query_points[one_ring]
    offsets = np.array([0] + [s * i for i in range(1, half + 1) for s in (-1, 1)])
    columns = (azimuth_columns(q, n_columns)[:, None] + offsets[None, :]) % n_columns
    best_rows = np.zeros((len(one_ring), half), dtype=np.intp)
    best_reach = np.full(len(one_ring), np.inf)
    for step in (-1, 1):
        adjacent = own[one_ring, 0] + step
        exists = (adjacent >= 0) & (adjacent < n_rings)
        cells = image[np.clip(adjacent, 0, n_rings - 1)[:, None], columns]
        cells[~exists] = -1
        first = np.argsort(cells < 0, axis=1, kind="stable")[:, :half]  # the first filled cells in that order
        rows = np.take_along_axis(cells, first, axis=1)
        reach = np.linalg.norm(cloud[np.maximum(rows, 0)] - q[:, None, :], axis=2).max(axis=1)
        reach[(rows < 0).any(axis=1)] = np.inf
        nearer = reach < best_reach
        best_rows[nearer], best_reach[nearer] = rows[nearer], reach[nearer]
    accept = best_reach <= max_distance_m
    idx[one_ring[accept], k - half:] = best_rows[accept]
    widened[one_ring[accept]] = True
    return idx, widened


@pytest.mark.parametrize("k", [12, 7, 1])
def test_the_compiled_widening_is_the_numpy_rule(k):
    """On a scan with holes (dropped returns: cells missing on the adjacent rings) and queries near and far,
    at the lowest and highest rings too, the compiled pass keeps and replaces the same neighbours."""
    points, rings = ground_scan(columns=900)
    rng = np.random.default_rng(8)
    kept = rng.random(len(points)) > 0.2
    points, rings = points[kept], rings[kept]
    queries = points[::5] + rng.normal(0.0, 0.05, size=points[::5].shape)
    idx = knn(points, queries, k)
    wide, widened = widen_one_ring_neighbourhoods(points, rings, queries, idx, RINGS, 900, max_distance_m=3.0)
    expected, expected_widened = widened_by_numpy(points, rings, queries, idx, RINGS, 900, 3.0)
    np.testing.assert_array_equal(wide, expected)
    np.testing.assert_array_equal(widened, expected_widened)
    if k > 1:
        one_ring = np.all(rings[idx] == rings[idx][:, :1], axis=1)
        assert 0 < widened.sum() < one_ring.sum()  # some widened, some too far or without the cells
