"""Off-screen pictures of a scene: a 3D view with the path and one scan, and a top-down overview.

The library of ``salo view``: ``scene_view`` (one scan simulated along a scene's
path) or ``sequence_view`` (one frame of a simulated sequence in the world it
was simulated in) gather what to draw, a ``View``; ``draw_view`` renders it.
pyvista renders with ``off_screen=True`` (no display needed).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

# Muted colours per object label (RGB 0-255), chosen to tell classes apart at a glance.
LABEL_COLOURS = {
    "ground": (150, 140, 110),
    "road": (95, 95, 100),
    "sidewalk": (175, 170, 160),
    "kerb": (200, 200, 195),
    "building": (205, 185, 160),
    "wall": (170, 160, 150),
    "roof": (150, 75, 60),
    "vehicle": (60, 90, 160),
    "pole": (70, 70, 70),
    "sign": (230, 200, 40),
    "vegetation": (70, 140, 60),
    "rock": (130, 120, 110),
    "rail": (190, 190, 200),
    "light": (250, 240, 180),
    "object": (180, 100, 180),
    "person": (200, 80, 60),
}


def _polydata(vertices: np.ndarray, faces: np.ndarray):
    import pyvista as pv

    cells = np.hstack([np.full((len(faces), 1), 3, dtype=np.int64), faces.astype(np.int64)]).ravel()
    return pv.PolyData(np.asarray(vertices, dtype=np.float64), cells)


def _unoccluded_camera(vertices, faces, target: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """``target + offset``, pulled toward ``target`` if a surface lies between them
    (inside a tunnel the camera would otherwise look at the hill from outside)."""
    from simlidar.raycast import Raycaster

    dist = float(np.linalg.norm(offset))
    direction = offset / dist
    hit = Raycaster(vertices, faces, threads=1).cast(target, direction[None], dist)
    if np.isfinite(hit.distance[0]):
        return target + direction * max(hit.distance[0] - 1.0, 2.0)
    return target + offset


def marker_radius_m(vertices: np.ndarray) -> float:
    """The overview's scan-position marker: 2 % of the world's larger horizontal extent (vertices (V, 3), m),
    so that it shows in a city and covers no room."""
    extent = np.ptp(np.asarray(vertices)[:, :2], axis=0).max() if len(vertices) else 1.0
    return float(0.02 * max(extent, 1.0))


def render_scene(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_labels: np.ndarray,
    path: np.ndarray,
    out_png: str | Path,
    T_world_lidar: np.ndarray | None = None,
    scan_xyz_world: np.ndarray | None = None,
    scan_ring: np.ndarray | None = None,
    title: str = "",
    size: tuple[int, int] = (1800, 900),
    moving: np.ndarray | None = None,
    boxes: np.ndarray | None = None,
    actors: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write a two-panel PNG: left a 3D view behind the sensor, right a top-down overview.

    vertices: (V, 3) m; faces: (F, 3); face_labels: (F,) str label per triangle;
    path: (M, 3) drivable centre-line, m; T_world_lidar: (4, 4) pose of the scan;
    scan_xyz_world: (N, 3) scan points in the world frame, m; scan_ring: (N,) ring index.
    moving: (N,) bool, the returns off a moving object (drawn in red over the rest), or None.
    boxes: (B, 8, 3) the moving objects' boxes in the world, m (drawn as red wireframes), or None.
    actors: (vertices (V, 3), faces (F, 3)) the moving objects' meshes where they are, or None.
    """
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger

    # Off-screen without an X display VTK logs a harmless "bad X server connection".
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    mesh = _polydata(vertices, faces)
    colours = np.array([LABEL_COLOURS.get(str(lbl), (180, 180, 180)) for lbl in face_labels], dtype=np.uint8)
    mesh.cell_data["rgb"] = colours
    path_line = pv.lines_from_points(np.asarray(path, dtype=float) + np.array([0.0, 0.0, 0.3]))

    pl = pv.Plotter(off_screen=True, shape=(1, 2), window_size=size, border=False)
    pl.set_background("white")

    # Left: a view from behind and above the sensor, the scan coloured by ring.
    pl.subplot(0, 0)
    pl.add_mesh(mesh, scalars="rgb", rgb=True, show_edges=False, lighting=True)
    if actors is not None and len(actors[1]):
        pl.add_mesh(_polydata(*actors), color=(120, 130, 150), lighting=True)
    pl.add_mesh(path_line, color="red", line_width=3)
    if scan_xyz_world is not None and len(scan_xyz_world):
        cloud = pv.PolyData(np.asarray(scan_xyz_world, dtype=float))
        cloud.point_data["ring"] = np.asarray(scan_ring if scan_ring is not None else np.zeros(len(cloud.points)))
        pl.add_mesh(cloud, scalars="ring", cmap="turbo", point_size=2.5, render_points_as_spheres=False,
                    scalar_bar_args={"title": "ring", "vertical": True, "position_x": 0.88, "height": 0.5})
        _draw_moving(pl, scan_xyz_world, moving, boxes)
    if T_world_lidar is not None:
        origin = T_world_lidar[:3, 3]
        fwd = T_world_lidar[:3, 0]
        fwd_h = fwd - np.array([0.0, 0.0, fwd[2]])
        fwd_h /= max(np.linalg.norm(fwd_h), 1e-9)
        pl.add_mesh(pv.Sphere(radius=min(0.25, 0.5 * marker_radius_m(vertices)), center=origin), color="magenta")
        camera = _unoccluded_camera(vertices, faces, origin, -45.0 * fwd_h + np.array([0.0, 0.0, 28.0]))
        pl.camera.position = tuple(camera)
        pl.camera.focal_point = tuple(origin + 25.0 * fwd_h)
        pl.camera.up = (0.0, 0.0, 1.0)
        pl.camera.view_angle = 55.0
        pl.camera.clipping_range = (1.0, 5000.0)
    pl.add_text(title or "scene", font_size=10, color="black")

    # Right: top-down overview of the whole scene with the path.
    pl.subplot(0, 1)
    pl.add_mesh(mesh.copy(), scalars="rgb", rgb=True, show_edges=False, lighting=True)
    # The path drawn above everything, so tunnels and bridges do not hide it.
    top = float(np.max(vertices[:, 2])) + 1.0
    flat = np.column_stack([np.asarray(path)[:, :2], np.full(len(path), top)])
    pl.add_mesh(pv.lines_from_points(flat), color="red", line_width=3)
    if T_world_lidar is not None:
        mark = np.array([*T_world_lidar[:2, 3], top + 1.0])
        pl.add_mesh(pv.Sphere(radius=marker_radius_m(vertices), center=mark), color="magenta")
    pl.view_xy()
    pl.enable_parallel_projection()
    pl.reset_camera()
    pl.add_text("top-down overview (red: path, magenta: scan position)", font_size=10, color="black")
    pl.screenshot(str(out_png))
    pl.close()
    log.info("wrote %s", out_png)
    return out_png


