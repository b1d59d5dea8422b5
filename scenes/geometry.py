"""Mesh parts for scene generators, each returned as ``(vertices (v, 3) float64, faces (f, 3) int64)``.

Winding convention everywhere: a triangle's normal ``(b - a) x (c - a)`` points
out of the solid, into the free space the sensor moves in (ground up, walls
outward, a tunnel's lining inward toward its axis).

Grids: a surface sampled on an (n, m) grid of vertices ``P[i, j]`` is wound so
its normal points along ``dP/di x dP/dj``.
"""

from __future__ import annotations

import copy
import functools

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

Part = tuple[np.ndarray, np.ndarray]


def rot_z(yaw: float) -> np.ndarray:
    """(3, 3) rotation about z by ``yaw`` radians."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def place(part: Part, yaw: float = 0.0, translation=(0.0, 0.0, 0.0)) -> Part:
    """Rotate a part about z by ``yaw`` rad, then translate it (m)."""
    v, f = part
    return v @ rot_z(yaw).T + np.asarray(translation, dtype=float), f


def place_tilted(part: Part, yaw: float, pitch: float, roll: float, translation=(0.0, 0.0, 0.0)) -> Part:
    """Turn a part by ``yaw`` about z, ``pitch`` about its y and ``roll`` about its x (rad;
    z-y-x order, pitch positive nose down as in the trajectory), then translate it (m).

    For objects resting on a slope (a parked car's wheels on a grade).
    """
    c, s = np.cos(pitch), np.sin(pitch)
    ry = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    c, s = np.cos(roll), np.sin(roll)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    v, f = part
    return v @ (rot_z(yaw) @ ry @ rx).T + np.asarray(translation, dtype=float), f


def box(size, center=(0.0, 0.0, 0.0), yaw: float = 0.0) -> Part:
    """Axis-aligned box of ``size`` (3,) m, rotated by ``yaw`` about z, centred at ``center``."""
    m = trimesh.creation.box(extents=np.asarray(size, dtype=float))
    return place((np.asarray(m.vertices), np.asarray(m.faces)), yaw, center)


def cylinder(radius: float, height: float, base=(0.0, 0.0, 0.0), sections: int = 8) -> Part:
    """Vertical cylinder standing on ``base`` (3,), m."""
    v, f = _unit_cylinder(sections)
    return v * np.array([radius, radius, height]) + np.asarray(base, dtype=float), f.copy()


@functools.lru_cache(maxsize=32)
def _unit_cylinder(sections: int) -> Part:
    """Radius 1, from z = 0 to 1 (trimesh's, built once per section count: scenes place thousands)."""
    m = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=sections)
    v = np.asarray(m.vertices) + np.array([0.0, 0.0, 0.5])
    v.setflags(write=False)
    f = np.asarray(m.faces)
    f.setflags(write=False)
    return v, f


def convex(points: np.ndarray) -> Part:
    """Convex hull of (n, 3) points, outward-wound (rocks, crowns, roofs, car cabins).

    scipy's qhull directly, each facet turned to agree with qhull's outward facet
    normal: the same result as ``trimesh.convex.convex_hull`` without building and
    processing a Trimesh, which dominates when a forest places thousands of crowns.
    """
    hull = ConvexHull(np.asarray(points, dtype=float))
    faces = hull.simplices.copy()
    p = hull.points
    cross = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    backwards = np.einsum("ij,ij->i", cross, hull.equations[:, :3]) < 0
    faces[backwards] = faces[backwards][:, ::-1]
    used, inverse = np.unique(faces, return_inverse=True)
    return p[used], inverse.reshape(faces.shape).astype(np.int64)


def blob(rng: np.random.Generator, radii, center, n_points: int = 24, jitter: float = 0.25) -> Part:
    """An irregular convex lump: hull of ``n_points`` random directions on an ellipsoid.

    radii: (3,) semi-axes, m; jitter: relative radial randomness.
    """
    d = rng.normal(size=(n_points, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = 1.0 + jitter * (rng.random(n_points) - 0.5) * 2.0
    return convex(d * r[:, None] * np.asarray(radii, dtype=float) + np.asarray(center, dtype=float))


def grid_faces(n: int, m: int, closed_j: bool = False) -> np.ndarray:
    """Faces of an (n, m) vertex grid (row-major), normal along dP/di x dP/dj.

    closed_j: also join column m - 1 to column 0 (a closed profile).
    """
    i, j = np.meshgrid(np.arange(n - 1), np.arange(m if closed_j else m - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    jn = (j + 1) % m
    a, b, c, d = i * m + j, (i + 1) * m + j, (i + 1) * m + jn, i * m + jn
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def grid_surface(X: np.ndarray, Y: np.ndarray, Z: np.ndarray) -> Part:
    """A surface sampled on (n, m) grids X, Y, Z, wound along dP/di x dP/dj."""
    n, m = X.shape
    v = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    return v, grid_faces(n, m)


def heightfield(xs: np.ndarray, ys: np.ndarray, height) -> Part:
    """Upward-facing terrain over the rectangle spanned by ``xs`` (n,) and ``ys`` (m,), ascending.

    height: callable (k,) x, (k,) y -> (k,) z, metres.
    """
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = np.asarray(height(X.ravel(), Y.ravel())).reshape(X.shape)
    return grid_surface(X, Y, Z)


def sweep(centres: np.ndarray, lefts: np.ndarray, profile: np.ndarray, closed: bool = False) -> Part:
    """Sweep a cross-section along a path.

    centres: (n, 3) path points; lefts: (n, 3) unit horizontal vectors to the left
    of travel; profile: (k, 2) or (n, k, 2) points (lateral l to the left, height h), m.
    Vertex (i, j) = centres[i] + l_ij * lefts[i] + h_ij * z. The normal points along
    forward x (profile direction): a profile running right-to-left (l increasing)
    faces up; one running up faces right (toward -l).
    """
    centres = np.asarray(centres, dtype=float)
    profile = np.asarray(profile, dtype=float)
    if profile.ndim == 2:
        profile = np.broadcast_to(profile, (len(centres),) + profile.shape)
    n, k = profile.shape[:2]
    v = (
        centres[:, None, :]
        + profile[:, :, :1] * np.asarray(lefts, dtype=float)[:, None, :]
        + profile[:, :, 1:2] * np.array([0.0, 0.0, 1.0])
    )
    return v.reshape(-1, 3), grid_faces(n, k, closed_j=closed)


def stitch_chains(inner: np.ndarray, outer: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Triangulate the band between two chains that wind the same way around ``centre``.

    inner: (a, 2), outer: (b, 2) points in a plane, both ordered by decreasing polar
    angle about ``centre`` (2,) (e.g. from the left end over the top to the right end);
    the inner chain must lie between ``centre`` and the outer one. Returns (f, 3)
    faces indexing the stacked ``[inner; outer]`` (a + b points), wound clockwise
    in the plane's (x, y) axes (so flip for the other side).
    """
    ang_i = np.unwrap(np.arctan2(inner[:, 1] - centre[1], inner[:, 0] - centre[0]))
    ang_o = np.unwrap(np.arctan2(outer[:, 1] - centre[1], outer[:, 0] - centre[0]))
    a, b = len(inner), len(outer)
    faces = []
    i = j = 0
    while i < a - 1 or j < b - 1:
        # advance the chain whose next point comes first in angle (both decrease)
        advance_inner = j == b - 1 or (i < a - 1 and ang_i[i + 1] >= ang_o[j + 1])
        if advance_inner:
            faces.append((i, i + 1, a + j))
            i += 1
        else:
            faces.append((i, a + j + 1, a + j))
            j += 1
    return np.asarray(faces, dtype=np.int64)


def grid_prism(xs: np.ndarray, ys: np.ndarray, mask: np.ndarray, z0: float, z1: float,
               top: bool = True) -> Part:
    """Extrude an orthogonal footprint (a union of grid cells) from ``z0`` up to ``z1``.

    xs: (nx + 1,) and ys: (ny + 1,) ascending cell boundaries, m; mask: (nx, ny)
    bool occupied cells (L-, T-, U-shapes, courtyards...). Walls only where an
    occupied cell meets an empty one or the border, a flat top over every occupied
    cell, no bottom (it stands in the ground). Watertight along the walls: walls
    and top share the grid's vertices.
    """
    mask = np.asarray(mask, dtype=bool)
    nx, ny = mask.shape
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    gx, gy = X.ravel(), Y.ravel()
    n_grid = len(gx)
    verts = np.concatenate([np.stack([gx, gy, np.full(n_grid, z0)], 1),
                            np.stack([gx, gy, np.full(n_grid, z1)], 1)])

    def vid(i, j, level):
        return level * n_grid + i * (ny + 1) + j

    faces = []
    if top:
        ci, cj = np.nonzero(mask)
        a, b = vid(ci, cj, 1), vid(ci + 1, cj, 1)
        c, d = vid(ci + 1, cj + 1, 1), vid(ci, cj + 1, 1)
        faces += [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    padded = np.zeros((nx + 2, ny + 2), dtype=bool)
    padded[1:-1, 1:-1] = mask
    # A wall where an occupied cell borders an empty one; each quad wound outward.
    # +x side of cell (i, j): edge from (i+1, j) to (i+1, j+1).
    for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        nb = padded[1 + di: nx + 1 + di, 1 + dj: ny + 1 + dj]
        ci, cj = np.nonzero(mask & ~nb)
        if len(ci) == 0:
            continue
        if (di, dj) == (1, 0):
            p, q = (ci + 1, cj), (ci + 1, cj + 1)
        elif (di, dj) == (-1, 0):
            p, q = (ci, cj + 1), (ci, cj)
        elif (di, dj) == (0, 1):
            p, q = (ci + 1, cj + 1), (ci, cj + 1)
        else:
            p, q = (ci, cj), (ci + 1, cj)
        # p -> q runs counter-clockwise around the cell seen from above; outward
        # normal of quad (p0, q0, q1, p1) is (q0 - p0) x z.
        p0, q0 = vid(*p, 0), vid(*q, 0)
        p1, q1 = vid(*p, 1), vid(*q, 1)
        faces += [np.stack([p0, q0, q1], 1), np.stack([p0, q1, p1], 1)]
    f = np.concatenate(faces).astype(np.int64)
    used, inverse = np.unique(f, return_inverse=True)
    return verts[used], inverse.reshape(f.shape)


def flip(part: Part) -> Part:
    """Reverse the winding of every triangle."""
    v, f = part
    return v, f[:, ::-1].copy()


def merge(parts: list[Part]) -> Part:
    """Concatenate parts into one."""
    vs, fs, base = [], [], 0
    for v, f in parts:
        vs.append(v)
        fs.append(f + base)
        base += len(v)
    return np.vstack(vs), np.vstack(fs)


class SmoothField:
    """A smooth random scalar field on the plane: a sum of plane waves.

    amplitude_m: standard deviation of the field; wavelengths_m: (min, max) of the
    waves' wavelengths. Evaluates exactly anywhere, so a mesh and the trajectory's
    roll and pitch read the same surface.
    """

    def __init__(self, rng: np.random.Generator, amplitude_m: float, wavelengths_m=(80.0, 300.0),
                 n_waves: int = 8):
        lam = np.exp(rng.uniform(np.log(wavelengths_m[0]), np.log(wavelengths_m[1]), n_waves))
        ang = rng.uniform(0, 2 * np.pi, n_waves)
        self.k = (2 * np.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (n, 2)
        self.phase = rng.uniform(0, 2 * np.pi, n_waves)
        # Longer waves carry more amplitude (a red spectrum, like real terrain).
        w = lam / lam.sum()
        self.amp = amplitude_m * np.sqrt(2.0) * w / np.sqrt(np.sum(w**2))

    def __call__(self, x, y) -> np.ndarray:
        """(k,) x, (k,) y, m -> (k,) value, m."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        arg = x[..., None] * self.k[:, 0] + y[..., None] * self.k[:, 1] + self.phase
        return np.sin(arg) @ self.amp

    def gradient(self, x, y) -> np.ndarray:
        """(k,) x, (k,) y, m -> (k, 2) exact slope (d/dx, d/dy), m/m."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        arg = x[..., None] * self.k[:, 0] + y[..., None] * self.k[:, 1] + self.phase
        return np.cos(arg) @ (self.amp[:, None] * self.k)

    def hessian(self, x, y) -> np.ndarray:
        """(k,) x, (k,) y, m -> (k, 2, 2) exact second derivatives (d2/dx2, d2/dxdy; d2/dydx, d2/dy2), 1/m."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        arg = x[..., None] * self.k[:, 0] + y[..., None] * self.k[:, 1] + self.phase
        kk = self.amp[:, None, None] * self.k[:, :, None] * self.k[:, None, :]  # (n, 2, 2)
        return -np.einsum("...n,nij->...ij", np.sin(arg), kk)

    def scaled(self, factor: float) -> SmoothField:
        """A copy whose values and slopes are ``factor`` times this field's."""
        out = copy.copy(self)
        out.amp = self.amp * factor
        return out


def wall_strip(points: np.ndarray, z_bottom: np.ndarray, z_top: np.ndarray, closed: bool = False) -> Part:
    """A vertical band along a plane polyline (a kerb, a fence, a barrier's face).

    points: (n, 2) m; z_bottom, z_top: (n,) heights, m. The band faces the right
    of travel, i.e. outward for a loop run counter-clockwise seen from above.
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    zb = np.broadcast_to(np.asarray(z_bottom, dtype=float), (n,))
    zt = np.broadcast_to(np.asarray(z_top, dtype=float), (n,))
    # grid i = along the polyline, j = bottom -> top: normal along forward x up = right.
    v = np.stack([np.column_stack([points, zb]), np.column_stack([points, zt])], axis=1)
    f = grid_faces(n + 1 if closed else n, 2)
    if closed:
        v = np.concatenate([v, v[:1]])
    return v.reshape(-1, 3), f
