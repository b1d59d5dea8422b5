"""Traffic and people that move: a scene's actors, drawn from densities and behaviours (``traffic.*`` parameters).

A scene that has roads gives a ``RoadLayout`` (its lanes as offsets of the ego's path,
each with its direction; its parking places, cyclists' lines, pavements, crossing
streets and places to cross). ``populate`` fills it, seeded from the scene's seed, with
actors (``scenes.actors.Actor``) of ``TrafficParams``' densities per class, doing what
its ``behaviours`` allow:

- ``oncoming``, ``same_direction``: vehicles in the lanes against and with the ego's travel
  (its own lane excepted), cyclists near the kerbs; each lane's vehicles follow one
  driver's speed profile (cruise, slowing for bends), each some seconds behind the next;
- ``overtaking``: a vehicle comes up behind the ego, passes it in the next lane and pulls in
  ahead (on a two-lane road, in the oncoming lane);
- ``crossing``: vehicles on the streets that cross the route at its junctions;
- ``queue``: a column of vehicles in a neighbouring lane that stops and creeps forward;
- ``pull_out``: a vehicle parked at the kerb that pulls out into the lane and drives on;
- ``walking``, ``crossing_pedestrians``: pedestrians along the pavements, and across the road.

``traffic.lead`` adds a vehicle in the ego's lane ahead of it, its gap drifting around
``lead_gap_m`` (by ``lead_gap_variation_m``; 0: a constant gap).

Every actor is checked before it is kept (``Occupancy``): its box never comes within a
margin of the ego's or of an actor already kept, at any instant of the scene's
trajectory; it stands clear of the static world (``StaticClearance``: no part of a
parked car, pole or tree in its way); and it appears or vanishes (the ends of an open
road, a door) only where the ego is at least ``VANISH_FAR_M`` away (people: ``VANISH_FAR_PERSON_M``).
A candidate that fails is dropped, so the densities are upper bounds. The static
twin of a scene is the same scene with ``traffic.enabled`` false: the same mesh and
path, nothing moving.
"""

from __future__ import annotations

import logging
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from paramspec import Params, param

from . import paths
from .actors import KINDS, Actor, LanePath, OffsetProfile, SpeedProfile, models_of

log = logging.getLogger(__name__)

VANISH_FAR_M = 130.0  # a vehicle appears or vanishes only this far from the ego (beyond most sensors' reach)
VANISH_FAR_PERSON_M = 70.0  # a person (a door, a side street): they show as a few returns at this range
GRID_S = 0.1  # the time step of the conflict checks, s
EGO_SIZE_M = (4.7, 1.9)  # the ego vehicle's footprint, the lidar over its centre
MARGIN_M = {"vehicle": (0.8, 0.3), "person": (0.3, 0.3)}  # kept around a box (along, across), m
PRE_ROLL_S = 60.0  # the traffic has been moving this long before the ego starts (lanes filled)
BEHAVIOURS = ("oncoming", "same_direction", "overtaking", "crossing", "queue", "pull_out", "walking",
              "crossing_pedestrians")
VEHICLES = ("car", "van", "lorry", "bus")


@dataclass(frozen=True)
class TrafficParams(Params):
    """moving actors: vehicles, cyclists and pedestrians along the scene's lanes and pavements (scenes.traffic)"""

    section_name = "traffic"

    enabled: bool = param(False, "put moving vehicles, cyclists and pedestrians in the scene (false: the static "
                          "world, the scene's static twin)")
    cars_per_km: float = param(12.0, "cars per km of road, all lanes together", min=0.0, max=200.0)
    vans_per_km: float = param(3.0, "vans per km of road", min=0.0, max=100.0)
    lorries_per_km: float = param(2.0, "lorries per km of road", min=0.0, max=100.0)
    buses_per_km: float = param(1.0, "buses per km of road", min=0.0, max=50.0)
    cyclists_per_km: float = param(3.0, "cyclists per km of road", min=0.0, max=100.0)
    pedestrians_per_km: float = param(25.0, "pedestrians per km of pavement (where the scene has pavements)",
                                      min=0.0, max=500.0)
    behaviours: tuple[str, ...] = param(BEHAVIOURS, "what the traffic does (scenes.traffic)", choices=BEHAVIOURS,
                                        one_or_more=True, unique=True)
    lead: str = param("none", "a vehicle ahead of the ego in its lane", choices=("none", *VEHICLES))
    lead_gap_m: float = param(15.0, "the lead vehicle's mean gap, bumper to bumper", min=4.0, max=150.0)
    lead_gap_variation_m: float = param(5.0, "how far the lead's gap drifts from its mean (0: a constant gap)",
                                        min=0.0, max=100.0)
    speed_factor: float = param(1.0, "the traffic's cruise speed as a share of the ego's", min=0.2, max=2.0)


# ---------------------------------------------------------------- where traffic may go
@dataclass(frozen=True)
class Lane:
    """A lane parallel to the ego's path: its offset from it (left positive), m, and direction (+1: the ego's)."""

    offset_m: float
    direction: int


@dataclass
class RoadLayout:
    """Where a scene's traffic may go, given by the scene (``Scene.roads``).

    lanes: every lane along the ego's path, the ego's own (offset 0) included. closed: the path is a
    loop. height: the road surface's height at (x, y), or None (each lane at the path's height).
    parking: offsets of parking places' centres (a vehicle may stand there, then pull out).
    cyclists: (offset, direction) of the lines cyclists ride. pavements: offsets of the lines people
    walk along beside the path, and pavement_lift_m their height above the road; pavement_spans:
    distance ranges along the path where there are pavements (None: all of it). walkways: loops or
    lines (points (m, 3) at walking height, closed) people walk along beyond the path's offsets (a
    city block's sidewalks). crossings: (a, b) points (3,) between which people cross the road.
    cross_streets: (centre line (m, 3), lane offset) of streets that cross the route. stop_lines:
    distances along the path where the lanes' traffic may queue at a red signal (a junction's approach).
    """

    lanes: tuple[Lane, ...]
    closed: bool
    height: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    parking: tuple[float, ...] = ()
    cyclists: tuple[tuple[float, int], ...] = ()
    pavements: tuple[float, ...] = ()
    pavement_lift_m: float = 0.0
    pavement_spans: tuple[tuple[float, float], ...] | None = None
    walkways: list = field(default_factory=list)
    crossings: list = field(default_factory=list)
    cross_streets: list = field(default_factory=list)
    stop_lines: tuple[float, ...] = ()

    def line(self, path: np.ndarray, offset_m: float, lift_m: float = 0.0) -> np.ndarray:
        """(m, 3) the line ``offset_m`` left of the ego's path (m, 3), at the road's height plus ``lift_m``."""
        xy = paths.offset(path[:, :2], offset_m, self.closed) if offset_m else path[:, :2].copy()
        z = self.height(xy[:, 0], xy[:, 1]) if self.height is not None and offset_m else path[:, 2]
        return np.column_stack([xy, z + lift_m])


