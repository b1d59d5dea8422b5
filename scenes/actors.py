"""Moving objects of a scene: vehicles, cyclists and pedestrians of real size, each on a smooth path of its own.

An ``Actor`` is a rigid mesh (an ``ActorModel`` of ``MODELS``, built from trimesh
primitives: a car's body, cabin and wheels; a lorry's cab and box body; a
pedestrian's legs, torso, arms and head) driving along a ``LanePath`` (a lane of
the scene, a pavement, a line across the road). Where it is at time t:

- along the lane, ``s(t)`` of a ``SpeedProfile``: the speed eases from one knot's value to
  the next with a smoothstep, so the acceleration is continuous (zero at the knots);
- across it, ``l(t)`` of an ``OffsetProfile`` (a lane change, pulling out of a parking
  place): a smootherstep between knots, continuous in its second derivative;
- its heading follows the lane, turned by ``atan(l' / max(s', 0.5 m/s))`` while it changes
  lane; its pitch follows the lane's grade.

``Actor.motion_at`` gives what the simulator needs (``simlidar.actors``): the pose,
the velocity of the origin and the angular velocity, in the world. The package
knows nothing of the simulator: an actor is plain data and numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from scipy.interpolate import CubicSpline

KINDS = ("car", "van", "lorry", "bus", "cyclist", "pedestrian")
LABEL_OF_KIND = {"car": "vehicle", "van": "vehicle", "lorry": "vehicle", "bus": "vehicle", "cyclist": "person",
                 "pedestrian": "person"}
HEADING_SPEED_M_S = 0.5  # below this speed a sideways motion turns the heading less (a car steers while rolling)
DIFF_S = 1e-3  # the step of the velocities' central differences, s


# ---------------------------------------------------------------- models
@dataclass(frozen=True)
class ActorModel:
    """A moving object's mesh in its own frame: x forward, y left, z up, origin on the ground under its centre.

    vertices (V, 3) m, faces (F, 3) wound outward; box_centre, box_size (3,): its bounding box, m.
    """

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    box_centre: np.ndarray
    box_size: np.ndarray

    @property
    def length_m(self) -> float:
        return float(self.box_size[0])

    @property
    def width_m(self) -> float:
        return float(self.box_size[1])

    @property
    def height_m(self) -> float:
        return float(self.box_size[2])


def _merge(parts) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.util.concatenate(parts)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def _box(size, centre):
    import trimesh

    b = trimesh.creation.box(extents=size)
    b.apply_translation(centre)
    return b


def _hull(points):
    import trimesh

    return trimesh.convex.convex_hull(np.asarray(points, float))


def _cylinder(radius, length, centre, axis):
    """A cylinder of ``length`` along ``axis`` ("x", "y" or "z") centred at ``centre``."""
    import trimesh

    c = trimesh.creation.cylinder(radius=radius, height=length, sections=12)
    if axis == "y":
        c.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    elif axis == "x":
        c.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    c.apply_translation(centre)
    return c


def _capsule(radius, length, bottom, tilt_y=0.0):
    """A capsule ``length`` long (its ends included) standing on ``bottom``, leaning ``tilt_y`` rad forward."""
    import trimesh

    c = trimesh.creation.capsule(height=max(length - 2 * radius, 1e-3), radius=radius, count=[8, 8])
    c.apply_translation([0, 0, length / 2])  # the capsule is centred on its middle
    if tilt_y:
        c.apply_transform(trimesh.transformations.rotation_matrix(tilt_y, [0, 1, 0]))
    c.apply_translation(bottom)
    return c


def _wheels(xs, half_track, radius, width):
    return [_cylinder(radius, width, (x, side * half_track, radius), "y") for x in xs for side in (-1, 1)]


def _car(name, length, width, height, cabin_from, cabin_to):
    """A passenger car: a body, a cabin (a trapezoid prism, narrower at the roof) and four wheels."""
    clearance, body_h = 0.22, 0.68
    zb, zt = clearance + body_h, height
    yb, yt = 0.47 * width, 0.40 * width
    x0, x1 = cabin_from * length, cabin_to * length
    cabin = _hull([[x, y, zb] for x in (x0, x1) for y in (-yb, yb)]
                  + [[x, y, zt] for x in (x0 + 0.12 * length, x1 - 0.16 * length) for y in (-yt, yt)])
    parts = [_box((length, width, body_h), (0, 0, clearance + body_h / 2)), cabin]
    parts += _wheels((-0.32 * length, 0.32 * length), 0.5 * width - 0.12, 0.31, 0.21)
    return name, "car", parts


def _van(name, length, width, height):
    """A panel van: a tall box body with a sloping bonnet and windscreen at the front, four wheels."""
    clearance = 0.3
    back = -length / 2
    nose = length / 2
    body = _hull([[x, y, z] for x in (back, nose - 1.0) for y in (-width / 2, width / 2) for z in (clearance, height)]
                 + [[nose, y, z] for y in (-width / 2, width / 2) for z in (clearance, clearance + 0.9)]
                 + [[nose - 0.4, y, height - 0.55] for y in (-width / 2 + 0.1, width / 2 - 0.1)])
    parts = [body] + _wheels((-0.33 * length, 0.3 * length), 0.5 * width - 0.15, 0.34, 0.24)
    return name, "van", parts


def _lorry(name, length, width, height, cab_length):
    """A rigid lorry: a cab at the front, a box body behind it on a chassis, three axles."""
    clearance = 0.5
    cab_h = min(3.2, height - 0.3)
    front = length / 2
    cab = _box((cab_length, width - 0.05, cab_h - clearance), (front - cab_length / 2, 0, (clearance + cab_h) / 2))
    box_len = length - cab_length - 0.3
    body = _box((box_len, width, height - 1.2), (front - cab_length - 0.3 - box_len / 2, 0, (1.2 + height) / 2))
    chassis = _box((length - 0.4, 0.9, 0.35), (0.2, 0, 0.75))
    xs = (front - 1.4, front - cab_length - 0.3 - 0.6 * box_len, front - cab_length - 0.3 - 0.75 * box_len)
    parts = [cab, body, chassis] + _wheels(xs, 0.5 * width - 0.3, 0.5, 0.6)
    return name, "lorry", parts


def _bus(name, length, width, height):
    """A city bus: a long box body, its front slightly sloped, a band of recessed windows, two axles."""
    clearance = 0.32
    front, back = length / 2, -length / 2
    body = _hull([[x, y, z] for x in (back, front - 0.25) for y in (-width / 2, width / 2) for z in (clearance, height)]
                 + [[front, y, z] for y in (-width / 2, width / 2) for z in (clearance, height - 0.5)])
    parts = [body] + _wheels((front - 2.6, back + 3.2), 0.5 * width - 0.3, 0.5, 0.3)
    return name, "bus", parts


def _cyclist(name, rider_height):
    """A bicycle (two wheels, a frame, handlebars) and its rider leaning forward (legs, torso, arms, head)."""
    wheel_r, base = 0.34, 1.05
    parts = [_cylinder(wheel_r, 0.04, (x, 0, wheel_r), "y") for x in (-base / 2, base / 2)]
    parts.append(_hull([[-base / 2, -0.02, wheel_r], [-base / 2, 0.02, wheel_r], [base / 2, -0.02, wheel_r],
                        [base / 2, 0.02, wheel_r], [-0.1, -0.02, 0.85], [-0.1, 0.02, 0.85], [0.35, -0.02, 0.95],
                        [0.35, 0.02, 0.95]]))  # the frame, a thin plate
    parts.append(_box((0.06, 0.55, 0.04), (0.4, 0, 1.0)))  # handlebars
    scale = rider_height / 1.75
    seat = np.array([-0.12, 0.0, 0.92])
    for side in (-1, 1):
        parts.append(_capsule(0.07, 0.85 * scale, (0.05, side * 0.1, 0.3), tilt_y=-0.35))  # legs to the pedals
        parts.append(_capsule(0.045, 0.6 * scale, seat + (0.25, side * 0.2, 0.45 * scale), tilt_y=1.2))  # arms
    parts.append(_capsule(0.16, 0.62 * scale, seat + (0, 0, 0.05), tilt_y=0.45))  # torso leaning forward
    parts.append(_ball(0.11 * scale, seat + (0.38 * scale, 0, 0.62 * scale)))
    return name, "cyclist", parts


def _ball(radius, centre):
    import trimesh

    b = trimesh.creation.icosphere(subdivisions=1, radius=radius)
    b.apply_translation(centre)
    return b


def _pedestrian(name, height, bag: bool = False):
    """A person standing: two legs, a torso, two arms, a head (and a bag on the side)."""
    scale = height / 1.75
    leg_len, torso_len = 0.88 * scale, 0.58 * scale
    parts = []
    for side in (-1, 1):
        parts.append(_capsule(0.075 * scale, leg_len, (0, side * 0.1 * scale, 0)))
        parts.append(_capsule(0.045 * scale, 0.62 * scale, (0, side * 0.24 * scale, leg_len + 0.05 * scale)))
    parts.append(_capsule(0.17 * scale, torso_len, (0, 0, leg_len - 0.05 * scale)))
    parts.append(_ball(0.11 * scale, (0, 0, height - 0.11 * scale)))
    if bag:
        parts.append(_box((0.3, 0.12, 0.35), (0, 0.33 * scale, 0.75 * scale)))
    return name, "pedestrian", parts


@cache
def models() -> dict[str, ActorModel]:
    """The catalogue of actor models by name (built once; sizes of common real vehicles and people)."""
    specs = [
        _car("car-hatchback", 4.05, 1.75, 1.45, -0.32, 0.18),
        _car("car-saloon", 4.75, 1.82, 1.45, -0.3, 0.15),
        _car("car-suv", 4.6, 1.9, 1.72, -0.36, 0.2),
        _van("van", 5.3, 2.0, 2.45),
        _lorry("lorry-rigid", 10.0, 2.55, 3.8, 2.3),
        _lorry("lorry-long", 12.0, 2.55, 4.0, 2.4),
        _bus("bus", 12.0, 2.55, 3.1),
        _cyclist("cyclist", 1.75),
        _pedestrian("pedestrian-tall", 1.82),
        _pedestrian("pedestrian", 1.7, bag=True),
        _pedestrian("pedestrian-child", 1.3),
    ]
    out = {}
    for name, kind, parts in specs:
        v, f = _merge(parts)
        lo, hi = v.min(axis=0), v.max(axis=0)
        out[name] = ActorModel(name, kind, v, f, (lo + hi) / 2, hi - lo)
    return out


def models_of(kind: str) -> list[ActorModel]:
    """The models of a class (``KINDS``)."""
    found = [m for m in models().values() if m.kind == kind]
    if not found:
        raise ValueError(f"unknown actor class {kind!r} (known: {', '.join(KINDS)})")
    return found


# ---------------------------------------------------------------- motion along and across a lane
def _smoothstep(u):
    return u * u * (3 - 2 * u)


class SpeedProfile:
    """Distance along a lane against time, its speed easing between knots.

    times (k,) s increasing, speeds (k,) m/s >= 0, s0: the distance at ``times[0]``, m. Between
    knots the speed is ``v_i + (v_{i+1} - v_i) smoothstep(u)``; before the first knot and after
    the last it holds. ``distance``, ``speed`` and ``accel`` take arrays of times.
    """

    def __init__(self, times, speeds, s0: float = 0.0):
        self.t = np.asarray(times, dtype=float)
        self.v = np.asarray(speeds, dtype=float)
        if self.t.ndim != 1 or len(self.t) < 1 or self.t.shape != self.v.shape:
            raise ValueError("a speed profile needs as many speeds as times, at least one")
        if np.any(np.diff(self.t) <= 0) or np.any(self.v < 0):
            raise ValueError("a speed profile's times must increase and its speeds be >= 0")
        self.s0 = float(s0)
        dt = np.diff(self.t)
        self._s = self.s0 + np.concatenate([[0.0], np.cumsum(dt * (self.v[:-1] + self.v[1:]) / 2)])

    def _where(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, max(len(self.t) - 2, 0))
        return t, i

    def distance(self, t) -> np.ndarray:
        t, i = self._where(t)
        if len(self.t) == 1:
            return self.s0 + self.v[0] * (t - self.t[0])
        dt = self.t[i + 1] - self.t[i]
        u = np.clip((t - self.t[i]) / dt, 0.0, 1.0)
        dv = self.v[i + 1] - self.v[i]
        inside = self._s[i] + dt * (self.v[i] * u + dv * (u**3 - u**4 / 2))
        before = self._s[0] + self.v[0] * (t - self.t[0])
        after = self._s[-1] + self.v[-1] * (t - self.t[-1])
        return np.where(t < self.t[0], before, np.where(t > self.t[-1], after, inside))

    def speed(self, t) -> np.ndarray:
        t, i = self._where(t)
        if len(self.t) == 1:
            return np.full(len(t), self.v[0])
        u = np.clip((t - self.t[i]) / (self.t[i + 1] - self.t[i]), 0.0, 1.0)
        return self.v[i] + (self.v[i + 1] - self.v[i]) * _smoothstep(u)

    def accel(self, t) -> np.ndarray:
        t, i = self._where(t)
        if len(self.t) == 1:
            return np.zeros(len(t))
        dt = self.t[i + 1] - self.t[i]
        u = (t - self.t[i]) / dt
        a = (self.v[i + 1] - self.v[i]) / dt * 6 * u * (1 - u)
        return np.where((u < 0) | (u > 1), 0.0, a)

    def shifted(self, dt_s: float, ds_m: float) -> SpeedProfile:
        """The same profile ``dt_s`` later and ``ds_m`` farther along: a vehicle following in a queue."""
        return SpeedProfile(self.t + dt_s, self.v, self.s0 + ds_m)


class OffsetProfile:
    """A lateral offset against time: held between changes, each a smootherstep (continuous acceleration).

    times (k,) s increasing, values (k,) m (left of the lane positive).
    """

    def __init__(self, times=(0.0,), values=(0.0,)):
        self.t = np.asarray(times, dtype=float)
        self.y = np.asarray(values, dtype=float)
        if self.t.shape != self.y.shape or len(self.t) < 1 or np.any(np.diff(self.t) <= 0):
            raise ValueError("an offset profile needs increasing times and one value each")

    def value(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if len(self.t) == 1:
            return np.full(len(t), self.y[0])
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        u = np.clip((t - self.t[i]) / (self.t[i + 1] - self.t[i]), 0.0, 1.0)
        w = u**3 * (10 - 15 * u + 6 * u * u)
        return self.y[i] + (self.y[i + 1] - self.y[i]) * w

    def rate(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if len(self.t) == 1:
            return np.zeros(len(t))
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        dt = self.t[i + 1] - self.t[i]
        u = (t - self.t[i]) / dt
        r = (self.y[i + 1] - self.y[i]) / dt * 30 * u * u * (1 - u) ** 2
        return np.where((u < 0) | (u > 1), 0.0, r)


class LanePath:
    """A lane's centre line: (m, 3) points (road height) about 0.5 m apart, in the direction of travel.

    closed: a loop (distances wrap). Position, unit tangent and left normal (horizontal), grade
    at distances along it, from cubic splines of the points (continuous curvature).
    """

    def __init__(self, points: np.ndarray, closed: bool):
        p = np.asarray(points, dtype=float)
        if closed:
            p = np.vstack([p, p[:1]])
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))])
        keep = np.concatenate([[True], np.diff(knots) > 1e-6])
        p, knots = p[keep], knots[keep]
        self.closed = closed
        self.length_m = float(knots[-1])
        self._spline = CubicSpline(knots, p, bc_type="periodic" if closed else "natural")

    def _s(self, s):
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return s % self.length_m if self.closed else s

    def point(self, s) -> np.ndarray:
        return self._spline(self._s(s))

    def frame(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(point (n, 3), tangent (n, 2) unit horizontal, left (n, 2), grade (n,) dz/ds) at distances s."""
        s = self._s(s)
        p = self._spline(s)
        d = self._spline(s, 1)
        h = np.hypot(d[:, 0], d[:, 1])
        tan = d[:, :2] / np.maximum(h, 1e-12)[:, None]
        return p, tan, np.stack([-tan[:, 1], tan[:, 0]], axis=1), d[:, 2] / np.maximum(h, 1e-12)

    def reversed(self) -> LanePath:
        """The same line driven the other way."""
        s = np.linspace(0.0, self.length_m, max(4, int(np.ceil(self.length_m / 0.5)) + 1))
        pts = self.point(s)[::-1]
        return LanePath(pts[:-1] if self.closed else pts, self.closed)


