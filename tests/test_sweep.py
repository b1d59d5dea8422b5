"""The sweep against analytic truth: exact geometry, noise statistics, indices, timing, motion."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import box_room, constant_velocity, ground_plane, sphere_room, wall_x

from simlidar import se3
from simlidar.sensor import from_dict, load_preset
from simlidar.sweep import SensorInsideGeometry, SweepSimulator
from simlidar.world import LABEL_REFLECTANCE

STILL = constant_velocity()
WIDE = from_dict(
    {
        "name": "wide",
        "rings": 24,
        "ring_pitch_deg": 5.0,
        "lowest_angle_deg": -57.5,
        "azimuth_step_deg": 1.0,
        "rotation_hz": 10.0,
        "range_noise_std_m": 0.0,
        "min_range_m": 0.1,
        "max_range_m": 200.0,
    }
)


def scan_of(world, sensor, trajectory=STILL, t0=0.0, motion=True, seed=0):
    return SweepSimulator(world, sensor, seed=seed, motion_distortion=motion).sweep(trajectory, t0)


def test_box_room_exact_ranges_points_and_normals():
    half = np.array([20.0, 15.0, 4.0])
    s = scan_of(box_room(size=2 * half), WIDE)
    assert len(s) == WIDE.rays_per_sweep  # closed room: every ray returns
    d = s.xyz / np.linalg.norm(s.xyz, axis=1, keepdims=True)
    # analytic: the first slab the ray leaves through
    t_axis = np.where(np.abs(d) > 0, half / np.maximum(np.abs(d), 1e-300), np.inf)
    t_true = t_axis.min(axis=1)
    axis = t_axis.argmin(axis=1)
    assert np.abs(s.range_m - t_true).max() < 1e-9
    assert np.abs(s.true_range_m - t_true).max() < 1e-9
    on_face = np.abs(np.abs(s.xyz[np.arange(len(s)), axis]) - half[axis])
    assert on_face.max() < 1e-9
    n_true = np.zeros_like(s.xyz)
    n_true[np.arange(len(s)), axis] = -np.sign(s.xyz[np.arange(len(s)), axis])
    assert np.abs(s.normal - n_true).max() < 1e-9


def test_ground_plane_exact():
    T = np.eye(4)
    T[2, 3] = 1.9
    traj = constant_velocity(start=(0, 0, 1.9))
    s = scan_of(ground_plane(), WIDE, traj)
    assert np.all(s.xyz[:, 2] < 0)
    # every downward ray returns, no upward ray does
    down = WIDE.elevation_rad < 0
    assert len(s) == down.sum() * WIDE.columns_per_sweep
    el = WIDE.elevation_rad[s.ring]
    assert np.allclose(s.range_m, 1.9 / np.sin(-el), rtol=0, atol=1e-9)
    assert np.allclose(s.xyz[:, 2], -1.9, atol=1e-9)
    assert np.allclose(s.normal, [0, 0, 1], atol=1e-12)
    assert np.allclose(s.true_xyz, s.xyz, atol=1e-9)


def test_sphere_within_tessellation_error():
    # A 5 m sphere tessellated into 327,680 triangles deviates from the true sphere by
    # at most R * (edge angle)^2 / 8 ~ 5.5e-5 m, and its facet normals by ~ edge/sqrt(3) rad.
    s = scan_of(sphere_room(radius=5.0), load_preset("vlp16").with_overrides(range_noise_std_m=0.0))
    assert len(s) == load_preset("vlp16").rays_per_sweep
    r = np.linalg.norm(s.xyz, axis=1)
    assert np.abs(r - 5.0).max() < 1e-4
    assert np.abs(s.range_m - 5.0).max() < 1e-4
    cos = np.einsum("ij,ij->i", s.normal, -s.xyz / r[:, None])
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.6


def test_range_noise_statistics():
    sigma = 0.03
    sensor = load_preset("salo32").with_overrides(range_noise_std_m=sigma)
    s = scan_of(box_room(), sensor, seed=7)
    res = s.range_m - s.true_range_m
    assert len(res) >= 100_000
    # mean within 5 standard errors of 0; std within 5 % of sigma (the spec's tolerance)
    assert abs(res.mean()) < 5 * sigma / np.sqrt(len(res))
    assert abs(res.std() / sigma - 1) < 0.05
    # noise is along the beam: measured and true point share a direction
    u = s.xyz / np.linalg.norm(s.xyz, axis=1, keepdims=True)
    assert np.allclose(s.true_xyz, u * s.true_range_m[:, None], atol=1e-9)


def test_no_returns_outside_range_limits():
    sensor = load_preset("vlp16").with_overrides(max_range_m=18.0, range_noise_std_m=0.05)
    s = scan_of(box_room(size=(40.0, 30.0, 8.0)), sensor)
    assert s.range_m.max() <= 18.0
    assert 0 < len(s) < sensor.rays_per_sweep  # far walls and corners are beyond 18 m
    near = load_preset("vlp16").with_overrides(min_range_m=5.01, range_noise_std_m=0.0)
    assert len(scan_of(sphere_room(radius=5.0), near)) == 0


def test_ring_and_azimuth_reproduce_direction_without_motion():
    for name in ("os1-64", "vlp16", "hdl32e"):
        sensor = load_preset(name).with_overrides(range_noise_std_m=0.0)
        s = scan_of(box_room(), sensor, motion=False)
        r = np.linalg.norm(s.xyz, axis=1)
        elevation = np.arcsin(s.xyz[:, 2] / r)
        assert np.abs(elevation - sensor.elevation_rad[s.ring]).max() < 1e-9
        az = np.arctan2(s.xyz[:, 1], s.xyz[:, 0])
        expected = sensor.column_azimuth_rad(s.azimuth_index) + sensor.ring_azimuth_offset_rad[s.ring]
        wrapped = np.angle(np.exp(1j * (az - expected)))
        assert np.abs(wrapped).max() < 1e-9
        assert np.allclose(s.time_s, sensor.firing_time_s(s.ring, s.azimuth_index))


def test_points_follow_firing_order():
    sensor = load_preset("vlp16")
    s = scan_of(box_room(), sensor)
    order = s.azimuth_index.astype(np.int64) * sensor.rings + s.ring
    assert np.all(np.diff(order) > 0)
    assert s.time_s.min() >= 0 and s.time_s.max() < sensor.sweep_period_s


def test_motion_distortion_shift_towards_wall():
    v = 10.0
    sensor = WIDE
    traj = constant_velocity(v=(v, 0, 0), start=(0, 0, 0))
    s = scan_of(wall_x(30.0), sensor, traj)
    # the wall's distance from the sensor shrinks by v * t at each point's firing time
    assert np.abs(s.xyz[:, 0] - (30.0 - v * s.time_s)).max() < 1e-9
    assert s.time_s.max() > 0.04  # the shift reaches tens of centimetres
    assert np.abs(s.true_xyz[:, 0] - 30.0).max() < 1e-9
    off = scan_of(wall_x(30.0), sensor, traj, motion=False)
    assert np.abs(off.xyz[:, 0] - 30.0).max() < 1e-9


def test_deskew_ground_truth_is_exact_under_rotation_and_translation():
    traj = constant_velocity(v=(8.0, 1.0, 0.0), yaw_rate=0.5, start=(0.0, 0.0, 0.0))
    sensor = load_preset("vlp16").with_overrides(range_noise_std_m=0.0)
    s = scan_of(box_room(size=(60, 50, 10)), sensor, traj, t0=0.3)
    T_ref = traj.pose_at(np.array([0.3]))[0]
    T_fire = se3.inverse(T_ref) @ traj.pose_at(0.3 + s.time_s)
    deskewed = np.einsum("nij,nj->ni", T_fire[:, :3, :3], s.xyz) + T_fire[:, :3, 3]
    assert np.abs(deskewed - s.true_xyz).max() < 1e-8
    assert np.abs(s.xyz - s.true_xyz).max() > 0.1  # and the raw scan is visibly distorted


def test_seed_reproducibility_and_options():
    sensor = load_preset("vlp16").with_overrides(ring_bias_std_m=0.05)
    a = scan_of(box_room(), sensor, seed=3)
    b = scan_of(box_room(), sensor, seed=3)
    c = scan_of(box_room(), sensor, seed=4)
    assert np.array_equal(a.xyz, b.xyz)
    assert not np.array_equal(a.xyz, c.xyz)
    sim = SweepSimulator(box_room(), sensor, seed=3)
    res = a.range_m - a.true_range_m
    per_ring = np.array([res[a.ring == r].mean() for r in range(sensor.rings)])
    # the per-laser bias is what each ring's mean residual converges to
    assert np.abs(per_ring - sim.ring_bias_m).max() < 5 * sensor.range_noise_std_m / np.sqrt(1000)
    drop = scan_of(box_room(), load_preset("vlp16").with_overrides(dropout_probability=0.3))
    assert len(drop) / sensor.rays_per_sweep == pytest.approx(0.7, abs=0.02)
    jit = scan_of(box_room(), load_preset("vlp16").with_overrides(angular_jitter_deg=0.1), motion=False)
    el = np.arcsin(jit.xyz[:, 2] / np.linalg.norm(jit.xyz, axis=1))
    assert np.degrees(el - sensor.elevation_rad[jit.ring]).std() == pytest.approx(0.1, rel=0.1)


def test_intensity_model():
    traj = constant_velocity(start=(0, 0, 1.9))
    s = scan_of(ground_plane(), WIDE, traj)
    cos_inc = 1.9 / s.range_m
    expected = LABEL_REFLECTANCE["ground"] * cos_inc * np.minimum(1.0, (10.0 / s.range_m) ** 2)
    assert np.allclose(s.intensity, expected, atol=1e-6)
    assert 0 <= s.intensity.min() and s.intensity.max() <= 1


def test_sensor_inside_geometry_is_detected():
    sim = SweepSimulator(box_room(), load_preset("vlp16"))
    sim.check_clear(np.eye(4))  # inside a room: fine
    import trimesh

    from simlidar.world import World

    b = trimesh.creation.box((10, 10, 10))  # a solid block with outward faces
    block = SweepSimulator(World(b.vertices, b.faces, np.zeros(12)), load_preset("vlp16"))
    with pytest.raises(SensorInsideGeometry, match="inside geometry"):
        block.check_clear(np.eye(4))
    T = np.eye(4)
    T[0, 3] = 20.0
    block.check_clear(T)
    under = SweepSimulator(ground_plane(), load_preset("vlp16"))
    T[2, 3] = -1.0
    with pytest.raises(SensorInsideGeometry):
        under.check_clear(T)


def room_with_winding(winding: str, size=(10.0, 8.0, 3.0)):
    """A closed room, floor at z = 0, wound as a user's mesh may be: "outward" (a solid box,
    trimesh's default), "inward" (faces turned to the room) or "mixed" (every other triangle flipped)."""
    import trimesh

    from simlidar.world import World

    m = trimesh.creation.box(size)
    m.apply_translation((0.0, 0.0, size[2] / 2))
    faces = np.array(m.faces)
    if winding == "inward":
        faces = faces[:, ::-1]
    elif winding == "mixed":
        faces[::2] = faces[::2, ::-1]
    return World(m.vertices, faces, np.zeros(len(faces)), ["wall"], source=f"{winding} room",
                 normals_reliable=False)


