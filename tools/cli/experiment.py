"""The experiment commands of ``salo``: ``experiment table|rejectors|ncf`` and ``report``.

Thin commands over ``tools.experiments``: parse, build the parameters, run the
library call, write the run folder, print where it went.
"""

from __future__ import annotations

from pathlib import Path

from .common import CommandError, command_line, parse_config_set, real_number, whole_number

DEFAULT_ROOT = Path("out/experiments")
DEFAULT_CACHE = DEFAULT_ROOT / "sequences"
TABLE_QUICK_FRAMES = 25
# The table's methods (tools.experiments.table.DEFAULT_METHODS, spelled out: `salo --help` imports no numpy).
TABLE_METHODS = "bl,ncf,salo,kiss-icp,genz-icp,small-gicp"
REJECTORS_QUICK_FRAMES = 5


def add_commands(subparsers) -> None:
    """Register ``experiment`` (with sub-commands table, rejectors, ncf) and ``report``."""
    p = subparsers.add_parser(
        "experiment",
        help="the SALO paper's experiments on simulated data (table, rejectors, ncf)",
        description="Run one of the paper's experiments on simulated sequences. Each writes a run folder "
        "(run.json with the command, parameters, seeds and version; results.json; CSV and Markdown tables; "
        "PNG figures; summary.md). Sequences are simulated in memory, or with --on-disk once into a capped cache "
        "(--cache, --cache-limit-gb) and reused when their parameters match.",
    )
    sub = p.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    _add_table(sub)
    _add_rejectors(sub)
    _add_ncf(sub)
    _add_generalize(sub)
    r = subparsers.add_parser(
        "report",
        help="gather an experiment's tables and figures into one HTML or Markdown page",
        description="Collect the summary.md, tables and PNG figures of a run folder (or of every run folder "
        "under RESULTS_DIR) into one page: HTML with the images embedded (self-contained), or Markdown "
        "linking the images by relative path.",
    )
    r.add_argument("results", type=Path, metavar="RESULTS_DIR", help="a run folder or a folder of run folders")
    r.add_argument("--format", choices=("html", "md"), default="html", help="page format (default html)")
    r.add_argument("--out", type=Path, help="output file (default RESULTS_DIR/report.html or report.md)")
    r.set_defaults(func=cmd_report)


def _common(p, name: str) -> None:
    p.add_argument("--out", type=Path, default=DEFAULT_ROOT / name, help=f"run folder (default {DEFAULT_ROOT / name})")
    p.add_argument("--on-disk", action="store_true",
                   help="simulate the sequences into the cache folder and read them from there, reused when their "
                   "parameters match (default: in memory, nothing but the results written)")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE,
                   help=f"with --on-disk: the cache folder (default {DEFAULT_CACHE})")
    p.add_argument("--cache-limit-gb", type=real_number(0.0, above=True), default=20.0,
                   help="with --on-disk: the cache's size cap; the least recently used sequences are removed, "
                   "each with a warning (default 20)")
    p.add_argument("--quick", action="store_true", help="a small, fast run (minutes -> seconds): for trying it out")
    p.add_argument("--set", dest="config_set", action="append", default=[], metavar="KEY=VALUE",
                   help="override an odometry parameter for every method (repeatable), a dotted key: e.g. "
                   "match.target=map (salo odometry --keys lists them)")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bars")


def _discard(out: Path, fresh: bool) -> None:
    """A run stopped by bad input leaves nothing: remove its run folder if this run made it."""
    if fresh:
        import shutil

        shutil.rmtree(out, ignore_errors=True)


def _cache(args) -> Path | None:
    """The cache folder with --on-disk, else None: sequences in memory."""
    return args.cache if args.on_disk else None


def _cache_limit(args) -> int:
    return int(args.cache_limit_gb * 1e9)


def _sequence_args(p, default_text: str, quick_frames: int) -> None:
    p.add_argument("--sequences", help=f"comma-separated SCENE[:SEED[:FRAMES]] (default {default_text})")
    p.add_argument("--frames", type=whole_number(2), help=f"frames per sequence (default 300; --quick {quick_frames})")
    p.add_argument("--sensor", default="salo32", help="sensor preset or YAML (default salo32)")
    p.add_argument("--noise-std", type=real_number(0.0), default=0.02, help="range noise, 1 sigma, m (default 0.02)")
    p.add_argument("--start", type=real_number(),
                   help="time along each path of the first sweep, s (default 0; --quick 10)")


