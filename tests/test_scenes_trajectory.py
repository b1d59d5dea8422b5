"""PathTrajectory against analytic motion: speed profile, heading, grade, roll, loops."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import build_scene, paths
from scenes.trajectory import ROLL_PER_LAT_ACCEL_RAD, PathTrajectory


def straight(length=200.0, step=0.5, grade=0.0):
    x = np.arange(0.0, length + step / 2, step)
    return np.column_stack([x, np.zeros_like(x), grade * x])


def circle(radius=30.0, step=0.5):
    n = int(round(2 * np.pi * radius / step))
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)])  # counter-clockwise


def make(path, closed=False, speed=10.0, accel=1.5, lat=2.0, **kw):
    return PathTrajectory(path, closed, speed, accel, lat, 1.9, **kw)


def test_straight_run_matches_the_analytic_profile():
    # Rest -> accelerate at a -> cruise at v -> brake at a -> rest, over 200 m:
    # t = 2 v / a + (L - v^2 / a) / v.
    tr = make(straight())
    v, a, L = 10.0, 1.5, 200.0
    assert tr.duration_s == pytest.approx(2 * v / a + (L - v**2 / a) / v, rel=2e-3)
    t = np.linspace(0, tr.duration_s, 2001)
    speed = tr.speed_at(t)
    assert speed[0] == 0.0 and speed[-1] == pytest.approx(0.0, abs=1e-9)
    assert speed.max() == pytest.approx(v, rel=1e-9)
    # standing still before the start and, once the body has settled, after the end
    np.testing.assert_allclose(tr.pose_at(np.array([-1.0]))[0], tr.pose_at(np.array([0.0]))[0])
    np.testing.assert_allclose(tr.pose_at(np.array([tr.duration_s + 5]))[0, :3, 3], [L, 0.0, 1.9], atol=1e-6)
    assert tr.time_at_distance(np.array([0.0, L / 2, L])) == pytest.approx([0.0, tr.duration_s / 2, tr.duration_s])


def test_poses_are_rigid_and_the_sensor_rides_at_mount_height():
    tr = make(straight(), suspension_pitch_rad=0.0, suspension_heave_m=0.0)
    T = tr.pose_at(np.linspace(0, tr.duration_s, 300))
    R = T[:, :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # On a flat straight road the only tilt is squat/dive from acceleration (< 1 degree),
    # so the sensor stays 1.9 m above the road to within 1.9 (1 - cos 1 deg) = 0.3 mm.
    np.testing.assert_allclose(T[:, 2, 3], 1.9, atol=3e-4)


def test_heading_pitch_follow_a_grade():
    g = 0.05
    tr = make(straight(grade=g), suspension_pitch_rad=0.0, suspension_heave_m=0.0)
    s = np.array([100.0])  # cruising: no acceleration pitch
    T = tr.pose_at(tr.time_at_distance(s))[0]
    np.testing.assert_allclose(T[:3, 0], [np.cos(np.arctan(g)), 0.0, np.sin(np.arctan(g))], atol=1e-6)
    # the sensor is mount height above the road along the body's up axis
    np.testing.assert_allclose(T[:3, 3], [100.0, 0.0, g * 100.0] + 1.9 * T[:3, 2], atol=1e-6)


def test_roll_follows_the_cross_slope_under_the_wheels():
    tr = make(straight(), suspension_pitch_rad=0.0, suspension_heave_m=0.0,
              surface_height=lambda x, y: 0.1 * y)  # left side higher
    T = tr.pose_at(tr.time_at_distance(np.array([100.0])))[0]
    assert T[2, 1] == pytest.approx(np.sin(np.arctan(0.1)), abs=1e-9)  # lidar y axis tilts up


def test_turns_slow_the_vehicle_and_the_body_leans_out():
    # On a 30 m circle the lateral limit of 2 m/s^2 allows sqrt(2 * 30) = 7.75 m/s < 10 cruise.
    R, a_lat = 30.0, 2.0
    tr = make(circle(R), closed=True, lat=a_lat, suspension_pitch_rad=0.0, suspension_heave_m=0.0)
    t = tr.time_at_distance(np.array([0.5 * tr.length_m]))
    v = tr.speed_at(t)[0]
    assert v == pytest.approx(np.sqrt(a_lat * R), rel=1e-2)
    T = tr.pose_at(t)[0]
    # left turn: centripetal acceleration to the left, the body rolls right (left side up)
    assert T[2, 1] == pytest.approx(np.sin(ROLL_PER_LAT_ACCEL_RAD * v**2 / R), rel=2e-2)


def test_a_loop_ends_where_it_starts():
    tr = make(circle(40.0), closed=True)
    T0, T1 = tr.pose_at(np.array([0.0, tr.duration_s + 5.0]))  # at rest, body settled
    np.testing.assert_allclose(T1[:3, 3], T0[:3, 3], atol=1e-6)
    assert tr.length_m == pytest.approx(2 * np.pi * 40.0, rel=1e-3)


def test_city_drive_respects_its_limits():
    # Road-level motion sampled at 50 Hz: speed within cruise, tangential and lateral
    # accelerations within the configured limits (5% for finite differences).
    s = build_scene("city", streets_x=3, streets_y=3, route_blocks=2, suspension_pitch_deg=0.0,
                    suspension_heave_m=0.0)
    tr, p = s.trajectory, s.params
    t = np.arange(0.0, tr.duration_s, 0.02)
    pos = tr.road_point_at(tr.distance_at(t))[:, :2]
    vel = np.gradient(pos, t, axis=0)
    acc = np.gradient(vel, t, axis=0)
    speed = np.linalg.norm(vel, axis=1)
    assert speed.max() <= p["speed_m_s"] * 1.01
    moving = speed > 0.5
    tangent = vel[moving] / speed[moving, None]
    a_tan = np.einsum("ij,ij->i", acc[moving], tangent)
    a_lat = np.abs(tangent[:, 0] * acc[moving, 1] - tangent[:, 1] * acc[moving, 0])
    assert np.abs(a_tan).max() <= p["accel_m_s2"] * 1.05
    assert a_lat.max() <= p["lateral_accel_m_s2"] * 1.05
    assert a_lat.max() >= p["lateral_accel_m_s2"] * 0.8  # the turns do reach the limit


def test_suspension_motion_is_small_and_seeded():
    tr_a = make(straight(), suspension_pitch_rad=np.radians(0.3), suspension_heave_m=0.01, seed=1)
    tr_b = make(straight(), suspension_pitch_rad=np.radians(0.3), suspension_heave_m=0.01, seed=2)
    t = tr_a.time_at_distance(np.linspace(60, 140, 200))  # cruising: only the oscillation
    za, zb = tr_a.pose_at(t)[:, 2, 3], tr_b.pose_at(t)[:, 2, 3]
    assert np.abs(za - 1.9).max() <= 0.01 + 1.9 * (1 - np.cos(np.radians(0.6))) + 1e-9
    assert np.abs(za - 1.9).max() > 0.002 and not np.allclose(za, zb)


def test_fillet_rounds_corners_with_exact_arcs():
    square = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]])
    r = 10.0
    pts = paths.fillet(square, r, closed=True, step_m=0.25)
    length = paths.arc_length(np.vstack([pts, pts[:1]]))[-1]
    assert length == pytest.approx(4 * (100 - 2 * r) + 2 * np.pi * r, rel=1e-3)
    corner = pts[(pts[:, 0] > 90) & (pts[:, 1] > 90)]
    np.testing.assert_allclose(np.linalg.norm(corner - [90.0, 90.0], axis=1), r, atol=1e-9)
    # a closed path starts at its first vertex's corner: the middle of that arc,
    # r (sqrt 2 - 1) from the vertex (within half a step)
    assert np.linalg.norm(pts[0] - square[0]) == pytest.approx(r * (np.sqrt(2) - 1), abs=0.13)
