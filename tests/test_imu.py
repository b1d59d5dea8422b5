"""The simulated IMU against the truth: the trajectory's derivatives, the lever arm, dead reckoning, the noise."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import scenes
from scenes.geometry import SmoothField
from scenes.trajectory import PathTrajectory
from simlidar.imu import ImuModel, noise, simulate_imu, true_motion
from tools.imu_check import MOUNTING, allan_deviation, allan_model, dead_reckon, integration_error_bound, reckon_truth


def s_curve(length=400.0, step=0.5):
    """A gentle S in plan with a grade that rolls between -3 % and +3 %, (m, 3)."""
    x = np.arange(0.0, length + step / 2, step)
    return np.column_stack([x, 12.0 * np.sin(x / 60.0), 0.03 * 40.0 * np.sin(x / 40.0)])


def curvy(smoothing=1.0, stops=((200.0, 3.0),)):
    terrain = SmoothField(np.random.default_rng(3), 0.4, (40.0, 120.0))
    return PathTrajectory(s_curve(), False, 12.0, 1.5, 2.0, 1.9, math.radians(0.3), 0.01, seed=2,
                          surface_height=terrain, accel_smoothing_s=smoothing, stops=stops)


def cumulative_trapezoid(y: np.ndarray, h: float) -> np.ndarray:
    return np.concatenate([np.zeros((1,) + y.shape[1:]), np.cumsum(h * (y[1:] + y[:-1]) / 2, axis=0)])


def trapezoid_bound(dy: np.ndarray, h: float) -> float:
    """The composite trapezoid rule's error bound for the integral of y over the samples, from the total
    variation of y' (its samples' differences ``dy`` / h): h^2 / 8 TV(y') (Peano kernel)."""
    return h**2 / 8 * float(np.sum(np.linalg.norm(np.diff(dy / h, axis=0), axis=1)))


def test_kinematics_are_the_derivatives_of_the_poses_smoothed():
    # Integrals are exact however the derivatives step: the velocity integrates to the positions, the
    # acceleration to the velocity, the angular acceleration to the angular velocity, each within the
    # trapezoid rule's own bound (h^2 / 8 times the integrand's derivative's variation, from the samples)
    tr = curvy(1.0)
    h = 1e-3
    t = np.arange(-0.5, tr.duration_s + 0.5, h)
    k = tr.kinematics_at(t)
    np.testing.assert_array_equal(k.pose, tr.pose_at(t))
    for integral, integrand in ((k.pose[:, :3, 3], k.velocity), (k.velocity, k.acceleration),
                                (k.angular_velocity, k.angular_acceleration)):
        got = cumulative_trapezoid(integrand, h)
        bound = trapezoid_bound(np.diff(integrand, axis=0), h) + 1e-9  # + the positions' rounding
        assert np.abs(got - (integral - integral[0])).max() <= bound
    check_angular_velocity(tr, t[::50], k.angular_velocity[::50])


def test_kinematics_are_the_derivatives_of_the_poses_raw():
    # The raw profile's acceleration steps at its knots (and, through the oscillation's speed scaling, the
    # velocity by mm/s): central differences of the poses, farther from the knots (the path spline's, the
    # profile's and the body mode spline's, where a third derivative steps) than the step h, against the
    # kinematics. Errors: the positions' rounding (~1e-13 m) over
    # h^2, 4e-5 m/s^2 at h = 1e-4 s; truncation h^2 / 12 times the fourth derivative, below 1e-7.
    tr = curvy(0.0)
    h = 1e-4
    t = np.sort(np.random.default_rng(0).uniform(0.0, tr.duration_s, 4000))
    knots = np.concatenate([tr._raw.t, tr.time_at_distance(tr._spline.x), tr._tb])
    t = t[np.abs(t[:, None] - knots[None]).min(axis=1) > 2 * h]
    k = tr.kinematics_at(t)
    p = [tr.pose_at(t + d)[:, :3, 3] for d in (-h, 0.0, h)]
    np.testing.assert_allclose(k.velocity, (p[2] - p[0]) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(k.acceleration, (p[2] - 2 * p[1] + p[0]) / h**2, atol=2e-4)
    w = [tr.kinematics_at(t + d).angular_velocity for d in (-h, h)]
    np.testing.assert_allclose(k.angular_acceleration, (w[1] - w[0]) / (2 * h), atol=1e-5)
    check_angular_velocity(tr, t, k.angular_velocity)


def check_angular_velocity(tr, t, w):
    """The angular velocity in the lidar frame, dR/dt = R [w]x, against the rotations' central difference
    (error h^2 |w''| / 6, and h |step| where the angular acceleration steps: steps < 10 rad/s^2 here)."""
    hh = 1e-6
    Rm, Rp = tr.pose_at(t - hh)[:, :3, :3], tr.pose_at(t + hh)[:, :3, :3]
    w_fd = Rotation.from_matrix(np.swapaxes(Rm, 1, 2) @ Rp).as_rotvec() / (2 * hh)
    R0 = tr.pose_at(t)[:, :3, :3]
    w_mid = np.einsum("nji,nj->ni", R0, np.einsum("nij,nj->ni", Rm, w_fd))  # the midpoint's frame
    np.testing.assert_allclose(w_mid, w, atol=1e-5 + 10 * hh)


def test_smoothing_makes_the_acceleration_continuous_and_the_stop_waits():
    raw, smooth = curvy(0.0, ()), curvy(1.0, ())
    h = 1e-3
    for tr, steps in ((raw, True), (smooth, False)):
        t = np.arange(0.0, tr.duration_s, h)
        a = tr._profile(t)[2]
        # raw: the acceleration steps by up to accel_m_s2; smoothed: it changes by at most 4 / tau^2 * 1.5 * h^2
        # per step of h (the snap's bound), plus the jerk's h * 4 * 1.5 / tau
        jump = np.abs(np.diff(a)).max()
        assert (jump > 1.0) if steps else (jump <= 4 * 1.5 * h + 4 * 1.5 * h**2)
    # the motion lags the raw profile by tau / 2 and lasts tau longer
    assert smooth.duration_s == pytest.approx(raw.duration_s + 1.0, abs=1e-9)
    stopping = curvy(1.0, ((200.0, 3.0),))
    raw = stopping._raw
    wait = int(np.flatnonzero(np.isclose(np.diff(raw.t), 3.0))[0])  # the wait's segment, at the step nearest 200 m
    assert raw.s[wait] == pytest.approx(200.0, abs=0.13)
    t_leave = stopping.time_at_distance(raw.s[wait : wait + 1])[0]
    during = np.linspace(t_leave - 1.95, t_leave - 0.05, 30)  # standing: the 3 s wait less the 1 s window
    assert np.all(np.abs(stopping.speed_at(during)) < 1e-9)
    assert stopping.speed_at(np.array([t_leave + 0.1]))[0] > 0
    np.testing.assert_allclose(stopping.distance_at(during), raw.s[wait], atol=1e-9)
    assert stopping.duration_s > smooth.duration_s + 3.0


@dataclass
class Spin:
    """A lidar at the origin turning about its z axis: yaw = w0 t + alpha t^2 / 2 (an exact test motion)."""

    w0: float
    alpha: float

    def pose_at(self, t):
        t = np.atleast_1d(t)
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = Rotation.from_euler("z", (self.w0 * t + self.alpha * t**2 / 2)[:, None]).as_matrix()
        return T

    def kinematics_at(self, t):
        from scenes.trajectory import Kinematics

        t = np.atleast_1d(t)
        z = np.zeros((len(t), 3))
        w = z.copy()
        w[:, 2] = self.w0 + self.alpha * t
        al = z.copy()
        al[:, 2] = self.alpha
        return Kinematics(self.pose_at(t), z, z, w, al)


def test_an_imu_on_a_spinning_arm_feels_the_centripetal_and_tangential_forces():
    spin = Spin(w0=2.0, alpha=0.5)
    model = ImuModel(enabled=True, lever_arm_m=(1.5, 0.0, 0.0), rotation_rpy_deg=(0.0, 0.0, 90.0))
    t = np.array([0.0, 1.0])
    gyro, accel, T_wi, v = true_motion(spin, model, t)
    w = 2.0 + 0.5 * t
    # in the lidar frame: centripetal -w^2 r along x, tangential alpha r along y, gravity's reaction +g z;
    # the IMU's x axis is the lidar's y, its y the lidar's -x
    lidar_force = np.column_stack([-(w**2) * 1.5, np.full(2, 0.5 * 1.5), np.full(2, model.gravity_m_s2)])
    np.testing.assert_allclose(accel, np.column_stack([lidar_force[:, 1], -lidar_force[:, 0], lidar_force[:, 2]]),
                               atol=1e-12)
    np.testing.assert_allclose(gyro, np.column_stack([np.zeros(2), np.zeros(2), w]), atol=1e-12)
    speed = np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(speed, w * 1.5, atol=1e-12)
    np.testing.assert_allclose(T_wi[:, :3, 3], spin.pose_at(t)[:, :3, :3] @ np.array([1.5, 0.0, 0.0]), atol=1e-12)


def test_at_rest_the_accelerometer_reads_gravity_along_the_imu_up_axis():
    tr = curvy()
    model = ImuModel(enabled=True, rotation_rpy_deg=(180.0, 0.0, 0.0), lever_arm_m=(0.2, 0.1, -0.3))
    gyro, accel, T_wi, _ = true_motion(tr, model, np.array([-5.0]))  # before the start: standing
    R_wi = T_wi[0, :3, :3]
    np.testing.assert_allclose(accel[0], R_wi.T @ np.array([0.0, 0.0, model.gravity_m_s2]), atol=1e-9)
    assert accel[0, 2] < -9.7  # upside down: z reads -g
    np.testing.assert_allclose(gyro[0], 0.0, atol=1e-12)


MOUNTED = MOUNTING


def test_dead_reckoning_reproduces_the_trajectory_within_the_schemes_bound():
    # The noise-free IMU of the bare tunnel (continuous acceleration), integrated from the true initial
    # state: within the bound the scheme's error terms give (tools.imu_check.integration_error_bound), after
    # 10 s and 60 s; and the error falls as dt^2 (a second-order scheme), which a model error would not do.
    traj = scenes.build_scene("bare-tunnel").trajectory
    errors = {}
    for rate in (200.0, 400.0):
        model = ImuModel(enabled=True, update_rate=rate, **MOUNTED)
        _, truth = simulate_imu(traj, model, 2.0, 60.0, seed=0)
        t, e_p, _ = reckon_truth(truth)
        errors[rate] = e_p
        if rate == 200.0:
            tb, bound = integration_error_bound(traj, model, 2.0, 60.0)
            np.testing.assert_allclose(tb, t, atol=1e-12)
            for s in (10.0, 60.0):
                k = int(round(s * rate))
                assert e_p[k] <= bound[k], (s, e_p[k], bound[k])
            # what the bound is worth: a specific-force bias it does not cover after 10 s is a few mm/s^2
            assert 2 * bound[2000] / 10.0**2 < 5e-4
    for s in (10.0, 60.0):
        order = math.log2(errors[200.0][int(200 * s)] / errors[400.0][int(400 * s)])
        assert order > 1.5, (s, order)  # 2 for a second-order scheme; 0 for a model error that dt does not shrink


def test_the_noise_matches_kalibrs_densities_and_random_walks():
    model = ImuModel(enabled=True)
    n = 200 * 600  # ten minutes at 200 Hz
    white_g, bias_g, white_a, bias_a = noise(model, n, seed=5)
    # White-noise region: the overlapping Allan deviation at tau = m dt against sqrt(N^2 / tau + K^2 tau / 3).
    # Tolerance: 5 standard errors of an Allan deviation from M = n / m non-overlapping clusters, 1 / sqrt(2 (M -
    # 1)) relative (the overlapping estimator's is smaller), over 3 axes x 4 taus.
    m = np.array([2, 10, 20, 40])
    tau = m / model.update_rate
    for x, density, walk in ((white_g + bias_g, model.gyroscope_noise_density, model.gyroscope_random_walk),
                             (white_a + bias_a, model.accelerometer_noise_density, model.accelerometer_random_walk)):
        ratio = allan_deviation(x, model.update_rate, m) / allan_model(tau, density, walk)[:, None]
        tolerance = 5 / np.sqrt(2 * (n // m - 1))
        assert np.all(np.abs(ratio - 1) < tolerance[:, None]), ratio
    # The bias random walk: its increments have variance K^2 dt (sample variance of n - 1 normal increments:
    # relative standard error sqrt(2 / (n - 1)); 5 of them).
    dt = model.sample_period_s
    for bias, walk in ((bias_g, model.gyroscope_random_walk), (bias_a, model.accelerometer_random_walk)):
        var = np.mean(np.diff(bias, axis=0) ** 2, axis=0)
        assert np.all(np.abs(var / (walk**2 * dt) - 1) < 5 * np.sqrt(2 / (n - 1)))
    # the turn-on bias: drawn per axis from its standard deviation, the first sample's bias
    on = ImuModel(enabled=True, gyroscope_turn_on_bias=0.01, accelerometer_turn_on_bias=0.05)
    starts = np.array([np.concatenate([noise(on, 1, seed)[1][0], noise(on, 1, seed)[3][0]]) for seed in range(400)])
    # 1200 draws per sensor: the sample standard deviation within 5 x 1 / sqrt(2 * 1200) relative
    assert np.std(starts[:, :3]) == pytest.approx(0.01, rel=5 / np.sqrt(2400))
    assert np.std(starts[:, 3:]) == pytest.approx(0.05, rel=5 / np.sqrt(2400))


def test_imu_samples_are_seeded_and_the_truth_adds_up():
    traj = curvy()
    model = ImuModel(enabled=True, gyroscope_turn_on_bias=0.002, accelerometer_turn_on_bias=0.02, **MOUNTED)
    a, ta = simulate_imu(traj, model, 3.0, 5.0, seed=7)
    b, _ = simulate_imu(traj, model, 3.0, 5.0, seed=7)
    c, _ = simulate_imu(traj, model, 3.0, 5.0, seed=8)
    np.testing.assert_array_equal(a.specific_force, b.specific_force)
    assert not np.allclose(a.specific_force, c.specific_force)
    assert len(a) == 1001 and a.time_s[0] == 0.0 and a.time_s[-1] == pytest.approx(5.0)
    # stamps are the IMU's clock: each measured the motion time_offset_s earlier
    np.testing.assert_allclose(ta.true_time_s, a.time_s - 0.004)
    gyro, accel, _, _ = true_motion(traj, model, 3.0 + ta.true_time_s)
    np.testing.assert_allclose(ta.angular_velocity, gyro, atol=1e-15)
    # measured = truth + bias + white noise, the white part of the set density
    white = a.angular_velocity - ta.angular_velocity - ta.gyroscope_bias
    assert np.std(white) == pytest.approx(model.gyroscope_noise_density * math.sqrt(200.0), rel=0.1)
    # the truth's pose: the lidar's at the first sweep start is the frame of the positions
    T_f = traj.pose_at(np.array([3.0]))[0]
    T_i = traj.pose_at(3.0 + ta.true_time_s[:1])[0] @ model.T_lidar_imu
    np.testing.assert_allclose(ta.position[0], (np.linalg.inv(T_f) @ T_i)[:3, 3], atol=1e-9)
    np.testing.assert_allclose(ta.rotation()[0], (np.linalg.inv(T_f) @ T_i)[:3, :3], atol=1e-9)


def test_dead_reckon_is_exact_for_constant_acceleration_and_rate():
    # a body spinning at a constant rate about its z axis and accelerating along world x: the scheme is
    # exact for rates and world accelerations linear between samples (to rounding)
    t = np.linspace(0.0, 2.0, 401)
    w = np.tile([0.0, 0.0, 0.7], (len(t), 1))
    R = Rotation.from_euler("z", (0.7 * t)[:, None]).as_matrix()
    g = np.array([0.0, 0.0, -9.8])
    a_world = np.tile([0.3, 0.0, 0.0], (len(t), 1))
    f = np.einsum("nji,nj->ni", R, a_world - g)
    Ri, p, v = dead_reckon(t, w, f, R[0], np.zeros(3), np.array([1.0, 0.0, 0.0]), g)
    np.testing.assert_allclose(Ri, R, atol=1e-12)
    np.testing.assert_allclose(p[:, 0], t + 0.15 * t**2, atol=1e-12)
    np.testing.assert_allclose(v[-1], [1.6, 0.0, 0.0], atol=1e-12)


def test_a_trajectory_without_derivatives_cannot_carry_an_imu():
    from simlidar.imu import ImuUnavailable
    from simlidar.trajectory import SampledTrajectory

    traj = SampledTrajectory(np.array([0.0, 1.0]), np.tile(np.eye(4), (2, 1, 1)))
    with pytest.raises(ImuUnavailable, match="SampledTrajectory.*no continuous acceleration"):
        simulate_imu(traj, ImuModel(enabled=True), 0.0, 1.0)
    # a surface given without its derivatives cannot give the roll's
    flat = PathTrajectory(s_curve(), False, 10.0, 1.5, 2.0, 1.9, surface_height=lambda x, y: 0.0 * x)
    with pytest.raises(ValueError, match="surface_height has no gradient and hessian"):
        flat.kinematics_at(np.array([1.0]))


def test_an_imu_grade_sets_its_noise_and_keeps_the_mounting():
    from simlidar.imu import IMU_GRADES, imu_of_grade

    mounted = ImuModel(lever_arm_m=(0.5, 0.0, 0.1), time_offset_s=0.004, update_rate=400.0)
    for grade, keys in IMU_GRADES.items():
        model = imu_of_grade(grade, mounted)
        assert model.enabled and all(getattr(model, k) == v for k, v in keys.items()), grade
        assert (model.lever_arm_m, model.time_offset_s, model.update_rate) == ((0.5, 0.0, 0.1), 0.004, 400.0)
    # the tactical unit is the quieter on every key
    assert all(IMU_GRADES["tactical"][k] < IMU_GRADES["consumer"][k] for k in IMU_GRADES["consumer"])
    with pytest.raises(ValueError, match="unknown IMU grade 'navigation'.*consumer"):
        imu_of_grade("navigation")
