"""Highway: a long divided multi-lane road through open land; feature-poor.

Two carriageways of ``lanes`` lanes each, separated by a concrete median
barrier, with hard shoulders and guard rails (posts every 4 m and a beam) on
both outer edges. The alignment has gentle curves (radius at least
``min_curve_radius_m``, smooth transitions) and grades; the land beside it
blends from embankments and cuttings into rolling terrain with a few groups
of trees. Signs stand beyond the rails every ``sign_spacing_m``, gantries
span the road every ``gantry_spacing_m``. The vehicle drives in lane
``lane`` of the right-hand carriageway (1 = the rightmost lane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import alignment as al
from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .traffic import Lane, RoadLayout
from .trajectory import PathTrajectory

DESCRIPTION = "divided multi-lane highway with guard rails, sparse signs and gantries, open land"

STEP_M = 0.5
SLICE_M = 4.0
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(25.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    lateral_accel_m_s2: float = param(
        1.5, "lateral acceleration allowed in turns (slows the vehicle in curves)", min=0.1, max=10.0
    )
    length_m: float = param(1500.0, "length of the road", min=200.0, max=20000.0)
    lanes: int = param(3, "lanes per direction", min=1, max=6)
    lane_width_m: float = param(3.5, "lane width", min=2.5, max=5.0)
    shoulder_m: float = param(2.5, "hard shoulder outside the lanes", min=0.0, max=5.0)
    median_m: float = param(3.0, "median width between the carriageways (barrier in its middle)",
                            min=1.0, max=30.0)
    lane: int = param(2, "lane the vehicle drives in, counted from the right (1 = rightmost)", min=1, max=6)
    min_curve_radius_m: float = param(1000.0, "smallest curve radius", min=250.0, max=1e6)
    max_grade_pct: float = param(2.0, "steepest grade", min=0.0, max=8.0)
    sign_spacing_m: float = param(400.0, "spacing of roadside signs (0: none)", min=0.0, max=20000.0)
    gantry_spacing_m: float = param(700.0, "spacing of sign gantries over the road (0: none)",
                                    min=0.0, max=20000.0)
    land_roughness_m: float = param(3.0, "standard deviation of the land's relief", min=0.0, max=30.0)
    tree_groups: int = param(25, "groups of trees scattered in the land", min=0, max=1000)
    rail_post_spacing_m: float = param(4.0, "spacing of the guard rails' posts (0: a bare beam)", min=0.0, max=100.0)
    written_when_set = (*CommonParams.written_when_set, "rail_post_spacing_m")  # added with the stress scenes

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.lane > self.lanes:
            raise ParamError(f"is {self.lane} but the road has {self.lanes} lanes", "lane")


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0x41C4])
    s = np.arange(0.0, p.length_m + STEP_M / 2, STEP_M)
    kappa = al.random_curves(rng, s, p.min_curve_radius_m, 350.0, 120.0)
    z = al.random_grades(rng, s, p.max_grade_pct / 100)
    road = al.integrate(s, kappa, z)
    left = road.left
    terrain = g.SmoothField(rng, p.land_roughness_m, (150.0, 600.0))
    mb = MeshBuilder()

    half_med = p.median_m / 2
    edge = half_med + p.lanes * p.lane_width_m + p.shoulder_m  # road edge from the centre-line
    k = int(round(SLICE_M / STEP_M))
    idx = np.unique(np.concatenate([np.arange(0, len(s), k), [len(s) - 1]]))
    c, lv = road.xyz[idx], left[idx]

    # Road surface, flat across.
    mb.add_object(*g.sweep(c, lv, np.array([[-edge - 1.0, 0.0], [edge + 1.0, 0.0]])), "road")
    # Land: a verge and ditch, then embankment or cutting blending into the terrain.
    d = np.concatenate([[1.0, 2.5, 4.0], 4.0 + np.geomspace(1.0, 220.0, 22)])
    land_obj = mb.new_object("ground")
    for side in (-1.0, 1.0):
        lat = side * (edge + d)
        xy = c[:, None, :2] + lat[None, :, None] * lv[:, None, :2]
        blend = np.clip((d - 4.0) / 35.0, 0.0, 1.0)
        blend = blend * blend * (3 - 2 * blend)
        ditch = np.where((d > 1.5) & (d < 4.5), -0.6, 0.0)
        rel = (terrain(xy[..., 0], xy[..., 1]) - c[:, None, 2]) * blend[None, :] + ditch[None, :]
        rel[:, 0] = 0.0  # meets the road's edge
        prof = np.stack([np.broadcast_to(lat, rel.shape), rel], -1)
        if side < 0:
            prof = prof[:, ::-1]  # run the profile right to left so the land faces up
        mb.add(*g.sweep(c, lv, prof), land_obj)

    # Median barrier (a concrete safety-shape profile) and guard rails with posts.
    # Profiles run from the right foot up, over and down the left side: faces outward.
    jersey = np.array([[-0.3, 0.0], [-0.25, 0.08], [-0.12, 0.33], [-0.075, 0.81],
                       [0.075, 0.81], [0.12, 0.33], [0.25, 0.08], [0.3, 0.0]])
    mb.add_object(*g.sweep(c, lv, jersey), "wall")
    beam = np.array([[-0.05, 0.55], [-0.05, 0.85], [0.05, 0.85], [0.05, 0.55]])
    for side in (-1.0, 1.0):
        rail = mb.new_object("rail")
        off = side * (edge + 0.4)
        mb.add(*g.sweep(c, lv, beam + [off, 0.0], closed=True), rail)
        for i in range(0, len(s), int(round(p.rail_post_spacing_m / STEP_M)) or len(s) + 1):
            q = road.xyz[i] + (off + side * 0.12) * left[i]
            mb.add(*g.box((0.12, 0.1, 0.9), q + 0.45 * UP, road.heading[i]), rail)

    n_signs = n_gantries = 0
    if p.sign_spacing_m > 0:
        for sd in np.arange(p.sign_spacing_m / 2, p.length_m - 20.0, p.sign_spacing_m):
            for side, facing in ((-1.0, np.pi), (1.0, 0.0)):  # each carriageway's own signs
                i = road.index(sd + (0.0 if side < 0 else p.sign_spacing_m / 4))
                q = road.xyz[i] + side * (edge + 3.0) * left[i]
                _roadside_sign(mb, q, road.heading[i] + facing, left[i])
                n_signs += 1
    if p.gantry_spacing_m > 0:
        for sd in np.arange(p.gantry_spacing_m * 0.6, p.length_m - 50.0, p.gantry_spacing_m):
            i = road.index(sd)
            _gantry(mb, road.xyz[i], road.heading[i], left[i], edge, half_med)
            n_gantries += 1
    _tree_groups(mb, p, rng, road, edge, terrain)

    lane_l = -(half_med + (p.lanes - p.lane + 0.5) * p.lane_width_m)
    lane_xy = paths.smooth(road.xyz[:, :2] + lane_l * left[:, :2], 1.0, STEP_M, closed=False)
    path = np.column_stack([lane_xy, road.xyz[:, 2]])
    traj = PathTrajectory(
        path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    w = p.lane_width_m  # the lanes of both carriageways, as offsets from the ego's
    lanes = tuple(Lane((j - p.lane) * w, 1) for j in range(1, p.lanes + 1)) + tuple(
        Lane(half_med + (p.lanes - j + 0.5) * w - lane_l, -1) for j in range(1, p.lanes + 1))
    return Scene(
        "highway", v, f, ids, labels, path, traj, p.to_dict(), roads=RoadLayout(lanes, False), metadata=
        {
            "path_length_m": traj.length_m,
            "road_half_width_m": edge,
            "min_radius_m": float(1.0 / max(np.abs(kappa).max(), 1e-9)),
            "signs": n_signs,
            "gantries": n_gantries,
        },
    )


def _roadside_sign(mb, q, yaw, left) -> None:
    """A 3 m x 2 m direction sign on two posts, its face turned by ``yaw``."""
    fwd = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    side = np.array([-fwd[1], fwd[0], 0.0])
    for o in (-1.1, 1.1):
        mb.add_object(*g.cylinder(0.06, 4.0, q + o * side, sections=8), "pole")
    mb.add_object(*g.box((0.06, 3.0, 2.0), q + 0.1 * fwd + 3.0 * UP, yaw), "sign")


def _gantry(mb, q, heading, left, edge, half_med) -> None:
    """Columns beyond both rails, a truss beam across at 6.6 m, a sign over each carriageway."""
    span = 2 * (edge + 1.5)
    for side in (-1.0, 1.0):
        mb.add_object(*g.box((0.6, 0.6, 8.2), q + side * (edge + 1.5) * left + 4.1 * UP, heading), "pole")
    mb.add_object(*g.box((1.0, span, 1.0), q + 7.1 * UP, heading), "pole")
    fwd = np.array([np.cos(heading), np.sin(heading), 0.0])
    centre_l = half_med + (edge - half_med) / 2
    for side, facing in ((-1.0, -1.0), (1.0, 1.0)):
        plate_c = q + side * centre_l * left + facing * 0.6 * fwd + 7.3 * UP
        mb.add_object(*g.box((0.1, 4.5, 2.2), plate_c, heading), "sign")


def _tree_groups(mb, p, rng, road, edge, terrain) -> None:
    """Clumps of 3-12 trees 45-180 m from the road edge, where the land is the terrain."""
    for _ in range(p.tree_groups):
        i = int(rng.integers(len(road.s)))
        side = rng.choice([-1.0, 1.0])
        centre = road.xyz[i, :2] + side * (edge + rng.uniform(45.0, 180.0)) * road.left[i, :2]
        for _ in range(int(rng.integers(3, 13))):
            q = centre + rng.normal(0.0, 6.0, 2)
            dist = np.min(np.linalg.norm(road.xyz[:, :2] - q, axis=1))
            if dist < edge + 40.0:
                continue
            z = float(terrain(q[:1], q[1:])[0])
            trunk, crown = props.tree(rng, rng.uniform(6.0, 14.0), rng.uniform(2.0, 4.0))
            obj = mb.new_object("vegetation")
            mb.add(*g.place(trunk, 0.0, (*q, z - 0.3)), obj)
            mb.add(*g.place(crown, 0.0, (*q, z - 0.3)), obj)
