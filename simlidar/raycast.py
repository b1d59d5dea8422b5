"""Thin wrapper over Embree (``embreex``): batches of rays -> range, triangle, normal.

Embree works in float32. Far from the origin (a city several km across) a
float32 coordinate has a ulp of about 0.5 mm per km, so the BVH is built on
vertices shifted by the mesh's centre, and every hit's range is recomputed in
float64 against the hit triangle's plane: Embree only decides *which*
triangle is hit, the geometry of the hit is exact to float64.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from .kernels.sweep import solve_hits


@dataclass
class RayHits:
    """Result of casting n rays.

    distance: (n,) float64 metres along the unit direction; inf where nothing was hit.
    face: (n,) int64 index of the hit triangle; -1 on a miss.
    normal: (n, 3) float64 unit normal of the hit triangle, turned to face the ray
        origin (zeros on a miss).
    back_face: (n,) bool, the ray hit the side the mesh's winding calls "inside".
    """

    distance: np.ndarray
    face: np.ndarray
    normal: np.ndarray
    back_face: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.face >= 0


@dataclass
class CompactHits:
    """The rays of a batch that hit something (m of n), float64 geometry.

    ray: (m,) int64 index of the ray in the batch.
    face: (m,) int64 hit triangle.
    distance: (m,) float64 metres along the ray.
    cos_incidence: (m,) float64 signed d . n_face (positive: the back side was hit).
    face_normals: (F, 3) the mesh's unit face normals (the raycaster's table, shared, not copied).
    ``normal`` (m, 3): the hit triangle's unit normal turned towards the ray origin, made when asked.
    With moving objects (``simlidar.actors.merge_hits``): actor (m,) the actor hit (-1: the static
    world; face is then -1 on an actor's row); actor_normal (k, 3) its outward normal in the world and
    actor_velocity (k, 3) the velocity of the point hit, m/s, one row per actor row (``actor >= 0``), in
    order; None without.
    """

    ray: np.ndarray
    face: np.ndarray
    distance: np.ndarray
    cos_incidence: np.ndarray
    face_normals: np.ndarray
    actor: np.ndarray | None = None
    actor_normal: np.ndarray | None = None
    actor_velocity: np.ndarray | None = None

    @property
    def normal(self) -> np.ndarray:
        n = np.take(self.face_normals, self.face, axis=0)
        if self.actor is not None:
            n[self.actor >= 0] = self.actor_normal
        n *= -np.sign(self.cos_incidence)[:, None]  # face the ray origin
        return n

    def select(self, mask: np.ndarray) -> CompactHits:
        """The rows ``mask`` (a boolean mask or ascending indices) picks."""
        if self.actor is None:
            return CompactHits(self.ray[mask], self.face[mask], self.distance[mask], self.cos_incidence[mask],
                               self.face_normals)
        slot = self.actor_slots()[mask]
        slot = slot[slot >= 0]
        return CompactHits(self.ray[mask], self.face[mask], self.distance[mask], self.cos_incidence[mask],
                           self.face_normals, self.actor[mask], self.actor_normal[slot], self.actor_velocity[slot])

    def actor_slots(self) -> np.ndarray:
        """(m,) each row's place in ``actor_normal`` and ``actor_velocity`` (-1 on the static world's rows)."""
        on = self.actor >= 0
        return np.where(on, np.cumsum(on) - 1, -1)


class Raycaster:
    """An Embree BVH over one triangle mesh.

    Args:
        vertices: (V, 3) float, metres.
        faces: (F, 3) int vertex indices.
        threads: worker threads for a batch (Embree releases the GIL); default all cores.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, threads: int | None = None):
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
            raise ValueError(f"vertices must be a non-empty (V, 3) array, got {vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise ValueError(f"faces must be a non-empty (F, 3) array, got {faces.shape}")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError("faces index vertices that do not exist")
        self.offset = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        local = vertices - self.offset
        self._scene = rtcore_scene.EmbreeScene()
        # The mesh object must stay alive as long as the scene uses it.
        self._mesh = TriangleMesh(
            self._scene, np.ascontiguousarray(local, dtype=np.float32), faces.astype(np.int32)
        )
        tri = local[faces]  # (F, 3, 3)
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(cross, axis=1, keepdims=True)
        self._face_normal = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
        self._face_offset = np.einsum("ij,ij->i", self._face_normal, tri[:, 0])  # n . v0
        self.n_faces = len(faces)
        self.threads = max(1, threads or os.cpu_count() or 1)
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def cast_raw(self, origins32: np.ndarray, directions32: np.ndarray, max_distance: np.ndarray):
        """The bare Embree call, threaded: float32 local-frame rays -> (primID, tfar).

        origins32, directions32: (n, 3) float32, already shifted by ``self.offset``.
        max_distance: (n,) float32 (left as it is).
        """
        bounds = np.linspace(0, len(origins32), self.threads + 1).astype(int)

        def run(k: int):
            a, b = bounds[k], bounds[k + 1]
            # (a copy: embreex writes each hit's distance back into the array it is given)
            return self._scene.run(origins32[a:b], directions32[a:b], dists=max_distance[a:b].copy(), output=1)

        parts = self.map(run, list(range(self.threads)))
        return (
            np.concatenate([p["primID"] for p in parts]),
            np.concatenate([p["tfar"] for p in parts]),
        )

    def cast_compact(
        self, origins_local: np.ndarray, directions: np.ndarray, max_distance: float,
        origins32: np.ndarray | None = None, directions32: np.ndarray | None = None,
    ) -> CompactHits:
        """Cast rays in the BVH's local frame (world minus ``self.offset``), one thread.

        origins_local: (n, 3) float64; directions: (n, 3) float64 unit vectors; origins32,
        directions32: their contiguous float32 copies, if the caller has them.
        Embree picks the triangle; the distance is then solved in float64 against
        the triangle's plane, so it is exact to float64 for the given ray.
        """
        n = len(directions)
        o32 = np.ascontiguousarray(origins_local, dtype=np.float32) if origins32 is None else origins32
        d32 = np.ascontiguousarray(directions, dtype=np.float32) if directions32 is None else directions32
        # Embree's distance is float32: leave a margin and cut exactly in float64 below.
        limit32 = np.full(n, max_distance * (1 + 1e-5) + 1e-3, dtype=np.float32)
        prim = self._scene.run(o32, d32, dists=limit32)  # the triangle ids alone: the range is solved below
        ray, face, t, denom, grazing = solve_hits(prim, origins_local, directions, self._face_normal,
                                                  self._face_offset)
        if grazing.any():  # a ray in the triangle's plane: Embree's own distance (asked again for these rays)
            g = ray[grazing]
            t[grazing] = self._scene.run(o32[g], d32[g], dists=limit32[g], output=1)["tfar"]
        hits = CompactHits(ray, face, t, denom, self._face_normal)
        return hits if t.max(initial=0.0) <= max_distance else hits.select(t <= max_distance)

    def cast(self, origins: np.ndarray, directions: np.ndarray, max_distance: float) -> RayHits:
        """Cast rays (world frame) and return the first hit of each, per ray.

        origins: (n, 3) or (3,) float64 world coordinates, metres.
        directions: (n, 3) float64 unit vectors.
        max_distance: metres; hits beyond it are misses.
        """
        directions = np.asarray(directions, dtype=np.float64)
        n = len(directions)
        local = np.broadcast_to(np.asarray(origins, dtype=np.float64) - self.offset, (n, 3))
        bounds = np.linspace(0, n, self.threads + 1).astype(int)
        chunks = [(bounds[k], bounds[k + 1]) for k in range(self.threads)]
        parts = self.map(
            lambda ab: self.cast_compact(local[ab[0]: ab[1]], directions[ab[0]: ab[1]], max_distance),
            chunks,
        )
        distance = np.full(n, np.inf)
        face = np.full(n, -1, dtype=np.int64)
        normal = np.zeros((n, 3))
        back = np.zeros(n, dtype=bool)
        for (a, _), h in zip(chunks, parts, strict=True):
            idx = h.ray + a
            distance[idx] = h.distance
            face[idx] = h.face
            normal[idx] = h.normal
            # The winding normal points "outside"; a ray hitting it from behind has d.n > 0.
            back[idx] = h.cos_incidence > 0
        return RayHits(distance=distance, face=face, normal=normal, back_face=back)

    def map(self, fn, items: list) -> list:
        """Run ``fn`` over items on the worker threads (Embree and numpy release the GIL)."""
        if self._pool is None or len(items) < 2:
            return [fn(it) for it in items]
        return list(self._pool.map(fn, items))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __del__(self):  # pragma: no cover - interpreter shutdown order varies
        try:
            self.close()
        except Exception:
            pass
