"""Tunnel: a long bore under a hill, open road before and after, sparse fittings inside.

The alignment runs straight for ``approach_m``, through the tunnel (straight,
or a constant-radius curve when ``curve_radius_m`` > 0) and straight again,
at a constant grade. The bore's lining (box or arched cross-section) faces
inward; raised walkways line both walls. At each portal a cliff face, cut by
the bore's outline, rises to a hill that covers the tunnel. Inside, every
``feature_spacing_m`` a pair of wall lights, on alternate sides an emergency
cabinet with a sign, and every fourth time a pair of jet fans under the roof:
otherwise nothing fixes the position along the axis, the degenerate case.
``bare_length_m`` leaves a stretch in the tunnel's middle without fittings (bare
walls); ``stop_wait_s`` has the vehicle brake to a stop at the tunnel's middle,
wait and accelerate again: where lidar alone cannot see the motion (the
``bare-tunnel`` scene sets both).

Metadata: ``interior_s`` (path arc length from the first portal to the
second, m), ``portal_s``, ``axis_xy`` (unit direction at the tunnel's middle),
``bare_s`` (the bare stretch's ends along the path, m) and ``stop_s`` (where the
vehicle stops, m) when there are.

Other scenes with a tunnel build it with ``add_bore`` and ``add_fittings`` (a
``Bore`` describes it) on an alignment sampled ``STEP_M`` apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .traffic import two_way_road
from .trajectory import PathTrajectory

DESCRIPTION = "long tunnel (box or arched, straight or curved) under a hill, portals, open road both ends"

STEP_M = 0.5  # path sampling
SLICE_M = 2.0  # length of one ring of the bore's mesh
FAN_CLEARANCE_M = 4.5  # usual clear height of a road tunnel: nothing hangs lower


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(15.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    length_m: float = param(500.0, "tunnel length portal to portal", min=50.0, max=10000.0)
    approach_m: float = param(80.0, "open road before and after the tunnel", min=20.0, max=2000.0)
    cross_section: str = param("arch", "shape of the bore", choices=("arch", "box"))
    width_m: float = param(10.5, "bore width wall to wall (two lanes and walkways)", min=7.0, max=30.0)
    height_m: float = param(7.0, "clear height at the bore's crown", min=4.5, max=20.0)
    walkway_width_m: float = param(1.0, "raised walkway along each wall", min=0.0, max=3.0)
    curve_radius_m: float = param(0.0, "radius of the tunnel's curve, left turning (0: straight)",
                                  min=0.0, max=1e6)
    grade_pct: float = param(1.0, "road grade (positive: rising)", min=-8.0, max=8.0)
    feature_spacing_m: float = param(80.0, "spacing of lights/cabinets/fans inside (0: bare bore)",
                                     min=0.0, max=10000.0)
    overburden_m: float = param(25.0, "height of the hill above the road mid-tunnel", min=2.0, max=500.0)
    lane_offset_m: float = param(1.75, "the vehicle drives this far right of the centre-line",
                                 min=0.0, max=5.0)
    bare_length_m: float = param(0.0, "a stretch this long in the tunnel's middle has no fittings: bare walls (0: "
                                 "none)", min=0.0, max=10000.0)
    stop_wait_s: float = param(0.0, "the vehicle brakes to a stop at the tunnel's middle and waits this long before "
                               "driving on (0: no stop)", min=0.0, max=600.0)

    written_when_set = (*CommonParams.written_when_set, "bare_length_m", "stop_wait_s")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.curve_radius_m and self.curve_radius_m < 100.0:
            raise ParamError("is too tight: a road tunnel curve needs a radius >= 100 m (or 0)", "curve_radius_m")
        if self.curve_radius_m and self.length_m / self.curve_radius_m > np.pi / 2:
            raise ParamError(f"is too tight: a {self.length_m:g} m tunnel on a {self.curve_radius_m:g} m radius "
                             f"turns more than 90 degrees (gently curved: radius >= length_m / (pi / 2))",
                             "curve_radius_m")
        if self.lane_offset_m > self.width_m / 2 - self.walkway_width_m - 1.2:
            raise ParamError(f"is {self.lane_offset_m} m: that puts the vehicle on the walkway", "lane_offset_m")
        if self.bare_length_m > self.length_m:
            raise ParamError(f"is longer than the tunnel ({self.bare_length_m:g} > length_m {self.length_m:g})",
                             "bare_length_m")
        if self.overburden_m < self.height_m + 1.0:
            raise ParamError("must exceed height_m + 1 (the hill covers the bore)", "overburden_m")
        if self.cross_section == "arch" and self.height_m < self.width_m / 2 + 1.0:
            raise ParamError("is too low: an arch needs height_m >= width_m / 2 + 1", "height_m")


def alignment(length_total: float, start_curve: float, curve_len: float, radius: float,
              grade: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre-line samples: (n,) arc length, (n, 3) points, (n,) heading, rad.

    Straight, then a left curve of ``radius`` (0: none) over ``curve_len`` m
    from ``start_curve``, then straight; z rises at ``grade``. Sample i is at
    exactly ``i * step`` m (the last within ``step / 2`` of ``length_total``): the
    helpers below find a place's sample as ``round(s / step)``.
    """
    n = int(round(length_total / step)) + 1
    s = step * np.arange(n)
    curv = 1.0 / radius if radius > 0 else 0.0
    heading = np.clip(s - start_curve, 0.0, curve_len) * curv
    mid_heading = 0.5 * (heading[1:] + heading[:-1])
    ds = np.diff(s)
    xy = np.vstack([[0.0, 0.0], np.cumsum(np.stack([np.cos(mid_heading), np.sin(mid_heading)], 1)
                                          * ds[:, None], axis=0)])
    return s, np.column_stack([xy, grade * s]), heading


