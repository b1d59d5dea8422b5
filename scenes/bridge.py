"""Bridge: a road passing under a deck that carries another, and a loop ramp up onto that deck.

Road A runs along x at ground level: ``lanes`` lanes each way, shoulders, a median with a
barrier and, under the bridge, a pier when ``pier``; on its south side an auxiliary lane
leads to the loop ramp. Road B crosses it along y on a bridge: a deck ``deck_depth_m`` deep
(a slab on girders) leaves ``clearance_m`` over A between two abutments; beyond them B's
approaches are fills between retaining walls, level near the bridge and then falling at
``b_grade_pct`` to the ground. The loop ramp leaves A's auxiliary lane after the bridge,
turns right through 270 degrees on a circle of ``loop_radius_m`` (a fill between walls,
parapets both sides), climbing smoothly, and joins B as an auxiliary lane on its east side,
which crosses the bridge.

The drive: along A's auxiliary lane under the deck, round the loop up to B, north over the
deck, above the road it came along, and on down B's far approach. Lamp posts line A and B,
trees and buildings stand in the land around (``trees``, ``buildings``).

Metadata: ``under_s`` (path distance where the drive passes under the deck's centre-line),
``over_s`` (where it crosses above A's centre-line), ``crossing_s`` (where it is halfway in time
between the two), ``loop_s`` (the loop's start and end),
``deck_z`` (the deck's top, m), ``loop_grade`` (rise over run between the transitions),
``path_length_m``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geometry as g
from . import paths, props
from . import structures as st
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .trajectory import PathTrajectory

DESCRIPTION = "road under a bridge deck carrying another, a loop ramp up onto it: the drive passes under, then over"

STEP_M = 0.5
LANE_M = 3.5
SHOULDER_M = 1.0
MEDIAN_M = 2.0  # with a pier in it
ABUTMENT_SET_BACK_M = 2.0  # from A's edge to the abutment's face
PLATEAU_M = 5.0  # B stays level this far beyond the abutments
B_TRANSITION_M = 20.0  # B's vertical curves
LOOP_TRANSITION_M = 15.0
MAX_LOOP_GRADE = 0.08
PARAPET_T_M = 0.3
SLAB_M = 0.3  # the deck's slab; girders make up the rest of its depth
FILL_FOOT_M = 0.3  # walls and fills reach this far into the ground
GROUND_Z_M = -0.02  # the land, a hair under the roads' surface
PATH_SMOOTHING_M = 2.0


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(11.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    lateral_accel_m_s2: float = param(3.0, "lateral acceleration allowed in turns (a loop ramp's, slowing the "
                                      "vehicle in the loop)", min=0.1, max=10.0)
    lanes: int = param(2, "road A's lanes in each direction", min=1, max=4)
    pier: bool = param(True, "a pier in A's median under the bridge (a median 2 m wide)")
    road_b_width_m: float = param(9.0, "road B's carriageway, kerb to kerb", min=6.5, max=16.0)
    ramp_lane_width_m: float = param(4.5, "the loop ramp's lane and B's auxiliary lane, wall to wall", min=4.0,
                                     max=7.0)
    clearance_m: float = param(5.0, "clear height under the deck over road A", min=4.0, max=8.0)
    deck_depth_m: float = param(1.2, "the deck's depth, slab and girders", min=0.5, max=3.0)
    loop_radius_m: float = param(24.0, "radius of the loop ramp's centre-line", min=12.0, max=80.0)
    b_grade_pct: float = param(5.0, "grade of road B's approaches to the bridge", min=1.0, max=8.0)
    parapet_height_m: float = param(1.0, "parapets along the deck, B's fills and the loop", min=0.5, max=1.5)
    approach_m: float = param(60.0, "road A before the bridge", min=20.0, max=1000.0)
    exit_m: float = param(60.0, "road B after the bridge", min=20.0, max=1000.0)
    lamp_spacing_m: float = param(35.0, "lamp posts along A and B (0: none)", min=0.0, max=500.0)
    trees: int = param(80, "trees in the land around", min=0, max=2000)
    buildings: int = param(12, "buildings in the land around", min=0, max=200)

    def __post_init__(self) -> None:
        super().__post_init__()
        lay = Layout(self)
        if lay.loop_grade > MAX_LOOP_GRADE:
            raise ParamError(f"is too small for the climb: the loop would rise {100 * lay.loop_grade:.1f} % "
                             f"(at most {100 * MAX_LOOP_GRADE:g} %)", "loop_radius_m")


class Layout:
    """Where the roads, the bridge and the loop are (m)."""

    def __init__(self, p: Params):
        self.p = p
        median = MEDIAN_M if p.pier else 0.0
        self.a_half = p.lanes * LANE_M + SHOULDER_M + median / 2  # A: centre-line to its edge
        self.median = median
        self.w_r = p.ramp_lane_width_m
        self.y_lane = -(self.a_half + self.w_r / 2)  # the auxiliary lane's centre, south of A
        self.b_half = p.road_b_width_m / 2
        self.x_lane = self.b_half + self.w_r / 2  # B's auxiliary lane's centre, east of B
        self.y_south = -(self.a_half + self.w_r + ABUTMENT_SET_BACK_M)  # abutments' faces
        self.y_north = self.a_half + ABUTMENT_SET_BACK_M
        self.deck_z = p.clearance_m + p.deck_depth_m
        self.b_descent = self.deck_z / (p.b_grade_pct / 100) + B_TRANSITION_M
        self.r = p.loop_radius_m
        self.x_tangent = self.x_lane + self.r  # where the loop leaves A's auxiliary lane
        self.centre = np.array([self.x_tangent, self.y_lane - self.r])
        self.y_merge = self.y_lane - self.r  # where the loop joins B
        self.loop_len = 1.5 * np.pi * self.r
        self.loop_transition = min(LOOP_TRANSITION_M, self.loop_len / 4)
        self.merge_z = float(self.b_height(np.array([self.y_merge]))[0])
        self.merge_grade = float(self.b_grade(self.y_merge))
        self.loop_grade = st.climb_grade(self.loop_len, self.merge_z, self.loop_transition, 0.0, self.merge_grade)
        self.y_b0 = self.y_south - PLATEAU_M - self.b_descent - 30.0  # B's ends
        self.y_b1 = self.y_north + PLATEAU_M + max(self.b_descent + 30.0, p.exit_m + 20.0)
        self.x_a0 = -p.approach_m - 30.0  # A's ends
        self.x_a1 = self.x_tangent + self.r + 80.0

    def b_height(self, y: np.ndarray) -> np.ndarray:
        """(n,) road B's height at y (n,), m: level over the bridge, falling to 0 both ways."""
        y = np.asarray(y, dtype=float)
        south = np.clip(self.y_south - PLATEAU_M - y, 0.0, None)
        north = np.clip(y - self.y_north - PLATEAU_M, 0.0, None)
        away = np.maximum(south, north)
        return self.deck_z - st.smooth_rise(np.minimum(away, self.b_descent), self.b_descent, self.deck_z,
                                            B_TRANSITION_M)

    def b_grade(self, y: float, dy: float = 1e-3) -> float:
        """Road B's grade going north at y (rise over run)."""
        return float(np.diff(self.b_height(np.array([y - dy, y + dy])))[0] / (2 * dy))


