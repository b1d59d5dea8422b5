"""The odometry's IMU stage (odometry/inertial.py) against the truth: the preintegrated prediction of a scan's
pose and of its sweep, the switch (nothing changes without it or without samples), and the bare tunnel."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import box_room
from test_imu_files import room_drive
from test_imu_files import sensor as vlp16_with_imu

import scenes
from odometry.config import ImuParams, variant
from odometry.inertial import InertialOdometry, preintegrate, preintegration_error_bound
from odometry.pipeline import run_sequence
from simlidar import se3
from simlidar.imu import ImuModel, simulate_imu, true_motion
from simlidar.in_memory import simulate_in_memory

NOISE_FREE = {"gyroscope_noise_density": 0.0, "gyroscope_random_walk": 0.0, "accelerometer_noise_density": 0.0,
              "accelerometer_random_walk": 0.0}
# An IMU off the lidar's origin, turned and with a clock offset: every term of the model is exercised
MOUNTED = ImuModel(enabled=True, lever_arm_m=(0.3, -0.2, -0.4), rotation_rpy_deg=(180.0, 0.0, 90.0),
                   time_offset_s=0.004, **NOISE_FREE)
PERIOD_S = 0.1


@pytest.fixture(scope="module")
def tunnel():
    return scenes.build_scene("bare-tunnel", 0).trajectory


def truth_extremes(trajectory, model: ImuModel, t0: float, t1: float) -> dict:
    """The largest specific force, its rate of change and that one's, angular rate and angular acceleration
    the IMU sees over trajectory times [t0, t1] (finite differences of the exact motion at 20 times the IMU's
    rate, 5 % added for the maxima between those samples; the span widened by a sample each side for the
    interpolated ends)."""
    h = model.sample_period_s / 20
    t = np.arange(t0 - model.sample_period_s, t1 + model.sample_period_s + h, h)
    gyro, accel, _, _ = true_motion(trajectory, model, t)
    k = trajectory.kinematics_at(t)
    jerk = np.diff(accel, axis=0) / h
    return {"specific_force_m_s2": float(np.linalg.norm(accel, axis=1).max()),
            "jerk_m_s3": float(np.linalg.norm(jerk, axis=1).max()) * 1.05,
            "jerk_rate_m_s4": float((np.linalg.norm(np.diff(jerk, axis=0), axis=1) / h).max()) * 1.05,
            "angular_rate_rad_s": float(np.linalg.norm(gyro, axis=1).max()),
            "angular_accel_rad_s2": float(np.linalg.norm(k.angular_acceleration, axis=1).max()) * 1.05}


def predictions(trajectory, model_sim: ImuModel, model_odo: ImuModel, t_start: float, scans: int):
    """For each scan interval: (the IMU's predicted motion and sweep from the true state at the previous scan,
    the true motion and sweep, the bounds for the span and for two spans). Samples of ``model_sim``,
    integrated as ``model_odo`` says the IMU is mounted."""
    samples, _ = simulate_imu(trajectory, model_sim, t_start, (scans + 2) * PERIOD_S)
    io = InertialOdometry(samples, model_odo, ImuParams())
    io.gravity = np.array([0.0, 0.0, -model_odo.gravity_m_s2])  # (the trajectory's world: z up)
    out = []
    for k in range(scans):
        ta, tb = k * PERIOD_S, (k + 1) * PERIOD_S
        T_a, T_b, T_c = trajectory.pose_at(t_start + np.array([ta, tb, tb + PERIOD_S]))
        io.velocity = true_motion(trajectory, model_odo, np.array([t_start + ta]))[3][0]
        io.records.append(None)  # (predict needs a frame before; the window's contents do not enter)
        pred = io.predict(T_a, ta, tb, PERIOD_S)
        ext = truth_extremes(trajectory, model_sim, t_start + ta, t_start + tb + PERIOD_S)
        bound1 = preintegration_error_bound(model_sim.sample_period_s, PERIOD_S, **ext)
        bound2 = preintegration_error_bound(model_sim.sample_period_s, 2 * PERIOD_S, **ext)
        out.append((pred, se3.inverse(T_a) @ T_b, se3.inverse(T_b) @ T_c, bound1, bound2))
    return out


def test_noise_free_prediction_matches_the_true_relative_pose_within_the_integration_bound(tunnel):
    """Braking into the bare tunnel's stop and standing (t = 20-35 s): each scan's predicted motion from the true
    pose and velocity of the previous one is within the bound of the scheme's own errors
    (``preintegration_error_bound``) of the true one, in position and rotation; the sweep's predicted
    motion (two spans of integration, from the predicted state) within the two spans' bounds."""
    worst = 0.0
    for pred, true, true_sweep, (p1, r1), (p2, r2) in predictions(tunnel, MOUNTED, MOUNTED, 20.0, 150):
        d = se3.inverse(true) @ pred.motion
        assert np.linalg.norm(d[:3, 3]) <= p1 and se3.rotation_angle(d) <= r1 + 1e-12
        ds = se3.inverse(true_sweep) @ pred.sweep
        # (the sweep starts at the predicted pose: its error, p1 and r1 over the sweep's travel, adds)
        travel = np.linalg.norm(true_sweep[:3, 3])
        assert np.linalg.norm(ds[:3, 3]) <= p1 + p2 + r2 * travel and se3.rotation_angle(ds) <= r1 + r2 + 1e-12
        worst = max(worst, np.linalg.norm(d[:3, 3]) / p1)
    assert worst > 0.1  # (the bound is not vacuous: the error reaches a tenth of it somewhere)


