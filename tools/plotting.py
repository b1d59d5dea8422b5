"""Figures shared by the experiments, the demo, the leaderboard, sweeps and ``salo evaluate`` (PNG, Agg).

Matplotlib is imported inside each function (``salo --help`` and the odometry
never load it). Figures are built with ``matplotlib.figure.Figure`` directly
(``new_figure``), never pyplot, so no GUI backend or global state is involved;
``save_png`` writes each PNG beside its final name and renames it, so a reader
never sees half a file. Units are in every axis label.

- ``METHOD_COLORS`` / ``METHOD_STYLES``: one colour and line style per method label;
- ``trajectory_plot``, ``trajectory_grid``: top views of the truth and every method
  (the paper's Fig. 4); ``position_error_plot``: position error along the path;
  ``scan_preview``: one scan from above, coloured by ring.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

METHOD_COLORS = {"ground truth": "black", "BL": "tab:blue", "NCF": "tab:orange", "SALO": "tab:green",
                 "KISS-ICP": "tab:purple", "default": "tab:red", "BL map": "tab:cyan", "NCF map": "tab:olive",
                 "SALO map": "tab:pink", "GenZ-ICP": "tab:brown", "small_gicp s2m": "tab:gray"}
# Widths and dashes differ so that methods whose tracks coincide stay visible under each other.
METHOD_STYLES = {"BL": ("-", 3.4), "NCF": ("--", 2.2), "SALO": ("-", 1.2), "KISS-ICP": (":", 2.2),
                 "default": ("-", 2.6), "GenZ-ICP": ("-.", 1.6), "small_gicp s2m": ((0, (1, 3)), 2.0)}
# Log-scale plots show errors below this as this (exact zeros have no logarithm).
LOG_FLOOR_M = 1e-4


def save_png(fig, path: str | Path, dpi: int = 110) -> Path:
    """Render ``fig`` to PNG in memory and write it atomically (a reader never sees half a file)."""
    from simlidar.formats.atomic import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")  # never crop a legend or a label
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)


def plain_log_ticks(ax, which: str = "both") -> None:
    """Log-axis tick labels as plain numbers (0.5, 1, 2, 5) rather than powers of ten."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    for name in ("x", "y") if which == "both" else (which,):
        axis = getattr(ax, f"{name}axis")
        axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 3.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def new_figure(**kwargs):
    """A ``matplotlib.figure.Figure`` with the constrained layout (no pyplot, no global state)."""
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


# ---------------------------------------------------------------- trajectories (Fig. 4)
def _view(gt: np.ndarray, square: bool) -> tuple[np.ndarray, np.ndarray]:
    """(2,) lower and upper x, y limits around the ground truth's track, m (a square, or its own shape)."""
    lo, hi = gt[:, :2, 3].min(axis=0), gt[:, :2, 3].max(axis=0)
    span = float(np.max(hi - lo))
    margin = max(3.0, 0.15 * span)
    lo, hi = lo - margin, hi + margin
    if square:
        centre, half = (lo + hi) / 2, float(np.max(hi - lo)) / 2
        return centre - half, centre + half
    # Not thinner than a third of the longer side: a straight road still shows its lateral error.
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, float(np.max(hi - lo)) / 6)
    return centre - half, centre + half


