"""The result of a scene generator, and the builder that assembles its mesh.

A scene is one triangle soup with an object id per triangle and a label per
object (the label vocabulary of the simulator's reflectance table), a drivable
centre-line, and a trajectory of lidar poses along it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

# The labels a scene may use (the simulator maps each to a reflectance).
LABELS = (
    "ground", "road", "sidewalk", "kerb", "building", "wall", "roof", "vehicle",
    "pole", "sign", "vegetation", "rock", "rail", "light", "object", "person",
)


class PoseSource(Protocol):
    """Anything giving ``T_world_lidar`` (n, 4, 4) at times (n,) in seconds."""

    @property
    def duration_s(self) -> float: ...

    def pose_at(self, times: np.ndarray) -> np.ndarray: ...


@dataclass
class Scene:
    """A generated world with its drivable path and lidar trajectory.

    name: scene name ("city", "tunnel", ...).
    vertices: (V, 3) float64 world coordinates, metres, z up.
    faces: (F, 3) int64 vertex indices, wound so normals face outward (ground up).
    face_object_id: (F,) int32 object id of each triangle.
    object_labels: label of each object id (see ``LABELS``).
    path: (M, 3) float64 drivable centre-line polyline at road level, metres.
    trajectory: lidar poses along ``path`` (``pose_at``, ``duration_s``).
    params: resolved parameters, seed included.
    metadata: anything else a user or a test needs (spans, axes, lengths).
    roads: where traffic may go (``scenes.traffic.RoadLayout``), or None: a scene without lanes.
    actors: its moving objects (``scenes.actors.Actor``), put in by ``scenes.build_scene`` when the
        ``traffic`` section is enabled (a scene module may place its own: the stress scenes); None: none yet.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    face_object_id: np.ndarray
    object_labels: list[str]
    path: np.ndarray
    trajectory: PoseSource
    params: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    roads: object | None = None
    actors: list | None = None

    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    def mesh_hash(self) -> str:
        """sha256 of vertices, faces, object ids and labels: equal meshes hash equal."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.faces, dtype="<i8").tobytes())
        h.update(np.ascontiguousarray(self.face_object_id, dtype="<i4").tobytes())
        h.update(",".join(self.object_labels).encode())
        return h.hexdigest()

    def label_of_face(self) -> np.ndarray:
        """(F,) str label of each triangle."""
        return np.asarray(self.object_labels, dtype=object)[self.face_object_id]


class MeshBuilder:
    """Collects parts into one vertex/face array set with a per-triangle object id.

    ``new_object(label)`` opens an object; ``add(vertices, faces, obj)`` appends a
    part to it (parts of one object need not be connected: a car's body and wheels).
    """

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._ids: list[np.ndarray] = []
        self.labels: list[str] = []
        self._n_vertices = 0
        self.n_faces = 0

    def new_object(self, label: str) -> int:
        if label not in LABELS:
            raise ValueError(f"unknown object label {label!r} (use one of {', '.join(LABELS)})")
        self.labels.append(label)
        return len(self.labels) - 1

    def add(self, vertices: np.ndarray, faces: np.ndarray, obj: int) -> None:
        """Append a part: (v, 3) float vertices, (f, 3) int faces local to them, to object ``obj``."""
        vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        if not 0 <= obj < len(self.labels):
            raise ValueError(f"object {obj} was not opened with new_object")
        if len(faces) == 0:
            return
        self._vertices.append(vertices)
        self._faces.append(faces + self._n_vertices)
        self._ids.append(np.full(len(faces), obj, dtype=np.int32))
        self._n_vertices += len(vertices)
        self.n_faces += len(faces)

    def add_object(self, vertices: np.ndarray, faces: np.ndarray, label: str) -> int:
        """A new object made of one part; returns its id."""
        obj = self.new_object(label)
        self.add(vertices, faces, obj)
        return obj

    def add_mesh(self, mesh, obj: int) -> None:
        """Append a ``trimesh.Trimesh`` (or anything with vertices/faces) to object ``obj``."""
        self.add(mesh.vertices, mesh.faces, obj)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
        """(V, 3) float64 vertices, (F, 3) int64 faces, (F,) int32 ids, labels."""
        if not self._faces:
            raise ValueError("the scene holds no triangles")
        return (
            np.vstack(self._vertices),
            np.vstack(self._faces),
            np.concatenate(self._ids),
            list(self.labels),
        )


def check_budget(n_faces: int, max_triangles: int) -> None:
    """Raise if a scene exceeds its face budget (the ``max_triangles`` parameter)."""
    if n_faces > max_triangles:
        raise ValueError(
            f"parameter max_triangles: the scene has {n_faces} triangles, over the budget of "
            f"{max_triangles}; reduce the scene's size or detail, or raise max_triangles"
        )