def _draw_moving(pl, xyz_world: np.ndarray, moving: np.ndarray | None, boxes: np.ndarray | None) -> None:
    """The returns off moving objects in red, larger, over the scan; the objects' boxes as red wireframes."""
    import pyvista as pv

    if moving is not None and np.any(moving):
        pl.add_mesh(pv.PolyData(np.asarray(xyz_world, float)[np.asarray(moving, bool)]), color=(230, 30, 40),
                    point_size=4.5, render_points_as_spheres=False)
    for corners in () if boxes is None else boxes:
        edges = [(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
        cells = np.hstack([[2, a, b] for a, b in edges])
        pl.add_mesh(pv.PolyData(np.asarray(corners, float), lines=cells), color=(230, 30, 40), line_width=2)


def _track_rotations(tracks: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = tracks["quaternion"]
    return Rotation.from_quat(np.column_stack([q[:, 1:], q[:, :1]])).as_matrix()


def actor_meshes(tracks: np.ndarray, T_world_scan: np.ndarray, models: list) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3), faces (F, 3)) of the moving objects' meshes in the world, each placed by its track row
    (``models``: its ``scenes.actors.ActorModel`` per row)."""
    verts, faces, base = [np.zeros((0, 3))], [np.zeros((0, 3), np.int64)], 0
    for row, R, m in zip(tracks, _track_rotations(tracks) if len(tracks) else [], models, strict=True):
        v = (m.vertices - m.box_centre) @ R.T + row["centre"]
        verts.append(v @ T_world_scan[:3, :3].T + T_world_scan[:3, 3])
        faces.append(m.faces + base)
        base += len(v)
    return np.vstack(verts), np.vstack(faces)


def box_corners(tracks: np.ndarray, T_world_scan: np.ndarray) -> np.ndarray:
    """(B, 8, 3) the corners in the world of tracks' boxes (``simlidar.formats.tracks.TRACK_DTYPE`` rows in the
    scan frame ``T_world_scan`` (4, 4) places), corner k at the box's (+-x, +-y, +-z) by the bits of k."""
    if len(tracks) == 0:
        return np.zeros((0, 8, 3))
    signs = np.array([[(k >> 2) & 1, (k >> 1) & 1, k & 1] for k in range(8)], float) * 2 - 1
    R = _track_rotations(tracks)
    local = signs[None] * tracks["size"][:, None, :] / 2
    scan = np.einsum("bij,bkj->bki", R, local) + tracks["centre"][:, None, :]
    return scan @ T_world_scan[:3, :3].T + T_world_scan[:3, 3]