def two_way_road(lane_offset_m: float, road_half_m: float, closed: bool, height=None,
                 parking_lateral_m: float | None = None, car_half_m: float = 0.95, sidewalk_m: float = 0.0,
                 kerb_m: float = 0.0, pavement_spans=None, cyclists: bool = True, **more) -> RoadLayout:
    """The layout of a two-lane road, the ego ``lane_offset_m`` right of its centre line, ``road_half_m`` to each
    kerb: the oncoming lane mirrored, cyclists along the kerbs, parked cars' places ``parking_lateral_m`` from the
    centre line on each side where a car leaves the lanes room (as the scenes park theirs), pavements ``sidewalk_m``
    wide beyond the kerbs (none when 0)."""
    lo = lane_offset_m
    parking = ()
    if parking_lateral_m is not None:
        parking = tuple(lo + side * parking_lateral_m for side in (-1.0, 1.0)
                        if parking_lateral_m - car_half_m - lo >= car_half_m + 0.5)
    ride = min(1.4, road_half_m - lo - 0.6)
    cyclists = ((-ride, 1), (2 * lo + ride, -1)) if ride > 0.9 and cyclists else ()
    pavements = (lo - road_half_m - sidewalk_m / 2, lo + road_half_m + sidewalk_m / 2) if sidewalk_m > 0 else ()
    return RoadLayout(lanes=(Lane(0.0, 1), Lane(2 * lo, -1)), closed=closed, height=height, parking=parking,
                      cyclists=cyclists, pavements=pavements, pavement_lift_m=kerb_m, pavement_spans=pavement_spans,
                      **more)


# ---------------------------------------------------------------- the ego
class EgoMotion:
    """The ego's motion as the traffic sees it: its distance along its path against time, a ``SpeedProfile``
    through its speeds every ``step_s`` (continuous acceleration; within centimetres of the ego), and its
    footprint (centre and heading) on a time grid."""

    def __init__(self, trajectory, path: np.ndarray, closed: bool, step_s: float = 0.25):
        self.trajectory = trajectory
        self.duration_s = float(trajectory.duration_s)
        t = np.arange(0.0, self.duration_s + step_s, step_s)
        self.profile = SpeedProfile(t, trajectory.speed_at(t), float(trajectory.distance_at(np.array([0.0]))[0]))
        self.lane = LanePath(path[:-1] if closed and np.allclose(path[0], path[-1]) else path, closed)
        self.grid = np.arange(0.0, self.duration_s + GRID_S / 2, GRID_S)
        T = trajectory.pose_at(self.grid)
        self.centre = T[:, :2, 3]
        self.yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])

    def position_at(self, t) -> np.ndarray:
        """(n, 3) the lidar's position at times (n,)."""
        return self.trajectory.pose_at(np.atleast_1d(t))[:, :3, 3]


# ---------------------------------------------------------------- conflicts
def _boxes_overlap(c1, y1, h1, c2, y2, h2) -> np.ndarray:
    """(n,) oriented rectangles overlap (separating axes): centres (n, 2), yaws (n,), half sizes (n, 2)."""
    u1 = np.stack([np.cos(y1), np.sin(y1)], 1)
    v1 = np.stack([-u1[:, 1], u1[:, 0]], 1)
    u2 = np.stack([np.cos(y2), np.sin(y2)], 1)
    v2 = np.stack([-u2[:, 1], u2[:, 0]], 1)
    d = c2 - c1
    overlap = np.ones(len(d), bool)
    for axis in (u1, v1, u2, v2):
        r1 = h1[:, 0] * np.abs(np.sum(u1 * axis, 1)) + h1[:, 1] * np.abs(np.sum(v1 * axis, 1))
        r2 = h2[:, 0] * np.abs(np.sum(u2 * axis, 1)) + h2[:, 1] * np.abs(np.sum(v2 * axis, 1))
        overlap &= np.abs(np.sum(d * axis, 1)) <= r1 + r2
    return overlap


class Occupancy:
    """The ego's and the kept actors' boxes on the conflict grid; ``admits`` a candidate that meets none."""

    def __init__(self, ego: EgoMotion):
        self.ego = ego
        self.grid = ego.grid
        self.kept: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # alive, centre, yaw, half

    def footprint(self, actor: Actor) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        alive = (self.grid >= actor.time_span_s[0]) & (self.grid <= actor.time_span_s[1])
        centre = np.full((len(self.grid), 2), np.nan)
        yaw = np.zeros(len(self.grid))
        if alive.any():
            centre[alive], yaw[alive] = actor.footprint_at(self.grid[alive])
        along, across = MARGIN_M["person" if actor.kind in ("cyclist", "pedestrian") else "vehicle"]
        half = np.array([actor.model.length_m / 2 + along / 2, actor.model.width_m / 2 + across / 2])
        return alive, centre, yaw, half

    def admits(self, actor: Actor) -> bool:
        alive, centre, yaw, half = fp = self.footprint(actor)
        if not alive.any():
            return False
        ego_half = np.array(EGO_SIZE_M) / 2 + np.array(MARGIN_M["vehicle"]) / 2
        idx = np.flatnonzero(alive)
        near = np.linalg.norm(centre[idx] - self.ego.centre[idx], axis=1) < np.linalg.norm(half) + np.linalg.norm(
            ego_half)
        k = idx[near]
        if len(k) and _boxes_overlap(centre[k], yaw[k], np.broadcast_to(half, (len(k), 2)), self.ego.centre[k],
                                     self.ego.yaw[k], np.broadcast_to(ego_half, (len(k), 2))).any():
            return False
        for alive2, centre2, yaw2, half2 in self.kept:
            both = np.flatnonzero(alive & alive2)
            if len(both) == 0:
                continue
            near = np.linalg.norm(centre[both] - centre2[both], axis=1) < np.linalg.norm(half) + np.linalg.norm(half2)
            k = both[near]
            if len(k) and _boxes_overlap(centre[k], yaw[k], np.broadcast_to(half, (len(k), 2)), centre2[k], yaw2[k],
                                         np.broadcast_to(half2, (len(k), 2))).any():
                return False
        self.kept.append(fp)
        return True


