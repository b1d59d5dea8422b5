"""Traffic jam: everything creeps, the ego among it, stopping and starting in its lane.

A three-lane highway, both carriageways jammed. The ego is one of a column in the middle
lane that stops, creeps forward at walking pace and stops again; the vehicles ahead and
behind it in its lane follow the same stop-and-go a second or so apart (so the gaps
open and close as they would); the other lanes, and the other carriageway, crawl to
stop-and-go rhythms of their own. Nearly everything in view moves about as slowly as
the ego, and often when the ego does not: a scan-to-scan match can lock onto the wrong
movers.

Metadata: ``ego_start_s`` (where the ego starts along the road, m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import highway
from .actors import Actor, LanePath, OffsetProfile, SpeedProfile, models
from .params import param
from .scripted import ProfiledTrajectory, place
from .traffic import Lane, RoadLayout, stop_and_go

DESCRIPTION = "stress: a jam on a three-lane highway where everything creeps, the ego stopping and starting in it"

EGO_START_M = 150.0
COLUMN = ("car-saloon", "car-hatchback", "van", "car-suv", "lorry-rigid", "car-saloon", "bus", "car-hatchback",
          "car-suv", "van", "car-saloon", "lorry-long", "car-hatchback", "car-saloon")


@dataclass(frozen=True)
class Params(highway.Params):
    length_m: float = param(700.0, "length of the road", min=400.0, max=5000.0)
    lanes: int = param(3, "lanes per direction", min=2, max=4)
    lane: int = param(2, "lane the ego creeps in, counted from the right (1 = rightmost)", min=1, max=4)
    min_curve_radius_m: float = param(1500.0, "smallest curve radius", min=250.0, max=1e6)
    creep_m_s: float = param(2.5, "the fastest the jam creeps", min=0.5, max=8.0)
    duration_s: float = param(45.0, "how long the ego's jam lasts", min=10.0, max=300.0)
    moving: bool = param(True, "the jammed vehicles around the ego (false: the static twin, the same ego motion with "
                         "nothing else moving)")
    vehicles_ahead: int = param(6, "vehicles ahead of the ego in its lane", min=0, max=12)
    vehicles_behind: int = param(4, "vehicles behind the ego in its lane", min=0, max=12)
    lane_vehicles: int = param(14, "vehicles in each other lane's column", min=0, max=14)


def build(p: Params):
    scene = highway.build(p)
    rng = np.random.default_rng([p.seed, 0x3A7])
    ego = stop_and_go(rng, 0.0, p.duration_s + 5.0, creep_m_s=(0.6, p.creep_m_s), stop_s=(2.0, 6.0),
                      move_s=(2.0, 5.0), s0=EGO_START_M)
    scene.trajectory = ProfiledTrajectory(scene.path, ego, p.duration_s, p.mount_height_m)
    scene.metadata["ego_start_s"] = EGO_START_M
    scene.name = "traffic_jam"
    scene.params = p.to_dict()
    if not p.moving:
        scene.actors = place(scene, [], p.seed, p.traffic)
        return scene
    roads: RoadLayout = scene.roads
    actors = _own_lane(p, rng, scene, ego)
    for ln in roads.lanes:
        if ln.offset_m == 0.0:
            continue
        actors += _column(p, rng, scene, ln)
    scene.actors = place(scene, actors, p.seed, p.traffic)
    return scene


def _lane(scene, ln: Lane) -> LanePath:
    lane = LanePath(scene.roads.line(scene.path, ln.offset_m), False)
    return lane if ln.direction > 0 else lane.reversed()


def _own_lane(p: Params, rng, scene, ego: SpeedProfile) -> list[Actor]:
    """The ego's column: the ego's profile, each vehicle a headway of time and a car length of road apart."""
    lane = LanePath(scene.path, False)
    out = []
    ego_half = 2.35
    for side, count in ((1, p.vehicles_ahead), (-1, p.vehicles_behind)):
        gap_s, lag, prev_half = 0.0, 0.0, ego_half
        for _ in range(count):
            m = models()[COLUMN[int(rng.integers(len(COLUMN)))]]
            gap_s += prev_half + m.length_m / 2 + rng.uniform(2.5, 4.0)
            lag += rng.uniform(0.8, 1.5)
            prev_half = m.length_m / 2
            profile = ego.shifted(-side * lag, side * gap_s)
            out.append(Actor(m, lane, profile, OffsetProfile(), "queue", (-1e9, 1e9)))
    return out


def _column(p: Params, rng, scene, ln: Lane) -> list[Actor]:
    """Another lane's column on a stop-and-go rhythm of its own, over the stretch the ego's view covers."""
    lane = _lane(scene, ln)
    ego_s = EGO_START_M if ln.direction > 0 else lane.length_m - EGO_START_M
    lead = stop_and_go(rng, -10.0, p.duration_s + 10.0, creep_m_s=(0.6, p.creep_m_s), s0=0.0)
    # the column's front starts some 80 m beyond the ego's start (the way this lane goes)
    front = ego_s + rng.uniform(60.0, 100.0) - (lead.distance(np.array([0.0]))[0])
    out, back, lag = [], 0.0, 0.0
    for _ in range(p.lane_vehicles):
        m = models()[COLUMN[int(rng.integers(len(COLUMN)))]]
        back += m.length_m / 2
        profile = lead.shifted(lag, front - back)
        out.append(Actor(m, lane, profile, OffsetProfile(), "queue", (-1e9, 1e9)))
        back += m.length_m / 2 + rng.uniform(2.5, 4.5)
        lag += rng.uniform(0.8, 1.5)
    return out
