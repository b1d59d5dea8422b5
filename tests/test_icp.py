"""ICP pieces against constructed truth: estimation, rejectors, termination, de-skew, init, config."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import box_room, constant_velocity

from odometry.config import BL, NCF, SALO, SALO_MAP, ConfigError, config_from_dict, load_config, variant
from odometry.deskew import deskew, redeskew, screw_apply
from odometry.estimation import point_to_plane_step
from odometry.icp import NearestCache, Source, Target, converged, match, register
from odometry.kdtree import KDTree
from odometry.pipeline import Odometry, OdometryError
from odometry.rejectors import Matches, distance_rejector, trimmed_rejector
from odometry.voxels import voxel_centroids
from simlidar import se3
from simlidar.sensor import load_preset
from simlidar.sweep import SweepSimulator


def planes_cloud(rng, n=3000):
    """Points on three orthogonal planes (a corner) with their normals: fully constrained."""
    pts, nrm = [], []
    for axis in range(3):
        p = rng.uniform(-5, 5, (n, 3))
        p[:, axis] = 3.0
        normal = np.zeros(3)
        normal[axis] = -1.0
        pts.append(p)
        nrm.append(np.tile(normal, (n, 1)))
    return np.vstack(pts), np.vstack(nrm)


def test_point_to_plane_step_recovers_small_motion():
    rng = np.random.default_rng(0)
    q, n = planes_cloud(rng)
    T_true = se3.exp(np.array([0.05, -0.03, 0.02, 0.01, -0.02, 0.015]))
    src = se3.transform_points(se3.inverse(T_true), q)  # source = target moved by T^-1
    T = np.eye(4)
    for _ in range(5):  # matches by index: the exact correspondences
        step = point_to_plane_step(se3.transform_points(T, src), q, n)
        T = step.increment @ T
    assert np.abs(T - T_true).max() < 1e-9
    assert step.rank == 6


def test_point_to_plane_step_leaves_unconstrained_direction_alone():
    rng = np.random.default_rng(1)
    q = rng.uniform(-5, 5, (500, 3))
    q[:, 2] = 0.0  # one plane: x, y and yaw are unobservable
    n = np.tile([0.0, 0.0, 1.0], (500, 1))
    step = point_to_plane_step(q + [0.3, 0.2, 0.1], q, n)
    assert step.rank == 3
    assert np.allclose(step.xi[:2], 0.0, atol=1e-12)  # no motion invented along the plane
    assert step.xi[2] == pytest.approx(-0.1)


def test_reused_nearest_neighbours_are_the_searched_ones():
    """match() with a cache proves most neighbours from its last search; the answer equals a fresh search's."""
    rng = np.random.default_rng(4)
    cloud = rng.uniform(-20, 20, (20000, 3))
    tree = KDTree(cloud)
    target = Target(cloud, tree, np.zeros_like(cloud))
    cache = NearestCache()
    points = cloud[rng.choice(len(cloud), 3000)] + rng.normal(0, 0.3, (3000, 3))
    reused = 0
    for step in (0.0, 0.002, 0.002, 0.05, 0.002, 1.0, 0.0):  # ICP-sized steps, a jump, none
        points = points + rng.normal(0, step, points.shape)
        before = None if cache.points is None else cache.points.copy()
        got = match(points, target, 1.0, cache)
        dist, idx = tree.query(points, k=1, distance_upper_bound=1.0)
        found = np.flatnonzero(np.isfinite(dist))
        assert np.array_equal(got.source_index, found)
        assert np.array_equal(got.target_index, idx[found])
        assert np.array_equal(got.distance_m, dist[found])  # the same values, not merely close
        if before is not None:
            reused += int(np.all(cache.points == before, axis=1).sum())
    assert reused > 3000  # the millimetre steps kept most neighbours without a search
    match(points[:10], target, 1.0, cache)  # other query points or another bound: a new search
    assert len(cache.points) == 10
    match(points[:10], target, 2.0, cache)
    assert cache.bound_m == 2.0
    uncached = match(points, target, 1.0)  # without a cache: a plain search
    assert np.array_equal(uncached.source_index, found)


