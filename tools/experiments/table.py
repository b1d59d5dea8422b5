"""Table I on simulated data: relative positioning error per 100 m, BL / NCF / SALO and the peers.

For every sequence of the suite (``tools.experiments.suite``) each method runs
over the same frames: our odometry with the ``bl``, ``ncf`` and ``salo``
configs (``odometry.pipeline.run_sequence``), and the peers KISS-ICP, GenZ-ICP
and a small_gicp scan-to-map pipeline through their Python APIs when installed
(``tools.experiments.peer``; a missing one gets a row saying so). The paper's figure is the
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

from .peer import PEERS
from .records import RunRecord, fmt, markdown_table, write_csv, write_json
from .suite import DEFAULT_CACHE_LIMIT_BYTES, SequenceSpec, load_sequence, table_suite

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


@dataclass
class MethodResult:
    """One method on one sequence: poses (N, 4, 4), per-segment errors (m per 100 m), metrics, flags."""

    method: str
    available: bool
    note: str = ""
    poses: np.ndarray | None = None
    segment_errors_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    metrics: dict = field(default_factory=dict)
    frames_per_second: float = float("nan")
    flagged_degenerate: int | None = None
    extrapolated: int | None = None
    diagnostics: list | None = None  # odometry.pipeline.FrameDiagnostics per frame (our methods)

    @property
    def mean(self) -> float:
        return float(np.mean(self.segment_errors_m)) if len(self.segment_errors_m) else float("nan")

    @property
    def std(self) -> float:
        return float(np.std(self.segment_errors_m)) if len(self.segment_errors_m) else float("nan")


def segment_errors_per_100m(T_gt: np.ndarray, T_est: np.ndarray, length_m: float, step_frames: int) -> np.ndarray:
    """(M,) translational error of each ``length_m`` segment, m per 100 m of path."""
    from odometry.metrics import kitti_segment_errors

    s = kitti_segment_errors(T_gt, T_est, [length_m], step_frames)
    return s.t_err_ratio * 100.0


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


def run_method(method: str, sequence, params: TableParams, progress: bool) -> MethodResult:
    """One method over one sequence (a peer: a "not installed" result when it cannot run here)."""
    from tqdm import tqdm

    from tools.runners import run_method as run_ours

    overrides = dict(params.config_overrides)
    desc = f"{METHOD_LABELS[method]} {sequence.path.name}"
    with tqdm(total=len(sequence), unit="frame", desc=desc, disable=not progress, dynamic_ncols=True) as bar:
        if method in PEER_METHODS:
            res = run_peer_method(method, sequence, odometry_config("salo", overrides), lambda k: bar.update(1))
            if not res.available:
                return res
        else:
            ours = run_ours(sequence, odometry_config(method, overrides), on_frame=lambda k, d: bar.update(1))
            res = MethodResult(method, True, "", ours.poses, frames_per_second=ours.frames_per_second,
                               flagged_degenerate=ours.flags.degenerate, extrapolated=ours.flags.extrapolated)
            res.diagnostics = ours.run.diagnostics
    return score_method(res, sequence, params)


def run_peer_method(method: str, sequence, cfg, on_frame) -> MethodResult:
    """A peer over one sequence with our range limits (``cfg``: our odometry config); its failure is a row."""
    from .peer import PeerUnavailable, peer_unavailable_reason, run_peer

    reason = peer_unavailable_reason(method)
    if reason is not None:
        return MethodResult(method, False, reason)
    try:
        run = run_peer(method, sequence, min_range_m=cfg.clean.min_range_m, max_range_m=cfg.clean.max_range_m,
                       on_frame=on_frame)
    except PeerUnavailable as exc:
        return MethodResult(method, False, str(exc))
    except Exception as exc:  # noqa: BLE001 - a peer failing must not end a long run; the row says why
        log.warning("%s failed on %s: %s", METHOD_LABELS[method], sequence.path.name, exc)
        return MethodResult(method, False, f"failed: {type(exc).__name__}: {exc}")
    return MethodResult(method, True, f"{PEERS[method].distribution} {run.config.get('version')}", run.poses,
                        frames_per_second=run.frames_per_second)


def score_method(res: MethodResult, sequence, params: TableParams) -> MethodResult:
    """Fill in a finished method's errors against the sequence's ground truth (or mark it diverged)."""
    from odometry.metrics import evaluate_trajectory

    gt = sequence.poses
    bad = ~np.all(np.isfinite(res.poses.reshape(len(res.poses), -1)), axis=1)
    if bad.any():
        res.available, res.note = False, f"diverged: non-finite pose from frame {int(np.argmax(bad))}"
        return res
    res.segment_errors_m = segment_errors_per_100m(gt, res.poses, params.segment_length_m, params.step_frames)
    res.metrics.update(evaluate_trajectory(gt, res.poses).to_dict())
    return res


@dataclass
class SequenceResult:
    spec: SequenceSpec
    folder: Path | None  # None: simulated in memory
    gt: np.ndarray
    degeneracy: dict
    methods: dict[str, MethodResult]


@dataclass
class TableResult:
    params: TableParams
    sequences: list[SequenceResult]

    def well_constrained(self) -> list[str]:
        """Sequences whose median frame is not weakly constrained (a property of the data, not of the results)."""
        return [s.spec.name for s in self.sequences if s.degeneracy["t_eig0_median"] >= WEAK_TRANSLATION_EIGENVALUE]

    def overall(self, method: str, names: list[str] | None = None) -> tuple[float, float, int]:
        """Pooled mean, std (m per 100 m) and segment count of a method over the sequences ``names`` (default all)."""
        errs = [s.methods[method].segment_errors_m for s in self.sequences
                if method in s.methods and s.methods[method].available and (names is None or s.spec.name in names)]
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
        methods = {}
        for m in params.methods:
            log.info("table: %s on %s", m, spec.name)
            methods[m] = run_method(m, seq, params, progress)
            if record is not None:
                _write_method_files(record, spec.name, methods[m])
        results.append(SequenceResult(spec, folder, seq.poses, degeneracy_summary(folder or seq), methods))
        if record is not None:
            from simlidar.formats.kitti import write_kitti_poses

            write_kitti_poses(record.path(f"poses/{spec.name}/gt.txt"), seq.poses)
    return TableResult(params, results)


def write_method_files(record: RunRecord, stem: str, res: MethodResult) -> None:
    """A method's poses at ``STEM.txt`` of the run folder and, for ours, its diagnostics at ``STEM_diagnostics.csv``."""
    from tools.runners import RunFiles, write_run_files

    diagnostics = record.path(f"{stem}_diagnostics.csv") if res.diagnostics is not None else None
    write_run_files(RunFiles(record.path(f"{stem}.txt"), diagnostics), res.poses, res.diagnostics)


