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
        self._face_point = tri[:, 0]
        self.n_faces = len(faces)
        self.threads = max(1, threads or os.cpu_count() or 1)
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def cast_raw(self, origins32: np.ndarray, directions32: np.ndarray, max_distance: np.ndarray):
        """The bare Embree call, threaded: float32 local-frame rays -> (primID, tfar).

        origins32, directions32: (n, 3) float32, already shifted by ``self.offset``.
        max_distance: (n,) float32.
        """
        n = len(origins32)
        if self._pool is None or n < 4096:
            out = self._scene.run(origins32, directions32, dists=max_distance, output=1)
            return out["primID"], out["tfar"]
        bounds = np.linspace(0, n, self.threads + 1).astype(int)

        def run(k: int):
            a, b = bounds[k], bounds[k + 1]
            return self._scene.run(
                origins32[a:b], directions32[a:b], dists=max_distance[a:b], output=1
            )

        parts = list(self._pool.map(run, range(self.threads)))
        return (
            np.concatenate([p["primID"] for p in parts]),
            np.concatenate([p["tfar"] for p in parts]),
        )

    def cast(
        self, origins: np.ndarray, directions: np.ndarray, max_distance: float | np.ndarray
    ) -> RayHits:
        """Cast rays and return the first hit of each.

        origins: (n, 3) or (3,) float64 world coordinates, metres.
        directions: (n, 3) float64 unit vectors.
        max_distance: scalar or (n,) metres; hits beyond it are misses.
        """
        directions = np.asarray(directions, dtype=np.float64)
        n = len(directions)
        local_origins = np.broadcast_to(np.asarray(origins, dtype=np.float64) - self.offset, (n, 3))
        o32 = np.ascontiguousarray(local_origins, dtype=np.float32)
        d32 = np.ascontiguousarray(directions, dtype=np.float32)
        # Embree's own distance is float32; leave margin and cut exactly in float64 below.
        limit = np.broadcast_to(np.asarray(max_distance, dtype=np.float64), (n,))
        dist32 = (limit * (1 + 1e-5) + 1e-3).astype(np.float32)
        face, tfar = self.cast_raw(o32, d32, dist32)
        face = face.astype(np.int64)
        hit = face >= 0
        idx = np.flatnonzero(hit)
        f = face[idx]
        n_f = self._face_normal[f]
        o = local_origins[idx]
        d = directions[idx]
        denom = np.einsum("ij,ij->i", d, n_f)
        num = np.einsum("ij,ij->i", self._face_point[f] - o, n_f)
        grazing = np.abs(denom) < 1e-9
        t = np.where(grazing, tfar[idx].astype(np.float64), num / np.where(grazing, 1.0, denom))
        distance = np.full(n, np.inf)
        distance[idx] = t
        beyond = distance > limit
        face[beyond] = -1
        distance[beyond] = np.inf
        normal = np.zeros((n, 3))
        back = np.zeros(n, dtype=bool)
        # Winding normal points "outside"; a ray hitting it from behind has d.n > 0.
        back[idx] = denom > 0
        normal[idx] = np.where(back[idx, None], -n_f, n_f)
        normal[beyond] = 0.0
        back[beyond] = False
        return RayHits(distance=distance, face=face, normal=normal, back_face=back)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __del__(self):  # pragma: no cover - interpreter shutdown order varies
        try:
            self.close()
        except Exception:
            pass