def test_rejectors():
    d = np.arange(100, dtype=float) / 10
    m = Matches(np.arange(100), np.arange(100), d)
    assert distance_rejector(5.0)(m, None).sum() == 50
    keep = trimmed_rejector(0.2)(m, None)
    assert keep.sum() == 80 and not keep[80:].any()


def test_the_chains_the_configs_make_are_recognised_and_no_other():
    from odometry.icp import rejectors_for
    from odometry.rejectors import geometric_rejector, standard_chain

    salo = standard_chain(rejectors_for(SALO))
    assert (salo.max_distance_m, salo.gcr, salo.trim_fraction) == (SALO.match.max_correspondence_distance_m, True,
                                                                    SALO.match.trim_fraction)
    assert salo.counted == (("distance", 0), ("gcr", 1), ("trimmed", 2))
    assert standard_chain(rejectors_for(BL.replace(match={"trim_fraction": 0.0}))).counted == (("distance", 0),)
    assert standard_chain([distance_rejector(1.0), trimmed_rejector(0.1)]).counted == (("distance", 0), ("trimmed", 2))
    for other in ([], [trimmed_rejector(0.2), distance_rejector(1.0)], [geometric_rejector()],
                  [distance_rejector(1.0), lambda m, s: m.distance_m < 0.5],
                  [distance_rejector(1.0), trimmed_rejector(0.2), geometric_rejector()]):
        assert standard_chain(other) is None


def test_termination():
    cfg = BL
    assert converged(np.array([1e-5, 0, 0, 0, 0, 0]), np.eye(4), cfg)
    assert not converged(np.array([1e-3, 0, 0, 0, 0, 0]), np.eye(4), cfg)
    T = np.eye(4)
    T[0, 3] = 20.0  # relative threshold: 1e-4 of a 20 m motion is 2 mm
    assert converged(np.array([1e-3, 0, 0, 0, 0, 0]), T, cfg)
    rng = np.random.default_rng(2)
    q, n = planes_cloud(rng)
    tgt = Target(q, KDTree(q), n)
    src = Source(se3.transform_points(se3.exp(np.array([0.2, 0, 0, 0, 0, 0.02])), q), -n)
    capped = register(src, tgt, np.eye(4), cfg.replace(icp={"max_iterations": 1}))
    assert capped.iterations == 1 and not capped.converged
    full = register(src, tgt, np.eye(4), cfg)
    assert full.converged and full.iterations < cfg.icp.max_iterations


def test_voxel_centroids():
    pts = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.2, 0.1, 0.1], [-0.1, 0.0, 0.0]])
    c, t = voxel_centroids(pts, 1.0, values=np.array([1.0, 3.0, 5.0, 7.0]))
    order = np.argsort(c[:, 0])
    assert np.allclose(c[order], [[-0.1, 0, 0], [0.2, 0.2, 0.2], [1.2, 0.1, 0.1]])
    assert np.allclose(t[order], [7.0, 2.0, 5.0])


def test_deskew_matches_simulator_truth():
    traj = constant_velocity(v=(12.0, 1.0, 0.0), yaw_rate=0.0)
    sensor = load_preset("vlp16").with_overrides(range_noise_std_m=0.0)
    scan = SweepSimulator(box_room(size=(80, 60, 10)), sensor).sweep(traj, 0.0)
    motion = se3.inverse(traj.pose_at(np.array([0.0]))[0]) @ traj.pose_at(np.array([0.1]))[0]
    fixed = deskew(scan.xyz, scan.time_s, motion, 0.1)
    assert np.abs(fixed - scan.true_xyz).max() < 1e-9
    assert np.abs(scan.xyz - scan.true_xyz).max() > 0.5
    # redeskew turns a de-skew with a wrong motion into the right one
    wrong = deskew(scan.xyz, scan.time_s, np.eye(4), 0.1)
    n = np.tile([1.0, 0, 0], (len(wrong), 1))
    p, n2 = redeskew(wrong, n, scan.time_s, np.eye(4), motion, 0.1)
    assert np.abs(p - scan.true_xyz).max() < 1e-9 and np.allclose(n2, n)


