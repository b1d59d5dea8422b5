"""Parking garage: levels stacked on thin slabs, straight ramps up through them, a helix down.

The building is a rectangle of ``bays`` structural bays (``pillar_spacing_m`` apart, three
stalls each) between two end zones where the drive turns. Across it: a row of stalls, aisle
A, two rows back to back, aisle B, a row of stalls (``stall_depth_m``, ``aisle_width_m``).
The ground floor and ``levels - 1`` slabs (``slab_thickness_m``) stand ``clear_height_m`` plus
the beams' depth apart; the top slab is an open roof deck. Under every slab, beams
(``beam_depth_m``) cross the bays at the pillar lines, so ``clear_height_m`` is the height
under the beams; pillars stand at the stalls' fronts and in the outer walls. Sides are
parapets (open) or walls all round (``closed_sides``). Cars fill the stalls (``occupancy``).

The drive (one way, along the aisles' centres), route "ramps_up": in from the street through
the ground floor's west wall along aisle A, round the east end, back along aisle B and up a
straight ramp (``ramp_grade_pct`` between smooth grade transitions) at its west end to the
next level, round the west end, and so on to the roof; along the roof's aisle A out over a
link to a helix east of the building, down it (``levels - 1`` turns, one lane, open with
parapets round a core) and out to the street. The straight ramps are stacked in one opening
of the slabs (each passes one level above the one below, with the slabs' full headroom);
the helix's turns are flat where the link above and the exit below cross them. Route
"helix_up" drives the same path the other way: up the helix, down the ramps.

Metadata: ``levels_z`` (floor heights, m), ``climb_s`` (path distance where the drive leaves
the ground floor: the first ramp's foot, or the helix's entry), ``ramp_x`` (the ramps' top and
foot, x, m), ``helix_centre`` (x, y), ``helix_grade`` and ``ramp_grade`` (rise over run between
the transitions), ``parked_cars``, ``path_length_m``.
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

DESCRIPTION = "multi-storey parking garage: levels on thin slabs, stacked straight ramps up, a helix down, parked cars"

STEP_M = 0.5  # path sampling
WALL_T_M = 0.25  # exterior walls and parapets
RAMP_WALL_T_M = 0.2  # the walls along the ramps and the helix's edges
LINK_GAP_M = 1.5  # between the building's east wall and the helix's outer edge
HEADROOM_M = 0.4  # the lidar clears the beams by this much at least (housing, suspension)
PATH_SMOOTHING_M = 1.5  # curvature transitions into and out of the turns
BEAM_WIDTH_M = 0.3
CLOSED_SIDES = ("none", "ground", "covered")
MIN_STALL_WIDTH_M = 2.3


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(5.0, "cruise speed of the vehicle (garage driving)", min=0.5, max=60.0)
    mount_height_m: float = param(1.6, "lidar height above the road (on a car's roof, no rack: under the beams)",
                                  min=0.3, max=5.0)
    levels: int = param(3, "floors, the ground floor and the open roof deck included", min=2, max=6)
    clear_height_m: float = param(2.3, "clear height, floor to the underside of the beams", min=2.0, max=4.0)
    slab_thickness_m: float = param(0.3, "floor slab thickness", min=0.15, max=0.6)
    beam_depth_m: float = param(0.4, "depth of the beams under each slab at the pillar lines (0: a flat slab)",
                                min=0.0, max=1.0)
    bays: int = param(7, "structural bays along the building, three stalls each", min=3, max=20)
    pillar_spacing_m: float = param(8.0, "pillar spacing along the building (one bay)", min=6.5, max=10.0)
    pillar_width_m: float = param(0.5, "pillar cross-section, square", min=0.25, max=1.0)
    aisle_width_m: float = param(6.5, "driving aisle width", min=5.5, max=9.0)
    stall_depth_m: float = param(5.0, "parking stall depth", min=4.9, max=6.0)
    ramp_grade_pct: float = param(12.0, "grade of the straight ramps between their transitions", min=4.0, max=18.0)
    ramp_transition_m: float = param(4.0, "length of each grade transition at a ramp's foot and top", min=1.0,
                                     max=10.0)
    helix_radius_m: float = param(10.0, "radius of the helix's lane centre-line", min=6.0, max=25.0)
    helix_lane_width_m: float = param(4.5, "the helix's lane, wall to wall", min=3.5, max=7.0)
    route: str = param("ramps_up", "up the straight ramps and down the helix, or up the helix and down the ramps",
                       choices=("ramps_up", "helix_up"))
    closed_sides: str = param("ground", "walls all round: on no level, the ground floor, every covered level "
                              "(the rest have parapets)", choices=CLOSED_SIDES)
    parapet_height_m: float = param(1.1, "parapet height on open sides, ramps and the helix", min=0.6, max=1.5)
    occupancy: float = param(0.6, "share of the stalls holding a parked car", min=0.0, max=1.0)
    approach_m: float = param(30.0, "street before the entrance", min=10.0, max=500.0)
    exit_m: float = param(30.0, "street after the helix", min=10.0, max=500.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.clear_height_m < self.mount_height_m + HEADROOM_M:
            raise ParamError(f"is {self.clear_height_m:g} m: the lidar at {self.mount_height_m:g} m needs "
                             f"{HEADROOM_M:g} m of headroom under the beams", "clear_height_m")
        if (self.pillar_spacing_m - self.pillar_width_m) / 3 < MIN_STALL_WIDTH_M:
            raise ParamError(f"leaves stalls narrower than {MIN_STALL_WIDTH_M} m between the pillars (three a bay)",
                             "pillar_width_m")
        lay = Layout(self)
        if lay.x_foot > lay.x_east - self.pillar_spacing_m:
            raise ParamError(f"are too few for a {lay.ramp_len:.1f} m ramp and a bay after it: the ramp "
                             f"needs {int(np.ceil(lay.ramp_len / self.pillar_spacing_m)) + 1}", "bays")
        if lay.helix_grade > 0.15:
            raise ParamError(f"makes the helix {100 * lay.helix_grade:.0f} % steep (at most 15 %)", "helix_radius_m")


class Layout:
    """Where everything of a garage is (m): cross-section, levels, ramps, helix."""

    def __init__(self, p: Params):
        self.p = p
        aw, sd = p.aisle_width_m, p.stall_depth_m
        self.width = 4 * sd + 2 * aw  # across, y
        self.y_a, self.y_b = sd + aw / 2, self.width - sd - aw / 2  # aisle centres
        self.y_mid = self.width / 2
        self.turn_r = (self.y_b - self.y_a) / 2  # the U-turns between the aisles
        self.end_zone = self.turn_r + aw / 2 + 0.5
        self.x_top = self.end_zone  # west end of the bays, where the ramps arrive
        self.x_east = self.x_top + p.bays * p.pillar_spacing_m  # east end of the bays
        self.length = self.x_east + self.end_zone  # along, x
        self.height = p.clear_height_m + p.beam_depth_m + p.slab_thickness_m  # floor to floor
        self.levels_z = self.height * np.arange(p.levels)
        self.z_roof = float(self.levels_z[-1])
        self.transition = p.ramp_transition_m
        self.ramp_len = self.height / (p.ramp_grade_pct / 100) + self.transition
        self.x_foot = self.x_top + self.ramp_len
        # the stacked ramps' opening in the slabs: aisle B between the ramps' top and foot
        self.hole = (self.x_top, self.x_foot, self.y_b - aw / 2, self.y_b + aw / 2)
        # The helix, east of the building, its lane's centre-line a circle tangent to aisle A's line.
        self.helix_r = p.helix_radius_m
        hw = p.helix_lane_width_m / 2 + RAMP_WALL_T_M
        self.helix_outer = self.helix_r + hw
        self.helix_c = np.array([self.length + WALL_T_M + LINK_GAP_M + self.helix_outer, self.y_a - self.helix_r])
        # Where the link above (and the exit below) cross the turns' band, the turns are flat
        # ("landings"): half the angle over which band and link overlap, and a margin.
        overlap = np.arccos((self.helix_r - hw) / (self.helix_r + hw))
        self.landing = float(overlap + 0.15)
        self.helix_slope_len = self.helix_r * (2 * np.pi - 2 * self.landing)
        self.helix_transition = min(self.transition, self.helix_slope_len / 4)
        self.helix_grade = st.climb_grade(self.helix_slope_len, self.height, self.helix_transition)
        self.ramp_grade = st.climb_grade(self.ramp_len, self.height, self.transition)
        self.helix_square = (self.helix_c[0] - self.helix_outer - 0.5, self.helix_c[0] + self.helix_outer + 0.5,
                             self.helix_c[1] - self.helix_outer - 0.5, self.helix_c[1] + self.helix_outer + 0.5)


def drive(lay: Layout) -> paths.Route:
    """The "ramps_up" drive (see the module's docstring), its places marked."""
    p = lay.p
    r = paths.Route((-p.approach_m, lay.y_a), 0.0, 0.0, STEP_M)
    r.straight(p.approach_m + lay.x_east)  # in through the west wall, along aisle A
    r.arc(lay.turn_r, np.pi)  # round the east end onto aisle B, heading west

    def ramp(u):
        return st.smooth_rise(u, lay.ramp_len, lay.height, lay.transition)

    for k in range(p.levels - 1):
        r.straight(lay.x_east - lay.x_foot)
        r.mark(f"ramp{k}_foot")
        r.straight(lay.ramp_len, ramp)
        r.arc(lay.turn_r, np.pi)  # round the west end onto aisle A, heading east, one level up
        if k < p.levels - 2:
            r.straight(lay.x_east - lay.x_top)
            r.arc(lay.turn_r, np.pi)
    r.straight(lay.length - lay.x_top)
    r.mark("link")  # the roof's east edge: the link to the helix
    r.straight(lay.helix_c[0] - lay.length)
    r.mark("helix_top")

    def down(u):
        return -st.smooth_rise(u, lay.helix_slope_len, lay.height, lay.helix_transition)

    r.arc(lay.helix_r, -lay.landing)  # clockwise, descending
    for k in range(p.levels - 1):
        r.arc(lay.helix_r, -(2 * np.pi - 2 * lay.landing), down)
        r.arc(lay.helix_r, -(lay.landing if k == p.levels - 2 else 2 * lay.landing))
    r.mark("helix_bottom")
    r.straight(lay.helix_square[1] - lay.helix_c[0])
    r.mark("exit")  # the helix's deck ends, the street begins
    r.straight(p.exit_m)
    return r


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0x6A7])
    lay = Layout(p)
    route = drive(lay)
    pts = route.points
    xy = paths.smooth(pts[:, :2], PATH_SMOOTHING_M, STEP_M, closed=False)
    path = np.column_stack([xy, pts[:, 2]])
    marks = dict(route.marks)
    if p.route == "helix_up":
        path = path[::-1].copy()
        marks = {k: len(path) - 1 - i for k, i in marks.items()}
    mb = MeshBuilder()
    _ground(mb, lay)
    _floors(mb, lay)
    _ramps(mb, lay)
    i0, i1 = sorted((marks["link"], marks["exit"]))
    _helix(mb, lay, path[i0:i1 + 1])
    _walls(mb, lay)
    n_cars = _parked_cars(mb, lay, rng)
    _fittings(mb, lay)

    traj = PathTrajectory(path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
                          np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed)
    s_path = paths.arc_length(path[:, :2])
    climb = marks["ramp0_foot"] if p.route == "ramps_up" else marks["helix_bottom"]
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    return Scene("garage", v, f, ids, labels, path, traj, p.to_dict(), {
        "levels_z": [float(z) for z in lay.levels_z],
        "climb_s": float(s_path[climb]),
        "ramp_x": [float(lay.x_top), float(lay.x_foot)],
        "helix_centre": [float(c) for c in lay.helix_c],
        "helix_grade": float(lay.helix_grade),
        "ramp_grade": float(lay.ramp_grade),
        "parked_cars": n_cars,
        "path_length_m": float(s_path[-1]),
    })