class StaticClearance:
    """The static world's vertices above the ground, to keep actors off parked cars, poles, trees and walls.

    A candidate is clear when no vertex of the scene lies within its box (a margin of ``margin_m``
    around) between ``floor_m`` above its ground and its height, at the poses asked for.
    """

    def __init__(self, vertices: np.ndarray, margin_m: float = 0.15, floor_m: float = 0.3):
        from scipy.spatial import cKDTree

        self.vertices = np.asarray(vertices, float)
        self.tree = cKDTree(self.vertices[:, :2])
        self.margin_m, self.floor_m = margin_m, floor_m

    def clear(self, actor: Actor, times: np.ndarray) -> bool:
        m = actor.model
        pos, yaw, _ = actor.place_at(times)
        u = np.stack([np.cos(yaw), np.sin(yaw)], 1)
        v = np.stack([-u[:, 1], u[:, 0]], 1)
        centre = pos[:, :2] + m.box_centre[0] * u + m.box_centre[1] * v
        half = np.array([m.length_m, m.width_m]) / 2 + self.margin_m
        for k, near in enumerate(self.tree.query_ball_point(centre, float(np.hypot(*half)))):
            if not near:
                continue
            q = self.vertices[near]
            d = q[:, :2] - centre[k]
            inside = (np.abs(d @ u[k]) <= half[0]) & (np.abs(d @ v[k]) <= half[1])
            z = q[inside, 2] - pos[k, 2]
            if np.any((z > self.floor_m) & (z < m.height_m + 0.1)):
                return False
        return True


# ---------------------------------------------------------------- drivers
def drive(lane: LanePath, s0: float, cruise_m_s: float, t0: float, t1: float, accel_m_s2: float = 1.5,
          lateral_m_s2: float = 2.0, step_s: float = 0.5, start_m_s: float | None = None) -> SpeedProfile:
    """A driver's speed profile along ``lane`` from distance ``s0`` at ``t0`` to ``t1``: cruise, slowing for bends.

    The speed aims at the lowest of the cruise speed and the bends' limits ahead within braking
    distance (lateral acceleration ``lateral_m_s2``), changing by at most ``accel_m_s2`` a second.
    start_m_s: the speed at ``t0`` (default: the target there).
    """
    ds = np.arange(0.0, lane.length_m, 1.0)
    d1 = lane._spline(ds, 1)
    d2 = lane._spline(ds, 2)
    kappa = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(np.hypot(d1[:, 0], d1[:, 1]) ** 3, 1e-12)
    v_bend = np.sqrt(lateral_m_s2 / np.maximum(kappa, 1e-9))

    def target(s: float, v: float) -> float:
        look = v * v / (2 * accel_m_s2) + 5.0
        sel = (np.arange(0.0, look, 1.0) + s)
        sel = sel % lane.length_m if lane.closed else np.clip(sel, 0, lane.length_m - 1)
        ahead = v_bend[np.minimum(sel.astype(int), len(v_bend) - 1)]
        dist = np.arange(len(sel), dtype=float)
        # the highest speed from which a bend `dist` ahead is reached at its limit
        allowed = np.sqrt(ahead**2 + 2 * accel_m_s2 * dist)
        return float(min(cruise_m_s, allowed.min()))

    times = np.arange(t0, t1 + step_s, step_s)
    v = np.empty(len(times))
    s = s0
    v[0] = target(s0, cruise_m_s) if start_m_s is None else start_m_s
    for k in range(1, len(times)):
        want = target(s, v[k - 1])
        v[k] = float(np.clip(want, v[k - 1] - accel_m_s2 * step_s, v[k - 1] + accel_m_s2 * step_s))
        s += step_s * (v[k - 1] + v[k]) / 2
    return SpeedProfile(times, np.maximum(v, 0.0), s0)


def stop_and_go(rng: np.random.Generator, t0: float, t1: float, creep_m_s: tuple[float, float] = (0.8, 2.5),
                stop_s: tuple[float, float] = (2.0, 6.0), move_s: tuple[float, float] = (2.0, 5.0),
                s0: float = 0.0) -> SpeedProfile:
    """A queue's speed profile: stopped, creeping, stopped again... from ``t0`` to ``t1``."""
    t, times, speeds = t0, [t0], [0.0]
    moving = bool(rng.random() < 0.5)
    while t < t1:
        if moving:
            ramp = rng.uniform(1.0, 2.0)
            v = rng.uniform(*creep_m_s)
            hold = rng.uniform(*move_s)
            times += [t + ramp, t + ramp + hold]
            speeds += [v, v]
            t += ramp + hold
        else:
            ramp = rng.uniform(1.0, 2.0)
            hold = rng.uniform(*stop_s)
            times += [t + ramp, t + ramp + hold]
            speeds += [0.0, 0.0]
            t += ramp + hold
        moving = not moving
    return SpeedProfile(times, speeds, s0)


