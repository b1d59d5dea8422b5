"""Poles (odometry/poles.py) against the truth the simulator knows: which returns are poles, where they
are, and what they give the odometry along a corridor that the planes leave unconstrained."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from odometry.config import DEFAULT_VARIANT, variant
from odometry.kernels.poles import foreground_runs
from odometry.pipeline import run_sequence
from odometry.poles import (
    CLUTTERED_PER_BEAM,
    LEAVE_PER_BEAM,
    PoleMap,
    PoleTarget,
    WeatherGate,
    alone_within_the_clutter,
    crowded,
    extract_poles,
    pole_rows,
    pole_translation,
)
from simlidar.in_memory import simulate_in_memory
from simlidar.sensor import load_preset
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.world import World
from tests.helpers import constant_velocity

POST_SPACING_M = 4.0
POST_Y_M = 6.0


def corridor(with_car: bool = True) -> World:
    """A straight road between two long walls (y = +-10 m), guard-rail posts (12 x 10 x 90 cm) every 4 m in
    front of both, and a parked car (4.2 m long): the planes constrain every direction but along x."""
    parts: list[tuple[trimesh.Trimesh, str]] = []

    def box(size, centre, label):
        b = trimesh.creation.box(size)
        b.apply_translation(centre)
        parts.append((b, label))

    box((600.0, 60.0, 1.0), (0.0, 0.0, -0.5), "ground")
    for side in (-1, 1):
        box((600.0, 0.5, 3.0), (0.0, side * 10.0, 1.5), "wall")
        for x in np.arange(-280.0, 280.0, POST_SPACING_M):
            box((0.12, 0.1, 0.9), (x, side * POST_Y_M, 0.45), "pole")
    if with_car:
        box((4.2, 1.8, 1.5), (14.0, -3.0, 0.75), "car")
    mesh = trimesh.util.concatenate([p for p, _ in parts])
    object_of_face = np.concatenate([np.full(len(p.faces), i) for i, (p, _) in enumerate(parts)])
    return World(mesh.vertices, mesh.faces, object_of_face, [label for _, label in parts], source="corridor")


def one_scan(world, sensor, x=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, 0.0, 1.9)
    return SweepSimulator(world, sensor, seed=3, motion_distortion=False, threads=2).sweep(
        SampledTrajectory(np.array([0.0]), T[None]), 0.0)


@pytest.mark.parametrize("preset", ["vlp16", "hdl32e"])
def test_poles_are_the_posts_and_nothing_else(preset):
    """Every pole found is a post, within a few centimetres of it horizontally; the car (4.2 m), the
    walls, the ground give none; most posts within 20 m are found."""
    world = corridor()
    sensor = load_preset(preset)
    scan = one_scan(world, sensor)
    poles = extract_poles(scan.xyz, scan.ring, sensor.rings, sensor.columns_per_sweep, 0.6)
    assert len(poles) > 10
    labels = np.asarray(world.object_labels)
    # the object of each pole's nearest return: a post
    nearest = np.argmin(np.linalg.norm(scan.xyz[None, :, :] - poles.points[:, None, :], axis=2), axis=1)
    assert set(labels[scan.object_id[nearest]]) == {"pole"}
    # horizontally within 12 cm of a post's centre: the returns lie on the faces it turns to the sensor, up
    # to half its diagonal (7.8 cm) from the centre, and the range noise (VLP-16: 3 cm) moves them along the beam
    post_x = np.round(poles.points[:, 0] / POST_SPACING_M) * POST_SPACING_M
    post_y = np.sign(poles.points[:, 1]) * POST_Y_M
    assert np.all(np.hypot(poles.points[:, 0] - post_x, poles.points[:, 1] - post_y) < 0.12)
    # most posts within 20 m, on both sides, are seen as poles
    near_posts = {(x, s) for x in np.arange(-16.0, 17.0, POST_SPACING_M) for s in (-1.0, 1.0)
                  if math.hypot(x, POST_Y_M) < 20.0}
    found = {(float(x), float(s)) for x, s in zip(post_x, np.sign(poles.points[:, 1]), strict=True)}
    assert len(near_posts & found) >= 0.75 * len(near_posts), (len(near_posts & found), len(near_posts))


def test_foreground_runs_of_a_ring():
    """One ring of 40 columns at 10 m: two returns at 5 m form a pole; twelve at 5 m are too wide; a run
    beside a missing return is not judged; at the sweep's seam neither."""
    n = 40
    step = 2 * math.pi / n
    ranges = np.full(n, 10.0)
    ranges[8:10] = 5.0  # narrow: 2 x 5 m x 9 deg = 1.6 m (with max width 2 m)
    ranges[20:32] = 5.0  # wide: 12 columns
    ranges[35] = 5.0  # next to a missing column (37 and 38 missing below)
    ranges[0] = 5.0  # at the seam
    az = -math.pi + (np.arange(n) + 0.5) * step
    points = np.column_stack([ranges * np.cos(az), ranges * np.sin(az), np.zeros(n)])
    image = np.arange(n, dtype=np.int64)[None, :].copy()
    image[0, 36:39] = -1
    times = np.arange(n, dtype=float)
    centroids, counts, mean_times = foreground_runs(image, points, times, step, 2.0, 0.5, 0.1, 0.15, 0.02, 2)
    assert counts.tolist() == [2]
    np.testing.assert_allclose(mean_times, [8.5])
    np.testing.assert_allclose(centroids[0], points[8:10].mean(axis=0))


