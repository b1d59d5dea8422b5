"""De-skew: undo a sweep's motion distortion under the constant-velocity assumption.

A spinning lidar reports each point in its own frame at the point's firing
time. If the sensor moves at constant velocity (twist xi per frame period),
the sensor at time t after the sweep start sits at ``exp((t / period) xi)`` in
the frame of the sweep start, so a point measured at t is brought into the
sweep-start frame by that transform. Beyond the paper (which leaves this to
wheel odometry); the simulator's ``true_xyz`` is the exact answer to check it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from simlidar import se3

from .kernels.screw import rescrew_motion, screw_motion

if TYPE_CHECKING:
    from .filters import FilteredScan


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
    in one compiled pass (``odometry.kernels.screw.screw_motion``)."""
    xi = np.asarray(xi, dtype=np.float64)
    if points is None and normals is None:
        return None, None
    n = len(points if points is not None else normals)
    if points is not None and normals is not None and np.shape(normals) != np.shape(points):
        raise ValueError(f"normals must be shaped as the points {np.shape(points)}, got {np.shape(normals)}")
    s = np.ascontiguousarray(np.broadcast_to(np.asarray(s, dtype=np.float64), (n,)))  # (a scalar: every point)
    if points is None:  # (the rotation alone: a twist without translation moves nothing else)
        if np.linalg.norm(xi[3:]) < 1e-12:
            return None, np.array(normals, dtype=np.float64)
        rotated, _ = screw_motion(np.concatenate([np.zeros(3), xi[3:]]), s, _rows(normals), _NO_ROWS)
        return None, rotated
    moved, n_out = screw_motion(xi, s, _rows(points), _NO_ROWS if normals is None else _rows(normals))
    return moved, None if normals is None else n_out


_NO_ROWS = np.zeros((0, 3))


def _rows(a: np.ndarray) -> np.ndarray:
    """(N, 3) float64 contiguous rows (the kernel's layout); anything else is refused."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"need (N, 3) points or normals, got {a.shape}")
    return a


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


@dataclass
class RedeskewMemo:
    """What the last ``redeskew`` of one array left for the next (an ICP re-de-skews its source at every
    step, each time from the twist the last one de-skewed it with).

    twist: (6,) the twist it de-skewed with; fractions: (M,) its points' times over the frame period;
    scalars: (M, 4) their ``kernels.screw.rescrew_motion`` scalars of that twist (cosine, sine and the left
    Jacobian's two factors), which undoing it takes again. None before the first.
    """

    twist: np.ndarray | None = None
    fractions: np.ndarray | None = None
    scalars: np.ndarray | None = None


def redeskew(points: np.ndarray, normals: np.ndarray | None, times_s: np.ndarray, old_motion: np.ndarray,
             new_motion: np.ndarray, frame_period_s: float, memo: RedeskewMemo | None = None
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """Re-do the de-skew of already de-skewed points (and normals) with a better motion.

    points, normals: (M, 3) de-skewed with ``old_motion`` (normals None: points only);
    times_s: (M,) their times. Returns the (M, 3) points and normals (or None) as
    ``new_motion`` would have de-skewed them: ``T_new(t) T_old(t)^-1`` applied per point.
    The motions are (4, 4) transforms or their (6,) twists (``se3.log``: a caller moving
    several arrays by the same motions takes the logarithms once).
    memo: kept by the caller for one array re-de-skewed again and again: when the last call
    de-skewed these times with exactly ``old_motion``, its per-point scalars spare the undo its
    trigonometry (the same numbers, so the same result); updated for the next call.
    """
    points = _rows(points)
    if normals is not None and np.shape(normals) != points.shape:
        raise ValueError(f"normals must be shaped as the points {points.shape}, got {np.shape(normals)}")
    s = np.ascontiguousarray(np.broadcast_to(np.asarray(times_s, dtype=np.float64) / frame_period_s, (len(points),)))
    xi_old, xi_new = twist_of(old_motion), twist_of(new_motion)
    old_scalars = new_scalars = _NO_SCALARS
    if memo is not None:
        if memo.scalars is not None and np.array_equal(memo.twist, xi_old) and np.array_equal(memo.fractions, s):
            old_scalars = memo.scalars
        new_scalars = np.empty((len(points), 4))
    # (exp(-s xi_old) undoes the old de-skew, exp(s xi_new) does the new one: one compiled pass)
    p, n = rescrew_motion(xi_old, xi_new, s, points, _NO_ROWS if normals is None else _rows(normals), old_scalars,
                          new_scalars)
    if memo is not None:
        memo.twist, memo.fractions, memo.scalars = xi_new.copy(), s, new_scalars
    return p, None if normals is None else n


_NO_SCALARS = np.zeros((0, 4))


def twist_of(motion: np.ndarray) -> np.ndarray:
    """(6,) the twist of a (4, 4) motion (``se3.log``), or the (6,) twist given."""
    motion = np.asarray(motion, dtype=np.float64)
    return motion if motion.shape == (6,) else se3.log(motion)


def redeskew_scan(scan: FilteredScan, old_motion: np.ndarray, new_motion: np.ndarray, period_s: float,
                  centroids_motion: np.ndarray | None = None, memo: RedeskewMemo | None = None) -> None:
    """Re-do the de-skew of a filtered scan's points, normals and poles with a better motion (in place).

    The centroids (what a map takes) move with the points when they are the points. Otherwise
    they move only when ``centroids_motion`` (4, 4), the motion they are de-skewed with now, is
    given: the de-skew refinements leave them, since only the frame's final motion matters to the map.
    Motions are (4, 4) transforms or their (6,) twists (``redeskew``). memo: the points'
    ``RedeskewMemo`` (``redeskew``), kept by whoever re-de-skews this scan again and again.
    """
    same = scan.points is scan.centroids  # (the ICP points are the centroids: move them once)
    old_motion, new_motion = twist_of(old_motion), twist_of(new_motion)  # (once for every array moved)
    # (a scan registered against a map has no normals of its own: nan rows, which stay nan)
    without_normals = len(scan.normals) > 0 and bool(np.isnan(scan.normals[:, 0]).all())
    scan.points, normals = redeskew(scan.points, None if without_normals else scan.normals, scan.times_s,
                                    old_motion, new_motion, period_s, memo)
    if not without_normals:
        scan.normals = normals
    poles = scan.poles
    if poles is not None and poles.times_s is not None and len(poles):
        poles.points, _ = redeskew(poles.points, None, poles.times_s, old_motion, new_motion, period_s)
    if same:
        scan.centroids = scan.points
    elif centroids_motion is not None and scan.centroid_times_s is not None and len(scan.centroids):
        scan.centroids, _ = redeskew(scan.centroids, None, scan.centroid_times_s, centroids_motion, new_motion,
                                     period_s)
