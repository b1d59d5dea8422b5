"""Trajectory error figures of an estimate against ground truth, as a report and a plot.

The library of ``salo evaluate``: read two KITTI pose files (``load_pair``),
evaluate (``odometry.metrics.evaluate_trajectory``), explain what is missing
(``evaluation_notes``), format a table (``format_table``), plot (``plot_evaluation``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from simlidar.sequence import DatasetError

PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


def load_pair(gt_path: Path, est_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read both pose files -> two (N, 4, 4) arrays; DatasetError if their frame counts differ."""
    from simlidar.formats.kitti import read_kitti_poses

    T_gt, T_est = read_kitti_poses(gt_path), read_kitti_poses(est_path)
    if len(T_gt) != len(T_est):
        raise DatasetError(
            f"{est_path}: {len(T_est)} poses, but the ground truth {gt_path} has {len(T_gt)}; "
            "the metrics need one estimated pose per ground-truth frame"
        )
    return T_gt, T_est


def evaluation_notes(T_gt: np.ndarray, T_est: np.ndarray, metrics) -> list[str]:
    notes = []
    if not metrics.has_relative_errors:
        notes.append(
            f"ground-truth path is {metrics.path_length_m:.1f} m, shorter than the shortest "
            f"segment ({min(metrics.lengths_m):g} m): KITTI and 100 m figures do not exist (null)"
        )
    if not np.allclose(T_gt[0], T_est[0], atol=1e-6):
        notes.append(
            "the first poses differ: the unaligned ATE includes that offset (the relative "
            "metrics and the aligned ATE do not depend on it)"
        )
    return notes


# ---------------------------------------------------------------- table
def _f(x: float, fmt: str = ".3f") -> str:
    return format(x, fmt) if math.isfinite(x) else "n/a"


def format_table(metrics, gt_path, est_path, notes: list[str] = ()) -> str:
    """A readable text report of a ``TrajectoryMetrics``."""
    from odometry.metrics import ErrorStats

    m = metrics
    lines = [
        f"ground truth  {gt_path}",
        f"estimate      {est_path}",
        f"frames {m.frames}, ground-truth path {m.path_length_m:.1f} m",
        "",
        "KITTI relative error (devkit definition: segments "
        f"{min(m.lengths_m):g}..{max(m.lengths_m):g} m along the ground truth, every 10th frame)",
    ]
    if m.has_relative_errors:
        lines += [
            f"  translation  {_f(m.t_err_pct):>8} %          ({len(m.segments)} segments pooled)",
            f"  rotation     {_f(m.r_err_deg_per_100m, '.4f'):>8} deg/100 m   "
            f"(devkit unit: {m.r_err_rad_per_m:.3e} rad/m)",
            "",
            "  length m  segments  t_err %  r_err deg/100m",
        ]
        for s in m.per_length:
            if s.count:
                r = _f(s.r_err_deg_per_100m, ".4f")
                lines.append(f"  {s.length_m:8g}  {s.count:8d}  {_f(s.t_err_pct):>7}  {r:>14}")
    else:
        lines.append("  n/a: no segment fits in the ground-truth path")
    lines += [
        "",
        "SALO paper (Table I): translational error of 100 m segments, m per 100 m",
        f"  mu {_f(m.t100_mean_m)}   sigma {_f(m.t100_std_m)}   ({len(m.t100_errors_m)} segments)",
        "",
        "ATE, position error, m         rmse      mean       max",
    ]
    for name, errs in (("as given", m.ate_errors_m), ("SE(3)-aligned", m.ate_aligned_errors_m)):
        st = ErrorStats.of(errs)
        lines.append(f"  {name:24s} {_f(st.rmse, '9.4f')} {_f(st.mean, '9.4f')} {_f(st.max, '9.4f')}")
    lines += [
        "",
        f"RPE, {len(m.rpe)} pairs {m.rpe_delta_frames} frame(s) apart"
        "       mean    median      rmse",
    ]
    for name, st in (("translation, m", m.rpe.t_stats_m), ("rotation, deg", m.rpe.r_stats_deg)):
        lines.append(
            f"  {name:24s} {_f(st.mean, '9.4f')} {_f(st.median, '9.4f')} {_f(st.rmse, '9.4f')}"
        )
    if notes:
        lines += ["", *(f"note: {n}" for n in notes)]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- plot