def test_pole_translation_takes_the_offset_most_poles_agree_on():
    """Four posts 4 m apart on each side, seen again from 1.5 m or 2.5 m farther on; the target sees one
    post more at each end. An offset of 1.5 m is found; 2.5 m fits the posts exactly as well as -1.5 m
    (one spacing less) and the smaller is taken, unless other objects (signs) say otherwise. With one
    post of the true offset's missing from the target (occluded), the alias one spacing off has one vote
    more (8 against 7): still the smaller, true, offset is taken."""
    def posts(xs):
        return np.array([(x, s * POST_Y_M, 0.3) for x in xs for s in (-1, 1)])

    target_posts, seen = posts(np.arange(-4.0, 17.0, POST_SPACING_M)), np.arange(0.0, 13.0, POST_SPACING_M)
    signs = np.array([(7.3, 9.0, 2.0), (-1.1, -8.5, 2.5), (3.7, -9.4, 1.0), (10.2, 9.1, 2.2)])
    for offset, with_signs, expected in ((1.5, False, 1.5), (2.5, False, -1.5), (2.5, True, 2.5)):
        target = np.vstack([target_posts, signs]) if with_signs else target_posts
        source = np.vstack([posts(seen), signs]) if with_signs else posts(seen)
        got = pole_translation(source - (offset, 0.0, 0.0), PoleTarget.of(target), 3.0)
        np.testing.assert_allclose(got, (expected, 0.0, 0.0), atol=1e-9, err_msg=f"{offset}, {with_signs}")
    occluded = target_posts[~np.all(np.isclose(target_posts[:, :2], (12.0, POST_Y_M)), axis=1)]
    got = pole_translation(posts(seen) - (1.5, 0.0, 0.0), PoleTarget.of(occluded), 3.0)
    np.testing.assert_allclose(got, (1.5, 0.0, 0.0), atol=1e-9)
    assert pole_translation(posts([0.0]), PoleTarget.of(target_posts), 3.0) is None  # too few to agree


def test_pole_rows_are_the_horizontal_distance_and_the_map_keeps_recent_frames():
    target = PoleTarget.of(np.array([[5.0, 6.0, 0.2], [9.0, 6.0, 0.5]]))
    moved = np.array([[5.1, 5.95, 0.9], [20.0, 0.0, 0.0]])  # the second has no pole within the bound
    src, tgt, normals = pole_rows(moved, target, 1.0)
    residuals = np.einsum("ij,ij->i", normals, src - tgt)
    np.testing.assert_allclose(residuals, [0.1, -0.05])  # x then y; the heights do not count
    pole_map = PoleMap(frames_kept=2)
    for k in range(3):
        pole_map.add(np.array([[float(k), 0.0, 0.0]]))
    assert len(pole_map) == 2
    T = np.eye(4)
    T[0, 3] = -1.0
    np.testing.assert_allclose(pole_map.target(T).points[:, 0], [0.0, 1.0])  # frames 1 and 2, moved


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["real", "simulated"])
def test_poles_pin_the_direction_along_a_corridor(kind):
    """A corridor whose planes constrain everything but the direction of travel, driven at 15 m/s from the
    first frame (HDL-32E, 2 cm noise), as real data and as simulated (motion distortion, per-point times:
    the poles are de-skewed with the scan). Against the map, with the posts as poles, the default
    configuration ends within 15 cm of the truth after 15 frames (21 m; measured 3 cm either way, 87
    pole matches a frame); without them it stays where it started (21.0 m short: the walls' and the
    ground's sampling patterns fit standing still; scan-to-scan BL and SALO end 12 m short)."""
    world = corridor()
    sensor = load_preset("hdl32e")
    traj = constant_velocity(v=(15.0, 0.0, 0.0), start=(-30.0, 0.0, 1.9), duration=3.0, n=61)
    seq = simulate_in_memory(world, traj, sensor, 15, seed=4, fields=kind)
    gt = seq.poses
    travelled = np.linalg.norm(gt[-1, :3, 3] - gt[0, :3, 3])
    assert travelled > 20.0
    errors = {}
    for name, config in (("poles", variant(DEFAULT_VARIANT)),
                         ("without", variant(DEFAULT_VARIANT).replace(poles={"enabled": False}))):
        run = run_sequence(seq, config)
        errors[name] = float(np.linalg.norm(run.poses[-1, :3, 3] - gt[-1, :3, 3]))
        if name == "poles":  # every registration, the de-skew refinements' too, had the poles
            assert min(d.matches.get("poles", 0) for d in run.diagnostics[1:]) > 20
    assert errors["poles"] < 0.15, errors
    assert errors["without"] > 0.5 * travelled, errors


