"""Suburb: a winding loop road over rolling terrain, detached houses, gardens, parked cars.

The terrain is a smooth heightfield (a few seeded long waves) scaled so that
the steepest grade along the driven lane is ``max_grade_pct``: the road, its
kerbs and sidewalks, the houses, trees and cars all follow it, and the
trajectory pitches with the grade and rolls with the cross-slope. The road is
a closed loop ``loop_length_m`` long with bends of varying radius (a circle
with random harmonics, no bend tighter than ``min_curve_radius_m``),
``road_width_m`` kerb to kerb, with a sidewalk on both sides.

Along both sides, detached houses face the road (``houses_per_100m`` per
side), set back ``setback_min_m``-``setback_max_m`` behind the sidewalk: one
to ``storeys_max`` storeys on a plinth that follows the slope (its foot 0.3 m
in the ground at every corner, its floor level above the highest corner), a
gable or hip roof, sometimes an attached garage. Front gardens are hedged or
fenced (``fence_fraction``), trees stand in the gardens
(``trees_per_100m``) and in the land beyond the houses
(``park_trees_per_ha``), lamp posts line the road and cars park along the
kerbs where the lane leaves room.

Metadata: ``path_length_m``, ``loop_length_m`` (the road's centre-line),
``grade_max`` (steepest grade of the driven lane, a fraction), ``relief_m``
(height range of the lane), ``min_radius_m`` (tightest bend of the
centre-line), ``houses``, ``trees``, ``parked_cars``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .open_field import random_loop
from .params import CommonParams, ParamError, param
from .traffic import two_way_road
from .trajectory import PathTrajectory

DESCRIPTION = "winding suburban loop over rolling terrain: detached houses, gardens, trees, parked cars"

STEP_M = 0.5  # path and centre-line sampling
SLICE_M = 2.0  # length of one row of the road's mesh
GRID_M = 4.0  # terrain mesh spacing
BEVEL_M = 0.3  # the sidewalk's outer edge slopes down to the ground over this width
FOOT_DEPTH_M = 0.3  # houses, hedges and fences reach this far into the ground
STOREY_M = 2.8
CAR_HALF_WIDTH_M = 0.95  # a parked car's half width with mirrors (props.car is at most 0.925)
PARK_FROM_KERB_M = 1.05  # a parked car's centre from the kerb


@dataclass(frozen=True)
class Params(CommonParams):
    loop_length_m: float = param(700.0, "length of the loop road's centre-line", min=250.0, max=3000.0)
    loop_wiggle: float = param(0.12, "largest relative amplitude of each of the loop's bends (harmonics 2-4 of "
                               "its radius; 0: a circle)", min=0.0, max=0.25)
    min_curve_radius_m: float = param(25.0, "tightest bend of the road's centre-line", min=12.0, max=1000.0)
    road_width_m: float = param(10.0, "road width kerb to kerb (two lanes, parking where it fits)",
                                min=6.0, max=16.0)
    lane_offset_m: float = param(1.5, "the vehicle drives this far right of the centre-line", min=0.0, max=5.0)
    sidewalk_width_m: float = param(1.8, "sidewalk width", min=1.0, max=5.0)
    kerb_height_m: float = param(0.12, "kerb height", min=0.0, max=0.3)
    max_grade_pct: float = param(5.0, "steepest grade of the driven lane (the terrain is scaled to it)",
                                 min=0.0, max=10.0)
    hill_wavelength_m: float = param(250.0, "typical wavelength of the terrain's undulations",
                                     min=80.0, max=2000.0)
    houses_per_100m: float = param(6.0, "houses per 100 m of road on each side (fewer where they do not fit)",
                                   min=0.0, max=12.0)
    setback_min_m: float = param(4.0, "shortest front garden, sidewalk to facade", min=2.0, max=50.0)
    setback_max_m: float = param(14.0, "longest front garden, sidewalk to facade", min=2.0, max=60.0)
    storeys_max: int = param(2, "most storeys of a house (1 to this)", min=1, max=3)
    garage_fraction: float = param(0.5, "share of houses with an attached garage", min=0.0, max=1.0)
    fence_fraction: float = param(0.6, "share of front gardens with a hedge or fence along the sidewalk",
                                  min=0.0, max=1.0)
    trees_per_100m: float = param(8.0, "garden trees per 100 m of road (both sides)", min=0.0, max=60.0)
    park_trees_per_ha: float = param(25.0, "trees per hectare in the land beyond the houses", min=0.0, max=400.0)
    parked_cars_per_100m: float = param(4.0, "parked cars per 100 m of road (both kerbs)", min=0.0, max=30.0)
    light_spacing_m: float = param(45.0, "spacing of lamp posts, alternating sides (0: none)",
                                   min=0.0, max=1000.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.setback_max_m < self.setback_min_m:
            raise ParamError("is below setback_min_m", "setback_max_m")
        if self.lane_offset_m > self.road_width_m / 2 - 1.5:
            raise ParamError(f"is {self.lane_offset_m} m: that leaves a {self.road_width_m} m road "
                             f"(at most road_width_m / 2 - 1.5)", "lane_offset_m")
        if self.loop_length_m / (2 * np.pi) < 1.5 * self.min_curve_radius_m:
            raise ParamError(f"is too large: a {self.loop_length_m:g} m loop cannot keep its bends above "
                             f"{self.min_curve_radius_m:g} m (at most loop_length_m / (3 pi))", "min_curve_radius_m")
        half = self.road_width_m / 2 + self.sidewalk_width_m + BEVEL_M
        if self.min_curve_radius_m < half + 5.0:
            raise ParamError(f"is too small: bends tighter than the road's half width + 5 m ({half + 5.0:g} m) "
                             f"fold its inner edge", "min_curve_radius_m")


class _Footprints:
    """Oriented rectangles on the plane (houses with their gardens' margins) and overlap tests."""

    def __init__(self) -> None:
        self.centres: list[np.ndarray] = []
        self.axes: list[np.ndarray] = []  # (2, 2) rows: unit u, unit v
        self.halves: list[np.ndarray] = []  # (2,) half sizes along u, v

    def overlaps(self, centre: np.ndarray, axes: np.ndarray, half: np.ndarray, gap: float) -> bool:
        """Whether the rectangle, grown by ``gap`` / 2 each way, meets one already added (grown alike)."""
        half = half + gap / 2
        for c, a, h in zip(self.centres, self.axes, self.halves, strict=True):
            h = h + gap / 2
            d = centre - c
            if np.linalg.norm(d) > np.linalg.norm(half) + np.linalg.norm(h):
                continue
            # separating axis test over the four edge normals
            separated = False
            for axis in (*axes, *a):
                r1 = np.abs(axes @ axis) @ half
                r2 = np.abs(a @ axis) @ h
                if abs(d @ axis) > r1 + r2:
                    separated = True
                    break
            if not separated:
                return True
        return False

    def add(self, centre: np.ndarray, axes: np.ndarray, half: np.ndarray) -> None:
        self.centres.append(centre)
        self.axes.append(axes)
        self.halves.append(half)

    def contains(self, points: np.ndarray, margin: float) -> np.ndarray:
        """(n,) whether each of (n, 2) points lies within ``margin`` of a rectangle."""
        inside = np.zeros(len(points), dtype=bool)
        for c, a, h in zip(self.centres, self.axes, self.halves, strict=True):
            local = np.abs((points - c) @ a.T)
            inside |= np.all(local <= h + margin, axis=1)
        return inside


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0x5B0B])
    centre, min_radius = _loop(p, rng)
    closed_centre = np.vstack([centre, centre[:1]])
    s_centre = paths.arc_length(closed_centre)
    loop_len = float(s_centre[-1])
    left = paths.left_normals(centre, closed=True)
    heading = np.arctan2(-left[:, 0], left[:, 1])
    near_road = cKDTree(centre)

    lane = paths.offset(centre, -p.lane_offset_m, closed=True)
    lane = paths.smooth(paths.resample(lane, STEP_M, closed=True), 2.0, STEP_M, closed=True)
    terrain = _terrain(p, rng, lane)

    road_half = p.road_width_m / 2
    corridor = road_half + p.sidewalk_width_m + BEVEL_M  # the road's built width, each side
    lo = centre.min(axis=0) - (corridor + p.setback_max_m + 90.0)
    hi = centre.max(axis=0) + (corridor + p.setback_max_m + 90.0)

    mb = MeshBuilder()
    _ground(mb, p, terrain, near_road, corridor, lo, hi)
    _road(mb, p, terrain, centre, left)

    footprints = _Footprints()
    n_houses = 0
    frontages = []  # (s, side, width) of each house, for its garden's fence
    for side in (1.0, -1.0):
        n, fr = _houses(mb, p, rng, terrain, centre, left, heading, s_centre, near_road, corridor, side,
                        footprints)
        n_houses += n
        frontages += fr
    _front_fences(mb, p, rng, terrain, centre, left, heading, s_centre, corridor, frontages)
    n_cars = _parked_cars(mb, p, rng, terrain, centre, left, heading, s_centre)
    _lamp_posts(mb, p, terrain, centre, left, heading, s_centre, corridor)
    n_trees = _garden_trees(mb, p, rng, terrain, centre, left, s_centre, near_road, corridor, footprints)
    n_trees += _park_trees(mb, p, rng, terrain, near_road, corridor, footprints, lo, hi)

    path = np.column_stack([lane, terrain(lane[:, 0], lane[:, 1])])
    traj = PathTrajectory(
        path, True, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed, surface_height=terrain,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    grade = _grades(path)
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    roads = two_way_road(p.lane_offset_m, p.road_width_m / 2, True, terrain, p.road_width_m / 2 - PARK_FROM_KERB_M,
                         CAR_HALF_WIDTH_M, p.sidewalk_width_m, p.kerb_height_m)
    return Scene(
        "suburb", v, f, ids, labels, path, traj, p.to_dict(), roads=roads, metadata=
        {
            "path_length_m": traj.length_m,
            "loop_length_m": loop_len,
            "grade_max": float(np.abs(grade).max()),
            "relief_m": float(np.ptp(path[:, 2])),
            "min_radius_m": min_radius,
            "houses": n_houses,
            "trees": n_trees,
            "parked_cars": n_cars,
        },
    )


# ---------------------------------------------------------------- plan and terrain
def _loop(p: Params, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(n, 2) the road's centre-line, a closed loop ``loop_length_m`` long sampled every
    ``STEP_M``, and its tightest bend radius, m.

    The loop is drawn again with smaller bends while one is tighter than
    ``min_curve_radius_m``; the parameters' check guarantees a circle qualifies.
    """
    radius = p.loop_length_m / (2 * np.pi)
    wiggle = p.loop_wiggle
    for _ in range(12):
        pts = random_loop(rng, radius, STEP_M, (wiggle / 4, wiggle))
        pts = pts * p.loop_length_m / paths.arc_length(np.vstack([pts, pts[:1]]))[-1]
        # smoothed: the resampled polyline's corners would make the kerbs' offsets wiggle
        pts = paths.smooth(paths.resample(pts, STEP_M, closed=True), 1.0, STEP_M, closed=True)
        r_min = _min_radius(pts)
        if r_min >= p.min_curve_radius_m:
            break
        wiggle *= 0.75
    else:
        pts = random_loop(rng, radius, STEP_M, (0.0, 0.0))
        r_min = _min_radius(pts)
    if rng.random() < 0.5:  # clockwise or counter-clockwise: the houses inside are on either hand
        pts = pts[::-1].copy()
    return pts, r_min


def _curvature(pts: np.ndarray, h: int = 6) -> np.ndarray:
    """(n,) signed curvature (left positive), 1/m, of a closed, evenly sampled loop (n, 2)
    (differences ``h`` samples either side, so sampling noise does not pass for curvature)."""
    d1 = (np.roll(pts, -h, 0) - np.roll(pts, h, 0)) / 2
    d2 = np.roll(pts, -h, 0) - 2 * pts + np.roll(pts, h, 0)
    return (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3


def _min_radius(pts: np.ndarray) -> float:
    """Tightest radius of curvature of a closed, evenly sampled loop (n, 2), m."""
    return float(1.0 / np.abs(_curvature(pts)).max())


def _grades(path: np.ndarray) -> np.ndarray:
    """(n,) grade of each segment of a closed path (n, 3), rise over horizontal run."""
    nxt = np.roll(path, -1, axis=0)
    return (nxt[:, 2] - path[:, 2]) / np.linalg.norm(nxt[:, :2] - path[:, :2], axis=1)


def _terrain(p: Params, rng: np.random.Generator, lane: np.ndarray) -> g.SmoothField:
    """The ground's height field: a few long waves, scaled so the lane's steepest grade is
    ``max_grade_pct``.

    A draw whose steepest slope anywhere near the loop is more than twice the lane's
    (the lane would run along the contours of steep hills) is replaced by another.
    """
    lam = p.hill_wavelength_m
    best = None
    for _ in range(10):
        field = g.SmoothField(rng, 1.0, (0.6 * lam, 1.6 * lam), n_waves=5)
        path = np.column_stack([lane, field(lane[:, 0], lane[:, 1])])
        lane_grade = float(np.abs(_grades(path)).max())
        # slopes over the loop's surroundings, on a coarse grid
        lo, hi = lane.min(axis=0) - 60.0, lane.max(axis=0) + 60.0
        X, Y = np.meshgrid(np.linspace(lo[0], hi[0], 40), np.linspace(lo[1], hi[1], 40))
        area_grade = float(np.linalg.norm(field.gradient(X.ravel(), Y.ravel()), axis=1).max())
        ratio = area_grade / lane_grade
        if best is None or ratio < best[0]:
            best = (ratio, field, lane_grade)
        if ratio <= 2.0:
            break
    _, field, lane_grade = best
    return field.scaled(p.max_grade_pct / 100 / lane_grade)


# ---------------------------------------------------------------- ground and road
def _ground(mb, p, terrain, near_road, corridor, lo, hi) -> None:
    """The terrain over the whole area, except under the road and its sidewalks.

    Triangles wholly under the road's built width are left out; vertices under it
    sink 0.15 m, so the ground never shows through the road's own surface.
    """
    xs = np.linspace(lo[0], hi[0], int(np.ceil((hi[0] - lo[0]) / GRID_M)) + 1)
    ys = np.linspace(lo[1], hi[1], int(np.ceil((hi[1] - lo[1]) / GRID_M)) + 1)
    v, f = g.heightfield(xs, ys, terrain)
    dist = near_road.query(v[:, :2])[0]
    v[dist < corridor - 0.3, 2] -= 0.15
    under = dist[f].max(axis=1) < corridor
    mb.add(v, f[~under], mb.new_object("ground"))


def _road(mb, p, terrain, centre, left) -> None:
    """Road, kerbs and sidewalks swept along the closed centre-line, on the terrain."""
    k = int(round(SLICE_M / STEP_M))
    idx = np.concatenate([np.arange(0, len(centre), k), [0]])  # back to the first row: closed
    c = np.column_stack([centre[idx], np.zeros(len(idx))])
    lv = np.column_stack([left[idx], np.zeros(len(idx))])
    rh, sw, kh = p.road_width_m / 2, p.sidewalk_width_m, p.kerb_height_m

    def prof(lat, lift):
        """(rows, k, 2) lateral offsets ``lat`` (k,) at the terrain's height + ``lift`` (k,)."""
        lat = np.asarray(lat, dtype=float)
        xy = c[:, None, :2] + lat[None, :, None] * lv[:, None, :2]
        h = terrain(xy[..., 0], xy[..., 1]) + np.asarray(lift, dtype=float)[None, :]
        return np.stack([np.broadcast_to(lat, h.shape), h], -1)

    n_across = max(2, int(np.ceil(p.road_width_m / 2.0)) + 1)
    mb.add_object(*g.sweep(c, lv, prof(np.linspace(-rh, rh, n_across), np.zeros(n_across))), "road")
    kerb = mb.new_object("kerb")
    walk = mb.new_object("sidewalk")
    if kh > 0:
        mb.add(*g.sweep(c, lv, prof([rh, rh], [0.0, kh])), kerb)  # left kerb, facing the road
        mb.add(*g.sweep(c, lv, prof([-rh, -rh], [kh, 0.0])), kerb)  # right kerb
    b = BEVEL_M
    mb.add(*g.sweep(c, lv, prof([rh, rh + sw, rh + sw + b], [kh, kh, 0.0])), walk)
    mb.add(*g.sweep(c, lv, prof([-rh - sw - b, -rh - sw, -rh], [0.0, kh, kh])), walk)


# ---------------------------------------------------------------- houses
def _houses(mb, p, rng, terrain, centre, left, heading, s_centre, near_road, corridor, side,
            footprints) -> tuple[int, list]:
    """Houses along one side (+1 left of travel, -1 right); returns how many and their frontages."""
    if p.houses_per_100m <= 0:
        return 0, []
    pitch = 100.0 / p.houses_per_100m
    n_pts = len(centre)
    # Houses are spaced along the line of their fronts, which is shorter than the
    # centre-line inside a bend and longer outside: its length at each centre-line sample.
    d_front = side * (corridor + (p.setback_min_m + p.setback_max_m) / 2)
    stretch = np.clip(1.0 - _curvature(centre) * d_front, 0.05, None)
    s_front = np.concatenate([[0.0], np.cumsum(stretch * np.diff(s_centre))])
    cursor = rng.uniform(0.0, pitch)  # where the next house's span may begin, along the fronts
    count = 0
    frontages = []
    while cursor < s_front[-1] - 10.0:
        garage = rng.random() < p.garage_fraction
        garage_w = rng.uniform(3.5, 6.0) if garage else 0.0
        garage_side = rng.choice([-1.0, 1.0])
        width = rng.uniform(7.5, max(7.5, min(14.0, pitch - 3.0 - garage_w)))
        depth = rng.uniform(8.0, 12.5)
        setback = rng.uniform(p.setback_min_m, p.setback_max_m)
        storeys = int(rng.integers(1, p.storeys_max + 1))
        roof_kind = "hip" if rng.random() < 0.35 else "gable"
        pitch_deg = rng.uniform(25.0, 42.0)
        span = width + garage_w
        # the gaps between houses make up the rest of the pitch on average (2 m at least)
        gap = max(3.0, pitch - span) * rng.uniform(0.8, 1.25)
        i = int(np.searchsorted(s_front, cursor + span / 2)) % n_pts
        cursor += span + gap
        yaw = heading[i] if side > 0 else heading[i] + np.pi  # local y points away from the road
        u = np.array([np.cos(yaw), np.sin(yaw)])
        v = np.array([-u[1], u[0]])
        front = centre[i] + side * (corridor + setback) * left[i]
        # the house's own frame: origin at its front's middle, u along the road, v away from it
        # the span (house and garage) centred on the lot, the house's own middle off centre
        u0, u1 = -span / 2, span / 2
        h0, h1 = (u0, u0 + width) if garage_side > 0 else (u1 - width, u1)
        half = np.array([span / 2, depth / 2])
        axes = np.stack([u, v])
        cxy = front + depth / 2 * v
        # clear of the road everywhere (the loop may bend back toward the lot) and of other houses
        grid = np.stack(np.meshgrid(np.linspace(-1, 1, 7), np.linspace(-1, 1, 5)), -1).reshape(-1, 2)
        samples = cxy + (grid * half) @ axes
        if near_road.query(samples)[0].min() < corridor + min(p.setback_min_m, 2.0) - 0.01:
            continue
        if footprints.overlaps(cxy, axes, half, 2.0):
            continue
        footprints.add(cxy, axes, half)
        _house(mb, rng, terrain, front, yaw, (h0, h1), depth, storeys, roof_kind, pitch_deg,
               (u0, u1) if garage else None, garage_side)
        frontages.append((front, yaw, u0, u1))
        count += 1
    return count, frontages


def _plinth_box(terrain, corners: np.ndarray, z_top: float) -> g.Part:
    """A box over the (4, 2) corners (counter-clockwise seen from above) from
    ``FOOT_DEPTH_M`` under the terrain at each corner up to ``z_top``."""
    z_foot = terrain(corners[:, 0], corners[:, 1]) - FOOT_DEPTH_M
    v = np.vstack([np.column_stack([corners, z_foot]), np.column_stack([corners, np.full(4, z_top)])])
    f = np.array([
        [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],  # walls
        [4, 5, 6], [4, 6, 7],  # top
        [0, 2, 1], [0, 3, 2],  # bottom (in the ground)
    ])
    return v, f


def _house(mb, rng, terrain, front, yaw, span_u, depth, storeys, roof_kind, pitch_deg, garage_span,
           garage_side) -> None:
    """A detached house whose front's middle is ``front`` (2,), turned by ``yaw`` (local v away
    from the road): walls on a plinth following the ground, a pitched roof, maybe a garage."""
    u = np.array([np.cos(yaw), np.sin(yaw)])
    v = np.array([-u[1], u[0]])

    def world(uv):
        uv = np.asarray(uv, dtype=float)
        return front + uv[:, :1] * u + uv[:, 1:] * v

    a, b = span_u
    corners = world([[a, 0.0], [b, 0.0], [b, depth], [a, depth]])
    # the floor sits above the highest ground under the footprint (sampled, not just its corners)
    su, sv = np.meshgrid(np.linspace(a, b, 4), np.linspace(0.0, depth, 4))
    under = world(np.column_stack([su.ravel(), sv.ravel()]))
    floor = float(terrain(under[:, 0], under[:, 1]).max()) + rng.uniform(0.3, 0.8)
    z_eaves = floor + storeys * STOREY_M
    building = mb.new_object("building")
    mb.add(*_plinth_box(terrain, corners, z_eaves), building)
    if garage_span is not None:
        g0, g1 = (b, garage_span[1]) if garage_side > 0 else (garage_span[0], a)
        gd = min(depth, 6.5)
        g_corners = world([[g0, 0.6], [g1, 0.6], [g1, 0.6 + gd], [g0, 0.6 + gd]])
        mb.add(*_plinth_box(terrain, g_corners, floor - 0.2 + 2.7), building)
    # Roof: a hull over the eaves (0.4 m overhang) and a ridge; the ridge runs along the longer side.
    o = 0.4
    ra, rb, rc, rd = a - o, b + o, -o, depth + o
    along_u = (b - a) >= depth
    span = (rd - rc) if along_u else (rb - ra)
    rise = 0.5 * span * np.tan(np.radians(pitch_deg))
    base = [[ra, rc], [rb, rc], [rb, rd], [ra, rd]]
    hip = 0.5 * span if roof_kind == "hip" else 0.0
    if along_u:
        ridge = [[ra + hip, (rc + rd) / 2], [rb - hip, (rc + rd) / 2]]
    else:
        ridge = [[(ra + rb) / 2, rc + hip], [(ra + rb) / 2, rd - hip]]
    if np.allclose(ridge[0], ridge[1]):  # a square hip roof is a pyramid
        ridge = ridge[:1]
    pts = np.vstack([
        np.column_stack([world(base), np.full(4, z_eaves)]),
        np.column_stack([world(ridge), np.full(len(ridge), z_eaves + rise)]),
    ])
    mb.add_object(*g.convex(pts), "roof")


def _front_fences(mb, p, rng, terrain, centre, left, heading, s_centre, corridor, frontages) -> None:
    """A hedge or a fence along some front gardens, 1 m behind the sidewalk, with a gap for
    the path to the door."""
    for front, yaw, u0, u1 in frontages:
        if rng.random() >= p.fence_fraction:
            continue
        hedge = rng.random() < 0.5
        thick, height = (rng.uniform(0.5, 0.8), rng.uniform(0.9, 1.6)) if hedge else (0.06, rng.uniform(0.9, 1.2))
        u = np.array([np.cos(yaw), np.sin(yaw)])
        v = np.array([-u[1], u[0]])
        # the garden's front line: from the facade ``setback`` back toward the sidewalk
        back = _distance_to_corridor(front, centre, corridor)
        base = front - (back - 1.0 - thick / 2) * v
        gap = rng.uniform(1.5, 3.5)
        gap_at = rng.uniform(u0 + 1.0 + gap / 2, u1 - 1.0 - gap / 2) if u1 - u0 > gap + 3.0 else None
        pieces = [(u0 - 1.0, u1 + 1.0)] if gap_at is None else [(u0 - 1.0, gap_at - gap / 2),
                                                                  (gap_at + gap / 2, u1 + 1.0)]
        obj = mb.new_object("vegetation" if hedge else "wall")
        for a, b in pieces:
            ends = np.array([base + a * u, base + b * u])
            half_t = thick / 2 * v
            corners = np.array([ends[0] - half_t, ends[1] - half_t, ends[1] + half_t, ends[0] + half_t])
            top = float(terrain(corners[:, 0], corners[:, 1]).max()) + height
            mb.add(*_plinth_box(terrain, corners, top), obj)


def _distance_to_corridor(front: np.ndarray, centre: np.ndarray, corridor: float) -> float:
    """How far a house's front lies behind the road's built edge, m."""
    return float(np.min(np.linalg.norm(centre - front, axis=1))) - corridor


# ---------------------------------------------------------------- street furniture, cars, trees
def _parked_cars(mb, p, rng, terrain, centre, left, heading, s_centre) -> int:
    """Cars along both kerbs, level with the slope under them, clear of the driven lane.

    A kerb gets cars only where a parked car leaves the lane a car's half width and
    0.5 m (the narrow roads of the range park on the far side only).
    """
    lateral = p.road_width_m / 2 - PARK_FROM_KERB_M
    slot = 6.5
    slots_per_side = int(s_centre[-1] // slot)
    chance = min(1.0, p.parked_cars_per_100m / 2 * slot / 100.0)
    count = 0
    for side in (1.0, -1.0):
        clearance = lateral - CAR_HALF_WIDTH_M + side * p.lane_offset_m  # car's inner side to the lane
        if clearance < CAR_HALF_WIDTH_M + 0.5:
            continue
        for k in range(slots_per_side):
            if rng.random() >= chance:
                continue
            car = props.car(rng)
            i = int(round((k + 0.5) * slot / STEP_M + rng.uniform(-0.5, 0.5) / STEP_M)) % len(centre)
            xy = centre[i] + side * lateral * left[i]
            yaw = heading[i] + (0.0 if side < 0 else np.pi) + rng.uniform(-0.03, 0.03)
            fwd = np.array([np.cos(yaw), np.sin(yaw)])
            slope = terrain.gradient(xy[:1], xy[1:])[0]
            pitch = -np.arctan(slope @ fwd)
            roll = np.arctan(slope @ np.array([-fwd[1], fwd[0]]))
            z = float(terrain(xy[:1], xy[1:])[0]) - 0.02  # the tyres squat a little
            mb.add_object(*g.place_tilted(car, yaw, pitch, roll, (*xy, z)), "vehicle")
            count += 1
    return count


def _lamp_posts(mb, p, terrain, centre, left, heading, s_centre, corridor) -> None:
    """Lamp posts just beyond the sidewalk, alternating sides, arms over the road."""
    if p.light_spacing_m <= 0:
        return
    for k, s in enumerate(np.arange(p.light_spacing_m / 2, s_centre[-1] - 5.0, p.light_spacing_m)):
        side = 1.0 if k % 2 else -1.0
        i = int(round(s / STEP_M)) % len(centre)
        xy = centre[i] + side * (corridor + 0.3) * left[i]
        z = float(terrain(xy[:1], xy[1:])[0]) - 0.2
        arm = corridor - p.road_width_m / 2 + 1.0  # reaches 1 m over the road
        mb.add_object(*g.place(props.street_light(7.0, arm), heading[i] - side * np.pi / 2, (*xy, z)), "pole")


def _tree(mb, rng, terrain, xy, height, crown) -> None:
    trunk, crown_part = (props.conifer(rng, height, crown) if rng.random() < 0.25
                         else props.tree(rng, height, crown))
    z = float(terrain(xy[:1], xy[1:])[0]) - 0.2
    obj = mb.new_object("vegetation")
    mb.add(*g.place(trunk, 0.0, (*xy, z)), obj)
    mb.add(*g.place(crown_part, rng.uniform(0, 2 * np.pi), (*xy, z)), obj)


def _garden_trees(mb, p, rng, terrain, centre, left, s_centre, near_road, corridor, footprints) -> int:
    """Trees in the gardens: beside and behind the houses, crowns clear of the road."""
    n = int(round(p.trees_per_100m * s_centre[-1] / 100.0))
    placed: list[np.ndarray] = []
    count = 0
    for _ in range(4 * n):
        if count == n:
            break
        i = int(rng.integers(len(centre)))
        side = rng.choice([-1.0, 1.0])
        crown = rng.uniform(1.5, 3.0)
        xy = centre[i] + side * (corridor + rng.uniform(2.5, p.setback_max_m + 12.0)) * left[i]
        if near_road.query(xy)[0] < corridor + max(2.5, crown - 1.0):
            continue
        if footprints.contains(xy[None], crown + 0.5)[0]:
            continue
        if placed and np.min(np.linalg.norm(np.asarray(placed) - xy, axis=1)) < 4.0:
            continue
        _tree(mb, rng, terrain, xy, rng.uniform(5.0, 12.0), crown)
        placed.append(xy)
        count += 1
    return count


def _park_trees(mb, p, rng, terrain, near_road, corridor, footprints, lo, hi) -> int:
    """Trees scattered over the land beyond the houses' gardens, clear of every house."""
    area_ha = float(np.prod(hi - lo)) / 1e4
    cand = rng.uniform(lo + 5.0, hi - 5.0, size=(int(p.park_trees_per_ha * area_ha), 2))
    if len(cand) == 0:
        return 0
    keep = near_road.query(cand)[0] > corridor + p.setback_max_m + 14.0
    keep &= ~footprints.contains(cand, 4.0)
    count = 0
    for xy in cand[keep]:
        _tree(mb, rng, terrain, xy, rng.uniform(7.0, 16.0), rng.uniform(2.0, 4.0))
        count += 1
    return count