# ---------------------------------------------------------------- population
@dataclass
class _Context:
    scene: object
    roads: RoadLayout
    params: TrafficParams
    rng: np.random.Generator
    ego: EgoMotion
    occupancy: Occupancy
    clearance: StaticClearance
    route_km: float
    cruise: float
    out: list[Actor] = field(default_factory=list)
    tally: dict[tuple[str, str], int] = field(default_factory=dict)  # (behaviour, outcome): candidates

    def _mark(self, actor: Actor, outcome: str) -> bool:
        key = (actor.behaviour, outcome)
        self.tally[key] = self.tally.get(key, 0) + 1
        return outcome == "kept"

    @property
    def duration(self) -> float:
        return self.ego.duration_s

    def lane(self, offset_m: float, direction: int, lift_m: float = 0.0) -> LanePath:
        pts = self.roads.line(self.scene.path, offset_m, lift_m)
        if self.roads.closed and np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
        lane = LanePath(pts, self.roads.closed)
        return lane if direction > 0 else lane.reversed()

    def model(self, kind: str):
        found = models_of(kind)
        return found[int(self.rng.integers(len(found)))]

    def try_add(self, actor: Actor) -> bool:
        """Keep ``actor`` if it meets nothing, stands clear of the static world and appears out of sight."""
        t_on, t_off = actor.time_span_s
        far = VANISH_FAR_PERSON_M if actor.kind in ("cyclist", "pedestrian") else VANISH_FAR_M
        for t in (t_on, t_off):
            if 0.0 <= t <= self.duration:
                pos, _, _ = actor.place_at(np.array([t]))
                if np.linalg.norm(pos[0, :2] - self.ego.position_at(t)[0, :2]) < far:
                    return self._mark(actor, "appears in sight")
        lo, hi = max(t_on, 0.0), min(t_off, self.duration)
        if hi < lo:
            return self._mark(actor, "gone before the scene")
        # where it goes while the scene lasts, every metre or so
        span = max(hi - lo, 1e-3)
        s = actor.along.distance(np.array([lo, hi]))
        n = int(np.clip(abs(s[1] - s[0]) / 1.0, 2, 2000)) + int(span / 2.0)
        if not self.clearance.clear(actor, np.linspace(lo, hi, n)):
            return self._mark(actor, "meets the static world")
        if not self.occupancy.admits(actor):
            return self._mark(actor, "meets the ego or an actor")
        self.out.append(actor)
        return self._mark(actor, "kept")


def _count(rng: np.random.Generator, per_km: float, km: float) -> int:
    """A Poisson draw of a density over a length."""
    return int(rng.poisson(per_km * km)) if per_km > 0 and km > 0 else 0


def _vehicle_kinds(ctx: _Context, n_total: int) -> list[str]:
    """``n_total`` vehicle classes in the proportions of the densities."""
    p = ctx.params
    dens = np.array([p.cars_per_km, p.vans_per_km, p.lorries_per_km, p.buses_per_km])
    if n_total <= 0 or dens.sum() <= 0:
        return []
    return [VEHICLES[i] for i in ctx.rng.choice(len(VEHICLES), size=n_total, p=dens / dens.sum())]


# The car-following model of a lane's vehicles (the intelligent driver model, Treiber, Hennecke and Helbing 2000).
IDM_ACCEL_M_S2 = 1.2
IDM_BRAKE_M_S2 = 2.0
IDM_HEADWAY_S = 1.5
IDM_GAP_M = 2.5
IDM_STEP_S = 0.1


@dataclass(frozen=True)
class Signal:
    """A stop line at distance ``s_m`` along a lane, red during each (start, end) of ``red_s``."""

    s_m: float
    red_s: tuple[tuple[float, float], ...]

    def red(self, t: float) -> bool:
        return any(a <= t < b for a, b in self.red_s)