@dataclass(frozen=True)
class Bore:
    """A road tunnel's bore: cross-section, walkways, cover and fittings.

    What a scene with a tunnel in it shares with this one (the canyon's street runs
    into one). The tunnel's ``Params`` has the same fields, so the functions below
    take either. Lengths in metres.
    """

    width_m: float
    height_m: float
    cross_section: str = "arch"
    walkway_width_m: float = 1.0
    overburden_m: float = 25.0
    feature_spacing_m: float = 80.0


def bore_outline(p: Bore | Params) -> np.ndarray:
    """(k, 2) the lining's cross-section (lateral l, height h), from the left wall's foot
    over the roof to the right wall's foot (so the swept lining faces the axis)."""
    half = p.width_m / 2
    if p.cross_section == "box":
        return np.array([[half, 0.0], [half, p.height_m], [-half, p.height_m], [-half, 0.0]])
    wall_top = p.height_m - half
    phi = np.linspace(0.0, np.pi, 25)
    arch = np.column_stack([half * np.cos(phi), wall_top + half * np.sin(phi)])
    return np.vstack([[[half, 0.0]], arch, [[-half, 0.0]]])


def slice_rows(a: float, b: float) -> np.ndarray:
    """Indices of alignment samples (``STEP_M`` apart from s = 0) spanning [a, b] m every ``SLICE_M``."""
    k = int(round(SLICE_M / STEP_M))
    i0, i1 = int(round(a / STEP_M)), int(round(b / STEP_M))
    return np.unique(np.concatenate([np.arange(i0, i1, k), [i1]]))


