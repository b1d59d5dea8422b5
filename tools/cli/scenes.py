"""The scene commands of ``salo``: ``scenes`` (list), ``scene`` (export a mesh), ``view`` (picture).

Thin commands over ``scenes``, ``tools.worlds`` and ``tools.view``. Heavy imports
(trimesh, Embree, pyvista) happen inside the commands.
"""

from __future__ import annotations

import argparse
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
    p.add_argument("--scene-params", dest="params", type=Path, metavar="FILE.yaml",
                   help="YAML file of scene parameters (KEY: VALUE; `salo scenes NAME --yaml` writes one)")
    p.add_argument("--params", dest="params", type=Path, help=argparse.SUPPRESS)  # the older name


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

    p = subparsers.add_parser("view", help="picture of a scene or a sequence (PNG), or an interactive page of a "
                              "sequence, a run or a bench result (HTML)",
                              description="PNG (--out): render off-screen a 3D view with the path and one scan "
                              "coloured by ring, beside a top-down overview. SOURCE is a scene name "
                              "(one scan is simulated along the path) or a simulated sequence folder "
                              "(one of its frames is shown in the world it was simulated in: --frame N, "
                              "or the frame nearest --at, else frame 0). HTML (--html): one self-contained page "
                              "that opens offline in a browser: the scans in 3D with a frame slider and play, the "
                              "true trajectory and each run's (--run), points coloured by ring, intensity, height, "
                              "the truth's object class or kept / dropped by our filters, and each run's error "
                              "along the path. SOURCE is then a sequence folder, or a `salo bench` output folder "
                              "(a page per sequence with every method, into OUT/views/ or --html FOLDER).")
    p.add_argument("source", help="scene name, sequence folder, or (with --html) a salo bench output folder")
    _add_param_args(p)
    p.add_argument("--at", type=float,
                   help="where along the scene's trajectory or the sequence, as a fraction of its duration "
                   "in [0, 1] (default: 0.5 for a scene, frame 0 of a sequence)")
    p.add_argument("--frame", type=whole_number(0), help="sequence: show frame N (its scan in the world)")
    p.add_argument("--sensor", help="scene: sensor preset or YAML (default salo32)")
    p.add_argument("--out", type=Path, help="output PNG")
    p.add_argument("--html", type=Path, nargs="?", const=Path(), metavar="PAGE.html",
                   help="write the interactive page (a bench folder: the folder of its pages, default OUT/views)")
    p.add_argument("--run", action="append", default=[], metavar="[LABEL=]POSES.txt",
                   help="--html of a sequence: a run's KITTI poses (salo odometry's, a bench result's; its "
                   "diagnostics and config beside it are read too), repeatable")
    p.add_argument("--frames", help="--html: frame range A:B of the sequence (Python slice)")
    p.add_argument("--max-points", type=whole_number(1000), metavar="N",
                   help="--html: at most N points a frame (evenly thinned; default every point)")
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
        _out(f"# salo scene parameters for {args.name!r}: edit and pass with --scene-params FILE")
        _out(yaml.safe_dump(defaults, sort_keys=False).rstrip())
        return 0
    for name in names:
        _out(f"{name}: {scenes.SCENES[name].DESCRIPTION}")
        if args.name is not None:
            _out(help_text(scenes.scene_schema(name), header=True))
    if args.name is None:
        _out("\n`salo scenes NAME` lists a scene's parameters; override them with --set KEY=VALUE "
             "or --scene-params FILE.yaml")
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


def _scene_options_given(args) -> list[str]:
    """The scene options given (``--set``, ``--scene-params``, ``--seed``, ``--sensor``): a scene's only."""
    given = [name for name, value in (("--set", args.overrides), ("--scene-params", args.params),
                                      ("--seed", args.seed), ("--sensor", args.sensor)) if value]
    return given


