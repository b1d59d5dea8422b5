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


def screw_apply(xi: np.ndarray, s: np.ndarray, points: np.ndarray, rotate_only: bool = False) -> np.ndarray:
    """Apply ``exp(s_i xi)`` to each point p_i, without forming a matrix per point.

    xi: (6,) twist (rho, omega) of ``simlidar.se3``; s: (N,) fractions; points: (N, 3).
    With k = omega / |omega| and phi_i = s_i |omega|, Rodrigues' formula gives the
    rotation and the SE(3) left Jacobian the translation, both as scalar functions of
    phi_i times a few fixed vectors (exact, not a small-angle approximation).
    rotate_only: apply the rotation alone (for normals).
    """
    if rotate_only:
        return _screw(xi, s, None, points)[1]
    return _screw(xi, s, points, None)[0]


def _screw(xi: np.ndarray, s: np.ndarray, points: np.ndarray | None, normals: np.ndarray | None
           ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``screw_apply`` of (N, 3) points and the rotation alone of (N, 3) normals (either may be None),
    the per-point angles' sines and cosines computed once for both."""
    rho, omega = xi[:3], xi[3:]
    theta = float(np.linalg.norm(omega))
    s = np.asarray(s, dtype=np.float64)
    if theta < 1e-12:
        return (None if points is None else points + np.outer(s, rho),
                None if normals is None else normals.copy())
    k = omega / theta
    phi = s * theta
    c, sn = np.cos(phi), np.sin(phi)
    n_out = None if normals is None else _rotate(k, c, sn, normals)
    if points is None:
        return None, n_out
    out = _rotate(k, c, sn, points)
    # t(s) = V(s omega) s rho = s rho + s (1 - cos phi)/phi (k x rho) + s (phi - sin phi)/phi k x (k x rho)
    small = phi < 1e-6
    phi_safe = np.where(small, 1.0, phi)
    a = s * np.where(small, phi / 2.0, (1.0 - c) / phi_safe)
    b = s * np.where(small, phi**2 / 6.0, (phi - sn) / phi_safe)
    k_rho = np.cross(k, rho)
    kk_rho = np.cross(k, k_rho)
    for i in range(3):
        out[:, i] += s * rho[i] + a * k_rho[i] + b * kk_rho[i]
    return out, n_out


def _rotate(k: np.ndarray, c: np.ndarray, sn: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) points rotated about the unit axis k (3,) by angles of cosines c and sines sn (N,)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    # Rodrigues, per component (skinny matmuls are slow in numpy):
    # R p = c p + sn (k x p) + (1 - c)(k . p) k
    kx, ky, kz = k
    w = (kx * x + ky * y + kz * z) * (1.0 - c)
    out = np.empty_like(points)
    out[:, 0] = c * x + sn * (ky * z - kz * y) + w * kx
    out[:, 1] = c * y + sn * (kz * x - kx * z) + w * ky
    out[:, 2] = c * z + sn * (kx * y - ky * x) + w * kz
    return out


def deskew(points: np.ndarray, times_s: np.ndarray, motion_per_frame: np.ndarray, frame_period_s: float) -> np.ndarray:
    """Bring every point into the sensor frame at the sweep start.

    points: (N, 3) as measured, each in the sensor frame at its own time, m.
    times_s: (N,) time of each point since the sweep start, s.
    motion_per_frame: (4, 4) pose of the next sweep's start in this sweep's start
        frame (the relative motion over one frame period; identity: no change).
    frame_period_s: time between sweep starts, s.
    Returns (N, 3) de-skewed points.
    """
    return screw_apply(se3.log(motion_per_frame), np.asarray(times_s) / frame_period_s, points)


def redeskew(points: np.ndarray, normals: np.ndarray | None, times_s: np.ndarray, old_motion: np.ndarray,
             new_motion: np.ndarray, frame_period_s: float) -> tuple[np.ndarray, np.ndarray | None]:
    """Re-do the de-skew of already de-skewed points (and normals) with a better motion.

    points, normals: (M, 3) de-skewed with ``old_motion`` (normals None: points only);
    times_s: (M,) their times. Returns the (M, 3) points and normals (or None) as
    ``new_motion`` would have de-skewed them: ``T_new(t) T_old(t)^-1`` applied per point.
    """
    s = np.asarray(times_s) / frame_period_s
    xi_old, xi_new = se3.log(old_motion), se3.log(new_motion)
    p, n = _screw(-xi_old, s, points, normals)  # exp(-s xi) undoes exp(s xi)
    return _screw(xi_new, s, p, n)