def drive(lay: Layout) -> paths.Route:
    """Along A's auxiliary lane under the bridge, round the loop, north over the bridge along B."""
    p = lay.p
    r = paths.Route((-p.approach_m, lay.y_lane), 0.0, 0.0, STEP_M)
    r.straight(p.approach_m + lay.x_tangent)
    r.mark("loop_start")

    def loop(u):
        return st.smooth_rise(u, lay.loop_len, lay.merge_z, lay.loop_transition, 0.0, lay.merge_grade)

    r.arc(lay.r, -1.5 * np.pi, loop)  # right, through 270 degrees
    r.mark("loop_end")
    y_end = lay.y_north + p.exit_m

    def along_b(u):
        return lay.b_height(lay.y_merge + u) - lay.merge_z

    r.straight(y_end - lay.y_merge, along_b)
    return r


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0xB81])
    lay = Layout(p)
    route = drive(lay)
    pts = route.points
    path = np.column_stack([paths.smooth(pts[:, :2], PATH_SMOOTHING_M, STEP_M, closed=False), pts[:, 2]])
    mb = MeshBuilder()
    _road_a(mb, lay)
    _road_b(mb, lay)
    i0, i1 = route.marks["loop_start"], route.marks["loop_end"]
    _loop(mb, lay, path[i0:i1 + 1])
    _lamps(mb, lay)
    n_trees, n_buildings = _land(mb, lay, rng)

    traj = PathTrajectory(path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
                          np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed)
    s_path = paths.arc_length(path[:, :2])
    under = int(np.argmin(np.abs(path[:i0, 0])))
    over = i1 + int(np.argmin(np.abs(path[i1:, 1])))
    halfway = 0.5 * (traj.time_at_distance(s_path[under]) + traj.time_at_distance(s_path[over]))
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    return Scene("bridge", v, f, ids, labels, path, traj, p.to_dict(), {
        "under_s": float(s_path[under]),
        "over_s": float(s_path[over]),
        "crossing_s": float(traj.distance_at(halfway)[0]),
        "loop_s": [float(s_path[i0]), float(s_path[i1])],
        "deck_z": float(lay.deck_z),
        "loop_grade": float(lay.loop_grade),
        "trees": n_trees,
        "buildings": n_buildings,
        "path_length_m": float(s_path[-1]),
    })


