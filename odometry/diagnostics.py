"""What happened to each frame of a run: its diagnostics, their CSV, and the stretches of weak frames.

``FrameDiagnostics`` is filled by the registration's stages (``odometry.pipeline``); a run writes
one CSV row per frame (``write_diagnostics_csv``, ``CSV_COLUMNS``). ``stretches_of`` groups weakly
constrained frames into ``DegenerateStretch`` runs, for a run's own flags and for the simulator's
truth alike.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from io import StringIO
from pathlib import Path

import numpy as np

from simlidar.formats.atomic import atomic_write_text

# The stages timed in the diagnostics, in the order a frame passes them.
STAGES = ("deskew", "voxel", "normals", "ncf_curvature", "poles", "match", "reject", "estimate", "map")


@dataclass
class FrameDiagnostics:
    """What happened to one frame (one row of the diagnostics CSV).

    ``iterations`` and the ICP stage ``seconds`` add up every registration of the
    frame (the first and the de-skew refinements); matches, convergence, residual
    and eigenvalues are those of the last.
    """

    frame: int
    points_raw: int = 0
    points_nonfinite: int = 0
    points_in_range: int = 0
    filter_counts: dict = field(default_factory=dict)
    matches: dict = field(default_factory=dict)
    iterations: int = 0
    converged: bool = False
    rms_m: float = float("nan")
    info_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    translation_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    weakest_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    translation_information: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    remapped: int = 0
    degenerate: bool = False
    singular: bool = False
    too_few_points: bool = False
    implausible: bool = False
    deskewed: bool = False
    seconds: dict = field(default_factory=dict)

    @property
    def extrapolated(self) -> bool:
        """The pose is the constant-velocity guess, not an ICP result."""
        return self.frame > 0 and (self.singular or self.too_few_points or self.implausible)

    def record(self, result) -> None:
        """Take the figures of a frame's last registration (``icp.RegistrationResult``)."""
        self.matches = result.matches
        self.iterations = result.iterations
        self.converged = result.converged
        self.rms_m = result.rms_m
        self.info_eigenvalues = result.info_eigenvalues
        self.translation_eigenvalues = result.translation_eigenvalues
        self.weakest_direction = result.weakest_direction
        self.translation_information = result.H[:3, :3] / max(result.n_matches, 1)
        self.remapped = result.remapped
        self.degenerate = result.degenerate
        self.singular = result.singular


CSV_COLUMNS = (
    ["frame", "points_raw", "points_nonfinite", "points_in_range", "voxels", "after_ncf", "after_curvature",
     "candidates", "after_distance", "after_gcr", "after_trimmed", "pole_matches", "iterations", "converged",
     "rms_m"]
    + [f"eig{k}" for k in range(6)] + ["t_eig0", "t_eig1", "t_eig2", "weak_x", "weak_y", "weak_z", "remapped",
                                        "restored"]
    + ["degenerate", "singular", "too_few_points", "implausible", "extrapolated", "deskewed"]
    + [f"s_{stage}" for stage in STAGES] + ["s_total"]
)


def diagnostics_row(d: FrameDiagnostics) -> list:
    fc, m, s = d.filter_counts, d.matches, d.seconds
    return (
        [d.frame, d.points_raw, d.points_nonfinite, d.points_in_range, fc.get("voxels", ""), fc.get("ncf", ""),
         fc.get("curvature", ""), m.get("candidates", ""), m.get("distance", ""), m.get("gcr", ""),
         m.get("trimmed", ""), m.get("poles", ""), d.iterations, int(d.converged), f"{d.rms_m:.6g}"]
        + [f"{v:.6g}" for v in d.info_eigenvalues] + [f"{v:.6g}" for v in d.translation_eigenvalues]
        + [f"{v:.4f}" for v in d.weakest_direction] + [d.remapped, fc.get("restored", "")]
        + [int(d.degenerate), int(d.singular), int(d.too_few_points), int(d.implausible), int(d.extrapolated),
           int(d.deskewed)]
        + [f"{s.get(k, 0.0):.6f}" for k in (*STAGES, "total")]
    )