def test_constant_velocity_extrapolation_when_a_frame_is_empty():
    rng = np.random.default_rng(3)
    q, _ = planes_cloud(rng, 4000)
    odo = Odometry(BL.replace(filter={"normal_neighbours": 10}, clean={"min_range_m": 0.1}, deskew={"enabled": False}))
    step = se3.exp(np.array([0.3, 0.05, 0.0, 0.0, 0.0, 0.01]))
    poses = [np.eye(4), step, step @ step]
    for T in poses[:2]:
        odo.register(se3.transform_points(se3.inverse(T), q))
    assert np.abs(odo.poses[1] - step).max() < 2e-3
    pose = odo.register(q[:5])  # nothing to register: the pose is extrapolated
    assert odo.last.too_few_points and odo.last.extrapolated
    assert np.allclose(pose, odo.poses[1] @ (se3.inverse(odo.poses[0]) @ odo.poses[1]))
    nan_scan = se3.transform_points(se3.inverse(step @ step @ step), q)
    nan_scan[:100] = np.nan
    pose = odo.register(nan_scan)
    assert odo.last.points_nonfinite == 100 and not odo.last.extrapolated
    # registered against the last scan with points (two frames back), not the empty one
    assert np.abs(pose - step @ step @ step).max() < 5e-3


def test_gcr_without_sensor_is_a_clear_error():
    with pytest.raises(OdometryError, match="--sensor"):
        Odometry(SALO)
    Odometry(NCF.replace(ncf={"range_noise_std_m": 0.02}))  # the NCF alone can run without a sensor table


def test_config_validation_and_yaml(tmp_path):
    assert variant("bl").gcr.enabled is False and variant("ncf").ncf.enabled and variant("salo").gcr.enabled
    with pytest.raises(ConfigError, match="unknown odometry variant 'x'"):
        variant("x")

    def error(fn, *args, **kwargs) -> str:
        with pytest.raises(ConfigError) as err:
            fn(*args, **kwargs)
        assert isinstance(err.value, ValueError) and "\n" not in str(err.value)
        return str(err.value)

    salo = "odometry config 'salo': "
    assert error(SALO.replace, match={"trim_fraction": 1.5}) == (
        salo + "key 'match.trim_fraction' must be a number in [0, 1), got 1.5")
    assert error(SALO.replace, filter={"voxel_size_m": 0}) == (
        salo + "key 'filter.voxel_size_m' must be a number > 0 (m), got 0")
    assert error(SALO.replace, ncf={"noise_model": "gaussian"}) == (
        salo + "key 'ncf.noise_model' must be one of range, isotropic, got 'gaussian'")
    assert error(SALO.replace, map={"max_distance_m": 0}) == (
        salo + "key 'map.max_distance_m' must be a number > 0 (m) or null, got 0")
    assert error(SALO.replace, icp={"max_iterations": 0}) == (
        salo + "key 'icp.max_iterations' must be an integer >= 1, got 0")
    assert error(SALO.replace, clean={"min_range_m": 130.0}) == (
        salo + "key 'clean.min_range_m' must be < clean.max_range_m (130.0 >= 120.0)")
    assert error(SALO.replace, ncf={"applies_to": "map"}) == (
        salo + "key 'ncf.applies_to' 'map' needs match.target: map (there is no map to judge)")
    assert error(SALO.replace, gcr={"bogus": 1}).startswith(salo + "key 'gcr.bogus' is unknown (known: enabled,")
    # the flat keys of earlier versions name their new place
    for old, new in (("voxel_size_m", "filter.voxel_size_m"), ("match_target", "match.target"),
                     ("ncf_max_normal_std_deg", "ncf.max_normal_std_deg"), ("deskew_refinements", "deskew.refinements"),
                     ("map_voxel_size_m", "map.voxel_size_m"), ("min_points", "filter.min_points"),
                     ("gcr_noise_floor_m", "gcr.noise_floor_m"), ("rotation_scale_m", "degeneracy.rotation_scale_m")):
        assert error(config_from_dict, {old: 1}, origin="old.yaml") == (
            f"old.yaml: key '{old}' is unknown; did you mean '{new}'?")
    assert error(config_from_dict, {"ncf": False}, origin="old.yaml") == (
        "old.yaml: key 'ncf' must be a mapping of ncf keys, got bool; did you mean 'ncf.enabled'?")
    # sections overlay the base's: keys left out keep its values
    both = SALO_MAP.replace(name="x", gcr={"enabled": False}, match={"trim_fraction": 0.0})
    assert (both.name, both.gcr.enabled, both.gcr.formula, both.match.trim_fraction, both.match.target,
            both.ncf.applies_to) == ("x", False, "beam", 0.0, "map", "map")
    assert config_from_dict({"name": "ncf-map"}) == variant("ncf-map")  # the base: the variant named
    p = tmp_path / "c.yaml"
    p.write_text(NCF.replace(filter={"voxel_size_m": 0.7}).to_yaml())
    assert load_config(p) == NCF.replace(filter={"voxel_size_m": 0.7})
    assert "filter:\n  voxel_size_m: 0.7\n" in p.read_text()
    p.write_text("filter: {voxel_size_m: -1}\n")
    assert error(load_config, p) == f"{p}: key 'filter.voxel_size_m' must be a number > 0 (m), got -1"