def _write_method_files(record: RunRecord, seq_name: str, res: MethodResult) -> None:
    if res.available:
        write_method_files(record, f"poses/{seq_name}/{res.method}", res)


# ---------------------------------------------------------------- outputs
def table_rows(result: TableResult) -> list[dict]:
    """One row per (sequence or "overall", method): the table's figures, flat, for CSV and JSON."""
    rows = []
    for s in result.sequences:
        for m, r in s.methods.items():
            met = r.metrics
            rows.append({
                "sequence": s.spec.name, "scene": s.spec.scene, "method": METHOD_LABELS[m], "available": r.available,
                "note": r.note, "mu_m_per_100m": r.mean, "sigma_m_per_100m": r.std,
                "segments": len(r.segment_errors_m), "path_length_m": met.get("path_length_m"),
                "frames": met.get("frames"), "t_err_pct": met.get("t_err_pct"),
                "r_err_deg_per_100m": met.get("r_err_deg_per_100m"), "ate_rmse_m": met.get("ate_rmse_m"),
                "ate_aligned_rmse_m": met.get("ate_aligned_rmse_m"), "rpe_t_mean_m": met.get("rpe_t_mean_m"),
                "rpe_r_mean_deg": met.get("rpe_r_mean_deg"), "flagged_degenerate": r.flagged_degenerate,
                "extrapolated": r.extrapolated, "frames_per_second": r.frames_per_second,
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
        b, a = s.methods["bl"].mean, s.methods["salo"].mean
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
        cols[s.spec.name] = {m: (r.mean, r.std) for m, r in s.methods.items() if r.available}
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
            r = s.methods.get(m)
            if r is not None and not r.available:
                lines.append(f"- {METHOD_LABELS[m]}: {r.note}.")
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
                                    "metrics": {m: r.metrics for m, r in s.methods.items() if r.available},
                                    "segment_errors_m_per_100m": {m: r.segment_errors_m for m, r in s.methods.items()}}
                      for s in result.sequences},
    })
    tracks = []
    for s in result.sequences:
        est = {METHOD_LABELS[m]: r.poses for m, r in s.methods.items() if r.available}
        errs = {METHOD_LABELS[m]: (r.mean, r.std) for m, r in s.methods.items() if r.available}
        tracks.append((s.spec.name, s.gt, est, errs))
        plots.trajectory_plot(record.path(f"plots/trajectory_{s.spec.name}.png"), s.gt, est, errs,
                              title=f"{s.spec.name}: top view", segment_length_m=result.params.segment_length_m)
    plots.trajectory_grid(record.path("trajectories.png"), tracks, segment_length_m=result.params.segment_length_m)
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
        methods = {}
        for m in params.methods:
            row = rows[(spec.name, METHOD_LABELS[m])]
            poses_file = run / "poses" / spec.name / f"{m}.txt"
            r = MethodResult(m, bool(row["available"]), row.get("note") or "")
            if r.available and poses_file.is_file():
                r.poses = read_kitti_poses(poses_file)
                r.segment_errors_m = np.asarray(stored["segment_errors_m_per_100m"][m], dtype=float)
                r.metrics = stored["metrics"].get(m, {})
                r.frames_per_second = row.get("frames_per_second") or float("nan")
                r.flagged_degenerate, r.extrapolated = row.get("flagged_degenerate"), row.get("extrapolated")
            else:
                r.available = False
            methods[m] = r
        gt = read_kitti_poses(run / "poses" / spec.name / "gt.txt")
        folder = None if stored.get("folder") is None else Path(stored["folder"])
        sequences.append(SequenceResult(spec, folder, gt, stored["degeneracy"], methods))
    return TableResult(params, sequences)


def rewrite_table(run_dir: str | Path) -> None:
    """Redraw a finished table run's tables, page and figures from what it stored (run.json kept)."""
    from .records import read_run

    result = load_table_result(run_dir)
    record = RunRecord(run_dir, "table", read_run(run_dir)["params"])
    write_table(result, record)
