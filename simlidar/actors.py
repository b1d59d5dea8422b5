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
are evaluated at ``KNOTS`` instants over the sweep; between them a ray's pose of the
actor is a cubic Hermite of the positions and velocities and a constant-rate turn (to
about a micrometre at 5 m/s^2); only the rays whose direction passes within the actor's
bounding sphere (grown by the motions during the sweep) are cast against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .formats.tracks import TRACK_DTYPE
from .formats.truth import ACTOR_CLASSES, MOVING_SPEED_M_S
from .raycast import CompactHits, Raycaster
from .world import DEFAULT_REFLECTANCE, LABEL_REFLECTANCE

KNOTS = 41  # instants per sweep at which each actor near the sensor is evaluated
CULL_STEP_S = 0.25  # the table of every actor's position that culls those out of reach
CULL_CHUNK_S = 20.0  # the table is filled this many seconds at a time
ANGLE_MARGIN_RAD = 2e-3  # added to every window (rounding, a ray's spread within a column)


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


def _rotvec_rotations(w: np.ndarray) -> np.ndarray:
    """(n, 3) rotation vectors -> (n, 3, 3) rotations (Rodrigues; first order below 1e-8 rad)."""
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    k = w / th[:, None]
    s, c = np.sin(theta), np.cos(theta)
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 0] = -k[:, 2], k[:, 1], k[:, 2]
    K[:, 1, 2], K[:, 2, 0], K[:, 2, 1] = -k[:, 0], -k[:, 1], k[:, 0]
    R = np.eye(3) + s[:, None, None] * K + (1 - c)[:, None, None] * (K @ K)
    if small.any():
        W = np.zeros((int(small.sum()), 3, 3))
        ws = w[small]
        W[:, 0, 1], W[:, 0, 2], W[:, 1, 0] = -ws[:, 2], ws[:, 1], ws[:, 2]
        W[:, 1, 2], W[:, 2, 0], W[:, 2, 1] = -ws[:, 0], -ws[:, 1], ws[:, 0]
        R[small] = np.eye(3) + W
    return R


