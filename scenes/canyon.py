"""Canyon: a street between continuous tall facades that runs into a tunnel, and out again.

The street (straight, or a gentle left curve of ``street_curve_radius_m``)
runs ``street_length_m`` from the vehicle's start to a tunnel's portal; it
reaches 40 m behind the start, where a building closes it. Both sides are
lined by buildings standing shoulder to shoulder on the building line behind
the sidewalks, ``building_height_min_m``-``building_height_max_m`` tall, with
a few alleys (``gap_fraction``, a building closing each at the back). How
much the facades are modelled is ``facade_relief``: at 0 flat walls; the
higher, the more buildings get window recesses (piers and floor bands
standing proud of the window plane), a recessed shop-front ground floor
between end pillars, balconies and a cornice. Cars park along both kerbs,
lamp posts line the sidewalks, signs announce the tunnel.

The tunnel is the tunnel scene's own bore (``tunnel.add_bore``: cliff faces at
the portals, a hill over it, lining, walkways, fittings every
``feature_spacing_m``), ``tunnel_length_m`` long and straight; after it the road
runs ``exit_m`` through open land. Street and tunnel are both weak along the
direction of travel: the odometry's degenerate case, twice.

Metadata: ``portal_s`` / ``interior_s`` (path arc length of the two portals,
m), ``axis_xy`` (unit direction of the tunnel), ``street_s`` (path arc length of
the street: start to portal), ``path_length_m``, ``buildings``, ``parked_cars``,
``fittings``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geometry as g
from . import paths, props, tunnel
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .traffic import two_way_road
from .trajectory import PathTrajectory

DESCRIPTION = "street canyon of continuous tall facades leading into a tunnel, open road after it"

STEP_M = tunnel.STEP_M  # the tunnel's helpers index the alignment by this sampling
BEHIND_M = 40.0  # the street reaches this far behind the start
RAMP_M = 3.0  # the sidewalks slope down to the road over this length before the portal
CAR_HALF_WIDTH_M = 0.95
PARK_FROM_KERB_M = 1.05


@dataclass(frozen=True)
class Params(CommonParams):
    street_length_m: float = param(180.0, "street from the start to the tunnel's portal", min=50.0, max=3000.0)
    street_width_m: float = param(14.0, "road width kerb to kerb (two lanes, parking both sides)",
                                  min=8.0, max=30.0)
    sidewalk_width_m: float = param(3.5, "sidewalk width, kerb to building line", min=1.5, max=8.0)
    kerb_height_m: float = param(0.15, "kerb height", min=0.0, max=0.3)
    street_curve_radius_m: float = param(0.0, "radius of the street's left curve (0: straight)", min=0.0,
                                         max=1e6)
    building_height_min_m: float = param(15.0, "lowest building", min=6.0, max=200.0)
    building_height_max_m: float = param(40.0, "tallest building", min=6.0, max=300.0)
    facade_relief: float = param(0.5, "how much the facades are modelled: 0 flat walls, 1 every facade with "
                                 "window recesses, shop fronts, balconies, cornices", min=0.0, max=1.0)
    gap_fraction: float = param(0.06, "share of the lots left as alleys between the buildings", min=0.0, max=0.6)
    parked_car_fraction: float = param(0.5, "share of parking places holding a car", min=0.0, max=1.0)
    light_spacing_m: float = param(30.0, "spacing of lamp posts on each sidewalk (0: none)", min=0.0,
                                   max=1000.0)
    tunnel_length_m: float = param(120.0, "tunnel length portal to portal", min=30.0, max=5000.0)
    tunnel_cross_section: str = param("box", "shape of the bore", choices=("arch", "box"))
    tunnel_width_m: float = param(10.5, "bore width wall to wall (two lanes and walkways)", min=7.0, max=30.0)
    tunnel_height_m: float = param(6.5, "clear height at the bore's crown", min=4.5, max=20.0)
    walkway_width_m: float = param(1.0, "raised walkway along each tunnel wall", min=0.0, max=3.0)
    overburden_m: float = param(20.0, "height of the hill above the road mid-tunnel", min=2.0, max=500.0)
    feature_spacing_m: float = param(60.0, "spacing of lights/cabinets/fans in the tunnel (0: bare bore)",
                                     min=0.0, max=10000.0)
    exit_m: float = param(100.0, "open road after the tunnel", min=20.0, max=3000.0)
    grade_pct: float = param(0.0, "road grade (positive: rising)", min=-8.0, max=8.0)
    lane_offset_m: float = param(1.75, "the vehicle drives this far right of the centre-line", min=0.0, max=5.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.building_height_max_m < self.building_height_min_m:
            raise ParamError("is below building_height_min_m", "building_height_max_m")
        if self.street_curve_radius_m and self.street_curve_radius_m < 300.0:
            raise ParamError("is too tight: a gentle curve needs a radius >= 300 m (or 0)", "street_curve_radius_m")
        if self.street_curve_radius_m and self.street_length_m / self.street_curve_radius_m > np.pi / 2:
            raise ParamError(f"is too tight: a {self.street_length_m:g} m street on a "
                             f"{self.street_curve_radius_m:g} m radius turns more than 90 degrees",
                             "street_curve_radius_m")
        if self.lane_offset_m > self.tunnel_width_m / 2 - self.walkway_width_m - 1.2:
            raise ParamError(f"is {self.lane_offset_m} m: that puts the vehicle on the tunnel's walkway",
                             "lane_offset_m")
        if self.lane_offset_m > self.street_width_m / 2 - 1.5:
            raise ParamError(f"is {self.lane_offset_m} m: that leaves the street", "lane_offset_m")
        if self.street_width_m / 2 + self.sidewalk_width_m < self.tunnel_width_m / 2 + 1.0:
            raise ParamError("is too wide: the bore must be narrower than the street's building line "
                             "(tunnel_width_m / 2 + 1 <= street_width_m / 2 + sidewalk_width_m)", "tunnel_width_m")
        if self.overburden_m < self.tunnel_height_m + 1.0:
            raise ParamError("must exceed tunnel_height_m + 1 (the hill covers the bore)", "overburden_m")
        if self.tunnel_cross_section == "arch" and self.tunnel_height_m < self.tunnel_width_m / 2 + 1.0:
            raise ParamError("is too low: an arch needs tunnel_height_m >= tunnel_width_m / 2 + 1", "tunnel_height_m")

    def bore(self) -> tunnel.Bore:
        """The tunnel's bore for ``tunnel.add_bore`` / ``add_fittings``."""
        return tunnel.Bore(self.tunnel_width_m, self.tunnel_height_m, self.tunnel_cross_section,
                           self.walkway_width_m, self.overburden_m, self.feature_spacing_m)


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0xCA7])
    bore = p.bore()
    s_in = BEHIND_M + p.street_length_m
    s_out = s_in + p.tunnel_length_m
    total = s_out + p.exit_m
    s, centre, heading = tunnel.alignment(total, BEHIND_M, p.street_length_m, p.street_curve_radius_m,
                                          p.grade_pct / 100, STEP_M)
    left = np.column_stack([-np.sin(heading), np.cos(heading), np.zeros_like(heading)])
    ground_noise = g.SmoothField(rng, 0.4, (60.0, 250.0))
    lat_side = tunnel.land_laterals(bore)
    edge = lat_side[0]

    def land_height(idx, lv):
        """(len(idx), len(lv)) land around the tunnel and the exit road, above the road level:
        level with the street at the first portal, a ditch and rolling land from 60 m on."""
        xy = centre[idx, None, :2] + lv[None, :, None] * left[idx, None, :2]
        rural = np.clip((s[idx] - s_in) / 60.0, 0.0, 1.0)[:, None]
        off_road = np.clip((np.abs(lv) - edge - 2.0) / 10.0, 0.0, 1.0)
        ditch = np.clip((np.abs(lv) - edge) / 0.5, 0.0, 1.0) * 0.3
        return rural * (ground_noise(xy[..., 0], xy[..., 1]) * off_road[None, :] - ditch[None, :])

    mb = MeshBuilder()
    road_obj = mb.new_object("road")
    land_obj = mb.new_object("ground")
    _street(mb, p, s, centre, left, s_in, road_obj, land_obj)
    n_buildings = _facades(mb, p, rng, s, centre, left, heading, s_in)
    tunnel.add_open_road(mb, centre, left, tunnel.slice_rows(s_out, total), lat_side, land_height, road_obj,
                         land_obj)
    tunnel.add_bore(mb, bore, s, centre, left, heading, s_in, s_out, lat_side, land_height, road_obj)
    n_fittings = tunnel.add_fittings(mb, bore, centre, left, heading, s_in, s_out)
    n_cars = _parked_cars(mb, p, rng, s, centre, left, heading, s_in)
    _furniture(mb, p, rng, s, centre, left, heading, s_in, s_out, land_height)

    # The path: the right lane from the start (BEHIND_M along the street) to the end.
    i0 = int(round(BEHIND_M / STEP_M))
    lane = paths.smooth(centre[:, :2] - p.lane_offset_m * left[:, :2], 1.0, STEP_M, closed=False)
    path = np.column_stack([lane, centre[:, 2]])[i0:]
    traj = PathTrajectory(
        path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    s_path = paths.arc_length(path[:, :2])
    i_in, i_out = int(round(s_in / STEP_M)) - i0, int(round(s_out / STEP_M)) - i0
    i_mid = (i_in + i_out) // 2 + i0
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    roads = two_way_road(p.lane_offset_m, p.street_width_m / 2, False, None, p.street_width_m / 2 - PARK_FROM_KERB_M,
                         CAR_HALF_WIDTH_M, p.sidewalk_width_m, p.kerb_height_m,
                         pavement_spans=((0.0, float(s_path[i_in]) - RAMP_M - 5.0),))
    return Scene(
        "canyon", v, f, ids, labels, path, traj, p.to_dict(), roads=roads, metadata=
        {
            "street_s": [0.0, float(s_path[i_in])],
            "portal_s": [float(s_path[i_in]), float(s_path[i_out])],
            "interior_s": [float(s_path[i_in]), float(s_path[i_out])],
            "axis_xy": [float(np.cos(heading[i_mid])), float(np.sin(heading[i_mid]))],
            "path_length_m": float(s_path[-1]),
            "buildings": n_buildings,
            "parked_cars": n_cars,
            "fittings": n_fittings,
        },
    )


def _ramp(p: Params, s: np.ndarray, s_in: float) -> np.ndarray:
    """(n,) the sidewalks' height above the road along the street: the kerb height, sloping
    to nothing over the last ``RAMP_M`` before the portal (which stands on road level)."""
    return p.kerb_height_m * np.clip((s_in - s) / RAMP_M, 0.0, 1.0)


# ---------------------------------------------------------------- street
def _street(mb, p, s, centre, left, s_in, road_obj, land_obj) -> None:
    """Road, kerbs, sidewalks to the building line and the ground behind it, from the street's
    closed end to the portal."""
    idx = tunnel.slice_rows(0.0, s_in)
    c, lv = centre[idx], left[idx]
    n = len(idx)
    sh, bl = p.street_width_m / 2, p.street_width_m / 2 + p.sidewalk_width_m
    kh = _ramp(p, s[idx], s_in)[:, None]

    def prof(lat, lift):
        lat = np.broadcast_to(np.asarray(lat, dtype=float), (n, len(lat)))
        return np.stack([lat, np.broadcast_to(lift, lat.shape)], -1)

    mb.add(*g.sweep(c, lv, np.array([[-sh, 0.0], [sh, 0.0]])), road_obj)
    if p.kerb_height_m > 0:
        kerb = mb.new_object("kerb")
        mb.add(*g.sweep(c, lv, prof([sh, sh], np.hstack([0 * kh, kh]))), kerb)  # left kerb faces the road
        mb.add(*g.sweep(c, lv, prof([-sh, -sh], np.hstack([kh, 0 * kh]))), kerb)
    walk = mb.new_object("sidewalk")
    mb.add(*g.sweep(c, lv, prof([sh, bl], np.hstack([kh, kh]))), walk)
    mb.add(*g.sweep(c, lv, prof([-bl, -sh], np.hstack([kh, kh]))), walk)
    # Ground behind the building line (alleys, under the buildings), level with the sidewalk.
    far = np.array([bl, bl + 30.0, 150.0])
    mb.add(*g.sweep(c, lv, prof(far, np.hstack([kh] * 3))), land_obj)
    mb.add(*g.sweep(c, lv, prof(-far[::-1], np.hstack([kh] * 3))), land_obj)


# ---------------------------------------------------------------- buildings
def _facades(mb, p, rng, s, centre, left, heading, s_in) -> int:
    """Buildings shoulder to shoulder on both building lines, alleys between a few; returns how many."""
    bl = p.street_width_m / 2 + p.sidewalk_width_m
    kh = p.kerb_height_m
    count = 0
    # The street's closed end: a building across it, its front at s = 0.
    width = 2 * (bl + 20.0)
    z = float(centre[0, 2])
    end = g.grid_prism(np.array([-12.0, 0.0]), np.array([-width / 2, width / 2]), np.ones((1, 1), dtype=bool),
                       z - 0.5, z + kh + rng.uniform(18.0, 35.0))
    mb.add_object(*g.place(end, heading[0], (*centre[0, :2], 0.0)), "building")
    count += 1
    for side in (1.0, -1.0):
        cursor = 0.0
        while cursor < s_in - 1e-6:
            alley = cursor > 0 and rng.random() < p.gap_fraction
            width = rng.uniform(4.0, 9.0) if alley else rng.uniform(12.0, 30.0)
            if s_in - (cursor + width) < 8.0:  # the last lot reaches the portal
                width = s_in - cursor
            a, b = cursor, cursor + width
            cursor = b
            ia, ib = int(round(a / STEP_M)), int(round(b / STEP_M))
            pa = centre[ia, :2] + side * bl * left[ia, :2]
            pb = centre[ib, :2] + side * bl * left[ib, :2]
            # lot frame: u along the frontage, v away from the street (right-handed, z up)
            origin, toward = (pa, pb) if side > 0 else (pb, pa)
            length = float(np.linalg.norm(toward - origin))
            yaw = float(np.arctan2(*(toward - origin)[::-1]))
            z_lo = float(min(centre[ia, 2], centre[ib, 2])) + _ramp(p, np.array([b]), s_in)[0]
            z_hi = float(max(centre[ia, 2], centre[ib, 2])) + kh
            if alley:
                depth = rng.uniform(16.0, 26.0)
                back = g.grid_prism(np.array([-4.0, length + 4.0]), np.array([depth, depth + 10.0]),
                                    np.ones((1, 1), dtype=bool), z_lo - 0.5, z_hi + rng.uniform(10.0, 25.0))
                mb.add_object(*g.place(back, yaw, (*origin, 0.0)), "building")
            else:
                parts = _building(p, rng, length, z_lo - 0.5, z_hi)
                obj = mb.new_object("building")
                for part in parts:
                    mb.add(*g.place(part, yaw, (*origin, 0.0)), obj)
            count += 1
    return count


def _box(u0, u1, v0, v1, z0, z1) -> g.Part:
    return g.box((u1 - u0, v1 - v0, z1 - z0), ((u0 + u1) / 2, (v0 + v1) / 2, (z0 + z1) / 2))


def _building(p: Params, rng, width: float, z0: float, z_ground: float) -> list[g.Part]:
    """One building's parts in its lot frame: u in [0, width] along the street, v >= 0 away from
    it, the front (its outermost face but balconies and cornice) on v = 0; metres.

    z0: its foot (in the ground); z_ground: the sidewalk's highest point in front of it.
    """
    r = p.facade_relief
    depth = rng.uniform(14.0, 22.0)
    height = float(np.exp(rng.uniform(np.log(p.building_height_min_m), np.log(p.building_height_max_m))))
    z_top = z_ground + height
    floor_h = rng.uniform(3.0, 3.6)
    shop = rng.random() < 0.8 * r and height > 8.0
    grid = rng.random() < r
    ground_h = rng.uniform(3.8, 4.6) if shop else 0.0
    recess = rng.uniform(0.15, 0.4) if grid else 0.0  # window plane behind the piers and bands
    z_upper = z_ground + ground_h if shop else z0
    # closed boxes throughout: an overhang's underside must not open into the building
    parts = [_box(0.0, width, recess, depth, z_upper, z_top)]
    if shop:
        # the ground floor's glazing set back between two end pillars, under the upper floors
        back = recess + rng.uniform(0.4, 1.2)
        parts.append(_box(0.0, width, back, depth, z0, z_upper))
        for u0, u1 in ((0.0, 0.6), (width - 0.6, width)):
            parts.append(_box(u0, u1, 0.0, back, z0, z_upper))
    n_floors = max(1, int((z_top - z_ground - ground_h) // floor_h))
    bays = max(1, int(round(width / rng.uniform(3.0, 4.5))))
    edges = np.linspace(0.0, width, bays + 1)
    floors = z_ground + ground_h + floor_h * np.arange(n_floors)
    if grid:
        pier = rng.uniform(0.4, 0.8)
        for u in edges:
            u0, u1 = np.clip([u - pier / 2, u + pier / 2], 0.0, width)
            parts.append(_box(u0, u1, 0.0, recess, z_upper, z_top))
        band = rng.uniform(0.8, 1.1)  # the wall under each row of windows
        for z in floors[floors + band < z_top]:
            parts.append(_box(0.0, width, 0.0, recess, max(z, z_upper), z + band))
    reach = min(rng.uniform(0.9, 1.4), p.sidewalk_width_m - 1.0)  # clear of the lamp posts
    if rng.random() < 0.6 * r and n_floors > 2 and reach >= 0.5:
        for z in floors[1:-1]:
            for k in range(int(rng.integers(0, 2)), bays, 2):
                u0, u1 = edges[k] + 0.4, edges[k + 1] - 0.4
                if u1 - u0 < 1.5:
                    continue
                parts.append(_box(u0, u1, -reach, recess, z - 0.1, z + 0.1))  # slab
                parts.append(_box(u0, u1, -reach, -reach + 0.08, z + 0.1, z + 1.05))  # front rail
    if rng.random() < r:
        parts.append(_box(0.0, width, -0.4, recess + 0.1, z_top - 0.5, z_top))  # cornice
    return parts


# ---------------------------------------------------------------- cars and furniture
def _parked_cars(mb, p, rng, s, centre, left, heading, s_in) -> int:
    """Cars along both kerbs from 10 m past the street's end to 25 m before the portal, where
    a parked car leaves the driven lane a car's half width and 0.5 m."""
    lateral = p.street_width_m / 2 - PARK_FROM_KERB_M
    slot = 6.0
    count = 0
    for side in (1.0, -1.0):
        clearance = lateral - CAR_HALF_WIDTH_M + side * p.lane_offset_m
        if clearance < CAR_HALF_WIDTH_M + 0.5:
            continue
        for sc in np.arange(10.0 + slot / 2, s_in - 25.0, slot):
            if rng.random() >= p.parked_car_fraction:
                continue
            car = props.car(rng)
            i = int(round((sc + rng.uniform(-0.5, 0.5)) / STEP_M))
            xy = centre[i, :2] + side * lateral * left[i, :2]
            facing = 0.0 if side < 0 else np.pi
            yaw = heading[i] + facing + rng.uniform(-0.03, 0.03)
            pitch = -np.arctan(p.grade_pct / 100) * (1.0 if side < 0 else -1.0)
            mb.add_object(*g.place_tilted(car, yaw, pitch, 0.0, (*xy, centre[i, 2] - 0.02)), "vehicle")
            count += 1
    return count


def _furniture(mb, p, rng, s, centre, left, heading, s_in, s_out, land_height) -> None:
    """Lamp posts on both sidewalks and along the exit road, signs announcing the tunnel."""
    sh = p.street_width_m / 2
    if p.light_spacing_m > 0:
        for side, offset in ((1.0, 0.0), (-1.0, 0.5)):
            for sl in np.arange(5.0 + offset * p.light_spacing_m, s_in - 10.0, p.light_spacing_m):
                i = int(round(sl / STEP_M))
                q = centre[i] + side * (sh + 0.5) * left[i]
                q[2] += p.kerb_height_m
                mb.add_object(*g.place(props.street_light(rng.uniform(7.0, 8.5), 1.8),
                                       heading[i] - side * np.pi / 2, q), "pole")
        half = p.tunnel_width_m / 2
        for sl in np.arange(s_out + 15.0, s[-1] - 5.0, p.light_spacing_m):
            i = int(round(sl / STEP_M))
            lat = half + 2.0  # beyond the ditch
            q = centre[i] + lat * left[i]
            q[2] += float(land_height(np.array([i]), np.array([lat]))[0, 0]) - 0.2
            mb.add_object(*g.place(props.street_light(8.0, 2.5), heading[i] - np.pi / 2, q), "pole")
    i = int(round(max(s_in - 40.0, 5.0) / STEP_M))
    for side in (-1.0, 1.0):
        q = centre[i] + side * (sh + 0.4) * left[i]
        q[2] += p.kerb_height_m
        post, plate = props.sign(2.8, (0.05, 0.9, 0.9))
        yaw = heading[i] + np.pi  # facing the traffic coming toward the portal
        mb.add_object(*g.place(post, yaw, q), "pole")
        mb.add_object(*g.place(plate, yaw, q), "sign")