def lane_traffic(lane: LanePath, lengths: list[float], v0: np.ndarray, t0: float, t1: float,
                 signals: tuple[Signal, ...] = (), lateral_m_s2: float = 2.0,
                 rng: np.random.Generator | None = None,
                 enter_s: np.ndarray | None = None) -> list[tuple[SpeedProfile, tuple[float, float]]]:
    """The vehicles of one lane, driving by the intelligent driver model from ``t0`` to ``t1``.

    lengths (n,) m and desired speeds v0 (n,) m/s of the vehicles, front to back; on a loop they start
    evenly spread, on an open lane they enter at its start at times spread over the run (when there is
    room: a vehicle waits for the one ahead to leave a headway). Each slows for bends (lateral acceleration
    ``lateral_m_s2``), keeps its headway to the one ahead and stops at a red signal it can stop for.
    enter_s: (n,) the times they enter an open lane (default: spread over the run). Returns each vehicle's
    (``SpeedProfile`` through its speeds every 0.5 s, (time it enters, time it leaves)).
    """
    n = len(lengths)
    if n == 0:
        return []
    rng = rng or np.random.default_rng(0)
    lengths, v0 = np.asarray(lengths, float), np.asarray(v0, float)
    ds = np.arange(0.0, lane.length_m + 1.0, 1.0)
    d1, d2 = lane._spline(ds % lane.length_m if lane.closed else ds, 1), lane._spline(
        ds % lane.length_m if lane.closed else ds, 2)
    kappa = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(np.hypot(d1[:, 0], d1[:, 1]) ** 3, 1e-12)
    # a bend's limit, reached in time: the lowest of the limits within 30 m ahead, eased by the braking distance
    v_bend = np.sqrt(lateral_m_s2 / np.maximum(kappa, 1e-9))
    ahead = np.array([np.min(np.sqrt(v_bend[np.arange(i, i + 30) % len(v_bend)] ** 2 + 2 * IDM_BRAKE_M_S2 * 0.5
                                     * np.arange(30))) for i in range(len(v_bend))])
    L = lane.length_m
    if lane.closed:
        spacing = L / n
        s = -np.arange(n) * spacing + rng.uniform(-0.2, 0.2, n) * spacing
        entered = np.ones(n, bool)
        t_sched = np.full(n, -np.inf)
    else:  # each enters at its start at a time of its own (when there is room), spread over the run
        s = np.full(n, -np.inf)
        entered = np.zeros(n, bool)
        t_sched = (t0 + (np.arange(n) + rng.uniform(0.2, 0.8, n)) * (t1 - t0) / n if enter_s is None
                   else np.asarray(enter_s, float))
    v = np.where(entered, np.minimum(v0, 5.0), 0.0)
    steps = int(np.ceil((t1 - t0) / IDM_STEP_S)) + 1
    times = t0 + np.arange(steps) * IDM_STEP_S
    S, V = np.empty((steps, n)), np.empty((steps, n))
    t_in = np.where(entered, -np.inf, np.inf)
    t_out = np.full(n, np.inf)
    sqab = 2 * np.sqrt(IDM_ACCEL_M_S2 * IDM_BRAKE_M_S2)
    np_err = np.seterr(invalid="ignore")  # (the gaps of vehicles not yet on the lane are -inf - -inf)
    for k, t in enumerate(times):
        # the gap to the vehicle ahead (the first on a loop follows the last, a lap ahead)
        front = np.empty(n)
        front[1:] = s[:-1] - (lengths[:-1] + lengths[1:]) / 2
        dv = np.zeros(n)
        dv[1:] = v[1:] - v[:-1]
        if lane.closed:
            front[0] = s[-1] + L - (lengths[-1] + lengths[0]) / 2
            dv[0] = v[0] - v[-1]
        else:
            front[0] = np.inf
        gap = front - s
        for sig in signals:
            if sig.red(t):
                pos = s % L if lane.closed else s
                to_line = (sig.s_m - pos) % L if lane.closed else sig.s_m - pos
                stop = (to_line - lengths / 2 > v * v / (2 * IDM_BRAKE_M_S2) * 0.5) & (to_line > 0)
                closer = stop & (to_line - lengths / 2 < gap)
                gap = np.where(closer, to_line - lengths / 2, gap)
                dv = np.where(closer, v, dv)
        idx = np.clip(((s % L) if lane.closed else np.clip(s, 0, L)).astype(int), 0, len(ahead) - 1)
        v_des = np.minimum(v0, ahead[idx])
        s_star = IDM_GAP_M + np.maximum(0.0, v * IDM_HEADWAY_S + v * dv / sqab)
        a = IDM_ACCEL_M_S2 * (1 - (v / np.maximum(v_des, 0.1)) ** 4 - (s_star / np.maximum(gap, 0.1)) ** 2)
        a = np.maximum(a, -9.0)
        S[k], V[k] = s, v
        v_new = np.maximum(v + a * IDM_STEP_S, 0.0)
        s = s + np.where(entered, IDM_STEP_S * (v + v_new) / 2, 0.0)
        v = np.where(entered, v_new, 0.0)
        if not lane.closed:
            # the next waiting vehicle enters when the last on the lane is far enough along
            waiting = np.flatnonzero(~entered)
            if len(waiting):
                j = waiting[0]
                room = s[j - 1] - (lengths[j - 1] + lengths[j]) / 2 if j > 0 else np.inf
                if t >= t_sched[j] and room > IDM_GAP_M + v0[j] * IDM_HEADWAY_S:
                    entered[j], s[j], t_in[j] = True, 0.0, t
                    v[j] = min(v0[j], v[j - 1]) if j > 0 else v0[j]
            left = entered & (s > L) & ~np.isfinite(t_out)
            t_out[left] = t
    np.seterr(**np_err)
    out = []
    knots = np.arange(0, steps, int(round(0.5 / IDM_STEP_S)))
    for i in range(n):
        if not np.isfinite(S[:, i]).any() and not np.isfinite(t_in[i]):
            continue
        ok = knots[np.isfinite(S[knots, i])]
        if len(ok) < 2:
            continue
        k0 = ok[0]
        profile = SpeedProfile(times[ok], V[ok, i], float(S[k0, i]))
        out.append((profile, (t_in[i] if np.isfinite(t_in[i]) else -1e9, t_out[i] if not lane.closed else 1e9)))
    return out


def _lane_vehicles(ctx: _Context, lane: LanePath, kinds: list[str], cruise: float, behaviour: str,
                   signals: tuple[Signal, ...] = ()) -> None:
    """A lane's vehicles by the car-following model: around a loop, spread over it; along an open road, on it at
    the scene's start and entering at its start as room allows."""
    if not kinds:
        return
    rng = ctx.rng
    models = [ctx.model(k) for k in kinds]
    v0 = cruise * rng.uniform(0.85, 1.1, len(models)) * np.array([0.85 if m.kind in ("lorry", "bus") else 1.0
                                                                   for m in models])
    begin = -PRE_ROLL_S if lane.closed else -1.2 * lane.length_m / max(cruise, 1.0) - PRE_ROLL_S
    runs = lane_traffic(lane, [m.length_m for m in models], v0, begin, ctx.duration + 5.0, signals, rng=rng)
    for m, (profile, span) in zip(models, runs, strict=False):
        scene_t = profile.t[(profile.t >= max(span[0], 0.0)) & (profile.t <= min(span[1], ctx.duration))]
        stops = len(scene_t) and profile.speed(scene_t).min() < 0.3  # it queues at a signal while the scene lasts
        ctx.try_add(Actor(m, lane, profile, OffsetProfile(), "queue" if stops else behaviour, span))


def _time_at(profile: SpeedProfile, s: float) -> float:
    """The first time a profile reaches distance ``s`` (inf if never)."""
    t = np.linspace(profile.t[0], profile.t[-1], 20001)
    d = profile.distance(t)
    i = np.searchsorted(d, s)
    return float(t[i]) if i < len(t) else np.inf


def _lead(ctx: _Context, kind: str) -> None:
    """A vehicle ahead of the ego in its lane, its gap a smooth function of the ego's distance (so it stops when
    the ego stops), drifting by ``lead_gap_variation_m`` around ``lead_gap_m``."""
    p, rng, ego = ctx.params, ctx.rng, ctx.ego
    model = ctx.model(kind)
    half = model.length_m / 2 + EGO_SIZE_M[0] / 2
    s_grid = np.arange(-100.0, ego.lane.length_m * (3 if ego.lane.closed else 1) + 200.0, 60.0)
    gaps = p.lead_gap_m + (rng.uniform(-1, 1, len(s_grid)) * p.lead_gap_variation_m if p.lead_gap_variation_m else 0.0)
    gap = OffsetProfile(s_grid, np.maximum(gaps, 4.0) + half)
    t = ego.profile.t
    s_ego = ego.profile.distance(t)
    v = ego.profile.speed(t) * (1.0 + gap.rate(s_ego))
    profile = SpeedProfile(t, np.maximum(v, 0.0), float(s_ego[0] + gap.value(s_ego[:1])[0]))
    actor = Actor(model, ego.lane, profile, OffsetProfile(), "lead", (-1e9, 1e9))
    ctx.try_add(actor)


