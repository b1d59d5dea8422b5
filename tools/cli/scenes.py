"""The scene commands of ``salo``: ``scenes`` (list), ``scene`` (export a mesh), ``view`` (picture).

Thin commands over ``scenes``, ``tools.worlds`` and ``tools.view``. Heavy imports
(trimesh, Embree, pyvista) happen inside the commands.
"""

from __future__ import annotations

import sys
from pathlib import Path

from paramspec import help_text

from .common import CommandError, parse_overrides, real_number, split_seed, whole_number


def _out(text: str) -> None:
    """The commands' report on stdout."""
    sys.stdout.write(text + "\n")


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
    p.add_argument("--path-out", type=Path, metavar="POSES.txt",
                   help="also write the scene's lidar trajectory as KITTI poses in the mesh's frame, one every "
                   "--path-period s, and their times beside it (POSES_times.txt): the --poses and --times of "
                   "`salo simulate --mesh`")
    p.add_argument("--path-period", type=real_number(0.0, above=True), default=0.1, metavar="S",
                   help="spacing of the --path-out poses, s (default 0.1: one sweep at 10 Hz)")
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
        raise CommandError(f"unknown scene {args.name!r} (known: {', '.join(scenes.SCENES)})")
    if args.yaml:
        if not args.name:
            raise CommandError("--yaml needs a scene NAME")
        import yaml

        defaults = _defaults(scenes.scene_parameters(args.name))
        _out(f"# salo scene parameters for {args.name!r}: edit and pass with --params FILE")
        _out(yaml.safe_dump(defaults, sort_keys=False).rstrip())
        return 0
    for name in names:
        _out(f"{name}: {scenes.SCENES[name].DESCRIPTION}")
        if args.name is not None:
            _out(help_text(scenes.scene_schema(name), header=True))
    if args.name is None:
        _out("\n`salo scenes NAME` lists a scene's parameters; override them with --set KEY=VALUE "
             "or --params FILE.yaml")
    return 0


def _defaults(members) -> dict:
    """{key: default} of declared parameters (lists as lists), a section's as a mapping of its own."""
    from paramspec import Section

    return {m.name: _defaults(m.members) if isinstance(m, Section) else (list(m.default) if isinstance(
        m.default, tuple) else m.default) for m in members}


def _scene_from_args(name: str, args):
    import scenes

    try:
        overrides = parse_overrides(args.overrides, args.params)
        seed, rest = split_seed(overrides, args.seed, args.overrides, args.params)
        return scenes.build_scene(name, seed=seed, **rest)
    except ValueError as exc:
        raise CommandError(str(exc)) from None


def cmd_scene(args) -> int:
    from tools.worlds import export_scene, export_trajectory, path_length_m

    scene = _scene_from_args(args.name, args)
    try:
        export_scene(scene, args.out)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    _out(f"{scene.name} seed {scene.params['seed']}: {scene.n_triangles} triangles, "
         f"{len(scene.object_labels)} objects, path {path_length_m(scene.path):.0f} m, "
         f"trajectory {scene.trajectory.duration_s:.1f} s -> {args.out}")
    if args.path_out is not None:
        times_file = export_trajectory(scene.trajectory, args.path_out, args.path_period)
        _out(f"trajectory as KITTI poses every {args.path_period:g} s -> {args.path_out} (times: {times_file}); "
             f"simulate it with: salo simulate --mesh {args.out} --poses {args.path_out} --times {times_file} "
             "--out SEQ")
    return 0


def cmd_view(args) -> int:
    from simlidar.sensor import load_sensor
    from tools import view as views

    if args.at is not None and not 0.0 <= args.at <= 1.0:
        raise CommandError(f"--at {args.at:g}: expected a fraction of the duration in [0, 1]")
    source = Path(args.source)
    try:
        if source.is_dir():
            if args.at is not None and args.frame is not None:
                raise CommandError("give --at or --frame, not both")
            picture = views.sequence_view(source, args.at, args.frame)
        else:
            import scenes

            if args.source not in scenes.SCENES:
                raise CommandError(
                    f"{args.source}: neither a sequence folder nor a scene (known: {', '.join(scenes.SCENES)})"
                )
            if args.frame is not None:
                raise CommandError(f"--frame {args.frame}: needs a sequence folder; along a scene use --at")
            scene = _scene_from_args(args.source, args)
            picture = views.scene_view(scene, load_sensor(args.sensor), 0.5 if args.at is None else args.at)
    except views.ViewError as exc:
        raise CommandError(str(exc)) from None
    views.draw_view(picture, args.out)
    _out(f"wrote {args.out}")
    return 0
