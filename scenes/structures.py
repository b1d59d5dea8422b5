"""Parts of structures stacked above the ground: slabs with openings, decks and walls along a path,
and the smooth climb of a ramp.

What the garage and the bridge share. A surface to drive on is returned apart from the rest of
its solid (underside, edges, end caps), so that it can carry the label "road" while everything
facing down or sideways carries another (the scene tests hold "road" surfaces to facing up).
Parts are ``(vertices (v, 3) float64 m, faces (f, 3) int64)``, wound outward (``geometry``).

Lateral offsets ``l`` are to the left of travel along a path (``geometry.sweep``), heights ``h``
relative to the path's points.
"""

from __future__ import annotations

import numpy as np

from . import geometry as g


# ---------------------------------------------------------------- climbs
def smooth_rise(u: np.ndarray, length_m: float, rise_m: float, transition_m: float,
                grade0: float = 0.0, grade1: float = 0.0) -> np.ndarray:
    """(n,) height gained at distances ``u`` (n,) m along a climb of ``length_m`` m.

    The grade starts at ``grade0``, turns to a constant grade over the first ``transition_m``
    (a cosine blend: the grade and its rate of change are continuous, so the pitch of a
    vehicle driving it is smooth), holds it, and blends to ``grade1`` over the last
    ``transition_m``; the constant grade is the one that gains ``rise_m`` in all. Closed form
    (the cosine blend integrates exactly); flat beyond both ends at their grades.
    """
    u = np.asarray(u, dtype=float)
    lt = float(transition_m)
    if not 0.0 < 2 * lt <= length_m:
        raise ValueError(f"a climb of {length_m:.2f} m cannot hold two transitions of {lt:.2f} m")
    g_mid = (rise_m - 0.5 * (grade0 + grade1) * lt) / (length_m - lt)

    def blend_integral(t):
        """Integral over [0, t] (t in [0, 1], times lt) of the blend S(t) = (1 - cos(pi t)) / 2."""
        return lt * (t / 2 - np.sin(np.pi * t) / (2 * np.pi))

    uc = np.clip(u, 0.0, length_m)
    t_in = np.clip(uc / lt, 0.0, 1.0)
    z = grade0 * lt * t_in + (g_mid - grade0) * blend_integral(t_in)  # first transition
    z = z + g_mid * np.clip(uc - lt, 0.0, length_m - 2 * lt)  # the constant grade
    t_out = np.clip((uc - (length_m - lt)) / lt, 0.0, 1.0)
    z = z + g_mid * lt * t_out + (grade1 - g_mid) * blend_integral(t_out)  # last transition
    # beyond the ends: straight on at the end grades
    return z + grade0 * np.minimum(u, 0.0) + grade1 * np.maximum(u - length_m, 0.0)


def climb_grade(length_m: float, rise_m: float, transition_m: float,
                grade0: float = 0.0, grade1: float = 0.0) -> float:
    """The constant grade in the middle of ``smooth_rise``'s climb (rise over run)."""
    return (rise_m - 0.5 * (grade0 + grade1) * transition_m) / (length_m - transition_m)


# ---------------------------------------------------------------- flat slabs
def cells_surface(xs: np.ndarray, ys: np.ndarray, mask: np.ndarray, z: float, up: bool = True) -> g.Part:
    """The cells of a grid where ``mask`` is set, as one flat surface at height ``z``.

    xs: (nx + 1,), ys: (ny + 1,) ascending cell boundaries, m; mask: (nx, ny) bool. Faces up,
    or down with ``up=False`` (a ceiling).
    """
    ci, cj = np.nonzero(np.asarray(mask, dtype=bool))
    if len(ci) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    corners = np.stack([np.stack([xs[ci], ys[cj]], 1), np.stack([xs[ci + 1], ys[cj]], 1),
                        np.stack([xs[ci + 1], ys[cj + 1]], 1), np.stack([xs[ci], ys[cj + 1]], 1)], 1)
    v = np.concatenate([corners.reshape(-1, 2), np.full((4 * len(ci), 1), float(z))], axis=1)
    base = 4 * np.arange(len(ci))[:, None]
    quad = np.array([[0, 1, 2], [0, 2, 3]]) if up else np.array([[0, 2, 1], [0, 3, 2]])
    return v, (base[:, None, :] + quad[None]).reshape(-1, 3)


