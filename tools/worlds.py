"""A procedural scene as the simulator's world: build it, describe it for a manifest, export its mesh.

The one place where ``scenes`` (which knows nothing of the simulator) meets
``simlidar.world.World`` (which knows nothing of scenes).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def jsonable(value: Any) -> Any:
    """Numpy scalars and arrays to plain Python, recursively (for manifests)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def world_of_scene(scene, source: str | None = None):
    """A built ``scenes`` scene as a ``simlidar.world.World`` (source: default ``scene:NAME``)."""
    from simlidar.world import World

    return World(scene.vertices, scene.faces, scene.face_object_id, scene.object_labels,
                 f"scene:{scene.name}" if source is None else source)


def build_world_and_trajectory(name: str, seed: int, overrides: dict[str, Any]):
    """Build scene ``name`` and wrap it for the simulator.

    Returns (``simlidar.world.World``, the scene's trajectory, info) where info is a
    JSON-able dict for the sequence manifest: ``scene``, ``scene_seed``, ``scene_params``
    (resolved, seed included), ``scene_metadata``, ``trajectory_duration_s``,
    ``mesh_sha256``. Raises ValueError naming an unknown scene or a bad parameter.
    """
    import scenes

    if "seed" in overrides:
        raise ValueError(f"parameter seed: give the seed as the seed argument ({seed}), not among the overrides "
                         f"(seed={overrides['seed']!r})")
    scene = scenes.build_scene(name, seed=seed, **overrides)
    info = {
        "scene": name,
        "scene_seed": int(seed),
        "scene_params": jsonable(scene.params),
        "scene_metadata": jsonable(scene.metadata),
        "trajectory_duration_s": float(scene.trajectory.duration_s),
        "mesh_sha256": scene.mesh_hash(),
    }
    return world_of_scene(scene, f"scene:{name}"), scene.trajectory, info


def export_scene(scene, out: Path) -> Path:
    """Write a scene's mesh: .ply (object_id per face, labels in the header) or .glb (a node per object)."""
    out = Path(out)
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".ply":
        from simlidar.world import save_world_ply

        save_world_ply(world_of_scene(scene, scene.name), out)
    elif suffix == ".glb":
        import trimesh

        order = np.argsort(scene.face_object_id, kind="stable")
        ids = scene.face_object_id[order]
        bounds = np.flatnonzero(np.diff(ids)) + 1
        tscene = trimesh.Scene()
        for chunk in np.split(order, bounds):
            obj = int(scene.face_object_id[chunk[0]])
            faces = scene.faces[chunk]
            used, inverse = np.unique(faces, return_inverse=True)
            mesh = trimesh.Trimesh(scene.vertices[used], inverse.reshape(faces.shape), process=False)
            name = f"{scene.object_labels[obj]}_{obj:06d}"
            tscene.add_geometry(mesh, node_name=name, geom_name=name)
        tmp = out.with_name(out.name + ".tmp")
        tmp.write_bytes(tscene.export(file_type="glb"))
        tmp.replace(out)
    else:
        raise ValueError(f"{out}: unsupported mesh format {out.suffix!r} (use .ply or .glb)")
    return out


def path_length_m(path: np.ndarray) -> float:
    """Length of a polyline (N, 3), m."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


__all__ = ["build_world_and_trajectory", "export_scene", "jsonable", "path_length_m", "world_of_scene"]
