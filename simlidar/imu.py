"""An IMU riding with the lidar: gyroscope and accelerometer from the trajectory's exact motion, with noise.

The model (``ImuModel``, the ``imu`` section of a sensor file, off by default)
uses Kalibr's noise parameters, names and units (the Kalibr wiki's "IMU Noise
Model"): white noise of density ``gyroscope_noise_density`` (rad/s/sqrt(Hz)) and
``accelerometer_noise_density`` (m/s^2/sqrt(Hz)), and biases that random-walk
with ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)) and ``accelerometer_random_walk``
(m/s^3/sqrt(Hz)). Sampled every dt = 1 / ``update_rate`` seconds, per axis::

    measured[k] = true[k] + bias[k] + sigma_noise / sqrt(dt) * n[k]
    bias[k + 1] = bias[k] + sigma_walk * sqrt(dt) * w[k],   bias[0] ~ N(0, turn_on^2)

with n, w independent standard normal draws. The turn-on bias is drawn once per
seed and axis (``*_turn_on_bias`` is its standard deviation).

The true values are the exact derivatives of the lidar's trajectory
(``kinematics_at``, e.g. ``scenes.trajectory.PathTrajectory``'s), carried to the
IMU: its origin sits at ``lever_arm_m`` in the lidar frame, its axes are
``R_lidar_imu = Rz(yaw) Ry(pitch) Rx(roll)`` of ``rotation_rpy_deg``. With the
lidar's world pose (R, p), body angular velocity w and acceleration alpha (lidar
frame) and the acceleration a of its origin (world)::

    angular rate   = R_lidar_imu^T w
    specific force = R_lidar_imu^T (R^T (a - g) + alpha x r + w x (w x r)),   g = (0, 0, -gravity_m_s2)

(the lever-arm terms are the IMU origin's acceleration relative to the lidar's).
At rest on level ground the accelerometer reads +gravity along the IMU's up axis.

Time: sample k is stamped ``tau_k = k dt`` in the sequence's time base (seconds
since the first sweep's start, as ``times.txt``) and measures the motion at
``tau_k - time_offset_s``: an IMU whose clock runs ``time_offset_s`` ahead of the
lidar's (Kalibr's ``timeshift_cam_imu``, with the lidar as the camera: t_imu =
t_lidar + shift). Samples run from the first sweep's start to the last sweep's end.

Noise comes from its own generator (seeded with the simulation's seed and a tag),
so the lidar's returns are the same with the IMU on or off, and the same seed gives
the same samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from paramspec import ParamError, Params, param

GRAVITY_M_S2 = 9.80665  # standard gravity
SEED_TAG = 0x1A0  # the IMU noise's own stream, beside the seed


class ImuUnavailable(ValueError):
    """An IMU was asked for along a trajectory that gives no derivatives (poses from a file)."""


def _three(values: tuple[float, ...]) -> str | None:
    return None if len(values) == 3 else f"must have 3 entries (x, y, z or roll, pitch, yaw), got {len(values)}"


@dataclass(frozen=True)
class ImuModel(Params):
    """an IMU riding with the lidar: rate, Kalibr's noise model, turn-on bias, mounting and clock offset"""

    error = ParamError
    section_name = "imu"

    enabled: bool = param(False, "simulate an IMU (imu.csv and imu_truth.csv beside the scans, an Imu topic in a "
                          "bag)")
    update_rate: float = param(200.0, "samples per second (Kalibr's update_rate)", unit="Hz", above=0.0,
                               max=10000.0)
    gyroscope_noise_density: float = param(1.6968e-4, "white noise of the angular rate (Kalibr's sigma_g)",
                                           unit="rad/s/sqrt(Hz)", min=0.0)
    gyroscope_random_walk: float = param(1.9393e-5, "random walk of the gyroscope's bias (Kalibr's sigma_bg)",
                                         unit="rad/s^2/sqrt(Hz)", min=0.0)
    accelerometer_noise_density: float = param(2.0e-3, "white noise of the specific force (Kalibr's sigma_a)",
                                               unit="m/s^2/sqrt(Hz)", min=0.0)
    accelerometer_random_walk: float = param(3.0e-3, "random walk of the accelerometer's bias (Kalibr's sigma_ba)",
                                             unit="m/s^3/sqrt(Hz)", min=0.0)
    gyroscope_turn_on_bias: float = param(0.0, "standard deviation of the gyroscope's bias at switch-on, drawn per "
                                          "axis and seed", unit="rad/s", min=0.0)
    accelerometer_turn_on_bias: float = param(0.0, "standard deviation of the accelerometer's bias at switch-on, "
                                              "drawn per axis and seed", unit="m/s^2", min=0.0)
    lever_arm_m: tuple[float, ...] = param((0.0, 0.0, 0.0), "the IMU's origin in the lidar frame (x, y, z)",
                                           check=_three)
    rotation_rpy_deg: tuple[float, ...] = param(
        (0.0, 0.0, 0.0), "the IMU's axes in the lidar frame, roll, pitch, yaw: R_lidar_imu = Rz(yaw) Ry(pitch) "
        "Rx(roll)", check=_three)
    time_offset_s: float = param(0.0, "the IMU's stamp minus the lidar's clock at the same instant (Kalibr's "
                                 "timeshift_cam_imu)", min=-1.0, max=1.0)
    gravity_m_s2: float = param(GRAVITY_M_S2, "gravity's magnitude, along the world's -z", above=0.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        for key in ("lever_arm_m", "rotation_rpy_deg"):
            object.__setattr__(self, key, tuple(float(v) for v in getattr(self, key)))

    @property
    def sample_period_s(self) -> float:
        return 1.0 / self.update_rate

    @property
    def rotation_lidar_imu(self) -> np.ndarray:
        """(3, 3) ``R_lidar_imu``: IMU axes in the lidar frame."""
        from scipy.spatial.transform import Rotation

        roll, pitch, yaw = self.rotation_rpy_deg
        return Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()

    @property
    def T_lidar_imu(self) -> np.ndarray:
        """(4, 4) the IMU frame in the lidar frame."""
        T = np.eye(4)
        T[:3, :3] = self.rotation_lidar_imu
        T[:3, 3] = self.lever_arm_m
        return T

    def to_dict(self) -> dict:
        """The keys as YAML writes them (lists, not tuples)."""
        out = super().to_dict()
        for key in ("lever_arm_m", "rotation_rpy_deg"):
            out[key] = list(out[key])
        return out


# Two IMU grades, in ImuModel's keys (docs/imu.md): a consumer MEMS unit (noise as EuRoC's ADIS16448
# in Kalibr's figures, 0.3 deg/s and 5 mg turn-on biases) and a tactical-grade unit (0.05 deg/sqrt(h),
# 30 ug/sqrt(Hz), 1 deg/h and 100 ug turn-on biases). What ``salo simulate --imu GRADE`` and the suite's
# ``--imu GRADE`` give.
IMU_GRADES = {
    "consumer": {"gyroscope_noise_density": 2.4e-4, "gyroscope_random_walk": 2.0e-5,
                 "accelerometer_noise_density": 2.0e-3, "accelerometer_random_walk": 3.0e-3,
                 "gyroscope_turn_on_bias": 5e-3, "accelerometer_turn_on_bias": 0.05},
    "tactical": {"gyroscope_noise_density": 1.5e-5, "gyroscope_random_walk": 1.0e-7,
                 "accelerometer_noise_density": 3.0e-4, "accelerometer_random_walk": 3.0e-5,
                 "gyroscope_turn_on_bias": 5e-6, "accelerometer_turn_on_bias": 1e-3},
}


def imu_of_grade(grade: str, base: ImuModel | None = None) -> ImuModel:
    """``base`` (the defaults: at the lidar's origin, no clock offset) switched on with the noise of ``grade``
    (a key of ``IMU_GRADES``); its mounting, rate and clock kept. Raises ValueError for an unknown grade."""
    if grade not in IMU_GRADES:
        raise ValueError(f"unknown IMU grade {grade!r} (known: {', '.join(IMU_GRADES)})")
    return replace(base or ImuModel(), enabled=True, **IMU_GRADES[grade])


@dataclass
class ImuSamples:
    """What an IMU reports, n samples in time order.

    time_s: (n,) stamps, s, in the sequence's time base (seconds since the first sweep's start).
    angular_velocity: (n, 3) rad/s, IMU frame. specific_force: (n, 3) m/s^2, IMU frame (what an
    accelerometer measures: at rest, +g along the up axis). frame_id: the IMU frame's name.
    """

    time_s: np.ndarray
    angular_velocity: np.ndarray
    specific_force: np.ndarray
    frame_id: str = "imu"

    def __len__(self) -> int:
        return len(self.time_s)

    def between(self, t0: float, t1: float) -> ImuSamples:
        """The samples stamped in [t0, t1] (s)."""
        keep = (self.time_s >= t0) & (self.time_s <= t1)
        return ImuSamples(self.time_s[keep], self.angular_velocity[keep], self.specific_force[keep], self.frame_id)


@dataclass
class ImuTruth:
    """The truth of each IMU sample (n samples, the order of ``ImuSamples``).

    time_s: (n,) stamps, s. true_time_s: (n,) the instant each measured (stamp - time_offset_s), s, same
    time base. angular_velocity, specific_force: (n, 3) noise-free and bias-free values, IMU frame.
    gyroscope_bias (rad/s), accelerometer_bias (m/s^2): (n, 3) the biases in each sample.
    position: (n, 3) the IMU's origin, m; orientation: (n, 4) quaternion x, y, z, w of ``R_first_imu``;
    velocity: (n, 3) of the IMU's origin, m/s; all in the first scan's frame (the frame of ``poses.txt``).
    gravity: (3,) gravity in the first scan's frame, m/s^2.
    """

    time_s: np.ndarray
    true_time_s: np.ndarray
    angular_velocity: np.ndarray
    specific_force: np.ndarray
    gyroscope_bias: np.ndarray
    accelerometer_bias: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray
    gravity: np.ndarray

    def __len__(self) -> int:
        return len(self.time_s)

    def rotation(self) -> np.ndarray:
        """(n, 3, 3) ``R_first_imu`` from the quaternions."""
        from scipy.spatial.transform import Rotation

        return Rotation.from_quat(self.orientation).as_matrix()


def sample_times(model: ImuModel, duration_s: float) -> np.ndarray:
    """(n,) stamps k / update_rate from 0 to ``duration_s`` (both included when it is a whole number of periods), s."""
    n = int(math.floor(duration_s * model.update_rate + 1e-9)) + 1
    return np.arange(n) / model.update_rate


def true_motion(trajectory, model: ImuModel, times_s: np.ndarray):
    """The IMU's noise-free readings and state at trajectory times ``times_s`` (n,), s.

    Returns (angular rate (n, 3) rad/s, specific force (n, 3) m/s^2, both in the IMU frame; the IMU's
    world pose (n, 4, 4) ``T_world_imu``; its origin's world velocity (n, 3), m/s). Raises
    ``ImuUnavailable`` when the trajectory gives no ``kinematics_at``.
    """
    kinematics_at = getattr(trajectory, "kinematics_at", None)
    if kinematics_at is None:
        raise ImuUnavailable(f"an IMU needs the trajectory's derivatives, and a {type(trajectory).__name__} (poses "
                             "interpolated between samples) has no continuous acceleration: simulate the IMU along "
                             "a scene's path")
    k = kinematics_at(np.asarray(times_s, dtype=float))
    R_li = model.rotation_lidar_imu
    r = np.asarray(model.lever_arm_m)
    R = k.pose[:, :3, :3]
    w, alpha = k.angular_velocity, k.angular_acceleration
    g = np.array([0.0, 0.0, -model.gravity_m_s2])
    # the IMU origin's acceleration relative to the lidar's, in the lidar frame
    lever = np.cross(alpha, r) + np.cross(w, np.cross(w, r))
    f_lidar = np.einsum("nji,nj->ni", R, k.acceleration - g) + lever
    gyro = w @ R_li  # rows: R_li^T w
    accel = f_lidar @ R_li
    T_wi = k.pose @ model.T_lidar_imu
    v_imu = k.velocity + np.einsum("nij,nj->ni", R, np.cross(w, r))
    return gyro, accel, T_wi, v_imu


def noise(model: ImuModel, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """n samples of the noise model: (gyroscope white noise, gyroscope bias, accelerometer white noise,
    accelerometer bias), each (n, 3), rad/s and m/s^2.

    Every draw is made whatever the parameters (zeros scale them), in a fixed order, so one parameter
    changes only its own term and the same seed gives the same numbers.
    """
    rng = np.random.default_rng([int(seed), SEED_TAG])
    dt = model.sample_period_s
    turn_on = rng.standard_normal((2, 3))
    white = rng.standard_normal((2, n, 3))
    steps = rng.standard_normal((2, max(n - 1, 0), 3))
    out = []
    for i, (density, walk, start) in enumerate((
            (model.gyroscope_noise_density, model.gyroscope_random_walk, model.gyroscope_turn_on_bias),
            (model.accelerometer_noise_density, model.accelerometer_random_walk, model.accelerometer_turn_on_bias))):
        bias = np.empty((n, 3))
        if n:
            bias[0] = start * turn_on[i]
            bias[1:] = bias[0] + np.cumsum(walk * math.sqrt(dt) * steps[i], axis=0)
        out += [density / math.sqrt(dt) * white[i], bias]
    return out[0], out[1], out[2], out[3]


def simulate_imu(trajectory, model: ImuModel, t_start: float, duration_s: float, seed: int = 0,
                 frame_id: str = "imu") -> tuple[ImuSamples, ImuTruth]:
    """The IMU of a sequence whose first sweep starts at trajectory time ``t_start`` and that lasts
    ``duration_s`` (to its last sweep's end): the samples and their truth (see the module doc).

    The truth's state is given in the first scan's frame (the lidar at ``t_start``).
    """
    stamps = sample_times(model, duration_s)
    true_t = stamps - model.time_offset_s
    gyro, accel, T_wi, v_imu = true_motion(trajectory, model, t_start + true_t)
    T_wf = trajectory.pose_at(np.array([float(t_start)]))[0]
    R_fw = T_wf[:3, :3].T
    position = (T_wi[:, :3, 3] - T_wf[:3, 3]) @ R_fw.T
    R_fi = R_fw @ T_wi[:, :3, :3]
    from scipy.spatial.transform import Rotation

    orientation = Rotation.from_matrix(R_fi).as_quat()
    orientation *= np.where(orientation[:, 3:] < 0, -1.0, 1.0)  # w >= 0: one of the two signs, always the same
    g_gyro, b_gyro, n_accel, b_accel = noise(model, len(stamps), seed)
    samples = ImuSamples(stamps, gyro + b_gyro + g_gyro, accel + b_accel + n_accel, frame_id)
    truth = ImuTruth(stamps, true_t, gyro, accel, b_gyro, b_accel, position, orientation, v_imu @ R_fw.T,
                     R_fw @ np.array([0.0, 0.0, -model.gravity_m_s2]))
    return samples, truth


__all__ = ["GRAVITY_M_S2", "IMU_GRADES", "ImuModel", "ImuSamples", "ImuTruth", "ImuUnavailable", "imu_of_grade",
           "noise", "sample_times", "simulate_imu", "true_motion"]