def _overtaking(ctx: _Context, lanes: list[Lane], kinds: list[str]) -> None:
    """Vehicles that come up behind the ego, pass it in the lane to its left and pull in ahead."""
    rng, ego = ctx.rng, ctx.ego
    left = sorted((ln for ln in lanes if ln.offset_m > 0.5), key=lambda ln: ln.offset_m)
    if not left or not kinds:
        return
    lane_off = left[0].offset_m
    for kind in kinds:
        model = ctx.model(kind)
        t_pass = rng.uniform(5.0, max(ego.duration_s - 10.0, 6.0))
        dv = rng.uniform(3.0, 7.0)
        clear = model.length_m / 2 + EGO_SIZE_M[0] / 2 + 3.0
        t_out, t_back = t_pass - 2 * clear / dv - 2.0, t_pass + 2 * clear / dv
        t = ego.profile.t
        # its gap to the ego: -2 clear behind, +2 clear ahead; its speed the ego's plus the gap's rate
        gap = OffsetProfile([t_out, t_back + 2.0], [-2 * clear, 2 * clear])
        v = np.maximum(ego.profile.speed(t) + gap.rate(t), 0.0)
        s0 = float(ego.profile.distance(t[:1])[0] + gap.value(t[:1])[0])
        profile = SpeedProfile(t, v, s0)
        across = OffsetProfile([t_out - 3.0, t_out, t_back, t_back + 3.0], [0.0, lane_off, lane_off, 0.0])
        actor = Actor(model, ego.lane, profile, across, "overtaking", (-1e9, 1e9))
        ctx.try_add(actor)


def _pull_out(ctx: _Context, kinds: list[str]) -> None:
    """Vehicles parked at the kerb that pull out into the nearest lane of their direction and drive on."""
    rng, roads, ego = ctx.rng, ctx.roads, ctx.ego
    if not roads.parking or not kinds:
        return
    for kind in kinds:
        park = roads.parking[int(rng.integers(len(roads.parking)))]
        same = [ln for ln in roads.lanes if ln.direction == (1 if park < 0 else -1)]
        if not same:
            continue
        lane_ln = min(same, key=lambda ln: abs(ln.offset_m - park))
        lane = ctx.lane(lane_ln.offset_m, lane_ln.direction)
        across_off = (park - lane_ln.offset_m) * (1 if lane_ln.direction > 0 else -1)
        model = ctx.model(kind)
        s0 = rng.uniform(0.0, lane.length_m)
        t_go = rng.uniform(0.0, ego.duration_s)
        cruise = ctx.cruise * rng.uniform(0.85, 1.05)
        moving = drive(lane, s0, cruise, t_go + 1.0, ego.duration_s + PRE_ROLL_S, start_m_s=0.0)
        profile = SpeedProfile(np.concatenate([[t_go - 1e3, t_go], moving.t[moving.t > t_go + 0.1]]),
                               np.concatenate([[0.0, 0.0], moving.v[moving.t > t_go + 0.1]]), s0)
        across = OffsetProfile([t_go + 1.5, t_go + 5.5], [across_off, 0.0])
        end = np.inf if lane.closed else _time_at(profile, lane.length_m)
        ctx.try_add(Actor(model, lane, profile, across, "pull_out", (-1e9, end)))


def _crossing_traffic(ctx: _Context, kinds: list[str]) -> None:
    """Vehicles along the streets that cross the route, either way, at times of their own."""
    rng = ctx.rng
    streets = ctx.roads.cross_streets
    if not streets or not kinds:
        return
    for kind in kinds:
        line, lane_off = streets[int(rng.integers(len(streets)))]
        direction = 1 if rng.random() < 0.5 else -1
        street = LanePath(line, False)
        pts = street.point(np.arange(0.0, street.length_m, 0.5))
        _, _, left, _ = street.frame(np.arange(0.0, street.length_m, 0.5))
        xy = pts[:, :2] - lane_off * left
        z = ctx.roads.height(xy[:, 0], xy[:, 1]) if ctx.roads.height is not None else pts[:, 2]
        lane = LanePath(np.column_stack([xy, z]), False)
        if direction < 0:
            lane = LanePath(np.column_stack([pts[:, :2] + lane_off * left, z])[::-1], False)
        t_in = rng.uniform(-20.0, ctx.duration)
        profile = drive(lane, 0.0, ctx.cruise * rng.uniform(0.8, 1.1), t_in, t_in + 3 * lane.length_m / 5.0)
        ctx.try_add(Actor(ctx.model(kind), lane, profile, OffsetProfile(), "crossing",
                          (t_in, _time_at(profile, lane.length_m))))


def _cyclists(ctx: _Context, n: int, behaviours: tuple[str, ...]) -> None:
    rng, roads = ctx.rng, ctx.roads
    lines = [c for c in roads.cyclists if ("same_direction" in behaviours and c[1] > 0)
             or ("oncoming" in behaviours and c[1] < 0)]
    if not lines:
        return
    for _ in range(n):
        offset, direction = lines[int(rng.integers(len(lines)))]
        lane = ctx.lane(offset, direction)
        speed = rng.uniform(3.5, 6.5)
        s0 = rng.uniform(0.0, lane.length_m)
        t0 = -PRE_ROLL_S if lane.closed else rng.uniform(-PRE_ROLL_S, ctx.duration)
        profile = drive(lane, s0 if lane.closed else 0.0, speed, t0, ctx.duration + PRE_ROLL_S, lateral_m_s2=1.5)
        span = (-1e9, 1e9) if lane.closed else (t0, _time_at(profile, lane.length_m))
        ctx.try_add(Actor(ctx.model("cyclist"), lane, profile, OffsetProfile(), "cycling", span))


