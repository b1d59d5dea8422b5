"""Figures of a run that tell environments apart, beside KITTI's t_err on the leaderboard.

- Windowed relative error (``windowed_error_pct``): KITTI's protocol with short
  windows, every frame a start: for each frame i and the first frame j at least
  past ``window_m`` further along the truth, the translation of
  ``(gt_i^-1 gt_j)^-1 (est_i^-1 est_j)`` over ``window_m`` (the nominal length, as
  KITTI divides), averaged, in %. KITTI's
  100-800 m segments need a long path and smooth local trouble away; 10 m and 50 m
  windows exist on short sequences and show a local slip at its size.
- Error along the truth's weakest direction over its weak stretches
  (``weak_direction_error``): for each stretch of frames that the simulator's truth
  finds weakly constrained (``tools.degenerate.truth_constraints``), the error the run
  accumulated from the frame before the stretch to its last frame, projected on the
  stretch's mean weakest direction (lidar frame), summed over the stretches and
  divided by the distance they span, in %. It is the error where the geometry leaves
  a direction open, along that direction: what a degeneracy-aware method should keep
  small. None where the truth has no weak stretch.
"""

from __future__ import annotations

import numpy as np

WINDOWS_M = (10.0, 50.0)


def windowed_error_pct(gt: np.ndarray, est: np.ndarray, window_m: float) -> float | None:
    """Mean relative translation error over windows of ``window_m`` along ``gt`` (N, 4, 4), every frame a start,
    %; None when the path is shorter than the window or ``est`` is not finite."""
    from odometry.metrics import kitti_segment_errors

    if not np.all(np.isfinite(est)):
        return None
    segments = kitti_segment_errors(gt, est, lengths_m=(window_m,), step_frames=1)
    return float(100.0 * segments.t_err_ratio.mean()) if len(segments) else None


def weak_direction_error(gt: np.ndarray, est: np.ndarray, stretches: list) -> tuple[float | None, float]:
    """(error along the weakest direction over the weak stretches, %, or None; the distance they span, m).

    gt, est: (N, 4, 4) ``T_first_lidar``. stretches: ``odometry.pipeline.DegenerateStretch`` of the truth
    (frame numbers of these poses; ``direction`` (3,) in the lidar frame). A stretch the run diverged in
    counts as None: no figure.
    """
    from odometry.metrics import trajectory_distances
    from simlidar import se3

    dist = trajectory_distances(gt)
    along, span = 0.0, 0.0
    for st in stretches:
        i, j = max(st.first - 1, 0), min(st.last, len(gt) - 1)
        if j <= i:
            continue
        if not (np.all(np.isfinite(est[i])) and np.all(np.isfinite(est[j]))):
            return None, float(dist[-1])
        error = se3.inverse(se3.inverse(gt[i]) @ gt[j]) @ (se3.inverse(est[i]) @ est[j])
        direction = np.asarray(st.direction, dtype=float)
        direction = direction / max(np.linalg.norm(direction), 1e-12)
        along += abs(float(error[:3, 3] @ direction))
        span += float(dist[j] - dist[i])
    if span <= 0:
        return None, 0.0
    return 100.0 * along / span, span


def environment_figures(gt: np.ndarray, est: np.ndarray, truth_stretches: list | None) -> dict:
    """The figures above for one run: ``rel_10m_pct``, ``rel_50m_pct``, ``weak_dir_err_pct``, ``weak_span_m``."""
    out = {f"rel_{w:g}m_pct": windowed_error_pct(gt, est, w) for w in WINDOWS_M}
    if truth_stretches is not None:
        out["weak_dir_err_pct"], out["weak_span_m"] = weak_direction_error(gt, est, truth_stretches)
    return out


__all__ = ["WINDOWS_M", "environment_figures", "weak_direction_error", "windowed_error_pct"]
