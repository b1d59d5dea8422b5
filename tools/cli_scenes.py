"""The scene commands of ``salo``: ``scenes`` (list), ``scene`` (export a mesh), ``view`` (picture).

Registered on the main parser by ``add_commands(subparsers)``. Also the
library entry ``build_world_and_trajectory`` that ``salo simulate --scene``
uses. Heavy imports (trimesh, Embree, pyvista) happen inside the commands.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np

from tools.argtypes import whole_number

log = logging.getLogger(__name__)


def _out(text: str) -> None:
    """The commands' report on stdout (library code logs; commands talk to the user)."""
    sys.stdout.write(text + "\n")


def _command_error(message: str) -> Exception:
    from tools.cli import CommandError  # late: tools.cli imports this module

    return CommandError(message)


# ---------------------------------------------------------------- overrides
def parse_overrides(pairs: list[str] | None, yaml_file: Path | None = None) -> dict[str, Any]:
    """Scene parameter overrides from a YAML file, then ``key=value`` pairs (which win).

    The YAML file holds a flat mapping ``parameter: value``. Values from pairs stay
    strings (the scene's parameter types convert them). Errors name the file or pair.
    """
    out: dict[str, Any] = {}
    if yaml_file is not None:
        from simlidar.yaml_file import read_yaml

        path = Path(yaml_file)
        data = read_yaml(path, ValueError, "parameter file")
        if data is None:
            data = {}
        if not isinstance(data, dict) or not all(isinstance(k, str) for k in data):
            raise ValueError(f"{path}: expected a mapping of parameter names to values")
        for key, value in data.items():
            if isinstance(value, (dict, list)):
                raise ValueError(f"{path}: parameter {key}: expected a single value")
            out[key] = value
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"override {pair!r}: expected KEY=VALUE (e.g. length_m=800)")
        out[key] = value.strip()
    return out


def split_seed(overrides: dict[str, Any], cli_seed: int | None, pairs: list[str] | None = None,
               yaml_file: Path | None = None) -> tuple[int, dict[str, Any]]:
    """The scene seed and the other overrides.

    A ``seed`` among the overrides (a parameter file's ``seed:``, as ``salo scenes
    NAME --yaml`` writes it, or ``--set seed=N``) and ``--seed`` (``cli_seed``) are
    one setting: either gives it (default 0); if both are given they must agree.
    ``pairs`` and ``yaml_file`` (what ``parse_overrides`` read) only name the
    seed's origin in messages. Raises ValueError naming the origin of a bad value
    (not a whole number >= 0) or both seeds when they differ.
    """
    from scenes.params import CommonParams, resolve

    rest = dict(overrides)
    if "seed" not in rest:
        return (0 if cli_seed is None else int(cli_seed)), rest
    value = rest.pop("seed")
    set_pairs = [p.strip() for p in pairs or [] if p.partition("=")[0].strip() == "seed"]
    origin = f"--set {set_pairs[-1]}" if set_pairs else f"{yaml_file}" if yaml_file is not None else "seed"
    try:
        seed = resolve(CommonParams, {"seed": value}).seed
    except ValueError as exc:
        raise ValueError(f"{origin}: {exc}") from None
    if cli_seed is not None and int(cli_seed) != seed:
        where = origin if set_pairs else f"seed: {seed} in {origin}"
        raise ValueError(f"--seed {cli_seed} and {where} differ: both set the scene seed, give one")
    return seed, rest


