"""De-skew: undo a sweep's motion distortion under the constant-velocity assumption.

A spinning lidar reports each point in its own frame at the point's firing
time. If the sensor moves at constant velocity (twist xi per frame period),
the sensor at time t after the sweep start sits at ``exp((t / period) xi)`` in
the frame of the sweep start, so a point measured at t is brought into the
sweep-start frame by that transform. Beyond the paper (which leaves this to
wheel odometry); the simulator's ``true_xyz`` is the exact answer to check it.
"""

from __future__ import annotations

import numpy as np

from simlidar import se3


def _motion_at(times_s: np.ndarray, motion_per_frame: np.ndarray, frame_period_s: float):
    """(U,) distinct times and (N,) inverse, (U, 4, 4) sensor pose at each time in the sweep-start frame."""
    t_unique, inverse = np.unique(np.asarray(times_s, dtype=np.float64), return_inverse=True)
    return se3.exp(np.outer(t_unique / frame_period_s, se3.log(motion_per_frame))), inverse


def deskew(points: np.ndarray, times_s: np.ndarray, motion_per_frame: np.ndarray, frame_period_s: float) -> np.ndarray:
    """Bring every point into the sensor frame at the sweep start.

    points: (N, 3) as measured, each in the sensor frame at its own time, m.
    times_s: (N,) time of each point since the sweep start, s.
    motion_per_frame: (4, 4) pose of the next sweep's start in this sweep's start
        frame (the relative motion over one frame period; identity: no change).
    frame_period_s: time between sweep starts, s.
    Returns (N, 3) de-skewed points.
    """
    # Points fire in a few thousand distinct instants: one transform per instant.
    T, inverse = _motion_at(times_s, motion_per_frame, frame_period_s)
    R, t = T[inverse, :3, :3], T[inverse, :3, 3]
    return np.einsum("nij,nj->ni", R, points) + t


def redeskew(points: np.ndarray, normals: np.ndarray, times_s: np.ndarray, old_motion: np.ndarray,
             new_motion: np.ndarray, frame_period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Re-do the de-skew of already de-skewed points (and normals) with a better motion.

    points, normals: (M, 3) de-skewed with ``old_motion``; times_s: (M,) their times.
    Returns the (M, 3) points and normals as ``new_motion`` would have de-skewed them:
    ``T_new(t) T_old(t)^-1`` applied per point.
    """
    T_old, inverse = _motion_at(times_s, old_motion, frame_period_s)
    T_new, _ = _motion_at(times_s, new_motion, frame_period_s)
    C = (T_new @ se3.inverse(T_old))[inverse]
    p = np.einsum("nij,nj->ni", C[:, :3, :3], points) + C[:, :3, 3]
    return p, np.einsum("nij,nj->ni", C[:, :3, :3], normals)