# ---------------------------------------------------------------- parts
def _ground(mb: MeshBuilder, lay: Layout) -> None:
    """The paved ground round the building and its ground floor, one surface at z = 0; under the
    first ramp and the helix a hair lower (their decks come down to 0 there, not into it)."""
    p = lay.p
    margin = 60.0
    outer = (-p.approach_m - margin, lay.helix_square[1] + p.exit_m + margin,
             lay.helix_square[2] - margin, lay.width + margin)
    sunk = [lay.hole, lay.helix_square]
    xs, ys = st.cell_grid([outer, *sunk])
    mask = ~st.cells_in(xs, ys, sunk)
    road = mb.new_object("road")
    mb.add(*st.cells_surface(xs, ys, mask, 0.0), road)
    for x0, x1, y0, y1 in sunk:  # reaching 0.1 m under the surface round it: no crack at the step
        e = np.array([x0 - 0.1, x1 + 0.1])
        mb.add(*st.cells_surface(e, np.array([y0 - 0.1, y1 + 0.1]), np.ones((1, 1), bool), -0.02), road)


def _pillar_xy(lay: Layout) -> np.ndarray:
    """(k, 2) pillar centres: the pillar lines at the stalls' fronts and in the outer walls, at every bay."""
    p = lay.p
    aw, pw = p.aisle_width_m, p.pillar_width_m
    set_back = 0.3 + pw / 2  # behind the stalls' front line
    ys = [pw / 2, lay.y_a - aw / 2 - set_back, lay.y_a + aw / 2 + set_back,
          lay.y_b - aw / 2 - set_back, lay.y_b + aw / 2 + set_back, lay.width - pw / 2]
    xs = lay.x_top + p.pillar_spacing_m * np.arange(p.bays + 1)
    return np.array([(x, y) for x in xs for y in ys])