def _add_table(sub) -> None:
    p = sub.add_parser(
        "table",
        help="Table I: mean / std of the relative error per 100 m, BL / NCF / SALO and the peers",
        description="Run BL, NCF and SALO (and the peers KISS-ICP, GenZ-ICP and small_gicp s2m when the peer "
        "extra is installed) over a suite of "
        "simulated sequences and tabulate the paper's figure: translational error of 100 m segments in m per "
        "100 m, mean and standard deviation per sequence and overall; plus KITTI %, ATE, RPE, each sequence's "
        "degeneracy summary and top-down trajectory plots (Fig. 4).",
    )
    _common(p, "table")
    _sequence_args(p, "city:1,city:2,city:3,tunnel:1,highway:1,open:1", TABLE_QUICK_FRAMES)
    p.add_argument("--methods", default=TABLE_METHODS, help="comma-separated (default all: %(default)s)")
    p.add_argument("--segment-length", type=real_number(0.0, above=True),
                   help="segment length, m (default 100; --quick 10)")
    p.add_argument("--step-frames", type=whole_number(1), help="frames between segment starts (default 10; --quick 5)")
    p.set_defaults(func=cmd_table)


def _add_rejectors(sub) -> None:
    p = sub.add_parser(
        "rejectors",
        help="Sec. IV-A / Fig. 3: GCR against the distance rejector from perturbed initial guesses",
        description="Register scan pairs from noisy initial guesses (rotation about a random axis by an angle "
        "uniform in [-l_r, l_r], translation along a random axis uniform in [-l_t, l_t]) with the distance "
        "rejector and with GCR, against the filtered and the raw previous scan and against a local map of the "
        "scans before it; translation-error box plots per level, and each rejector's precision and recall "
        "against the true correspondences.",
    )
    _common(p, "rejectors")
    _sequence_args(p, "city:1,city:2,city:3 (the table's)", REJECTORS_QUICK_FRAMES)
    p.add_argument("--pairs", type=whole_number(1), help="scan pairs (default 100, the paper's; --quick 4)")
    p.add_argument("--levels", help="comma-separated L_R_DEG:L_T_M (default 0:0,1:0.1,3:0.3,5:0.5,10:1)")
    p.add_argument("--targets", default="filtered,raw,map",
                   help="match targets: filtered, raw (the previous scan), map (default filtered,raw,map)")
    p.add_argument("--map-frames", type=whole_number(1), default=10,
                   help="scans before the source in the map target (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pair and noise draws (default 0)")
    p.set_defaults(func=cmd_rejectors)


def _add_ncf(sub) -> None:
    p = sub.add_parser(
        "ncf",
        help="NCF on known noise: predicted normal std against the true normal error",
        description="Predicted normal uncertainty (NCF) against the actual angle to the true normal, binned "
        "(calibration); kept share and errors of kept / rejected points as c_tau varies; isotropic against "
        "beam-aligned noise; over several range-noise levels.",
    )
    _common(p, "ncf")
    p.add_argument("--scans", help="comma-separated SCENE[:SEED] (default city:1,city:2,tunnel:1,open:1)")
    p.add_argument("--sensor", default="salo32", help="sensor preset or YAML (default salo32)")
    p.add_argument("--noise-levels", help="comma-separated range noise sigmas, m (default 0.005,0.01,0.02,0.04)")
    p.add_argument("--max-points", type=whole_number(1),
                   help="subsample ICP points per scan (default all; --quick 1500)")
    p.add_argument("--seed", type=int, default=0, help="seed of the subsampling (default 0)")
    p.set_defaults(func=cmd_ncf)


