"""The leaderboard's figures per sequence (PNG; matplotlib inside the functions, as ``tools.plotting``).

- trajectories: the top view of the truth and every method (``tools.plotting.trajectory_plot``);
- error over distance: each method's position error (m, log) against the distance
  travelled, with the frames the simulator's truth finds weakly constrained shaded,
  and beneath, a strip per method that reports its own weak frames;
- error against the weakest eigenvalue: each frame's translation error (m per frame,
  log) against the smallest translational eigenvalue of the truth's information at
  that frame (log): degenerate frames are on the left.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

LOG_FLOOR_M = 1e-4
FALLBACK_COLORS = ("#1b4f9c", "#d95f02", "#1b9e77", "#7570b3", "#e7298a", "#66a61e", "#a6761d", "#444444")


def method_colors(labels) -> dict:
    """A colour per method label: ``tools.plotting``'s for the built-in methods, distinct others for the rest."""
    from tools.plotting import METHOD_COLORS

    spare = iter(c for c in FALLBACK_COLORS)
    return {label: METHOD_COLORS.get(label) or next(spare, "0.5") for label in labels}


def _style(label: str) -> tuple:
    from tools.plotting import METHOD_STYLES

    return METHOD_STYLES.get(label, ("-", 1.6))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True in ``mask``."""
    idx = np.flatnonzero(mask)
    if not len(idx):
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _span(dist: np.ndarray, first: int, last: int) -> tuple[float, float]:
    """A frame run as a distance interval, half a frame's travel wider on each side, m."""
    lo = max(0.0, dist[first] - 0.5 * (dist[min(first + 1, len(dist) - 1)] - dist[first]))
    hi = min(float(dist[-1]), dist[last] + 0.5 * (dist[last] - dist[max(last - 1, 0)]))
    return float(lo), float(max(hi, lo + 0.3))


def trajectories_png(path, gt: np.ndarray, estimates: dict, title: str) -> Path:
    """Top view of ``gt`` (N, 4, 4) and each method's poses (label -> (N, 4, 4))."""
    from tools.plotting import trajectory_plot

    finite = {k: v for k, v in estimates.items() if np.all(np.isfinite(v))}
    return trajectory_plot(path, gt, finite, title=title)


def draw_error_over_distance(ax, strip, gt: np.ndarray, estimates: dict, truth_weak: np.ndarray | None,
                             own_weak: dict, colors: dict | None = None) -> None:
    """Onto ``ax``: each method's position error (m, log) against distance, the truth's weak frames shaded;
    onto ``strip``: a row of weak frames for the truth and for each method in ``own_weak``."""
    from matplotlib.patches import Patch

    from odometry.metrics import trajectory_distances
    from tools.plotting import plain_log_ticks

    dist = trajectory_distances(gt)
    colors = colors or method_colors(estimates)
    shade = "#f4c7a1"
    if truth_weak is not None:
        for a, b in _runs(truth_weak):
            ax.axvspan(*_span(dist, a, b), color=shade, alpha=0.6, lw=0, zorder=0)
    for label, poses in estimates.items():
        err = np.linalg.norm(poses[:, :3, 3] - gt[:, :3, 3], axis=1)
        ls, lw = _style(label)
        # from frame 1: frame 0 is the identity for every method (no error, no logarithm)
        ax.plot(dist[1:], np.maximum(err[1:], LOG_FLOOR_M), color=colors.get(label), ls=ls, lw=min(lw, 2.2),
                label=label)
    ax.set_yscale("log")
    plain_log_ticks(ax, "y")
    ax.set_ylabel("position error, m (log)")
    ax.grid(True, which="major", alpha=0.3)
    handles, _ = ax.get_legend_handles_labels()
    if truth_weak is not None and np.any(truth_weak):  # the shade's entry only where something is shaded
        handles.append(Patch(color=shade, alpha=0.6, label="weak in the truth"))
    ax.legend(handles=handles, loc="upper left", fontsize=8.5, ncol=2, framealpha=0.9)
    rows = (["truth"] if truth_weak is not None else []) + list(own_weak)
    for i, name in enumerate(rows):
        mask = truth_weak if name == "truth" else own_weak[name]
        y = len(rows) - 1 - i
        color = shade if name == "truth" else colors.get(name, "0.4")
        for a, b in _runs(mask):
            lo, hi = _span(dist, a, b)
            strip.broken_barh([(lo, hi - lo)], (y + 0.15, 0.7), color=color)
    strip.set_yticks(np.arange(len(rows)) + 0.5,
                     [f"{r}: weak" if r == "truth" else f"{r}: own flag" for r in rows][::-1], fontsize=8.5)
    strip.set_ylim(0, max(len(rows), 1))
    if not any(np.any(truth_weak if name == "truth" else own_weak[name]) for name in rows):
        strip.text(0.5, 0.5, "no weak frame: " + ("neither the truth nor any method flags one" if own_weak else
                                                   "the truth flags none"),
                   transform=strip.transAxes, ha="center", va="center", fontsize=9, color="0.35")
    for a in (ax, strip):
        a.set_xlim(0, float(dist[-1]) if dist[-1] > 0 else 1.0)
    strip.set_xlabel("distance travelled along the ground truth, m")
    strip.grid(True, axis="x", alpha=0.3)