def analytic_box_range(origin, directions, lo, hi):
    """Distance from ``origin`` (3,) along unit ``directions`` (n, 3) to the inside of the box [lo, hi], m,
    and the index of the axis whose wall is hit."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_axis = np.where(directions > 0, (np.asarray(hi) - origin) / directions,
                          np.where(directions < 0, (np.asarray(lo) - origin) / directions, np.inf))
    return t_axis.min(axis=1), t_axis.argmin(axis=1)


@pytest.mark.parametrize("winding", ["outward", "inward", "mixed"])
def test_enclosed_room_of_any_winding_ranges_to_the_analytic_walls(winding):
    world = room_with_winding(winding)
    lo, hi = np.array([-5.0, -4.0, 0.0]), np.array([5.0, 4.0, 3.0])
    origin = np.array([1.0, -0.5, 1.8])
    T = np.eye(4)
    T[:3, 3] = origin
    sim = SweepSimulator(world, WIDE)
    found = sim.check_clear(T)  # a user's mesh: evidence, no refusal
    assert found.n_hit == found.n_rays
    if winding == "mixed":
        assert 0 < found.n_back < found.n_hit
    else:
        assert found.n_back == (found.n_hit if winding == "outward" else 0)
    assert found.enclosed == (winding == "outward")
    if found.enclosed:
        with pytest.raises(SensorInsideGeometry, match=r"sensor at \(1.00, -0.50, 1.80\) m is inside geometry"):
            sim.check_clear(T, strict=True)
    s = sim.sweep(constant_velocity(start=origin), 0.0)
    assert len(s) == WIDE.rays_per_sweep  # closed room: every ray returns, back face or not
    d = s.xyz / np.linalg.norm(s.xyz, axis=1, keepdims=True)
    t_true, axis = analytic_box_range(origin, d, lo, hi)
    assert np.abs(s.range_m - t_true).max() < 1e-9
    assert np.abs(s.true_range_m - t_true).max() < 1e-9
    n_true = np.zeros_like(d)
    n_true[np.arange(len(s)), axis] = -np.sign(d[np.arange(len(s)), axis])  # the wall's side facing the sensor
    assert np.abs(s.normal - n_true).max() < 1e-9
    assert np.all(np.einsum("ij,ij->i", s.normal, s.true_xyz) < 0)
    # intensity uses |cos incidence|: back faces are as bright as front faces
    ref = SweepSimulator(room_with_winding("inward"), WIDE).sweep(constant_velocity(start=origin), 0.0)
    assert np.allclose(s.intensity, ref.intensity, atol=1e-7)


def test_back_face_returns_carry_the_configured_noise():
    sigma = 0.02
    sensor = load_preset("vlp16").with_overrides(range_noise_std_m=sigma)
    origin = np.array([-2.0, 1.0, 1.8])
    s = scan_of(room_with_winding("outward"), sensor, constant_velocity(start=origin), seed=3)
    d = s.xyz / np.linalg.norm(s.xyz, axis=1, keepdims=True)
    t_true, _ = analytic_box_range(origin, d, [-5.0, -4.0, 0.0], [5.0, 4.0, 3.0])
    res = s.range_m - t_true
    assert len(res) == sensor.rays_per_sweep
    assert abs(res.mean()) < 5 * sigma / np.sqrt(len(res))
    assert abs(res.std() / sigma - 1) < 0.05
