"""The local map of scan-to-map registration and the degeneracy handling, against constructed truth."""

from __future__ import annotations

import numpy as np
import pytest

from odometry.constraints import remapped_step, restore_constraints
from odometry.icp import match
from odometry.local_map import (
    MIN_BASELINE_M,
    MIN_ELEVATION_SPREAD_RAD,
    LocalMap,
    rank_within_groups,
    spans_two_scan_lines,
)
from odometry.voxels import voxel_keys
from simlidar import se3


def make_map(**kw) -> LocalMap:
    args = {"voxel_size_m": 1.0, "max_points_per_voxel": 20, "max_distance_m": 100.0, "normal_neighbours": 12,
            "noise_std_m": 0.02, "max_curvature": 0.05, "prune_stride_m": 0.0}
    return LocalMap(**{**args, **kw})


def test_rank_within_groups():
    assert rank_within_groups(np.array([3, 3, 5, 7, 7, 7])).tolist() == [0, 1, 0, 0, 1, 2]
    assert len(rank_within_groups(np.zeros(0, dtype=np.int64))) == 0


def test_voxel_keys_distinguish_neighbours_and_refuse_the_far_away():
    p = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.5, -0.5, 0.5], [0.5, 0.5, -0.5], [0.9, 0.1, 0.2]])
    k = voxel_keys(p, 1.0)
    assert len(set(k[:4].tolist())) == 4 and k[4] == k[0]
    with pytest.raises(ValueError, match="cannot be put"):
        voxel_keys(np.array([[2e6, 0.0, 0.0]]), 1.0)


def test_map_caps_each_voxel_and_drops_far_points():
    rng = np.random.default_rng(0)
    m = make_map(max_points_per_voxel=5, max_distance_m=10.0)
    in_one_voxel = rng.uniform(0.0, 1.0, (40, 3))
    stats = m.update(in_one_voxel, np.zeros(3))
    assert stats.added == 5 and len(m) == 5 and stats.voxels == 1
    assert np.array_equal(m.points, in_one_voxel[:5])  # the first come stay (a stable map)
    assert m.update(0.98 * in_one_voxel + 0.01, np.zeros(3)).added == 0  # full: nothing more
    far = rng.uniform(0.0, 1.0, (3, 3)) + [20.0, 0.0, 0.0]
    m.update(far, np.array([20.0, 0.0, 0.0]))  # the sensor moved: the first voxel is now 20 m behind
    assert len(m) == 3 and np.all(m.points[:, 0] >= 20.0)
    assert m.update(in_one_voxel, np.zeros(3)).added == 5  # the dropped voxel takes points again


def test_map_arrays_grow_in_place_and_earlier_targets_keep_their_rows():
    """Updates append to the per-point arrays without rewriting them (``LocalMap._append``): a target
    taken before an update still holds the points and normals it had, through growth and a pruning."""
    rng = np.random.default_rng(8)
    m = make_map(max_distance_m=30.0, prune_stride_m=5.0)
    plane = np.c_[rng.uniform(-8, 8, (3000, 2)), np.zeros(3000)]
    m.update(plane, np.array([0.0, 0.0, 2.0]))
    before = m.target()
    points, rows = before.points.copy(), np.arange(0, len(before.points), 7)
    normals = before.normals_at(rows).copy()
    dropped = 0
    for step in range(1, 6):  # several updates: past the first buffer's room, and a pruning
        shift = np.array([5.0 * step, 0.0, 0.0])
        stats = m.update(plane + shift + [0.0, 0.0, 0.001 * step], shift + [0.0, 0.0, 2.0])
        assert stats.added > 0
        dropped += stats.dropped
        assert len(m._beams) == len(m._origins) == len(m._normals) == len(m._known) == len(m) == len(m._keys)
    assert dropped > 0  # (the first plane's far end, over 30 m behind, went)
    np.testing.assert_array_equal(before.points, points)
    np.testing.assert_array_equal(before.normals.take(rows, axis=0), normals)
    assert np.isfinite(normals).all() and np.abs(normals[:, 2]).min() > 0.99
    # the map as it stands holds what a map built at once from its points holds (in voxel order), and
    # its normals are theirs (up to sign: the sensor positions differ)
    fresh = make_map(max_distance_m=30.0)
    fresh.update(m.points, np.array([25.0, 0.0, 2.0]))
    mine, theirs = np.lexsort(m.points.T), np.lexsort(fresh.points.T)
    np.testing.assert_array_equal(m.points[mine], fresh.points[theirs])
    a = m.target().normals_at(mine)
    b = fresh.target().normals_at(theirs)
    both = np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
    assert both.mean() > 0.9
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", a[both], b[both])), 1.0, atol=1e-9)


