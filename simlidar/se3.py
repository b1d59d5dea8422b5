"""Small SE(3) helpers on 4x4 homogeneous matrices (float64), vectorised over a leading axis.

Twists are ordered ``xi = (rho, omega)``: translation part first, rotation part
(axis-angle, radians) second, so that ``exp(xi)`` of a pure translation is that
translation.
"""

from __future__ import annotations

import math

import numpy as np


def hat(w: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) skew-symmetric matrices with ``hat(w) @ v = w x v``."""
    w = np.asarray(w, dtype=float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def make(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations and (..., 3) translations -> (..., 4, 4) transforms."""
    R = np.asarray(R, dtype=float)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (..., 4, 4) inverse of rigid transforms."""
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    return make(R, -np.einsum("...ij,...j->...i", R, T[..., :3, 3]))


def orthonormalize(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) with the rotation block replaced by the nearest rotation (polar decomposition).

    Products of transforms and their transpose-inverses accumulate rounding that a
    feedback loop (pose = previous pose x (previous pose^-1 x estimate)) can double
    every step; projecting back onto SO(3) keeps it at machine precision.
    """
    T = np.array(T, dtype=float)
    U, _, Vt = np.linalg.svd(T[..., :3, :3])
    T[..., :3, :3] = U @ Vt
    return T


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (N, 3) points."""
    return points @ T[:3, :3].T + T[:3, 3]


def _v_matrix(omega: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors -> (..., 3, 3) left Jacobian V of SO(3)."""
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    W = hat(omega)
    W2 = W @ W
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    return np.eye(3) + a * W + b * W2


def rotation_of_rotvec(omega: np.ndarray) -> np.ndarray:
    """(3,) rotation vector -> (3, 3) rotation (Rodrigues).

    One transform at a time (the odometry's per-iteration updates), scipy's ``Rotation``
    costs a tenth of a millisecond of call overhead for three lines of arithmetic.
    """
    a, b = _jacobian_coefficients(omega)[:2]
    W = _hat3(omega)
    return np.eye(3) + a * W + b * (W @ W)


def _hat3(w: np.ndarray) -> np.ndarray:
    """(3,) -> (3, 3) ``hat`` of one vector."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _jacobian_coefficients(omega: np.ndarray) -> tuple[float, float, float]:
    """(3,) rotation vector -> ``sin(t)/t, (1 - cos t)/t^2, (t - sin t)/t^3`` (t = |omega|), series near 0:
    ``R = I + a W + b W^2`` and ``V = I + b W + c W^2``."""
    t2 = float(omega @ omega)
    if t2 < 1e-16:
        return 1.0 - t2 / 6.0, 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0
    t = math.sqrt(t2)
    return math.sin(t) / t, (1.0 - math.cos(t)) / t2, (t - math.sin(t)) / (t2 * t)


def rotvec_of_rotation(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) rotation vector, through the unit quaternion (stable at every angle).

    The quaternion's largest component is computed first (Shepperd's method), the others from
    it; then ``omega = 2 atan2(|v|, w) v / |v|``. One matrix at a time, as ``rotation_of_rotvec``.
    """
    m = R.tolist()
    diag = (m[0][0], m[1][1], m[2][2])
    tr = diag[0] + diag[1] + diag[2]
    if tr >= max(diag):
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        v = [(m[2][1] - m[1][2]) / (4.0 * w), (m[0][2] - m[2][0]) / (4.0 * w), (m[1][0] - m[0][1]) / (4.0 * w)]
    else:
        i = diag.index(max(diag))
        j, k = (i + 1) % 3, (i + 2) % 3
        v = [0.0, 0.0, 0.0]
        v[i] = 0.5 * math.sqrt(max(1.0 + m[i][i] - m[j][j] - m[k][k], 0.0))
        v[j] = (m[j][i] + m[i][j]) / (4.0 * v[i])
        v[k] = (m[k][i] + m[i][k]) / (4.0 * v[i])
        w = (m[k][j] - m[j][k]) / (4.0 * v[i])
    if w < 0:  # the quaternion of the shorter rotation
        v, w = [-x for x in v], -w
    s = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    f = 2.0 / w if s < 1e-12 else 2.0 * math.atan2(s, w) / s  # (small angle: omega = 2 v (1 + O(s^2)))
    return np.array([f * v[0], f * v[1], f * v[2]])


def _v_matrix_of(omega: np.ndarray) -> np.ndarray:
    """(3,) rotation vector -> (3, 3) left Jacobian V of SO(3) (``_v_matrix`` of one vector)."""
    _, b, c = _jacobian_coefficients(omega)
    W = _hat3(omega)
    return np.eye(3) + b * W + c * (W @ W)


def exp(xi: np.ndarray) -> np.ndarray:
    """(..., 6) twists (rho, omega) -> (..., 4, 4) transforms."""
    xi = np.asarray(xi, dtype=float)
    rho, omega = xi[..., :3], xi[..., 3:]
    if xi.shape == (6,):
        return make(rotation_of_rotvec(omega), _v_matrix_of(omega) @ rho)
    from scipy.spatial.transform import Rotation  # (not at import: scipy.spatial is most of a short run's start-up)

    R = Rotation.from_rotvec(omega.reshape(-1, 3)).as_matrix().reshape(omega.shape[:-1] + (3, 3))
    t = np.einsum("...ij,...j->...i", _v_matrix(omega), rho)
    return make(R, t)


def log(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) transforms -> (..., 6) twists (rho, omega)."""
    T = np.asarray(T, dtype=float)
    if T.shape == (4, 4):
        omega = rotvec_of_rotation(T[:3, :3])
        return np.concatenate([np.linalg.solve(_v_matrix_of(omega), T[:3, 3]), omega])
    R = T[..., :3, :3]
    from scipy.spatial.transform import Rotation

    omega = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))
    rho = np.linalg.solve(_v_matrix(omega), T[..., :3, 3][..., None])[..., 0]
    return np.concatenate([rho, omega], axis=-1)


def interpolate(T_a: np.ndarray, T_b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Screw-motion interpolation ``T_a exp(s log(T_a^-1 T_b))``.

    T_a, T_b: (4, 4) or (..., 4, 4) broadcastable with s; s: (...) fractions
    (0 gives T_a, 1 gives T_b; values outside [0, 1] extrapolate).
    """
    s = np.asarray(s, dtype=float)
    xi = log(inverse(T_a) @ T_b)
    return T_a @ exp(xi * s[..., None])


def rotation_angle(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (...) rotation angle in radians."""
    tr = np.trace(T[..., :3, :3], axis1=-2, axis2=-1)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def kitti_lines_to_poses(rows: np.ndarray) -> np.ndarray:
    """(N, 12) row-major 3x4 KITTI pose lines -> (N, 4, 4)."""
    rows = np.asarray(rows, dtype=float).reshape(-1, 12)
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    T[:, :3, :4] = rows.reshape(-1, 3, 4)
    return T


def poses_to_kitti_lines(T: np.ndarray) -> np.ndarray:
    """(N, 4, 4) -> (N, 12) row-major 3x4 KITTI pose lines."""
    return np.asarray(T)[:, :3, :4].reshape(-1, 12)
