"""The IMU between scans: preintegration, the next scan's predicted pose, the motion within a sweep,
and the velocity, gravity and biases fitted to the registered poses as the scans go.

Preintegration (Forster, Carlone, Dellaert and Scaramuzza, "On-Manifold Preintegration for
Real-Time Visual-Inertial Odometry", IEEE T-RO 2017, Sec. V-A): between IMU times t_i and t_j,
with the biases b_g, b_a held, in the IMU frame at t_i::

    dR = prod_k Exp((w_k - b_g) dt_k)
    dv = sum_k dR_k (a_k - b_a) dt_k
    dp = sum_k [dv_k dt_k + 1/2 dR_k (a_k - b_a) dt_k^2]

and the state at t_j follows from the state at t_i, gravity g (world) and Dt = t_j - t_i::

    R_j = R_i dR,   v_j = v_i + g Dt + R_i dv,   p_j = p_i + v_i Dt + 1/2 g Dt^2 + R_i dp.

Each step here takes the mean of its two end samples (interpolated linearly at t_i and t_j) and
dR_k at the step's middle, a midpoint form of Forster's Euler steps whose error falls with dt^2
(``preintegration_error_bound``); the first-order Jacobians of dv and dp in b_a go with it (their
Appendix, the same recursion), so a window's fit moves the accelerometer bias without integrating
again.

The estimator (``InertialOdometry``): a Kalman filter over the IMU origin's position and velocity,
gravity (world) and the accelerometer's bias, linear because the registered rotations carry each
preintegrated segment (so the gyroscope's drift does not enter). Between scans it propagates with
the segment (``_propagate``); at each scan it takes the registered position, each direction by the
registration's information in it and only what the registration added to the pose it started
from (``_correct``: a direction held to the prediction is no evidence), an extrapolated frame not at
all; gravity's magnitude is held by projection (``_hold_gravity_magnitude``). Each frame counts
once: the window's fit this replaced took the last fit as its prior while sharing all but one
frame with it, so the constants grew certain at once and kept what the first frames made of a cold
start's registrations for hundreds of frames. The IMU predicts once the filter has taken
``imu.window_frames`` frames. The gyroscope's bias is a weighted mean of what each segment's
rotation over the last ``imu.window_frames`` frames, against the registered rotations, says it is,
with the last estimate as its prior.

The lidar-to-IMU transform, the IMU's clock offset and gravity's magnitude come from the sensor
file's ``imu`` section (``simlidar.imu.ImuModel``; its defaults when it has none: the IMU at the
lidar, no offset).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from simlidar import se3
from simlidar.imu import ImuModel, ImuSamples

from .config import ImuParams


@dataclass
class Preintegrated:
    """The IMU's motion between two IMU times, in the IMU frame at the first (Forster's dR, dv, dp).

    dt_s: the span, s. dR: (3, 3). dv: (3,) m/s. dp: (3,) m. dv_dba, dp_dba: (3, 3) their first-order
    Jacobians in the accelerometer bias. gyro_bias (rad/s), accel_bias (m/s^2): (3,) the biases held.
    """

    dt_s: float
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dv_dba: np.ndarray
    dp_dba: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray

    def corrected(self, accel_bias: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dv, dp) for another accelerometer bias (3,), to first order."""
        d = np.asarray(accel_bias) - self.accel_bias
        return self.dv + self.dv_dba @ d, self.dp + self.dp_dba @ d


