"""Lead vehicle: a van ahead of the ego at a constant gap, on an otherwise featureless road.

A straight, level highway, one lane each way, through flat land: no signs, no gantries,
no trees, guard rails without posts. The ego drives at a constant speed; a van drives
``gap_m`` ahead of it in its lane at exactly its speed. The van is the only thing in
view whose position along the road changes the scan; it moves with the ego, so a method
that trusts it sees the ego standing still.

Metadata: ``gap_m``.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import highway
from .actors import Actor, LanePath, OffsetProfile, SpeedProfile, models
from .params import param
from .scripted import ProfiledTrajectory, place

DESCRIPTION = "stress: a van ahead of the ego at a constant gap on a straight road with nothing else along it"

EGO_START_M = 40.0
EGO_LENGTH_M = 4.7


@dataclass(frozen=True)
class Params(highway.Params):
    length_m: float = param(1200.0, "length of the road", min=600.0, max=5000.0)
    lanes: int = param(1, "lanes per direction", min=1, max=1)
    lane: int = param(1, "the ego's lane", min=1, max=1)
    min_curve_radius_m: float = param(1e6, "smallest curve radius (straight)", min=250.0, max=1e6)
    max_grade_pct: float = param(0.0, "steepest grade", min=0.0, max=8.0)
    sign_spacing_m: float = param(0.0, "spacing of roadside signs (0: none)", min=0.0, max=20000.0)
    gantry_spacing_m: float = param(0.0, "spacing of sign gantries (0: none)", min=0.0, max=20000.0)
    land_roughness_m: float = param(0.0, "standard deviation of the land's relief", min=0.0, max=30.0)
    tree_groups: int = param(0, "groups of trees scattered in the land", min=0, max=1000)
    rail_post_spacing_m: float = param(0.0, "spacing of the guard rails' posts (0: a bare beam)", min=0.0, max=100.0)
    speed_m_s: float = param(15.0, "the ego's and the van's speed", min=2.0, max=35.0)
    gap_m: float = param(12.0, "the van's gap ahead of the ego, bumper to bumper", min=3.0, max=60.0)
    duration_s: float = param(30.0, "the ego's drive", min=10.0, max=200.0)
    moving: bool = param(True, "the van (false: the static twin, the same ego motion on the empty road)")


def build(p: Params):
    scene = highway.build(p)
    ego = SpeedProfile([0.0, p.duration_s + 10.0], [p.speed_m_s] * 2, EGO_START_M)
    scene.trajectory = ProfiledTrajectory(scene.path, ego, p.duration_s, p.mount_height_m)
    scene.metadata["gap_m"] = p.gap_m
    scene.name = "lead_vehicle"
    scene.params = p.to_dict()
    actors = []
    if p.moving:
        van = models()["van"]
        ahead = p.gap_m + (van.length_m + EGO_LENGTH_M) / 2
        lead = SpeedProfile(ego.t, ego.v, EGO_START_M + ahead)  # the ego's profile, the gap further on: exactly
        actors = [Actor(van, LanePath(scene.path, False), lead, OffsetProfile(), "lead", (-1e9, 1e9))]
    scene.actors = place(scene, actors, p.seed, p.traffic)
    return scene