def _rotvec_of(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations (angles below pi) -> (n, 3) rotation vectors."""
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    s2 = np.linalg.norm(v, axis=1)
    theta = np.arctan2(s2, np.trace(R, axis1=1, axis2=2) - 1.0)
    return v * np.where(s2 > 1e-12, theta / np.where(s2 > 1e-12, s2, 1.0), 0.5)[:, None]


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations -> (n, 4) unit quaternions (w, x, y, z), w >= 0."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()  # (x, y, z, w)
    q = np.concatenate([q[:, 3:], q[:, :3]], axis=1)
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


class ActorSet:
    """The actors of a world, their BVHs and a coarse table of where each is, for the sweeps.

    actors: the actor objects (see the module doc). first_object_id: the id of the first (the
    static world's object count); actor ``i`` has object id ``first_object_id + i``.
    """

    def __init__(self, actors: list, first_object_id: int):
        self.actors = list(actors)
        self.first_object_id = int(first_object_id)
        n = len(self.actors)
        models: dict[str, int] = {}
        self.raycasters: list[Raycaster] = []
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
                models[m.name] = len(self.raycasters)
                self.raycasters.append(Raycaster(m.vertices, m.faces, threads=1))
            self.model_of[i] = models[m.name]
            self.class_code[i] = ACTOR_CLASSES.index(a.kind)
            self.reflectance[i] = LABEL_REFLECTANCE.get(a.label, DEFAULT_REFLECTANCE)
            self.box_centre[i], self.box_size[i] = m.box_centre, m.box_size
            t_on, t_off = a.time_span_s
            if not t_off >= t_on:
                raise ActorError(f"{where}: its time span ends ({t_off}) before it starts ({t_on})")
            self.span[i] = t_on, t_off
        self.radius = 0.5 * np.linalg.norm(self.box_size, axis=1)
        self._cull_table()

    def __len__(self) -> int:
        return len(self.actors)

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
        period = 0.0 if self.frozen else s.sweep_period_s
        self.knot_t = t0 + np.linspace(0.0, period, KNOTS)
        self.dt = period / (KNOTS - 1)
        n = len(idx)
        T = np.empty((n, KNOTS, 4, 4))
        v = np.empty((n, KNOTS, 3))
        w = np.empty((n, KNOTS, 3))
        for j, i in enumerate(idx):
            T[j], v[j], w[j] = aset.actors[i].motion_at(self.knot_t)
        self.alive = (self.knot_t[None] >= aset.span[idx, 0, None]) & (self.knot_t[None] <= aset.span[idx, 1, None])
        self.idx, self.T, self.v, self.w = idx, T, v, w
        # the turn between consecutive knots, as a rotation vector in the earlier knot's frame
        R = T[:, :, :3, :3]
        rel = np.swapaxes(R[:, :-1], -1, -2) @ R[:, 1:]
        self.turn = _rotvec_of(rel.reshape(-1, 3, 3)).reshape(n, KNOTS - 1, 3) if KNOTS > 1 else None
        self.candidates = [self._window(j, T_cols) for j in range(n)]
        keep = [j for j in range(n) if len(self.candidates[j])]
        self._keep = keep

    # ------------------------------------------------------------ which rays may meet an actor
    def _window(self, j: int, T_cols) -> np.ndarray:
        """Sorted global indices of the sweep's rays that may meet actor ``j`` (of this sweep)."""
        s, aset = self.sim.sensor, self.aset
        i = self.idx[j]
        C, rings = s.columns_per_sweep, s.rings
        centre = self.T[j, :, :3, :3] @ aset.box_centre[i] + self.T[j, :, :3, 3]  # (K, 3) world
        col_t = self.t0 + np.arange(C) * (0.0 if self.frozen else s.column_period_s)
        if T_cols is None:
            Rc = np.broadcast_to(self.T_ref[:3, :3], (C, 3, 3))
            pc = np.broadcast_to(self.T_ref[:3, 3], (C, 3))
        else:
            Rc, pc = T_cols[:C, :3, :3], T_cols[:C, :3, 3]
        if self.frozen:
            c_at = np.broadcast_to(centre[0], (C, 3))
            alive = np.full(C, bool(self.alive[j, 0]))
        else:
            c_at = np.stack([np.interp(col_t, self.knot_t, centre[:, k]) for k in range(3)], axis=1)
            alive = np.interp(col_t, self.knot_t, self.alive[j].astype(float)) > 0
        rel = np.einsum("cji,cj->ci", Rc, c_at - pc)  # the centre in the sensor frame at each column
        dist = np.linalg.norm(rel, axis=1)
        speed = float(np.linalg.norm(self.v[j], axis=1).max())
        # within a column the actor moves by speed x column period, and the Hermite curve stays within 1 mm
        r = aset.radius[i] + speed * s.column_period_s + 0.01
        spread = ANGLE_MARGIN_RAD + np.radians(4.0 * s.angular_jitter_deg + 0.5 * s.beam_divergence_deg)
        inside = dist <= r
        half = np.arcsin(np.clip(r / np.maximum(dist, 1e-9), 0.0, 1.0)) + spread
        half_az = half + (np.abs(s.ring_azimuth_offset_rad).max() if rings else 0.0)
        az = np.arctan2(rel[:, 1], rel[:, 0])
        col_az = s.column_azimuth_rad(np.arange(C))
        d_az = np.abs((col_az - az + np.pi) % (2 * np.pi) - np.pi)
        horiz = np.hypot(rel[:, 0], rel[:, 1])
        # within reach (the box's nearest point no farther than the maximum range), alive, and facing it
        cols = np.flatnonzero(alive & (dist - r <= s.max_range_m) & (inside | (d_az <= half_az)))
        if len(cols) == 0:
            return np.zeros(0, np.int64)
        if inside[cols].any():
            ring_sel = np.arange(rings)
        else:
            el = np.arctan2(rel[cols, 2], horiz[cols])
            lo, hi = float((el - half[cols]).min()), float((el + half[cols]).max())
            ring_sel = np.flatnonzero((s.elevation_rad >= lo) & (s.elevation_rad <= hi))
        if len(ring_sel) == 0:
            return np.zeros(0, np.int64)
        return (cols[:, None] * rings + ring_sel[None, :]).ravel()

    # ------------------------------------------------------------ casting
    def _poses(self, j: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R (n, 3, 3), p (n, 3)) of this sweep's actors ``j`` (n,) at times ``t`` (n,): Hermite positions,
        constant-rate turns between knots."""
        if self.frozen or self.dt == 0:
            return self.T[j, 0, :3, :3], self.T[j, 0, :3, 3]
        x = np.clip((t - self.t0) / self.dt, 0.0, KNOTS - 1 - 1e-12)
        k = x.astype(np.int64)
        u = x - k
        p0, p1 = self.T[j, k, :3, 3], self.T[j, k + 1, :3, 3]
        v0, v1 = self.v[j, k] * self.dt, self.v[j, k + 1] * self.dt
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
        p = h00[:, None] * p0 + h10[:, None] * v0 + h01[:, None] * p1 + h11[:, None] * v1
        R = self.T[j, k, :3, :3] @ _rotvec_rotations(self.turn[j, k] * u[:, None])
        return R, p

    def _velocity(self, j: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(velocity of the origin (n, 3), angular velocity (n, 3)) of actors ``j`` at ``t``, linear between knots."""
        if self.frozen or self.dt == 0:
            return self.v[j, 0], self.w[j, 0]
        x = np.clip((t - self.t0) / self.dt, 0.0, KNOTS - 1 - 1e-12)
        k = x.astype(np.int64)
        u = (x - k)[:, None]
        return (self.v[j, k] * (1 - u) + self.v[j, k + 1] * u, self.w[j, k] * (1 - u) + self.w[j, k + 1] * u)

    def cast(self, rows_of: list[np.ndarray], origin_world: np.ndarray, direction: np.ndarray,
             ray_time: np.ndarray, max_distance: float) -> ActorHits | None:
        """The nearest actor hit of each of a call's rays.

        rows_of: per actor of this sweep (index j), the rows of the call's rays that may meet it.
        origin_world, direction: (n, 3) the call's rays in the world; ray_time: (n,) s.
        """
        js = [np.full(len(r), j, np.int64) for j, r in enumerate(rows_of) if len(r)]
        if not js:
            return None
        rows = np.concatenate([r for r in rows_of if len(r)])
        j = np.concatenate(js)
        R, p = self._poses(j, ray_time[rows])
        o_a = np.einsum("nji,nj->ni", R, origin_world[rows] - p)
        d_a = np.einsum("nji,nj->ni", R, direction[rows])
        model = self.aset.model_of[self.idx[j]]
        found = []
        for m in np.unique(model):
            sel = np.flatnonzero(model == m)
            rc = self.aset.raycasters[m]
            h = rc.cast_compact(np.ascontiguousarray(o_a[sel] - rc.offset), np.ascontiguousarray(d_a[sel]),
                                max_distance)
            if len(h.ray):
                found.append((sel[h.ray], h.distance, h.cos_incidence, rc._face_normal[h.face]))
        if not found:
            return None
        sel = np.concatenate([f[0] for f in found])
        dist = np.concatenate([f[1] for f in found])
        cos = np.concatenate([f[2] for f in found])
        n_model = np.concatenate([f[3] for f in found])
        # the nearest actor per ray
        order = np.lexsort((dist, rows[sel]))
        sel, dist, cos, n_model = sel[order], dist[order], cos[order], n_model[order]
        first = np.ones(len(sel), bool)
        first[1:] = rows[sel][1:] != rows[sel][:-1]
        sel, dist, cos, n_model = sel[first], dist[first], cos[first], n_model[first]
        normal = np.einsum("nij,nj->ni", R[sel], n_model)
        hit = origin_world[rows[sel]] + direction[rows[sel]] * dist[:, None]
        v, w = self._velocity(j[sel], ray_time[rows[sel]])
        velocity = v + np.cross(w, hit - p[sel])
        return ActorHits(rows[sel], dist, cos, normal, self.idx[j[sel]], velocity)

    def block_rows(self, a: int, b: int) -> list[np.ndarray]:
        """Per actor of this sweep, the rays of the block a:b (global firing indices) that may meet it, as rows
        of the block (0 .. b - a - 1)."""
        out = []
        for c in self.candidates:
            lo, hi = np.searchsorted(c, a), np.searchsorted(c, b)
            out.append(c[lo:hi] - a)
        return out

    def rows_of_rays(self, rays: np.ndarray) -> list[np.ndarray]:
        """Per actor, the rows of ``rays`` (sorted global firing indices, repeats allowed) that may meet it."""
        out = []
        for c in self.candidates:
            if len(c) == 0 or len(rays) == 0:
                out.append(np.zeros(0, np.int64))
                continue
            pos = np.clip(np.searchsorted(c, rays), 0, len(c) - 1)
            out.append(np.flatnonzero(c[pos] == rays))
        return out

    # ------------------------------------------------------------ per frame truth
    def tracks(self, scan_object_id: np.ndarray) -> np.ndarray:
        """(n,) ``TRACK_DTYPE`` rows: the actors alive at the sweep's start whose box comes within the sensor's
        maximum range, in the scan frame at the sweep's start; returns counted in ``scan_object_id``."""
        aset, s = self.aset, self.sim.sensor
        T0 = self.T[:, 0]
        centre = T0[:, :3, :3] @ aset.box_centre[self.idx][..., None]
        centre = centre[..., 0] + T0[:, :3, 3]
        R_ref, p_ref = self.T_ref[:3, :3], self.T_ref[:3, 3]
        reach = np.linalg.norm(centre - p_ref, axis=1) - 0.5 * np.linalg.norm(aset.box_size[self.idx], axis=1)
        keep = np.flatnonzero(self.alive[:, 0] & (reach <= s.max_range_m))
        rows = np.zeros(len(keep), TRACK_DTYPE)
        if len(keep) == 0:
            return rows
        i = self.idx[keep]
        mine = scan_object_id[scan_object_id >= aset.first_object_id] - aset.first_object_id
        counts = np.bincount(mine, minlength=len(aset))
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


def merge_hits(static: CompactHits, n_rays: int, found: ActorHits | None) -> CompactHits:
    """The nearest of the static world's hit and the actors' hit of each of ``n_rays`` rays.

    The result is ordered by ray, as ``static``; its ``actor`` rows (>= 0) carry the actor's
    normal (world, outward) and the velocity of the point hit.
    """
    if found is None:
        return static
    t_static = np.full(n_rays, np.inf)
    t_static[static.ray] = static.distance
    win = found.distance < t_static[found.ray]
    if not win.any():
        return static
    ray_a = found.ray[win]
    lost = np.zeros(n_rays, bool)
    lost[ray_a] = True
    keep = ~lost[static.ray]
    ray = np.concatenate([static.ray[keep], ray_a])
    order = np.argsort(ray, kind="stable")
    m_s, m_a = int(keep.sum()), len(ray_a)
    face = np.concatenate([static.face[keep], np.full(m_a, -1, np.int64)])[order]
    distance = np.concatenate([static.distance[keep], found.distance[win]])[order]
    cos = np.concatenate([static.cos_incidence[keep], found.cos_incidence[win]])[order]
    actor = np.concatenate([np.full(m_s, -1, np.int64), found.actor[win]])[order]
    normal = np.concatenate([np.zeros((m_s, 3)), found.normal[win]])[order]
    velocity = np.concatenate([np.zeros((m_s, 3)), found.velocity[win]])[order]
    return CompactHits(ray[order], face, distance, cos, static.face_normals, actor, normal, velocity)


__all__ = ["KNOTS", "ActorError", "ActorHits", "ActorSet", "SweepActors", "merge_hits"]
