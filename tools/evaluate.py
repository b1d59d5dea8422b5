"""Trajectory error figures of an estimate against ground truth, as a report and a plot.

The library of ``salo evaluate``: read two trajectories, KITTI pose files or TUM
(``read_trajectory``, ``load_pair``: paired by line, or by time stamp when both are
TUM and their counts differ; camera-frame KITTI ground truth to the lidar frame
with ``calib.txt``), evaluate (``odometry.metrics.evaluate_trajectory``), explain
what is missing or suspicious (``evaluation_notes``, ``frame_mixup``), format a
table (``format_table``), plot (``plot_evaluation``, weakly constrained stretches shaded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simlidar.sequence import DatasetError

PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


@dataclass(frozen=True)
class Trajectory:
    """Poses (N, 4, 4) read from ``path``, in ``format`` ("KITTI" or "TUM"), with their times (N,) s (TUM only)."""

    path: Path
    format: str
    poses: np.ndarray
    times: np.ndarray | None = None

    def describe(self) -> str:
        return f"{self.path} as {self.format} ({len(self.poses)} poses)"


def read_trajectory(path: str | Path) -> Trajectory:
    """A KITTI pose file (12 numbers a line) or a TUM trajectory (8), told apart by the first data line."""
    from simlidar.formats.kitti import read_kitti_poses
    from simlidar.formats.tum import read_tum

    path = Path(path)
    try:
        lines = [t for t in path.read_text().splitlines() if t.strip() and not t.lstrip().startswith("#")]
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read trajectory ({exc.strerror})") from None
    columns = len(lines[0].split()) if lines else 0
    if columns == 8:
        times, poses = read_tum(path)
        return Trajectory(path, "TUM", poses, times)
    if columns == 12:
        return Trajectory(path, "KITTI", read_kitti_poses(path))
    raise DatasetError(f"{path}: neither KITTI poses (12 numbers a line) nor a TUM trajectory (8: time tx ty tz "
                       f"qx qy qz qw); the first line has {columns}")


def _match_times(gt: Trajectory, est: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Indices pairing ``gt`` and ``est`` poses whose time stamps agree within a quarter of gt's median period."""
    period = float(np.median(np.diff(gt.times))) if len(gt.times) > 1 else 1.0
    n = len(est.times)
    j = np.searchsorted(est.times, gt.times)
    lo, hi = np.clip(j - 1, 0, n - 1), np.clip(j, 0, n - 1)
    pick = np.where(np.abs(est.times[lo] - gt.times) <= np.abs(est.times[hi] - gt.times), lo, hi)
    keep = np.abs(est.times[pick] - gt.times) <= 0.25 * period
    return np.flatnonzero(keep), pick[keep]