def _add_generalize(sub) -> None:
    p = sub.add_parser(
        "generalize",
        help="held-out suite: scene families x sensors x simulated/real-like data, with the peers",
        description="Run our odometry and the peers (KISS-ICP, GenZ-ICP, small_gicp scan-to-map, when the peer "
        "extra is installed) on the same in-memory frames of a suite of randomised scene families (city, suburb, "
        "canyon, tunnel, highway, open, forest, garage, bridge), sensors (vlp16, hdl32e, salo32, os1-64, "
        "narrow32) and two kinds of data: 'simulated' (motion distortion, ring and per-point time given) and "
        "'real' (x y z only, no "
        "distortion). Parameters are chosen on the tuning seeds; report the evaluation seeds. Per family and "
        "kind: mean and spread of KITTI t_err, r_err, vertical drift, failures (t_err > 10 %), frames/s.",
    )
    p.add_argument("--out", type=Path, help=f"run folder (default {DEFAULT_ROOT}/generalize-SPLIT)")
    p.add_argument("--split", choices=("tuning", "evaluation"), default="evaluation",
                   help="seed split (default evaluation; choose parameters on tuning)")
    p.add_argument("--seeds", help="comma-separated seeds instead of the split's (must not be the other split's)")
    p.add_argument("--families", help="comma-separated families (default all nine)")
    p.add_argument("--kinds", default="simulated,real", help="simulated, real or both (default both)")
    p.add_argument("--weather", help="comma-separated weather conditions, each sequence in each (clear, light-fog, "
                   "dense-fog, rain, snow, or all; clear is the others' twin: docs/weather.md); default: the suite "
                   "as it is, no receiver model")
    p.add_argument("--methods", help="comma-separated: default, bl, ncf, salo, bl-map, ncf-map, salo-map, kiss-icp, "
                   "genz-icp, small-gicp (default: default,bl,ncf,salo and the three peers)")
    p.add_argument("--frames", type=whole_number(20), help="frames per sequence (default 200; --quick 40)")
    p.add_argument("--workers", type=whole_number(1), default=1, help="sequences run at once (default 1)")
    p.add_argument("--quick", action="store_true",
                   help="a small, fast run: 40 frames of city and canyon, one seed, default + bl + kiss-icp")
    p.add_argument("--set", dest="config_set", action="append", default=[], metavar="KEY=VALUE",
                   help="override an odometry parameter for our methods (repeatable), a dotted key: e.g. "
                   "ncf.max_normal_std_deg=3 (salo odometry --keys lists them)")
    p.add_argument("--imu", metavar="GRADE", help="give every sequence an IMU of this grade (consumer, tactical: "
                   "docs/imu.md; the lidar's frames are those without it) and run the default with it too "
                   "(method default-imu)")
    p.add_argument("--resume", action="store_true",
                   help="read back the sequences a stopped run in --out finished (their poses) and run the rest; "
                   "with --families narrowed to what finished, it only writes the summary")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    p.set_defaults(func=cmd_generalize)


# ---------------------------------------------------------------- helpers
def _config_overrides(pairs: list[str]) -> dict:
    """``--set`` odometry overrides, nested by stage; checked once on the ``salo`` config."""
    from odometry.config import SALO, ConfigError, config_from_dict

    changes = parse_config_set(pairs)
    try:
        config_from_dict(changes, base=SALO, origin="--set")
    except ConfigError as exc:
        raise CommandError(str(exc)) from None
    return changes


def _specs(text: str | None, default: list, args, quick_frames: int, start_default: float = 0.0) -> tuple:
    from tools.sequence_cache import parse_spec

    frames = args.frames or (quick_frames if args.quick else None)
    start = args.start if args.start is not None else (10.0 if args.quick else start_default)
    common = {"sensor": args.sensor, "noise_std_m": args.noise_std, "start_s": start}
    try:
        if text:
            specs = [parse_spec(t.strip(), **common, **({"frames": frames} if frames else {}))
                     for t in text.split(",") if t.strip()]
        else:
            specs = [s.with_changes(**common, **({"frames": frames} if frames else {})) for s in default]
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return tuple(specs)


def _finish(record, out: Path) -> None:
    record.finish()
    print(f"wrote {out}/ (summary.md, results.json, tables, figures); `salo report {out}` makes one page")


