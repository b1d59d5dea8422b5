"""Overtaking lorry: a long lorry passes the ego in the next lane, close enough to fill half the view.

A two-lane highway with narrow lanes. The ego holds its speed in the right lane; a 12 m,
4 m high lorry comes up from behind in the left lane, draws alongside (its side 2 m from
the lidar: half the horizon is lorry) and pulls ahead. Oncoming traffic flows on the
other carriageway. Whatever a method matches on the lorry moves with it: a scan whose
largest surface moves.

Metadata: ``alongside_s`` (when the lorry's middle passes the lidar, s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import highway
from .actors import Actor, LanePath, OffsetProfile, SpeedProfile, models
from .params import param
from .scripted import ProfiledTrajectory, place
from .traffic import lane_traffic

DESCRIPTION = "stress: a long lorry overtakes the ego close by in the next lane, filling half its view"

EGO_START_M = 60.0


@dataclass(frozen=True)
class Params(highway.Params):
    length_m: float = param(1500.0, "length of the road", min=800.0, max=5000.0)
    lanes: int = param(2, "lanes per direction", min=2, max=2)
    lane: int = param(1, "the ego's lane (the right one)", min=1, max=1)
    lane_width_m: float = param(3.3, "lane width", min=3.0, max=4.0)
    speed_m_s: float = param(22.0, "the ego's speed", min=5.0, max=35.0)
    lorry_gain_m: float = param(70.0, "how far the lorry gains on the ego, from behind it to ahead of it", min=30.0,
                                max=200.0)
    pass_s: float = param(14.0, "how long it takes to gain it", min=5.0, max=60.0)
    alongside_s: float = param(12.0, "when the lorry's middle passes the lidar", min=5.0, max=100.0)
    duration_s: float = param(30.0, "the ego's drive", min=15.0, max=200.0)
    moving: bool = param(True, "the lorry and the oncoming traffic (false: the static twin, the same ego motion with "
                         "nothing else moving)")
    oncoming_vehicles: int = param(10, "vehicles on the other carriageway", min=0, max=60)


def build(p: Params):
    scene = highway.build(p)
    v = p.speed_m_s
    ego = SpeedProfile([0.0, p.duration_s + 10.0], [v, v], EGO_START_M)  # at speed from the start
    scene.trajectory = ProfiledTrajectory(scene.path, ego, p.duration_s, p.mount_height_m)
    scene.metadata["alongside_s"] = p.alongside_s
    scene.name = "overtaking_lorry"
    scene.params = p.to_dict()
    if not p.moving:
        scene.actors = place(scene, [], p.seed, p.traffic)
        return scene
    rng = np.random.default_rng([p.seed, 0x0F7])
    lorry = models()["lorry-long"]
    lane = LanePath(scene.roads.line(scene.path, p.lane_width_m), False)
    # its gap to the lidar eases from -gain/2 to +gain/2, reaching 0 at alongside_s; its speed the ego's plus
    # the gap's rate (continuous acceleration)
    from .actors import OffsetProfile as Gap

    t_a = p.alongside_s - p.pass_s / 2
    gap = Gap([t_a, t_a + p.pass_s], [-p.lorry_gain_m / 2, p.lorry_gain_m / 2])
    t = np.arange(-10.0, p.duration_s + 10.0, 0.25)
    profile = SpeedProfile(t, v + gap.rate(t), EGO_START_M + v * t[0] + gap.value(t[:1])[0])
    actors = [Actor(lorry, lane, profile, OffsetProfile(), "overtaking", (-1e9, 1e9))]
    oncoming = [ln for ln in scene.roads.lanes if ln.direction < 0]
    for k, ln in enumerate(oncoming):
        path = LanePath(scene.roads.line(scene.path, ln.offset_m), False).reversed()
        names = ("car-saloon", "car-hatchback", "van", "lorry-rigid", "car-suv", "bus")
        ms = [models()[names[int(rng.integers(len(names)))]] for _ in range(p.oncoming_vehicles // len(oncoming))]
        runs = lane_traffic(path, [m.length_m for m in ms], np.full(len(ms), 24.0 + 3 * k), -60.0,
                            p.duration_s + 5.0, rng=rng)
        actors += [Actor(m, path, prof, OffsetProfile(), "oncoming", span) for m, (prof, span) in zip(ms, runs,
                                                                                                       strict=False)]
    scene.actors = place(scene, actors, p.seed, p.traffic)
    return scene