def _walkers(ctx: _Context, n: int) -> None:
    rng, roads = ctx.rng, ctx.roads
    lines = [(ctx.lane(off, 1, roads.pavement_lift_m), roads.pavement_spans) for off in roads.pavements]
    lines += [(LanePath(w[:-1] if closed and np.allclose(w[0], w[-1]) else w, closed), None)
              for w, closed in roads.walkways]
    if not lines:
        return
    for _ in range(n):
        lane, spans = lines[int(rng.integers(len(lines)))]
        if rng.random() < 0.5:
            lane = lane.reversed()
        speed = rng.uniform(1.1, 1.6)
        if lane.closed and spans is None:
            s0 = rng.uniform(0.0, lane.length_m)
            profile = SpeedProfile([-PRE_ROLL_S], [speed], s0 - speed * 0.0)
            span = (-1e9, 1e9)
        else:
            a, b = (0.0, lane.length_m) if spans is None else spans[int(rng.integers(len(spans)))]
            a, b = max(a, 0.0), min(b, lane.length_m)
            if b - a < 10.0:
                continue
            t_in = rng.uniform(-(b - a) / speed, ctx.duration)
            profile = SpeedProfile([t_in], [speed], a)
            span = (t_in, t_in + (b - a) / speed)
        ctx.try_add(Actor(ctx.model("pedestrian"), lane, profile, OffsetProfile(), "walking", span))


def _crossers(ctx: _Context, n: int) -> None:
    """People crossing the road: at the layout's crossings, or across the path between its pavements."""
    rng, roads = ctx.rng, ctx.roads
    for _ in range(n):
        if roads.crossings:
            a, b = roads.crossings[int(rng.integers(len(roads.crossings)))]
        elif len(roads.pavements) >= 2:
            ego = ctx.ego
            spans = roads.pavement_spans or ((0.0, ego.lane.length_m),)
            lo, hi = spans[int(rng.integers(len(spans)))]
            s = rng.uniform(lo, hi)
            p, _, left, _ = ego.lane.frame(np.array([s]))
            off_a, off_b = min(roads.pavements), max(roads.pavements)
            a = np.array([*(p[0, :2] + off_a * left[0]), p[0, 2] + roads.pavement_lift_m])
            b = np.array([*(p[0, :2] + off_b * left[0]), p[0, 2] + roads.pavement_lift_m])
        else:
            return
        if rng.random() < 0.5:
            a, b = b, a
        line = np.linspace(a, b, max(4, int(np.linalg.norm(b - a) / 0.5)))
        if roads.height is not None:
            road_z = roads.height(line[:, 0], line[:, 1])
            kerb = np.clip((np.minimum(np.arange(len(line)), np.arange(len(line))[::-1]) * 0.5 - 2.0), 0, None) == 0
            line[:, 2] = np.where(kerb, line[:, 2], road_z)
        lane = LanePath(line, False)
        speed = rng.uniform(1.1, 1.6)
        t_in = rng.uniform(0.0, ctx.duration)
        profile = SpeedProfile([t_in, t_in + 1.0], [0.0, speed], 0.0)
        ctx.try_add(Actor(ctx.model("pedestrian"), lane, profile, OffsetProfile(), "crossing_pedestrian",
                          (t_in, _time_at(SpeedProfile([t_in, t_in + 1.0, t_in + 1e3], [0.0, speed, speed]),
                                          lane.length_m))))