def test_implausible_estimate_is_flagged_and_extrapolated():
    """An estimate farther from the constant-velocity prediction than the config allows
    (here 1 cm, while the platform accelerates by 20 cm per frame) is not trusted."""
    rng = np.random.default_rng(4)
    q, _ = planes_cloud(rng, 4000)
    cfg = BL.replace(filter={"normal_neighbours": 10}, clean={"min_range_m": 0.1}, deskew={"enabled": False},
                     icp={"max_prediction_error_m": 0.01})
    odo = Odometry(cfg)
    steps = [np.eye(4), se3.exp(np.r_[0.2, 0, 0, 0, 0, 0]), se3.exp(np.r_[0.4, 0, 0, 0, 0, 0])]
    pose = np.eye(4)
    for k, step in enumerate(steps):
        pose = pose @ step
        odo.register(se3.transform_points(se3.inverse(pose), q))
        if k == 1:
            assert not odo.last.implausible  # the first registration has no prediction to compare with
    assert odo.last.implausible and odo.last.extrapolated
    assert np.allclose(odo.poses[2], odo.poses[1] @ (se3.inverse(odo.poses[0]) @ odo.poses[1]))
    loose = Odometry(cfg.replace(icp={"max_prediction_error_m": 1.0}))
    pose = np.eye(4)
    for step in steps:
        pose = pose @ step
        loose.register(se3.transform_points(se3.inverse(pose), q))
    assert not loose.last.implausible and np.abs(loose.poses[2] - pose).max() < 5e-3


@pytest.mark.parametrize("target", ["filtered", "map"])
def test_every_match_target_tracks_a_known_motion(target):
    """A corner of three planes, seen from a sensor that moves and turns: the previous filtered scan and
    the local map both recover the path."""
    rng = np.random.default_rng(5)
    q, _ = planes_cloud(rng, 4000)
    q += rng.normal(0.0, 0.002, q.shape)
    cfg = BL.replace(filter={"normal_neighbours": 10}, clean={"min_range_m": 0.1}, deskew={"enabled": False},
                     match={"target": target}, map={"voxel_size_m": 0.5})
    odo = Odometry(cfg)
    step = se3.exp(np.array([0.15, 0.03, 0.01, 0.0, 0.002, 0.01]))
    pose = np.eye(4)
    for k in range(8):
        odo.register(se3.transform_points(se3.inverse(pose), q))
        assert not odo.last.extrapolated, (target, k)
        err = se3.inverse(pose) @ odo.poses[-1]
        assert np.linalg.norm(err[:3, 3]) < 5e-3 and np.degrees(se3.rotation_angle(err)) < 0.05, (target, k)
        pose = pose @ step
    if target == "map":
        assert len(odo.state.local_map) > 0 and "plane" in odo.last.matches


