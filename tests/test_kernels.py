"""The compiled kernels (odometry/kernels/) compute what their docstrings' numpy expressions compute."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from odometry.constraints import constraint_rows
from odometry.kernels.gcr import row_max_with_floor
from odometry.kernels.ncf import beam_noise_moments, range_noise_moments, tangent_covariance_in_frame
from odometry.kernels.nearest import reusable_matches
from odometry.kernels.normals import eigh3_closed_form, gathered_scatter, map_normal_verdicts, neighbourhood_scatter
from odometry.kernels.plane_system import (
    constraint_information,
    more_plane_rows,
    plane_gate,
    plane_normal_equations,
    standard_rejection_system,
)
from odometry.kernels.poles import consensus_votes
from odometry.kernels.range_image import fill_range_image
from odometry.kernels.screw import rescrew_motion, screw_motion
from odometry.kernels.voxel_hash import group_keys, keys_near, packed_voxel_keys, voxel_sums, within_reach_of_any
from simlidar import se3
from simlidar.degeneracy import plane_jacobian


def unit_rows(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_plane_normal_equations_are_J_transpose_J_and_J_transpose_r():
    rng = np.random.default_rng(0)
    p = rng.uniform(-40, 40, size=(3000, 3))
    q = p + rng.normal(scale=0.05, size=p.shape)
    n = unit_rows(rng, 3000)
    H, g, sum_r2 = plane_normal_equations(p, q, n)
    r = np.einsum("ij,ij->i", n, p - q)
    J = plane_jacobian(p, n).T  # (the numpy reference of the compiled row)
    np.testing.assert_array_equal(J, np.hstack([n, np.cross(p, n)]))
    np.testing.assert_allclose(H, J.T @ J, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(g, J.T @ r, rtol=1e-12, atol=1e-12)
    assert sum_r2 == pytest.approx(float(r @ r), rel=1e-12)
    H0, g0, s0 = plane_normal_equations(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    assert not H0.any() and not g0.any() and s0 == 0.0


def test_constraint_information_sums_the_scaled_rows_of_the_chosen_points():
    rng = np.random.default_rng(1)
    p = rng.uniform(-30, 30, size=(500, 3))
    n = unit_rows(rng, 500)
    rows = np.flatnonzero(rng.random(500) < 0.4)
    J = constraint_rows(p[rows], n[rows], 7.0)
    np.testing.assert_allclose(constraint_information(p, n, rows, 7.0), J.T @ J, rtol=1e-12, atol=1e-12)


def test_eigh3_closed_form_decomposes_symmetric_matrices():
    rng = np.random.default_rng(2)
    P = rng.normal(size=(400, 12, 3)) * np.array([2.0, 0.5, 0.01])
    R = se3.exp(np.concatenate([np.zeros(3), rng.normal(size=3)]))[:3, :3]
    D = (P - P.mean(axis=1, keepdims=True)) @ R.T
    A = np.einsum("mki,mkj->mij", D, D)
    w, V, unsure = eigh3_closed_form(A, 1e-3)
    assert not unsure.any()
    np.testing.assert_allclose(w, np.linalg.eigvalsh(A)[:, ::-1], rtol=1e-9, atol=1e-12 * np.abs(A).max())
    np.testing.assert_allclose(np.einsum("mij,mjk->mik", A, V), V * w[:, None, :], atol=1e-9 * np.abs(A).max())
    np.testing.assert_allclose(np.einsum("mji,mjk->mik", V, V), np.broadcast_to(np.eye(3), V.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(V), 1.0, atol=1e-12)
    # two equal eigenvalues (a rod) and a non-finite matrix are flagged for LAPACK
    rod = np.diag([5.0, 1.0, 1.0])[None]
    assert eigh3_closed_form(np.concatenate([rod, np.full((1, 3, 3), np.nan)]), 1e-3)[2].all()


def test_neighbourhood_scatter_is_the_centred_scatter():
    P = np.random.default_rng(6).normal(size=(300, 12, 3)) * 5 + 40
    mean, S = neighbourhood_scatter(P)
    D = P - P.mean(axis=1, keepdims=True)
    np.testing.assert_allclose(mean, P.mean(axis=1), rtol=1e-14)
    np.testing.assert_allclose(S, np.einsum("mki,mkj->mij", D, D), rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("omega", [0.0, 1e-14, 1e-8, 0.03, 1.5])
def test_screw_motion_is_the_exponential_of_each_points_fraction_of_the_twist(omega):
    rng = np.random.default_rng(3)
    xi = np.concatenate([rng.normal(size=3), omega * np.array([0.36, -0.48, 0.8])])
    s = np.concatenate([[0.0, 1e-9], rng.uniform(0.0, 1.0, size=98)])
    p = rng.uniform(-50, 50, size=(100, 3))
    n = unit_rows(rng, 100)
    moved, turned = screw_motion(xi, s, p, n)
    for i in range(100):
        T = se3.exp(s[i] * xi)
        np.testing.assert_allclose(moved[i], T[:3, :3] @ p[i] + T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(turned[i], T[:3, :3] @ n[i], atol=1e-14)
    moved_alone, none = screw_motion(xi, s, p, np.zeros((0, 3)))
    np.testing.assert_array_equal(moved_alone, moved)
    assert none.shape == (0, 3)


def test_reusable_matches_keep_only_nearest_neighbours_they_can_prove():
    rng = np.random.default_rng(4)
    target = rng.uniform(-10, 10, size=(4000, 3))
    tree = cKDTree(target)
    searched = rng.uniform(-10, 10, size=(2000, 3))
    bound = 1.0
    d2, i2 = tree.query(searched, k=2, distance_upper_bound=bound)
    clear = np.minimum(d2[:, 1], bound)
    moved = searched + rng.normal(scale=0.02, size=searched.shape)
    dist, redo = reusable_matches(moved, searched, i2[:, 0], clear, target, bound, 1e-9)
    held = np.setdiff1d(np.arange(2000), redo)
    assert len(held) > 1000 and len(redo) > 0
    d_now, i_now = tree.query(moved, k=1, distance_upper_bound=bound)
    np.testing.assert_array_equal(i2[held, 0], i_now[held])  # a kept match is the nearest now
    np.testing.assert_allclose(dist[held], d_now[held], rtol=1e-12)
    assert np.isinf(dist[redo]).all()
    assert set(np.flatnonzero(np.isinf(d2[:, 0]))) <= set(redo)  # no neighbour then: searched again


def test_more_plane_rows_continue_one_system():
    rng = np.random.default_rng(1)
    p = rng.uniform(-40, 40, size=(500, 3))
    q = p + rng.normal(scale=0.05, size=p.shape)
    n = unit_rows(rng, 500)
    whole = plane_normal_equations(p, q, n)
    first = plane_normal_equations(p[:300], q[:300], n[:300])
    H0 = first[0].copy()
    for got, expected in zip(more_plane_rows(*first, p[300:], q[300:], n[300:]), whole, strict=True):
        np.testing.assert_array_equal(got, expected)  # (the same sums in the same order)
    np.testing.assert_array_equal(first[0], H0)  # (the given system is left as it was)


def test_plane_gate_is_the_plane_and_ncf_masks_and_the_sure_information():
    rng = np.random.default_rng(2)
    moved = rng.uniform(-30, 30, size=(900, 3))
    target_index = rng.integers(0, 400, size=700)
    source_index = np.sort(rng.choice(900, 700, replace=False))
    normals = unit_rows(rng, 700)
    normals[::9] = np.nan  # no plane there
    uncertain = rng.random(400) < 0.3
    centre = np.array([3.0, -2.0, 0.5])
    plane, sure, H = plane_gate(moved, centre, source_index, target_index, normals, uncertain, 12.0)
    np.testing.assert_array_equal(plane, np.isfinite(normals[:, 0]))
    np.testing.assert_array_equal(sure, plane & ~uncertain[target_index])
    assert 0 < sure.sum() < plane.sum() < 700
    expected = constraint_information(moved[source_index] - centre, normals, np.flatnonzero(sure), 12.0)
    np.testing.assert_array_equal(H, expected)
    plane, every, none = plane_gate(moved, centre, source_index, target_index, normals, np.zeros(0, bool),
                                            12.0)
    np.testing.assert_array_equal(every, plane)  # no verdicts: every plane is sure, and no information summed
    assert not none.any()


def test_standard_rejection_system_is_the_rejector_chain_and_its_system():
    from odometry.rejectors import Matches, distance_rejector, geometric_rejector, trimmed_rejector

    rng = np.random.default_rng(3)
    moved = rng.uniform(-30, 30, size=(1200, 3))
    target_points = rng.uniform(-30, 30, size=(500, 3))
    source_index = np.sort(rng.choice(1200, 1000, replace=False))
    target_index = rng.integers(0, 500, size=1000)
    normals = unit_rows(rng, 1000)
    centre = np.array([1.0, 2.0, -0.5])
    bound = rng.uniform(0.0, 1.2, size=1200)
    bound[::13] = np.inf  # (no bound known: the rejector abstains)
    bound[::17] = np.nan
    keep = rng.random(1000) < 0.9
    source = type("S", (), {"gcr_threshold_m": bound})()
    for quantum in (0.0, 0.05):  # distinct distances, then many ties at the trimming's cut
        distance = rng.uniform(0.0, 1.5, size=1000)
        if quantum:
            distance = np.round(distance / quantum) * quantum
        for gcr, trim in ((True, 0.2), (False, 0.2), (True, 0.0), (False, 0.0), (True, 1.0)):
            counts, H, g, sum_r2 = standard_rejection_system(
                moved, target_points, normals, source_index, target_index, distance, keep, 1.0,
                bound if gcr else np.zeros(0), trim, centre)
            m = Matches(source_index, target_index, distance, normals).select(keep)
            expected = []
            for reject in [distance_rejector(1.0)] + ([geometric_rejector()] if gcr else []):
                m = m.select(reject(m, source))
                expected.append(len(m))
            # (trimming with the first rows kept among those at the cut's distance: a stable sort)
            n_keep = len(m) - int(np.floor(trim * len(m)))
            if not quantum:
                assert trimmed_rejector(trim)(m, source).sum() == n_keep
            rows = np.sort(np.argsort(m.distance_m, kind="stable")[:n_keep])
            assert counts.tolist() == [expected[0], expected[-1], n_keep]
            kept = m.select(np.isin(np.arange(len(m)), rows))
            system = plane_normal_equations(moved[kept.source_index] - centre,
                                                    target_points[kept.target_index] - centre, kept.target_normals)
            for got, want in zip((H, g, sum_r2), system, strict=True):
                np.testing.assert_array_equal(got, want)
    assert n_keep == 0 and not H.any()  # (everything trimmed: an empty system)


def test_row_max_with_floor_is_nanmax_raised_to_the_floor():
    rng = np.random.default_rng(4)
    table = rng.uniform(0.0, 0.3, size=(400, 4))
    table[rng.random(table.shape) < 0.3] = np.nan
    table[::7] = np.nan  # rows without a number
    table[::11, 2] = np.inf  # grazing incidence
    for floor in (0.0, 0.1):
        with np.errstate(invalid="ignore"), pytest.warns(RuntimeWarning):
            expected = np.nanmax(table, axis=1)
        expected = np.where(np.isnan(expected), expected, np.maximum(expected, floor))
        np.testing.assert_array_equal(row_max_with_floor(table, floor), expected)


def test_voxel_keys_and_grouping_agree_with_numpy():
    rng = np.random.default_rng(5)
    p = rng.uniform(-60, 60, size=(20000, 3))
    p[::3] = p[1::3][: len(p[::3])] + rng.uniform(-0.1, 0.1, size=(len(p[::3]), 3))  # voxels of several points
    keys, inside = packed_voxel_keys(p, 0.35, 21)
    ijk = np.floor(p / 0.35).astype(np.int64) + (1 << 20)
    assert inside
    np.testing.assert_array_equal(keys, (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2])
    distinct, slot = group_keys(keys)
    u, inverse = np.unique(keys, return_inverse=True)
    np.testing.assert_array_equal(distinct, u)
    np.testing.assert_array_equal(slot, inverse)
    # the hash table grows as distinct keys arrive (from 2048): across its sizes, and with none
    for n_distinct in (0, 1, 2048, 2049, 9000):
        some = rng.permutation(np.repeat(rng.choice(keys, n_distinct, replace=False), 3))
        for got, expected in zip(group_keys(some), np.unique(some, return_inverse=True), strict=True):
            np.testing.assert_array_equal(got, expected)
    values = rng.random(20000)
    sums, value_sums, counts = voxel_sums(slot, len(u), p, values)
    np.testing.assert_array_equal(counts, np.bincount(inverse))
    for c in range(3):
        np.testing.assert_array_equal(sums[:, c], np.bincount(inverse, weights=p[:, c]))
    np.testing.assert_array_equal(value_sums, np.bincount(inverse, weights=values))
    for bad in (np.nan, np.inf, 1e9):
        q = p.copy()
        q[7, 1] = bad
        assert not packed_voxel_keys(q, 0.35, 21)[1]


def test_keys_near_and_within_reach_agree_with_numpy_and_a_kd_tree():
    from odometry.voxels import neighbour_key_steps, voxel_keys

    rng = np.random.default_rng(6)
    points = rng.uniform(-30, 30, size=(6000, 3))
    changed = np.vstack([rng.uniform(-30, 30, size=(300, 3)), points[:50] + rng.normal(scale=0.2, size=(50, 3))])
    keys, changed_keys, steps = voxel_keys(points, 1.0), voxel_keys(changed, 1.0), neighbour_key_steps()
    near = keys_near(keys, changed_keys, steps)
    np.testing.assert_array_equal(near, np.isin(keys, np.unique(changed_keys[:, None] + steps)))
    assert 0 < near.sum() < len(keys)
    assert not keys_near(keys, changed_keys[:0], steps).any()
    # within a voxel's edge: the nearest changed point by a k-d tree decides
    reach = rng.uniform(0.05, 1.0, size=len(points))
    found = within_reach_of_any(points, keys, reach, changed, changed_keys, steps)
    d, _ = cKDTree(changed).query(points)
    np.testing.assert_array_equal(found, d <= reach)
    assert 0 < found.sum() < len(points)
    assert not within_reach_of_any(points, keys, reach, changed[:0], changed_keys[:0], steps).any()


def pca_of(P):
    """(mean (M, 3), V (M, 3, 3)) of neighbourhoods by numpy's SVD."""
    mean = P.mean(axis=1)
    _, _, Vh = np.linalg.svd(P - mean[:, None, :], full_matrices=False)
    return mean, np.ascontiguousarray(Vh.transpose(0, 2, 1))


