"""The scenes' traffic: smooth motions, seeded and kept apart, the static twins, the stress scenes' scripts.

Each claim is checked against what the scene itself knows: its ego trajectory, its actors'
motions, its static mesh.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import scenes
from scenes.actors import KINDS, Actor, LanePath, OffsetProfile, SpeedProfile, models, models_of
from scenes.families import draw_family_params, family_scene
from scenes.traffic import EGO_SIZE_M, FAMILY_TRAFFIC

TRAFFIC = {"enabled": True}


@functools.cache
def with_traffic(name: str, seed: int = 1):
    return scenes.build_scene(name, seed=seed, traffic=TRAFFIC)


# ---------------------------------------------------------------- motions
def test_a_speed_profile_eases_between_knots_and_integrates_its_speed():
    p = SpeedProfile([0.0, 2.0, 5.0, 9.0], [0.0, 8.0, 8.0, 1.0], s0=3.0)
    t = np.linspace(-1.0, 11.0, 120001)
    s, v, a = p.distance(t), p.speed(t), p.accel(t)
    dt = t[1] - t[0]
    # the distance is the integral of the speed, the speed the integral of the acceleration
    assert np.allclose(np.diff(s) / dt, (v[1:] + v[:-1]) / 2, atol=1e-6)
    assert np.allclose(np.diff(v) / dt, (a[1:] + a[:-1]) / 2, atol=1e-4)
    # the acceleration is continuous: between neighbouring instants, knots included, it changes by no more
    # than the steepest jerk (6 x 8 m/s over 2 s, squared: 12 m/s^3) allows in 1e-4 s
    assert np.abs(np.diff(a)).max() <= 12.0 * dt * 1.01
    assert s[0] == pytest.approx(3.0 - 0.0) and np.all(np.diff(s) >= 0)
    q = p.shifted(1.5, -10.0)
    assert np.allclose(q.distance(t + 1.5), s - 10.0)


def test_an_offset_profile_is_smooth_to_its_acceleration():
    o = OffsetProfile([1.0, 4.0, 6.0], [0.0, 3.2, 3.2])
    t = np.linspace(0.0, 7.0, 70001)
    y, r = o.value(t), o.rate(t)
    dt = t[1] - t[0]
    assert np.allclose(np.diff(y) / dt, (r[1:] + r[:-1]) / 2, atol=1e-6)
    acc = np.diff(r) / dt
    assert np.abs(np.diff(acc)).max() < 1e-2  # the lateral acceleration has no step
    assert y[0] == 0.0 and y[-1] == pytest.approx(3.2)


def test_an_actors_velocity_and_turn_rate_are_those_of_its_poses():
    lane_pts = np.column_stack([30 * np.cos(np.linspace(0, 2, 400)), 30 * np.sin(np.linspace(0, 2, 400)),
                                np.linspace(0, 4, 400)])
    actor = Actor(models()["car-saloon"], LanePath(lane_pts, False), SpeedProfile([0, 3, 8], [2, 9, 6]),
                  OffsetProfile([2, 5], [0.0, 1.5]), "test", (-1e9, 1e9))
    t = np.linspace(0.5, 7.5, 50)
    T, v, w = actor.motion_at(t)
    h = 1e-5
    Tp, _, _ = actor.motion_at(t + h)
    Tm, _, _ = actor.motion_at(t - h)
    assert np.allclose(v, (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h), atol=1e-4)
    dR = np.swapaxes(T[:, :3, :3], 1, 2) @ (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h)  # R^T dR/dt = [w_body]x
    w_body = np.stack([dR[:, 2, 1], dR[:, 0, 2], dR[:, 1, 0]], 1)
    assert np.allclose(np.einsum("nij,nj->ni", T[:, :3, :3], w_body), w, atol=1e-4)
    assert np.allclose(np.linalg.det(T[:, :3, :3]), 1.0)


@pytest.mark.parametrize("kind", KINDS)
def test_every_class_has_models_of_real_size(kind):
    sizes = {"car": ((3.8, 5.0), (1.6, 2.0), (1.3, 1.9)), "van": ((4.8, 6.5), (1.8, 2.2), (2.0, 2.8)),
             "lorry": ((8.0, 13.0), (2.4, 2.6), (3.4, 4.1)), "bus": ((10.0, 13.0), (2.4, 2.6), (2.9, 3.5)),
             "cyclist": ((1.5, 2.0), (0.4, 0.8), (1.5, 1.9)), "pedestrian": ((0.2, 0.6), (0.3, 0.8), (1.1, 2.0))}
    for m in models_of(kind):
        for value, (lo, hi) in zip(m.box_size, sizes[kind], strict=True):
            assert lo <= value <= hi, (m.name, m.box_size)
        assert m.vertices[:, 2].min() == pytest.approx(0.0, abs=1e-9)  # standing on the ground


# ---------------------------------------------------------------- the scenes' traffic
def test_scenes_are_static_unless_traffic_is_on_and_the_twin_is_the_same_world():
    static = scenes.build_scene("city", seed=1)
    moving = with_traffic("city")
    assert static.actors == [] and len(moving.actors) >= 10
    assert static.mesh_hash() == moving.mesh_hash()
    t = np.linspace(0, static.trajectory.duration_s, 40)
    np.testing.assert_array_equal(static.trajectory.pose_at(t), moving.trajectory.pose_at(t))
    again = scenes.build_scene("city", seed=1, traffic=TRAFFIC)
    assert [a.model.name for a in again.actors] == [a.model.name for a in moving.actors]
    np.testing.assert_array_equal(again.actors[3].motion_at(t)[0], moving.actors[3].motion_at(t)[0])
    assert {a.behaviour for a in moving.actors} >= {"walking"}


def _footprint_points(centre, yaw, length, width, step=0.25) -> np.ndarray:
    u = np.array([np.cos(yaw), np.sin(yaw)])
    v = np.array([-u[1], u[0]])
    a, b = np.meshgrid(np.linspace(-length / 2, length / 2, max(2, int(length / step) + 1)),
                       np.linspace(-width / 2, width / 2, max(2, int(width / step) + 1)))
    return centre + a.ravel()[:, None] * u + b.ravel()[:, None] * v


def _inside(points, centre, yaw, length, width) -> bool:
    d = points - centre
    u = np.array([np.cos(yaw), np.sin(yaw)])
    v = np.array([-u[1], u[0]])
    return bool(np.any((np.abs(d @ u) < length / 2) & (np.abs(d @ v) < width / 2)))


@pytest.mark.parametrize("name", ["city", "suburb", "highway", "red_light", "traffic_jam", "overtaking_lorry"])
def test_no_actor_drives_into_the_ego_or_another(name):
    """Every second of the scene, no point of an actor's footprint lies inside the ego's or another actor's."""
    s = with_traffic(name) if name in FAMILY_TRAFFIC else scenes.build_scene(name)
    times = np.arange(0.0, s.trajectory.duration_s, 1.0)
    ego = s.trajectory.pose_at(times)
    for k, t in enumerate(times):
        alive = [a for a in s.actors if a.time_span_s[0] <= t <= a.time_span_s[1]]
        feet = []
        for a in alive:
            c, yaw = a.footprint_at(np.array([t]))
            feet.append((c[0], yaw[0], a.model.length_m, a.model.width_m))
        e_yaw = np.arctan2(ego[k, 1, 0], ego[k, 0, 0])
        for i, (c, yaw, length, width) in enumerate(feet):
            pts = _footprint_points(c, yaw, length, width)
            assert not _inside(pts, ego[k, :2, 3], e_yaw, *EGO_SIZE_M), (name, t, alive[i].behaviour)
            for c2, yaw2, l2, w2 in feet[i + 1:]:
                if np.linalg.norm(c - c2) < (length + l2) / 2 + (width + w2) / 2:
                    assert not _inside(pts, c2, yaw2, l2, w2), (name, t, alive[i].behaviour)


