"""Off-screen pictures of a scene: a 3D view with the path and one scan, and a top-down overview.

Used by ``salo view``. pyvista renders with ``off_screen=True`` (no display needed).
"""

from __future__ import annotations

import logging
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
) -> Path:
    """Write a two-panel PNG: left a 3D view behind the sensor, right a top-down overview.

    vertices: (V, 3) m; faces: (F, 3); face_labels: (F,) str label per triangle;
    path: (M, 3) drivable centre-line, m; T_world_lidar: (4, 4) pose of the scan;
    scan_xyz_world: (N, 3) scan points in the world frame, m; scan_ring: (N,) ring index.
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
    pl.add_mesh(path_line, color="red", line_width=3)
    if scan_xyz_world is not None and len(scan_xyz_world):
        cloud = pv.PolyData(np.asarray(scan_xyz_world, dtype=float))
        cloud.point_data["ring"] = np.asarray(scan_ring if scan_ring is not None else np.zeros(len(cloud.points)))
        pl.add_mesh(cloud, scalars="ring", cmap="turbo", point_size=2.5, render_points_as_spheres=False,
                    scalar_bar_args={"title": "ring", "vertical": True, "position_x": 0.88, "height": 0.5})
    if T_world_lidar is not None:
        origin = T_world_lidar[:3, 3]
        fwd = T_world_lidar[:3, 0]
        fwd_h = fwd - np.array([0.0, 0.0, fwd[2]])
        fwd_h /= max(np.linalg.norm(fwd_h), 1e-9)
        pl.add_mesh(pv.Sphere(radius=0.25, center=origin), color="magenta")
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
        pl.add_mesh(pv.Sphere(radius=max(4.0, 0.006 * np.ptp(vertices[:, 0])), center=mark), color="magenta")
    pl.view_xy()
    pl.enable_parallel_projection()
    pl.reset_camera()
    pl.add_text("top-down overview (red: path, magenta: scan position)", font_size=10, color="black")
    pl.screenshot(str(out_png))
    pl.close()
    log.info("wrote %s", out_png)
    return out_png