def test_map_min_spacing_keeps_the_first_observation_of_a_surface():
    """With ``min_spacing_m``, a point closer than that to a map point is not added, one farther is,
    whatever room its voxel has; payloads stay with the points that were added."""
    rng = np.random.default_rng(5)
    grid = np.stack(np.meshgrid(np.arange(0.0, 6.0, 0.5), np.arange(0.0, 6.0, 0.5), [0.0]), -1).reshape(-1, 3)
    above = np.array([0.0, 0.0, 2.0])  # the sensor, off the surface
    m = make_map(min_spacing_m=0.2)
    assert m.update(grid, above, payload=np.arange(len(grid))).added == len(grid)
    # the same surface seen again, each point moved by less than the spacing: nothing new
    jitter = rng.normal(size=grid.shape)
    jitter *= 0.15 / np.linalg.norm(jitter, axis=1, keepdims=True)
    assert m.update(grid + jitter, above, payload=np.arange(len(grid))).added == 0
    # points half-way between the grid's (0.25 m from the nearest) are new
    between = grid + [0.25, 0.0, 0.0]
    stats = m.update(between, above, payload=1000 + np.arange(len(grid)))
    assert stats.added == len(grid) and len(m) == 2 * len(grid)
    assert np.array_equal(m.points[m.payload >= 1000], between[m.payload[m.payload >= 1000] - 1000])
    # without a spacing every point goes in while its voxel has room
    plain = make_map()
    plain.update(grid, above)
    assert plain.update(grid + jitter, above).added == len(grid)


def test_map_spacing_check_takes_the_distances_a_caller_knows():
    """``update(nearest_m=...)``: the spacing check uses the given distances (the odometry passes its
    last nearest-neighbour search, ``icp.match`` on the final points) and then agrees with its own search."""
    rng = np.random.default_rng(12)
    first = rng.uniform(0.0, 8.0, size=(3000, 3)) * [1.0, 1.0, 0.1]
    later = first + rng.normal(scale=0.25, size=first.shape)
    above = np.array([4.0, 4.0, 3.0])
    searched, given = make_map(min_spacing_m=0.3), make_map(min_spacing_m=0.3)
    searched.update(first, above)
    given.update(first, above)
    target = given.target()
    m = match(later, target, 1.0)
    nearest = np.full(len(later), np.inf)
    nearest[m.source_index] = m.distance_m
    stats = given.update(later, above, nearest_m=nearest)
    assert stats == searched.update(later, above) and 0 < stats.added < len(later)
    np.testing.assert_array_equal(given.points, searched.points)
    with pytest.raises(ValueError):
        given.update(later, above, nearest_m=nearest[:-1])
    # the given distances are what decides: the same points again, said to be far, go in where room is
    few = first[:200]  # (voxels with room)
    again = make_map(min_spacing_m=0.3)
    again.update(few, above)
    assert again.update(few, above).added == 0
    assert again.update(few, above, nearest_m=np.full(len(few), np.inf)).added == len(few)