# ---------------------------------------------------------------- commands
def cmd_table(args) -> int:
    from tools.experiments.table import (
        METHOD_LABELS,
        PEER_METHODS,
        TableParams,
        run_table,
        salo_vs_bl,
        table_rows,
        write_table,
    )
    from tools.records import RunRecord
    from tools.sequence_cache import table_suite

    default = table_suite()
    if args.quick and not args.sequences:
        default = [s for s in default if s.label is None and (s.scene, s.seed) in (("city", 1), ("tunnel", 1))]
    specs = _specs(args.sequences, default, args, quick_frames=TABLE_QUICK_FRAMES)
    try:
        params = TableParams(
            sequences=specs,
            methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()),
            segment_length_m=args.segment_length or (10.0 if args.quick else 100.0),
            step_frames=args.step_frames or (5 if args.quick else 10),
            config_overrides=_config_overrides(args.config_set),
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    fresh = not args.out.exists()
    record = RunRecord(args.out, "table", params.to_dict(), command_line()).start()
    try:
        result = run_table(params, _cache(args), record=record, progress=args.progress,
                           cache_limit_bytes=_cache_limit(args))
    except ValueError as exc:
        _discard(args.out, fresh)
        raise CommandError(str(exc)) from None
    write_table(result, record)
    print((args.out / "table.md").read_text(), end="")
    for v in salo_vs_bl(result):
        if v["salo_better"] is not None:
            verdict = "SALO lower" if v["salo_better"] else "SALO NOT lower"
            print(f"{v['sequence']}: BL {v['bl_mu']:.3f}, SALO {v['salo_mu']:.3f} m/100 m: {verdict}")
    peers = {METHOD_LABELS[m] for m in PEER_METHODS}
    for row in table_rows(result):
        if row["method"] in peers and not row["available"] and row.get("note"):
            print(f"{row['method']}: {row['note']}")
            peers.discard(row["method"])  # once per peer
    _finish(record, args.out)
    return 0


def _parse_levels(text: str) -> tuple:
    try:
        levels = tuple((float(a), float(b)) for a, b in (t.split(":") for t in text.split(",") if t.strip()))
    except ValueError:
        raise CommandError(f"--levels {text!r}: expected L_R_DEG:L_T_M pairs, e.g. 1:0.1,3:0.3") from None
    if not levels or any(a < 0 or b < 0 for a, b in levels):
        raise CommandError(f"--levels {text!r}: need at least one non-negative pair")
    return levels


def cmd_rejectors(args) -> int:
    from tools.experiments.rejector_study import (
        DEFAULT_LEVELS,
        TARGETS,
        RejectorStudyParams,
        run_rejector_study,
        write_rejector_study,
    )
    from tools.records import RunRecord
    from tools.sequence_cache import table_suite

    default = [s for s in table_suite() if s.scene == "city"]
    if args.quick and not args.sequences:
        default = default[:1]
    specs = _specs(args.sequences, default, args, quick_frames=REJECTORS_QUICK_FRAMES)
    targets = tuple(t.strip() for t in args.targets.split(",") if t.strip())
    if not targets or any(t not in TARGETS for t in targets):
        raise CommandError(f"--targets {args.targets!r}: choose from {', '.join(TARGETS)}")
    levels = _parse_levels(args.levels) if args.levels else (((0.0, 0.0), (5.0, 0.5)) if args.quick
                                                             else DEFAULT_LEVELS)
    params = RejectorStudyParams(pairs=args.pairs or (4 if args.quick else 100), levels=levels, targets=targets,
                                 sequences=specs, seed=args.seed, config_overrides=_config_overrides(args.config_set),
                                 map_frames=args.map_frames)
    fresh = not args.out.exists()
    record = RunRecord(args.out, "rejectors", params.to_dict(), command_line()).start()
    try:
        result = run_rejector_study(params, _cache(args), progress=args.progress,
                                    cache_limit_bytes=_cache_limit(args))
    except ValueError as exc:
        _discard(args.out, fresh)
        raise CommandError(str(exc)) from None
    write_rejector_study(result, record)
    for kind, f in result.finding.items():
        print(f"{kind:8s} target at the true pose: GCR precision {f['gcr_precision']:.3f} recall "
              f"{f['gcr_recall']:.3f}; distance rejector precision {f['distance_precision']:.3f} recall "
              f"{f['distance_recall']:.3f}")
    for r in result.error_summary:
        print(f"{r['level']:>16s}  {r['target']:8s} {r['rejector']:8s}  median t error {r['t_err_median_m']:.4f} m"
              f"  p90 {r['t_err_p90_m']:.4f} m")
    _finish(record, args.out)
    return 0