def test_redeskew_points_alone_match_points_with_normals():
    """``redeskew`` without normals moves the points exactly as with them (the normals share its terms)."""
    rng = np.random.default_rng(3)
    p = rng.uniform(-30, 30, size=(200, 3))
    n = rng.normal(size=(200, 3))
    t = rng.uniform(0.0, 0.1, size=200)
    old, new = se3.exp(np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.02])), se3.exp(np.array([0.7, 0.1, 0.0, 0.0, 0.01, 0.03]))
    p_both, n_both = redeskew(p, n, t, old, new, 0.1)
    p_alone, none = redeskew(p, None, t, old, new, 0.1)
    assert none is None
    np.testing.assert_array_equal(p_both, p_alone)
    s = t / 0.1
    np.testing.assert_array_equal(n_both, screw_apply(se3.log(new), s, screw_apply(-se3.log(old), s, n, True), True))


def test_redeskew_with_a_memo_of_the_last_one_gives_the_same_points():
    """A chain of re-de-skews (as the joint de-skew makes, one per ICP step) with the memo, which spares
    each undo its trigonometry, moves the points exactly as without; a memo of other times or another
    twist is not used."""
    from odometry.deskew import RedeskewMemo

    rng = np.random.default_rng(4)
    p = rng.uniform(-30, 30, size=(300, 3))
    n = rng.normal(size=(300, 3))
    t = rng.uniform(0.0, 0.1, size=300)
    twists = [np.zeros(6)] + [np.array([0.8, 0.05, 0.01, 0.0, 0.003, 0.02]) * (1 + 0.01 * k) for k in range(4)]
    memo = RedeskewMemo()
    plain, memoed = (p, n), (p, n)
    for old, new in zip(twists, twists[1:], strict=False):
        plain = redeskew(*plain, t, old, new, 0.1)
        memoed = redeskew(*memoed, t, old, new, 0.1, memo)
        for a, b in zip(plain, memoed, strict=True):
            np.testing.assert_array_equal(a, b)
    assert np.array_equal(memo.twist, twists[-1]) and memo.scalars.shape == (300, 4)
    # the memo is what the undo takes: scalars spoiled behind its back change the points
    spoiled = RedeskewMemo(memo.twist, memo.fractions, memo.scalars * 1.01)
    nxt = twists[-1] * 1.01
    assert not np.array_equal(redeskew(memoed[0], None, t, twists[-1], nxt, 0.1, spoiled)[0],
                              redeskew(memoed[0], None, t, twists[-1], nxt, 0.1)[0])
    kept = memo.scalars
    moved, _ = redeskew(p, None, t[::-1].copy(), twists[-1], twists[1], 0.1, memo)  # other times: computed anew
    np.testing.assert_array_equal(moved, redeskew(p, None, t[::-1].copy(), twists[-1], twists[1], 0.1)[0])
    assert memo.scalars is not kept


@pytest.mark.parametrize("angle", [0.0, 1e-13, 1e-7, 1e-3, 0.5, 2.0, np.pi - 1e-7])
def test_se3_of_one_transform_agrees_with_the_batched_scipy_path(angle):
    """exp and log of a single (4, 4) / (6,) take a path of their own (no scipy Rotation call overhead):
    they agree with the batched path, which goes through scipy, at every rotation angle."""
    rng = np.random.default_rng(int(angle * 1000))
    for _ in range(50):
        axis = rng.normal(size=3)
        xi = np.r_[rng.normal(size=3) * 3.0, axis / np.linalg.norm(axis) * angle]
        T = se3.exp(xi)
        np.testing.assert_allclose(T, se3.exp(xi[None])[0], rtol=0, atol=1e-14)
        np.testing.assert_allclose(se3.log(T), se3.log(T[None])[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(se3.log(T), xi, rtol=0, atol=1e-9)