def test_map_payload_follows_its_points_through_caps_and_pruning():
    """Each map point keeps the payload given with it: points arrive out of voxel order, full voxels
    refuse some, and a far voxel is dropped."""
    rng = np.random.default_rng(3)
    m = make_map(max_points_per_voxel=3, max_distance_m=10.0)
    first = rng.uniform(-4.0, 4.0, (200, 3))  # about 2.5 points per voxel, in no particular order
    m.update(first, np.zeros(3), payload=np.arange(200))
    second = rng.uniform(-4.0, 8.0, (300, 3))
    stats = m.update(second, np.array([3.0, 0.0, 0.0]), payload=200 + np.arange(300))
    assert stats.dropped > 0 and 0 < stats.added < 300  # both the caps and the pruning acted
    everything = np.vstack([first, second])
    assert m.payload.shape == (len(m),) and len(np.unique(m.payload)) == len(m)
    assert np.array_equal(m.points, everything[m.payload])  # row for row
    with pytest.raises(ValueError, match="every update"):
        m.update(first[:3], np.zeros(3))
    with pytest.raises(ValueError, match=r"payload must be \(3,\)"):
        m.update(first[:3], np.zeros(3), payload=np.arange(4))
    plain = make_map()
    plain.update(first, np.zeros(3))
    assert plain.payload is None
    with pytest.raises(ValueError, match="first update"):
        plain.update(first, np.zeros(3), payload=np.arange(200))


def test_map_normals_on_a_plane_but_not_on_a_single_ring():
    """A noisy plane seen from several positions gives its normal; points of one line do not define a plane."""
    rng = np.random.default_rng(1)
    n_true = np.array([0.0, np.sin(0.2), np.cos(0.2)])  # a slope of 11 deg
    u = np.cross(n_true, [1.0, 0.0, 0.0])
    uv = rng.uniform(-5, 5, (4000, 2))
    plane = uv[:, :1] * [[1.0, 0.0, 0.0]] + uv[:, 1:] * u + rng.normal(0, 0.02, (4000, 1)) * n_true
    line = np.column_stack([np.linspace(0, 4, 200), np.full(200, 30.0), np.zeros(200)])
    line += rng.normal(0, 0.02, line.shape) * [0.0, 1.0, 0.0]  # range noise across the line only
    m = make_map()
    m.update(np.vstack([plane, line]), np.zeros(3))
    target = m.target()
    q = np.array([[0.3, 0.0, 0.0], [-2.0, 1.0, 0.5], [2.0, 30.0, 0.0]])
    q[:2] = q[:2, :1] * [1.0, 0.0, 0.0] + q[:2, 1:2] * u
    found = match(q, target, 1.0)
    assert len(found) == 3
    n = target.normals_at(found.target_index)
    angles = np.degrees(np.arccos(np.clip(np.abs(n[:2] @ n_true), 0, 1)))
    assert np.all(angles < 2.0), angles
    assert np.isnan(n[2]).all()  # the line: no plane
    # the estimate is cached in the map until points arrive nearby
    assert m._known[found.target_index].all()
    m.update(plane[:5] + 0.001, np.zeros(3))  # nothing added (voxels full) ...
    assert m._known[found.target_index[:2]].all()


def test_two_scan_lines_are_two_rings_or_one_ring_seen_from_two_places():
    """Neighbourhoods of one ring from one place are one scan line; another ring or a far origin makes two."""
    elevations = np.array([0.0, 0.0, 0.5 * MIN_ELEVATION_SPREAD_RAD, 2.0 * MIN_ELEVATION_SPREAD_RAD])
    origins = np.array([[0.0, 0.0, 0.0], [0.5 * MIN_BASELINE_M, 0.0, 0.0], [0.0, 0.0, 0.0],
                        [0.0, 2.0 * MIN_BASELINE_M, 0.0]])
    neighbours = np.array([
        [0, 2, 0],  # one ring (elevations within the spread), origins within the baseline
        [0, 1, 2],  # the same
        [0, 3, 0],  # two rings
        [0, 0, 3],  # two rings, and two places
        [2, 2, 3],  # two rings
    ])
    assert spans_two_scan_lines(neighbours, elevations, origins).tolist() == [False, False, True, True, True]
    # one ring from two places: the same elevation, origins farther apart than the baseline
    elevations[3] = 0.0
    assert spans_two_scan_lines(neighbours, elevations, origins).tolist() == [False, False, True, True, True]
    origins[3] = [0.0, 0.5 * MIN_BASELINE_M, 0.0]
    assert spans_two_scan_lines(neighbours, elevations, origins).tolist() == [False, False, False, False, False]


