"""Red light: the ego stops at a junction and waits while cross traffic and a queue in the next lane move.

A city of 20 m streets, two lanes each way. The ego drives east in the outer lane of a
street towards a junction, brakes to a stop at the stop line and stands still for
``wait_s`` (its true motion exactly zero), then drives on across the junction. While it
waits, cross traffic passes in front of it (a lorry, a bus, cars and a van, both ways,
in both lanes of the crossing street), a queue of vehicles in the lane beside it comes
up from behind, stops at the line and creeps forward as it closes up, and vehicles in the
oncoming lanes wait at their own line; all drive on when the light turns.
Stationary sensors that invent motion from what moves around them are what it tests.

Metadata: ``stop_s`` (distance along the path where the ego stands, m), ``wait_s``
(when it stands: [stop, go], s), ``junction_xy``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import city
from .actors import Actor, LanePath, OffsetProfile, SpeedProfile, models
from .params import param
from .scripted import ProfiledTrajectory, place, straight
from .traffic import Lane, RoadLayout, Signal, drive, lane_traffic

DESCRIPTION = ("stress: the ego waits at a red light while cross traffic and a queue in the next lane move "
               "(true motion zero)")

STREET_M = 20.0
LANE_OFFSET_M = 5.0  # the ego's lane, right of the street's centre; the next lane at 1.8 m
NEXT_LANE_M = 1.8
APPROACH_M = 100.0  # the ego's start, before the junction's centre
EXIT_M = 160.0  # the path beyond the junction's centre
EGO_HALF_M = 2.35


@dataclass(frozen=True)
class Params(city.Params):
    streets_x: int = param(3, "number of streets running along y (north-south)", min=3, max=12)
    streets_y: int = param(3, "number of streets running along x (east-west)", min=3, max=12)
    block_length_m: float = param(90.0, "block size along x, kerb to kerb", min=60.0, max=300.0)
    block_width_m: float = param(70.0, "block size along y, kerb to kerb", min=60.0, max=300.0)
    street_width_m: float = param(STREET_M, "road width kerb to kerb (four lanes and parking)", min=STREET_M,
                                  max=STREET_M)
    lane_offset_m: float = param(LANE_OFFSET_M, "the ego's lane, right of the street's centre-line",
                                 min=LANE_OFFSET_M, max=LANE_OFFSET_M)
    turn_radius_m: float = param(14.0, "radius of the (unused) loop route's turns", min=4.0, max=30.0)
    route_blocks: int = param(1, "blocks of the (unused) loop route", min=1, max=1)
    parked_car_fraction: float = param(0.35, "share of parking places holding a car", min=0.0, max=1.0)
    speed_m_s: float = param(9.0, "the ego's speed before and after the stop", min=2.0, max=15.0)
    wait_s: float = param(10.0, "how long the ego stands at the stop line", min=0.0, max=60.0)
    moving: bool = param(True, "the cross traffic, the queue and the oncoming vehicles (false: the static twin, the "
                         "same ego motion with nothing else moving)")
    cross_vehicles: int = param(7, "vehicles crossing in front of the waiting ego", min=0, max=20)
    queue_vehicles: int = param(6, "vehicles queueing in the lane beside the ego", min=0, max=12)


def ego_profile(p: Params, stop_s: float) -> tuple[SpeedProfile, float, float]:
    """(the ego's speed profile, when it stops, when it goes): up to speed, cruise, brake to a stop at
    ``stop_s``, wait, and on."""
    v, ramp, brake = p.speed_m_s, 4.0, 5.0
    cruise_s = stop_s - v * ramp / 2 - v * brake / 2
    if cruise_s < 0:
        raise ValueError(f"parameter speed_m_s: {v} m/s does not stop within {stop_s:.0f} m")
    t_cruise = ramp + cruise_s / v
    t_stop = t_cruise + brake
    t_go = t_stop + p.wait_s
    profile = SpeedProfile([0.0, ramp, t_cruise, t_stop, t_go + 1e-3, t_go + ramp],
                           [0.0, v, v, 0.0, 0.0, v]) if p.wait_s > 0 else SpeedProfile(
        [0.0, ramp, t_cruise, t_stop, t_stop + ramp], [0.0, v, v, 0.0, v])
    return profile, t_stop, t_go


def build(p: Params):
    scene = city.build(p)
    terrain_of = scene.roads.height
    # the junction: the middle street of each direction
    pitch_x, pitch_y = p.block_length_m + p.street_width_m, p.block_width_m + p.street_width_m
    jx, jy = pitch_x * ((p.streets_x - 1) // 2), pitch_y * ((p.streets_y - 1) // 2)
    half = p.street_width_m / 2
    y_lane = jy - LANE_OFFSET_M
    path = straight((jx - APPROACH_M, y_lane, 0.0), (jx + EXIT_M, y_lane, 0.0), terrain_of)
    stop_s = APPROACH_M - half - 3.0 - EGO_HALF_M  # the car's front 3 m before the crossing street's kerb line
    profile, t_stop, t_go = ego_profile(p, stop_s)
    duration = t_go + 4.0 + (EXIT_M + APPROACH_M - stop_s - p.speed_m_s * 2.0) / p.speed_m_s
    scene.path = path
    scene.trajectory = ProfiledTrajectory(path, profile, duration, p.mount_height_m, terrain_of)
    # the street's four lanes along the path (the next lane, the two oncoming), and its parking
    scene.roads = RoadLayout(
        lanes=(Lane(0.0, 1), Lane(LANE_OFFSET_M - NEXT_LANE_M, 1), Lane(LANE_OFFSET_M + NEXT_LANE_M, -1),
               Lane(2 * LANE_OFFSET_M, -1)), closed=False, height=terrain_of,
        parking=(LANE_OFFSET_M - (half - 1.1), LANE_OFFSET_M + (half - 1.1)))
    scene.metadata.update(stop_s=float(stop_s), wait_s=[float(t_stop), float(t_go)], junction_xy=[jx, jy])
    scene.name = "red_light"
    scene.params = p.to_dict()
    if not p.moving:
        scene.actors = place(scene, [], p.seed, p.traffic)
        return scene
    rng = np.random.default_rng([p.seed, 0x2ED])
    actors = _cross_traffic(p, rng, jx, jy, terrain_of, t_stop, t_go)
    actors += _queue_beside(p, rng, jx, y_lane, terrain_of, t_stop, t_go, duration)
    actors += _oncoming_waiting(p, rng, jx, jy, terrain_of, t_go, duration)
    scene.actors = place(scene, actors, p.seed, p.traffic)
    return scene


def _vehicle(name: str):
    return models()[name]


def _cross_traffic(p, rng, jx, jy, height, t_stop, t_go) -> list[Actor]:
    """Vehicles along the crossing street, both ways, each through the junction while the ego waits."""
    names = ["lorry-long", "bus", "car-saloon", "van", "car-hatchback", "car-suv", "car-saloon", "lorry-rigid",
             "car-hatchback", "van"]
    # along the crossing street as far as it goes each way, less 5 m (the junction is its middle one)
    pitch_y = p.block_width_m + p.street_width_m
    reach = 2 * pitch_y - p.street_width_m / 2 - 5.0
    out = []
    window = (t_stop + 1.0, t_go - 2.5)
    if window[1] <= window[0] or p.cross_vehicles == 0:
        return out
    gap = (window[1] - window[0]) / p.cross_vehicles  # evenly over the wait, so a lane's vehicles are 4 gaps apart
    passes = window[0] + (np.arange(p.cross_vehicles) + rng.uniform(0.3, 0.7, p.cross_vehicles)) * gap
    lane_speed = rng.uniform(8.0, 11.0, 4)  # one speed a lane: its vehicles stay the gaps apart they pass at
    for k, t_pass in enumerate(passes):
        north = k % 2 == 0
        offset = (NEXT_LANE_M if k % 4 < 2 else LANE_OFFSET_M) * (1 if north else -1)
        x = jx + offset
        a, b = (jy - reach, jy + reach) if north else (jy + reach, jy - reach)
        lane = LanePath(straight((x, a, 0.0), (x, b, 0.0), height), False)
        v = lane_speed[k % 4]
        model = _vehicle(names[k % len(names)])
        t_in = t_pass - reach / v
        profile = SpeedProfile([t_in], [v], 0.0)
        out.append(Actor(model, lane, profile, OffsetProfile(), "crossing", (t_in, t_in + 2 * reach / v)))
    return out


def _queue_beside(p, rng, jx, y_lane, height, t_stop, t_go, duration) -> list[Actor]:
    """A column in the next lane that comes up from behind, stops at the line, closes up and goes at green."""
    if p.queue_vehicles == 0:
        return []
    y = y_lane + (LANE_OFFSET_M - NEXT_LANE_M)
    start = jx - APPROACH_M - 60.0
    lane = LanePath(straight((start, y, 0.0), (jx + EXIT_M, y, 0.0), height), False)
    line = jx - p.street_width_m / 2 - 3.0 - start  # the stop line along this lane
    names = ["car-saloon", "van", "car-hatchback", "lorry-rigid", "car-suv", "car-saloon", "car-hatchback", "van",
             "car-suv", "bus", "car-saloon", "car-hatchback"][:p.queue_vehicles]
    ms = [_vehicle(n) for n in names]
    # they enter 60 m behind the ego's start, some 20 s before they reach the line: while the ego waits
    enter = t_stop - 22.0 + np.cumsum(rng.uniform(1.5, 2.5, len(ms)))
    runs = lane_traffic(lane, [m.length_m for m in ms], np.full(len(ms), 8.0), enter[0] - 1.0, duration + 5.0,
                        (Signal(float(line), ((-100.0, t_go),)),), rng=rng, enter_s=enter)
    return [Actor(m, lane, prof, OffsetProfile(), "queue", span) for m, (prof, span) in zip(ms, runs, strict=False)]


def _oncoming_waiting(p, rng, jx, jy, height, t_go, duration) -> list[Actor]:
    """Two vehicles in the oncoming lanes, waiting at their line on the junction's far side, that go at green."""
    out = []
    for k, (offset, name) in enumerate(((NEXT_LANE_M, "car-suv"), (LANE_OFFSET_M, "van"))):
        y = jy + offset
        start = jx + EXIT_M + 20.0
        lane = LanePath(straight((start, y, 0.0), (jx - APPROACH_M - 60.0, y, 0.0), height), False)
        model = _vehicle(name)
        s_wait = start - (jx + p.street_width_m / 2 + 3.0) - model.length_m / 2
        v = 8.0 + 0.5 * k
        go = drive(lane, s_wait, v, t_go + 0.5 + k, duration + 5.0, start_m_s=0.0)
        profile = SpeedProfile(np.concatenate([[-50.0], go.t]), np.concatenate([[0.0], go.v]), s_wait)
        end = go.t[np.searchsorted(profile.distance(go.t), lane.length_m)] if profile.distance(go.t[-1:])[0] > \
            lane.length_m else 1e9
        out.append(Actor(model, lane, profile, OffsetProfile(), "oncoming", (-1e9, float(end))))
    return out