# ---------------------------------------------------------------- weather clutter
def _labelled_poles(condition: str, family: str, seed: int, clutter_filter: bool):
    """One scan of a weather-suite sequence: its poles and, per pole, whether its nearest return is a weather
    return in the truth (fog's backscatter, a raindrop, a snowflake) rather than a surface's."""
    from scipy.spatial import KDTree

    from tools.family_suite import suite_world, weather_suite

    (spec,) = weather_suite((seed,), 200, (family,), (condition,))
    world, trajectory, sensor, start_s = suite_world(spec)
    frame = simulate_in_memory(world, trajectory, sensor, 1, seed=seed, t_start=start_s + 3.0, fields="truth")[0]
    cfg = variant(DEFAULT_VARIANT)
    r = np.linalg.norm(frame.points, axis=1)
    ok = np.isfinite(r) & (r >= cfg.clean.min_range_m) & (r <= cfg.clean.max_range_m)
    weather = frame.field("weather")  # (absent in clear air)
    points, weather = frame.points[ok], (np.zeros(len(ok)) if weather is None else weather)[ok] > 0
    poles = extract_poles(points, frame.ring[ok], sensor.rings, sensor.columns_per_sweep, cfg.poles.max_width_m,
                          clutter_filter=clutter_filter)
    if clutter_filter and WeatherGate().update(poles.clutter_per_beam):  # (a scan alone: no scans before it)
        poles = poles.without_suspects()
    _, nearest = KDTree(points).query(poles.points)
    return poles, weather[nearest]


@pytest.mark.slow
@pytest.mark.parametrize("condition", ["dense-fog", "snow"])
@pytest.mark.parametrize("family", ["city", "forest"])
def test_poles_of_weather_clutter_are_crowded_and_the_structures_stand_clear(family, condition):
    """Seed 7 is in neither split. Fog's backscatter and snowflakes make near-range "poles" by the thousand; the
    isolation rule drops nearly all of them and keeps most poles of structure (the truth says which is which).
    What it leaves is for the pole map's confirmation (the next test)."""
    every, is_weather = _labelled_poles(condition, family, 7, clutter_filter=False)
    kept, kept_weather = _labelled_poles(condition, family, 7, clutter_filter=True)
    assert every.dropped == 0 and not every.cluttered and every.suspect is None
    assert kept.cluttered and kept.dropped == len(every) - len(kept)
    structure, clutter = int((~is_weather).sum()), int(is_weather.sum())
    assert clutter > 2 * structure and structure > 50  # the failure's cause: clutter outnumbers the poles
    assert kept_weather.sum() <= 0.1 * clutter
    assert (~kept_weather).sum() >= 0.6 * structure