def section(idx: np.ndarray, lv: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(len(idx), len(lv), 2) sweep profile: lateral offsets ``lv`` (k,) with ``heights`` (n, k), m."""
    return np.stack([np.broadcast_to(lv, (len(idx), len(lv))), heights], -1)


def land_laterals(p: Bore | Params, w_land: float = 150.0) -> np.ndarray:
    """(16,) lateral offsets of the land beside an open road as wide as the bore, one side, m:
    from the road's edge (half the bore's width + 0.5 m) out to ``w_land``, denser near the road."""
    return np.geomspace(p.width_m / 2 + 0.5, w_land, 16)


def add_open_road(mb: MeshBuilder, centre: np.ndarray, left: np.ndarray, idx: np.ndarray, lat_side: np.ndarray,
                  land_height, road_obj: int, land_obj: int) -> None:
    """A road out to ``lat_side[0]`` each side and the land beyond it, over the samples ``idx``.

    centre: (n, 3) centre-line; left: (n, 3) unit left vectors; lat_side: (k,) land laterals
    (``land_laterals``); land_height: (idx, lv) -> (len(idx), len(lv)) height above the road, m.
    """
    edge = lat_side[0]
    mb.add(*g.sweep(centre[idx], left[idx], np.array([[-edge, 0.0], [edge, 0.0]])), road_obj)
    for side in (-lat_side[::-1], lat_side):
        mb.add(*g.sweep(centre[idx], left[idx], section(idx, side, land_height(idx, side))), land_obj)


def add_bore(mb: MeshBuilder, p: Bore | Params, s: np.ndarray, centre: np.ndarray, left: np.ndarray,
             heading: np.ndarray, s_in: float, s_out: float, lat_side: np.ndarray, land_height,
             road_obj: int) -> None:
    """The tunnel from ``s_in`` to ``s_out`` m: the hill over it, the portals' cliff faces, the
    lining, the road inside and the raised walkways (fittings: ``add_fittings``).

    s: (n,) arc length of the alignment samples (``STEP_M`` apart from 0), centre: (n, 3),
    left: (n, 3), heading: (n,) rad; lat_side and land_height as for ``add_open_road`` (the
    land around the portals, which the hill rises from and the cliff faces meet).
    """
    half = p.width_m / 2
    road_half = half - p.walkway_width_m
    edge = lat_side[0]
    # The portals as built: the samples nearest s_in and s_out, where the lining starts and
    # ends and the cliff faces stand. The hill covers every ring of the lining, whichever
    # side of s_in / s_out (up to STEP_M / 2 away) the end rings fall on.
    idx = slice_rows(s_in, s_out)
    s_a, s_b = s[idx[0]], s[idx[-1]]

    def hill_height(idx, lv):
        return np.maximum(land_height(idx, lv), _hill(s[idx], lv, p, s_a, s_b))

    # The hill over the bore, and the cliff faces at the portals (between the land's and
    # the bore's outline below, and the hill's section above).
    hill_lat = np.concatenate([-lat_side[::-1], np.linspace(-edge, edge, 5)[1:-1], lat_side])
    hill_prof = section(idx, hill_lat, hill_height(idx, hill_lat))
    mb.add(*g.sweep(centre[idx], left[idx], hill_prof), mb.new_object("ground"))
    outline = bore_outline(p)
    face_obj = mb.new_object("wall")
    up = np.array([0.0, 0.0, 1.0])
    for row, end, toward in ((0, idx[0], -1.0), (-1, idx[-1], 1.0)):
        one = np.array([end])
        lower = np.vstack([
            section(one, -lat_side[::-1], land_height(one, -lat_side[::-1]))[0],
            outline[::-1],  # right foot, over the roof, left foot
            section(one, lat_side, land_height(one, lat_side))[0],
        ])
        faces = g.stitch_chains(lower, hill_prof[row], np.array([0.0, -5.0]))
        pts2 = np.vstack([lower, hill_prof[row]])
        v = centre[end] + pts2[:, :1] * left[end] + pts2[:, 1:2] * up
        fwd = np.array([np.cos(heading[end]), np.sin(heading[end]), 0.0])
        mb.add(v, _orient(v, faces, toward * fwd), face_obj)

    # The bore: lining, road, walkways.
    lining_obj = mb.new_object("wall")
    mb.add(*g.sweep(centre[idx], left[idx], outline), lining_obj)
    mb.add(*g.sweep(centre[idx], left[idx], np.array([[-road_half, 0.0], [road_half, 0.0]])), road_obj)
    if p.walkway_width_m > 0:
        walk_obj = mb.new_object("sidewalk")
        wh = 0.25
        right = np.array([[-half, wh], [-road_half, wh], [-road_half, 0.0]])
        leftw = np.array([[road_half, 0.0], [road_half, wh], [half, wh]])
        for prof in (right, leftw):
            mb.add(*g.sweep(centre[idx], left[idx], prof), walk_obj)
            for end, toward in ((idx[0], -1.0), (idx[-1], 1.0)):  # end caps at the portals
                lo, hi = prof[:, 0].min(), prof[:, 0].max()
                quad = np.array([[lo, 0.0], [hi, 0.0], [hi, wh], [lo, wh]])
                v = centre[end] + quad[:, :1] * left[end] + quad[:, 1:2] * np.array([0.0, 0.0, 1.0])
                fwd = np.array([np.cos(heading[end]), np.sin(heading[end]), 0.0])
                mb.add(v, _orient(v, np.array([[0, 1, 2], [0, 2, 3]]), toward * fwd), walk_obj)


def build(p: Params, name: str = "tunnel") -> Scene:
    rng = np.random.default_rng([p.seed, 0x7E1])
    total = 2 * p.approach_m + p.length_m
    s_in, s_out = p.approach_m, p.approach_m + p.length_m
    s, centre, heading = alignment(total, s_in, p.length_m, p.curve_radius_m, p.grade_pct / 100, STEP_M)
    left = np.column_stack([-np.sin(heading), np.cos(heading), np.zeros_like(heading)])
    mb = MeshBuilder()
    ground_noise = g.SmoothField(rng, 0.4, (60.0, 250.0))
    lat_side = land_laterals(p)  # land beside the road, one side
    edge = lat_side[0]  # the approach road's edge

    def land_height(idx, lv):
        """(len(idx), len(lv)) land height above the road level: a shallow ditch, then rolling land."""
        xy = centre[idx, None, :2] + lv[None, :, None] * left[idx, None, :2]
        off_road = np.clip((np.abs(lv) - edge - 2.0) / 10.0, 0.0, 1.0)
        ditch = np.clip((np.abs(lv) - edge) / 0.5, 0.0, 1.0) * 0.3
        return ground_noise(xy[..., 0], xy[..., 1]) * off_road[None, :] - ditch[None, :]

    # Approach roads and the land beside them, then the tunnel.
    road_obj = mb.new_object("road")
    land_obj = mb.new_object("ground")
    for a, b in ((0.0, s_in), (s_out, total)):
        add_open_road(mb, centre, left, slice_rows(a, b), lat_side, land_height, road_obj, land_obj)
    add_bore(mb, p, s, centre, left, heading, s_in, s_out, lat_side, land_height, road_obj)

    mid = (s_in + s_out) / 2
    bare = (mid - p.bare_length_m / 2, mid + p.bare_length_m / 2) if p.bare_length_m > 0 else None
    n_features = add_fittings(mb, p, centre, left, heading, s_in, s_out, bare)
    _approach_furniture(mb, p, s, centre, left, heading, s_in, s_out, lat_side, land_height)

    # The path: the right lane, offset from the centre-line.
    lane = centre[:, :2] - p.lane_offset_m * left[:, :2]
    lane = paths.smooth(lane, 1.0, STEP_M, closed=False)
    path = np.column_stack([lane, centre[:, 2]])
    s_path = paths.arc_length(path[:, :2])
    i_in, i_out = int(round(s_in / STEP_M)), int(round(s_out / STEP_M))
    i_mid = (i_in + i_out) // 2
    stop_s = float(s_path[i_mid]) if p.stop_wait_s > 0 else None
    traj = PathTrajectory(
        path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed,
        accel_smoothing_s=p.accel_smoothing_s, stops=() if stop_s is None else ((stop_s, p.stop_wait_s),),
    )
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    roads = two_way_road(p.lane_offset_m, p.width_m / 2 - p.walkway_width_m, False, cyclists=False)
    return Scene(
        name, v, f, ids, labels, path, traj, p.to_dict(), roads=roads, metadata=
        {
            "portal_s": [float(s_path[i_in]), float(s_path[i_out])],
            "interior_s": [float(s_path[i_in]), float(s_path[i_out])],
            "axis_xy": [float(np.cos(heading[i_mid])), float(np.sin(heading[i_mid]))],
            "path_length_m": float(s_path[-1]),
            "fittings": n_features,
            # only when set: a tunnel's metadata stays as it was
            **({} if bare is None else {"bare_s": [float(s_path[int(round(b / STEP_M))]) for b in bare]}),
            **({} if stop_s is None else {"stop_s": stop_s}),
        },
    )


def _orient(v: np.ndarray, faces: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Flip ``faces`` if their summed normal points against ``direction`` (3,)."""
    tri = v[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).sum(axis=0)
    return faces if n @ direction >= 0 else faces[:, ::-1].copy()