@dataclass
class Actor:
    """One moving object: its model on a lane, its speed profile along it, its offset across it.

    model: an ``ActorModel``; lane: a ``LanePath``; along: ``SpeedProfile`` (distance along the lane, s);
    across: ``OffsetProfile`` (left of the lane, m); lift_m: its height above the lane (a pavement's kerb);
    time_span_s: (t_on, t_off) while it is in the world; behaviour: what it does (a word).
    """

    model: ActorModel
    lane: LanePath
    along: SpeedProfile
    across: OffsetProfile
    behaviour: str
    time_span_s: tuple[float, float]
    lift_m: float = 0.0

    @property
    def kind(self) -> str:
        return self.model.kind

    @property
    def label(self) -> str:
        return LABEL_OF_KIND[self.model.kind]

    def place_at(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(origin (n, 3), yaw (n,), pitch (n,)) at times (n,) s: on the ground, heading along its motion."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        s = self.along.distance(t)
        l = self.across.value(t)
        p, tan, left, grade = self.lane.frame(s)
        pos = p.copy()
        pos[:, :2] += l[:, None] * left
        pos[:, 2] += self.lift_m
        yaw = np.arctan2(tan[:, 1], tan[:, 0]) + np.arctan2(self.across.rate(t),
                                                            np.maximum(self.along.speed(t), HEADING_SPEED_M_S))
        pitch = -np.arctan(grade)
        return pos, yaw, pitch

    def motion_at(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(T_world_actor (n, 4, 4), velocity of the origin (n, 3) m/s, angular velocity (n, 3) rad/s) at times (n,)."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        n = len(t)
        pos, yaw, pitch = self.place_at(np.concatenate([t, t - DIFF_S, t + DIFF_S]))
        cy, sy, cp, sp = np.cos(yaw[:n]), np.sin(yaw[:n]), np.cos(pitch[:n]), np.sin(pitch[:n])
        T = np.tile(np.eye(4), (n, 1, 1))
        T[:, 0, 0], T[:, 0, 1], T[:, 0, 2] = cy * cp, -sy, cy * sp
        T[:, 1, 0], T[:, 1, 1], T[:, 1, 2] = sy * cp, cy, sy * sp
        T[:, 2, 0], T[:, 2, 1], T[:, 2, 2] = -sp, 0.0, cp
        T[:, :3, 3] = pos[:n]
        velocity = (pos[2 * n:] - pos[n:2 * n]) / (2 * DIFF_S)
        yaw_rate = (np.unwrap(np.stack([yaw[n:2 * n], yaw[2 * n:]]), axis=0)[1]
                    - np.unwrap(np.stack([yaw[n:2 * n], yaw[2 * n:]]), axis=0)[0]) / (2 * DIFF_S)
        pitch_rate = (pitch[2 * n:] - pitch[n:2 * n]) / (2 * DIFF_S)
        omega = np.zeros((n, 3))
        omega[:, 2] = yaw_rate
        omega[:, 0], omega[:, 1] = -sy * pitch_rate, cy * pitch_rate  # about the yawed y axis
        return T, velocity, omega

    def footprint_at(self, times) -> tuple[np.ndarray, np.ndarray]:
        """(box centre on the ground (n, 2), yaw (n,)) at times (n,): where it stands, seen from above."""
        pos, yaw, _ = self.place_at(times)
        c = self.model.box_centre
        centre = pos[:, :2] + c[0] * np.stack([np.cos(yaw), np.sin(yaw)], 1) + c[1] * np.stack(
            [-np.sin(yaw), np.cos(yaw)], 1)
        return centre, yaw


__all__ = ["KINDS", "Actor", "ActorModel", "LanePath", "OffsetProfile", "SpeedProfile", "models", "models_of"]