def test_remapped_step_keeps_the_prior_along_a_weak_direction():
    """A corridor: walls (normals +-y) and floor (z) constrain y, z and rotations; 1 % of the points
    see the corridor's end (normal x). With the threshold above that share, x stays at the prior."""
    rng = np.random.default_rng(2)
    n = 3000
    walls = np.column_stack([rng.uniform(-20, 20, n), np.where(rng.random(n) < 0.5, -3.0, 3.0),
                             rng.uniform(0, 4, n)])
    floor = np.column_stack([rng.uniform(-20, 20, n), rng.uniform(-3, 3, n), np.zeros(n)])
    end = np.column_stack([np.full(60, 25.0), rng.uniform(-3, 3, 60), rng.uniform(0, 4, 60)])
    points = np.vstack([walls, floor, end])
    normals = np.vstack([np.column_stack([np.zeros(n), -np.sign(walls[:, 1]), np.zeros(n)]),
                         np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([-1.0, 0.0, 0.0], (60, 1))])
    truth = np.array([0.05, -0.02, 0.01, 0.001, -0.002, 0.003])
    # residuals of the linearised problem for the motion 'truth': r = -J truth
    J = np.hstack([normals, np.cross(points, normals)])
    r = -J @ truth
    H, g = J.T @ J, J.T @ r
    full = remapped_step(H, g, len(r), rotation_scale_m=10.0)
    assert np.allclose(full.xi, truth, atol=1e-9) and full.remapped == 0
    weak_share = 60 / len(r)  # the end wall's share of x information
    kept = remapped_step(H, g, len(r), rotation_scale_m=10.0, min_eigenvalue=2 * weak_share)
    assert kept.remapped == 1
    assert abs(kept.xi[0]) < 1e-3  # x: left at the prior (no update)
    assert np.allclose(kept.xi[1:], truth[1:], atol=2e-3)  # the rest solved