def preintegrate(samples: ImuSamples, t0: float, t1: float, gyro_bias: np.ndarray, accel_bias: np.ndarray
                 ) -> Preintegrated | None:
    """Forster's preintegration (module doc) of ``samples`` over the IMU times [t0, t1], s; None when the
    samples do not cover the span."""
    t = samples.time_s
    if not (t1 > t0) or len(t) < 2 or t[0] > t0 + 1e-9 or t[-1] < t1 - 1e-9:
        return None
    lo = max(int(np.searchsorted(t, t0, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(t, t1, side="left")) + 1, len(t))
    ts, w, a = t[lo:hi], samples.angular_velocity[lo:hi], samples.specific_force[lo:hi]
    inner = (ts > t0) & (ts < t1)
    times = np.concatenate([[t0], ts[inner], [t1]])
    wk = np.stack([np.interp(times, ts, w[:, i]) for i in range(3)], axis=1) - gyro_bias
    ak = np.stack([np.interp(times, ts, a[:, i]) for i in range(3)], axis=1) - accel_bias
    dR, dv, dp = np.eye(3), np.zeros(3), np.zeros(3)
    dv_dba, dp_dba = np.zeros((3, 3)), np.zeros((3, 3))
    for k in range(len(times) - 1):
        h = times[k + 1] - times[k]
        w_mean, a_mean = 0.5 * (wk[k] + wk[k + 1]), 0.5 * (ak[k] + ak[k + 1])
        R_mid = dR @ se3.rotation_of_rotvec(0.5 * h * w_mean)
        dp = dp + dv * h + 0.5 * (R_mid @ a_mean) * h * h
        dp_dba = dp_dba + dv_dba * h - 0.5 * R_mid * h * h
        dv = dv + (R_mid @ a_mean) * h
        dv_dba = dv_dba - R_mid * h
        dR = dR @ se3.rotation_of_rotvec(h * w_mean)
    return Preintegrated(float(t1 - t0), dR, dv, dp, dv_dba, dp_dba, np.array(gyro_bias, dtype=float),
                         np.array(accel_bias, dtype=float))


def preintegration_error_bound(dt_s: float, span_s: float, specific_force_m_s2: float, jerk_m_s3: float,
                               angular_rate_rad_s: float, angular_accel_rad_s2: float,
                               jerk_rate_m_s4: float = math.inf) -> tuple[float, float]:
    """Bounds (position m, rotation rad) on the error of ``preintegrate`` of noise-free samples every ``dt_s``
    over ``span_s`` (both s), for a motion whose specific force is at most f (m/s^2), changes at most J
    (m/s^3) and its rate of change at most J2 (m/s^4, when given), whose angular rate is at most w (rad/s) and
    changes at most alpha (rad/s^2), in the span.

    With h = dt_s and T = span_s, no cancellation assumed:

    - attitude: a step's rotation vector h (w_k + w_k+1) / 2 misses the rate's integral by at most
      alpha h^2 / 4 (the trapezoid rule for a rate that changes at most alpha) and the non-commuting part
      by w alpha h^3 / 12; over T / h steps, and the two interpolated end samples (each at most alpha h / 2
      off, for at most h): theta = alpha h T / 4 (1 + w h / 3) + alpha h^2;
    - acceleration, per unit time: the mean of a step's end samples misses the force's mean by at most
      min(J h / 4, J2 h^2 / 12) (the trapezoid rule's bounds); turning the force with the step's middle
      attitude instead of along the step leaves out w J h^2 / 12 + (w^2 + alpha) f h^2 / 24 (the odd
      first-order term integrates to zero); the middle attitude is off by at most theta, so
      E = f theta + min(J h / 4, J2 h^2 / 12) + w J h^2 / 12 + (w^2 + alpha) f h^2 / 24;
    - position: an acceleration error E over the span moves it by at most E T^2 / 2, and the two
      interpolated end samples (each at most min(J h / 2, J2 h^2 / 8) off, for at most h / 2 of weight)
      add that times h of velocity, for T.
    """
    h, T, f, J, w, a = dt_s, span_s, specific_force_m_s2, jerk_m_s3, angular_rate_rad_s, angular_accel_rad_s2
    theta = a * h * T / 4 * (1 + w * h / 3) + a * h * h
    E = f * theta + min(J * h / 4, jerk_rate_m_s4 * h * h / 12) + w * J * h * h / 12 + (w * w + a) * f * h * h / 24
    return E * T * T / 2 + min(J * h / 2, jerk_rate_m_s4 * h * h / 8) * h * T, theta


@dataclass
class _Record:
    """One registered frame: lidar time (s), pose (4, 4), whether its pose is a registration (not
    extrapolated), and the segment from the previous frame (None for the first)."""

    time_s: float
    pose: np.ndarray
    usable: bool
    segment: Preintegrated | None


@dataclass
class InertialPrediction:
    """The IMU's prediction of one scan: ``motion`` (4, 4) ``T_prev_cur``, and ``sweep`` (4, 4) the lidar's
    motion over the scan's own sweep (the next sweep's start in this one's start frame)."""

    motion: np.ndarray
    sweep: np.ndarray


# The filter's state: the IMU origin's position and velocity (world), gravity (world) and the accelerometer's
# bias (IMU frame), each (3,), in this order
_P, _V, _G, _B = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)


