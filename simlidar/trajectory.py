"""Poses at arbitrary times from timed pose samples, interpolated on SE(3).

The sweep only needs an object with ``pose_at(times) -> (n, 4, 4)``; this
module provides one for sampled poses (a KITTI pose file, a scene's path).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from . import se3


class Trajectory(Protocol):
    """Anything that gives the lidar pose ``T_world_lidar`` (4x4) at times in seconds."""

    def pose_at(self, times: np.ndarray) -> np.ndarray:  # (n,) s -> (n, 4, 4)
        ...


class SampledTrajectory:
    """Screw-motion interpolation between timed poses.

    Args:
        times: (N,) strictly increasing sample times, s (N >= 1).
        poses: (N, 4, 4) ``T_world_lidar`` at those times.

    Outside the sampled interval the first / last segment's constant velocity
    is extrapolated (a single pose stands still).
    """

    def __init__(self, times: np.ndarray, poses: np.ndarray):
        self.times = np.asarray(times, dtype=float)
        self.poses = np.asarray(poses, dtype=float)
        if self.poses.ndim != 3 or self.poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must be (N, 4, 4), got {self.poses.shape}")
        if self.times.shape != (len(self.poses),) or len(self.poses) == 0:
            raise ValueError("need one time per pose and at least one pose")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("pose times must be strictly increasing")
        if len(self.poses) > 1:
            self._twists = se3.log(se3.inverse(self.poses[:-1]) @ self.poses[1:])  # (N-1, 6)

    @property
    def duration_s(self) -> float:
        return float(self.times[-1] - self.times[0])

    def pose_at(self, times: np.ndarray) -> np.ndarray:
        """(n,) times, s -> (n, 4, 4) poses."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        if len(self.poses) == 1:
            return np.broadcast_to(self.poses[0], (len(t), 4, 4)).copy()
        seg = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.poses) - 2)
        s = (t - self.times[seg]) / (self.times[seg + 1] - self.times[seg])
        return self.poses[seg] @ se3.exp(self._twists[seg] * s[:, None])
