"""Pictures of the worlds stacked on themselves (docs/stacked-worlds.md): one scan in a garage and on a bridge.

    python -m tools.view_stacked --out out/stacked     # garage_frame.png, bridge_frame.png

- ``garage_frame.png``: the default garage (``scenes.garage``) cut open along aisle B, seen from the
  south: its floors, the stacked straight ramps, the drive (red) and one vlp16 sweep (coloured by
  ring) from the lidar (magenta) on the first ramp;
- ``bridge_frame.png``: the default bridge (``scenes.bridge``) from the south-east, twice: a vlp16
  sweep as the drive passes under the deck, and one as it passes over it.

The scans are ``tools.view.scene_view``'s (one sweep simulated along the scene's trajectory).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _mesh(view, clip: tuple[np.ndarray, np.ndarray] | None = None):
    """The view's world as pyvista polydata coloured by label, cut by a plane (normal, origin) if given."""
    import pyvista as pv

    from tools.view import LABEL_COLOURS

    cells = np.hstack([np.full((len(view.faces), 1), 3), view.faces]).ravel()
    mesh = pv.PolyData(np.asarray(view.vertices, dtype=float), cells)
    mesh.cell_data["rgb"] = np.array([LABEL_COLOURS.get(str(lbl), (180, 180, 180)) for lbl in view.labels],
                                     dtype=np.uint8)
    if clip is not None:
        mesh = mesh.clip(normal=tuple(clip[0]), origin=tuple(clip[1]), invert=False)
    return mesh


def _draw(pl, view, clip=None, camera=None, title: str = "") -> None:
    """One panel: the world, the path and the scan by ring (what lies on the plane's side: ``clip`` (normal,
    origin)), the lidar; ``camera``: (position, focal point)."""
    import pyvista as pv

    pl.add_mesh(_mesh(view, clip), scalars="rgb", rgb=True, lighting=True)
    path, xyz, ring = view.path, np.asarray(view.xyz, dtype=float), np.asarray(view.ring, dtype=float)
    if clip is not None:
        keep = (xyz - clip[1]) @ clip[0] >= 0
        xyz, ring = xyz[keep], ring[keep]
        path = path[(path - clip[1]) @ clip[0] >= -0.5]
    pl.add_mesh(pv.PolyData(path + np.array([0.0, 0.0, 0.15])), color="red", point_size=4.0)
    cloud = pv.PolyData(xyz)
    cloud.point_data["ring"] = ring
    pl.add_mesh(cloud, scalars="ring", cmap="turbo", point_size=3.0,
                scalar_bar_args={"title": "ring", "vertical": True, "position_x": 0.9, "height": 0.4})
    pl.add_mesh(pv.Sphere(radius=0.35, center=view.T[:3, 3]), color="magenta")
    if camera is not None:
        pl.camera.position, pl.camera.focal_point = tuple(camera[0]), tuple(camera[1])
        pl.camera.up = (0.0, 0.0, 1.0)
        pl.camera.view_angle = 40.0
    pl.add_text(title, font_size=11, color="black")


def garage_frame(out: Path, sensor_name: str = "vlp16") -> Path:
    """The default garage cut open along aisle B, a sweep from its first ramp (see the module's docstring)."""
    import pyvista as pv

    from scenes import build_scene
    from simlidar.sensor import load_preset
    from tools.view import scene_view

    scene = build_scene("garage")
    p, m = scene.params, scene.metadata
    tr = scene.trajectory
    t = float(tr.time_at_distance(m["climb_s"] + 0.6 * (m["ramp_x"][1] - m["ramp_x"][0]))[0])
    view = scene_view(scene, load_preset(sensor_name), at=t / (tr.duration_s - 0.1))
    y_cut = p["stall_depth_m"] * 3 + p["aisle_width_m"] + 0.25  # aisle B, just inside the ramps' south walls
    x_mid = 0.5 * (m["ramp_x"][0] + m["ramp_x"][1])
    pl = pv.Plotter(off_screen=True, window_size=(1600, 1000))
    pl.set_background("white")
    _draw(pl, view, (np.array([0.0, 1.0, 0.0]), np.array([0.0, y_cut, 0.0])),
          (np.array([x_mid - 16.0, y_cut - 26.0, 13.0]), np.array([x_mid + 2.0, y_cut + 4.0, 3.0])),
          f"garage (defaults: {p['levels']} floors, {p['clear_height_m']} m clear, "
          f"{p['slab_thickness_m']} m slabs), cut open along aisle B: the stacked ramps; "
          f"{sensor_name} sweep on the first ramp ({len(view.xyz)} points)")
    out.mkdir(parents=True, exist_ok=True)
    png = out / "garage_frame.png"
    pl.screenshot(str(png))
    pl.close()
    return png


def bridge_frame(out: Path, sensor_name: str = "vlp16") -> Path:
    """The default bridge, a sweep passing under the deck and one passing over it."""
    import pyvista as pv

    from scenes import build_scene
    from simlidar.sensor import load_preset
    from tools.view import scene_view

    scene = build_scene("bridge")
    m, tr = scene.metadata, scene.trajectory
    pl = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(2000, 900), border=False)
    pl.set_background("white")
    for col, (key, what) in enumerate((("under_s", "passing under the deck"), ("over_s", "passing over it"))):
        t = float(tr.time_at_distance(m[key])[0])
        view = scene_view(scene, load_preset(sensor_name), at=t / (tr.duration_s - 0.1))
        pl.subplot(0, col)
        target = view.T[:3, 3]
        _draw(pl, view, None, (target + np.array([45.0, -60.0, 35.0]), target + np.array([0.0, 0.0, -2.0])),
              f"bridge (defaults): {sensor_name} sweep {what}, t = {t:.1f} s ({len(view.xyz)} points)")
    out.mkdir(parents=True, exist_ok=True)
    png = out / "bridge_frame.png"
    pl.screenshot(str(png))
    pl.close()
    return png


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/stacked"), help="folder for the PNGs (default out/stacked)")
    ap.add_argument("--sensor", default="vlp16", help="sensor preset of the sweeps (default vlp16)")
    args = ap.parse_args(argv)
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)  # off-screen without X: a harmless warning
    for png in (garage_frame(args.out, args.sensor), bridge_frame(args.out, args.sensor)):
        print(f"wrote {png}")  # noqa: T201


if __name__ == "__main__":
    main()