# ---------------------------------------------------------------- parts
def _road_a(mb: MeshBuilder, lay: Layout) -> None:
    """Road A and its auxiliary lane (up to the loop), the land round everything, A's median barrier."""
    road = (lay.x_a0, lay.x_a1, -lay.a_half, lay.a_half)
    aux = (lay.x_a0, lay.x_tangent, -lay.a_half - lay.w_r, -lay.a_half)
    xs, ys = st.cell_grid([road, aux])
    mb.add_object(*st.cells_surface(xs, ys, st.cells_in(xs, ys, [road, aux]), 0.0), "road")
    land_x, land_y = np.array([lay.x_a0 - 100.0, lay.x_a1 + 100.0]), np.array([lay.y_b0 - 50.0, lay.y_b1 + 50.0])
    mb.add_object(*st.cells_surface(land_x, land_y, np.ones((1, 1), bool), GROUND_Z_M), "ground")
    if lay.median > 0:  # a concrete barrier along the median, the pier in its line under the bridge
        h = 0.8
        mb.add_object(*g.box((lay.x_a1 - lay.x_a0, 0.6, h + FILL_FOOT_M),
                             ((lay.x_a0 + lay.x_a1) / 2, 0.0, (h - FILL_FOOT_M) / 2)), "wall")


def _road_b(mb: MeshBuilder, lay: Layout) -> None:
    """Road B: its fills between retaining walls, the deck over A (slab, girders, the pier), parapets."""
    p = lay.p
    wide = (-lay.b_half - lay.w_r, lay.b_half)  # l (left of travel north = west): B and its auxiliary lane
    narrow = (-lay.b_half, lay.b_half)
    for (y0, y1), (l0, l1), fill in (((lay.y_b0, lay.y_merge), narrow, True),
                                      ((lay.y_merge, lay.y_south), wide, True),
                                      ((lay.y_south, lay.y_north), wide, False),
                                      ((lay.y_north, lay.y_b1), wide, True)):
        n = max(2, int(np.ceil((y1 - y0) / STEP_M)) + 1)
        y = np.linspace(y0, y1, n)
        z = lay.b_height(y)
        centres = np.column_stack([np.zeros(n), y, z])
        lefts = np.tile([-1.0, 0.0, 0.0], (n, 1))
        bottom = -(z + FILL_FOOT_M) if fill else -SLAB_M
        top, rest = st.prism_along(centres, lefts, l0, l1, bottom, 0.0)
        mb.add_object(*top, "road")
        mb.add_object(*rest, "wall" if fill else "building")
        parapets = mb.new_object("wall")
        for a in (l0, l1 - PARAPET_T_M):
            mb.add(*st.wall_along(centres, lefts, a, a + PARAPET_T_M, 0.0, p.parapet_height_m), parapets)
    # girders under the slab, along B, and the pier in A's median
    x0, x1 = -wide[1], -wide[0]  # the deck's extent across, x
    z_under = lay.deck_z - p.deck_depth_m
    girder_h = p.deck_depth_m - SLAB_M
    n_g = max(3, int(round((x1 - x0) / 2.5)))
    girders = mb.new_object("building")
    for x in np.linspace(x0 + 0.6, x1 - 0.6, n_g):
        mb.add(*g.box((0.5, lay.y_north - lay.y_south, girder_h),
                      (x, (lay.y_south + lay.y_north) / 2, z_under + girder_h / 2)), girders)
    if p.pier:
        h = z_under + FILL_FOOT_M
        mb.add_object(*g.box((x1 - x0 - 1.0, 1.0, h), ((x0 + x1) / 2, 0.0, z_under - h / 2)), "building")