# ---------------------------------------------------------------- what to draw
class ViewError(ValueError):
    """A view cannot be made from what was given; the message says why."""


@dataclass
class View:
    """One picture's content: the world, its path, one scan and its pose, a title.

    vertices: (V, 3) m; faces: (F, 3); labels: (F,) label per triangle; path: (M, 3) m;
    T: (4, 4) ``T_world_lidar`` of the scan; xyz: (N, 3) scan points in the world frame, m;
    ring: (N,) ring per point. moving: (N,) bool, the returns off moving objects, and boxes: (B, 8, 3) their
    boxes in the world (``box_corners``), or None (a world where nothing moves).
    """

    vertices: np.ndarray
    faces: np.ndarray
    labels: np.ndarray
    path: np.ndarray
    T: np.ndarray
    xyz: np.ndarray
    ring: np.ndarray
    title: str
    moving: np.ndarray | None = None
    boxes: np.ndarray | None = None
    actors: tuple[np.ndarray, np.ndarray] | None = None


def draw_view(view: View, out_png: str | Path) -> Path:
    """Render a ``View`` to a PNG (``render_scene``)."""
    return render_scene(view.vertices, view.faces, view.labels, view.path, out_png, view.T, view.xyz, view.ring,
                        title=view.title, moving=view.moving, boxes=view.boxes, actors=view.actors)


def scene_view(scene, sensor, at: float = 0.5) -> View:
    """One scan of ``sensor`` simulated along a built scene's trajectory, at the fraction ``at`` of it."""
    from simlidar.sweep import SweepSimulator

    from .worlds import world_of_scene

    traj = scene.trajectory
    t0 = float(at * max(traj.duration_s - sensor.sweep_period_s, 0.0))
    scan = SweepSimulator(world_of_scene(scene, scene.name), sensor, seed=scene.params["seed"]).sweep(traj, t0)
    T = traj.pose_at(np.array([t0]))[0]
    return View(scene.vertices, scene.faces, scene.label_of_face(), scene.path, T,
                scan.xyz @ T[:3, :3].T + T[:3, 3], scan.ring,
                f"{scene.name} seed {scene.params['seed']}: {sensor.name} scan at t = {t0:.1f} s ({len(scan)} points)",
                scan.moving, None if scan.tracks is None else box_corners(scan.tracks, T),
                None if scan.tracks is None else actor_meshes(scan.tracks, T, _models(scene, scan.tracks)))


def pick_frame(n: int, times: np.ndarray | None, at: float | None, frame: int | None, name: str = "") -> int:
    """The frame of an ``n``-frame sequence to show: ``frame``, else the one whose start time
    (``times``, (n,) s) is nearest the fraction ``at`` of the duration, else 0.

    Raises ValueError for a frame out of range.
    """
    if frame is not None:
        if frame >= n:
            raise ValueError(f"--frame {frame}: {name or 'the sequence'} has {n} frames (0..{n - 1})")
        return int(frame)
    if at is None:
        return 0
    if times is None or n < 2:
        return int(round(at * (n - 1)))
    target = times[0] + at * (times[-1] - times[0])
    return int(np.argmin(np.abs(np.asarray(times) - target)))