def test_the_pole_map_targets_only_poles_the_next_or_previous_frame_confirms():
    posts = np.array([[5.0, 2.0, 0.5], [8.0, -3.0, 0.4], [12.0, 6.0, 0.6]])
    rng = np.random.default_rng(41)
    clutter = [rng.uniform(-6, 6, (20, 3)) for _ in range(3)]  # random from frame to frame, as weather's is
    pole_map = PoleMap(frames_kept=3, confirmed_only=True)
    pole_map.add(np.vstack([posts, clutter[0]]), cluttered=True)
    assert len(pole_map.target().points) == len(posts) + 20  # one frame: no neighbour to confirm by
    for k in (1, 2):
        pole_map.add(np.vstack([posts + rng.normal(0, 0.03, posts.shape), clutter[k]]), cluttered=True)
    target = pole_map.target().points
    # every post seen in each of the three frames, and only the clutter that happened to fall near other clutter
    d_posts = np.linalg.norm(target[:, None, :2] - posts[None, :, :2], axis=2).min(axis=1)
    assert (d_posts < 0.2).sum() == 3 * len(posts)
    lucky = sum(np.any(np.linalg.norm(c[:, None, :2] - o[None, :, :2], axis=2) <= 0.25, axis=1).sum()
                for i, c in enumerate(clutter) for j, o in enumerate(clutter) if abs(i - j) == 1)
    assert len(target) - 3 * len(posts) <= lucky
    unconfirmed = PoleMap(frames_kept=3)
    for k in range(3):
        unconfirmed.add(np.vstack([posts, clutter[k]]))
    assert len(unconfirmed.target().points) == 3 * (len(posts) + 20)
    clear = PoleMap(frames_kept=3, confirmed_only=True)  # a clear frame's poles are targets at once
    for k in range(3):
        clear.add(np.vstack([posts, clutter[k]]), cluttered=False)
    assert np.array_equal(clear.target().points, unconfirmed.target().points)


@pytest.mark.slow
def test_a_clear_scan_keeps_its_poles_with_the_clutter_filter_on():
    """The clear twin of a wood (trunks close together: the most crowded clear scans of the tuning seeds) is
    not cluttered: the filter leaves its poles as they are."""
    off, _ = _labelled_poles("clear", "forest", 7, clutter_filter=False)
    on, _ = _labelled_poles("clear", "forest", 7, clutter_filter=True)
    assert len(off) > 50 and not on.cluttered and on.dropped == 0
    assert np.array_equal(on.points, off.points)


def test_the_weather_gate_enters_over_its_threshold_and_holds_while_the_clutter_lasts():
    """Weather lasts: a scan under the gate after scans in weather stays in weather while its statistic is over
    the lower threshold (near walls leave the fog few beams); clear air (under both) never enters."""
    gate = WeatherGate()
    low, between, high = 0.5 * LEAVE_PER_BEAM, 0.5 * (LEAVE_PER_BEAM + CLUTTERED_PER_BEAM), 2 * CLUTTERED_PER_BEAM
    assert [gate.update(v) for v in (low, between, between, high, between, between, low, between, high)] == [
        False, False, False, True, True, True, False, False, True]


@pytest.mark.parametrize("preset", ["vlp16", "hdl32e"])
def test_no_post_is_narrower_than_the_weather_rule(preset):
    """A post (12 x 10 cm) spans at least ``MIN_WIDTH_M`` as its run measures it, near or far: the width rule
    the clutter filter applies in weather never takes a post for a particle (every pole here is a post)."""
    world = corridor()
    sensor = load_preset(preset)
    scan = one_scan(world, sensor)
    poles = extract_poles(scan.xyz, scan.ring, sensor.rings, sensor.columns_per_sweep, 0.6, clutter_filter=True)
    r = np.hypot(poles.points[:, 0], poles.points[:, 1])
    assert len(poles) > 10 and r.max() > 20.0
    assert not poles.suspect.any() and poles.clutter_per_beam == 0.0
    # particles: single returns of one ring pulled to 3 m along their beams, tens of degrees apart (no
    # other pole within the isolation radius): only the width rule can mark them, and it must
    xyz = scan.xyz.copy()
    ring = sensor.rings // 2 + 2
    far = np.flatnonzero((scan.ring == ring) & (np.linalg.norm(xyz, axis=1) > 8.0))[::150]
    xyz[far] *= 3.0 / np.linalg.norm(xyz[far], axis=1, keepdims=True)
    with_particles = extract_poles(xyz, scan.ring, sensor.rings, sensor.columns_per_sweep, 0.6, clutter_filter=True)
    d = np.linalg.norm(with_particles.points[:, None, :] - xyz[far][None, :, :], axis=2).min(axis=1)
    particle = d < 1e-6
    assert particle.sum() >= 5
    assert with_particles.suspect[particle].all() and not with_particles.suspect[~particle].any()
    assert not crowded(with_particles.points, sensor.columns_per_sweep)[particle].any()