@pytest.mark.parametrize("wrong", [{"time_offset_s": 0.0}, {"gravity_m_s2": 9.81},
                                   {"rotation_rpy_deg": (180.0, 0.0, 89.0)}])
def test_a_wrong_mounting_or_clock_breaks_the_bound(tunnel, wrong):
    """The bound is tight enough to catch a model error: the odometry told a 4 ms wrong clock, 9.81 for
    gravity or a degree of yaw misses it in some scan interval while braking."""
    wrong_model = dataclasses.replace(MOUNTED, **wrong)
    misses = [np.linalg.norm((se3.inverse(true) @ pred.motion)[:3, 3]) > p1
              for pred, true, _, (p1, _), _ in predictions(tunnel, MOUNTED, wrong_model, 20.0, 60)]
    assert any(misses)


def test_preintegration_composes_and_its_bias_jacobians_are_first_order(tunnel):
    """Two halves composed (Forster's chaining) give the whole; moving the accelerometer bias by 0.01 m/s^2
    through the Jacobians matches integrating again to second order."""
    samples, _ = simulate_imu(tunnel, MOUNTED, 20.0, 1.0)
    zero = np.zeros(3)
    a, b = preintegrate(samples, 0.1, 0.25, zero, zero), preintegrate(samples, 0.25, 0.4, zero, zero)
    whole = preintegrate(samples, 0.1, 0.4, zero, zero)
    assert np.allclose(a.dR @ b.dR, whole.dR, atol=1e-12)
    assert np.allclose(a.dv + a.dR @ b.dv, whole.dv, atol=1e-10)
    assert np.allclose(a.dp + a.dv * b.dt_s + a.dR @ b.dp, whole.dp, atol=1e-10)
    bias = np.array([0.01, -0.01, 0.005])
    again = preintegrate(samples, 0.1, 0.4, zero, bias)
    dv, dp = whole.corrected(bias)
    assert np.allclose(dv, again.dv, atol=1e-9) and np.allclose(dp, again.dp, atol=1e-9)
    assert preintegrate(samples, 0.5, 1.5, zero, zero) is None  # (beyond the samples: no prediction)
    w = np.array([0.3, -0.2, 0.1])
    assert np.allclose(se3.rotvec_of_rotation(se3.rotation_of_rotvec(w)), w)


@pytest.fixture(scope="module")
def room():
    """40 frames of a vlp16 driving through a room, with an IMU (noise-free)."""
    s = vlp16_with_imu().with_overrides(imu={**NOISE_FREE, "enabled": True})
    return simulate_in_memory(box_room(), room_drive(), s, 40, seed=3, t_start=1.0)