def cmd_view(args) -> int:
    from simlidar.sensor import load_sensor
    from tools import view as views

    if args.at is not None and not 0.0 <= args.at <= 1.0:
        raise CommandError(f"--at {args.at:g}: expected a fraction of the duration in [0, 1]")
    if args.out is None and args.html is None:
        raise CommandError("give --out PICTURE.png, or --html PAGE.html for the interactive page")
    source = Path(args.source)
    if source.is_dir() and _scene_options_given(args):
        raise CommandError(f"{', '.join(_scene_options_given(args))}: options of a scene, and {source} is a folder "
                           "(a sequence's scene, seed and sensor are its manifest's)")
    html_only = [name for name, value in (("--run", args.run), ("--frames", args.frames),
                                          ("--max-points", args.max_points)) if value]
    if html_only and args.html is None:
        raise CommandError(f"{', '.join(html_only)}: options of the interactive page; add --html PAGE.html")
    if args.html is not None:
        return _view_html(args, source)
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
            picture = views.scene_view(scene, load_sensor(args.sensor or "salo32"),
                                       0.5 if args.at is None else args.at)
    except views.ViewError as exc:
        raise CommandError(str(exc)) from None
    views.draw_view(picture, args.out)
    _out(f"wrote {args.out}")
    return 0


def _view_html(args, source: Path) -> int:
    """``salo view SOURCE --html``: a sequence's page (with its runs), or a bench folder's pages."""
    import time

    from tools import view_html

    from .common import frames_selected, parse_frames, progress_bar

    if not source.is_dir():
        raise CommandError(f"{source}: --html needs a sequence folder or a salo bench output folder")
    if args.out is not None or args.frame is not None or args.at is not None:
        raise CommandError("--html writes the page of every frame: leave out --out, --frame and --at")
    t0 = time.perf_counter()
    try:
        if (source / "results").is_dir() and not (source / "manifest.json").is_file():
            if args.run or args.frames:
                raise CommandError("--run and --frames apply to a sequence folder; a bench folder's pages show "
                                   "every method it ran")
            out = args.html if args.html != Path() and args.html.suffix != ".html" else None
            pages = view_html.bench_pages(source, max_points=args.max_points,
                                          on_page=lambda name: print(f"writing the page of {name}", flush=True))
            if not pages:
                raise CommandError(f"{source}: no sequence with a finished run to show")
            if out is not None:
                import shutil

                out.mkdir(parents=True, exist_ok=True)
                pages = {k: Path(shutil.move(str(v), out / v.name)) for k, v in pages.items()}
            for k, v in pages.items():
                _out(f"{k}: {v} ({v.stat().st_size / 1e6:.1f} MB)")
            _out(f"wrote {len(pages)} pages in {time.perf_counter() - t0:.0f} s")
            return 0
        from simlidar.dataset import open_sequence

        if args.html == Path():
            raise CommandError(f"{source}: give the page's file, --html PAGE.html")
        total = len(open_sequence(source))
        frames = parse_frames(args.frames, total, str(source))
        n = frames_selected(total, frames)
        runs, configs = {}, {}
        for text in args.run:
            label, sep, file = text.rpartition("=")
            path = Path(file)
            label = label if sep else (path.parent.name if path.name == "poses.txt" else path.stem)
            if label in runs:
                raise CommandError(f"--run {text}: two runs are labelled {label!r}; give LABEL=POSES.txt")
            if not path.is_file():
                raise CommandError(f"--run {text}: no such poses file {path}")
            view_html.read_poses_file(path, (total, n))  # refused before the work, naming the file
            runs[label] = path
            configs[label] = view_html.run_config_beside(path)
        bar = progress_bar(n, "frame", "page")
        try:
            data = view_html.sequence_page(source, runs, frames=frames, max_points=args.max_points, configs=configs,
                                           on_frame=lambda k: bar.update(1))
        finally:
            bar.close()
        page = view_html.write_page(data, args.html)
    except view_html.PageError as exc:
        raise CommandError(str(exc)) from None
    _out(f"wrote {page}: {len(data.points)} frames, {sum(len(p) for p in data.points)} points, "
         f"{len(runs)} runs, {page.stat().st_size / 1e6:.1f} MB in {time.perf_counter() - t0:.0f} s")
    return 0
