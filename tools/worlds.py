"""A procedural scene as the simulator's world: build it, describe it for a manifest, export its mesh.

The one place where ``scenes`` (which knows nothing of the simulator) meets
``simlidar.world.World`` (which knows nothing of scenes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from simlidar.sequence import DEFAULT_FRAME_PERIOD_S


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
    """A built ``scenes`` scene as a ``simlidar.world.World`` (source: default ``scene:NAME``), its moving
    objects (``scene.actors``) with it."""
    from simlidar.world import World

    return World(scene.vertices, scene.faces, scene.face_object_id, scene.object_labels,
                 f"scene:{scene.name}" if source is None else source, actors=list(scene.actors or []))


@dataclass(frozen=True)
class SceneWorld:
    """A procedural scene built for the simulator.

    world: the ``simlidar.world.World`` (source ``scene:NAME``). trajectory: the
    scene's smooth lidar trajectory (``simlidar.trajectory.Trajectory``). info: a
    JSON-able dict for the sequence manifest: ``scene``, ``scene_seed``,
    ``scene_params`` (resolved, seed included), ``scene_metadata``,
    ``trajectory_duration_s``, ``mesh_sha256``.
    """

    world: Any
    trajectory: Any
    info: dict

    def sweeps_available(self, sensor, start_s: float = 0.0) -> int:
        """How many whole sweeps of ``sensor`` fit in the trajectory after ``start_s`` (s)."""
        return int((self.trajectory.duration_s - start_s) / sensor.sweep_period_s)


def build_scene_world(name: str, seed: int, overrides: dict[str, Any]) -> SceneWorld:
    """Build scene ``name`` with ``seed`` and parameter ``overrides`` and wrap it for the simulator.

    Raises ValueError naming an unknown scene or a bad parameter.
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
    return SceneWorld(world_of_scene(scene, f"scene:{name}"), scene.trajectory, info)


@dataclass(frozen=True)
class MeshWorld:
    """A world mesh file and a lidar path through it from a KITTI pose file.

    world: the ``simlidar.world.World``. trajectory: the poses interpolated on SE(3)
    (``simlidar.trajectory.SampledTrajectory``). times: (N,) pose times, s. info:
    manifest entries: ``mesh``, ``mesh_sha256``, ``poses_file`` (and ``times_file``).
    """

    world: Any
    trajectory: Any
    times: np.ndarray
    info: dict

    def sweeps_covered(self, sensor) -> int:
        """How many sweeps, one period apart from the first pose time, start within the pose times."""
        return int((self.times[-1] - self.times[0]) / sensor.sweep_period_s + 1e-9) + 1

    def beyond_last_pose_s(self, sensor, frames: int) -> float:
        """How far the last sweep's start lies beyond the last pose time, s (0 when the poses cover every frame).

        The first sweep starts at the first pose time. The last sweep's own firings
        run one sweep period past its start; the last pose interval's velocity
        carries them (as it does with one frame per pose).
        """
        times = self.times
        need = times[0] + (frames - 1) * sensor.sweep_period_s
        beyond = float(need - times[-1])
        return beyond if beyond > 1e-9 * max(1.0, abs(float(times[-1]))) else 0.0


def load_mesh_world(mesh: Path, poses_file: Path, times_file: Path | None, sensor) -> MeshWorld:
    """Read a world mesh (PLY, OBJ, GLB, STL) and lidar poses in its frame, one per sweep start.

    times_file: the poses' times, s (default: one sweep period of ``sensor`` apart).
    Raises DatasetError (or WorldError) naming the file at fault.
    """
    from simlidar.formats.atomic import sha256_file
    from simlidar.formats.kitti import read_kitti_poses, read_times
    from simlidar.sequence import DatasetError
    from simlidar.trajectory import SampledTrajectory
    from simlidar.world import load_world

    world = load_world(mesh)
    poses = read_kitti_poses(poses_file)
    if times_file is not None:
        times = read_times(times_file)
        if len(times) != len(poses):
            raise DatasetError(f"{times_file}: {len(times)} times for {len(poses)} poses in {poses_file}")
    else:
        times = sensor.sweep_period_s * np.arange(len(poses))
    try:
        trajectory = SampledTrajectory(times, poses)
    except ValueError as exc:
        raise DatasetError(f"{times_file or poses_file}: {exc}") from None
    info = {"mesh": str(Path(mesh).resolve()), "mesh_sha256": sha256_file(mesh),
            "poses_file": str(Path(poses_file).resolve())}
    if times_file is not None:
        info["times_file"] = str(Path(times_file).resolve())
    return MeshWorld(world, trajectory, times, info)


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


def export_trajectory(trajectory, out: Path, period_s: float = DEFAULT_FRAME_PERIOD_S) -> Path:
    """Write a trajectory's lidar poses every ``period_s`` s as a KITTI pose file ``out`` (in the world's frame,
    as ``load_mesh_world`` reads them) and their times beside it, ``<stem>_times.txt``; returns the times file."""
    from simlidar.formats.atomic import atomic_write_text
    from simlidar.formats.kitti import format_times, write_kitti_poses

    out = Path(out)
    times = np.arange(0.0, float(trajectory.duration_s) + 1e-9, period_s)
    write_kitti_poses(out, trajectory.pose_at(times))
    times_file = out.with_name(out.stem + "_times.txt")
    atomic_write_text(times_file, format_times(times))
    return times_file


def path_length_m(path: np.ndarray) -> float:
    """Length of a polyline (N, 3), m."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


__all__ = ["MeshWorld", "SceneWorld", "build_scene_world", "export_scene", "export_trajectory", "jsonable",
           "load_mesh_world", "path_length_m", "world_of_scene"]