def error_over_distance_png(path, gt: np.ndarray, estimates: dict, truth_weak: np.ndarray | None,
                            own_weak: dict, title: str) -> Path:
    """Position error against distance travelled, truth's weak frames shaded, methods' own flags beneath.

    estimates: label -> (N, 4, 4). truth_weak: (N,) bool from the sequence's degeneracy (None:
    unknown). own_weak: label -> (N,) bool for the methods that report their own weak frames.
    """
    from tools.plotting import new_figure, save_png

    rows = len(own_weak) + (truth_weak is not None)
    fig = new_figure(figsize=(10.0, 4.6 + 0.32 * max(rows, 1)))
    ax, strip = fig.subplots(2, 1, sharex=True, height_ratios=[4.0, 0.45 * max(rows, 1)])
    draw_error_over_distance(ax, strip, gt, estimates, truth_weak, own_weak)
    ax.set_title(title)
    return save_png(fig, path)


def error_vs_eigenvalue_png(path, gt: np.ndarray, estimates: dict, t_eig0: np.ndarray, threshold: float,
                            title: str) -> Path:
    """Each frame's translation error (m per frame, frame k-1 to k) against the truth's weakest eigenvalue at k."""
    from odometry.metrics import relative_pose_errors
    from tools.plotting import new_figure, plain_log_ticks, save_png

    colors = method_colors(estimates)
    fig = new_figure(figsize=(8.0, 5.2))
    ax = fig.subplots()
    eig = np.maximum(np.asarray(t_eig0, dtype=float), 1e-6)
    for label, poses in estimates.items():
        finite = np.all(np.isfinite(poses), axis=(1, 2))
        n = int(np.argmin(finite)) if not finite.all() else len(poses)
        if n < 2:
            continue
        rpe = relative_pose_errors(gt[:n], poses[:n], 1)
        ax.scatter(eig[rpe.last_frame], np.maximum(rpe.t_err_m, LOG_FLOOR_M), s=9, alpha=0.55,
                   color=colors[label], label=label, edgecolors="none")
    ax.axvline(threshold, color="0.3", ls="--", lw=1, label=f"weak below {threshold:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    plain_log_ticks(ax)
    ax.set_xlabel("smallest translational eigenvalue of the truth's information per return (log)")
    ax.set_ylabel("translation error of the frame, m (log)")
    ax.grid(True, which="major", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6), fontsize=8.5, markerscale=2)
    ax.set_title(title)
    return save_png(fig, path)


__all__ = ["draw_error_over_distance", "error_over_distance_png", "error_vs_eigenvalue_png", "method_colors",
           "trajectories_png"]