@dataclass
class InertialOdometry:
    """The IMU's state between scans (module doc): ``predict`` a scan's motion and sweep, ``update`` with
    its registered pose.

    samples: the sequence's IMU (``simlidar.imu.ImuSamples``, stamps in the IMU's clock, the sequence's
    time base). model: the sensor file's ``imu`` section (mounting, clock offset, gravity, noise).
    params: the config's ``imu`` section.
    """

    samples: ImuSamples
    model: ImuModel
    params: ImuParams
    velocity: np.ndarray | None = None  # (3,) the IMU origin's world velocity at the last frame, m/s
    gravity: np.ndarray | None = None  # (3,) world, m/s^2
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    records: deque = field(default_factory=deque)
    state: np.ndarray | None = None  # (12,) the filter's mean (position, velocity, gravity, bias), None: not started
    covariance: np.ndarray | None = None  # (12, 12)
    filtered_frames: int = 0  # frames the filter has taken since it started

    def __post_init__(self) -> None:
        self.T_lidar_imu = self.model.T_lidar_imu
        self.T_imu_lidar = se3.inverse(self.T_lidar_imu)
        self.records = deque(maxlen=self.params.window_frames)

    @property
    def ready(self) -> bool:
        """The filter has taken ``imu.window_frames`` frames: the IMU predicts."""
        return self.velocity is not None and self.gravity is not None

    def _imu_time(self, lidar_time_s: float) -> float:
        return lidar_time_s + self.model.time_offset_s

    def _segment(self, t0: float, t1: float) -> Preintegrated | None:
        return preintegrate(self.samples, self._imu_time(t0), self._imu_time(t1), self.gyro_bias, self.accel_bias)

    def _advance(self, T_world_imu: np.ndarray, v: np.ndarray, seg: Preintegrated) -> tuple[np.ndarray, np.ndarray]:
        """The IMU pose (4, 4) and velocity (3,) after ``seg`` from (T_world_imu, v)."""
        R, p, dt = T_world_imu[:3, :3], T_world_imu[:3, 3], seg.dt_s
        dv, dp = seg.corrected(self.accel_bias)
        out = np.eye(4)
        out[:3, :3] = R @ seg.dR
        out[:3, 3] = p + v * dt + 0.5 * self.gravity * dt * dt + R @ dp
        return out, v + self.gravity * dt + R @ dv

    def predict(self, T_world_prev: np.ndarray, prev_time_s: float | None, time_s: float | None,
                period_s: float) -> InertialPrediction | None:
        """The scan at lidar time ``time_s`` (its sweep ``period_s`` long) after the frame at ``T_world_prev``
        (4, 4) and ``prev_time_s``: None before the filter is ready, without times, or where the samples
        do not cover the span."""
        if not self.ready or prev_time_s is None or time_s is None or not self.records:
            return None
        seg = self._segment(prev_time_s, time_s)
        if seg is None:
            return None
        T_imu, v = self._advance(T_world_prev @ self.T_lidar_imu, self.velocity, seg)
        T_world_cur = T_imu @ self.T_imu_lidar
        motion = se3.inverse(T_world_prev) @ T_world_cur
        sweep_seg = self._segment(time_s, time_s + period_s)
        if sweep_seg is None:
            return InertialPrediction(motion, motion)
        T_next, _ = self._advance(T_imu, v, sweep_seg)
        return InertialPrediction(motion, se3.inverse(T_world_cur) @ (T_next @ self.T_imu_lidar))

    def reset(self) -> None:
        """Forget the motion (a break in the stamps or the samples): the filter starts again from the next
        two frames as at the first (``_start``); until it is ready again the IMU does not predict."""
        self.records.clear()
        self.state = self.covariance = self.velocity = None
        self.filtered_frames = 0

    def update(self, T_world_cur: np.ndarray, time_s: float | None, information_world: np.ndarray | None,
               usable: bool, T_world_predicted: np.ndarray | None = None, prior_eigenvalue: float = 0.0,
               weak_update: str = "prior") -> None:
        """Take a frame's registered pose (4, 4) at lidar time ``time_s``: the filter carried to it with the
        segment from the last frame, then corrected with its position. information_world: (3, 3) the
        registration's information on its translation per match (world), or None (all directions count).
        usable: the pose is a registration, not an extrapolation. T_world_predicted: (4, 4) the pose the
        registration started from and was held to in weak directions with ``prior_eigenvalue`` (the config's
        ``degeneracy.min_constraint_eigenvalue``) as ``weak_update`` says (``degeneracy.weak_direction_update``):
        what the registration added to it is the evidence (``_correct``)."""
        if time_s is None:  # (no stamps: nothing to integrate between; the filter starts again)
            self.reset()
            return
        seg = None
        if self.records:
            prev = self.records[-1]
            seg = self._segment(prev.time_s, time_s)
            if seg is None:  # (a gap in the samples: the chain breaks; start again)
                self.reset()
            else:
                if self.state is None:
                    self._start(prev, seg)
                self._propagate(prev.pose, seg)
                if usable:
                    predicted = None if T_world_predicted is None else (T_world_predicted @ self.T_lidar_imu)[:3, 3]
                    self._correct((T_world_cur @ self.T_lidar_imu)[:3, 3], information_world, predicted,
                                  prior_eigenvalue, weak_update)
                self._hold_gravity_magnitude()
                self.filtered_frames += 1
                self.gravity, self.accel_bias = self.state[_G].copy(), self.state[_B].copy()
                if self.filtered_frames >= self.params.window_frames:
                    self.velocity = self.state[_V].copy()
        self.records.append(_Record(float(time_s), np.array(T_world_cur), bool(usable), seg))
        if len(self.records) == self.records.maxlen:
            self._fit_gyro_bias()

    # ---- the filter
    def _start(self, first: _Record, seg: Preintegrated) -> None:
        """The state at the first frame: its registered position, velocity unknown, gravity along the mean
        specific force over the first segment (the vehicle's own acceleration is the error, loose), the
        accelerometer's bias zero with its turn-on spread."""
        s = self.samples.between(self._imu_time(first.time_s), self._imu_time(first.time_s + seg.dt_s))
        f = s.specific_force.mean(axis=0) if len(s) else np.array([0.0, 0.0, self.model.gravity_m_s2])
        f_world = first.pose[:3, :3] @ self.T_lidar_imu[:3, :3] @ f
        g = -self.model.gravity_m_s2 * f_world / max(np.linalg.norm(f_world), 1e-9)
        self.state = np.concatenate([(first.pose @ self.T_lidar_imu)[:3, 3], np.zeros(3), g, np.zeros(3)])
        ba_std = max(self.model.accelerometer_turn_on_bias, 1e-3)
        self.covariance = np.diag([self.params.position_std_m**2] * 3 + [100.0**2] * 3 + [1.0] * 3
                                  + [ba_std**2] * 3)

    def _propagate(self, T_world_prev: np.ndarray, seg: Preintegrated) -> None:
        """Carry the state over ``seg`` (Forster's chaining, linear in the state with the previous frame's
        registered rotation), its covariance with the accelerometer's noise, the bias's random walk and the
        registered rotation's error turning the segment's velocity and position changes."""
        x, R, dt = self.state, T_world_prev[:3, :3] @ self.T_lidar_imu[:3, :3], seg.dt_s
        dv, dp = seg.corrected(x[_B])
        I3 = np.eye(3)
        F = np.eye(12)
        F[_P, _V], F[_P, _G], F[_P, _B] = dt * I3, 0.5 * dt * dt * I3, R @ seg.dp_dba
        F[_V, _G], F[_V, _B] = dt * I3, R @ seg.dv_dba
        out = x.copy()
        out[_P] = x[_P] + x[_V] * dt + 0.5 * x[_G] * dt * dt + R @ dp
        out[_V] = x[_V] + x[_G] * dt + R @ dv
        na, rot = self.model.accelerometer_noise_density**2, math.radians(self.params.rotation_std_deg) ** 2
        Q = np.zeros((12, 12))
        Q[_P, _P] = (na * dt**3 / 3 + rot * float(dp @ dp)) * I3
        Q[_P, _V] = Q[_V, _P] = na * dt * dt / 2 * I3
        Q[_V, _V] = (na * dt + rot * float(dv @ dv)) * I3
        Q[_B, _B] = self.model.accelerometer_random_walk**2 * dt * I3
        self.state, self.covariance = out, F @ self.covariance @ F.T + Q

    def _measure(self, H: np.ndarray, residual: np.ndarray) -> None:
        """A whitened linear measurement: rows ``H`` (m, 12) of unit noise, ``residual`` (m,) = measured - H x."""
        P = self.covariance
        S = H @ P @ H.T + np.eye(len(H))
        K = np.linalg.solve(S, H @ P).T
        A = np.eye(12) - K @ H
        self.state = self.state + K @ residual
        self.covariance = A @ P @ A.T + K @ K.T  # (Joseph's form: stays symmetric and positive)

    def _correct(self, position: np.ndarray, information: np.ndarray | None, predicted: np.ndarray | None = None,
                 prior_eigenvalue: float = 0.0, weak_update: str = "prior") -> None:
        """The registered IMU origin (3,) as evidence. Along each direction of the registration's translation
        information (``information`` (3, 3) per match; None: every direction full), w: the position counts with
        sqrt(min(3 w, 1)) / ``position_std_m`` (1/3 per match is the most one direction can have among three,
        ``odometry.constraints``). Where the registration was held to its prior (``predicted`` (3,), with
        information ``prior_eigenvalue`` = lambda per match), only what the data moved it counts: with the prior
        blended in (``weak_update`` "prior", ``odometry.constraints.remapped_step``) the data's own position is
        predicted + (w + lambda) / w (position - predicted); a direction kept at the prior ("remap", w < lambda)
        says nothing. Taking the blend itself would count the prediction, the filter's own or a constant
        velocity's, as a measurement of the motion."""
        W, evidence = np.eye(3), np.array(position, dtype=float)
        if information is not None:
            w, V = np.linalg.eigh(information)
            w = np.clip(w, 0.0, None)
            scale = np.sqrt(np.clip(w * 3.0, 0.0, 1.0))
            if predicted is not None and prior_eigenvalue > 0:
                if weak_update == "prior":
                    moved = (V.T @ (position - predicted)) * (w + prior_eigenvalue) / np.maximum(w, 1e-12)
                    evidence = predicted + V @ moved
                else:
                    scale = np.where(w < prior_eigenvalue, 0.0, scale)
            W = (V * scale) @ V.T
        W = W / self.params.position_std_m
        H = np.zeros((3, 12))
        H[:, _P] = W
        self._measure(H, W @ (evidence - self.state[_P]))

    def _hold_gravity_magnitude(self) -> None:
        """Gravity's magnitude is the sensor file's: the mean scaled to it and the covariance kept to the
        sphere's tangent plane there. (A tight measurement of the magnitude, linearised about each frame's
        estimate, would constrain a slightly different direction each time and so, over frames, the
        direction of gravity too: information nobody measured.)"""
        g = self.state[_G]
        unit = g / np.linalg.norm(g)
        self.state[_G] = self.model.gravity_m_s2 * unit
        Pi = np.eye(12)
        Pi[_G, _G] -= np.outer(unit, unit)
        self.covariance = Pi @ self.covariance @ Pi.T

    def _fit_gyro_bias(self) -> None:
        """The gyroscope's bias: each segment between registered frames says ``b_s - Log(dR_s^T dR_lidar) / Dt``
        (its rotation integrated with b_s against the registered one); their weighted mean with the last
        estimate as a prior."""
        recs = list(self.records)
        rot_var = math.radians(self.params.rotation_std_deg) ** 2 * 2  # (two poses' errors in each relative rotation)
        window_s = recs[-1].time_s - recs[0].time_s
        prior_std = max(self.model.gyroscope_turn_on_bias, self.model.gyroscope_random_walk * math.sqrt(window_s),
                        1e-7)
        info, total = 1.0 / prior_std**2, self.gyro_bias / prior_std**2
        for a, b in zip(recs[:-1], recs[1:], strict=True):
            if not (a.usable and b.usable) or b.segment is None:
                continue
            R_a, R_b = a.pose[:3, :3] @ self.T_lidar_imu[:3, :3], b.pose[:3, :3] @ self.T_lidar_imu[:3, :3]
            seg = b.segment
            said = seg.gyro_bias - se3.rotvec_of_rotation(seg.dR.T @ (R_a.T @ R_b)) / seg.dt_s
            weight = seg.dt_s**2 / rot_var
            info, total = info + weight, total + weight * said
        self.gyro_bias = total / info


__all__ = ["InertialOdometry", "InertialPrediction", "Preintegrated", "preintegrate", "preintegration_error_bound"]
