"""Table I on simulated data: relative positioning error per 100 m, BL / NCF / SALO and the peers.

For every sequence of the suite (``tools.sequence_cache``) each method runs
over the same frames, through the one interface (``tools.methods.run_method``,
handed the sensor's data only): our odometry with the ``bl``, ``ncf`` and
``salo`` configs, and the peers KISS-ICP, GenZ-ICP and a small_gicp scan-to-map
pipeline through their Python APIs when installed (``tools.peers``; a missing
one gets a row saying so). The paper's figure is the
translational error of every ``segment_length_m`` (100 m) segment of the KITTI
protocol (first frames every 10th frame, ``odometry.metrics.kitti_segment_errors``)
in metres per 100 m: mean mu and population standard deviation sigma per
sequence, and over all segments of all sequences pooled ("Overall"). The
other figures of ``odometry.metrics`` (KITTI %, deg/100 m, ATE, RPE) come along.

Besides the table: each sequence's degeneracy summary (from the point-to-plane
information of the true normals the simulator records, ``degeneracy.csv``;
and how many frames each method flagged degenerate or extrapolated), the
trajectories (KITTI pose files) and per-frame diagnostics of every method, and
top-down plots of ground truth against every method (the paper's Fig. 4).
Where SALO's mean is not below BL's, the summary says so.
"""

from __future__ import annotations

import csv
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paramspec import value_text
from tools.peers import PEERS
from tools.records import RunRecord, fmt, markdown_table, write_csv, write_json
from tools.runners import FrameFlags, MethodRun, segment_errors_per_100m
from tools.sequence_cache import DEFAULT_CACHE_LIMIT_BYTES, SequenceSpec, load_sequence, table_suite

log = logging.getLogger(__name__)

OUR_METHODS = ("bl", "ncf", "salo")
PEER_METHODS = tuple(PEERS)  # kiss-icp, genz-icp, small-gicp
DEFAULT_METHODS = (*OUR_METHODS, *PEER_METHODS)
METHOD_LABELS = {"bl": "BL", "ncf": "NCF", "salo": "SALO", **{name: p.label for name, p in PEERS.items()}}
# A frame is "weakly constrained" when the smallest translational eigenvalue of its
# per-point information (true normals) is below this (the odometry's degeneracy.degenerate_eigenvalue default).
WEAK_TRANSLATION_EIGENVALUE = 0.01


@dataclass(frozen=True)
class TableParams:
    """What the table runs on.

    sequences: the suite. methods: any of bl, ncf, salo, kiss-icp, genz-icp, small-gicp.
    segment_length_m: the paper's 100 m (shorter for quick runs; errors are
    still per 100 m). step_frames: spacing of segment starts (KITTI: 10).
    config_overrides: changes to all three odometry configs, nested by stage as in YAML (e.g.
    ``{"match": {"target": "raw"}}``).
    """

    sequences: tuple[SequenceSpec, ...] = field(default_factory=lambda: tuple(table_suite()))
    methods: tuple[str, ...] = DEFAULT_METHODS
    segment_length_m: float = 100.0
    step_frames: int = 10
    config_overrides: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = [m for m in self.methods if m not in DEFAULT_METHODS]
        if unknown:
            raise ValueError(f"unknown method {unknown[0]!r} (known: {', '.join(DEFAULT_METHODS)})")
        names = [s.name for s in self.sequences]
        if len(set(names)) != len(names):
            raise ValueError(f"sequence names repeat: {names} (give each a label)")

    def to_dict(self) -> dict:
        return {"sequences": [s.to_dict() for s in self.sequences], "methods": list(self.methods),
                "segment_length_m": self.segment_length_m, "step_frames": self.step_frames,
                "config_overrides": dict(self.config_overrides)}


def odometry_config(method: str, overrides: dict):
    from odometry.config import variant

    return variant(method).replace(**overrides)


def mean_std(errors: np.ndarray) -> tuple[float, float]:
    """Mean and population standard deviation of segment errors (m per 100 m); NaN, NaN when there are none."""
    return (float(np.mean(errors)), float(np.std(errors))) if len(errors) else (float("nan"), float("nan"))