def cmd_ncf(args) -> int:
    from tools.experiments.ncf_study import DEFAULT_NOISE_LEVELS_M, NcfStudyParams, run_ncf_study, write_ncf_study
    from tools.records import RunRecord
    from tools.sequence_cache import SequenceSpec

    try:
        if args.scans:
            scans = []
            for t in args.scans.split(","):
                scene, _, seed = t.strip().partition(":")
                scans.append(SequenceSpec(scene, int(seed or 0), frames=2, start_s=10.0, sensor=args.sensor))
        elif args.quick:
            scans = [SequenceSpec("city", 1, frames=2, start_s=10.0, sensor=args.sensor)]
        else:
            scans = [s.with_changes(sensor=args.sensor) for s in NcfStudyParams().scans]
        levels = (tuple(float(x) for x in args.noise_levels.split(",")) if args.noise_levels
                  else ((0.01, 0.02) if args.quick else DEFAULT_NOISE_LEVELS_M))
    except ValueError:
        raise CommandError("--scans SCENE[:SEED],... and --noise-levels S1,S2,... (metres)") from None
    if any(n <= 0 for n in levels):
        raise CommandError("--noise-levels: every level must be > 0 m")
    params = NcfStudyParams(noise_levels_m=levels, scans=tuple(scans),
                            max_points_per_scan=args.max_points or (1500 if args.quick else None), seed=args.seed,
                            config_overrides=_config_overrides(args.config_set))
    fresh = not args.out.exists()
    record = RunRecord(args.out, "ncf", params.to_dict(), command_line()).start()
    try:
        result = run_ncf_study(params, _cache(args), progress=args.progress,
                               cache_limit_bytes=_cache_limit(args))
    except ValueError as exc:
        _discard(args.out, fresh)
        raise CommandError(str(exc)) from None
    write_ncf_study(result, record)
    for r in result.overview:
        print(f"{r['model']:9s} noise {1000 * r['noise_std_m']:4g} mm: {r['points']} points, median error "
              f"{r['error_median_deg']:.2f} deg, single-surface median Mahalanobis^2 "
              f"{r['single_surface_mahalanobis2_median']:.2f} (1.39 = calibrated), within 95 % bound "
              f"{r['single_surface_within_95']:.2f}")
    _finish(record, args.out)
    return 0


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(t.strip() for t in (text or "").split(",") if t.strip())


def _weather_conditions(text: str | None) -> tuple[str, ...]:
    """--weather's conditions ("all": every one); each checked (ValueError)."""
    from tools.weather_conditions import CONDITIONS, check_condition

    names = _csv(text)
    return CONDITIONS if names == ("all",) else tuple(check_condition(c) for c in names)


def cmd_generalize(args) -> int:
    from tools.experiments.generalize import (
        DEFAULT_FRAMES,
        DEFAULT_METHODS,
        IMU_METHOD,
        SPLITS,
        GeneralizeParams,
        method_label,
        run_generalize,
        write_generalize,
    )
    from tools.records import RunRecord

    try:
        seeds = tuple(int(s) for s in _csv(args.seeds))
    except ValueError:
        raise CommandError(f"--seeds {args.seeds!r}: expected whole numbers, e.g. 1,2") from None
    quick = args.quick
    methods = _csv(args.methods) or (("default", "bl", "kiss-icp") if quick else DEFAULT_METHODS)
    if args.imu and IMU_METHOD not in methods:
        methods = (*methods, IMU_METHOD)
    try:
        params = GeneralizeParams(
            split=args.split,
            seeds=seeds or ((SPLITS[args.split][0],) if quick else ()),
            families=_csv(args.families) or (("city", "canyon") if quick else ()),
            kinds=_csv(args.kinds),
            methods=tuple(methods),
            frames=args.frames or (40 if quick else DEFAULT_FRAMES),
            config_overrides=_config_overrides(args.config_set),
            weather=_weather_conditions(args.weather),
            imu=args.imu,
            **({"segment_lengths_m": (10.0, 20.0)} if quick else {}),
        )
        params.sequences()  # unknown families fail here, before anything is written
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    out = args.out or DEFAULT_ROOT / f"generalize-{args.split}"
    record = RunRecord(out, "generalize", params.to_dict(), command_line()).start()
    results = run_generalize(params, record=record, workers=args.workers, progress=args.progress,
                             resume=args.resume)
    rows = write_generalize(results, params, record)
    for r in rows:
        if r["family"] == "all":
            print(f"{r['kind']:9s} {method_label(r['method']):15s} t_err {r['t_err_pct_mean']:7.3f} "
                  f"± {r['t_err_pct_std']:.3f} %  failures {r['failures']}/{r['ran']}  "
                  f"{r['frames_per_second_mean']:.1f} frames/s")
    _finish(record, out)
    return 0


def cmd_report(args) -> int:
    from tools.experiments.report import ReportError, write_report

    out = args.out or args.results / f"report.{args.format}"
    try:
        path = write_report(args.results, out, fmt=args.format)
    except ReportError as exc:
        raise CommandError(str(exc)) from None
    print(f"wrote {path}")
    return 0
