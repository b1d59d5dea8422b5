"""Moving objects (actors): rigid meshes on trajectories of their own, met by each ray where they are at its time.

A spinning lidar fires its rays over a whole sweep, so it sees a car passing the
other way where the car was at each ray's instant: shortened or stretched in the
scan. Each actor is cast as such: its mesh has a BVH of its own (shared by the
actors of one model), in the actor's frame; a ray that may reach it is moved into
that frame at the ray's firing time, and the nearest of the static world's hit and
the actors' hits is the return.

An actor (``scenes.actors.Actor`` makes them; anything with these members does):

- ``model``: ``.name`` (actors of one model share its BVH), ``.vertices`` (V, 3) and ``.faces``
  (F, 3) in the actor's own frame (x forward, y left, z up, origin on the ground under its
  centre), ``.box_centre`` (3,) and ``.box_size`` (3,): its bounding box in that frame, m;
- ``kind``: its class, one of ``ACTOR_CLASSES[1:]`` (car, van, lorry, bus, cyclist, pedestrian);
- ``label``: its reflectance class (``simlidar.world.LABEL_REFLECTANCE``); ``behaviour``: a word
  for the manifest;
- ``time_span_s``: (t_on, t_off), the time it is in the world, s (outside: nowhere);
- ``motion_at(times)`` -> (T_world_actor (n, 4, 4), velocity (n, 3) of its origin, m/s,
  angular velocity (n, 3), rad/s), in the world, at times (n,) s.

Per sweep (``ActorSet.for_sweep``), the actors that may come within the sensor's range
are evaluated every ``KNOT_STEP_S`` over the sweep (a second's worth at a time, for the
sweeps that follow: ``ActorSet.knots``); between them a ray's pose of the
actor is a cubic Hermite of the positions and velocities and a constant-rate turn (a
micrometre off at 5 m/s^2); only the rays whose direction passes within the actor's
bounding sphere at their column's instant (``kernels.actors.ray_windows``) and then
cross its box (``kernels.actors.rays_in_actor_frame``) are cast against its BVH.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .formats.tracks import TRACK_DTYPE
from .formats.truth import ACTOR_CLASSES, MOVING_SPEED_M_S
from .kernels.actors import merge_rows, nearest_actor_hits, ray_windows, rays_by_block, rays_in_actor_frame
from .raycast import CompactHits, Raycaster
from .world import DEFAULT_REFLECTANCE, LABEL_REFLECTANCE

KNOT_STEP_S = 0.005  # the actors near the sensor are evaluated this often during a sweep (their knots)
KNOT_TABLE = 201  # knots evaluated at once per actor (a second), reused by the sweeps that follow
BOX_MARGIN_M = 0.05  # a candidate ray must cross the actor's box grown by this
CULL_STEP_S = 0.25  # the table of every actor's position that culls those out of reach
CULL_CHUNK_S = 20.0  # the table is filled this many seconds at a time
ANGLE_MARGIN_RAD = 2e-3  # added to every window (rounding, a ray's spread within a column)
_NO_RAYS, _NO_DISTANCES = np.zeros(0, np.int64), np.zeros(0)


class ActorError(ValueError):
    """An actor that cannot be simulated; the message names it and what is wrong."""


@dataclass
class ActorHits:
    """Rows of actor hits: ray (m,) index within the call's rays, distance (m,) m, cos_incidence (m,) d . n,
    normal (m, 3) outward unit normal in the world, actor (m,) index in the ActorSet, velocity (m, 3) of the
    point hit in the world, m/s."""

    ray: np.ndarray
    distance: np.ndarray
    cos_incidence: np.ndarray
    normal: np.ndarray
    actor: np.ndarray
    velocity: np.ndarray


def _rotvec_of(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations (angles below pi) -> (n, 3) rotation vectors."""
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    s2 = np.linalg.norm(v, axis=1)
    theta = np.arctan2(s2, np.trace(R, axis1=1, axis2=2) - 1.0)
    return v * np.where(s2 > 1e-12, theta / np.where(s2 > 1e-12, s2, 1.0), 0.5)[:, None]


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations -> (n, 4) unit quaternions (w, x, y, z), w >= 0 (from the largest of the four's
    squares, as Shepperd's method does)."""
    tr = np.trace(R, axis1=1, axis2=2)
    sq = np.stack([1 + tr, 1 + 2 * R[:, 0, 0] - tr, 1 + 2 * R[:, 1, 1] - tr, 1 + 2 * R[:, 2, 2] - tr], 1)  # 4 q_i^2
    best = np.argmax(sq, axis=1)
    big = np.sqrt(np.maximum(sq[np.arange(len(R)), best], 1e-300)) / 2  # |q_best|
    a, b = (R[:, 2, 1] - R[:, 1, 2]), (R[:, 0, 2] - R[:, 2, 0])
    c, d = (R[:, 1, 0] - R[:, 0, 1]), (R[:, 0, 1] + R[:, 1, 0])
    e, f = (R[:, 0, 2] + R[:, 2, 0]), (R[:, 1, 2] + R[:, 2, 1])
    q = np.empty((len(R), 4))
    rows = [np.stack([4 * big**2, a, b, c], 1), np.stack([a, 4 * big**2, d, e], 1),
            np.stack([b, d, 4 * big**2, f], 1), np.stack([c, e, f, 4 * big**2], 1)]
    for k in range(4):
        on = best == k
        q[on] = rows[k][on] / (4 * big[on, None])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


class ActorSet:
    """The actors of a world, their BVHs and a coarse table of where each is, for the sweeps.

    actors: the actor objects (see the module doc). first_object_id: the id of the first (the
    static world's object count); actor ``i`` has object id ``first_object_id + i``. max_range_m: the
    sensor's (the models' places in their one BVH lie farther apart than a ray can go and come back).
    """

    def __init__(self, actors: list, first_object_id: int, max_range_m: float = 1000.0):
        self.actors = list(actors)
        self.first_object_id = int(first_object_id)
        n = len(self.actors)
        models: dict[str, int] = {}
        meshes: list = []
        self.model_of = np.empty(n, np.int64)
        self.class_code = np.empty(n, np.uint8)
        self.reflectance = np.empty(n)
        self.box_centre = np.empty((n, 3))
        self.box_size = np.empty((n, 3))
        self.span = np.empty((n, 2))
        for i, a in enumerate(self.actors):
            where = f"actor {i} ({getattr(a, 'kind', '?')}, {getattr(a, 'behaviour', '?')})"
            if a.kind not in ACTOR_CLASSES[1:]:
                raise ActorError(f"{where}: class {a.kind!r} is not one of {', '.join(ACTOR_CLASSES[1:])}")
            m = a.model
            if m.name not in models:
                models[m.name] = len(meshes)
                meshes.append(m)
            self.model_of[i] = models[m.name]
            self.class_code[i] = ACTOR_CLASSES.index(a.kind)
            self.reflectance[i] = LABEL_REFLECTANCE.get(a.label, DEFAULT_REFLECTANCE)
            self.box_centre[i], self.box_size[i] = m.box_centre, m.box_size
            t_on, t_off = a.time_span_s
            if not t_off >= t_on:
                raise ActorError(f"{where}: its time span ends ({t_off}) before it starts ({t_on})")
            self.span[i] = t_on, t_off
        self.radius = 0.5 * np.linalg.norm(self.box_size, axis=1)
        self._fleet(meshes, float(max_range_m))
        self._knot_tables: dict[int, tuple] = {}
        self._cull_table()

    def __len__(self) -> int:
        return len(self.actors)

    def _fleet(self, meshes: list, max_range_m: float) -> None:
        """One BVH of every model, each moved to a place of its own on a grid (``model_shift``) farther apart
        than a ray from the sensor (within range of an actor) can reach: a ray in an actor's frame, shifted
        by its model's place, meets that model alone, so the rays of every actor of a block are cast in one
        call."""
        if not meshes:
            self.model_shift, self.fleet = np.zeros((0, 3)), None
            return
        size = max(float(np.ptp(np.asarray(m.vertices), axis=0).max()) for m in meshes)
        spacing = 2.0 * (max_range_m + 1.0) + 2.0 * size + 10.0
        side = int(np.ceil(np.sqrt(len(meshes))))
        self.model_shift = np.array([[spacing * (k % side), spacing * (k // side), 0.0] for k in range(len(meshes))])
        verts, faces, base = [], [], 0
        for m, shift in zip(meshes, self.model_shift, strict=True):
            verts.append(np.asarray(m.vertices, float) + shift)
            faces.append(np.asarray(m.faces, np.int64) + base)
            base += len(m.vertices)
        self.fleet = Raycaster(np.vstack(verts), np.vstack(faces), threads=1)

    def knots(self, i: int, t0: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actor ``i``'s motion (``motion_at``) at the ``n`` knots ``t0 + k KNOT_STEP_S``: from a table of
        ``KNOT_TABLE`` knots kept per actor, evaluated afresh when ``t0`` is not one of its knots (so a
        sequence's sweeps, a whole number of knots apart, evaluate each actor once a second)."""
        table = self._knot_tables.get(i)
        if table is not None:
            x = (t0 - table[0]) / KNOT_STEP_S
            k = int(round(x))
            if abs(x - k) < 1e-6 and 0 <= k and k + n <= len(table[1]):
                return table[1][k:k + n], table[2][k:k + n], table[3][k:k + n]
        times = t0 + np.arange(max(n, KNOT_TABLE)) * KNOT_STEP_S
        T, v, w = self.actors[i].motion_at(times)
        self._knot_tables[i] = (t0, T, v, w)
        return T[:n], v[:n], w[:n]

    @property
    def labels(self) -> list[str]:
        return [a.label for a in self.actors]

    def describe(self) -> list[dict]:
        """Per actor, for a manifest: object id, class, label, model, behaviour, box size (m), time span (s)."""
        return [{"object_id": self.first_object_id + i, "class": a.kind, "label": a.label, "model": a.model.name,
                 "behaviour": a.behaviour, "box_size_m": [round(float(v), 3) for v in self.box_size[i]],
                 "time_span_s": [round(float(v), 3) for v in self.span[i]]} for i, a in enumerate(self.actors)]

    def _cull_table(self) -> None:
        """Start the table of every actor's box centre on a common time grid ``CULL_STEP_S`` apart (NaN where it is
        not in the world), filled a chunk of ``CULL_CHUNK_S`` at a time as sweeps need it; and the farthest each
        moves within a grid step."""
        self._chunks: dict[int, np.ndarray] = {}
        self._step_reach = np.full(len(self.actors), np.inf)

    def _chunk(self, c: int) -> np.ndarray:
        """(n, m, 3) the actors' box centres at the grid times of chunk ``c`` (``_chunk_times``)."""
        if c not in self._chunks:
            t = self._chunk_times(c)
            out = np.full((len(self.actors), len(t), 3), np.nan)
            for i, a in enumerate(self.actors):
                on = (t >= self.span[i, 0] - CULL_STEP_S) & (t <= self.span[i, 1] + CULL_STEP_S)
                if not on.any():
                    continue
                T, v, _ = a.motion_at(np.clip(t[on], *self.span[i]))
                out[i, on] = T[:, :3, :3] @ self.box_centre[i] + T[:, :3, 3]
                reach = float(np.linalg.norm(v, axis=1).max()) * CULL_STEP_S + 1.0
                self._step_reach[i] = reach if not np.isfinite(self._step_reach[i]) else max(self._step_reach[i],
                                                                                              reach)
            self._chunks[c] = out
        return self._chunks[c]

    @staticmethod
    def _chunk_times(c: int) -> np.ndarray:
        n = int(round(CULL_CHUNK_S / CULL_STEP_S))
        return (c * n + np.arange(n + 1)) * CULL_STEP_S

    def near(self, t0: float, t1: float, positions: np.ndarray, times: np.ndarray, reach_m: float) -> np.ndarray:
        """Indices of the actors that exist during [t0, t1] and may come within ``reach_m`` of the sensor
        (its positions (k, 3) at times (k,), spanning [t0, t1])."""
        alive = (self.span[:, 0] <= t1) & (self.span[:, 1] >= t0)
        if not alive.any():
            return np.zeros(0, np.int64)
        c0, c1 = int(np.floor((t0 - CULL_STEP_S) / CULL_CHUNK_S)), int(np.floor((t1 + CULL_STEP_S) / CULL_CHUNK_S))
        grid_t = np.concatenate([self._chunk_times(c) for c in range(c0, c1 + 1)])
        table = np.concatenate([self._chunk(c) for c in range(c0, c1 + 1)], axis=1)
        sel = (grid_t >= t0 - CULL_STEP_S) & (grid_t <= t1 + CULL_STEP_S)
        idx = np.flatnonzero(alive)
        ego = np.stack([np.interp(grid_t[sel], times, positions[:, k]) for k in range(3)], 1)
        centres = table[idx][:, sel]  # (a, g, 3)
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(centres - ego[None], axis=2)
        d = np.where(np.isnan(d), np.inf, d).min(axis=1)
        d[~np.isfinite(d)] = 0.0  # (alive, yet its grid points fall just outside its span: keep it)
        ego_step = float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()) + 1.0
        keep = d - self.radius[idx] - self._step_reach[idx] - ego_step <= reach_m
        return idx[keep]

    def for_sweep(self, sim, t0: float, T_ref: np.ndarray, T_cols: np.ndarray | None) -> SweepActors | None:
        """The actors of the sweep starting at ``t0`` (s) of ``sim`` (a ``SweepSimulator``): None if none can be seen.

        T_ref: (4, 4) the sensor at the sweep's start. T_cols: (C + 1, 4, 4) the sensor at each column's start
        and at the sweep's end in the world (motion distortion), or None (every ray from ``T_ref``, and the
        actors frozen at ``t0``: an instantaneous scan).
        """
        s = sim.sensor
        period = s.sweep_period_s
        if T_cols is None:
            times, positions = np.array([t0, t0 + period]), np.stack([T_ref[:3, 3]] * 2)
        else:
            times = t0 + np.arange(len(T_cols)) * s.column_period_s
            times[-1] = t0 + period
            positions = T_cols[:, :3, 3]
        idx = self.near(t0, t0 + (period if T_cols is not None else 0.0), positions, times, s.max_range_m)
        if len(idx) == 0:
            return None
        return SweepActors(self, idx, sim, t0, T_ref, T_cols)


class SweepActors:
    """The actors near the sensor during one sweep: their knots, which rays may meet each, and the casting."""

    def __init__(self, aset: ActorSet, idx: np.ndarray, sim, t0: float, T_ref: np.ndarray, T_cols):
        s = sim.sensor
        self.aset, self.sim, self.t0 = aset, sim, float(t0)
        self.frozen = T_cols is None
        self.T_ref = T_ref
        nk = 1 if self.frozen else int(np.ceil(s.sweep_period_s / KNOT_STEP_S - 1e-9)) + 1
        self.dt = 0.0 if self.frozen else KNOT_STEP_S
        self.knot_t = t0 + np.arange(nk) * KNOT_STEP_S
        n = len(idx)
        T = np.empty((n, nk, 4, 4))
        v = np.empty((n, nk, 3))
        w = np.empty((n, nk, 3))
        for j, i in enumerate(idx):
            T[j], v[j], w[j] = aset.knots(i, float(t0), nk)
        self.alive = (self.knot_t[None] >= aset.span[idx, 0, None]) & (self.knot_t[None] <= aset.span[idx, 1, None])
        self.idx, self.T, self.v, self.w = idx, T, v, w
        # the turn between consecutive knots, as a rotation vector in the earlier knot's frame
        R = T[:, :, :3, :3]
        rel = np.swapaxes(R[:, :-1], -1, -2) @ R[:, 1:]
        self.turn = np.ascontiguousarray(_rotvec_of(rel.reshape(-1, 3, 3)).reshape(n, nk - 1, 3))
        self.vdt = np.ascontiguousarray(v * self.dt)
        half = aset.box_size[idx] / 2 + BOX_MARGIN_M
        self.box_lo = np.ascontiguousarray(aset.box_centre[idx] - half)
        self.box_hi = np.ascontiguousarray(aset.box_centre[idx] + half)
        # a ray in an actor's frame, shifted by this, is in the frame of the BVH of every model (``ActorSet._fleet``)
        self.shift = aset.model_shift[aset.model_of[idx]] - aset.fleet.offset
        self.candidates = self._windows(T_cols)

    # ------------------------------------------------------------ which rays may meet an actor
    def _windows(self, T_cols) -> list[np.ndarray]:
        """Per actor of this sweep, the sorted global indices of the sweep's rays that may meet it
        (``kernels.actors.ray_windows``)."""
        s, aset = self.sim.sensor, self.aset
        C = s.columns_per_sweep
        centre = np.ascontiguousarray(self.T[:, :, :3, :3] @ aset.box_centre[self.idx][:, None, :, None])[..., 0] \
            + self.T[:, :, :3, 3]
        if self.frozen:
            col_t = np.full(C, self.t0)
            Rc = np.ascontiguousarray(np.broadcast_to(self.T_ref[:3, :3], (C, 3, 3)))
            pc = np.ascontiguousarray(np.broadcast_to(self.T_ref[:3, 3], (C, 3)))
        else:
            col_t = self.t0 + np.arange(C) * s.column_period_s
            Rc, pc = np.ascontiguousarray(T_cols[:C, :3, :3]), np.ascontiguousarray(T_cols[:C, :3, 3])
        speed = np.linalg.norm(self.v, axis=2).max(axis=1)
        # within a column the actor moves by speed x column period; the Hermite curve stays within a millimetre
        radius = aset.radius[self.idx] + speed * s.column_period_s + 0.01
        spread = ANGLE_MARGIN_RAD + np.radians(4.0 * s.angular_jitter_deg + 0.5 * s.beam_divergence_deg)
        az_extra = float(np.abs(s.ring_azimuth_offset_rad).max()) if s.rings else 0.0
        # above and below its centre: its box's half height, and its half length tilted by a pitch or roll of its
        # own (up to a 10 % grade) or of the sensor's (in the sensor frame: up to 0.1 rad, a hard braking dive)
        size = aset.box_size[self.idx]
        half_height = size[:, 2] / 2 + 0.2 * np.hypot(size[:, 0], size[:, 1]) / 2 + 0.05
        counts, rays = ray_windows(np.ascontiguousarray(centre), self.alive, self.knot_t, col_t, Rc, pc, radius,
                                   np.ascontiguousarray(half_height), float(spread), az_extra,
                                   s.column_azimuth_rad(np.arange(C)), np.ascontiguousarray(s.elevation_rad),
                                   float(s.max_range_m))
        self._candidate_rays, self._candidate_counts = rays, counts
        return np.split(rays, np.cumsum(counts)[:-1])

    # ------------------------------------------------------------ casting
    def cast(self, rows: np.ndarray, j: np.ndarray, origin: np.ndarray, offset: np.ndarray, direction: np.ndarray,
             t_rows: np.ndarray, max_distance: float, nearer: CompactHits | None = None) -> ActorHits | None:
        """The nearest actor hit of each of a call's rays that could be the ray's nearest hit.

        rows (n,), j (n,): the rows of the call's rays that may meet an actor, and which (of this sweep's);
        origin + offset (3,), direction: (B, 3) the call's rays in the world; t_rows (n,): each row's time, s.
        nearer: the hits the rays have already (the static world's), or None: a ray is not cast against an
        actor whose box it enters only beyond its hit (``merge_hits`` would keep that hit, the nearer).
        """
        if len(rows) == 0:
            return None
        nearer_ray, nearer_distance = (_NO_RAYS, _NO_DISTANCES) if nearer is None else (nearer.ray, nearer.distance)
        keep, o_a, d_a, R, p = rays_in_actor_frame(rows, j, t_rows, origin, offset, direction, self.T, self.vdt,
                                                   self.turn, self.t0, 0.0 if self.frozen else self.dt, self.box_lo,
                                                   self.box_hi, float(max_distance), nearer_ray, nearer_distance,
                                                   self.shift)
        if len(keep) == 0:
            return None
        fleet = self.aset.fleet
        h = fleet.cast_compact(o_a, d_a, max_distance)
        if len(h.ray) == 0:
            return None
        ray, dist, cos, normal, who, velocity = nearest_actor_hits(
            len(origin), rows, keep, h.ray, h.distance, h.cos_incidence, h.face, fleet._face_normal, R, p, j, t_rows,
            self.idx, origin, offset, direction, self.v, self.w, self.t0, 0.0 if self.frozen else self.dt)
        return ActorHits(ray, dist, cos, normal, who, velocity)

    def split(self, bounds: np.ndarray) -> None:
        """Cut the candidate rays at the sweep's block bounds (global firing indices, ascending): per block, its
        rows that may meet an actor and which (``block_rows``; ``kernels.actors.rays_by_block``)."""
        rows, j, starts = rays_by_block(self._candidate_rays, self._candidate_counts, np.asarray(bounds, np.int64))
        self._blocks = {int(bounds[k]): (rows[starts[k]:starts[k + 1]], j[starts[k]:starts[k + 1]])
                        for k in range(len(bounds) - 1)}

    def block_rows(self, a: int) -> tuple[np.ndarray, np.ndarray]:
        """(rows of the block starting at ray ``a`` that may meet an actor, which actor of this sweep's each)."""
        return self._blocks[a]

    def rows_of_rays(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows of ``rays`` (sorted global firing indices, repeats allowed) that may meet an actor, which)."""
        rows, js = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        for k, c in enumerate(self.candidates):
            if len(c) == 0 or len(rays) == 0:
                continue
            pos = np.clip(np.searchsorted(c, rays), 0, len(c) - 1)
            mine = np.flatnonzero(c[pos] == rays)
            rows.append(mine)
            js.append(np.full(len(mine), k, np.int64))
        return np.concatenate(rows), np.concatenate(js)

    # ------------------------------------------------------------ per frame truth
    def tracks(self, scan_object_id: np.ndarray) -> np.ndarray:
        """(n,) ``TRACK_DTYPE`` rows: the actors alive at the sweep's start whose box comes within the sensor's
        maximum range, and any other the sweep's returns hit (one that came into the world during the sweep),
        in the scan frame at the sweep's start; returns counted in ``scan_object_id``."""
        aset, s = self.aset, self.sim.sensor
        T0 = self.T[:, 0]
        centre = T0[:, :3, :3] @ aset.box_centre[self.idx][..., None]
        centre = centre[..., 0] + T0[:, :3, 3]
        R_ref, p_ref = self.T_ref[:3, :3], self.T_ref[:3, 3]
        reach = np.linalg.norm(centre - p_ref, axis=1) - 0.5 * np.linalg.norm(aset.box_size[self.idx], axis=1)
        mine = scan_object_id[scan_object_id >= aset.first_object_id] - aset.first_object_id
        counts = np.bincount(mine, minlength=len(aset))
        keep = np.flatnonzero((self.alive[:, 0] & (reach <= s.max_range_m)) | (counts[self.idx] > 0))
        rows = np.zeros(len(keep), TRACK_DTYPE)
        if len(keep) == 0:
            return rows
        i = self.idx[keep]
        v = self.v[keep, 0] + np.cross(self.w[keep, 0], centre[keep] - T0[keep, :3, 3])
        rows["object_id"] = aset.first_object_id + i
        rows["object_class"] = aset.class_code[i]
        rows["moving"] = np.linalg.norm(self.v[keep, 0], axis=1) > MOVING_SPEED_M_S
        rows["returns"] = counts[i]
        rows["centre"] = (centre[keep] - p_ref) @ R_ref
        rows["quaternion"] = _quaternion(np.swapaxes(R_ref, 0, 1)[None] @ T0[keep, :3, :3])
        rows["size"] = aset.box_size[i]
        rows["velocity"] = v @ R_ref
        return rows


def merge_hits(static: CompactHits, found: ActorHits | None) -> CompactHits:
    """The nearest of the static world's hit and the actors' hit of each ray
    (``kernels.actors.merge_rows``).

    The result is ordered by ray, as ``static``; its ``actor`` rows (>= 0) carry the actor's
    normal (world, outward) and the velocity of the point hit (one row each, in order).
    """
    if found is None:
        return static
    ray, face, distance, cos, actor, taken = merge_rows(static.ray, static.face, static.distance,
                                                       static.cos_incidence, found.ray, found.distance,
                                                       found.cos_incidence, found.actor)
    if len(taken) == 0:
        return static
    return CompactHits(ray, face, distance, cos, static.face_normals, actor, found.normal[taken],
                       found.velocity[taken])


__all__ = ["KNOT_STEP_S", "KNOT_TABLE", "ActorError", "ActorHits", "ActorSet", "SweepActors", "merge_hits"]
