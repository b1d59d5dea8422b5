"""Smooth 6-DoF lidar poses along a drivable path.

The vehicle starts at rest, accelerates to cruise speed, slows where the path
curves (lateral acceleration limit) and stops at the path's end. Poses are
evaluated in closed form at any time (no pose table to interpolate):

- position: the path's cubic spline at the distance travelled, ``s(t)`` (a
  monotone C1 interpolant of the speed profile's time table);
- heading: the spline's tangent; pitch: the road grade; roll: the cross-slope
  of the road surface under the wheels (when the scene gives its height);
- body motion: squat under acceleration, dive under braking, roll outward in
  turns, and a small seeded oscillation of heave, pitch and roll (suspension
  modes near 1.2-1.8 Hz) that scales with speed;
- the lidar sits ``mount_height_m`` above the road along the body's z axis.

Frames: lidar x forward, y left, z up; poses are ``T_world_lidar`` (4, 4).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator
from scipy.spatial.transform import Rotation

# Body-motion gains of a passenger car (typical figures): pitch per unit
# longitudinal acceleration, roll per unit lateral acceleration.
PITCH_PER_ACCEL_RAD = np.radians(0.35)  # rad per m/s^2
ROLL_PER_LAT_ACCEL_RAD = np.radians(0.5)  # rad per m/s^2
HALF_TRACK_M = 0.8  # wheels' lateral offset from the centre, for the road's cross-slope


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
        dt = 2 * step / (v[:-1] + v[1:])
        t = np.concatenate([[0.0], np.cumsum(dt)])
        self._s_grid, self._t_grid, self._v_grid = s, t, v
        self._curv_grid = curvature
        self._accel_grid = np.gradient(v**2, s) / 2  # dv/dt = v dv/ds
        self._s_of_t = PchipInterpolator(t, s)
        self._duration = float(t[-1])

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

    def distance_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) distance travelled along the path, m (clamped to the ends)."""
        t = np.clip(np.atleast_1d(np.asarray(times, dtype=float)), 0.0, self._duration)
        return np.clip(self._s_of_t(t), 0.0, self.length_m)

    def time_at_distance(self, distance_m: np.ndarray) -> np.ndarray:
        """(n,) distance along the path, m -> (n,) time the vehicle passes there, s."""
        return np.interp(np.atleast_1d(distance_m), self._s_grid, self._t_grid)

    def speed_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) speed, m/s."""
        return np.interp(self.distance_at(times), self._s_grid, self._v_grid)

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
        v = np.interp(s, self._s_grid, self._v_grid)
        accel = np.interp(s, self._s_grid, self._accel_grid)
        curv = np.interp(s, self._s_grid, self._curv_grid)
        pitch = pitch - PITCH_PER_ACCEL_RAD * accel  # squat when accelerating, dive when braking
        roll = roll + ROLL_PER_LAT_ACCEL_RAD * v**2 * curv  # body leans out of the turn
        scale = np.minimum(1.0, v / max(self.speed_m_s, 1e-6))
        osc = np.sin(2 * np.pi * self._osc_freq[None] * t[:, None, None] + self._osc_phase[None]).sum(-1)
        osc = osc * 0.5 * self._osc_amp[None] * scale[:, None]  # (n, 3): heave, pitch, roll
        R = Rotation.from_euler("ZYX", np.stack([yaw, pitch + osc[:, 1], roll + osc[:, 2]], 1)).as_matrix()
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = p + R[:, :, 2] * (self.mount_height_m + osc[:, 0])[:, None]
        return T