def degeneracy_summary(sequence) -> dict:
    """Figures of a sequence's per-frame degeneracy (dimensionless translational eigenvalues, per point).

    sequence: a folder (its ``degeneracy.csv``) or a sequence in memory (its ``degeneracy``, the same figures).
    """
    if isinstance(sequence, (str, Path)):
        with open(Path(sequence) / "degeneracy.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        t0 = np.array([float(r["t_eig0"]) for r in rows])
        t2 = np.array([float(r["t_eig2"]) for r in rows])
        weak = np.array([[float(r["weak_x"]), float(r["weak_y"]), float(r["weak_z"])] for r in rows])
    else:
        t0 = np.array([d.translation_eigenvalues[0] for d in sequence.degeneracy])
        t2 = np.array([d.translation_eigenvalues[2] for d in sequence.degeneracy])
        weak = np.array([d.weakest_translation for d in sequence.degeneracy])
    worst = int(np.argmin(t0))
    return {
        "frames": len(t0),
        "t_eig0_min": float(t0.min()), "t_eig0_median": float(np.median(t0)),
        "t_condition_median": float(np.median(t2 / np.maximum(t0, 1e-12))),
        "weak_frames": int((t0 < WEAK_TRANSLATION_EIGENVALUE).sum()),
        "weak_threshold": WEAK_TRANSLATION_EIGENVALUE,
        "weakest_direction_at_min": weak[worst].tolist(),
        "weakest_direction_median_abs": np.median(np.abs(weak), axis=0).tolist(),
    }


def table_method(method: str, params: TableParams):
    """The ``tools.methods.Method`` a table's method name stands for: ours with the table's overrides, or a
    peer on the range limits of SALO's configuration with them."""
    from tools.methods import OursMethod, PeerMethod

    overrides = dict(params.config_overrides)
    if method in PEER_METHODS:
        clean = odometry_config("salo", overrides).clean
        return PeerMethod(method, clean.min_range_m, clean.max_range_m)
    return OursMethod(method, odometry_config(method, overrides))


def run_in_table(method: str, sequence, params: TableParams, progress: bool) -> MethodRun:
    """One method over one sequence (``tools.methods.run_method``: the sensor's data only). A peer that cannot
    run here or fails gives a run without poses whose ``error`` says why; the run's note is the table's:
    a peer's distribution and version, nothing for ours."""
    from tqdm import tqdm

    from tools.methods import run_method

    desc = f"{METHOD_LABELS[method]} {sequence.path.name}"
    with tqdm(total=len(sequence), unit="frame", desc=desc, disable=not progress, dynamic_ncols=True) as bar:
        run = run_method(table_method(method, params), sequence, on_frame=lambda k, d: bar.update(1),
                         keep_failures=True)
    run.note = f"{PEERS[method].distribution} {run.settings.get('version')}" if method in PEER_METHODS else ""
    return run


def score_run(run: MethodRun, gt: np.ndarray, params: TableParams) -> tuple[np.ndarray, dict]:
    """A finished run's per-segment errors (m per 100 m) and figures (``odometry.metrics``) against the ground
    truth ``gt`` (N, 4, 4); none for a run without poses, and a diverged run is marked so in its ``error``."""
    from odometry.metrics import evaluate_trajectory

    if not run.ok:
        return np.zeros(0), {}
    bad = ~np.all(np.isfinite(run.poses.reshape(len(run.poses), -1)), axis=1)
    if bad.any():
        run.error = f"diverged: non-finite pose from frame {int(np.argmax(bad))}"
        return np.zeros(0), {}
    errors = segment_errors_per_100m(gt, run.poses, params.segment_length_m, params.step_frames)
    return errors, evaluate_trajectory(gt, run.poses).to_dict()


@dataclass
class SequenceResult:
    """One sequence of the table: its spec, folder (None: simulated in memory), ground truth (N, 4, 4),
    degeneracy summary, and per method its run, its per-segment errors (m per 100 m; none for a run
    without poses) and its figures against the truth (``odometry.metrics.TrajectoryMetrics.to_dict``)."""

    spec: SequenceSpec
    folder: Path | None
    gt: np.ndarray
    degeneracy: dict
    runs: dict[str, MethodRun]
    segment_errors: dict[str, np.ndarray]
    metrics: dict[str, dict]


@dataclass
class TableResult:
    params: TableParams
    sequences: list[SequenceResult]

    def well_constrained(self) -> list[str]:
        """Sequences whose median frame is not weakly constrained (a property of the data, not of the results)."""
        return [s.spec.name for s in self.sequences if s.degeneracy["t_eig0_median"] >= WEAK_TRANSLATION_EIGENVALUE]

    def overall(self, method: str, names: list[str] | None = None) -> tuple[float, float, int]:
        """Pooled mean, std (m per 100 m) and segment count of a method over the sequences ``names`` (default all)."""
        errs = [s.segment_errors[method] for s in self.sequences
                if method in s.runs and s.runs[method].ok and (names is None or s.spec.name in names)]
        v = np.concatenate(errs) if errs else np.zeros(0)
        return (float(np.mean(v)), float(np.std(v)), len(v)) if len(v) else (float("nan"), float("nan"), 0)


def run_table(params: TableParams, cache_dir: str | Path | None, record: RunRecord | None = None,
              progress: bool = False, cache_limit_bytes: int | None = DEFAULT_CACHE_LIMIT_BYTES) -> TableResult:
    """Run every method on every sequence; with ``record``, write each sequence's poses as it finishes.

    cache_dir: the sequence cache (``suite.ensure_sequence``), or None: each sequence simulated in
    memory, used by every method, then dropped (nothing but the results is written).
    """
    results = []
    for spec in params.sequences:
        seq = load_sequence(spec, cache_dir, progress, cache_limit_bytes=cache_limit_bytes)
        folder = seq.path if cache_dir is not None else None
        runs, errors, metrics = {}, {}, {}
        for m in params.methods:
            log.info("table: %s on %s", m, spec.name)
            runs[m] = run_in_table(m, seq, params, progress)
            errors[m], metrics[m] = score_run(runs[m], seq.poses, params)
            if record is not None and runs[m].ok:
                record.write_run(f"poses/{spec.name}/{m}", runs[m])
        results.append(SequenceResult(spec, folder, seq.poses, degeneracy_summary(folder or seq), runs, errors,
                                      metrics))
        if record is not None:
            from simlidar.formats.kitti import write_kitti_poses

            write_kitti_poses(record.path(f"poses/{spec.name}/gt.txt"), seq.poses)
    return TableResult(params, results)


# ---------------------------------------------------------------- outputs
def table_rows(result: TableResult) -> list[dict]:
    """One row per (sequence or "overall", method): the table's figures, flat, for CSV and JSON."""
    rows = []
    for s in result.sequences:
        for m, r in s.runs.items():
            met = s.metrics[m]
            mu, sigma = mean_std(s.segment_errors[m])
            flags = r.flags or FrameFlags(None, None, None)
            rows.append({
                "sequence": s.spec.name, "scene": s.spec.scene, "method": METHOD_LABELS[m], "available": r.ok,
                "note": r.error if r.error is not None else r.note, "mu_m_per_100m": mu, "sigma_m_per_100m": sigma,
                "segments": len(s.segment_errors[m]), "path_length_m": met.get("path_length_m"),
                "frames": met.get("frames"), "t_err_pct": met.get("t_err_pct"),
                "r_err_deg_per_100m": met.get("r_err_deg_per_100m"), "ate_rmse_m": met.get("ate_rmse_m"),
                "ate_aligned_rmse_m": met.get("ate_aligned_rmse_m"), "rpe_t_mean_m": met.get("rpe_t_mean_m"),
                "rpe_r_mean_deg": met.get("rpe_r_mean_deg"), "flagged_degenerate": flags.degenerate,
                "extrapolated": flags.extrapolated, "frames_per_second": r.frames_per_second,
            })
    for m in result.params.methods:
        mu, sigma, n = result.overall(m)
        rows.append({"sequence": "overall", "scene": "", "method": METHOD_LABELS[m],
                     "available": n > 0, "mu_m_per_100m": mu, "sigma_m_per_100m": sigma, "segments": n})
    good = result.well_constrained()
    if 0 < len(good) < len(result.sequences):
        for m in result.params.methods:
            mu, sigma, n = result.overall(m, good)
            rows.append({"sequence": "overall well-constrained", "scene": "", "method": METHOD_LABELS[m],
                         "available": n > 0, "mu_m_per_100m": mu, "sigma_m_per_100m": sigma, "segments": n,
                         "note": "sequences: " + ", ".join(good)})
    return rows


def salo_vs_bl(result: TableResult) -> list[dict]:
    """Per sequence and overall: SALO's and BL's means, and whether SALO's is lower."""
    if "salo" not in result.params.methods or "bl" not in result.params.methods:
        return []
    out = []
    for s in result.sequences:
        b, a = mean_std(s.segment_errors["bl"])[0], mean_std(s.segment_errors["salo"])[0]
        out.append({"sequence": s.spec.name, "bl_mu": b, "salo_mu": a, "salo_better": bool(a < b)
                    if math.isfinite(a) and math.isfinite(b) else None,
                    "change_pct": 100.0 * (a - b) / b if math.isfinite(a) and math.isfinite(b) and b > 0 else None})
    good = result.well_constrained()
    pools = [("overall", None)] + ([("overall well-constrained", good)] if 0 < len(good) < len(result.sequences)
                                   else [])
    for label, names in pools:
        b, a = result.overall("bl", names)[0], result.overall("salo", names)[0]
        out.append({"sequence": label, "bl_mu": b, "salo_mu": a,
                    "salo_better": bool(a < b) if math.isfinite(a) and math.isfinite(b) else None,
                    "change_pct": 100.0 * (a - b) / b if math.isfinite(a) and math.isfinite(b) and b > 0 else None})
    return out


def paper_table_markdown(result: TableResult) -> str:
    """The paper's layout: a row per method, (mu, sigma) per sequence and overall; the lowest mu in bold."""
    seqs = [s.spec.name for s in result.sequences]
    header = ["Method"] + [f"{n} {q}" for n in [*seqs, "Overall"] for q in ("mu, m", "sigma, m")]
    cols: dict[str, dict[str, tuple[float, float]]] = {}
    for s in result.sequences:
        cols[s.spec.name] = {m: mean_std(s.segment_errors[m]) for m, r in s.runs.items() if r.ok}
    cols["Overall"] = {m: result.overall(m)[:2] for m in result.params.methods}
    best = {c: min((v[0] for v in d.values() if math.isfinite(v[0])), default=None) for c, d in cols.items()}
    rows = []
    for m in result.params.methods:
        row = [METHOD_LABELS[m]]
        for c in [*seqs, "Overall"]:
            mu, sd = cols[c].get(m, (float("nan"), float("nan")))
            cell_mu, cell_sd = fmt(mu), fmt(sd)
            if best[c] is not None and math.isfinite(mu) and mu == best[c]:
                cell_mu, cell_sd = f"**{cell_mu}**", f"**{cell_sd}**"
            row += [cell_mu, cell_sd]
        rows.append(row)
    return markdown_table(header, rows)


def table_markdown(result: TableResult, params: dict) -> str:
    L = result.params.segment_length_m
    lines = ["# Mean relative positioning error per 100 m (SALO Table I, simulated)", ""]
    sens = result.sequences[0].spec if result.sequences else None
    if sens is not None:
        lines.append(f"Sensor `{sens.sensor}`, range noise {1000 * sens.noise_std_m:g} mm (1 sigma); "
                     f"translational error of every {L:g} m segment (KITTI protocol, starts every "
                     f"{result.params.step_frames}th frame) in metres per 100 m: mean mu and standard deviation "
                     "sigma per sequence, and over all segments pooled (Overall). Lowest mu per column in bold.")
    if result.params.config_overrides:
        changed = ", ".join(f"`{k}: {value_text(v)}`" for k, v in result.params.config_overrides.items())
        lines.append(f"\nOdometry parameters changed from the variants' defaults, for every method: {changed}.")
    if L != 100.0:
        lines.append(f"\n**Segments are {L:g} m here, not the paper's 100 m** (a quick run): errors are still "
                     "scaled to m per 100 m, but are not comparable with 100 m figures.")
    lines += ["", paper_table_markdown(result)]
    good = result.well_constrained()
    if 0 < len(good) < len(result.sequences):
        weak = [s.spec.name for s in result.sequences if s.spec.name not in good]
        lines.append(f"Weakly constrained sequences (median smallest translational eigenvalue of the true-normal "
                     f"information below {WEAK_TRANSLATION_EIGENVALUE:g}, see the degeneracy table): "
                     f"{', '.join(weak)}. Pooled over the others ({', '.join(good)}):")
        lines.append("")
        header = ["Method", "mu, m", "sigma, m", "segments"]
        rows = [[METHOD_LABELS[m], *(fmt(v) for v in result.overall(m, good)[:2]), result.overall(m, good)[2]]
                for m in result.params.methods]
        lines.append(markdown_table(header, rows))
    for m in result.params.methods:
        for s in result.sequences:
            r = s.runs.get(m)
            if r is not None and not r.ok:
                lines.append(f"- {METHOD_LABELS[m]}: {r.error if r.error is not None else r.note}.")
                break
    verdict = salo_vs_bl(result)
    if verdict:
        lines += ["", "## SALO against BL", ""]
        worse = [v for v in verdict if v["salo_better"] is False]
        for v in verdict:
            change = "n/a" if v["change_pct"] is None else f"{v['change_pct']:+.1f} %"
            state = {True: "SALO lower", False: "**SALO not lower**", None: "n/a"}[v["salo_better"]]
            lines.append(f"- {v['sequence']}: BL {fmt(v['bl_mu'], '.3f')}, SALO {fmt(v['salo_mu'], '.3f')} m/100 m "
                         f"({change}): {state}")
        if worse:
            lines.append("")
            lines.append(f"SALO does not beat BL on {', '.join(v['sequence'] for v in worse)} in this run. These "
                         "are the measured figures; see the degeneracy summary and the per-frame diagnostics "
                         "(`poses/<sequence>/<method>_diagnostics.csv`) for where the errors arise.")
    lines += ["", "## Further figures", ""]
    header = ["sequence", "method", "path, m", "segments", "KITTI t_err, %", "r_err, deg/100 m", "ATE RMSE, m",
              "RPE t mean, m", "flagged degenerate", "extrapolated", "frames/s"]
    rows = []
    for r in table_rows(result):
        if r["sequence"].startswith("overall") or not r["available"]:
            continue
        rows.append([r["sequence"], r["method"], fmt(r["path_length_m"], ".0f"), r["segments"],
                     fmt(r["t_err_pct"], ".3f"), fmt(r["r_err_deg_per_100m"], ".3f"), fmt(r["ate_rmse_m"], ".3f"),
                     fmt(r["rpe_t_mean_m"], ".4f"), fmt(r["flagged_degenerate"], "d"), fmt(r["extrapolated"], "d"),
                     fmt(r["frames_per_second"], ".1f")])
    lines.append(markdown_table(header, rows, "llrrrrrrrrr"))
    lines += ["## Degeneracy of each sequence", "",
              "Eigenvalues of the point-to-plane information per point from the true normals (`degeneracy.csv`): "
              "the smallest translational eigenvalue t_eig0 is the share of the normals along the worst-constrained "
              f"direction (1/3 at best); frames below {WEAK_TRANSLATION_EIGENVALUE:g} are weakly constrained.", ""]
    header = ["sequence", "frames", "t_eig0 min", "t_eig0 median", "weak frames", "weakest direction (x, y, z) at min"]
    rows = []
    for s in result.sequences:
        d = s.degeneracy
        rows.append([s.spec.name, d["frames"], fmt(d["t_eig0_min"], ".4f"), fmt(d["t_eig0_median"], ".4f"),
                     d["weak_frames"], "(" + ", ".join(f"{v:.2f}" for v in d["weakest_direction_at_min"]) + ")"])
    lines.append(markdown_table(header, rows, "lrrrrl"))
    lines += ["## Trajectories", "", "![all trajectories](trajectories.png)", "",
              "![mu and sigma per sequence](errors_per_sequence.png)", ""]
    for s in result.sequences:
        lines.append(f"![{s.spec.name}](plots/trajectory_{s.spec.name}.png)")
    return "\n".join(lines) + "\n"


def write_table(result: TableResult, record: RunRecord) -> None:
    """table.md / table.csv / results.json / summary.md and the plots into the run folder."""
    from tools.plotting import trajectory_grid, trajectory_plot

    from . import plots

    rows = table_rows(result)
    cols = ["sequence", "scene", "method", "available", "note", "mu_m_per_100m", "sigma_m_per_100m", "segments",
            "path_length_m", "frames", "t_err_pct", "r_err_deg_per_100m", "ate_rmse_m", "ate_aligned_rmse_m",
            "rpe_t_mean_m", "rpe_r_mean_deg", "flagged_degenerate", "extrapolated", "frames_per_second"]
    write_csv(record.path("table.csv"), rows, cols)
    record.write_text("table.md", paper_table_markdown(result))
    write_json(record.path("results.json"), {
        "experiment": "table", "params": record.params,
        "table": rows, "salo_vs_bl": salo_vs_bl(result),
        "sequences": {s.spec.name: {"spec": s.spec.to_dict(), "folder": None if s.folder is None else str(s.folder),
                                    "degeneracy": s.degeneracy,
                                    "metrics": {m: s.metrics[m] for m, r in s.runs.items() if r.ok},
                                    "segment_errors_m_per_100m": dict(s.segment_errors)}
                      for s in result.sequences},
    })
    tracks = []
    for s in result.sequences:
        est = {METHOD_LABELS[m]: r.poses for m, r in s.runs.items() if r.ok}
        errs = {METHOD_LABELS[m]: mean_std(s.segment_errors[m]) for m, r in s.runs.items() if r.ok}
        tracks.append((s.spec.name, s.gt, est, errs))
        trajectory_plot(record.path(f"plots/trajectory_{s.spec.name}.png"), s.gt, est, errs,
                              title=f"{s.spec.name}: top view", segment_length_m=result.params.segment_length_m)
    trajectory_grid(record.path("trajectories.png"), tracks, segment_length_m=result.params.segment_length_m)
    plots.error_bars(record.path("errors_per_sequence.png"), rows, result.params.segment_length_m)
    record.write_text("summary.md", table_markdown(result, record.params))


# ---------------------------------------------------------------- a finished run, read back
def load_table_result(run_dir: str | Path) -> TableResult:
    """A ``TableResult`` rebuilt from a run folder's results.json and poses (no odometry is run).

    For redrawing a run's pages and figures after the presentation code changed;
    diagnostics are not stored in results.json, so they are not restored.
    """
    import json

    from simlidar.formats.kitti import read_kitti_poses

    run = Path(run_dir)
    res = json.loads((run / "results.json").read_text())
    p = res["params"]
    specs = tuple(SequenceSpec(**{**{k: v for k, v in s.items() if k != "name"},
                                  "overrides": tuple(s["overrides"].items())}) for s in p["sequences"])
    params = TableParams(sequences=specs, methods=tuple(p["methods"]), segment_length_m=p["segment_length_m"],
                         step_frames=p["step_frames"], config_overrides=p["config_overrides"])
    rows = {(r["sequence"], r["method"]): r for r in res["table"]}
    sequences = []
    for spec in specs:
        stored = res["sequences"][spec.name]
        runs, errors, metrics = {}, {}, {}
        for m in params.methods:
            row = rows[(spec.name, METHOD_LABELS[m])]
            poses_file = run / "poses" / spec.name / f"{m}.txt"
            note = row.get("note") or ""
            errors[m], metrics[m] = np.zeros(0), {}
            if row["available"] and poses_file.is_file():
                flags = FrameFlags(row.get("extrapolated"), row.get("flagged_degenerate"), None)
                runs[m] = MethodRun(m, read_kitti_poses(poses_file), note=note, flags=flags,
                                    frames_per_second=row.get("frames_per_second") or float("nan"))
                errors[m] = np.asarray(stored["segment_errors_m_per_100m"][m], dtype=float)
                metrics[m] = stored["metrics"].get(m, {})
            else:
                runs[m] = MethodRun(m, None, error=note)
        gt = read_kitti_poses(run / "poses" / spec.name / "gt.txt")
        folder = None if stored.get("folder") is None else Path(stored["folder"])
        sequences.append(SequenceResult(spec, folder, gt, stored["degeneracy"], runs, errors, metrics))
    return TableResult(params, sequences)


def rewrite_table(run_dir: str | Path) -> None:
    """Redraw a finished table run's tables, page and figures from what it stored (run.json kept)."""
    from tools.records import read_run

    result = load_table_result(run_dir)
    record = RunRecord(run_dir, "table", read_run(run_dir)["params"])
    write_table(result, record)