@pytest.mark.parametrize("folder, sensor", [("kitti/sequences/05", "hdl64e"), ("hdl32-pair", "hdl32e")])
def test_real_streets_are_not_cluttered(real_data, folder, sensor):
    """Real scans in clear air (an urban KITTI street, a campus with the HDL-32E: up to 0.56 of their poles
    stand within 0.5 m of another) are not weather: the clutter filter leaves their poles as they are."""
    from odometry.gcr import ring_of_points
    from simlidar.dataset import open_sequence

    seq = open_sequence(real_data / folder, sensor=sensor)
    lidar = load_preset(sensor)
    gate = WeatherGate()
    for k in range(len(seq)):
        points = seq[k].points
        points = points[np.linalg.norm(points, axis=1) > 1.0]  # (the HDL-32E pair's range-0 returns)
        rings = ring_of_points(points, lidar)
        off = extract_poles(points, rings, lidar.rings, lidar.columns_per_sweep, 1.2)
        on = extract_poles(points, rings, lidar.rings, lidar.columns_per_sweep, 1.2, clutter_filter=True)
        assert len(off) > 50 and not gate.update(on.clutter_per_beam), (folder, k)
        assert np.array_equal(on.points, off.points)


@pytest.mark.slow
def test_the_odometry_drops_the_weathers_poles_on_scans_in_weather_only():
    """The pipeline's gate: every scan of a dense-fog drive is in weather and loses its suspect poles (counted
    per frame); the clear twin's scans lose none."""
    from simlidar.in_memory import simulate_in_memory
    from tools.family_suite import suite_world, weather_suite
    from tools.methods import OursMethod, run_method

    dropped = {}
    for spec in weather_suite((7,), 200, ("city",), ("clear", "dense-fog"), ("real",)):
        world, trajectory, sensor, start_s = suite_world(spec)
        seq = simulate_in_memory(world, trajectory, sensor, 3, seed=7, t_start=start_s + 3.0, fields="real")
        run = run_method(OursMethod("default", variant(DEFAULT_VARIANT)), seq)
        dropped[spec.weather] = [d.filter_counts["poles_weather"] for d in run.diagnostics]
    assert dropped["clear"] == [0, 0, 0]
    assert all(n > 100 for n in dropped["dense-fog"]), dropped


def test_a_lone_single_return_is_a_suspect_only_within_the_clutters_reach():
    """Crowded one-return clutter out to 6 m (pairs 0.1-0.3 m apart, apart in direction): a single return at
    7 m that no other ring sees is within its reach (1.25 x its 99th percentile) and a suspect; the same
    with a pole of another ring beside it (the same post), a single return at 30 m (a far post), and a
    two-return run at 7 m are not; with fewer than 20 crowded returns there is no reach to measure."""
    n_columns = 1800
    rng = np.random.default_rng(4)
    az = rng.uniform(-np.pi, np.pi, 40)
    r = rng.uniform(2.0, 6.0, 40)
    clutter = np.stack([r * np.cos(az), r * np.sin(az), np.zeros(40)], axis=1)
    partners = clutter.copy()  # (0.1-0.3 m away at 0.05 rad, beyond the same object's three columns)
    partners[:, :2] = np.stack([np.cos(az + 0.05), np.sin(az + 0.05)], axis=1) * r[:, None]
    lone = np.array([[7.0, 0.0, 0.0], [0.0, 7.0, 0.0], [0.0, 7.0, 1.0], [-30.0, 0.0, 0.0], [0.0, -7.0, 0.0]])
    points = np.vstack([clutter, partners, lone])
    counts = np.ones(len(points), dtype=int)
    counts[-1] = 2
    among = crowded(points, n_columns)
    assert among[:80].sum() >= 20 and not among[80:].any()
    suspect = alone_within_the_clutter(points, counts, among, n_columns)
    assert suspect[80] and not suspect[81:].any()  # (81, 82: one post on two rings; 83: far; 84: two returns)
    few = np.zeros(len(points), dtype=bool)
    few[:19] = True
    assert not alone_within_the_clutter(points, counts, few, n_columns).any()
    # (without the reach, poles.clutter_reach false: the far single return is a suspect too, the rest still not)
    anywhere = alone_within_the_clutter(points, counts, among, n_columns, within_reach=False)
    assert anywhere[80] and anywhere[83] and not anywhere[[81, 82, 84]].any()
    assert not alone_within_the_clutter(points, counts, few, n_columns, within_reach=False).any()
