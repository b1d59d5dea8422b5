"""Polylines for drivable paths: corners rounded by arcs, resampling, offsets, and ``Route``:
a path driven as straights and arcs, each with its own height profile."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.ndimage import gaussian_filter1d


def fillet(corners: np.ndarray, radius_m: float, closed: bool, step_m: float = 0.5) -> np.ndarray:
    """Replace each corner of a polyline by a tangent circular arc.

    corners: (n, 2) vertices, m; radius_m: arc radius (shrunk at a corner where
    the adjacent segments are too short to hold it); closed: the last vertex
    joins the first. Returns (m, 2) points about ``step_m`` apart (open: from the
    first vertex to the last; closed: once round, not repeating the start).
    """
    p = np.asarray(corners, dtype=float)
    n = len(p)
    idx = range(n) if closed else range(1, n - 1)
    seg_len = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)  # seg k: p[k] -> p[k+1]
    pieces: list[np.ndarray] = []
    start = None if closed else p[0]
    first_tangent_point = None
    for k in idx:
        a, b, c = p[k - 1], p[k], p[(k + 1) % n]
        u = (b - a) / np.linalg.norm(b - a)
        w = (c - b) / np.linalg.norm(c - b)
        turn = np.arctan2(u[0] * w[1] - u[1] * w[0], u @ w)  # signed, left positive
        if abs(turn) < 1e-9:
            continue
        half_seg = 0.5 * min(seg_len[k - 1], seg_len[k % n])
        r = min(radius_m, half_seg / np.tan(abs(turn) / 2))
        t = r * np.tan(abs(turn) / 2)
        p_in, p_out = b - u * t, b + w * t
        normal = np.array([-u[1], u[0]]) * np.sign(turn)  # toward the arc's centre
        centre = p_in + normal * r
        a0 = np.arctan2(p_in[1] - centre[1], p_in[0] - centre[0])
        n_arc = max(2, int(np.ceil(abs(turn) * r / step_m)) + 1)
        ang = a0 + np.linspace(0.0, turn, n_arc)
        arc = centre + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        if start is not None:
            pieces.append(_line(start, p_in, step_m))
        else:
            first_tangent_point = p_in
        pieces.append(arc[:-1])
        start = p_out
    if closed:
        if first_tangent_point is None:
            raise ValueError("a closed path needs at least one corner")
        pieces.append(_line(start, first_tangent_point, step_m))
        out = np.vstack(pieces)
        # Begin where the polyline begins (its first vertex may lie on a straight).
        return np.roll(out, -int(np.argmin(np.linalg.norm(out - p[0], axis=1))), axis=0)
    else:
        pieces.append(_line(start, p[-1], step_m))
        pieces.append(p[-1:])
    return np.vstack(pieces)


def _line(a: np.ndarray, b: np.ndarray, step_m: float) -> np.ndarray:
    """Points from a (included) to b (excluded), about step_m apart."""
    n = max(1, int(np.ceil(np.linalg.norm(b - a) / step_m)))
    s = np.arange(n) / n
    return a + s[:, None] * (b - a)


def arc_length(points: np.ndarray, closed: bool = False) -> np.ndarray:
    """(m,) cumulative length along (m, d) points, m (closed: without the closing segment)."""
    d = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(d)])


def resample(points: np.ndarray, step_m: float, closed: bool) -> np.ndarray:
    """Points evenly ``step_m`` apart (approximately) along a polyline (m, d)."""
    p = np.vstack([points, points[:1]]) if closed else np.asarray(points)
    s = arc_length(p)
    n = max(2, int(round(s[-1] / step_m)) + (0 if closed else 1))
    s_new = np.linspace(0.0, s[-1], n, endpoint=not closed)
    return np.stack([np.interp(s_new, s, p[:, k]) for k in range(p.shape[1])], axis=1)


def smooth(points: np.ndarray, sigma_m: float, step_m: float, closed: bool) -> np.ndarray:
    """Gaussian smoothing along an evenly sampled polyline (continuous curvature at arc joins).

    Open paths keep their end points (the filter reflects about them).
    """
    if sigma_m <= 0:
        return points
    sigma = sigma_m / step_m
    if closed:
        return gaussian_filter1d(points, sigma, axis=0, mode="wrap")
    # Odd reflection about the ends keeps the end points and the end tangents.
    n_pad = int(4 * sigma) + 1
    head = 2 * points[0] - points[n_pad:0:-1]
    tail = 2 * points[-1] - points[-2:-n_pad - 2:-1]
    ext = np.vstack([head, points, tail])
    return gaussian_filter1d(ext, sigma, axis=0, mode="nearest")[n_pad:-n_pad]


def left_normals(points: np.ndarray, closed: bool) -> np.ndarray:
    """(m, 2) unit normals to the left of travel along (m, 2) points."""
    if closed:
        tang = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        tang = np.gradient(points, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    return np.stack([-tang[:, 1], tang[:, 0]], axis=1)


def offset(points: np.ndarray, distance_m: float, closed: bool) -> np.ndarray:
    """Shift (m, 2) points ``distance_m`` to the left of travel (negative: right)."""
    return points + distance_m * left_normals(points, closed)


class Route:
    """A path built by driving it: straights and circular arcs from a start point and heading,
    each with a height profile of its own (multi-level worlds: a ramp, a helix).

    Points come every ``step_m`` (about: each piece is divided evenly); ``points`` is the (m, 3)
    path so far, ``marks`` the index of each named place (``mark``). Headings in radians, x
    east, y north, arcs turning left for a positive sweep.
    """

    def __init__(self, start_xy, heading: float, z: float, step_m: float = 0.5):
        self.xy = np.asarray(start_xy, dtype=float)
        self.heading = float(heading)
        self.z = float(z)
        self.step_m = step_m
        self._pieces: list[np.ndarray] = [np.array([[*self.xy, self.z]])]
        self.marks: dict[str, int] = {}

    @property
    def points(self) -> np.ndarray:
        return np.vstack(self._pieces)

    def mark(self, name: str) -> None:
        """Remember the index of the current (last) point as ``name``."""
        self.marks[name] = sum(len(p) for p in self._pieces) - 1

    def _append(self, xy: np.ndarray, u: np.ndarray, height: Callable[[np.ndarray], np.ndarray] | None) -> None:
        z = np.full(len(u), self.z) if height is None else self.z + np.asarray(height(u), dtype=float)
        self._pieces.append(np.column_stack([xy, z]))
        self.xy, self.z = xy[-1].copy(), float(z[-1])

    def straight(self, length_m: float, height: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        """Drive ``length_m`` straight on; ``height(u)``: (k,) distance -> (k,) rise above the start, m."""
        n = max(1, int(np.ceil(length_m / self.step_m)))
        u = length_m * np.arange(1, n + 1) / n
        d = np.array([np.cos(self.heading), np.sin(self.heading)])
        self._append(self.xy + u[:, None] * d, u, height)

    def arc(self, radius_m: float, sweep_rad: float, height: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        """Turn through ``sweep_rad`` (positive: left) on a circle of ``radius_m``; ``height`` as ``straight``'s."""
        length = radius_m * abs(sweep_rad)
        n = max(2, int(np.ceil(length / self.step_m)))
        u = length * np.arange(1, n + 1) / n
        side = np.sign(sweep_rad)
        centre = self.xy + side * radius_m * np.array([-np.sin(self.heading), np.cos(self.heading)])
        start = np.arctan2(self.xy[1] - centre[1], self.xy[0] - centre[0])
        ang = start + side * u / radius_m
        self._append(centre + radius_m * np.column_stack([np.cos(ang), np.sin(ang)]), u, height)
        self.heading += sweep_rad