def test_beam_noise_moments_are_the_sums_of_the_beam_terms():
    rng = np.random.default_rng(7)
    P = rng.normal(size=(200, 12, 3)) * np.array([1.0, 0.5, 0.02]) + rng.uniform(-30, 30, size=(200, 1, 3))
    beams = unit_rows(rng, 200 * 12).reshape(200, 12, 3)
    mean, V = pca_of(P)
    zz, cc = beam_noise_moments(P, mean, V, beams)
    a = np.einsum("mki,mil->mkl", P - mean[:, None, :], V)
    c = np.einsum("mki,mil->mkl", beams, V)
    z = a[:, :, 2:3] * c[:, :, :2] + a[:, :, :2] * c[:, :, 2:3]
    np.testing.assert_allclose(zz, np.einsum("mkl,mkn->mln", z, z), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(cc, np.einsum("mkl,mkl->ml", c, c), rtol=1e-12)


@pytest.mark.parametrize("angular_var", [0.0, 1e-7])
def test_range_noise_moments_are_the_sums_of_the_range_model_terms(angular_var):
    rng = np.random.default_rng(8)
    P = rng.normal(size=(200, 12, 3)) * np.array([1.0, 0.5, 0.02]) + rng.uniform(-30, 30, size=(200, 1, 3))
    mean, V = pca_of(P)
    num, diag = range_noise_moments(P, mean, V, 4e-4, angular_var)
    PV = np.einsum("mki,mil->mkl", P, V)
    a = np.einsum("mki,mil->mkl", P - mean[:, None, :], V)
    r2 = np.einsum("mki,mki->mk", P, P)
    beta_r2 = (4e-4 - angular_var * r2) / r2
    alpha = angular_var * r2
    y = a[:, :, :2] * PV[:, :, 2:3] + a[:, :, 2:3] * PV[:, :, :2]
    expect = np.einsum("mk,mkl,mkn->mln", beta_r2, y, y) + np.einsum("mk,mkl,mkn->mln", alpha, a[:, :, :2], a[:, :, :2])
    expect += np.einsum("mk,mk->m", alpha, a[:, :, 2] ** 2)[:, None, None] * np.eye(2)
    np.testing.assert_allclose(num, expect, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(diag, np.einsum("mk,mkl->ml", beta_r2, PV**2) + alpha.sum(axis=1)[:, None],
                               rtol=1e-10)


def test_tangent_covariance_in_frame_rotates_and_decomposes():
    rng = np.random.default_rng(9)
    _, V = pca_of(rng.normal(size=(100, 12, 3)))
    L = rng.normal(size=(100, 2, 2))
    C = L @ L.transpose(0, 2, 1)
    cov, eig, Q = tangent_covariance_in_frame(V, C)
    Vt = V[:, :, :2]
    np.testing.assert_allclose(cov, Vt @ C @ Vt.transpose(0, 2, 1), atol=1e-12)
    w, U = np.linalg.eigh(cov)  # ascending: 0 along the normal, then minor, major
    np.testing.assert_allclose(eig, np.maximum(w, 0.0), atol=1e-12)
    np.testing.assert_allclose(np.abs(np.einsum("mij,mik->mjk", Q, U)), np.broadcast_to(np.eye(3), Q.shape),
                               atol=1e-6)


def test_the_kernels_callers_refuse_what_the_kernels_cannot_check():
    """numba does not check bounds: the numpy callers check shapes (and broadcast a scalar time) first."""
    from odometry.deskew import redeskew, screw_apply
    from odometry.voxels import voxel_centroids, voxel_keys

    rng = np.random.default_rng(10)
    p = rng.uniform(-10, 10, size=(50, 3))
    xi = np.array([0.5, 0.1, 0.0, 0.0, 0.01, 0.03])
    np.testing.assert_array_equal(screw_apply(xi, 0.5, p), screw_apply(xi, np.full(50, 0.5), p))
    with pytest.raises(ValueError):
        screw_apply(xi, np.full(49, 0.5), p)
    with pytest.raises(ValueError):
        redeskew(p, p[:10], np.zeros(50), np.eye(4), se3.exp(xi), 0.1)
    np.testing.assert_array_equal(screw_apply(np.zeros(6), np.nan, p, rotate_only=True), p)
    with pytest.raises(ValueError):
        voxel_keys(np.hstack([p, p[:, :1]]), 0.5)
    with pytest.raises(ValueError):
        voxel_centroids(p, 0.5, np.zeros(49))


def test_fill_range_image_is_numpys_assignment_of_rows_to_cells():
    from odometry.scan_lines import azimuth_columns

    rng = np.random.default_rng(11)
    points = rng.normal(size=(20000, 3)) * 20
    points[:5, :2] = [[1.0, 0.0], [-1.0, 0.0], [-1.0, -0.0], [0.0, 1.0], [0.0, -1.0]]  # the seam and the axes
    rings = rng.integers(0, 16, size=20000)
    expect = np.full((16, 900), -1, dtype=np.int64)
    expect[rings, azimuth_columns(points, 900)] = np.arange(20000)  # (repeated cells: the last row)
    np.testing.assert_array_equal(fill_range_image(rings, points, 16, 900), expect)


def test_consensus_votes_count_the_groups_with_an_offset_within_the_radius():
    rng = np.random.default_rng(7)
    # crowded offsets (a pole on many rings is many poles at one place), with empty groups among them
    sizes = rng.integers(0, 12, size=40)
    owner = np.repeat(np.arange(40), sizes)
    centres = rng.uniform(-1.5, 1.5, size=(8, 2))
    offsets = centres[rng.integers(0, 8, size=len(owner))] + rng.normal(scale=0.15, size=(len(owner), 2))
    offsets[::7, 0] = np.round(offsets[::7, 0], 1)  # ties in x
    order = np.lexsort((offsets[:, 0], owner))
    offsets, owner = offsets[order], owner[order]
    starts = np.searchsorted(owner, np.arange(41))
    groups = list(zip(starts[:-1], starts[1:], strict=True))
    expected = [sum(bool(np.any(np.hypot(*(offsets[s:e] - o).T) <= 0.25)) for s, e in groups) for o in offsets]
    np.testing.assert_array_equal(consensus_votes(offsets, starts, 0.25), expected)


def test_gathered_scatter_and_map_normal_verdicts_are_the_map_normals_numpy_expressions():
    """The map's compiled normals (``LocalMap.target``) are the PCA, plane tests and NCF spelled in numpy."""
    from odometry import local_map
    from odometry.ncf import DEFAULT_GAP_SIGNIFICANCE_Z, DEGENERATE_GAP, ncf_keep, normal_covariance_along_beams
    from odometry.normals import local_pca, symmetric_eigh_descending

    rng = np.random.default_rng(7)
    # ground rings seen from three places, a wall, a pole and scattered clutter: planes, lines and neither
    origins = np.repeat(np.array([[0.0, 0, 1.8], [0.4, 0, 1.8], [0.8, 0.1, 1.8]]), 1500, axis=0)
    az = rng.uniform(-np.pi, np.pi, 4500)
    ring = rng.integers(0, 8, 4500)
    r = 1.8 / np.tan(np.radians(4.0 + 1.33 * ring))
    ground = origins + np.column_stack([r * np.cos(az), r * np.sin(az), np.full(4500, -1.8)])
    wall = np.column_stack([np.full(800, 6.0), rng.uniform(-4, 4, 800), rng.uniform(0, 3, 800)])
    pole = np.column_stack([np.full(100, 3.0), np.full(100, 2.0), np.linspace(0, 3, 100)])
    clutter = rng.uniform(-8, 8, size=(300, 3))
    points = np.vstack([ground, wall, pole, clutter])
    points += rng.normal(scale=0.01, size=points.shape)
    from_ = np.vstack([origins, np.zeros((1200, 3)) + [0, 0, 1.8]])
    beams = points - from_
    beams /= np.linalg.norm(beams, axis=1, keepdims=True)
    elevations = local_map.beam_elevation_rad(beams)
    rows = rng.choice(len(points), 2000, replace=False)
    at = points[rows]
    k = 12
    _, nb = cKDTree(points).query(at, k=k)
    noise, max_curvature, c_tau = 0.01, 0.05, np.radians(1.5) ** 2

    mean, scatter, reach = gathered_scatter(points, nb, at)
    hood = points[nb]
    mean_np, scatter_np = neighbourhood_scatter(hood)
    np.testing.assert_array_equal(mean, mean_np)
    np.testing.assert_array_equal(scatter, scatter_np)
    np.testing.assert_array_equal(reach, np.linalg.norm(hood[:, -1] - at, axis=1))

    lam, V = symmetric_eigh_descending(scatter)
    normals, variance = map_normal_verdicts(
        points, beams, elevations, from_, nb, at, mean, lam, V, (local_map.MIN_PLANE_EXTENT_SIGMAS * noise) ** 2,
        max_curvature, local_map.MIN_ELEVATION_SPREAD_RAD, local_map.MIN_BASELINE_M, noise**2, DEGENERATE_GAP,
        DEFAULT_GAP_SIGNIFICANCE_Z * np.sqrt(2.0 / (k - 1)))
    est = local_pca(hood, query_points=at)
    valid = local_map.plane_normals_valid(est, noise, max_curvature)
    valid &= local_map.spans_two_scan_lines(nb, elevations, from_)
    assert 0.2 < valid.mean() < 0.95  # (both verdicts are tested)
    np.testing.assert_array_equal(np.isfinite(normals[:, 0]), valid)
    np.testing.assert_array_equal(normals[valid], est.normals[valid])
    np.testing.assert_array_equal(V, est.axes)  # (oriented in place as local_pca orients them)
    nc = normal_covariance_along_beams(hood, beams[nb], noise, pca=est)
    np.testing.assert_array_equal(variance, nc.max_variance_rad2)
    keep = ncf_keep(variance, c_tau)
    assert 0.05 < keep.mean() < 0.95


def test_rescrew_motion_is_undoing_one_screw_then_doing_another():
    rng = np.random.default_rng(11)
    p = rng.uniform(-50, 50, size=(400, 3))
    n = unit_rows(rng, 400)
    s = rng.uniform(0, 1, 400)
    xi_old = np.array([0.9, 0.05, 0.01, 0.002, -0.001, 0.03])
    xi_new = np.array([1.1, -0.02, 0.0, 0.0, 0.001, 0.025])
    p1, n1 = screw_motion(-xi_old, s, p, n)
    p2, n2 = screw_motion(xi_new, s, p1, n1)
    none = np.zeros((0, 4))
    old_scalars, new_scalars = np.empty((400, 4)), np.empty((400, 4))
    rescrew_motion(np.zeros(6), xi_old, s, p, n, none, old_scalars)  # (the scalars of xi_old)
    p3, n3 = rescrew_motion(xi_old, xi_new, s, p, n, none, none)
    np.testing.assert_array_equal(p3, p2)
    np.testing.assert_array_equal(n3, n2)
    # given the scalars of the old twist (the undo's), the same; the new twist's are handed back
    p4, n4 = rescrew_motion(xi_old, xi_new, s, p, n, old_scalars, new_scalars)
    np.testing.assert_array_equal(p4, p2)
    np.testing.assert_array_equal(n4, n2)
    phi = s * np.linalg.norm(xi_new[3:])
    np.testing.assert_allclose(new_scalars, np.stack([np.cos(phi), np.sin(phi), s * (1 - np.cos(phi)) / phi,
                                                      s * (phi - np.sin(phi)) / phi], axis=1), rtol=1e-9)
    # a zero old twist undoes nothing; a pure translation moves by s rho
    np.testing.assert_array_equal(rescrew_motion(np.zeros(6), xi_new, s, p, n, none, none)[0],
                                  screw_motion(xi_new, s, p, n)[0])
    shift = np.array([1.0, 2.0, 3.0, 0, 0, 0])
    np.testing.assert_allclose(rescrew_motion(np.zeros(6), shift, s, p, p[:0], none, none)[0],
                               p + s[:, None] * shift[:3])