def _loop(mb: MeshBuilder, lay: Layout, path: np.ndarray) -> None:
    """The loop ramp along the drive's ``path`` (n, 3): a fill between walls, parapets both sides."""
    p = lay.p
    lefts = st.lefts_of(path)
    half = lay.w_r / 2
    top, rest = st.prism_along(path, lefts, -half, half, -(path[:, 2] + FILL_FOOT_M), 0.0)
    mb.add_object(*top, "road")
    mb.add_object(*rest, "wall")
    parapets = mb.new_object("wall")
    for a in (-half, half - PARAPET_T_M):
        mb.add(*st.wall_along(path, lefts, a, a + PARAPET_T_M, 0.0, p.parapet_height_m), parapets)


def _lamps(mb: MeshBuilder, lay: Layout) -> None:
    """Lamp posts along A's north side and beside B's west wall, their arms over the roads."""
    p = lay.p
    if p.lamp_spacing_m <= 0:
        return
    deck = (-lay.b_half - 3.0, lay.b_half + lay.w_r + 3.0)
    for x in np.arange(lay.x_a0 + 10.0, lay.x_a1 - 10.0, p.lamp_spacing_m):
        if deck[0] < x < deck[1]:
            continue
        base = (x, lay.a_half + 1.5, -FILL_FOOT_M)
        mb.add_object(*g.place(props.street_light(9.0 + FILL_FOOT_M, 2.0), -np.pi / 2, base), "pole")
    for y in np.arange(lay.y_b0 + 10.0, lay.y_b1 - 10.0, p.lamp_spacing_m):
        if lay.y_south - 3.0 < y < lay.y_north + 3.0:
            continue
        z_b = float(lay.b_height(np.array([y]))[0])
        base = (-lay.b_half - 1.5, y, -FILL_FOOT_M)
        mb.add_object(*g.place(props.street_light(z_b + 8.0 + FILL_FOOT_M, 2.5), 0.0, base), "pole")


def _land(mb: MeshBuilder, lay: Layout, rng: np.random.Generator) -> tuple[int, int]:
    """Buildings and trees at random in the land, clear of the roads, the fills and the loop."""
    p = lay.p
    lo = np.array([lay.x_a0 + 20.0, lay.y_b0 + 20.0])
    hi = np.array([lay.x_a1 - 20.0, lay.y_b1 - 20.0])

    def clearance(xy: np.ndarray) -> np.ndarray:
        """(k,) distance from (k, 2) points to the nearest road, fill or the loop, m (rectangles and
        the loop's annulus: a lower bound, not exact at the roads' ends)."""
        d_a = np.maximum(xy[:, 1] - lay.a_half, -lay.a_half - lay.w_r - xy[:, 1])
        d_b = np.maximum(xy[:, 0] - lay.b_half - lay.w_r, -lay.b_half - xy[:, 0])
        d_loop = np.abs(np.linalg.norm(xy - lay.centre, axis=1) - lay.r) - lay.w_r / 2
        return np.maximum(np.minimum.reduce([d_a, d_b, d_loop]), 0.0)

    n_buildings = 0
    placed = []  # (centre (2,), radius) of every building, so that none overlap
    for _ in range(p.buildings):
        size = rng.uniform([10.0, 10.0, 6.0], [30.0, 25.0, 30.0])
        c, yaw = rng.uniform(lo, hi), rng.uniform(0, np.pi)
        radius = 0.5 * np.hypot(size[0], size[1])
        if clearance(c[None])[0] < radius + 12.0 or any(np.linalg.norm(c - q) < radius + rq + 3.0 for q, rq in placed):
            continue
        placed.append((c, radius))
        mb.add_object(*g.box((size[0], size[1], size[2] + FILL_FOOT_M), (*c, (size[2] - FILL_FOOT_M) / 2), yaw),
                      "building")
        n_buildings += 1
    n_trees = 0
    for _ in range(p.trees):
        c = rng.uniform(lo, hi)
        height, crown = rng.uniform(5.0, 14.0), rng.uniform(1.5, 3.5)
        tree = props.tree(rng, height, crown)
        if clearance(c[None])[0] < crown + 4.0 or any(np.linalg.norm(c - q) < rq + crown for q, rq in placed):
            continue
        trunk, top = tree
        mb.add_object(*g.place(trunk, 0.0, (*c, -FILL_FOOT_M)), "vegetation")
        mb.add_object(*g.place(top, 0.0, (*c, -FILL_FOOT_M)), "vegetation")
        n_trees += 1
    return n_trees, n_buildings
