"""Open loop: the odometry run with its state advanced by the true motion, to see each registration's own error.

A closed-loop run mixes two things: the error each registration makes, and the drift those
errors feed back (a map or a motion prior built from wrong poses). ``run_open_loop`` wraps an
``Odometry``: every frame goes through its stages as always (``prepare``, ``predict``,
``align``), and the frame's estimate is kept, but ``update`` takes the true motion, so the pose,
the motion prior, the de-skew and the map advance with the truth and every frame meets a
target the truth built (except that with per-point times the first scan keeps the de-skew the
cold start's refinements gave it). ``tools.open_loop`` prints the errors.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from simlidar import se3
from simlidar.formats.scan_folders import Sequence
from simlidar.sensor import LidarModel

from .config import OdometryConfig
from .pipeline import Alignment, Odometry, OdometryError, OdometryRun, frames_of, prepared_scans, scan_inputs


@dataclass
class OpenLoopRun:
    """An open-loop run: ``run`` (its poses are the true ones, relative to the first frame run; its
    diagnostics those of each frame's registration) and ``estimated_motions`` (F, 4, 4), each frame's
    own estimate of its motion ``T_prev_cur`` (the constant-velocity guess where it was extrapolated;
    nan for the first frame, which has none)."""

    run: OdometryRun
    estimated_motions: np.ndarray


def run_open_loop(sequence: Sequence, config: OdometryConfig, true_poses: np.ndarray,
                  sensor: LidarModel | None = None, frames: slice | None = None,
                  prefetch: int | None = None) -> OpenLoopRun:
    """Run the odometry open loop over (a slice of) a sequence.

    true_poses: (F, 4, 4) the sequence's true poses (every frame of it). sensor: default the
    sequence's own. prefetch: scans prepared ahead (``odometry.pipeline.prepared_scans``).
    """
    idx = frames_of(sequence, frames)
    true_poses = np.asarray(true_poses, dtype=float)
    if len(true_poses) != len(sequence):
        raise OdometryError(f"{sequence.path}: {len(true_poses)} true poses for {len(sequence)} frames")
    odo = Odometry(config, sensor or sequence.sensor)
    estimates = np.full((len(idx), 4, 4), np.nan)
    t0 = time.perf_counter()
    for j, (scan, prepared) in enumerate(prepared_scans(odo, scan_inputs(sequence, idx), prefetch)):
        frame = odo.predict(prepared, scan.stamp_s)
        alignment = odo.align(frame)
        if j > 0:
            estimates[j] = alignment.motion
            true_motion = se3.inverse(true_poses[idx[j - 1]]) @ true_poses[idx[j]]
            alignment = Alignment(true_motion, alignment.target, alignment.nearest)
        odo.update(frame, alignment)
        odo.conclude(frame)
    times = None if sequence.times is None else np.asarray(sequence.times)[idx]
    run = OdometryRun(np.stack(odo.poses), idx, times, odo.diagnostics, config, time.perf_counter() - t0)
    return OpenLoopRun(run, estimates)