def populate(scene, params: TrafficParams, seed: int, existing: list[Actor] | None = None) -> list[Actor]:
    """The actors of ``scene`` (its ``roads`` and trajectory) for ``params``, drawn from ``seed``.

    existing: actors the scene placed itself (a stress scene's): kept, and the new ones kept clear of them.
    Raises ValueError when the scene has no roads for the traffic asked for.
    """
    roads = scene.roads
    if roads is None:
        raise ValueError(f"parameter traffic.enabled: scene {scene.name} has no lanes for traffic")
    rng = np.random.default_rng([int(seed), 0x7AF1C, zlib.crc32(scene.name.encode())])
    ego = EgoMotion(scene.trajectory, scene.path, roads.closed)
    occupancy = Occupancy(ego)
    for a in existing or []:
        occupancy.kept.append(occupancy.footprint(a))
    route_km = ego.lane.length_m / 1000.0
    cruise = float(scene.params.get("speed_m_s", 10.0)) * params.speed_factor
    # an open road: the vehicles that pass over the run (from before the scene fills the road), not only
    # those on it at once
    flow_km = route_km if roads.closed else route_km * 2.2 + cruise * (ego.duration_s + PRE_ROLL_S) / 1000.0
    ctx = _Context(scene, roads, params, rng, ego, occupancy, StaticClearance(scene.vertices), route_km, cruise,
                   list(existing or []))
    b = set(params.behaviours)
    if params.lead != "none":
        _lead(ctx, params.lead)
    vehicles = _vehicle_kinds(ctx, _count(rng, params.cars_per_km + params.vans_per_km + params.lorries_per_km
                                          + params.buses_per_km, flow_km))
    # the vehicles' share of each behaviour: lanes first, then the rest in turns
    others = [ln for ln in roads.lanes if ln.offset_m != 0.0]
    groups = {"oncoming": [ln for ln in others if ln.direction < 0], "same_direction": [ln for ln in others
                                                                                        if ln.direction > 0]}
    wanted = [k for k in ("oncoming", "same_direction", "overtaking", "crossing", "queue", "pull_out") if k in b
              and (k not in groups or groups[k]) and (k != "crossing" or roads.cross_streets)
              and (k != "pull_out" or roads.parking)]
    weights = {"oncoming": 4.0, "same_direction": 3.0, "overtaking": 0.5, "crossing": 2.0, "queue": 1.5,
               "pull_out": 0.5}
    share: dict[str, list[str]] = {k: [] for k in wanted}
    if wanted:
        w = np.array([weights[k] for k in wanted])
        for kind, k in zip(vehicles, rng.choice(len(wanted), size=len(vehicles), p=w / w.sum()), strict=True):
            share[wanted[k]].append(kind)
    # queues: red signals on the other lanes, where their vehicles stop and then creep on
    signals: dict[float, tuple[Signal, ...]] = {}
    if share.get("queue") and others:
        for ln in [others[int(rng.integers(len(others)))]]:  # one lane queues
            lane = ctx.lane(ln.offset_m, ln.direction)
            lines = roads.stop_lines or tuple(rng.uniform(0.0, lane.length_m, max(1, int(lane.length_m // 400))))
            sig = []
            for s_line in lines:
                s_on = s_line if ln.direction > 0 else lane.length_m - s_line
                t, reds = rng.uniform(-40.0, 0.0), []
                while t < ctx.duration:
                    red = rng.uniform(15.0, 35.0)
                    reds.append((t, t + red))
                    t += red + rng.uniform(10.0, 30.0)
                sig.append(Signal(float(s_on), tuple(reds)))
            signals[ln.offset_m] = tuple(sig)
        for k, kind in enumerate(share["queue"]):  # the queues' vehicles join the lanes' flows
            (share.setdefault("oncoming", []) if k % 2 == 0 and groups["oncoming"] else
             share.setdefault("same_direction", []) if groups["same_direction"] else
             share.setdefault("oncoming", [])).append(kind)
    for name in ("oncoming", "same_direction"):
        lanes = groups.get(name, [])
        kinds = share.get(name, [])
        for j, ln in enumerate(lanes):
            mine = kinds[j::len(lanes)]
            speed = cruise * rng.uniform(0.9, 1.1) * (1.0 + 0.08 * (abs(ln.offset_m) // 3.0))
            _lane_vehicles(ctx, ctx.lane(ln.offset_m, ln.direction), mine, speed, name, signals.get(ln.offset_m, ()))
    if share.get("overtaking"):
        _overtaking(ctx, list(roads.lanes), share["overtaking"])
    if share.get("crossing"):
        _crossing_traffic(ctx, share["crossing"])
    if share.get("pull_out"):
        _pull_out(ctx, share["pull_out"])
    if ("same_direction" in b or "oncoming" in b) and params.cyclists_per_km > 0:
        _cyclists(ctx, _count(rng, params.cyclists_per_km, route_km), tuple(b))
    pavement_km = route_km * (len(roads.pavements) + len(roads.walkways)) / 2.0 if (
        roads.pavements or roads.walkways) else 0.0
    if "walking" in b:
        _walkers(ctx, _count(rng, params.pedestrians_per_km * 0.8, pavement_km))
    if "crossing_pedestrians" in b:
        _crossers(ctx, _count(rng, params.pedestrians_per_km * 0.2, pavement_km))
    log.info("traffic of %s seed %d: %s", scene.name, seed,
             "; ".join(f"{b} {o}: {n}" for (b, o), n in sorted(ctx.tally.items())))
    return ctx.out


# ---------------------------------------------------------------- the families' traffic
# Densities drawn per family member when the suite asks for traffic (a stream of draws of its own, so
# the family's other parameters are drawn as without traffic).
FAMILY_TRAFFIC: dict[str, dict[str, tuple[float, float]]] = {
    "city": {"cars_per_km": (10.0, 40.0), "vans_per_km": (2.0, 8.0), "lorries_per_km": (0.5, 4.0),
             "buses_per_km": (0.5, 3.0), "cyclists_per_km": (2.0, 10.0), "pedestrians_per_km": (20.0, 80.0)},
    "suburb": {"cars_per_km": (4.0, 15.0), "vans_per_km": (1.0, 4.0), "lorries_per_km": (0.0, 1.0),
               "buses_per_km": (0.0, 1.0), "cyclists_per_km": (1.0, 6.0), "pedestrians_per_km": (5.0, 30.0)},
    "canyon": {"cars_per_km": (10.0, 35.0), "vans_per_km": (2.0, 8.0), "lorries_per_km": (0.5, 4.0),
               "buses_per_km": (0.5, 3.0), "cyclists_per_km": (1.0, 6.0), "pedestrians_per_km": (20.0, 80.0)},
    "tunnel": {"cars_per_km": (8.0, 30.0), "vans_per_km": (2.0, 6.0), "lorries_per_km": (1.0, 6.0),
               "buses_per_km": (0.0, 2.0), "cyclists_per_km": (0.0, 0.0), "pedestrians_per_km": (0.0, 0.0)},
    "highway": {"cars_per_km": (10.0, 40.0), "vans_per_km": (2.0, 8.0), "lorries_per_km": (2.0, 10.0),
                "buses_per_km": (0.0, 2.0), "cyclists_per_km": (0.0, 0.0), "pedestrians_per_km": (0.0, 0.0)},
}
LEAD_CHANCE = 0.5  # of a family member with traffic having a lead vehicle


def draw_traffic(family: str, seed: int) -> dict | None:
    """The ``traffic`` section of a family member with traffic (enabled, densities, a lead vehicle or none),
    drawn from ``seed``; None for a family without traffic."""
    ranges = FAMILY_TRAFFIC.get(family)
    if ranges is None:
        return None
    rng = np.random.default_rng([zlib.crc32(family.encode()), int(seed), 0x7AF])
    out: dict = {"enabled": True}
    for key in sorted(ranges):
        lo, hi = ranges[key]
        out[key] = round(float(rng.uniform(lo, hi)), 3)
    if rng.random() < LEAD_CHANCE:
        out["lead"] = str(rng.choice(["car", "car", "van", "lorry"]))
        out["lead_gap_m"] = round(float(rng.uniform(8.0, 30.0)), 2)
    return out


__all__ = ["BEHAVIOURS", "FAMILY_TRAFFIC", "KINDS", "EgoMotion", "Lane", "Occupancy", "RoadLayout", "Signal",
           "StaticClearance", "TrafficParams", "draw_traffic", "drive", "lane_traffic", "populate", "stop_and_go",
           "two_way_road"]