def test_the_switch_off_or_no_samples_change_nothing_and_on_the_imu_predicts(room):
    replace = dataclasses.replace
    base = variant("salo-map")
    lidar_only = run_sequence(room, base).poses
    assert np.array_equal(run_sequence(replace(room, imu=None), base.replace(imu={"enabled": True})).poses,
                          lidar_only)  # (on, but the sequence has no IMU)
    with_imu = run_sequence(room, base.replace(imu={"enabled": True, "window_frames": 10}))
    # (until the filter has taken 10 frames after the first: constant velocity; from the 12th frame, the IMU)
    assert np.array_equal(with_imu.poses[:11], lidar_only[:11])
    assert not np.array_equal(with_imu.poses[11], lidar_only[11])
    truth = np.asarray(room.poses)
    truth = np.linalg.inv(truth[0]) @ truth
    for poses in (lidar_only, with_imu.poses):  # (a well-constrained room: the lidar holds either way)
        assert np.linalg.norm(poses[:, :3, 3] - truth[:, :3, 3], axis=1).max() < 0.05


def test_the_cold_start_is_no_prediction_to_the_filter(room, monkeypatch):
    """The second scan's registration holds to no guess (``motion_prior=False``): the filter takes its whole
    move as the data's, not as what the data added to a prediction (which the prior's blend would magnify by
    (w + lambda) / w); every later registration hands over the pose it started from."""
    calls = []
    original = InertialOdometry.update

    def recording(self, pose, time_s, information_world, usable, T_world_predicted=None, *args):
        calls.append(T_world_predicted)
        return original(self, pose, time_s, information_world, usable, T_world_predicted, *args)

    monkeypatch.setattr(InertialOdometry, "update", recording)
    run_sequence(room, variant("salo-map").replace(imu={"enabled": True}))
    assert len(calls) == len(room)
    assert calls[0] is None and calls[1] is None  # (the first scan, then the cold start)
    assert all(c is not None and c.shape == (4, 4) for c in calls[2:])


@pytest.mark.slow
def test_on_the_bare_tunnel_the_imu_holds_where_lidar_alone_drifts(tmp_path):
    """The bare tunnel from the open road (2 s) through the braking between bare walls (32 s), salo32 and a
    noise-free IMU: lidar alone runs on at the speed it had (the weak stretch's axis); with the IMU the
    motion along it is the IMU's, off only by what the approach left of gravity and velocity."""
    from simlidar.sensor import load_preset
    from tools.imu_odometry import measure
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    built = build_scene_world("bare-tunnel", 0, {})
    s = load_preset("salo32").with_overrides(imu={**NOISE_FREE, "enabled": True})
    path = simulate_scene(built, s, tmp_path / "bare", 300, seed=0, start_s=2.0).path
    (_, lidar), (_, imu) = measure(path, "salo-map", None)
    assert lidar["stretch"] == imu["stretch"]
    # lidar alone: metres along the axis by the stretch's end (the braking it cannot see: up to 1.5 m/s^2)
    assert abs(lidar["stretch_along_m"]) > 5.0
    assert imu["stretch_end_m"] < 0.1 * lidar["stretch_end_m"] and imu["t_err_pct"] < lidar["t_err_pct"]


def _drive(grade: str, frames: int, seed: int = 1):
    """The bare tunnel's approach from 2 s (the open road, constant speed): an IMU of ``grade`` at the lidar,
    and the true lidar poses (frames, 4, 4) every PERIOD_S in the first scan's frame with the truth's
    velocity at each (frames, 3)."""
    from simlidar.imu import imu_of_grade, simulate_imu

    trajectory = scenes.build_scene("bare-tunnel", 0).trajectory
    model = imu_of_grade(grade)
    samples, truth = simulate_imu(trajectory, model, 2.0, (frames + 1) * PERIOD_S, seed=seed)
    poses = trajectory.pose_at(2.0 + PERIOD_S * np.arange(frames))
    poses = np.linalg.inv(poses[0]) @ poses
    t = PERIOD_S * np.arange(frames)
    velocity = np.stack([np.interp(t, truth.time_s, truth.velocity[:, i]) for i in range(3)], axis=1)
    return samples, model, poses, velocity