def cell_grid(rects: list[tuple[float, float, float, float]], *more_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(xs, ys): the sorted boundaries of rectangles ``(x0, x1, y0, y1)`` (and of ``more_x``), a grid
    on which each rectangle is a block of whole cells."""
    xs = np.unique(np.round([v for r in rects for v in r[:2]] + list(more_x), 9))
    ys = np.unique(np.round([v for r in rects for v in r[2:]], 9))
    return xs, ys


def cells_in(xs: np.ndarray, ys: np.ndarray, rects) -> np.ndarray:
    """(nx, ny) bool: the grid's cells whose centre lies in any of ``rects`` ``(x0, x1, y0, y1)``."""
    cx, cy = 0.5 * (xs[1:] + xs[:-1]), 0.5 * (ys[1:] + ys[:-1])
    X, Y = np.meshgrid(cx, cy, indexing="ij")
    out = np.zeros(X.shape, dtype=bool)
    for x0, x1, y0, y1 in rects:
        out |= (X > x0) & (X < x1) & (Y > y0) & (Y < y1)
    return out


def floor_slab(xs: np.ndarray, ys: np.ndarray, mask: np.ndarray, z_top: float,
               thickness_m: float) -> tuple[g.Part, g.Part]:
    """(top, rest) of a slab over the grid cells ``mask`` (openings where unset): the floor at
    ``z_top`` facing up; the ceiling ``thickness_m`` below facing down and the edges (round the
    outline and every opening) facing out."""
    top = cells_surface(xs, ys, mask, z_top, up=True)
    bottom = cells_surface(xs, ys, mask, z_top - thickness_m, up=False)
    edges = g.grid_prism(xs, ys, mask, z_top - thickness_m, z_top, top=False)
    return top, g.merge([bottom, edges])


# ---------------------------------------------------------------- solids along a path
def _cap(corners: np.ndarray, facing: np.ndarray) -> g.Part:
    """A flat convex polygon (k, 3), fanned from its first corner, wound to face along ``facing`` (3,)."""
    k = len(corners)
    faces = np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], 1)
    tri = corners[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).sum(axis=0)
    return corners, faces if n @ facing >= 0 else faces[:, ::-1].copy()


def _heights(h, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(h, dtype=float), (n,))


def prism_along(centres: np.ndarray, lefts: np.ndarray, l0: float, l1: float, h0, h1,
                caps: bool = True) -> tuple[g.Part, g.Part]:
    """(top, rest) of a solid swept along a path: laterally from ``l0`` to ``l1`` (> l0) m, from
    ``h0`` up to ``h1`` m relative to the path's points (scalars or (n,) per point).

    centres: (n, 3) points along the path, in travel order; lefts: (n, 3) unit horizontal vectors
    to the left of travel. top faces up; rest holds the underside (down), the two sides (out)
    and, with ``caps``, the two end faces.
    """
    centres = np.asarray(centres, dtype=float)
    n = len(centres)
    a, b = _heights(h0, n), _heights(h1, n)
    if np.any(b <= a):
        raise ValueError("prism_along: h1 must lie above h0 everywhere")

    def side(p, q):  # one face of the solid: profile points p -> q, each (n, 2)
        return g.sweep(centres, lefts, np.stack([p, q], axis=1))

    L0, L1 = np.full(n, float(l0)), np.full(n, float(l1))
    top = side(np.stack([L0, b], 1), np.stack([L1, b], 1))  # l increasing: faces up
    rest = [
        side(np.stack([L1, a], 1), np.stack([L0, a], 1)),  # underside, facing down
        side(np.stack([L1, b], 1), np.stack([L1, a], 1)),  # left side, facing left (out)
        side(np.stack([L0, a], 1), np.stack([L0, b], 1)),  # right side, facing right (out)
    ]
    if caps:
        up = np.array([0.0, 0.0, 1.0])
        for i, sign in ((0, -1.0), (n - 1, 1.0)):
            j = min(i + 1, n - 1) if i == 0 else i
            fwd = centres[j] - centres[j - 1]
            c, lv = centres[i], np.asarray(lefts[i], dtype=float)
            corners = np.array([c + l0 * lv + a[i] * up, c + l1 * lv + a[i] * up,
                                c + l1 * lv + b[i] * up, c + l0 * lv + b[i] * up])
            rest.append(_cap(corners, sign * fwd))
    return top, g.merge(rest)


def wall_along(centres: np.ndarray, lefts: np.ndarray, l0: float, l1: float, h0, h1) -> g.Part:
    """A closed wall (a parapet, a retaining wall) along a path: ``prism_along`` in one part."""
    top, rest = prism_along(centres, lefts, l0, l1, h0, h1)
    return g.merge([top, rest])


def lefts_of(points: np.ndarray) -> np.ndarray:
    """(n, 3) unit horizontal vectors to the left of travel along (n, >= 2) points."""
    tang = np.gradient(np.asarray(points, dtype=float)[:, :2], axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    return np.column_stack([-tang[:, 1], tang[:, 0], np.zeros(len(tang))])


__all__ = ["cell_grid", "cells_in", "cells_surface", "climb_grade", "floor_slab", "lefts_of", "prism_along",
           "smooth_rise", "wall_along"]