@dataclass(frozen=True)
class DegenerateStretch:
    """Consecutive frames whose registration was weakly constrained (flagged degenerate or remapped).

    first, last: frame numbers (inclusive). direction: (3,) unit mean weakest translation
    direction over the stretch, in the lidar frame. min_eigenvalue: the smallest translational
    eigenvalue per match in it. remapped: frames whose update kept the prior in a direction.
    """

    first: int
    last: int
    direction: np.ndarray
    min_eigenvalue: float
    remapped: int

    def describe(self) -> str:
        x, y, z = self.direction
        axis = ("along x (forward)", "along y (sideways)", "along z (up)")[int(np.nanargmax(np.abs(self.direction)))]
        span = f"frame {self.first}" if self.first == self.last else f"frames {self.first}-{self.last}"
        return (f"{span}: weakest direction ({x:+.2f}, {y:+.2f}, {z:+.2f}), mostly {axis}; smallest eigenvalue "
                f"{self.min_eigenvalue:.2g}" + (f"; prior kept on {self.remapped} frames" if self.remapped else ""))


def degenerate_stretches(diagnostics: list[FrameDiagnostics], min_gap: int = 1) -> list[DegenerateStretch]:
    """The runs of degenerate (or remapped) frames, merged across gaps shorter than ``min_gap`` frames."""
    return stretches_of(np.array([d.frame for d in diagnostics], dtype=int),
                        np.array([bool(d.degenerate or d.remapped) for d in diagnostics], dtype=bool),
                        np.array([d.weakest_direction for d in diagnostics], dtype=float).reshape(-1, 3),
                        np.array([d.translation_eigenvalues[0] for d in diagnostics], dtype=float),
                        np.array([d.remapped > 0 for d in diagnostics], dtype=bool), min_gap)


def stretches_of(frames: np.ndarray, weak: np.ndarray, directions: np.ndarray, eigenvalues: np.ndarray,
                 remapped: np.ndarray | None = None, min_gap: int = 1) -> list[DegenerateStretch]:
    """The runs of ``weak`` frames, merged across gaps shorter than ``min_gap`` frames.

    frames: (N,) frame numbers, ascending. weak: (N,) bool. directions: (N, 3) weakest
    translational direction per frame (lidar frame; sign arbitrary). eigenvalues: (N,) the
    smallest translational eigenvalue per frame. remapped: (N,) bool, frames whose update kept
    the prior (default none). Used for a run's own diagnostics (``degenerate_stretches``) and
    for the simulator's truth (a sequence's ``degeneracy.csv``).
    """
    remapped = np.zeros(len(frames), dtype=bool) if remapped is None else np.asarray(remapped, dtype=bool)
    out: list[list[int]] = []
    for i in np.flatnonzero(weak):
        if out and frames[i] - frames[out[-1][-1]] <= min_gap:
            out[-1].append(int(i))
        else:
            out.append([int(i)])
    stretches = []
    for run in out:
        dirs = directions[run]
        dirs = dirs[np.all(np.isfinite(dirs), axis=1)]
        if len(dirs):
            dirs = dirs * np.sign(dirs @ dirs[0])[:, None]  # eigenvectors have no sign: align them first
            mean = dirs.mean(axis=0)
            mean /= np.linalg.norm(mean)
        else:
            mean = np.full(3, np.nan)
        eig = eigenvalues[run]
        eig = eig[np.isfinite(eig)]
        stretches.append(DegenerateStretch(int(frames[run[0]]), int(frames[run[-1]]), mean,
                                           float(eig.min()) if len(eig) else float("nan"), int(remapped[run].sum())))
    return stretches


def write_diagnostics_csv(path: str | Path, diagnostics: list[FrameDiagnostics]) -> None:
    """One row per frame (``CSV_COLUMNS``), written atomically."""
    buf = StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for d in diagnostics:
        w.writerow(diagnostics_row(d))
    atomic_write_text(path, buf.getvalue())