def _draw_tracks(ax, gt: np.ndarray, est: dict, errs: dict | None, segment_length_m: float,
                 square: bool = True) -> None:
    ax.plot(gt[:, 0, 3], gt[:, 1, 3], color=METHOD_COLORS["ground truth"], lw=2.2, ls="--", label="ground truth",
            zorder=5)
    for name, poses in est.items():
        label = name
        if errs and name in errs and math.isfinite(errs[name][0]):
            mu, sd = errs[name]
            label = f"{name}: mu {mu:.2f}, sigma {sd:.2f} m/100 m"
        ls, lw = METHOD_STYLES.get(name, ("-", 1.4))
        ax.plot(poses[:, 0, 3], poses[:, 1, 3], color=METHOD_COLORS.get(name), ls=ls, lw=lw, label=label)
    ax.plot(gt[0, 0, 3], gt[0, 1, 3], "ks", ms=7, mfc="none", mew=1.5, label="start")
    # The view follows the ground truth (with a margin): a diverged estimate must not shrink it to a dot.
    lo, hi = _view(gt, square)
    outside = [name for name, poses in est.items()
               if np.any(poses[:, :2, 3] < lo) or np.any(poses[:, :2, 3] > hi)]
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    if outside:
        ax.text(0.99, 0.01, "leaves the view: " + ", ".join(outside), transform=ax.transAxes, ha="right",
                va="bottom", fontsize=8.5, color="0.25", bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
    ax.set_xlabel("x, m (first frame: forward)")
    ax.set_ylabel("y, m (first frame: left)")
    ax.grid(True, alpha=0.3)


def trajectory_plot(path, gt: np.ndarray, est: dict, errs: dict | None = None, title: str = "",
                    segment_length_m: float = 100.0) -> Path:
    """Top view of ground truth (N, 4, 4) and each method's poses (name -> (N, 4, 4)), in metres."""
    lo, hi = _view(gt, square=False)
    ratio = float((hi[1] - lo[1]) / (hi[0] - lo[0]))
    width = 9.0 if ratio <= 1 else max(7.0, 8.0 / ratio)  # wide enough for a two-column legend
    fig = new_figure(figsize=(width, min(9.0, max(3.0, width * ratio)) + 1.6))
    ax = fig.subplots()
    _draw_tracks(ax, gt, est, errs, segment_length_m, square=False)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    _end_inset(ax, gt, est)
    note = "" if segment_length_m == 100.0 else f" ({segment_length_m:g} m segments)"
    ax.set_title((title or "trajectory, top view") + note)
    return save_png(fig, path)


def _end_inset(ax, gt: np.ndarray, est: dict) -> None:
    """A zoom on the end of the path, where the methods' drift shows (tracks overlap at full scale)."""
    from matplotlib.ticker import MaxNLocator

    end = gt[-1, :2, 3]
    errs = [float(np.linalg.norm(p[-1, :2, 3] - end)) for p in est.values()]
    half = max(1.0, 1.5 * max(errs, default=0.0))
    extent = float(np.max(np.ptp(gt[:, :2, 3], axis=0)))
    if extent < 8 * half:  # the ends are as far apart as the path is long: the full view shows it all
        return
    # The corner of the axes the ground truth crosses least (axes coordinates of its points).
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    u = (gt[:, 0, 3] - x0) / (x1 - x0)
    v = (gt[:, 1, 3] - y0) / (y1 - y0)
    size = 0.34
    corners = [(0.1, 0.05), (0.62, 0.05), (0.1, 0.6), (0.62, 0.6)]
    crossing = [np.sum((u > cx - 0.03) & (u < cx + size + 0.03) & (v > cy - 0.03) & (v < cy + size + 0.08))
                for cx, cy in corners]
    cx, cy = corners[int(np.argmin(crossing))]
    inset = ax.inset_axes([cx, cy, size, size])
    inset.plot(gt[:, 0, 3], gt[:, 1, 3], color="black", lw=2.0, ls="--")
    for name, poses in est.items():
        ls, lw = METHOD_STYLES.get(name, ("-", 1.4))
        inset.plot(poses[:, 0, 3], poses[:, 1, 3], color=METHOD_COLORS.get(name), ls=ls, lw=lw)
        inset.plot(poses[-1, 0, 3], poses[-1, 1, 3], "o", color=METHOD_COLORS.get(name), ms=5)
    inset.plot(end[0], end[1], "k*", ms=10)
    inset.set_xlim(end[0] - half, end[0] + half)
    inset.set_ylim(end[1] - half, end[1] + half)
    inset.set_aspect("equal", adjustable="box")
    inset.set_title(f"end of path, +-{half:.1f} m (star: truth)", fontsize=8)
    inset.tick_params(labelsize=7)
    inset.xaxis.set_major_locator(MaxNLocator(4))
    inset.yaxis.set_major_locator(MaxNLocator(4))
    inset.grid(True, alpha=0.3)
    ax.indicate_inset_zoom(inset, edgecolor="0.4")


def panel_label(i: int) -> str:
    """The i-th panel's letters, from 0: a, b, ..., z, aa, ab, ... (a grid of every sequence has more than 26)."""
    label = ""
    i += 1
    while i:
        i, r = divmod(i - 1, 26)
        label = chr(97 + r) + label
    return label


def trajectory_grid(path, tracks: list, segment_length_m: float = 100.0) -> Path:
    """All sequences side by side, as the paper's Fig. 4: tracks = [(name, gt, est, errs), ...]."""
    n = max(len(tracks), 1)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = new_figure(figsize=(5.6 * cols, 5.0 * rows + 0.8))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for i, (name, gt, est, errs) in enumerate(tracks):
        ax = axes[i]
        _draw_tracks(ax, gt, est, None, segment_length_m)
        parts = [f"{k} {v[0]:.2f}" for k, v in errs.items() if math.isfinite(v[0])]
        ax.set_title(f"{panel_label(i)}) {name}" + ("\nmu, m/100 m: " + ", ".join(parts) if parts else ""), fontsize=10)
    for ax in axes[len(tracks):]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=10)
    fig.suptitle("Ground truth against every method, top view" +
                 ("" if segment_length_m == 100.0 else f" ({segment_length_m:g} m segments)"))
    return save_png(fig, path)