def _hill(s: np.ndarray, lv: np.ndarray, p: Bore | Params, s_in: float, s_out: float) -> np.ndarray:
    """(len(s), len(lv)) height of the hill above the road level; -inf off the hill.

    At each portal a headwall 2 m above the bore's crown with steep cut slopes
    beside it; over 60 m the crest rises to ``overburden_m`` and the flanks widen
    to 90 m, a hill the bore runs under.
    """
    ramp = np.clip(np.minimum(s - s_in, s_out - s) / 60.0, 0.0, 1.0)
    smooth = 3 * ramp**2 - 2 * ramp**3
    crest = p.height_m + 2.0 + (p.overburden_m - p.height_m - 2.0) * smooth
    flank = 15.0 + 75.0 * smooth  # width of the hill's side slope, m
    inside = (s >= s_in - 1e-6) & (s <= s_out + 1e-6)
    core = p.width_m / 2 + 4.0
    t = np.clip((np.abs(lv)[None, :] - core) / flank[:, None], 0.0, 1.0)
    h = crest[:, None] * 0.5 * (1 + np.cos(np.pi * t))  # full over the bore, 0 beyond the flank
    return np.where(inside[:, None], h, -np.inf)


def add_fittings(mb: MeshBuilder, p: Bore | Params, centre: np.ndarray, left: np.ndarray, heading: np.ndarray,
                 s_in: float, s_out: float, bare: tuple[float, float] | None = None) -> int:
    """Lights, emergency cabinets with signs, and jet fans along the bore every
    ``feature_spacing_m``, none between ``bare``'s ends (alignment arc length, m); returns how
    many sets (arrays as for ``add_bore``)."""
    if p.feature_spacing_m <= 0:
        return 0
    half = p.width_m / 2
    up = np.array([0.0, 0.0, 1.0])
    wall_h = p.height_m if p.cross_section == "box" else p.height_m - half
    count = 0
    for k, sf in enumerate(np.arange(s_in + p.feature_spacing_m / 2, s_out - 5.0, p.feature_spacing_m)):
        if bare is not None and bare[0] <= sf <= bare[1]:
            continue  # the same fittings elsewhere as without a bare stretch
        i = int(round(sf / STEP_M))
        c, lv, yaw = centre[i], left[i], heading[i]
        light_h = min(wall_h - 0.3, 4.5)
        for side in (-1.0, 1.0):
            q = c + side * (half - 0.1) * lv + light_h * up
            mb.add_object(*g.box((1.2, 0.12, 0.15), q, yaw), "light")
        # An emergency cabinet, nearly flush with the wall, and its sign; alternate walls.
        side = 1.0 if k % 2 else -1.0
        q = c + side * (half - 0.06) * lv
        mb.add_object(*g.box((1.5, 0.12, 2.0), q + 1.25 * up, yaw), "object")
        mb.add_object(*g.box((0.8, 0.05, 0.5), q + 2.8 * up - side * 0.05 * lv, yaw), "sign")
        fan_lat, fan_r = 2.2, 0.6
        edge = fan_lat + fan_r
        roof = p.height_m if p.cross_section == "box" else wall_h + np.sqrt(max(half**2 - edge**2, 0.0))
        fan_h = roof - 0.2 - fan_r
        # a pair of jet fans hung 0.2 m under the roof, where they clear a 4.5 m vehicle envelope
        if k % 4 == 1 and fan_h - fan_r >= FAN_CLEARANCE_M and edge < half:
            for lat in (-fan_lat, fan_lat):
                fan = g.cylinder(fan_r, 4.0, sections=12)
                v = fan[0] - np.array([0.0, 0.0, 2.0])
                v = np.stack([v[:, 2], v[:, 1], -v[:, 0]], axis=1)  # axis along x
                mb.add_object(*g.place((v, fan[1]), yaw, c + lat * lv + fan_h * up), "object")
        count += 1
    return count