def sequence_view(folder: Path, at: float | None = None, frame_index: int | None = None) -> View:
    """World, path, world pose and points of one frame of a simulated sequence folder.

    The frame's world pose is the manifest's ``T_world_first_lidar`` times its
    ``poses.txt`` line. A mesh world is read from the manifest's path and checked
    against its sha256, so a moved or changed file is reported, not drawn.
    Raises ViewError (nothing to draw, a frame out of range, a scene that no
    longer builds) or DatasetError (missing pose, missing or changed mesh).
    """
    import scenes
    from simlidar.dataset import open_sequence
    from simlidar.formats.atomic import sha256_file
    from simlidar.sequence import DatasetError
    from simlidar.world import load_world

    seq = open_sequence(folder)
    manifest = seq.manifest
    where = folder / "manifest.json"
    if not (manifest.get("scene") or manifest.get("mesh")):
        raise ViewError(f"{where if manifest else folder}: names neither a scene nor a mesh to draw")
    try:
        k = pick_frame(len(seq), seq.times, at, frame_index, str(folder))
    except ValueError as exc:
        raise ViewError(str(exc)) from None
    frame = seq[k]
    ring = frame.ring if frame.ring is not None else np.zeros(len(frame.points), dtype=int)
    first = manifest.get("T_world_first_lidar")
    if first is None or len(first) != 12:
        raise DatasetError(f"{where}: no T_world_first_lidar (12 numbers) to place the frames in the world")
    T_first = np.eye(4)
    T_first[:3, :4] = np.reshape(np.asarray(first, dtype=float), (3, 4))
    T = T_first @ seq.poses[k]
    path = (T_first @ seq.poses)[:, :3, 3]
    t_k = float(seq.times[k]) if seq.times is not None else 0.0
    what = f"frame {k} of {len(seq)} at t = {t_k:.1f} s ({len(frame.points)} points)"
    if manifest.get("scene"):
        params = dict(manifest.get("scene_params") or {})
        # the resolved parameters hold the scene's seed; a top-level "seed" may be the noise's
        seed = int(params.pop("seed", manifest.get("seed", 0)))
        try:
            scene = scenes.build_scene(manifest["scene"], seed=seed, **params)
        except ValueError as exc:
            raise ViewError(f"{where}: {exc}") from None
        if manifest.get("mesh_sha256") and scene.mesh_hash() != manifest["mesh_sha256"]:
            log.warning("%s: scene %s seed %d builds a different mesh now than when it was simulated "
                        "(mesh sha256 differs): the picture may not match the scan", where, scene.name, seed)
        vertices, faces, labels, path = scene.vertices, scene.faces, scene.label_of_face(), scene.path
        title = f"{folder.name}: scene {scene.name} seed {seed}, {what}"
    else:
        mesh = Path(manifest["mesh"])
        if not mesh.is_file():
            raise DatasetError(f"{where}: the world mesh {mesh} is missing (moved or deleted since the simulation)")
        digest = manifest.get("mesh_sha256")
        if digest:
            now = sha256_file(mesh)
            if now != digest:
                raise DatasetError(f"{mesh}: the mesh changed since {folder} was simulated (sha256 {now[:12]}... "
                                   f"differs from the manifest's {digest[:12]}...): the picture would show "
                                   "another world")
        else:
            log.warning("%s: no mesh_sha256 (an older sequence): %s is drawn unchecked", where, mesh)
        world = load_world(mesh)
        vertices, faces = world.vertices, world.faces
        labels = np.asarray(world.object_labels, dtype=object)[world.face_object_id]
        title = f"{folder.name}: mesh {mesh.name}, {what}"
    moving = boxes = actors = None
    if frame.fields is not None and "moving" in (frame.fields.dtype.names or ()):  # a world with moving objects
        from simlidar.formats.tracks import FILE, read_tracks

        moving = frame.fields["moving"]
        if (folder / FILE).is_file():
            frames, rows = read_tracks(folder / FILE)
            boxes = box_corners(rows[frames == k], T)
            if manifest.get("scene"):
                actors = actor_meshes(rows[frames == k], T, _models(scene, rows[frames == k]))
    return View(vertices, faces, labels, path, T, frame.points @ T[:3, :3].T + T[:3, 3], ring, title, moving, boxes,
                actors)


def _models(scene, tracks: np.ndarray) -> list:
    """The model of each track row's moving object (its object id counts after the scene's static objects)."""
    return [scene.actors[int(i) - len(scene.object_labels)].model for i in tracks["object_id"]]


__all__ = ["View", "ViewError", "actor_meshes", "box_corners", "draw_view", "marker_radius_m", "pick_frame",
           "render_scene", "scene_view",
           "sequence_view"]