def test_restore_constraints_gives_back_the_only_evidence_of_a_direction():
    rng = np.random.default_rng(3)
    n = 2000
    points = rng.uniform(-10, 10, (n, 3))
    normals = np.zeros((n, 3))
    normals[: n // 2, 1] = 1.0
    normals[n // 2: n - 40, 2] = 1.0
    normals[n - 40:, 0] = 1.0  # 40 points alone constrain x
    candidates = np.ones(n, dtype=bool)
    kept = rng.random(n) < 0.5
    kept[n - 40:] = False  # the filter rejected every one of them
    out = restore_constraints(points, normals, candidates, kept, min_eigenvalue=0.01, rotation_scale_m=10.0)
    assert np.array_equal(out[:n - 40], kept[:n - 40])  # nothing else is touched
    restored = out[n - 40:].sum()
    assert restored == 20  # 20 of 2000 points are exactly the 0.01 needed, no more
    assert restore_constraints(points, normals, candidates, kept, 0.0, 10.0).sum() == kept.sum()


def test_orthonormalize_stops_rounding_feedback():
    """pose_k = pose_{k-1} (pose_{k-1}^-1 estimate): with transpose-inverses the rotation's error doubles
    every step unless it is projected back onto SO(3)."""
    M = se3.exp(np.array([1.0, 0.1, 0.0, 0.001, 0.002, 0.03]))  # the motion per frame
    start = se3.exp(np.array([5.0, 2.0, 0.0, 0.0, 0.0, 1.0]))
    start[:3, :3] *= 1 + 1e-15
    drifting, fixed = start.copy(), start.copy()
    for _ in range(24):  # the estimate is prev @ M; the motion is prev^-1 @ estimate; the pose prev @ motion
        drifting = drifting @ (se3.inverse(drifting) @ (drifting @ M))
        fixed = se3.orthonormalize(fixed @ (se3.inverse(fixed) @ (fixed @ M)))
    def err(A):
        return np.abs(A[:3, :3] @ A[:3, :3].T - np.eye(3)).max()
    assert err(drifting) > 1e-6 and err(fixed) < 1e-12


def test_prior_step_blends_data_and_prior_by_their_information():
    """With a motion prior of information lambda per match, a direction of information w ends at
    w / (w + lambda) of the data's answer (from a deviation of zero), and a strong one at the data's."""
    rng = np.random.default_rng(4)
    n = 3000
    normals = np.zeros((n, 3))
    normals[:1470, 1] = 1.0
    normals[1470:2940, 2] = 1.0
    normals[2940:, 0] = 1.0  # 2 % of the matches see x
    points = rng.uniform(-10, 10, (n, 3))
    truth = np.array([0.05, -0.02, 0.01, 0.0, 0.0, 0.0])
    J = np.hstack([normals, np.cross(points, normals)])
    r = -J @ truth
    H, g = J.T @ J, J.T @ r
    lam = 0.02
    s = remapped_step(H, g, n, rotation_scale_m=10.0, min_eigenvalue=lam, mode="prior", deviation=np.zeros(6))
    w_x = 60 / n
    assert s.xi[0] == pytest.approx(truth[0] * w_x / (w_x + lam), rel=0.05)
    assert np.allclose(s.xi[1:3], truth[1:3], rtol=0.1)  # y, z: information 0.49 >> lambda
    # already off the prior by +3 cm in x: the prior pulls back, the data push on
    s2 = remapped_step(H, g, n, 10.0, lam, mode="prior", deviation=np.array([0.03, 0, 0, 0, 0, 0]))
    assert s2.xi[0] == pytest.approx((w_x * truth[0] - lam * 0.03) / (w_x + lam), rel=0.05)


def test_map_keeps_a_cached_normal_exactly_while_its_neighbourhood_stands():
    """After points arrive and far ones are dropped, every normal the map still holds equals one
    estimated afresh from the map as it is now, and a useful share of them is still held."""
    rng = np.random.default_rng(7)
    m = make_map(max_distance_m=9.0, max_points_per_voxel=8, min_spacing_m=0.1)

    def surface_seen_from(x0: float) -> np.ndarray:  # rolling ground ahead of a sensor at (x0, 0, 2)
        xy = rng.uniform([x0 - 6.0, -6.0], [x0 + 6.0, 6.0], (1500, 2))
        z = 0.3 * np.sin(0.7 * xy[:, 0]) + 0.2 * np.cos(0.5 * xy[:, 1]) + rng.normal(0, 0.02, len(xy))
        return np.column_stack([xy, z])

    held, gone = 0, 0  # normals kept across an update; forgotten, or pruned with their point
    for step in range(8):
        sensor = np.array([1.5 * step, 0.0, 2.0])
        if not m.empty:
            before = m._known.copy()
        m.update(surface_seen_from(sensor[0]), sensor)
        target = m.target()
        rows = np.flatnonzero(m._known)
        if step:
            held, gone = held + len(rows), gone + int(before.sum()) - len(rows)
        if len(rows):
            fresh, _ = target.estimate_normals(rows)
            np.testing.assert_array_equal(target.normals[rows], fresh)
        asked = rng.choice(len(m), 600, replace=False)  # the matches of the next registration
        target.normals_at(asked)
    assert held > 1000 and gone > 100, (held, gone)