def _plane_axes(T_gt: np.ndarray, plane: str) -> tuple[int, int]:
    if plane != "auto":
        return PLANES[plane]
    extent = np.ptp(T_gt[:, :3, 3], axis=0)
    # Driving is mostly horizontal: the axis of least extent is the vertical one.
    keep = sorted(int(i) for i in np.argsort(extent)[1:])
    return keep[0], keep[1]


def plot_evaluation(path: Path, T_gt, T_est, metrics, plane: str = "auto", title: str = "") -> None:
    """Write a PNG: top-down trajectories, and KITTI translation / rotation error per segment length."""
    from matplotlib.figure import Figure

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise DatasetError(f"{path}: the plot is written as PNG; give a .png file name")
    i, j = _plane_axes(T_gt, plane)
    names = "xyz"
    fig = Figure(figsize=(14, 5.2), layout="constrained")
    ax_traj, ax_t, ax_r = fig.subplots(1, 3, width_ratios=[1.25, 1, 1])

    p_gt, p_est = T_gt[:, :3, 3], T_est[:, :3, 3]
    ax_traj.plot(p_gt[:, i], p_gt[:, j], color="tab:red", lw=1.8, label="ground truth")
    ax_traj.plot(p_est[:, i], p_est[:, j], color="tab:blue", lw=1.4, label="estimate")
    ax_traj.plot(p_gt[0, i], p_gt[0, j], "ks", ms=7, mfc="none", mew=1.5, label="start")
    ax_traj.set_aspect("equal", adjustable="datalim")
    ax_traj.set_xlabel(f"{names[i]} [m]")
    ax_traj.set_ylabel(f"{names[j]} [m]")
    ax_traj.set_title(f"trajectory, top view ({metrics.path_length_m:.0f} m, {metrics.frames} frames)")
    ax_traj.grid(True, alpha=0.3)
    ax_traj.legend(loc="best")

    per = [s for s in metrics.per_length if s.count]
    panels = (
        (ax_t, "t_err_pct", "translation error [%]", metrics.t_err_pct, "%.2f %%", True),
        (ax_r, "r_err_deg_per_100m", "rotation error [deg/100 m]", metrics.r_err_deg_per_100m,
         "%.3f deg/100 m", False),
    )
    for ax, key, ylabel, overall, fmt, show_counts in panels:
        ax.set_xlabel("segment length [m]")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if not per:
            ax.text(
                0.5, 0.5,
                f"no segment of {min(metrics.lengths_m):g} m or more:\n"
                f"ground-truth path is {metrics.path_length_m:.1f} m",
                ha="center", va="center", transform=ax.transAxes,
            )
            ax.set_xlim(0, max(metrics.lengths_m) + 100)
            ax.set_ylim(0, 1)
            continue
        x = [s.length_m for s in per]
        y = [getattr(s, key) for s in per]
        label = "mean per length (n = segments)" if show_counts else "mean per length"
        ax.plot(x, y, "o-", color="tab:blue", mfc="none", mew=1.5, label=label)
        ax.axhline(overall, color="tab:gray", ls="--", lw=1, label="overall (pooled): " + fmt % overall)
        # The counts once, on the first panel: they are the same on both.
        for xx, yy, s in zip(x, y, per, strict=True) if show_counts else ():
            ax.annotate(f"n={s.count}", (xx, yy), textcoords="offset points", xytext=(0, 7),
                        ha="center", fontsize=8, color="0.35")
        ax.set_xlim(0, max(metrics.lengths_m) + 100)
        ax.set_ylim(0, max(max(y), overall) * 1.25 or 1.0)
        ax.legend(loc="lower right", fontsize=9)
    ax_t.set_title("KITTI translational error")
    ax_r.set_title("KITTI rotational error")
    if title:
        fig.suptitle(title)

    from tools.experiments.plots import save_png

    try:
        save_png(fig, path)
    except OSError as exc:
        raise DatasetError(f"{path}: cannot write the plot ({exc.strerror})") from None


__all__ = ["PLANES", "evaluation_notes", "format_table", "load_pair", "plot_evaluation"]
