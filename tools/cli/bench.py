"""``salo bench``: chosen methods over a suite of simulated sequences, and a leaderboard page."""

from __future__ import annotations

from pathlib import Path

from .common import CommandError, parse_config_set, real_number, whole_number


def add_commands(sub) -> None:
    p = sub.add_parser(
        "bench",
        help="run methods over a suite and write a leaderboard (HTML + Markdown)",
        description="Run methods over a suite of simulated sequences (each simulated once into OUT/sequences) "
        "and write OUT/leaderboard.html (one self-contained page) and OUT/leaderboard.md: a table per scene "
        "family (KITTI t_err and r_err, ATE, RPE, vertical drift, failures, frames/s), and per sequence the "
        "trajectories, the error over distance with the weakly constrained stretches shaded (the simulator's "
        "truth, and the method's own flags), and each frame's error against the truth's weakest eigenvalue. "
        "Results are kept per method and sequence in OUT/results: running again with another method adds it "
        "to the page without re-running the others. Every method gets the sensor's data only (no ground "
        "truth): a method is one of ours (bl, ncf, salo, bl-map, ncf-map, salo-map, default; --set changes "
        "them), a peer (kiss-icp, genz-icp, small-gicp), an installed plug-in (entry-point group "
        "salo.methods) or a command (--command NAME=CMD with {scans}, {sensor}, {times}, {fields}, "
        "{sequence}, {out}). Each sequence also gets a 3D page, OUT/views/SEQUENCE.html (the scans frame by "
        "frame, the trajectories, the error along the path; offline, one file), linked from the leaderboard.",
    )
    p.add_argument("--suite", default="regress",
                   help="regress (the regression suite: city, forest, highway), generalize (the held-out "
                   "families, evaluation seeds, simulated and real kinds), weather (generalize's simulated "
                   "sequences in clear air, light and dense fog, rain and snow: docs/weather.md), traffic (its "
                   "sequences of the families with traffic, each with moving traffic and as its static twin), "
                   "stress (the named stress scenes of moving traffic and their static twins: docs/traffic.md), or "
                   "a sweep spec YAML (default regress)")
    p.add_argument("--method", action="append", default=[], metavar="NAME",
                   help="a method to run (repeatable; default: bl, ncf, salo, default)")
    p.add_argument("--command", action="append", default=[], metavar="NAME=CMD",
                   help="an external method: NAME=\"my_odometry {scans} {sensor} {out}\" (repeatable)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="change our configurations' parameters (dotted keys; the method is then NAME+HASH)")
    p.add_argument("--fields", metavar="F,G",
                   help="per-point fields handed to the methods: of ring, time_s, azimuth_index, range_m, or none "
                   "(default ring,time_s; the generalize suite's real kind: none)")
    p.add_argument("--frames", type=whole_number(2), help="sweeps per sequence (default: the suite's)")
    p.add_argument("--families", help="generalize, weather, traffic: only these families; stress: only these scenes; "
                   "comma-separated")
    p.add_argument("--rerun", action="append", default=[], metavar="NAME",
                   help="redo this method's stored results (repeatable)")
    p.add_argument("--out", type=Path, help="output folder (default out/bench/<suite name>)")
    p.add_argument("--no-views", dest="views", action="store_false",
                   help="do not write the 3D page of each sequence (OUT/views/SEQUENCE.html, linked from the "
                   "leaderboard)")
    p.add_argument("--view-points", type=whole_number(1000), metavar="N",
                   help="at most N points a frame on the 3D pages (default: every point)")
    p.add_argument("--timeout", type=real_number(0.0, above=True), default=3600.0, metavar="S",
                   help="time limit of a command per sequence, s (default 3600)")
    p.set_defaults(func=cmd_bench)


def cmd_bench(args) -> int:
    import shlex
    import sys

    from tools.leaderboard import SUITES, SuiteError, run_bench
    from tools.methods import CommandMethod, MethodError, method_from_name
    from tools.staging import StagingError, parse_fields

    names = list(dict.fromkeys(args.method)) or (["bl", "ncf", "salo", "default"] if not args.command else [])
    overrides = parse_config_set(args.set)
    try:
        methods = [method_from_name(n, overrides if n in _ours() else None) for n in names]
        for text in args.command:
            name, sep, template = text.partition("=")
            if not sep or not name.strip():
                raise CommandError(f"--command {text!r}: expected NAME=COMMAND")
            methods.append(CommandMethod(name.strip(), template))
        fields = parse_fields(args.fields) if args.fields is not None else None
    except (MethodError, StagingError) as exc:
        raise CommandError(str(exc)) from None
    taken = [m.name for m in methods]
    if len(set(taken)) != len(taken):
        raise CommandError(f"two methods are named alike: {', '.join(taken)}")
    for m in methods:
        why = m.unavailable()
        if why:
            print(f"note: {m.label}: {why}; its runs will fail", file=sys.stderr)
    suite = args.suite
    if suite not in SUITES and not Path(suite).is_file():
        raise CommandError(f"--suite {suite!r}: {', '.join(SUITES)}, or a sweep spec file")
    out = args.out or Path("out") / "bench" / Path(suite).stem
    families = tuple(f.strip() for f in args.families.split(",") if f.strip()) if args.families else ()
    try:
        result = run_bench(suite, methods, out, fields=fields, frames=args.frames, families=families,
                           rerun=tuple(args.rerun), timeout_s=args.timeout, command=shlex.join(["salo", *args.argv]),
                           on_event=lambda text: print(text, file=sys.stderr, flush=True), views=args.views,
                           view_max_points=args.view_points)
    except SuiteError as exc:
        raise CommandError(str(exc)) from None
    print(f"{len(result.sequences)} sequences x {len(methods)} methods: {result.ran} runs, {result.reused} reused, "
          f"{result.seconds:.0f} s")
    print(f"leaderboard: {result.outputs['html']} (Markdown: {result.outputs['markdown']})")
    views = [v for k, v in result.outputs.items() if k.startswith("view ")]
    if views:
        print(f"3D views: {len(views)} pages in {views[0].parent}")
    for r in result.failures:
        print(f"  failed: {r['label']} on {r['sequence']}: {r['error']}")
    return 0


def _ours() -> tuple[str, ...]:
    from tools.methods import builtin_names

    return builtin_names()