def load_pair(gt_path: Path, est_path: Path, calib: Path | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Read both trajectories -> (T_gt (N, 4, 4), T_est (N, 4, 4), lines saying what was read and done).

    Poses pair by line; two TUM trajectories of different lengths pair by time stamp
    (within a quarter frame). calib: a KITTI ``calib.txt`` whose ``Tr`` takes the
    ground truth from KITTI's camera frame to the lidar frame
    (``simlidar.formats.kitti.camera_poses_to_lidar``). DatasetError when they cannot pair.
    """
    gt, est = read_trajectory(gt_path), read_trajectory(est_path)
    said = [f"ground truth: {gt.describe()}", f"estimate:     {est.describe()}"]
    T_gt, T_est = gt.poses, est.poses
    if len(T_gt) != len(T_est):
        if gt.times is None or est.times is None:
            raise DatasetError(
                f"{est_path}: {len(T_est)} poses, but the ground truth {gt_path} has {len(T_gt)}; "
                "the metrics need one estimated pose per ground-truth frame (or two TUM files, paired by time)"
            )
        i, j = _match_times(gt, est)
        if len(i) < 2:
            raise DatasetError(f"{est_path}: fewer than 2 of its time stamps match the ground truth's {gt_path}")
        T_gt, T_est = T_gt[i], T_est[j]
        said.append(f"paired by time stamp: {len(i)} poses (of {len(gt.poses)} and {len(est.poses)})")
    if calib is not None:
        from simlidar.formats.kitti import camera_poses_to_lidar, read_kitti_calib_tr

        T_gt = camera_poses_to_lidar(T_gt, read_kitti_calib_tr(calib))
        said.append(f"ground truth converted from KITTI's camera frame to the lidar frame with Tr of {calib}")
    return T_gt, T_est, said


# KITTI's camera axes from the lidar's: camera x = -lidar y, camera y = -lidar z, camera z = lidar x.
CAMERA_FROM_LIDAR = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
MIXUP_ANGLE_DEG = 45.0
MATCH_ANGLE_DEG = 20.0


def _first_motion(T: np.ndarray, k: int) -> np.ndarray:
    """Where pose k lies in the first pose's frame, m."""
    return (np.linalg.inv(T[0]) @ T[k])[:3, 3]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def frame_mixup(T_gt: np.ndarray, T_est: np.ndarray, distance_m: float = 5.0) -> str | None:
    """A warning when the two trajectories' first motions point apart in a way a frame mix-up explains.

    The first motion: where each trajectory is, in its own first frame, when the ground truth
    has travelled ``distance_m`` (or half its path). When the two directions differ by more
    than 45 deg and KITTI's camera-from-lidar axes bring one onto the other (within 20 deg),
    one trajectory is in the lidar frame and the other in KITTI's camera frame.
    """
    from odometry.metrics import trajectory_distances

    dist = trajectory_distances(T_gt)
    if len(dist) < 2 or dist[-1] <= 0.5:
        return None
    k = int(np.searchsorted(dist, min(distance_m, 0.5 * dist[-1])))
    k = min(max(k, 1), len(dist) - 1)
    d_gt, d_est = _first_motion(T_gt, k), _first_motion(T_est, k)
    if min(np.linalg.norm(d_gt), np.linalg.norm(d_est)) < 0.2 or not np.all(np.isfinite(d_est)):
        return None
    apart = _angle_deg(d_gt, d_est)
    if apart <= MIXUP_ANGLE_DEG:
        return None
    axis = "xyz"
    head = (f"the first motions disagree by {apart:.0f} deg (ground truth moves mostly along "
            f"{axis[int(np.argmax(np.abs(d_gt)))]}, the estimate along {axis[int(np.argmax(np.abs(d_est)))]})")
    if _angle_deg(CAMERA_FROM_LIDAR @ d_est, d_gt) < MATCH_ANGLE_DEG:
        return (head + ": the ground truth looks like KITTI's camera frame (forward = z) and the estimate like "
                "the lidar frame (forward = x); give --calib calib.txt to convert the ground truth")
    if _angle_deg(CAMERA_FROM_LIDAR @ d_gt, d_est) < MATCH_ANGLE_DEG:
        return (head + ": the estimate looks like KITTI's camera frame (forward = z) and the ground truth like "
                "the lidar frame (forward = x); compare lidar-frame poses (salo odometry writes them)")
    return head + ": are both in the same frame and do they start at the same instant?"


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
    mixup = frame_mixup(T_gt, T_est)
    if mixup:
        notes.append(f"warning: {mixup}")
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
        lines += ["", *(n if n.startswith("warning:") else f"note: {n}" for n in notes)]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- plot
def _plane_axes(T_gt: np.ndarray, plane: str) -> tuple[int, int]:
    if plane != "auto":
        return PLANES[plane]
    extent = np.ptp(T_gt[:, :3, 3], axis=0)
    # Driving is mostly horizontal: the axis of least extent is the vertical one.
    keep = sorted(int(i) for i in np.argsort(extent)[1:])
    return keep[0], keep[1]


def metres_text(value: float) -> str:
    """A length for a title: whole metres from 10 m on, two significant figures below (0.59 m, not 1 m)."""
    return f"{value:.0f} m" if value >= 10 else f"{value:.2g} m"


def plot_evaluation(path: Path, T_gt, T_est, metrics, plane: str = "auto", title: str = "",
                    truth_weak: np.ndarray | None = None, own_weak: np.ndarray | None = None) -> None:
    """Write a PNG: top-down trajectories, KITTI translation / rotation error per segment length, and the
    position error over distance with the weakly constrained frames shaded.

    truth_weak: (N,) bool, frames the truth finds weak (a simulated sequence's degeneracy); own_weak:
    (N,) bool, frames the estimate's method flagged itself (its diagnostics). Either may be None.
    """
    from matplotlib.figure import Figure

    from tools.leaderboard.figures import draw_error_over_distance

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise DatasetError(f"{path}: the plot is written as PNG; give a .png file name")
    i, j = _plane_axes(T_gt, plane)
    names = "xyz"
    strips = (truth_weak is not None) + (own_weak is not None)
    fig = Figure(figsize=(14, 9.0 + 0.3 * strips), layout="constrained")
    axes = fig.subplot_mosaic([["traj", "t", "r"], ["err", "err", "err"], ["strip", "strip", "strip"]],
                              width_ratios=[1.25, 1, 1], height_ratios=[5.2, 2.6, 0.35 * max(strips, 1)])
    ax_traj, ax_t, ax_r = axes["traj"], axes["t"], axes["r"]
    draw_error_over_distance(axes["err"], axes["strip"], T_gt, {"estimate": T_est}, truth_weak,
                             {} if own_weak is None else {"estimate": own_weak}, {"estimate": "tab:blue"})
    axes["err"].set_title("position error over distance (both start at the first pose)")

    p_gt, p_est = T_gt[:, :3, 3], T_est[:, :3, 3]
    ax_traj.plot(p_gt[:, i], p_gt[:, j], color="tab:red", lw=1.8, label="ground truth")
    ax_traj.plot(p_est[:, i], p_est[:, j], color="tab:blue", lw=1.4, label="estimate")
    ax_traj.plot(p_gt[0, i], p_gt[0, j], "ks", ms=7, mfc="none", mew=1.5, label="start")
    ax_traj.set_aspect("equal", adjustable="datalim")
    ax_traj.set_xlabel(f"{names[i]} [m]")
    ax_traj.set_ylabel(f"{names[j]} [m]")
    ax_traj.set_title(f"trajectory, top view ({metres_text(metrics.path_length_m)}, {metrics.frames} frames)")
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
                f"ground-truth path is {metres_text(metrics.path_length_m)}",
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

    from tools.plotting import save_png

    try:
        save_png(fig, path)
    except OSError as exc:
        raise DatasetError(f"{path}: cannot write the plot ({exc.strerror})") from None


__all__ = ["PLANES", "Trajectory", "evaluation_notes", "format_table", "frame_mixup", "load_pair", "metres_text",
           "plot_evaluation",
           "read_trajectory"]