def _floors(mb: MeshBuilder, lay: Layout) -> None:
    """The slabs above the ground floor (an opening for the ramps), the beams under them and the pillars."""
    p = lay.p
    t, b = p.slab_thickness_m, p.beam_depth_m
    foot = (0.0, lay.length, 0.0, lay.width)
    xs, ys = st.cell_grid([foot, lay.hole])
    mask = st.cells_in(xs, ys, [foot]) & ~st.cells_in(xs, ys, [lay.hole])
    pillars = _pillar_xy(lay)
    x0, x1, y0, y1 = lay.hole
    for k, z in enumerate(lay.levels_z):
        if k > 0:
            top, rest = st.floor_slab(xs, ys, mask, z, t)
            mb.add_object(*top, "road")
            mb.add_object(*rest, "building")
            if b > 0:  # beams across the building at the pillar lines, not across the opening
                beams = mb.new_object("building")
                zc = z - t - b / 2
                for xb in np.unique(pillars[:, 0]):
                    spans = [(0.0, lay.width)]
                    if xb + BEAM_WIDTH_M / 2 > x0 and xb - BEAM_WIDTH_M / 2 < x1:
                        spans = [(0.0, y0), (y1, lay.width)]
                    for ya, yb in spans:
                        mb.add(*g.box((BEAM_WIDTH_M, yb - ya, b), (xb, (ya + yb) / 2, zc)), beams)
        if k < p.levels - 1:  # pillars up to the slab above (the roof deck has none)
            h = lay.height - t
            cols = mb.new_object("building")
            for x, y in pillars:
                mb.add(*g.box((p.pillar_width_m, p.pillar_width_m, h), (x, y, z + h / 2)), cols)


