"""Smooth 6-DoF lidar poses along a drivable path, and their exact time derivatives.

The vehicle starts at rest, accelerates to cruise speed, slows where the path
curves (lateral acceleration limit), stops where told to (and waits), and stops
at the path's end. Poses are evaluated in closed form at any time (no pose table
to interpolate):

- position: the path's cubic spline at the distance travelled, ``s(t)``. The raw
  speed profile has a constant acceleration within each 0.25 m step (exact, C1
  in time: the acceleration steps where it changes). With ``accel_smoothing_s``
  = tau > 0 the distance is the raw one averaged over a triangular window of the
  last tau seconds (two moving averages of tau / 2, in closed form), so the
  acceleration and the jerk are continuous (the snap is bounded) and the motion
  lags the raw profile by tau / 2;
- heading: the spline's tangent; pitch: the road grade; roll: the cross-slope
  of the road surface under the wheels (when the scene gives its height);
- body motion: squat under acceleration, dive under braking, roll outward in
  turns (through a critically damped 1 Hz body mode, so the attitude lags the
  accelerations and settles after a stop; its response is computed every 10 ms and
  interpolated linearly, or with smoothing by a cubic spline, so the attitude is C2),
  and a small seeded oscillation of heave, pitch and roll (suspension modes near
  1.2-1.8 Hz) that scales with speed;
- the lidar sits ``mount_height_m`` above the road along the body's z axis.

``kinematics_at`` gives the exact first and second derivatives of ``pose_at``
(velocity, acceleration, body angular velocity and acceleration): what an IMU
riding on the vehicle measures (``simlidar.imu``). Where they are not continuous
(``docs/imu.md`` measures each): without smoothing the acceleration steps wherever
the raw profile's does, the oscillation's speed scaling then makes the angular rate,
and the lidar's velocity through the mount's lever, step by under 2 mm/s, and the
body mode's rate steps every 10 ms (its impulses are left out of the acceleration);
with or without, the path spline's third derivative steps at its knots, so the
angular acceleration steps (finitely) in curves.

Frames: lidar x forward, y left, z up; poses are ``T_world_lidar`` (4, 4).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Kinematics:
    """The lidar's motion at n times: the pose and its exact time derivatives.

    pose: (n, 4, 4) ``T_world_lidar``. velocity, acceleration: (n, 3) of the lidar's
    origin in the world frame, m/s and m/s^2. angular_velocity, angular_acceleration:
    (n, 3) of the lidar frame relative to the world, in the lidar frame, rad/s and rad/s^2
    (``dR/dt = R [w]x``).
    """

    pose: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    angular_velocity: np.ndarray
    angular_acceleration: np.ndarray


class _RawProfile:
    """Distance along the path against time with a constant acceleration per segment.

    Segments k = 0 .. m-1 start at time t[k], distance s[k], speed v[k], with acceleration a[k]
    (a wait: v = a = 0). Before t[0] = 0 the vehicle stands at 0, after t[m] at the path's end.
    S, S2: (m + 1,) the first and second repeated integrals of s at the segments' starts.
    """

    def __init__(self, s: np.ndarray, t: np.ndarray, v: np.ndarray, a: np.ndarray):
        self.s, self.t, self.v, self.a = s, t, v, a
        self.duration = float(t[-1])
        self.length = float(s[-1])
        dt = np.diff(t)
        # integral of s over each segment, for the moving average: S(t) = int_0^t s(u) du
        seg = s[:-1] * dt + v[:-1] * dt**2 / 2 + a * dt**3 / 6
        self.S = np.concatenate([[0.0], np.cumsum(seg)])
        seg2 = self.S[:-1] * dt + s[:-1] * dt**2 / 2 + v[:-1] * dt**3 / 6 + a * dt**4 / 24
        self.S2 = np.concatenate([[0.0], np.cumsum(seg2)])

    def _segment(self, times: np.ndarray):
        t = np.clip(times, 0.0, self.duration)
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        return k, t - self.t[k]

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n,) times -> (n,) distance, speed, acceleration (at rest before 0 and after the end)."""
        k, tau = self._segment(times)
        s = np.clip(self.s[k] + self.v[k] * tau + 0.5 * self.a[k] * tau**2, self.s[k], self.s[k + 1])
        v = np.maximum(self.v[k] + self.a[k] * tau, 0.0)
        outside = (times < 0) | (times > self.duration)
        return s, np.where(outside, 0.0, v), np.where(outside, 0.0, self.a[k])

    def integral(self, times: np.ndarray, order: int = 1) -> np.ndarray:
        """(n,) times -> (n,) the ``order``-th (1 or 2) repeated integral of s from 0 to t, m s^order (0 before
        the start; growing with the end's distance after it)."""
        k, tau = self._segment(times)
        after = np.maximum(times - self.duration, 0.0)
        if order == 1:
            S = self.S[k] + self.s[k] * tau + self.v[k] * tau**2 / 2 + self.a[k] * tau**3 / 6
            S = S + self.length * after
        else:
            S = (self.S2[k] + self.S[k] * tau + self.s[k] * tau**2 / 2 + self.v[k] * tau**3 / 6
                 + self.a[k] * tau**4 / 24)
            S = S + self.S[-1] * after + self.length * after**2 / 2
        return np.where(times < 0, 0.0, S)


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
        surface_height: optional callable (k,) x, (k,) y -> (k,) road height, m, for roll
            (``kinematics_at`` needs its ``gradient`` and ``hessian`` too, as ``scenes.geometry.SmoothField``'s).
        ds_m: resolution of the speed profile along the path, m.
        accel_smoothing_s: tau, the length of the triangular moving average that makes the acceleration
            and the jerk continuous (0: off, the raw profile's steps).
        stops: (distance along the path, m; wait, s) pairs: the vehicle brakes to a stop there (at the
            profile step nearest), waits, and accelerates again.
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
        accel_smoothing_s: float = 0.0,
        stops: Sequence[tuple[float, float]] = (),
    ):
        path = np.asarray(path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 3 or len(path) < 4:
            raise ValueError(f"path must be (m >= 4, 3), got {path.shape}")
        if accel_smoothing_s < 0:
            raise ValueError(f"accel_smoothing_s must be >= 0, got {accel_smoothing_s}")
        self.closed = closed
        self.mount_height_m = float(mount_height_m)
        self.speed_m_s = float(speed_m_s)
        self.surface_height = surface_height
        self.accel_smoothing_s = float(accel_smoothing_s)
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
        step = s[1] - s[0]
        waits = {}
        for where, wait in stops:
            if not 0.0 < where < self.length_m or wait < 0:
                raise ValueError(f"a stop must lie inside the path (0, {self.length_m:.1f}) m and wait >= 0 s, "
                                 f"got ({where}, {wait})")
            k = int(round(where / step))
            v_max[k] = 0.0
            waits[k] = waits.get(k, 0.0) + float(wait)
        v = v_max.copy()
        for k in range(1, n):  # accelerate no faster than accel_m_s2
            v[k] = min(v[k], np.sqrt(v[k - 1] ** 2 + 2 * accel_m_s2 * step))
        for k in range(n - 2, -1, -1):  # brake no harder than accel_m_s2
            v[k] = min(v[k], np.sqrt(v[k + 1] ** 2 + 2 * accel_m_s2 * step))
        # Constant acceleration within each step of the profile: exact, C1 motion.
        a_seg = (v[1:] ** 2 - v[:-1] ** 2) / (2 * step)
        dt = 2 * step / (v[:-1] + v[1:])
        s_knots, v_knots, a_knots, dt_knots = list(s), list(v), list(a_seg), list(dt)
        for k in sorted(waits, reverse=True):  # a wait: a segment of its own, standing at s[k]
            s_knots.insert(k, s[k])
            v_knots.insert(k, 0.0)
            a_knots.insert(k, 0.0)
            dt_knots.insert(k, waits[k])
        t = np.concatenate([[0.0], np.cumsum(dt_knots)])
        self._raw = _RawProfile(np.array(s_knots), t, np.array(v_knots), np.array(a_knots))
        self._duration = self._raw.duration + self.accel_smoothing_s

        # Body attitude from the accelerations, through the body's pitch/roll mode (a
        # critically damped second-order response, so the body settles after a stop).
        tb = np.arange(-BODY_SETTLE_S, self._duration + BODY_SETTLE_S, BODY_DT_S)
        sb, vb, a_long, _ = self._profile(tb)
        a_lat = vb**2 * np.interp(sb, s, curvature)
        tau = np.arange(0.0, BODY_SETTLE_S, BODY_DT_S)
        w = 2 * np.pi * BODY_MODE_HZ
        kernel = w**2 * tau * np.exp(-w * tau) * BODY_DT_S  # unit gain at steady state
        self._tb = tb
        self._pitch_dyn = -PITCH_PER_ACCEL_RAD * np.convolve(a_long, kernel)[: len(tb)]
        self._roll_dyn = ROLL_PER_LAT_ACCEL_RAD * np.convolve(a_lat, kernel)[: len(tb)]
        # Smoothed motion: the response is a cubic spline (C2 attitude); raw: linear between the 10 ms samples,
        # as the poses have always been (a spline would move them by up to 9 um and 5 urad)
        self._body_splines = None
        if self.accel_smoothing_s > 0:
            self._body_splines = {id(table): CubicSpline(tb, table) for table in (self._pitch_dyn, self._roll_dyn)}

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

    def _profile(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(n,) times -> (n,) distance (m), speed (m/s), acceleration (m/s^2), jerk (m/s^3); at rest outside.

        With smoothing, the raw distance averaged over a triangular window of length tau behind t (two
        moving averages of tau / 2: the second differences of its repeated integrals), so the acceleration
        and the jerk are continuous and the snap is at most 4 / tau^2 times the largest step of the raw
        acceleration.
        """
        t = np.atleast_1d(np.asarray(times, dtype=float))
        tau = self.accel_smoothing_s
        if tau == 0:
            s, v, a = self._raw.at(t)
            return s, v, a, np.zeros_like(t)
        h = tau / 2
        ends = [self._raw.at(t - i * h) for i in range(3)]  # (s, v, a) at t, t - h, t - 2h

        def second_difference(values):
            return (values[0] - 2 * values[1] + values[2]) / h**2

        s = second_difference([self._raw.integral(t - i * h, 2) for i in range(3)])
        s = np.clip(s, ends[2][0], ends[0][0])  # the mean lies between the window's ends (guards rounding)
        v = second_difference([self._raw.integral(t - i * h, 1) for i in range(3)])
        return s, v, second_difference([e[0] for e in ends]), second_difference([e[1] for e in ends])

    def distance_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) distance travelled along the path, m (clamped to the ends)."""
        return self._profile(times)[0]

    def speed_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n,) speed, m/s (zero before the start and after the end)."""
        return self._profile(times)[1]

    def _accel_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) longitudinal acceleration, m/s^2 (zero at rest before and after)."""
        return self._profile(times)[2]

    def time_at_distance(self, distance_m: np.ndarray) -> np.ndarray:
        """(n,) distance along the path, m -> (n,) time the vehicle passes there, s (where it waits: when it
        leaves)."""
        d = np.clip(np.atleast_1d(np.asarray(distance_m, dtype=float)), 0.0, self.length_m)
        if self.accel_smoothing_s > 0:  # distance never decreases: bisection to the last time it is at most d
            lo, hi = np.zeros_like(d), np.full_like(d, self._duration)
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                before = self.distance_at(mid) <= d
                lo, hi = np.where(before, mid, lo), np.where(before, hi, mid)
            return lo
        raw = self._raw
        k = np.clip(np.searchsorted(raw.s, d, side="right") - 1, 0, len(raw.s) - 2)
        v0, a = raw.v[k], raw.a[k]
        ds = d - raw.s[k]
        # solve ds = v0 tau + a tau^2 / 2 for the root in the segment
        disc = np.sqrt(np.maximum(v0**2 + 2 * a * ds, 0.0))
        tau = np.where(np.abs(a) > 1e-12, (disc - v0) / np.where(np.abs(a) > 1e-12, a, 1.0),
                       ds / np.maximum(v0, 1e-12))
        return raw.t[k] + tau

    def road_point_at(self, distance_m: np.ndarray) -> np.ndarray:
        """(n,) distance -> (n, 3) road-level point of the path, m."""
        return self._spline(np.atleast_1d(distance_m) % self.length_m if self.closed
                            else np.atleast_1d(distance_m))

    # ---------------------------------------------------------------- poses
    def _body(self, table: np.ndarray, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """The body mode's response (table: its samples every ``BODY_DT_S``) or its nu-th derivative at times t:
        the cubic spline through the samples with smoothing, else linear between them (nu = 1: the segment's
        slope; nu = 2: zero, the impulses at the samples left out); zero outside the table (settled)."""
        tb = self._tb
        inside = (t >= tb[0]) & (t <= tb[-1])
        if self._body_splines is not None:
            return np.where(inside, self._body_splines[id(table)](np.clip(t, tb[0], tb[-1]), nu), 0.0)
        if nu == 0:
            return np.interp(t, tb, table, left=0.0, right=0.0)
        if nu == 1:
            k = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, len(tb) - 2)
            return np.where(inside, (table[k + 1] - table[k]) / (tb[k + 1] - tb[k]), 0.0)
        return np.zeros_like(t)

    def _oscillation(self, t: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n,) times and speeds -> (n, 3) heave (m), pitch and roll (rad) of the suspension's oscillation."""
        scale = np.minimum(1.0, v / max(self.speed_m_s, 1e-6))
        osc = np.sin(2 * np.pi * self._osc_freq[None] * t[:, None, None] + self._osc_phase[None]).sum(-1)
        return osc * 0.5 * self._osc_amp[None] * scale[:, None]

    def _roll_of_surface(self, p: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
        zl = self.surface_height(*(p[:, :2] + HALF_TRACK_M * left).T)
        zr = self.surface_height(*(p[:, :2] - HALF_TRACK_M * left).T)
        return np.arctan2(zl - zr, 2 * HALF_TRACK_M)  # left side higher: positive about x

    def pose_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n, 4, 4) ``T_world_lidar``; before the start / after the end it stands still."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        s, v, _, _ = self._profile(t)
        p = self._spline(s)
        d1 = self._spline(s, 1)
        horiz = np.hypot(d1[:, 0], d1[:, 1])
        yaw = np.arctan2(d1[:, 1], d1[:, 0])
        pitch = -np.arctan2(d1[:, 2], horiz)  # nose up on an up-grade: negative about y
        roll = np.zeros_like(s) if self.surface_height is None else self._roll_of_surface(p, yaw)
        # squat when accelerating, dive when braking; lean out of turns
        pitch = pitch + self._body(self._pitch_dyn, t)
        roll = roll + self._body(self._roll_dyn, t)
        osc = self._oscillation(t, v)  # (n, 3): heave, pitch, roll
        R = _rotation_zyx(yaw, pitch + osc[:, 1], roll + osc[:, 2])
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = p + R[:, :, 2] * (self.mount_height_m + osc[:, 0])[:, None]
        return T

    def kinematics_at(self, times: np.ndarray) -> Kinematics:
        """(n,) times, s -> the pose and its exact first and second time derivatives (``Kinematics``).

        Each term of ``pose_at`` differentiated in closed form: the path spline's derivatives up to the
        third, the speed profile's speed, acceleration and jerk, the body mode spline's and the
        oscillation's derivatives, and the surface's gradient and Hessian for the roll.
        """
        t = np.atleast_1d(np.asarray(times, dtype=float))
        s, v, a, j = self._profile(t)
        p, c1, c2, c3 = (self._spline(s, k) for k in range(4))

        def in_time(f_s, f_ss):  # d/dt and d2/dt2 of a function of s(t)
            return f_s * v, f_ss * v**2 + f_s * a

        # heading: the horizontal tangent's angle
        x1, y1, z1 = c1.T
        x2, y2, z2 = c2.T
        x3, y3, z3 = c3.T
        D = x1**2 + y1**2
        N = x1 * y2 - y1 * x2
        yaw = np.arctan2(y1, x1)
        yaw_s = N / D
        yaw_ss = ((x1 * y3 - y1 * x3) * D - N * 2 * (x1 * x2 + y1 * y2)) / D**2
        # grade: pitch = -atan2(A, B) with A = z', B = |(x', y')|
        B = np.sqrt(D)
        B1 = (x1 * x2 + y1 * y2) / B
        B2 = (x2**2 + y2**2 + x1 * x3 + y1 * y3) / B - B1**2 / B
        A, A1, A2 = z1, z2, z3
        Q = A**2 + B**2
        num = B * A1 - A * B1
        pitch = -np.arctan2(A, B)
        pitch_s = -num / Q
        pitch_ss = -((B * A2 - A * B2) * Q - num * (2 * A * A1 + 2 * B * B1)) / Q**2
        roll, roll_s, roll_ss = self._surface_roll_derivatives(p, c1, c2, yaw, yaw_s, yaw_ss)

        yaw_t, yaw_tt = in_time(yaw_s, yaw_ss)
        pitch_t, pitch_tt = in_time(pitch_s, pitch_ss)
        roll_t, roll_tt = in_time(roll_s, roll_ss)
        # body mode
        pitch = pitch + self._body(self._pitch_dyn, t)
        pitch_t = pitch_t + self._body(self._pitch_dyn, t, 1)
        pitch_tt = pitch_tt + self._body(self._pitch_dyn, t, 2)
        roll = roll + self._body(self._roll_dyn, t)
        roll_t = roll_t + self._body(self._roll_dyn, t, 1)
        roll_tt = roll_tt + self._body(self._roll_dyn, t, 2)
        # oscillation: 0.5 amp scale(t) sum sin(w t + phase), scale = min(1, v / cruise)
        cruise = max(self.speed_m_s, 1e-6)
        below = v < cruise
        scale = np.minimum(1.0, v / cruise)
        scale_t = np.where(below, a / cruise, 0.0)
        scale_tt = np.where(below, j / cruise, 0.0)
        w = 2 * np.pi * self._osc_freq  # (3, 2)
        arg = w[None] * t[:, None, None] + self._osc_phase[None]
        S0 = np.sin(arg).sum(-1)
        S1 = (w[None] * np.cos(arg)).sum(-1)
        S2 = -(w[None] ** 2 * np.sin(arg)).sum(-1)
        half = 0.5 * self._osc_amp[None]
        osc = half * scale[:, None] * S0
        osc_t = half * (scale_t[:, None] * S0 + scale[:, None] * S1)
        osc_tt = half * (scale_tt[:, None] * S0 + 2 * scale_t[:, None] * S1 + scale[:, None] * S2)
        pitch, pitch_t, pitch_tt = pitch + osc[:, 1], pitch_t + osc_t[:, 1], pitch_tt + osc_tt[:, 1]
        roll, roll_t, roll_tt = roll + osc[:, 2], roll_t + osc_t[:, 2], roll_tt + osc_tt[:, 2]

        # body rates of R = Rz(yaw) Ry(pitch) Rx(roll), and their derivatives
        sp, cp, sr, cr = np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
        omega = np.column_stack([
            roll_t - yaw_t * sp,
            pitch_t * cr + yaw_t * cp * sr,
            -pitch_t * sr + yaw_t * cp * cr,
        ])
        alpha = np.column_stack([
            roll_tt - yaw_tt * sp - yaw_t * pitch_t * cp,
            pitch_tt * cr - pitch_t * roll_t * sr + yaw_tt * cp * sr - yaw_t * pitch_t * sp * sr
            + yaw_t * roll_t * cp * cr,
            -pitch_tt * sr - pitch_t * roll_t * cr + yaw_tt * cp * cr - yaw_t * pitch_t * sp * cr
            - yaw_t * roll_t * cp * sr,
        ])
        T = self.pose_at(t)  # the same numbers as the poses (the angles above agree with its to rounding)
        R = T[:, :3, :3]

        # position: p(s) + R e_z H, H = mount height + heave
        H_t, H_tt = osc_t[:, 0], osc_tt[:, 0]
        H = self.mount_height_m + osc[:, 0]
        e3 = np.array([0.0, 0.0, 1.0])
        w_e3 = np.cross(omega, e3)
        acc_e3 = np.cross(alpha, e3) + np.cross(omega, w_e3)
        rot = lambda x: np.einsum("nij,nj->ni", R, x)  # noqa: E731  body -> world
        vel = c1 * v[:, None] + rot(w_e3 * H[:, None]) + R[:, :, 2] * H_t[:, None]
        acc = (c2 * v[:, None] ** 2 + c1 * a[:, None] + rot(acc_e3 * H[:, None] + 2 * w_e3 * H_t[:, None])
               + R[:, :, 2] * H_tt[:, None])
        return Kinematics(T, vel, acc, omega, alpha)

    def _surface_roll_derivatives(self, p, c1, c2, yaw, yaw_s, yaw_ss):
        """(n,) roll from the cross-slope under the wheels and its first two derivatives along the path."""
        zeros = np.zeros(len(p))
        if self.surface_height is None:
            return zeros, zeros, zeros
        field = self.surface_height
        if not (hasattr(field, "gradient") and hasattr(field, "hessian")):
            raise ValueError("surface_height has no gradient and hessian (as scenes.geometry.SmoothField has): "
                             "the roll's derivatives, and so an IMU, need them")
        left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
        dleft = -np.stack([np.cos(yaw), np.sin(yaw)], axis=1)  # d left / d yaw
        z, z_s, z_ss = [], [], []
        for side in (1.0, -1.0):
            q = p[:, :2] + side * HALF_TRACK_M * left
            q_s = c1[:, :2] + side * HALF_TRACK_M * dleft * yaw_s[:, None]
            q_ss = c2[:, :2] + side * HALF_TRACK_M * (-left * yaw_s[:, None] ** 2 + dleft * yaw_ss[:, None])
            g, h = field.gradient(*q.T), field.hessian(*q.T)
            z.append(field(*q.T))
            z_s.append(np.sum(g * q_s, axis=1))
            z_ss.append(np.einsum("ni,nij,nj->n", q_s, h, q_s) + np.sum(g * q_ss, axis=1))
        u = (z[0] - z[1]) / (2 * HALF_TRACK_M)
        u_s = (z_s[0] - z_s[1]) / (2 * HALF_TRACK_M)
        u_ss = (z_ss[0] - z_ss[1]) / (2 * HALF_TRACK_M)
        return np.arctan(u), u_s / (1 + u**2), u_ss / (1 + u**2) - 2 * u * u_s**2 / (1 + u**2) ** 2


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