def test_families_with_traffic_draw_it_apart_from_the_rest():
    for family in FAMILY_TRAFFIC:
        for seed in (1, 2, 101):
            plain = draw_family_params(family, seed)
            busy = draw_family_params(family, seed, traffic=True)
            assert "traffic" not in plain and busy.pop("traffic")["enabled"] is True
            assert busy == plain  # the static twin is the member without its traffic
    with pytest.raises(ValueError, match="forest"):
        draw_family_params("forest", 1, traffic=True)


@pytest.mark.slow
@pytest.mark.parametrize("family", list(FAMILY_TRAFFIC))
def test_every_family_builds_its_traffic(family):
    s = scenes.build_scene(family_scene(family), **draw_family_params(family, 1, traffic=True))
    assert len(s.actors) > 0


# ---------------------------------------------------------------- the stress scenes
def test_the_red_light_ego_stands_still_to_the_bit_while_traffic_crosses_in_front():
    s = scenes.build_scene("red_light")
    t_stop, t_go = s.metadata["wait_s"]
    t = np.arange(t_stop + 0.05, t_go - 0.05, 0.1)
    poses = s.trajectory.pose_at(t)
    assert np.all(poses == poses[0])  # not a micrometre of motion
    assert s.trajectory.speed_at(np.array([t_stop - 2.0]))[0] > 1.0 and s.trajectory.speed_at(t_go + 3.0)[0] > 1.0
    ahead = poses[0][:3, 0]
    crossing = [a for a in s.actors if a.behaviour == "crossing"]
    queue = [a for a in s.actors if a.behaviour == "queue"]
    assert len(crossing) == s.params["cross_vehicles"] and len(queue) == s.params["queue_vehicles"]
    for a in crossing:  # each passes in front of the waiting ego, across its heading
        T, v, _ = a.motion_at(t)
        rel = T[:, :3, 3] - poses[0][:3, 3]
        assert np.any(np.abs(rel @ ahead - 15.0) < 8.0) and np.all(np.abs(v[:, :2] @ ahead[:2]) < 0.5)
    speeds = np.array([np.linalg.norm(a.motion_at(t)[1], axis=1) for a in queue])
    assert np.any(speeds > 0.3) and np.any(speeds < 0.01)  # the queue creeps and stops
    twin = scenes.build_scene("red_light", moving=False)
    assert twin.actors == [] and twin.mesh_hash() == s.mesh_hash()
    np.testing.assert_array_equal(twin.trajectory.pose_at(t), poses)


