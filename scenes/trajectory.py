"""Smooth 6-DoF lidar poses along a drivable path.

The vehicle starts at rest, accelerates to cruise speed, slows where the path
curves (lateral acceleration limit) and stops at the path's end. Poses are
evaluated in closed form at any time (no pose table to interpolate):

- position: the path's cubic spline at the distance travelled, ``s(t)``
  (exact within each 0.25 m step of the profile, where the acceleration is
  constant: C1 in time);
- heading: the spline's tangent; pitch: the road grade; roll: the cross-slope
  of the road surface under the wheels (when the scene gives its height);
- body motion: squat under acceleration, dive under braking, roll outward in
  turns (through a critically damped 1 Hz body mode, so the attitude lags the
  accelerations and settles after a stop), and a small seeded oscillation of heave, pitch and roll (suspension
  modes near 1.2-1.8 Hz) that scales with speed;
- the lidar sits ``mount_height_m`` above the road along the body's z axis.

Frames: lidar x forward, y left, z up; poses are ``T_world_lidar`` (4, 4).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline

# Body-motion gains of a passenger car (typical figures): pitch per unit
# longitudinal acceleration, roll per unit lateral acceleration.
PITCH_PER_ACCEL_RAD = np.radians(0.35)  # rad per m/s^2
ROLL_PER_LAT_ACCEL_RAD = np.radians(0.5)  # rad per m/s^2
HALF_TRACK_M = 0.8  # wheels' lateral offset from the centre, for the road's cross-slope
BODY_MODE_HZ = 1.0  # natural frequency of the body's pitch/roll response to accelerations
BODY_SETTLE_S = 3.0  # the response's length (it has settled to 1e-8 by then)
BODY_DT_S = 0.01  # time step of the precomputed body response


class PathTrajectory:
    """Lidar poses driving along a path with a speed profile.

    Args:
        path: (m, 3) road-level centre-line of travel, metres, evenly sampled.
        closed: the path is a loop (one lap is driven, ending where it started).
        speed_m_s: cruise speed; accel_m_s2: acceleration and braking limit;
        lateral_accel_m_s2: lateral acceleration limit that slows turns.
        mount_height_m: lidar height above the road.
        suspension_pitch_rad, suspension_heave_m: oscillation amplitudes at cruise speed.
        seed: seeds the oscillation's phases and frequencies.
        surface_height: optional callable (k,) x, (k,) y -> (k,) road height, m, for roll.
        ds_m: resolution of the speed profile along the path, m.
    """

    def __init__(
        self,
        path: np.ndarray,
        closed: bool,
        speed_m_s: float,
        accel_m_s2: float,
        lateral_accel_m_s2: float,
        mount_height_m: float,
        suspension_pitch_rad: float = 0.0,
        suspension_heave_m: float = 0.0,
        seed: int = 0,
        surface_height: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
        ds_m: float = 0.25,
    ):
        path = np.asarray(path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 3 or len(path) < 4:
            raise ValueError(f"path must be (m >= 4, 3), got {path.shape}")
        self.closed = closed
        self.mount_height_m = float(mount_height_m)
        self.speed_m_s = float(speed_m_s)
        self.surface_height = surface_height
        pts = np.vstack([path, path[:1]]) if closed else path
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1))])
        if np.any(np.diff(knots) <= 1e-9):
            raise ValueError("path has repeated points")
        self.length_m = float(knots[-1])
        self._spline = CubicSpline(knots, pts, bc_type="periodic" if closed else "natural")

        # Speed profile on a fine grid of distance.
        n = max(8, int(np.ceil(self.length_m / ds_m)) + 1)
        s = np.linspace(0.0, self.length_m, n)
        d1, d2 = self._spline(s, 1), self._spline(s, 2)
        speed2 = d1[:, 0] ** 2 + d1[:, 1] ** 2
        curvature = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / speed2**1.5
        v_max = np.minimum(speed_m_s, np.sqrt(lateral_accel_m_s2 / np.maximum(np.abs(curvature), 1e-9)))
        v_max[0] = v_max[-1] = 0.0
        v = v_max.copy()
        step = s[1] - s[0]
        for k in range(1, n):  # accelerate no faster than accel_m_s2
            v[k] = min(v[k], np.sqrt(v[k - 1] ** 2 + 2 * accel_m_s2 * step))
        for k in range(n - 2, -1, -1):  # brake no harder than accel_m_s2
            v[k] = min(v[k], np.sqrt(v[k + 1] ** 2 + 2 * accel_m_s2 * step))
        # Constant acceleration within each step of the profile: exact, C1 motion.
        self._a_seg = (v[1:] ** 2 - v[:-1] ** 2) / (2 * step)
        dt = 2 * step / (v[:-1] + v[1:])
        t = np.concatenate([[0.0], np.cumsum(dt)])
        self._s_grid, self._t_grid, self._v_grid = s, t, v
        self._curv_grid = curvature
        self._duration = float(t[-1])

        # Body attitude from the accelerations, through the body's pitch/roll mode (a
        # critically damped second-order response, so the body settles after a stop).
        self._tb = np.arange(-BODY_SETTLE_S, self._duration + BODY_SETTLE_S, BODY_DT_S)
        a_long = self._accel_at(self._tb)
        sb = self.distance_at(self._tb)
        a_lat = self.speed_at(self._tb) ** 2 * np.interp(sb, s, curvature)
        a_lat[(self._tb < 0) | (self._tb > self._duration)] = 0.0
        tau = np.arange(0.0, BODY_SETTLE_S, BODY_DT_S)
        w = 2 * np.pi * BODY_MODE_HZ
        kernel = w**2 * tau * np.exp(-w * tau) * BODY_DT_S  # unit gain at steady state
        self._pitch_dyn = -PITCH_PER_ACCEL_RAD * np.convolve(a_long, kernel)[: len(self._tb)]
        self._roll_dyn = ROLL_PER_LAT_ACCEL_RAD * np.convolve(a_lat, kernel)[: len(self._tb)]

        # Suspension oscillation: two modes per axis with seeded frequency and phase.
        rng = np.random.default_rng([int(seed), 0x5A5])
        self._osc_freq = rng.uniform(1.2, 1.8, size=(3, 2))  # heave, pitch, roll x 2 modes, Hz
        self._osc_phase = rng.uniform(0, 2 * np.pi, size=(3, 2))
        self._osc_amp = np.array([suspension_heave_m, suspension_pitch_rad, suspension_pitch_rad])

    # ---------------------------------------------------------------- timing
    @property
    def duration_s(self) -> float:
        """Time from rest at the start to rest at the end, s."""
        return self._duration

    def _segment(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Clamped times, their profile segment and time into it."""
        t = np.clip(np.atleast_1d(np.asarray(times, dtype=float)), 0.0, self._duration)
        k = np.clip(np.searchsorted(self._t_grid, t, side="right") - 1, 0, len(self._t_grid) - 2)
        return t, k, t - self._t_grid[k]

    def distance_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) distance travelled along the path, m (clamped to the ends)."""
        _, k, tau = self._segment(times)
        s = self._s_grid[k] + self._v_grid[k] * tau + 0.5 * self._a_seg[k] * tau**2
        return np.clip(s, self._s_grid[k], self._s_grid[k + 1])

    def speed_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) speed, m/s (zero before the start and after the end)."""
        t, k, tau = self._segment(times)
        v = np.maximum(self._v_grid[k] + self._a_seg[k] * tau, 0.0)
        raw = np.atleast_1d(np.asarray(times, dtype=float))
        return np.where((raw < 0) | (raw > self._duration), 0.0, v)

    def _accel_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) longitudinal acceleration, m/s^2 (zero at rest before and after)."""
        _, k, _ = self._segment(times)
        raw = np.atleast_1d(np.asarray(times, dtype=float))
        return np.where((raw < 0) | (raw > self._duration), 0.0, self._a_seg[k])

    def time_at_distance(self, distance_m: np.ndarray) -> np.ndarray:
        """(n,) distance along the path, m -> (n,) time the vehicle passes there, s."""
        d = np.clip(np.atleast_1d(np.asarray(distance_m, dtype=float)), 0.0, self.length_m)
        k = np.clip(np.searchsorted(self._s_grid, d, side="right") - 1, 0, len(self._s_grid) - 2)
        v0, a = self._v_grid[k], self._a_seg[k]
        ds = d - self._s_grid[k]
        # solve ds = v0 tau + a tau^2 / 2 for the root in the segment
        disc = np.sqrt(np.maximum(v0**2 + 2 * a * ds, 0.0))
        tau = np.where(np.abs(a) > 1e-12, (disc - v0) / np.where(np.abs(a) > 1e-12, a, 1.0),
                       ds / np.maximum(v0, 1e-12))
        return self._t_grid[k] + tau

    def road_point_at(self, distance_m: np.ndarray) -> np.ndarray:
        """(n,) distance -> (n, 3) road-level point of the path, m."""
        return self._spline(np.atleast_1d(distance_m) % self.length_m if self.closed
                            else np.atleast_1d(distance_m))

    # ---------------------------------------------------------------- poses
    def pose_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n, 4, 4) ``T_world_lidar``; before the start / after the end it stands still."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        s = self.distance_at(t)
        p = self._spline(s)
        d1 = self._spline(s, 1)
        horiz = np.hypot(d1[:, 0], d1[:, 1])
        yaw = np.arctan2(d1[:, 1], d1[:, 0])
        pitch = -np.arctan2(d1[:, 2], horiz)  # nose up on an up-grade: negative about y
        roll = np.zeros_like(s)
        if self.surface_height is not None:
            left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
            zl = self.surface_height(*(p[:, :2] + HALF_TRACK_M * left).T)
            zr = self.surface_height(*(p[:, :2] - HALF_TRACK_M * left).T)
            roll = np.arctan2(zl - zr, 2 * HALF_TRACK_M)  # left side higher: positive about x
        v = self.speed_at(t)
        # squat when accelerating, dive when braking; lean out of turns
        pitch = pitch + np.interp(t, self._tb, self._pitch_dyn, left=0.0, right=0.0)
        roll = roll + np.interp(t, self._tb, self._roll_dyn, left=0.0, right=0.0)
        scale = np.minimum(1.0, v / max(self.speed_m_s, 1e-6))
        osc = np.sin(2 * np.pi * self._osc_freq[None] * t[:, None, None] + self._osc_phase[None]).sum(-1)
        osc = osc * 0.5 * self._osc_amp[None] * scale[:, None]  # (n, 3): heave, pitch, roll
        R = _rotation_zyx(yaw, pitch + osc[:, 1], roll + osc[:, 2])
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = p + R[:, :, 2] * (self.mount_height_m + osc[:, 0])[:, None]
        return T


def _rotation_zyx(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(n,) yaw, pitch, roll, rad -> (n, 3, 3) ``Rz(yaw) Ry(pitch) Rx(roll)`` (intrinsic Z-Y-X).

    The same rotations as scipy's ``Rotation.from_euler("ZYX", ...)`` (to rounding, ~1e-16), written
    out in numpy: scipy's per-element conversion took 17 ms for a sweep's 4,500 firing poses.
    """
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    R = np.empty((len(yaw), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -sp, cp * sr, cp * cr
    return R
