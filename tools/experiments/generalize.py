"""Generalisation: odometry on worlds, sensors and data kinds its defaults were not chosen on.

The suite is ``tools.family_suite``'s: scene families x sensors x the two data
kinds ("simulated" with per-point ring and time, "real" with x, y, z only), the
seeds split into tuning and evaluation.

Per sequence every method runs on the same in-memory frames
(``simlidar.in_memory``), in one worker process, through the one interface
(``tools.methods.run_method``: the sensor's view, no truth): our variants (the
default configuration of ``salo odometry``, the paper's scan-to-scan BL / NCF /
SALO, their scan-to-map twins) and the peers (``tools.peers``: KISS-ICP,
GenZ-ICP, a small_gicp scan-to-map pipeline) when installed. Figures per
method (``family_suite.trajectory_figures``): KITTI t_err (%) and r_err
(deg/100 m) over segments of ``SEGMENT_LENGTHS_M`` (the sequences are 100-500 m
long, shorter than KITTI's 800 m), the vertical drift (end-point height error
over the distance travelled, %), failure (t_err > 10 %), frames/s. Per family
and kind: mean and spread (standard deviation over the sequences) of each.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from paramspec import value_text
from tools.family_suite import (
    DEFAULT_FRAMES,
    FAILURE_T_ERR_PCT,
    KINDS,
    SEGMENT_LENGTHS_M,
    SPLITS,
    SuiteSequence,
    simulate,
    suite,
    trajectory_figures,
    weather_suite,
)
from tools.records import RunRecord, fmt, markdown_table, write_csv, write_json
from tools.runners import MethodRun

log = logging.getLogger(__name__)

# "default-imu": the default with ``imu.enabled`` (the suite's sequences given an IMU: ``--imu GRADE``).
IMU_METHOD = "default-imu"
OUR_METHODS = ("default", "bl", "ncf", "salo", "bl-map", "ncf-map", "salo-map", IMU_METHOD)
PEER_METHODS = ("kiss-icp", "genz-icp", "small-gicp")
DEFAULT_METHODS = ("default", "bl", "ncf", "salo", *PEER_METHODS)


# ---------------------------------------------------------------- methods
def odometry_config(method: str, overrides: dict):
    """The odometry config a method name stands for (``default``: what ``salo odometry`` uses)."""
    from tools.methods import our_config

    if method == IMU_METHOD:
        return our_config("default").replace(**overrides).replace(imu={"enabled": True})
    return our_config(method).replace(**overrides)


def run_one(method: str, sequence, overrides: dict) -> MethodRun:
    """Run ``method`` over every frame of ``sequence`` through ``tools.methods.run_method`` (the sensor's view:
    no poses, no truth); a peer that is missing or fails gives a run without poses whose ``error`` says why."""
    from tools.methods import OursMethod, method_from_name, run_method

    m = OursMethod(method, odometry_config(method, overrides)) if method in OUR_METHODS else method_from_name(method)
    return run_method(m, sequence, keep_failures=True)


def run_sequence_task(seq: SuiteSequence, methods: tuple[str, ...], overrides: dict,
                      lengths_m: tuple[float, ...] = SEGMENT_LENGTHS_M) -> dict:
    """Simulate one suite sequence and run every method on it (a worker's task). JSON-able except poses."""
    t0 = time.perf_counter()
    try:
        sequence = simulate(seq)
    except Exception as exc:  # noqa: BLE001 - one bad draw must not end the suite; its row says why
        log.warning("%s: simulation failed: %s", seq.name, exc)
        return {"sequence": asdict(seq), "name": seq.name, "error": f"{type(exc).__name__}: {exc}", "methods": {}}
    sim_s = time.perf_counter() - t0
    gt = sequence.poses
    t_eig0 = np.array([d.translation_eigenvalues[0] for d in sequence.degeneracy])
    out = {"sequence": asdict(seq) | {"start_s": sequence.manifest["t_start_s"]}, "name": seq.name,
           "simulate_s": sim_s, "gt": gt,
           "t_eig0_median": float(np.median(t_eig0)), "t_eig0_min": float(np.min(t_eig0)), "methods": {}}
    for method in methods:
        run = run_one(method, sequence, overrides)
        flags = {} if run.flags is None else {"extrapolated": run.flags.extrapolated,
                                              "degenerate": run.flags.degenerate,
                                              "remapped_frames": run.flags.remapped}
        res = {"ok": run.ok, "note": run.error if run.error is not None else run.note,
               "frames_per_second": run.frames_per_second, "flags": flags}
        if run.ok:
            res.update(trajectory_figures(gt, run.poses, lengths_m))
            res["failed"] = bool(res["diverged"] or res["t_err_pct"] > FAILURE_T_ERR_PCT)
            res["poses"] = run.poses
        out["methods"][method] = res
        log.info("%s %s: %s", seq.name, method,
                 f"t_err {res.get('t_err_pct', float('nan')):.3f} %, {run.frames_per_second:.1f} frames/s"
                 if run.ok else res["note"])
    return out


# ---------------------------------------------------------------- the experiment
@dataclass(frozen=True)
class GeneralizeParams:
    """split: "tuning" or "evaluation" (or explicit ``seeds``). families, kinds, methods, frames:
    what runs. weather: conditions of ``tools.weather_conditions`` (each sequence in each, "clear" its
    twin); empty: the suite as it is, without a receiver model. config_overrides: odometry parameters
    changed for every one of our methods, nested by stage as in YAML. imu: an IMU grade
    (``simlidar.imu.IMU_GRADES``) given to every sequence (the lidar's frames are the same without it),
    which ``default-imu`` uses; None: no IMU."""

    split: str = "evaluation"
    seeds: tuple[int, ...] = ()
    families: tuple[str, ...] = ()
    kinds: tuple[str, ...] = KINDS
    methods: tuple[str, ...] = DEFAULT_METHODS
    frames: int = DEFAULT_FRAMES
    config_overrides: dict = field(default_factory=dict)
    segment_lengths_m: tuple[float, ...] = SEGMENT_LENGTHS_M
    weather: tuple[str, ...] = ()
    imu: str | None = None

    def __post_init__(self) -> None:
        from simlidar.imu import IMU_GRADES

        if self.imu is not None and self.imu not in IMU_GRADES:
            raise ValueError(f"unknown IMU grade {self.imu!r} (known: {', '.join(IMU_GRADES)})")
        if IMU_METHOD in self.methods and self.imu is None:
            raise ValueError(f"method {IMU_METHOD} needs sequences with an IMU: give an IMU grade "
                             f"({', '.join(IMU_GRADES)})")
        if self.split not in SPLITS and not self.seeds:
            raise ValueError(f"split must be one of {', '.join(SPLITS)} (or give seeds), got {self.split!r}")
        if self.seeds and self.split in SPLITS:
            other = set(self.seeds) & set(SPLITS["evaluation" if self.split == "tuning" else "tuning"])
            if other:
                raise ValueError(f"seeds {sorted(other)} belong to the other split")
        unknown = [m for m in self.methods if m not in OUR_METHODS + PEER_METHODS]
        if unknown:
            raise ValueError(f"unknown method {unknown[0]!r} (known: {', '.join(OUR_METHODS + PEER_METHODS)})")
        bad_kind = [k for k in self.kinds if k not in KINDS]
        if bad_kind:
            raise ValueError(f"unknown kind {bad_kind[0]!r} (known: {', '.join(KINDS)})")

    @property
    def seed_list(self) -> tuple[int, ...]:
        return tuple(self.seeds) or SPLITS[self.split]

    def sequences(self) -> list[SuiteSequence]:
        families = tuple(self.families) or None
        if self.weather:
            seqs = weather_suite(self.seed_list, self.frames, families, tuple(self.weather), tuple(self.kinds))
        else:
            seqs = suite(self.seed_list, self.frames, families, tuple(self.kinds))
        return seqs if self.imu is None else [replace(s, imu=self.imu) for s in seqs]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["seeds"] = list(self.seed_list)
        d["config_overrides"] = dict(self.config_overrides)
        return d


def run_generalize(params: GeneralizeParams, record: RunRecord | None = None, workers: int = 1,
                   progress: bool = False, resume: bool = False) -> list[dict]:
    """Run the suite, ``workers`` sequences at a time; with ``record``, write each sequence's poses as it ends.
    resume: a sequence a stopped run in ``record``'s folder finished is read back (``finished_result``), not run."""
    from tqdm import tqdm

    seqs = params.sequences()
    overrides = dict(params.config_overrides)
    results = []
    bar = tqdm(total=len(seqs), unit="sequence", desc="generalize", disable=not progress, dynamic_ncols=True)
    if resume and record is not None:
        finished = [finished_result(record.out_dir, seq, params) for seq in seqs]
        results = [r for r in finished if r is not None]
        seqs_to_run = [s for s, r in zip(seqs, finished, strict=True) if r is None]
        bar.update(len(results))
        log.info("resumed %d finished sequences, %d to run", len(results), len(seqs_to_run))
    else:
        seqs_to_run = seqs

    def done(res: dict) -> None:
        results.append(res)
        if record is not None:
            _write_poses(record, res)
        bar.update(1)
        bar.set_postfix_str(res["name"])

    if workers <= 1:
        for seq in seqs_to_run:
            done(run_sequence_task(seq, params.methods, overrides, params.segment_lengths_m))
    else:
        from concurrent.futures import as_completed

        from tools.worker_pool import spawned_pool

        with spawned_pool(workers) as pool:
            futures = [pool.submit(run_sequence_task, seq, params.methods, overrides, params.segment_lengths_m)
                       for seq in seqs_to_run]
            for f in as_completed(futures):
                done(f.result())
    bar.close()
    order = {s.name: i for i, s in enumerate(seqs)}
    return sorted(results, key=lambda r: order[r["name"]])


def _write_poses(record: RunRecord, res: dict) -> None:
    """A finished sequence's poses (gt.txt, METHOD.txt) and, last, its result.json (without the poses): what
    ``finished_result`` reads back."""
    from simlidar.formats.kitti import write_kitti_poses

    if "gt" in res:
        write_kitti_poses(record.path(f"poses/{res['name']}/gt.txt"), res["gt"])
    for m, r in res["methods"].items():
        if r.get("poses") is not None:
            write_kitti_poses(record.path(f"poses/{res['name']}/{m}.txt"), r["poses"])
    write_json(record.path(f"poses/{res['name']}/result.json"), {k: v for k, v in res.items() if k != "gt"} | {
        "methods": {m: {k: v for k, v in x.items() if k != "poses"} for m, x in res["methods"].items()}})


def finished_result(folder: Path, seq: SuiteSequence, params: GeneralizeParams) -> dict | None:
    """The result of a sequence a stopped run in ``folder`` finished, as ``run_sequence_task`` returns it, or None
    (not finished, another frame count, or a method asked for now without its run there). The figures are
    computed again from the poses (``params``' segments); frames/s, flags and notes come from its result.json,
    which a run before it was written lacks (frames/s then unknown: nan)."""
    import json

    from simlidar.formats.kitti import read_kitti_poses

    d = Path(folder) / "poses" / seq.name
    if not (d / "gt.txt").is_file():
        return None
    gt = read_kitti_poses(d / "gt.txt")
    saved = json.loads((d / "result.json").read_text()) if (d / "result.json").is_file() else None
    if len(gt) != params.frames or (saved is not None and saved.get("error")):
        return None
    saved_methods = (saved or {}).get("methods", {})
    res = saved or {"sequence": asdict(seq), "name": seq.name}
    res["methods"], res["gt"] = {}, gt
    for m in params.methods:
        before = saved_methods.get(m)
        if before is not None and not before.get("ok"):
            res["methods"][m] = before  # (a peer not installed, a method that failed: as it was)
            continue
        if not (d / f"{m}.txt").is_file():
            return None
        x = {"ok": True, "note": "read back from its poses", "frames_per_second": float("nan"), "flags": {}}
        x.update({k: before[k] for k in ("note", "frames_per_second", "flags") if before and k in before})
        x["poses"] = read_kitti_poses(d / f"{m}.txt")
        x.update(trajectory_figures(gt, x["poses"], params.segment_lengths_m))
        x["failed"] = bool(x["diverged"] or x["t_err_pct"] > FAILURE_T_ERR_PCT)
        res["methods"][m] = x
    return res


# ---------------------------------------------------------------- summaries
FIGURES = ("t_err_pct", "r_err_deg_per_100m", "vertical_drift_pct", "frames_per_second")


def summarize(results: list[dict], methods: tuple[str, ...]) -> list[dict]:
    """Per (family, kind, method): mean and standard deviation over the sequences of each figure,
    failures, and how many sequences ran. Also (family "all") over every family."""
    rows = []
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in results:
        s = r["sequence"]
        kind = s["kind"] if not s.get("weather") else f"{s['kind']}, {s['weather']}"
        groups.setdefault((s["family"], kind), []).append(r)
        groups.setdefault(("all", kind), []).append(r)
    for (family, kind), rs in groups.items():
        for m in methods:
            runs = [r["methods"].get(m, {}) for r in rs]
            ok = [x for x in runs if x.get("ok")]
            row = {"family": family, "kind": kind, "method": m, "sequences": len(rs), "ran": len(ok),
                   "failures": sum(x["failed"] for x in ok),
                   "note": next((x.get("note", "") for x in runs if not x.get("ok")), "")}
            for f in FIGURES:
                v = np.array([x.get(f, np.nan) for x in ok], dtype=float)
                v = v[np.isfinite(v)]
                if f == "vertical_drift_pct":
                    v = np.abs(v)
                row[f"{f}_mean"] = float(v.mean()) if len(v) else float("nan")
                row[f"{f}_std"] = float(v.std()) if len(v) else float("nan")
            rows.append(row)
    return rows


# The bound a weather's t_err is held to against its clear twin's (issue "Weather": light fog and rain).
TWIN_RATIO_BOUND = 1.5


def twin_ratios(results: list[dict], methods: tuple[str, ...]) -> list[dict]:
    """Per (weather condition, method): each sequence's t_err against its clear twin's (the same sequence,
    weather "clear"): the median and largest ratio over the sequences, how many exceed ``TWIN_RATIO_BOUND``,
    and the failures in the weather. Empty without a clear twin."""
    def twin_key(seq: dict) -> tuple:
        return tuple(sorted((k, str(v)) for k, v in seq.items() if k != "weather"))

    clear = {twin_key(r["sequence"]): r for r in results if r["sequence"].get("weather") == "clear"}
    rows = []
    conditions = dict.fromkeys(r["sequence"]["weather"] for r in results
                               if r["sequence"].get("weather") not in (None, "clear"))
    for cond in conditions:
        pairs = [(r, clear.get(twin_key(r["sequence"]))) for r in results if r["sequence"].get("weather") == cond]
        for m in methods:
            ratios, failures, ran = [], 0, 0
            for r, twin in pairs:
                x, y = r["methods"].get(m, {}), (twin or {}).get("methods", {}).get(m, {})
                if not x.get("ok"):
                    continue
                ran += 1
                failures += bool(x.get("failed"))
                a, b = x.get("t_err_pct"), y.get("t_err_pct") if y.get("ok") else None
                if a is not None and b is not None and math.isfinite(a) and math.isfinite(b) and b > 0:
                    ratios.append(a / b)
            rows.append({"weather": cond, "method": m, "ran": ran, "failures": failures, "pairs": len(ratios),
                         "ratio_median": float(np.median(ratios)) if ratios else float("nan"),
                         "ratio_max": float(max(ratios)) if ratios else float("nan"),
                         "over_bound": sum(v > TWIN_RATIO_BOUND for v in ratios)})
    return rows


def twin_table_markdown(rows: list[dict], methods: tuple[str, ...]) -> str:
    """Rows per weather condition, a column per method: median / largest ratio to the clear twin's t_err,
    (sequences over the bound), failures."""
    by = {(r["weather"], r["method"]): r for r in rows}
    out = []
    for cond in dict.fromkeys(r["weather"] for r in rows):
        cells = []
        for m in methods:
            r = by[(cond, m)]
            cell = (f"{fmt(r['ratio_median'], '.2f')} / {fmt(r['ratio_max'], '.2f')} "
                    f"({r['over_bound']}/{r['pairs']} over {TWIN_RATIO_BOUND:g}x)") if r["pairs"] else "n/a"
            if r["failures"]:
                cell += f", {r['failures']}/{r['ran']} failed"
            cells.append(cell)
        out.append([cond, *cells])
    return markdown_table(["weather", *(method_label(m) for m in methods)], out)


def imu_against_lidar_only(results: list[dict]) -> list[dict]:
    """Per kind (and "all"): each sequence's t_err with the IMU (``default-imu``) against the default's on
    the same frames: the median and largest ratio, the sequence of the largest, failures of each. Empty
    when no result has both runs."""
    groups: dict[str, list[tuple[str, float, float, bool, bool]]] = {}
    for r in results:
        a, b = r["methods"].get("default", {}), r["methods"].get(IMU_METHOD, {})
        if not (a.get("ok") and b.get("ok") and not np.isnan(a["t_err_pct"]) and not np.isnan(b["t_err_pct"])):
            continue  # (a path shorter than every segment has no t_err to compare)
        pair = (r["name"], a["t_err_pct"], b["t_err_pct"], bool(a["failed"]), bool(b["failed"]))
        groups.setdefault(r["sequence"]["kind"], []).append(pair)
        groups.setdefault("all", []).append(pair)
    rows = []
    for kind, pairs in groups.items():
        ratios = np.array([w / max(wo, 1e-9) for _, wo, w, _, _ in pairs])
        worst = int(np.argmax(ratios))
        rows.append({"kind": kind, "sequences": len(pairs), "ratio_median": float(np.median(ratios)),
                     "ratio_max": float(ratios[worst]), "worst": pairs[worst][0],
                     "worst_t_err_pct": (pairs[worst][1], pairs[worst][2]),
                     "failures_lidar_only": sum(p[3] for p in pairs), "failures_with_imu": sum(p[4] for p in pairs)})
    return rows


def method_label(m: str) -> str:
    from tools.methods import method_label as label

    return label(m)


def table_markdown(rows: list[dict], methods: tuple[str, ...], figure: str = "t_err_pct", spec: str = ".2f") -> str:
    """Rows family x kind, a column per method: ``mean +- std`` of ``figure`` (failures marked), best in bold."""
    header = ["family", "kind", *(method_label(m) for m in methods)]
    keys = sorted({(r["family"], r["kind"]) for r in rows}, key=lambda k: (k[0] == "all", k[0], k[1]))
    by = {(r["family"], r["kind"], r["method"]): r for r in rows}
    out = []
    for fam, kind in keys:
        cells = []
        means = [by[(fam, kind, m)][f"{figure}_mean"] for m in methods if (fam, kind, m) in by]
        finite = [v for v in means if math.isfinite(v)]
        best = min(finite) if finite and figure != "frames_per_second" else (max(finite) if finite else None)
        for m in methods:
            r = by.get((fam, kind, m))
            if r is None or not r["ran"]:
                cells.append("n/a")
                continue
            mu, sd = r[f"{figure}_mean"], r[f"{figure}_std"]
            cell = f"{fmt(mu, spec)} ± {fmt(sd, spec)}"
            if best is not None and math.isfinite(mu) and mu == best:
                cell = f"**{cell}**"
            if r["failures"]:
                cell += f" ({r['failures']}/{r['ran']} failed)"
            cells.append(cell)
        out.append([fam, kind, *cells])
    return markdown_table(header, out)


def write_generalize(results: list[dict], params: GeneralizeParams, record: RunRecord) -> list[dict]:
    """results.json, per-sequence and summary CSV, summary.md and the plots into the run folder."""
    from tools.plotting import trajectory_grid

    from . import plots

    methods = params.methods
    rows = summarize(results, methods)
    per_seq = []
    for r in results:
        for m, x in r["methods"].items():
            per_seq.append({"sequence": r["name"], **r["sequence"], "method": m,
                            "t_eig0_median": r.get("t_eig0_median"),
                            **{k: v for k, v in x.items() if k not in ("poses", "flags")}, **x.get("flags", {})})
    cols = ["sequence", "family", "seed", "sensor", "kind", "weather", "frames", "noise_std_m", "start_s",
            "t_eig0_median",
            "method", "ok", "note", "t_err_pct", "r_err_deg_per_100m", "vertical_drift_pct", "ate_aligned_m",
            "rpe_t_cm", "rpe_r_deg", "path_length_m", "failed", "frames_per_second", "extrapolated", "degenerate",
            "remapped_frames"]
    write_csv(record.path("sequences.csv"), per_seq, cols)
    write_csv(record.path("summary.csv"), rows, ["family", "kind", "method", "sequences", "ran", "failures", "note"]
              + [f"{f}_{s}" for f in FIGURES for s in ("mean", "std")])
    write_json(record.path("results.json"), {
        "experiment": "generalize", "params": params.to_dict(), "summary": rows,
        "weather_against_clear": twin_ratios(results, methods),
        "imu_against_lidar_only": imu_against_lidar_only(results),
        "sequences": [{k: v for k, v in r.items() if k != "gt"} | {"methods": {
            m: {k: v for k, v in x.items() if k != "poses"} for m, x in r["methods"].items()}} for r in results],
    })
    errors = [r for r in results if r.get("error")]
    lines = [f"# Generalisation suite: {params.split} seeds {list(params.seed_list)}", "",
             f"{len(results)} sequences ({len(results) - len(errors)} simulated without error), "
             f"{params.frames} frames each; "
             f"families {', '.join(sorted({r['sequence']['family'] for r in results}))}; kinds "
             f"{', '.join(params.kinds)}. KITTI t_err over "
             f"{', '.join(f'{v:g}' for v in params.segment_lengths_m)} m "
             f"segments; mean ± standard deviation over the sequences of each family; "
             f"failed: t_err > {FAILURE_T_ERR_PCT:g} %.", ""]
    if params.config_overrides:
        lines += ["Odometry parameters changed for our methods: "
                  + ", ".join(f"`{k}: {value_text(v)}`" for k, v in params.config_overrides.items()) + ".", ""]
    from odometry.config import DEFAULT_VARIANT

    lines += [f"`default` is `salo odometry`'s default configuration, the variant `{DEFAULT_VARIANT}`.", ""]
    for figure, title, spec in (("t_err_pct", "KITTI t_err, %", ".2f"),
                                ("r_err_deg_per_100m", "KITTI r_err, deg / 100 m", ".3f"),
                                ("vertical_drift_pct", "vertical drift |dz| / distance, %", ".2f"),
                                ("frames_per_second", "frames / s", ".1f")):
        lines += [f"## {title}", "", table_markdown(rows, methods, figure, spec), ""]
    twins = twin_ratios(results, methods)
    if twins:
        lines += ["## Each weather against its clear twin", "",
                  "Per sequence, t_err in the weather / t_err of the same sequence in clear air: median / largest "
                  f"over the sequences (how many above {TWIN_RATIO_BOUND:g}x), and failures in the weather.", "",
                  twin_table_markdown(twins, methods), ""]
    with_imu = imu_against_lidar_only(results)
    if with_imu:
        lines += [f"## The default with the IMU ({params.imu} grade) against lidar only", "",
                  "Per sequence, t_err with the IMU / t_err lidar only, on the same frames: median and largest over "
                  "the sequences, and the sequence of the largest (its t_err lidar only, with the IMU).", "",
                  markdown_table(["kind", "sequences", "median", "largest", "where (lidar only, with IMU, %)",
                                  "failures lidar only", "failures with IMU"],
                                 [[r["kind"], r["sequences"], fmt(r["ratio_median"], ".2f"), fmt(r["ratio_max"], ".2f"),
                                   f"{r['worst']} ({fmt(r['worst_t_err_pct'][0], '.3f')}, "
                                   f"{fmt(r['worst_t_err_pct'][1], '.3f')})",
                                   r["failures_lidar_only"], r["failures_with_imu"]] for r in with_imu]), ""]
    for r in errors:
        lines.append(f"- {r['name']}: not simulated ({r['error']})")
    unavailable = {m: x["note"] for r in results for m, x in r["methods"].items() if not x.get("ok")}
    for m, note in unavailable.items():
        lines.append(f"- {method_label(m)}: {note}")
    lines += ["", "## Per sequence", "", "![t_err per family](t_err_per_family.png)", "",
              "![trajectories](trajectories.png)", ""]
    header = ["sequence", "sensor", "noise, cm", "start, s", "t_eig0 median", *(method_label(m) for m in methods)]
    body = []
    for r in results:
        s = r["sequence"]
        cells = []
        for m in methods:
            x = r["methods"].get(m, {})
            cells.append("n/a" if not x.get("ok") else fmt(x.get("t_err_pct"), ".2f") + (" ✗" if x.get("failed")
                                                                                         else ""))
        body.append([r["name"], s["sensor"], fmt(100 * s["noise_std_m"], ".1f"), fmt(s["start_s"], ".1f"),
                     fmt(r.get("t_eig0_median"), ".4f"), *cells])
    lines.append(markdown_table(header, body))
    record.write_text("summary.md", "\n".join(lines) + "\n")
    weathers = sorted({r["sequence"].get("weather") or "clear" for r in results})
    note = "; ".join(
        ([f"our methods with {', '.join(f'{k}={value_text(v)}' for k, v in params.config_overrides.items())}"]
         if params.config_overrides else [])
        + ([f"each bar pools the weathers {', '.join(weathers)}"] if len(weathers) > 1 else []))
    plots.family_error_plot(record.path("t_err_per_family.png"), results, methods, method_label,
                            FAILURE_T_ERR_PCT, note)
    tracks = []
    for r in results:
        if "gt" not in r:
            continue
        est = {method_label(m): x["poses"] for m, x in r["methods"].items() if x.get("ok")}
        errs = {method_label(m): (x["t_err_pct"], 0.0) for m, x in r["methods"].items() if x.get("ok")}
        tracks.append((r["name"], r["gt"], est, errs))
    if tracks:
        trajectory_grid(record.path("trajectories.png"), tracks, segment_length_m=100.0)
    return rows