def test_the_lead_van_keeps_its_gap_exactly():
    s = scenes.build_scene("lead_vehicle")
    (van,) = s.actors
    t = np.linspace(0.0, s.trajectory.duration_s, 200)
    ego = s.trajectory.pose_at(t)[:, :3, 3]
    T, _, _ = van.motion_at(t)
    gap = np.linalg.norm(T[:, :2, 3] - ego[:, :2], axis=1)
    expected = s.metadata["gap_m"] + (van.model.length_m + EGO_SIZE_M[0]) / 2
    assert np.allclose(gap, expected, atol=1e-6)


def test_the_jam_creeps_and_the_lorry_overtakes():
    jam = scenes.build_scene("traffic_jam")
    t = np.arange(0.0, jam.trajectory.duration_s, 0.1)
    v = jam.trajectory.speed_at(t)
    assert v.max() <= jam.params["creep_m_s"] + 1e-9 and np.mean(v < 0.01) > 0.2
    movers = [np.linalg.norm(a.motion_at(t)[1], axis=1).max() for a in jam.actors]
    assert len(jam.actors) > 30 and max(movers) <= jam.params["creep_m_s"] + 1e-6
    over = scenes.build_scene("overtaking_lorry")
    lorry = next(a for a in over.actors if a.behaviour == "overtaking")
    t_a = over.metadata["alongside_s"]
    ego = over.trajectory.pose_at(np.array([t_a - 6.0, t_a, t_a + 6.0]))
    T, _, _ = lorry.motion_at(np.array([t_a - 6.0, t_a, t_a + 6.0]))
    along = np.einsum("ni,ni->n", T[:, :3, 3] - ego[:, :3, 3], ego[:, :3, 0])
    assert along[0] < -5.0 and abs(along[1]) < 0.5 and along[2] > 5.0  # behind, alongside, ahead
    # in the next lane all along: one lane width left of the ego's own path where the ego passes (or will pass)
    # the lorry's place (the road bends, so the ego's frame of the moment would not do 35 m away)
    path = over.trajectory.pose_at(np.arange(0.0, over.trajectory.duration_s, 0.005))
    for centre in T[:, :3, 3]:
        d = centre - path[:, :3, 3]
        k = np.argmin(np.abs(np.einsum("ni,ni->n", d, path[:, :3, 0])))
        assert d[k] @ path[k, :3, 1] == pytest.approx(over.params["lane_width_m"], abs=1e-3)
