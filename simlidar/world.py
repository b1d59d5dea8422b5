"""A world to scan: a triangle mesh, an object id per triangle and a label per object.

Loaded from PLY / OBJ / GLB / STL through trimesh, or built by ``scenes``.
Object ids come from, in order: a PLY face property ``object_id`` (what
``salo scene --out x.ply`` writes), the geometries of a multi-part file (one id
each, labelled by the geometry's name), else a single object 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Diffuse reflectance at 905 nm by object class, used by the intensity model.
# Rounded figures typical of the literature (asphalt dark, vegetation bright in
# the near infrared, signs retro-reflective).
LABEL_REFLECTANCE = {
    "ground": 0.15,
    "road": 0.12,
    "sidewalk": 0.3,
    "kerb": 0.35,
    "building": 0.35,
    "wall": 0.4,
    "roof": 0.25,
    "vehicle": 0.3,
    "pole": 0.5,
    "sign": 0.9,
    "vegetation": 0.6,
    "rock": 0.35,
    "rail": 0.6,
    "light": 0.7,
    "object": 0.4,
    "person": 0.35,  # clothing, 0.1 to 0.6 at 905 nm
}
DEFAULT_REFLECTANCE = 0.4


class WorldError(ValueError):
    """A mesh file cannot be used as a world; the message names the file."""


@dataclass
class World:
    """vertices: (V, 3) float64 metres; faces: (F, 3) int; face_object_id: (F,) int32.

    object_labels: one class label per object id (see ``LABEL_REFLECTANCE``).
    source: where the mesh came from (file path or scene name), for manifests.
    normals_reliable: every triangle's winding faces out of the solid it bounds, so
        a sensor that sees mostly back faces is inside a solid (``simlidar.inside``).
        True for worlds built in code (the procedural scenes); ``load_world`` sets
        False: a user's mesh may be a room with outward normals, or have flipped
        or inconsistent ones.
    reflectance: (n_objects,) diffuse reflectance per object in [0, 1], or None: from each
        object's label (``LABEL_REFLECTANCE``). ``with_reflectance`` sets it by label or object id.
    actors: moving objects (``simlidar.actors``: cars, lorries, cyclists, pedestrians on trajectories of
        their own); their object ids follow the static world's (``object_count``, ``all_object_labels``).
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_object_id: np.ndarray
    object_labels: list[str] = field(default_factory=list)
    source: str = ""
    normals_reliable: bool = True
    reflectance: np.ndarray | None = None
    actors: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        self.face_object_id = np.asarray(self.face_object_id, dtype=np.int32)
        if len(self.face_object_id) != len(self.faces):
            raise WorldError(f"{self.source or 'world'}: one object id per face is required")
        n_obj = int(self.face_object_id.max()) + 1 if len(self.faces) else 0
        if len(self.object_labels) < n_obj:
            self.object_labels = list(self.object_labels) + ["object"] * (
                n_obj - len(self.object_labels)
            )

        if self.reflectance is not None:
            self.reflectance = np.asarray(self.reflectance, dtype=np.float64)
            if self.reflectance.shape != (len(self.object_labels),):
                raise WorldError(f"{self.source or 'world'}: reflectance needs one value per object "
                                 f"({len(self.object_labels)}), got shape {self.reflectance.shape}")
            if not np.all((self.reflectance >= 0) & (self.reflectance <= 1)):
                raise WorldError(f"{self.source or 'world'}: reflectance must lie in [0, 1]")

    @property
    def object_count(self) -> int:
        """Objects that returns may hit: the static world's, then the actors'."""
        return len(self.object_labels) + len(self.actors)

    @property
    def all_object_labels(self) -> list[str]:
        """The label of every object id: the static world's, then each actor's."""
        return list(self.object_labels) + [a.label for a in self.actors]

    def without_actors(self) -> World:
        """The same world with nothing moving (its static twin)."""
        import dataclasses

        return dataclasses.replace(self, actors=[])

    @property
    def object_reflectance(self) -> np.ndarray:
        """(n_objects,) float reflectance of each object: set (``reflectance``), else from its label."""
        if self.reflectance is not None:
            return self.reflectance
        return np.array(
            [LABEL_REFLECTANCE.get(lbl, DEFAULT_REFLECTANCE) for lbl in self.object_labels]
        )

    def with_reflectance(self, values: dict) -> World:
        """A copy with the reflectance of some objects set: keys are labels (every object of that label)
        or object ids (int, or digits), values in [0, 1]. Raises WorldError naming an unknown key."""
        import dataclasses

        refl = self.object_reflectance.copy()
        labels = np.asarray(self.object_labels, dtype=object)
        for key, value in values.items():
            text = str(key)
            if text.isdigit():
                if int(text) >= len(refl):
                    raise WorldError(f"{self.source or 'world'}: reflectance for object {text}, but the world has "
                                     f"{len(refl)} objects (0..{len(refl) - 1})")
                refl[int(text)] = float(value)
            elif text in set(self.object_labels):
                refl[labels == text] = float(value)
            else:
                raise WorldError(f"{self.source or 'world'}: reflectance for '{text}', which is neither an object "
                                 f"id nor a label of the world ({', '.join(sorted(set(self.object_labels)))})")
        return dataclasses.replace(self, reflectance=refl)

    def to_trimesh(self):
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def load_world(path: str | Path) -> World:
    """Read a mesh file (PLY/OBJ/GLB/GLTF/STL/OFF) into a ``World``; errors name the file.

    Its winding is not trusted (``World.normals_reliable`` False).
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise WorldError(f"{path}: mesh file does not exist")
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as exc:  # trimesh raises many types for broken files
        raise WorldError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None
    if isinstance(loaded, trimesh.Scene):
        parts = []
        for node in loaded.graph.nodes_geometry:
            transform, geom_name = loaded.graph[node]
            g = loaded.geometry[geom_name]
            if isinstance(g, trimesh.Trimesh) and len(g.faces):
                parts.append((str(node), g.copy().apply_transform(transform)))
        if not parts:
            raise WorldError(f"{path}: the file holds no triangles")
        verts, faces, ids, labels, base = [], [], [], [], 0
        for k, (name, g) in enumerate(parts):
            verts.append(np.asarray(g.vertices))
            faces.append(np.asarray(g.faces) + base)
            ids.append(np.full(len(g.faces), k))
            labels.append(_label_from_name(name))
            base += len(g.vertices)
        world = World(np.vstack(verts), np.vstack(faces), np.concatenate(ids), labels, str(path))
    elif isinstance(loaded, trimesh.Trimesh):
        if len(loaded.faces) == 0:
            raise WorldError(f"{path}: the file holds no triangles")
        ids = np.zeros(len(loaded.faces), dtype=np.int32)
        labels: list[str] = []
        raw = loaded.metadata.get("_ply_raw", {}) if isinstance(loaded.metadata, dict) else {}
        face_data = raw.get("face", {}).get("data", None) if isinstance(raw, dict) else None
        if face_data is not None and "object_id" in (face_data.dtype.names or ()):
            ids = np.asarray(face_data["object_id"], dtype=np.int32).reshape(-1)
        comment_labels = _labels_from_ply_header(path) if path.suffix.lower() == ".ply" else []
        if comment_labels:
            labels = comment_labels
        world = World(loaded.vertices, loaded.faces, ids, labels, str(path))
    else:
        raise WorldError(f"{path}: not a triangle mesh (got {type(loaded).__name__})")
    if not np.all(np.isfinite(world.vertices)):
        raise WorldError(f"{path}: mesh has non-finite vertex coordinates")
    world.normals_reliable = False  # a user's mesh: rooms with outward normals, scans with flipped ones
    return world


def _label_from_name(name: str) -> str:
    low = name.lower()
    for label in LABEL_REFLECTANCE:
        if label in low:
            return label
    return "object"


def _labels_from_ply_header(path: Path) -> list[str]:
    """Labels stored as a PLY header comment ``object_labels: a,b,c`` by ``save_world_ply``."""
    with open(path, "rb") as fh:
        header = fh.read(1 << 16).split(b"end_header", 1)[0].decode("ascii", "replace")
    for line in header.splitlines():
        if line.startswith("comment object_labels:"):
            return [s.strip() for s in line.split(":", 1)[1].split(",") if s.strip()]
    return []


def save_world_ply(world: World, path: str | Path) -> None:
    """Write a binary PLY with a per-face ``object_id`` and the labels in a comment."""
    path = Path(path)
    v = world.vertices.astype("<f8")
    f = world.faces.astype("<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment object_labels: {','.join(world.object_labels)}\n"
        f"element vertex {len(v)}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\n"
        "property int object_id\nend_header\n"
    )
    face_rec = np.zeros(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,)), ("oid", "<i4")])
    face_rec["n"] = 3
    face_rec["idx"] = f
    face_rec["oid"] = world.face_object_id
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(v.tobytes())
        fh.write(face_rec.tobytes())
    tmp.replace(path)