def position_error_plot(path, gt: np.ndarray, est: dict, distances_m: np.ndarray) -> Path:
    """Position error (m) of each method against the distance travelled (m)."""
    fig = new_figure(figsize=(8.0, 4.2))
    ax = fig.subplots()
    for name, poses in est.items():
        err = np.linalg.norm(poses[:, :3, 3] - gt[:, :3, 3], axis=1)
        ls, lw = METHOD_STYLES.get(name, ("-", 1.5))
        ax.plot(distances_m, err, color=METHOD_COLORS.get(name), ls=ls, lw=lw, label=name)
    ax.set_xlabel("distance travelled along the ground truth, m")
    ax.set_ylabel("position error, m")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title("Position error against ground truth (both start at the identity)")
    return save_png(fig, path)


def scan_preview(path, points: np.ndarray, rings: np.ndarray, n_rings: int, title: str = "",
                 half_width_m: float = 60.0) -> Path:
    """Top view of one scan (N, 3) coloured by ring (N,), within +-half_width_m of the sensor."""
    fig = new_figure(figsize=(8.0, 7.2))
    ax = fig.subplots()
    keep = (np.abs(points[:, 0]) < half_width_m) & (np.abs(points[:, 1]) < half_width_m)
    sc = ax.scatter(points[keep, 0], points[keep, 1], c=rings[keep], s=0.5, cmap="turbo", vmin=0,
                    vmax=max(n_rings - 1, 1), rasterized=True, linewidths=0)
    ax.plot(0, 0, marker="^", color="black", ms=9, label="sensor (x forward)")
    ax.set_aspect("equal")
    ax.set_xlim(-half_width_m, half_width_m)
    ax.set_ylim(-half_width_m, half_width_m)
    ax.set_xlabel("x, m (forward)")
    ax.set_ylabel("y, m (left)")
    ax.legend(loc="upper right")
    fig.colorbar(sc, ax=ax, label="ring (0 = lowest beam)", shrink=0.85)
    ax.set_title(title or "one scan, top view")
    return save_png(fig, path, dpi=130)


__all__ = ["LOG_FLOOR_M", "METHOD_COLORS", "METHOD_STYLES", "new_figure", "panel_label", "plain_log_ticks",
           "position_error_plot", "save_png", "scan_preview", "trajectory_grid", "trajectory_plot"]