def _ramps(mb: MeshBuilder, lay: Layout) -> None:
    """The straight ramps, one above the other in the slabs' opening: a deck each, walls both sides."""
    p = lay.p
    n = int(np.ceil(lay.ramp_len / STEP_M)) + 1
    u = np.linspace(0.0, lay.ramp_len, n)  # from the foot, heading west
    rise = st.smooth_rise(u, lay.ramp_len, lay.height, lay.transition)
    lefts = np.tile([0.0, -1.0, 0.0], (n, 1))  # heading west: left is south
    half = p.aisle_width_m / 2
    for z in lay.levels_z[:-1]:
        centres = np.column_stack([lay.x_foot - u, np.full(n, lay.y_b), z + rise])
        top, rest = st.prism_along(centres, lefts, -half, half, -p.slab_thickness_m, 0.0)
        mb.add_object(*top, "road")
        mb.add_object(*rest, "building")
        walls = mb.new_object("wall")
        for l0 in (-half, half - RAMP_WALL_T_M):
            mb.add(*st.wall_along(centres, lefts, l0, l0 + RAMP_WALL_T_M, 0.0, p.parapet_height_m), walls)


def _helix(mb: MeshBuilder, lay: Layout, path: np.ndarray) -> None:
    """The link from the roof, the helix's deck and its exit at ground level, along the drive
    (``path``: (n, 3) its stretch, link to exit); walls on both edges, a core in the middle."""
    p = lay.p
    lefts = st.lefts_of(path)
    half = p.helix_lane_width_m / 2
    top, rest = st.prism_along(path, lefts, -half - RAMP_WALL_T_M, half + RAMP_WALL_T_M, -p.slab_thickness_m, 0.0)
    mb.add_object(*top, "road")
    mb.add_object(*rest, "building")
    walls = mb.new_object("wall")
    for l0 in (-half - RAMP_WALL_T_M, half):
        mb.add(*st.wall_along(path, lefts, l0, l0 + RAMP_WALL_T_M, 0.0, p.parapet_height_m), walls)
    core_r = lay.helix_r - half - RAMP_WALL_T_M - 0.3
    mb.add_object(*g.cylinder(core_r, lay.z_roof + p.parapet_height_m + 0.3,
                              (*lay.helix_c, -0.3), sections=48), "wall")