def land_surface_height(lat_side: np.ndarray, land_height, i: int, lat: float) -> float:
    """Height above the road level of the land beside an open road as ``add_open_road`` meshes
    it (linear between the laterals ``lat_side``, not ``land_height`` itself: its ditch is
    narrower than their spacing) at sample ``i``, ``lat`` m left of the centre-line (negative:
    right), beyond the road's edge; exact on the mesh's rows (every ``SLICE_M``), within
    millimetres between them (the land varies slowly along the road)."""
    side = np.copysign(lat_side, lat)
    return float(np.interp(abs(lat), lat_side, land_height(np.array([i]), side)[0]))


POST_FOOT_M = 0.2  # posts beside the road stand this deep in the land


def _approach_furniture(mb, p, s, centre, left, heading, s_in, s_out, lat_side, land_height) -> None:
    """Signs announcing the tunnel and a few lamp posts on the approaches, in the land beyond
    the ditch: their posts reach ``POST_FOOT_M`` into it, plates and lamps at their heights
    above the road."""
    half = p.width_m / 2
    for s_sign, toward in ((s_in - 40.0, 1.0), (s_out + 40.0, -1.0)):
        i = int(round(np.clip(s_sign, 0, s[-1]) / STEP_M))
        for side in (-1.0, 1.0):
            lat = side * (half + 2.0)
            foot = land_surface_height(lat_side, land_height, i, lat) - POST_FOOT_M
            q = centre[i] + lat * left[i] + foot * np.array([0.0, 0.0, 1.0])
            post, plate = props.sign(2.8 - foot, (0.05, 1.2, 0.9))
            yaw = heading[i] + (np.pi if toward > 0 else 0.0)
            mb.add_object(*g.place(post, yaw, q), "pole")
            mb.add_object(*g.place(plate, yaw, q), "sign")
    for a, b in ((0.0, s_in - 10.0), (s_out + 10.0, s[-1] - 5.0)):  # not at the world's end
        for sl in np.arange(a + 10.0, b, 30.0):
            i = int(round(sl / STEP_M))
            lat = half + 1.5
            foot = land_surface_height(lat_side, land_height, i, lat) - POST_FOOT_M
            q = centre[i] + lat * left[i] + foot * np.array([0.0, 0.0, 1.0])
            mb.add_object(*g.place(props.street_light(8.0 - foot, 2.0), heading[i] - np.pi / 2, q), "pole")