def _jsonable(value: Any) -> Any:
    """Numpy scalars and arrays to plain Python, recursively (for manifests)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


# ---------------------------------------------------------------- library entry
def build_scene_checked(name: str, seed: int, overrides: dict[str, Any]):
    """``scenes.build_scene`` with its ValueError (unknown scene, bad parameter) as is."""
    import scenes

    return scenes.build_scene(name, seed=seed, **overrides)


def build_world_and_trajectory(name: str, seed: int, overrides: dict[str, Any]):
    """Build scene ``name`` and wrap it for the simulator.

    Returns (``simlidar.world.World``, the scene's trajectory, info) where info is a
    JSON-able dict for the sequence manifest: ``scene``, ``seed``, ``scene_params``
    (resolved, seed included), ``scene_metadata``, ``trajectory_duration_s``,
    ``mesh_sha256``. Raises ValueError naming an unknown scene or a bad parameter.
    """
    from simlidar.world import World

    if "seed" in overrides:
        raise ValueError(f"parameter seed: give the seed as the seed argument ({seed}), not among the overrides "
                         f"(seed={overrides['seed']!r})")
    scene = build_scene_checked(name, seed, overrides)
    world = World(scene.vertices, scene.faces, scene.face_object_id, scene.object_labels, f"scene:{name}")
    info = {
        "scene": name,
        "seed": int(seed),
        "scene_params": _jsonable(scene.params),
        "scene_metadata": _jsonable(scene.metadata),
        "trajectory_duration_s": float(scene.trajectory.duration_s),
        "mesh_sha256": scene.mesh_hash(),
    }
    return world, scene.trajectory, info


# ---------------------------------------------------------------- parsers
def _add_param_args(p) -> None:
    p.add_argument("--seed", type=int, help="scene seed (default 0, or the parameter file's or --set seed=N; "
                   "both given must agree)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene parameter (repeatable); see `salo scenes NAME`")
    p.add_argument("--params", type=Path, help="YAML file of scene parameters (KEY: VALUE)")


def add_commands(subparsers) -> None:
    """Register ``scenes``, ``scene`` and ``view`` on the main parser's sub-parsers."""
    p = subparsers.add_parser("scenes", help="list the procedural scenes and their parameters",
                              description="List the scenes with their parameters, defaults and help.")
    p.add_argument("name", nargs="?", help="only this scene")
    p.add_argument("--yaml", action="store_true",
                   help="print the scene's defaults as a YAML parameter file (needs NAME)")
    p.set_defaults(func=cmd_scenes)

    p = subparsers.add_parser("scene", help="build a scene and export its mesh (PLY or GLB)",
                              description="Build a procedural scene and write its mesh with an object "
                              "id per triangle and a label per object: PLY (face property object_id, "
                              "labels in a header comment) or GLB (one node per object, named label_id).")
    p.add_argument("name", help="scene name (see `salo scenes`)")
    _add_param_args(p)
    p.add_argument("--out", type=Path, required=True, help="output mesh file, .ply or .glb")
    p.add_argument("--path-out", type=Path, help="also write the drivable path as x y z lines")
    p.set_defaults(func=cmd_scene)

    p = subparsers.add_parser("view", help="picture of a scene or a simulated sequence (PNG)",
                              description="Render off-screen: a 3D view with the path and one scan "
                              "coloured by ring, beside a top-down overview. SOURCE is a scene name "
                              "(one scan is simulated along the path) or a simulated sequence folder "
                              "(one of its frames is shown in the world it was simulated in: --frame N, "
                              "or the frame nearest --at, else frame 0).")
    p.add_argument("source", help="scene name or sequence folder")
    _add_param_args(p)
    p.add_argument("--at", type=float,
                   help="where along the scene's trajectory or the sequence, as a fraction of its duration "
                   "in [0, 1] (default: 0.5 for a scene, frame 0 of a sequence)")
    p.add_argument("--frame", type=whole_number(0), help="sequence: show frame N (its scan in the world)")
    p.add_argument("--sensor", default="salo32", help="scene: sensor preset or YAML (default salo32)")
    p.add_argument("--out", type=Path, required=True, help="output PNG")
    p.set_defaults(func=cmd_view)


# ---------------------------------------------------------------- commands
def cmd_scenes(args) -> int:
    import scenes

    names = [args.name] if args.name else list(scenes.SCENES)
    if args.name and args.name not in scenes.SCENES:
        raise _command_error(f"unknown scene {args.name!r} (known: {', '.join(scenes.SCENES)})")
    if args.yaml:
        if not args.name:
            raise _command_error("--yaml needs a scene NAME")
        import yaml

        defaults = {p.name: p.default for p in scenes.scene_parameters(args.name)}
        _out(f"# salo scene parameters for {args.name!r}: edit and pass with --params FILE")
        _out(yaml.safe_dump(defaults, sort_keys=False).rstrip())
        return 0
    for name in names:
        _out(f"{name}: {scenes.SCENES[name].DESCRIPTION}")
        if args.name is None:
            continue
        for p in scenes.scene_parameters(name):
            bounds = ""
            if p.choices:
                bounds = f" [{'|'.join(p.choices)}]"
            elif p.min is not None or p.max is not None:
                lo = "" if p.min is None else f"{p.min:g}"
                hi = "" if p.max is None else f"{p.max:g}"
                bounds = f" [{lo}..{hi}]"
            _out(f"  {p.name:24s} {p.type:5s} = {p.default!s:10s} {p.help}{bounds}")
    if args.name is None:
        _out("\n`salo scenes NAME` lists a scene's parameters; override them with --set KEY=VALUE "
             "or --params FILE.yaml")
    return 0


def _scene_from_args(name: str, args):
    try:
        overrides = parse_overrides(args.overrides, args.params)
        seed, rest = split_seed(overrides, args.seed, args.overrides, args.params)
        return build_scene_checked(name, seed, rest)
    except ValueError as exc:
        raise _command_error(str(exc)) from None


def export_scene(scene, out: Path) -> Path:
    """Write a scene's mesh: .ply (object_id per face, labels in the header) or .glb (a node per object)."""
    out = Path(out)
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".ply":
        from simlidar.world import World, save_world_ply

        save_world_ply(World(scene.vertices, scene.faces, scene.face_object_id, scene.object_labels,
                             scene.name), out)
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


def cmd_scene(args) -> int:
    scene = _scene_from_args(args.name, args)
    try:
        export_scene(scene, args.out)
    except ValueError as exc:
        raise _command_error(str(exc)) from None
    if args.path_out is not None:
        np.savetxt(args.path_out, scene.path, fmt="%.4f")
    _out(f"{scene.name} seed {scene.params['seed']}: {scene.n_triangles} triangles, "
         f"{len(scene.object_labels)} objects, path {_path_length(scene.path):.0f} m, "
         f"trajectory {scene.trajectory.duration_s:.1f} s -> {args.out}")
    return 0


def _path_length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def cmd_view(args) -> int:
    from simlidar.sensor import load_sensor
    from simlidar.sweep import SweepSimulator
    from tools.view import render_scene

    if args.at is not None and not 0.0 <= args.at <= 1.0:
        raise _command_error(f"--at {args.at:g}: expected a fraction of the duration in [0, 1]")
    source = Path(args.source)
    if source.is_dir():
        if args.at is not None and args.frame is not None:
            raise _command_error("give --at or --frame, not both")
        view = _sequence_view(source, args.at, args.frame)
    else:
        import scenes

        if args.source not in scenes.SCENES:
            raise _command_error(
                f"{args.source}: neither a sequence folder nor a scene (known: {', '.join(scenes.SCENES)})"
            )
        if args.frame is not None:
            raise _command_error(f"--frame {args.frame}: needs a sequence folder; along a scene use --at")
        at = 0.5 if args.at is None else args.at
        scene = _scene_from_args(args.source, args)
        world, traj, _ = _wrap(scene)
        sensor = load_sensor(args.sensor)
        t0 = float(at * max(traj.duration_s - sensor.sweep_period_s, 0.0))
        scan = SweepSimulator(world, sensor, seed=scene.params["seed"]).sweep(traj, t0)
        T = traj.pose_at(np.array([t0]))[0]
        view = {
            "vertices": scene.vertices, "faces": scene.faces, "labels": scene.label_of_face(),
            "path": scene.path, "T": T, "xyz": scan.xyz @ T[:3, :3].T + T[:3, 3], "ring": scan.ring,
            "title": f"{scene.name} seed {scene.params['seed']}: {sensor.name} scan at t = {t0:.1f} s "
                     f"({len(scan)} points)",
        }
    render_scene(view["vertices"], view["faces"], view["labels"], view["path"], args.out,
                 view["T"], view["xyz"], view["ring"], title=view["title"])
    _out(f"wrote {args.out}")
    return 0


def _wrap(scene):
    from simlidar.world import World

    world = World(scene.vertices, scene.faces, scene.face_object_id, scene.object_labels, scene.name)
    return world, scene.trajectory, {}


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


def _sequence_view(folder: Path, at: float | None = None, frame_index: int | None = None) -> dict:
    """World, path, world pose and points of one frame of a simulated sequence folder.

    The frame's world pose is the manifest's ``T_world_first_lidar`` times its
    ``poses.txt`` line. A mesh world is read from the manifest's path and checked
    against its sha256, so a moved or changed file is reported, not drawn.
    """
    from simlidar.dataset import open_sequence
    from simlidar.formats.atomic import sha256_file
    from simlidar.sequence import DatasetError
    from simlidar.world import load_world

    seq = open_sequence(folder)
    manifest = seq.manifest
    where = folder / "manifest.json"
    if not (manifest.get("scene") or manifest.get("mesh")):
        raise _command_error(f"{where if manifest else folder}: names neither a scene nor a mesh to draw")
    try:
        k = pick_frame(len(seq), seq.times, at, frame_index, str(folder))
    except ValueError as exc:
        raise _command_error(str(exc)) from None
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
            scene = build_scene_checked(manifest["scene"], seed, params)
        except ValueError as exc:
            raise _command_error(f"{where}: {exc}") from None
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
    return {"vertices": vertices, "faces": faces, "labels": labels, "path": path, "T": T,
            "xyz": frame.points @ T[:3, :3].T + T[:3, 3], "ring": ring, "title": title}


__all__ = ["add_commands", "build_world_and_trajectory", "export_scene", "parse_overrides", "split_seed"]