def _walls(mb: MeshBuilder, lay: Layout) -> None:
    """Exterior walls (closed sides) or parapets (open sides) round every floor, an entrance in the
    ground floor's west wall and an opening for the link in the roof's east parapet; a stair core."""
    p = lay.p
    t, tw = p.slab_thickness_m, WALL_T_M
    L, W = lay.length, lay.width
    entrance = (lay.y_a - p.aisle_width_m / 2, lay.y_a + p.aisle_width_m / 2)
    link = (lay.y_a - p.helix_lane_width_m / 2 - RAMP_WALL_T_M, lay.y_a + p.helix_lane_width_m / 2 + RAMP_WALL_T_M)
    obj = mb.new_object("wall")
    for k, z in enumerate(lay.levels_z):
        covered = k < p.levels - 1
        closed = covered and (p.closed_sides == "covered" or (p.closed_sides == "ground" and k == 0))
        h = lay.height - t if closed else p.parapet_height_m
        # (x0, x1, y0, y1) of each side, with its opening cut out along y
        sides = [(-tw, L + tw, -tw, 0.0), (-tw, L + tw, W, W + tw)]
        for x0, gap in ((-tw, entrance if k == 0 else None), (L, link if k == p.levels - 1 else None)):
            spans = [(0.0, W)] if gap is None else [(0.0, gap[0]), (gap[1], W)]
            sides += [(x0, x0 + tw, a, b) for a, b in spans]
        for x0, x1, y0, y1 in sides:
            mb.add(*g.box((x1 - x0, y1 - y0, h), ((x0 + x1) / 2, (y0 + y1) / 2, z + h / 2)), obj)
    core_h = lay.z_roof + 3.0  # stairs and lift in the north-west corner, a stair house on the roof
    mb.add_object(*g.box((5.0, 5.0, core_h + 0.3), (2.8, W - 2.8, core_h / 2 - 0.15)), "building")


def _parked_cars(mb: MeshBuilder, lay: Layout, rng: np.random.Generator) -> int:
    """Cars in the stalls of every floor (not beside the ramps' opening), nose in or out at random."""
    p = lay.p
    aw, sd = p.aisle_width_m, p.stall_depth_m
    stall_w = (p.pillar_spacing_m - p.pillar_width_m) / 3
    rows = [sd / 2, lay.y_a + aw / 2 + sd / 2, lay.y_b - aw / 2 - sd / 2, lay.width - sd / 2]  # stall centres, y
    count = 0
    for z in lay.levels_z:
        for row, yc in enumerate(rows):
            for j in range(p.bays):
                for k in range(3):
                    xc = lay.x_top + j * p.pillar_spacing_m + p.pillar_width_m / 2 + (k + 0.5) * stall_w
                    beside_ramps = row >= 2 and lay.hole[0] - 1.0 < xc < lay.hole[1] + 1.0
                    # draw every stall's numbers, so occupancy changes only which stalls hold a car
                    parked, nose_in, car = rng.random() < p.occupancy, rng.random() < 0.5, props.car(rng)
                    if beside_ramps or not parked:
                        continue
                    # facing the aisle or the wall behind (the car's origin is its footprint's centre)
                    toward_back = -1.0 if row in (0, 2) else 1.0
                    yaw = toward_back * np.pi / 2 if nose_in else -toward_back * np.pi / 2
                    mb.add_object(*g.place(car, yaw, (xc, yc, z)), "vehicle")
                    count += 1
    return count


def _fittings(mb: MeshBuilder, lay: Layout) -> None:
    """Lights over the aisles under every slab (their bottom at the clear height), lamp posts on the roof."""
    p = lay.p
    x0, x1, _, _ = lay.hole
    for z in lay.levels_z[:-1]:
        for j in range(p.bays):
            xc = lay.x_top + (j + 0.5) * p.pillar_spacing_m
            for yc in (lay.y_a, lay.y_b):
                if yc == lay.y_b and x0 - 1.0 < xc < x1 + 1.0:
                    continue  # over the ramps
                mb.add_object(*g.box((1.2, 0.2, 0.1), (xc, yc, z + p.clear_height_m + 0.05)), "light")
    for j in range(0, p.bays + 1, 2):
        base = (lay.x_top + j * p.pillar_spacing_m, lay.y_mid, lay.z_roof)
        mb.add_object(*g.place(props.street_light(5.0, 1.0), np.pi / 2 * (1 if j % 4 else -1), base), "pole")
