"""``salo bench``: methods over a suite of simulated sequences, and a leaderboard page of the results.

The pieces, one module each:

- ``suites``: which sequences (the regression suite, the generalisation suite, a
  sweep spec), simulated once into ``OUT/sequences/``;
- ``results``: one method on one sequence, staged without ground truth
  (``tools.methods.run_method``), evaluated, stored per method and sequence
  in ``OUT/results/<method>/<sequence>/``; a stored result of the same method
  settings on the same sequence is reused, so a new method is added without
  re-running the others;
- ``figures``: per sequence, the trajectories, the error over distance with the
  weak stretches shaded (the truth's, and the method's own flags), the error of
  each frame against the truth's weakest eigenvalue;
- ``page``: a table per scene family.

``run_bench`` does it all and writes ``OUT/leaderboard.md`` and
``OUT/leaderboard.html`` (one self-contained page), with every method stored for
these sequences, and ``OUT/bench.json``: the commands that made it and their times.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from simlidar.formats.atomic import atomic_write_text

from .results import is_current, read_result, result_dir, run_one
from .suites import SUITES, BenchSequence, SuiteError, bench_sequences

HISTORY_FILE = "bench.json"


@dataclass(frozen=True)
class StoredMethod:
    """A method known only by its stored results (run by an earlier bench into the same folder)."""

    name: str
    label: str
    kind: str


@dataclass
class BenchResult:
    """A finished bench: its sequences, every result on the page (this run's and stored ones), how many
    runs were done now and reused, the wall time, s, and the files written."""

    sequences: list[BenchSequence]
    results: list[dict]
    ran: int
    reused: int
    seconds: float
    outputs: dict[str, Path] = field(default_factory=dict)

    @property
    def failures(self) -> list[dict]:
        return [r for r in self.results if r["status"] != "ok"]


def run_bench(suite: str | Path, methods: list, out: str | Path, *, fields=None, frames: int | None = None,
              families: tuple[str, ...] = (), rerun: tuple[str, ...] = (), timeout_s: float = 3600.0,
              workdir: str | Path | None = None, command: str = "", on_event: Callable[[str], None] | None = None,
              on_frame=None, views: bool = True, view_max_points: int | None = None) -> BenchResult:
    """Run ``methods`` (``tools.methods.Method``) over ``suite`` into ``out`` and write the leaderboard.

    fields: per-point fields handed to the methods (default ``tools.staging.DEFAULT_FIELDS``).
    rerun: method names whose stored results are redone. command: the command line, recorded.
    on_event(text) before each simulation and each run; on_frame(k, diagnostics) as methods run.
    views: write a 3D page per sequence (``tools.view_html.bench_pages``, ``OUT/views/``; at most
    ``view_max_points`` points a frame), linked from the leaderboard.
    Raises SuiteError when the suite cannot be simulated.
    """
    from tools.staging import DEFAULT_FIELDS

    t0 = time.perf_counter()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    out = Path(out)
    say = on_event or (lambda text: None)
    sequences = bench_sequences(suite, out, frames=frames, families=families,
                                on_sequence=lambda name: say(f"simulating {name}"))
    ran = reused = 0
    for method in methods:
        for seq in sequences:
            stored = read_result(result_dir(out, method.name, seq.id))
            if method.name not in rerun and is_current(stored, method, seq):
                reused += 1
                continue
            say(f"{method.name} on {seq.id}")
            r = run_one(method, seq, out, DEFAULT_FIELDS if fields is None else fields, timeout_s=timeout_s,
                        workdir=workdir, on_frame=on_frame)
            ran += 1
            if r["status"] != "ok":
                say(f"  failed: {r['error']}")
    seconds = time.perf_counter() - t0
    history = _read_history(out)
    history.append({"command": command, "started_utc": started, "seconds": round(seconds, 1),
                    "methods": [m.name for m in methods], "ran": ran, "reused": reused})
    atomic_write_text(out / HISTORY_FILE, json.dumps(history, indent=1) + "\n")
    pages = {}
    if views:
        from tools.view_html import bench_pages

        pages = bench_pages(out, [s.id for s in sequences], max_points=view_max_points,
                            on_page=lambda name: say(f"writing the 3D view of {name}"))
    say("writing the leaderboard")
    shown, results = _on_page(out, methods, sequences)
    outputs = write_leaderboard(out, str(suite), sequences, shown, results, history, pages)
    outputs.update({f"view {k}": v for k, v in pages.items()})
    history[-1]["total_s"] = round(time.perf_counter() - t0, 1)  # the page and its figures included
    atomic_write_text(out / HISTORY_FILE, json.dumps(history, indent=1) + "\n")
    return BenchResult(sequences, results, ran, reused, time.perf_counter() - t0, outputs)


def _read_history(out: Path) -> list:
    try:
        data = json.loads((out / HISTORY_FILE).read_text())
    except (OSError, json.JSONDecodeError):
        return []
    return data if isinstance(data, list) else []


def _on_page(out: Path, methods: list, sequences: list[BenchSequence]) -> tuple[list, list[dict]]:
    """The methods on the page (this run's, then those stored for these very sequences) and their results."""
    keys = {s.id: s.key for s in sequences}
    shown = list(methods)
    names = {m.name for m in methods}
    root = out / "results"
    for folder in sorted(root.iterdir()) if root.is_dir() else ():
        if folder.name in names:
            continue
        found = [read_result(folder / s.id) for s in sequences]
        found = [r for r in found if r is not None and r.get("sequence_key") == keys.get(r.get("sequence"))]
        if found:
            shown.append(StoredMethod(folder.name, found[0].get("label", folder.name), found[0].get("kind", "")))
    results = []
    for m in shown:
        for s in sequences:
            r = read_result(result_dir(out, m.name, s.id))
            if r is not None and r.get("sequence_key") == keys[s.id]:
                results.append(r)
    return shown, results


def write_leaderboard(out: Path, suite: str, sequences: list[BenchSequence], methods: list, results: list[dict],
                      history: list, pages: dict[str, Path] | None = None) -> dict[str, Path]:
    """The figures, ``leaderboard.md`` and ``leaderboard.html`` into ``out``; pages: each sequence's 3D view."""
    from odometry.config import DEFAULT_VARIANT
    from tools.degenerate import TRUTH_THRESHOLD, diagnostics_constraints, truth_constraints
    from tools.html_page import html_page

    from . import figures
    from .page import family_rows, table_markdown

    lines = [f"# Leaderboard: {suite} suite", "",
             f"{len(sequences)} sequences, {len(methods)} methods: "
             + ", ".join(f"{m.label} ({m.kind})" for m in methods) + f"; `default` is `{DEFAULT_VARIANT}`. "
             f"Made by these commands (`{HISTORY_FILE}`), each with its wall time and the runs it did "
             "(a stored result of the same method on the same sequence is reused):", ""]
    lines += [f"- `{h['command'] or 'run_bench'}`: {h['started_utc']}, {h['ran']} runs and {h['reused']} reused "
              f"in {h['seconds']:.0f} s" + (f" ({h['total_s']:.0f} s with the page)" if "total_s" in h else "")
              for h in history[-10:]]
    lines += ["",
             "Every method ran on the sensor's data only (scans, per-point ring and time unless the kind says "
             "otherwise, the sensor model, times), without the ground truth. Figures are means over a family's "
             "sequences: KITTI t_err and r_err over 50-200 m segments; beside t_err, the relative error over "
             "10 m and 50 m windows (every frame a start, so short sequences have one too); the SE(3)-aligned "
             "ATE, the frame-to-frame RPE, the vertical drift (|end height error| / distance); the error along "
             "the truth's weakest direction over its weakly constrained stretches (accumulated over each "
             "stretch, projected on its weakest direction, over the distance they span; n/a where the truth "
             "has no weak stretch); the success rate: runs without a failure (a failed run, a divergence or "
             "t_err above 10 %; a failed run's figures stay in the means when it has them). Best figure in "
             "bold.", ""]
    truths = _add_environment_figures(out, sequences, results)
    families = list(dict.fromkeys(s.family for s in sequences))
    for family in families:
        ids = {s.id for s in sequences if s.family == family}
        rows = family_rows([r for r in results if r["sequence"] in ids], methods)
        lines += [f"## {family}", "", table_markdown(rows), ""]
        linked = [f"[{s.id}]({_link(out, pages[s.id])})" for s in sequences if s.family == family and s.id in
                  (pages or {})]
        if linked:
            lines += ["3D views (scans, trajectories, error along the path): " + ", ".join(linked), ""]
    if str(suite) in ("stress", "traffic"):  # moving traffic: each sequence's end error and motion standing still
        from .standstill import motion_table

        lines += ["## End error and motion while standing still", "",
                  "Per sequence: the error of the last pose, m, and the summed translation of a method's poses "
                  "between frames where the sensor truly stood still, m (- where it never did); each stress "
                  "scene beside its static twin (the same ego motion, nothing else moving).", "",
                  motion_table(results, methods, sequences), ""]
    failed = [r for r in results if r["status"] != "ok"]
    if failed:
        lines += ["## Failed runs", ""]
        lines += [f"- {r['label']} on {r['sequence']}: {r['error']}" for r in failed]
        lines.append("")
    lines += ["## Per sequence", "",
              "Shaded: frames whose truth is weakly constrained (smallest translational eigenvalue of the "
              f"information per return below {TRUTH_THRESHOLD:g}, from the sequence's `degeneracy.csv`); beneath, "
              "the frames each method flagged itself (ours: degenerate or prior kept).", ""]
    outputs = {}
    for s in sequences:
        gt = truths[s.id]
        est, own = {}, {}
        for m in methods:
            r = next((x for x in results if x["method"] == m.name and x["sequence"] == s.id), None)
            folder = result_dir(out, m.name, s.id)
            if r is None or r["status"] != "ok":
                continue
            est[m.label] = _read_nan_poses(folder / "poses.txt")
            if (folder / "diagnostics.csv").is_file():
                own[m.label] = diagnostics_constraints(folder / "diagnostics.csv").weak
        truth = truth_constraints(s.path) if (s.path / "degeneracy.csv").is_file() else None
        base = out / "figures" / s.id
        base.mkdir(parents=True, exist_ok=True)
        figures.trajectories_png(base / "trajectories.png", gt, est, f"{s.id}: top view")
        figures.error_over_distance_png(base / "error_over_distance.png", gt, est,
                                        None if truth is None else truth.weak, own,
                                        f"{s.id}: position error over distance")
        lines += [f"### {s.id}", ""]
        if s.id in (pages or {}):
            lines += [f"[Open the 3D view of {s.id}]({_link(out, pages[s.id])}): the scans frame by frame, the "
                      "truth's and each method's trajectory, the error along the path.", ""]
        if truth is not None:
            figures.error_vs_eigenvalue_png(base / "error_vs_eigenvalue.png", gt, est, truth.t_eig0,
                                            TRUTH_THRESHOLD, f"{s.id}: per-frame error against the weakest "
                                            "eigenvalue")
            stretches = truth.stretches()
            lines += ["Weak in the truth: " + ("; ".join(st.describe() for st in stretches[:8])
                                               + (f"; {len(stretches) - 8} more" if len(stretches) > 8 else "")
                                               if stretches else "nowhere") + ".", ""]
        rel = base.relative_to(out).as_posix()
        lines += [f"![trajectories]({rel}/trajectories.png)", "",
                  f"![position error over distance]({rel}/error_over_distance.png)", ""]
        if truth is not None:
            lines += [f"![error against the weakest eigenvalue]({rel}/error_vs_eigenvalue.png)", ""]
    markdown = "\n".join(lines) + "\n"
    atomic_write_text(out / "leaderboard.md", markdown)
    atomic_write_text(out / "leaderboard.html", html_page(markdown, f"salo bench: {suite}", out))
    outputs.update(markdown=out / "leaderboard.md", html=out / "leaderboard.html")
    return outputs


def _add_environment_figures(out: Path, sequences: list[BenchSequence], results: list[dict]) -> dict:
    """Each finished result's ``environment`` figures, added to its figures (computed from its poses, so a
    result stored by an earlier bench has them too); the true poses of each sequence, by id."""
    from simlidar.dataset import open_sequence
    from tools.degenerate import truth_constraints

    from .environment import environment_figures

    truths = {}
    for s in sequences:
        truths[s.id] = gt = np.asarray(open_sequence(s.path).poses)
        stretches = truth_constraints(s.path).stretches() if (s.path / "degeneracy.csv").is_file() else None
        for r in results:
            if r["sequence"] == s.id and r["status"] == "ok":
                est = _read_nan_poses(result_dir(out, r["method"], s.id) / "poses.txt")
                r["figures"] = {**r["figures"], **environment_figures(gt, est, stretches)}
    return truths


def _link(out: Path, page: Path) -> str:
    """A page's address relative to the leaderboard (which sits in ``out``)."""
    return Path(page).relative_to(out).as_posix()


def _read_nan_poses(path: Path) -> np.ndarray:
    """A poses file with NaN rows (a method that diverged): (N, 4, 4), NaN where it did."""
    rows = np.loadtxt(path, ndmin=2)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :4] = rows.reshape(-1, 3, 4)
    return poses


__all__ = ["SUITES", "BenchResult", "BenchSequence", "StoredMethod", "SuiteError", "bench_sequences", "run_bench",
           "write_leaderboard"]