def test_the_filter_finds_the_velocity_from_registered_positions():
    """Positions as exact as the filter is told (2 cm): once ready (20 frames) its velocity is within a few
    cm/s of the truth's, and stays there; the gravity it carries has the sensor file's magnitude."""
    samples, model, poses, velocity = _drive("consumer", 80)
    io = InertialOdometry(samples, model, ImuParams())
    errors = []
    for k, pose in enumerate(poses):
        io.update(pose, k * PERIOD_S, None, True)
        assert io.ready == (k >= 20)
        if io.ready:
            errors.append(np.linalg.norm(io.velocity - velocity[k]))
            assert abs(np.linalg.norm(io.gravity) - model.gravity_m_s2) < 1e-9
    # (a velocity error of e over a 0.1 s frame is e/10 of prediction error; 3 cm/s is 3 mm a frame)
    assert max(errors) < 0.03


def test_positions_without_information_leave_the_motion_unmeasured():
    """A registration with no information in any direction (open ground everywhere, say) is no evidence:
    the filter's velocity stays as uncertain as it started and gravity's direction keeps its prior's spread
    across it. (Holding gravity's magnitude by a tight measurement instead of the projection pins its
    direction only once positions move the estimate: the test above catches that one.)"""
    samples, model, poses, _ = _drive("consumer", 60)
    io = InertialOdometry(samples, model, ImuParams())
    for k, pose in enumerate(poses):
        io.update(pose, k * PERIOD_S, np.zeros((3, 3)), True)
    P = io.covariance
    assert np.sqrt(np.diag(P)[3:6]).min() > 50.0  # (started at 100 m/s: nothing measured it)
    g = io.state[6:9] / np.linalg.norm(io.state[6:9])
    tangent = np.linalg.eigvalsh(P[6:9, 6:9] - np.outer(g, g) * float(g @ P[6:9, 6:9] @ g))
    assert tangent[-2:].min() > 0.9  # (the prior's 1 (m/s^2)^2 on each direction across gravity)


def test_a_registration_held_to_its_prediction_is_no_evidence():
    """What the filter takes from a registration is what the data added to the pose it started from: along a
    direction without information, where the registration stayed at that pose, nothing (a prediction 0.5 m
    off there changes nothing); along one with information w, blended with the prior's lambda, the data's own
    position, the prediction plus (w + lambda) / w of the move."""
    import copy

    samples, model, poses, _ = _drive("consumer", 30)
    io = InertialOdometry(samples, model, ImuParams())
    for k in range(25):
        io.update(poses[k], k * PERIOD_S, None, True)
    info, lam = np.diag([0.0, 0.02, 0.2]), 0.01  # (per match: nothing along x, weak along y)
    off_x = poses[25].copy()
    off_x[0, 3] += 0.5
    a, b = copy.deepcopy(io), copy.deepcopy(io)
    a.update(poses[25], 2.5, info, True, T_world_predicted=poses[25], prior_eigenvalue=lam)
    b.update(off_x, 2.5, info, True, T_world_predicted=off_x, prior_eigenvalue=lam)
    assert np.allclose(a.state, b.state, atol=1e-12) and np.allclose(a.covariance, b.covariance, atol=1e-15)
    # (along y: started 0.1 m off the data's position, the registration moved w / (w + lambda) of the way)
    predicted, moved = poses[25].copy(), poses[25].copy()
    predicted[1, 3] += 0.1
    moved[1, 3] += 0.1 - 0.1 * 0.02 / (0.02 + lam)
    c, d = copy.deepcopy(io), copy.deepcopy(io)
    c.update(moved, 2.5, info, True, T_world_predicted=predicted, prior_eigenvalue=lam)
    d.update(poses[25], 2.5, info, True, T_world_predicted=poses[25], prior_eigenvalue=lam)
    assert np.allclose(c.state, d.state, atol=1e-9)
