"""City: a street grid of blocks, buildings of varied shape, street furniture, a loop route.

Layout: ``streets_x`` streets run along y at x = 0, p_x, 2 p_x, ... and
``streets_y`` along x, with p = block size + street width. The blocks between
them (and a ring of blocks outside the outermost streets, so every street has
buildings on both sides) are raised 15 cm above the road: a sidewalk band at
the kerb, courtyards inside. Each block's edge is cut into lots; a lot holds
a building set back from the sidewalk: a rectangle, L, T or U footprint,
sometimes stepped (upper tiers set back), with a flat roof behind a parapet,
a gable, hip or shed roof, pilasters and a cornice on the facades. Parked
cars line the kerbs, street lights and trees the sidewalks, signs stand before
intersections. The ground (the road surface) undulates gently.

The route is the boundary of a random group of ``route_blocks`` adjacent
inner blocks: it turns left and right at intersections and closes a loop.
The vehicle drives ``lane_offset_m`` right of the street's centre-line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .traffic import Lane, RoadLayout
from .trajectory import PathTrajectory

DESCRIPTION = "street grid of blocks with varied buildings, parked cars, poles, trees; a loop route"


@dataclass(frozen=True)
class Params(CommonParams):
    streets_x: int = param(4, "number of streets running along y (north-south)", min=2, max=12)
    streets_y: int = param(3, "number of streets running along x (east-west)", min=2, max=12)
    block_length_m: float = param(80.0, "block size along x, kerb to kerb", min=30.0, max=300.0)
    block_width_m: float = param(60.0, "block size along y, kerb to kerb", min=30.0, max=300.0)
    street_width_m: float = param(12.0, "road width kerb to kerb (two lanes + parking)", min=7.0, max=30.0)
    sidewalk_width_m: float = param(3.5, "sidewalk width", min=1.5, max=8.0)
    kerb_height_m: float = param(0.15, "kerb height", min=0.0, max=0.4)
    building_height_min_m: float = param(8.0, "lowest building", min=3.0, max=100.0)
    building_height_max_m: float = param(35.0, "tallest building", min=3.0, max=300.0)
    setback_max_m: float = param(4.0, "largest setback of a facade behind the sidewalk", min=0.5, max=15.0)
    parked_car_fraction: float = param(0.45, "share of parking places holding a car", min=0.0, max=1.0)
    tree_spacing_m: float = param(16.0, "spacing of street trees (0: none)", min=0.0, max=200.0)
    light_spacing_m: float = param(32.0, "spacing of street lights (0: none)", min=0.0, max=200.0)
    ground_roughness_m: float = param(0.3, "standard deviation of the ground's undulation", min=0.0, max=3.0)
    route_blocks: int = param(3, "number of adjacent blocks the loop route goes around", min=1, max=60)
    closed_loop: bool = param(True, "drive a full loop back to the start (else stop 30 m short)")
    turn_radius_m: float = param(9.0, "radius of the centre-line's turns at intersections", min=4.0, max=30.0)
    lane_offset_m: float = param(2.0, "the vehicle drives this far right of the centre-line",
                                 min=0.0, max=6.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.building_height_max_m < self.building_height_min_m:
            raise ParamError("is below building_height_min_m", "building_height_max_m")
        if self.lane_offset_m > self.street_width_m / 2 - 2.5:
            raise ParamError(f"is {self.lane_offset_m} m: that leaves the lane in a {self.street_width_m} m "
                             f"street (at most street_width_m / 2 - 2.5)", "lane_offset_m")
        if self.route_blocks > (self.streets_x - 1) * (self.streets_y - 1):
            raise ParamError(f"is {self.route_blocks}: more than the "
                             f"{(self.streets_x - 1) * (self.streets_y - 1)} blocks between the streets",
                             "route_blocks")
        # On a right turn the lane's arc (radius turn - offset about a centre on the corner's
        # diagonal) must pass the kerb corner by a car's half width and a margin (0.95 + 0.5 m),
        # plus 0.3 m that the path's smoothing cuts from the arc.
        r_path = self.turn_radius_m - self.lane_offset_m
        corner = np.sqrt(2.0) * abs(self.turn_radius_m - self.street_width_m / 2)
        if r_path < 4.0 or r_path - corner < 1.75:
            raise ParamError(
                f"is {self.turn_radius_m:g} m: with {self.street_width_m:g} m streets and the lane "
                f"{self.lane_offset_m:g} m right of the centre, such a turn "
                f"{'is too tight for a car' if r_path < 4.0 else 'cuts over the kerb corner'}", "turn_radius_m")


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0xC171])
    terrain = g.SmoothField(rng, p.ground_roughness_m, (120.0, 400.0))
    sw = p.street_width_m
    pitch_x, pitch_y = p.block_length_m + sw, p.block_width_m + sw
    # Block k spans street k-1 .. street k: k = 0 and k = n are the outer ring.
    sx = np.arange(-1, p.streets_x + 1) * pitch_x
    sy = np.arange(-1, p.streets_y + 1) * pitch_y
    x_lo, x_hi = sx[0] + sw / 2, sx[-1] - sw / 2
    y_lo, y_hi = sy[0] + sw / 2, sy[-1] - sw / 2
    mb = MeshBuilder()

    # Road: the ground everywhere, under the blocks too.
    xs = np.linspace(x_lo - 10, x_hi + 10, int(np.ceil((x_hi - x_lo + 20) / 4.0)) + 1)
    ys = np.linspace(y_lo - 10, y_hi + 10, int(np.ceil((y_hi - y_lo + 20) / 4.0)) + 1)
    mb.add_object(*g.heightfield(xs, ys, terrain), "road")

    sidewalk_obj = mb.new_object("sidewalk")
    court_obj = mb.new_object("ground")
    kerb_obj = mb.new_object("kerb")
    n_buildings = 0
    for i in range(len(sx) - 1):
        for j in range(len(sy) - 1):
            bx = (sx[i] + sw / 2, sx[i + 1] - sw / 2)
            by = (sy[j] + sw / 2, sy[j + 1] - sw / 2)
            _block_platform(mb, p, terrain, bx, by, sidewalk_obj, court_obj, kerb_obj)
            n_buildings += _block_buildings(mb, p, rng, terrain, bx, by)
            _sidewalk_furniture(mb, p, rng, terrain, bx, by)
    # Close each street's end with a building across it, so no view runs into the void.
    for x in sx[1:-1]:
        for y_end, yaw in ((y_lo - 8.0, 0.0), (y_hi + 8.0, np.pi)):
            _end_building(mb, rng, terrain, x, y_end, sw + 2 * p.sidewalk_width_m, yaw)
    for y in sy[1:-1]:
        for x_end, yaw in ((x_lo - 8.0, -np.pi / 2), (x_hi + 8.0, np.pi / 2)):
            _end_building(mb, rng, terrain, x_end, y, sw + 2 * p.sidewalk_width_m, yaw)
    n_cars = _parked_cars(mb, p, rng, terrain, sx, sy)

    route = _route_corners(p, rng, sx[1:-1], sy[1:-1])
    step = 0.5
    centre = paths.fillet(route, p.turn_radius_m, closed=True, step_m=step)
    centre = paths.resample(centre, step, closed=True)
    lane = paths.offset(centre, -p.lane_offset_m, closed=True)
    lane = paths.smooth(paths.resample(lane, step, closed=True), 2.0, step, closed=True)
    closed = p.closed_loop
    if not closed:
        lane = lane[: -int(30.0 / step)]
    path = np.column_stack([lane, terrain(lane[:, 0], lane[:, 1])])
    traj = PathTrajectory(
        path, closed, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed, surface_height=terrain,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    roads = _roads(p, terrain, sx, sy, route, closed, path)
    return Scene(
        "city", v, f, ids, labels, path, traj, p.to_dict(), roads=roads, metadata=
        {
            "route_length_m": traj.length_m,
            "route_corners_xy": route.tolist(),
            "closed_loop": closed,
            "extent_xy": [[x_lo, y_lo], [x_hi, y_hi]],
            "buildings": n_buildings,
            "parked_cars": n_cars,
        },
    )


# ---------------------------------------------------------------- traffic
def _roads(p: Params, terrain, sx: np.ndarray, sy: np.ndarray, route: np.ndarray, closed: bool,
           path: np.ndarray) -> RoadLayout:
    """Where the city's traffic goes (``scenes.traffic``): the two lanes of the route's streets, the parking
    lanes, the cyclists' lines, the sidewalks around the route's blocks, the crossings at its junctions and the
    streets that cross it."""
    half, lo = p.street_width_m / 2, p.lane_offset_m
    lateral = half - 1.1  # a parked car's centre (``_parked_cars``)
    parks = lateral - 0.95 - lo >= 0.95 + 0.5
    walk = half + 0.65 * p.sidewalk_width_m  # the walking line, from the street's centre

    def on_block(x, y):
        return (np.abs(x[:, None] - sx[None, 1:-1]).min(axis=1) > half) & (
            np.abs(y[:, None] - sy[None, 1:-1]).min(axis=1) > half)

    def surface(x, y):  # the sidewalk where it is one, else the road
        return terrain(x, y) + np.where(on_block(x, y), p.kerb_height_m, 0.0)

    walkways = []
    corners = np.asarray(route, float)
    for side in (1.0, -1.0):
        loop = paths.resample(paths.fillet(_offset_polygon(corners, side * walk), 1.5, closed=True), 0.5, closed=True)
        walkways.append((np.column_stack([loop, surface(loop[:, 0], loop[:, 1])]), True))
    junctions = [(x, y) for x in sx[1:-1] for y in sy[1:-1] if _on_loop(corners, np.array([x, y]))]
    crossings, streets = [], {}
    x_lo, x_hi, y_lo, y_hi = sx[0] + half, sx[-1] - half, sy[0] + half, sy[-1] - half
    for x, y in junctions:
        for u in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            u = np.array(u)
            n = np.array([-u[1], u[0]])
            c = np.array([x, y]) + (half + 2.0) * u
            a, b = c + walk * n, c - walk * n
            crossings.append(tuple(np.array([*q, float(terrain(q[:1], q[1:])[0]) + p.kerb_height_m]) for q in (a, b)))
        streets[("x", x)] = np.column_stack([np.full(200, x), np.linspace(y_lo + 2.0, y_hi - 2.0, 200)])
        streets[("y", y)] = np.column_stack([np.linspace(x_lo + 2.0, x_hi - 2.0, 200), np.full(200, y)])
    cross_streets = [(np.column_stack([xy, terrain(xy[:, 0], xy[:, 1])]), lo) for xy in streets.values()]
    # where the path meets a junction, its lanes' traffic may queue: a stop line before each
    path_xy = path[:, :2]
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path_xy, axis=0), axis=1))])
    stop_lines = tuple(float(along[np.argmin(np.linalg.norm(path_xy - np.array([x, y]), axis=1))]) - half - 3.0
                       for x, y in junctions)
    return RoadLayout(
        lanes=(Lane(0.0, 1), Lane(2 * lo, -1)), closed=closed, height=terrain, stop_lines=stop_lines,
        parking=(lo - lateral, lo + lateral) if parks else (),
        cyclists=((-min(1.4, half - lo - 0.6), 1), (2 * lo + min(1.4, half - lo - 0.6), -1)),
        walkways=walkways, crossings=crossings, cross_streets=cross_streets)


def _offset_polygon(corners: np.ndarray, d: float) -> np.ndarray:
    """The corners of a closed polyline of axis-parallel and collinear edges, moved ``d`` to the left of travel."""
    nxt = np.roll(corners, -1, axis=0) - corners
    n = np.stack([-nxt[:, 1], nxt[:, 0]], 1) / np.linalg.norm(nxt, axis=1, keepdims=True)
    prev = np.roll(n, 1, axis=0)
    return corners + d * (prev + n) / (1.0 + np.sum(prev * n, axis=1, keepdims=True))


def _on_loop(corners: np.ndarray, q: np.ndarray) -> bool:
    """Whether point q lies on the closed polyline through ``corners``."""
    a, b = corners, np.roll(corners, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((q - a) * ab, 1) / np.maximum(np.sum(ab * ab, 1), 1e-12), 0.0, 1.0)
    return bool(np.min(np.linalg.norm(a + t[:, None] * ab - q, axis=1)) < 1e-6)


# ---------------------------------------------------------------- blocks
def _block_platform(mb, p, terrain, bx, by, sidewalk_obj, court_obj, kerb_obj) -> None:
    """The raised block: a sidewalk band at the kerb, courtyard ground inside, kerb faces."""
    w, kh = p.sidewalk_width_m, p.kerb_height_m

    def axis(lo, hi):
        inner = np.linspace(lo + w, hi - w, max(2, int(np.ceil((hi - lo - 2 * w) / 4.0)) + 1))
        return np.concatenate([[lo], inner, [hi]])

    xs, ys = axis(*bx), axis(*by)
    v, f = g.heightfield(xs, ys, lambda x, y: terrain(x, y) + kh)
    centroid = v[f].mean(axis=1)
    inner = ((centroid[:, 0] > bx[0] + w) & (centroid[:, 0] < bx[1] - w)
             & (centroid[:, 1] > by[0] + w) & (centroid[:, 1] < by[1] - w))
    mb.add(v, f[~inner], sidewalk_obj)
    mb.add(v, f[inner], court_obj)
    # Kerb: the block's rim, counter-clockwise seen from above, sampled at the grid's
    # own vertices so it meets the sidewalk edge without a crack.
    ring = np.concatenate([
        np.column_stack([xs[:-1], np.full(len(xs) - 1, by[0])]),
        np.column_stack([np.full(len(ys) - 1, bx[1]), ys[:-1]]),
        np.column_stack([xs[:0:-1], np.full(len(xs) - 1, by[1])]),
        np.column_stack([np.full(len(ys) - 1, bx[0]), ys[:0:-1]]),
    ])
    h = terrain(ring[:, 0], ring[:, 1])
    mb.add(*g.wall_strip(ring, h - 0.1, h + kh, closed=True), kerb_obj)


# Footprint shapes in the lot frame: u along the street, v into the block.
_SHAPES = ("rect", "rect", "L", "L", "T", "U", "stepped")


def _block_buildings(mb, p, rng, terrain, bx, by) -> int:
    """Buildings on lots around the block's edge; returns how many."""
    w = p.sidewalk_width_m
    ix0, ix1, iy0, iy1 = bx[0] + w, bx[1] - w, by[0] + w, by[1] - w
    depth = min(rng.uniform(14.0, 24.0), 0.5 * min(ix1 - ix0, iy1 - iy0) - 1.0)
    if depth < 6.0:
        return 0
    # (start, end of the frontage in world, yaw) per side: yaw turns the lot frame
    # (u, v) so that v points into the block.
    sides = [
        ((ix0, iy0), (ix1, iy0), 0.0),  # south side, facing -y
        ((ix1, iy1), (ix0, iy1), np.pi),  # north
        ((ix0, iy1 - depth), (ix0, iy0 + depth), -np.pi / 2),  # west
        ((ix1, iy0 + depth), (ix1, iy1 - depth), np.pi / 2),  # east
    ]
    count = 0
    for a, b, yaw in sides:
        a, b = np.asarray(a), np.asarray(b)
        length = np.linalg.norm(b - a)
        u_dir = (b - a) / max(length, 1e-9)
        pos = 0.0
        while length - pos >= 8.0:
            lot_w = min(rng.uniform(12.0, 30.0), length - pos)
            if length - pos - lot_w < 8.0:
                lot_w = length - pos
            if rng.random() < 0.9:  # some lots stay empty: gaps and alleys
                origin = a + u_dir * pos
                _building(mb, p, rng, terrain, origin, yaw, lot_w, depth)
                count += 1
            pos += lot_w
    return count


def _building(mb, p, rng, terrain, origin, yaw, lot_w, lot_d) -> None:
    """One building on a lot whose front-left corner is ``origin`` (2,), turned by ``yaw``.

    Built in the lot frame (u along the street, v into the block, front at v = 0).
    """
    gap = rng.uniform(0.0, 1.0)  # side gaps between neighbours
    u0, u1 = gap, lot_w - gap
    sb = rng.uniform(0.5, p.setback_max_m)
    v0, v1 = sb, lot_d - rng.uniform(0.0, 2.0)
    if u1 - u0 < 6.0 or v1 - v0 < 5.0:
        return
    height = float(np.exp(rng.uniform(np.log(p.building_height_min_m), np.log(p.building_height_max_m))))
    shape = _SHAPES[rng.integers(len(_SHAPES))]
    du, dv = u1 - u0, v1 - v0
    xs, ys, mask = np.array([u0, u1]), np.array([v0, v1]), np.ones((1, 1), dtype=bool)
    if shape in ("L", "T", "U"):
        split_v = v0 + dv * rng.uniform(0.35, 0.6)
        ys = np.array([v0, split_v, v1])
        if shape == "L":
            xs = np.array([u0, u0 + du * rng.uniform(0.35, 0.65), u1])
            mask = np.array([[1, 1], [1, 0]] if rng.random() < 0.5 else [[1, 0], [1, 1]], dtype=bool)
        else:
            xs = np.array([u0, u0 + du * 0.3, u0 + du * 0.7, u1])
            mask = np.array([[1, 0], [1, 1], [1, 0]] if shape == "T" else [[1, 1], [1, 0], [1, 1]],
                            dtype=bool)
    corners = _to_world(np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]]), origin, yaw)
    h_corners = terrain(corners[:, 0], corners[:, 1])
    z0 = float(h_corners.min()) - 0.5  # sunk below the sidewalk everywhere
    ground = float(h_corners.max()) + p.kerb_height_m
    z_top = ground + height

    parts = []
    facade_top = z_top
    if shape == "stepped":
        # Two or three tiers, each set back from the one below (wedding-cake massing).
        n_tiers = int(rng.integers(2, 4))
        zs = [z0] + [ground + height * lv for lv in np.sort(rng.uniform(0.35, 0.85, n_tiers - 1))] + [z_top]
        facade_top = zs[1]
        inset = 0.0
        for k in range(n_tiers):
            txs, tys = np.array([u0 + inset, u1 - inset]), np.array([v0 + inset, v1 - inset * 0.5])
            if k > 0 and (txs[1] - txs[0] < 4.0 or tys[1] - tys[0] < 4.0):
                break
            parts.append(g.grid_prism(txs, tys, mask, zs[k], zs[k + 1]))
            xs, ys, z_top = txs, tys, zs[k + 1]
            inset += rng.uniform(2.0, 4.0)
    else:
        parts.append(g.grid_prism(xs, ys, mask, z0, z_top))
    roof_parts = []
    roof_kind = rng.choice(["flat", "flat", "gable", "hip", "shed"]) if mask.size == 1 else "flat"
    if roof_kind == "flat":
        parts.append(_parapet(xs, ys, mask, 0.3, z_top - 0.2, z_top + rng.uniform(0.6, 1.2)))
    else:
        ridge_h = rng.uniform(2.0, 5.0)
        (a, b), (c, d) = xs, ys
        base = [[a, c, z_top], [b, c, z_top], [b, d, z_top], [a, d, z_top]]
        mid = (c + d) / 2
        if roof_kind == "gable":
            top = [[a, mid, z_top + ridge_h], [b, mid, z_top + ridge_h]]
        elif roof_kind == "hip":
            inset = min((b - a) * 0.25, (d - c) * 0.5)
            top = [[a + inset, mid, z_top + ridge_h], [b - inset, mid, z_top + ridge_h]]
        else:  # shed: rises toward the back
            top = [[a, d, z_top + ridge_h], [b, d, z_top + ridge_h]]
        roof_parts.append(g.convex(np.array(base + top)))
    # Facade relief on the street front (row v0, always full width): pilasters, a ledge.
    if rng.random() < 0.7:
        n_pil = int(du // rng.uniform(3.0, 5.0)) + 1
        zc = (z0 + facade_top) / 2
        for u in np.linspace(u0 + 0.2, u1 - 0.2, n_pil):
            parts.append(g.box((0.4, 0.25, facade_top - z0), (u, v0 - 0.125, zc)))
    if rng.random() < 0.6:
        parts.append(g.box((du + 0.4, 0.4, 0.3), ((u0 + u1) / 2, v0 - 0.2, ground + 3.5)))
    building = mb.new_object("building")
    for part in parts:
        mb.add(*g.place(part, yaw, (*origin, 0.0)), building)
    if roof_parts:
        roof = mb.new_object("roof")
        for part in roof_parts:
            mb.add(*g.place(part, yaw, (*origin, 0.0)), roof)


def _parapet(xs, ys, mask, width, z0, z1) -> g.Part:
    """A wall ``width`` m thick along the rim of an orthogonal footprint, from z0 to z1."""
    def refine(b):
        fine = np.unique(np.concatenate([b, b + width, b - width]))
        return fine[(fine >= b[0] - 1e-9) & (fine <= b[-1] + 1e-9)]

    fx, fy = refine(xs), refine(ys)
    cx, cy = (fx[:-1] + fx[1:]) / 2, (fy[:-1] + fy[1:]) / 2
    occ = mask[np.searchsorted(xs, cx) - 1][:, np.searchsorted(ys, cy) - 1]
    padded = np.zeros((occ.shape[0] + 2, occ.shape[1] + 2), dtype=bool)
    padded[1:-1, 1:-1] = occ
    surrounded = np.ones_like(occ)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            surrounded &= padded[1 + di: padded.shape[0] - 1 + di, 1 + dj: padded.shape[1] - 1 + dj]
    return g.grid_prism(fx, fy, occ & ~surrounded, z0, z1)


def _to_world(uv: np.ndarray, origin: np.ndarray, yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return uv @ np.array([[c, s], [-s, c]]) + origin


def _end_building(mb, rng, terrain, x, y, width, yaw) -> None:
    """A building across a street's end at (x, y), its front facing the street."""
    depth = 14.0
    h = rng.uniform(10.0, 30.0)
    z = float(terrain(np.array([x]), np.array([y]))[0])
    part = g.grid_prism(np.array([-width / 2 - 4, width / 2 + 4]), np.array([-depth / 2, depth / 2]),
                        np.ones((1, 1)), z - 0.5, z + h)
    mb.add_object(*g.place(part, yaw, (x, y, 0.0)), "building")


# ---------------------------------------------------------------- furniture
def _sidewalk_furniture(mb, p, rng, terrain, bx, by) -> None:
    """Street lights, trees and signs along the block's four kerbs."""
    kh = p.kerb_height_m
    edges = [  # (start, end, inward normal) counter-clockwise
        ((bx[0], by[0]), (bx[1], by[0]), (0.0, 1.0)),
        ((bx[1], by[0]), (bx[1], by[1]), (-1.0, 0.0)),
        ((bx[1], by[1]), (bx[0], by[1]), (0.0, -1.0)),
        ((bx[0], by[1]), (bx[0], by[0]), (1.0, 0.0)),
    ]
    for a, b, n in edges:
        a, b, n = np.asarray(a), np.asarray(b), np.asarray(n)
        length = np.linalg.norm(b - a)
        u = (b - a) / length
        street_yaw = float(np.arctan2(-n[1], -n[0]))  # facing the street
        if p.light_spacing_m > 0:
            for s in np.arange(8.0, length - 8.0, p.light_spacing_m):
                q = a + u * s + n * 0.5
                z = float(terrain(q[:1], q[1:])[0]) + kh
                mb.add_object(*g.place(props.street_light(rng.uniform(6.5, 8.0)), street_yaw, (*q, z)), "pole")
                mb.add_object(*g.place(g.box((0.4, 0.4, 0.15), (0.0, 0.0, 0.0)), 0.0, (*q, z)), "light")
        if p.tree_spacing_m > 0:
            offset = p.light_spacing_m / 2 if p.light_spacing_m > 0 else 0.0
            for s in np.arange(8.0 + offset % p.tree_spacing_m, length - 8.0, p.tree_spacing_m):
                if p.light_spacing_m > 0 and np.min(np.abs(((s - 8.0) % p.light_spacing_m)
                                                           - np.array([0.0, p.light_spacing_m]))) < 4.0:
                    continue  # keep clear of the lights
                if rng.random() < 0.2:
                    continue
                q = a + u * s + n * min(1.2, p.sidewalk_width_m / 2)
                z = float(terrain(q[:1], q[1:])[0]) + kh
                trunk, crown = props.tree(rng, rng.uniform(6.0, 10.0), rng.uniform(1.4, 2.0))
                tree = mb.new_object("vegetation")
                mb.add(*g.place(trunk, 0.0, (*q, z)), tree)
                mb.add(*g.place(crown, 0.0, (*q, z)), tree)
        # A sign before the corner the traffic on this side drives toward (right-hand traffic
        # along this kerb drives from a to b).
        if rng.random() < 0.7:
            q = a + u * (length - 6.0) + n * 0.4
            z = float(terrain(q[:1], q[1:])[0]) + kh
            post, plate = props.sign(rng.uniform(2.3, 2.8))
            face_back = float(np.arctan2(-u[1], -u[0]))  # plate faces oncoming drivers
            mb.add_object(*g.place(post, face_back, (*q, z)), "pole")
            mb.add_object(*g.place(plate, face_back, (*q, z)), "sign")


def _parked_cars(mb, p, rng, terrain, sx, sy) -> int:
    """Cars in the parking lanes along both kerbs of every street, clear of intersections."""
    lateral = p.street_width_m / 2 - 1.1  # car centre from the street centre-line
    # Park only where a car (0.95 m half width, 0.5 m margin) passes in the driven lane.
    if lateral - 0.95 - p.lane_offset_m < 0.95 + 0.5:
        return 0
    slot = 6.0
    keep_clear = p.street_width_m / 2 + 8.0
    count = 0
    lines = []  # (fixed coordinate, along-axis, span) per street
    for x in sx[1:-1]:
        lines.append(("x", x, sy))
    for y in sy[1:-1]:
        lines.append(("y", y, sx))
    for axis, c, cross in lines:
        for k in range(len(cross) - 1):
            lo = cross[k] + (keep_clear if k > 0 else p.street_width_m / 2 + 2.0)
            hi = cross[k + 1] - (keep_clear if k < len(cross) - 2 else p.street_width_m / 2 + 2.0)
            for s in np.arange(lo + slot / 2, hi - slot / 2, slot):
                for side in (-1.0, 1.0):
                    if rng.random() >= p.parked_car_fraction:
                        continue
                    jitter = rng.uniform(-0.6, 0.6)
                    if axis == "x":
                        q = np.array([c + side * lateral, s + jitter])
                        yaw = np.pi / 2 if side > 0 else -np.pi / 2
                    else:
                        q = np.array([s + jitter, c + side * lateral])
                        yaw = np.pi if side > 0 else 0.0
                    z = float(terrain(q[:1], q[1:])[0])
                    mb.add_object(*g.place(props.car(rng), yaw + rng.uniform(-0.03, 0.03), (*q, z)),
                                  "vehicle")
                    count += 1
    return count


# ---------------------------------------------------------------- route
def _route_corners(p, rng, street_x: np.ndarray, street_y: np.ndarray) -> np.ndarray:
    """(n, 2) corners of the loop around a random group of adjacent inner blocks."""
    nx, ny = len(street_x) - 1, len(street_y) - 1
    for _ in range(200):
        cells = {(int(rng.integers(nx)), int(rng.integers(ny)))}
        while len(cells) < p.route_blocks:
            ci, cj = sorted(cells)[int(rng.integers(len(cells)))]
            di, dj = ((1, 0), (-1, 0), (0, 1), (0, -1))[int(rng.integers(4))]
            nb = (ci + di, cj + dj)
            if 0 <= nb[0] < nx and 0 <= nb[1] < ny:
                cells.add(nb)
        loop = _boundary_loop(cells)
        if loop is not None:
            break
    else:  # pragma: no cover - a single block always has a simple boundary
        raise ValueError("parameter route_blocks: no simple loop found")
    pts = np.array([[street_x[i], street_y[j]] for i, j in loop], dtype=float)
    if rng.random() < 0.5:
        pts = pts[::-1]
    # Start in the middle of the longest side, on a straight.
    seg = np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)
    k = int(np.argmax(seg))
    mid = (pts[k] + pts[(k + 1) % len(pts)]) / 2
    return np.vstack([mid, np.roll(pts, -(k + 1), axis=0)])


def _boundary_loop(cells: set[tuple[int, int]]) -> list[tuple[int, int]] | None:
    """Corner vertices of the boundary of a set of grid cells, counter-clockwise.

    None if the boundary is not a single simple loop (a hole, or cells touching
    only at a corner).
    """
    edges = {}
    for i, j in cells:
        for a, b in (((i, j), (i + 1, j)), ((i + 1, j), (i + 1, j + 1)),
                     ((i + 1, j + 1), (i, j + 1)), ((i, j + 1), (i, j))):
            if (b, a) in edges:
                del edges[(b, a)]
            else:
                edges[(a, b)] = True
    nxt: dict[tuple[int, int], tuple[int, int]] = {}
    for a, b in edges:
        if a in nxt:
            return None
        nxt[a] = b
    start = min(nxt)
    loop = [start]
    while True:
        b = nxt[loop[-1]]
        if b == start:
            break
        loop.append(b)
    if len(loop) != len(nxt):
        return None
    # keep only turning vertices
    n = len(loop)
    corners = []
    for k in range(n):
        a, b, c = np.array(loop[k - 1]), np.array(loop[k]), np.array(loop[(k + 1) % n])
        u, w = b - a, c - b
        if u[0] * w[1] - u[1] * w[0] != 0:
            corners.append(loop[k])
    return corners
