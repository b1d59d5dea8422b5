"""KISS-ICP (Vizzo et al., RA-L 2023) as a peer, through its Python API (``kiss_icp.kiss_icp.KissICP``).

Configuration: ``KISSConfig()``'s defaults (adaptive threshold, de-skew on, point-to-point
ICP on a voxel-hash map, max 20 points per voxel) with our range limits
(``tools.peers.range_limits``) and the voxel size its ``load_config`` derives from the
range, ``max_range / 100`` (1 m at 100 m).

Pose instants (``tools.peers`` notes). ``KissICP.register_frame(points, timestamps)``
de-skews with ``last_delta``, its previous frame-to-frame motion, when timestamps are
given: every point moves by ``exp((s - 1) log(last_delta))``, s the times mapped to
[0, 1] by their minimum and maximum, so the pose it returns is the sensor pose at the
sweep's last firing (instant 1). ``last_delta`` is the identity for the first two
frames (frame 0's pose is the identity, so is the delta it leaves), whose scans stay
as measured (instant ``UNDESKEWED_INSTANT``). With no timestamps (an empty array) it
does not de-skew and the pose is the scan's own frame's (instant 0).
"""

from __future__ import annotations

import numpy as np

from tools.runners import MethodRun

from . import PEER_MAX_RANGE_M, pose_instant, range_limits, require_peer, run_frames

KISS_DESKEW_INSTANT = 1.0


def run_kiss_icp(sequence, min_range_m: float = 2.5, max_range_m: float = PEER_MAX_RANGE_M,
                 frames: slice | None = None, on_frame=None) -> MethodRun:
    """Run KISS-ICP over (a slice of) a sequence (``simlidar.sequence``).

    Args:
        sequence: frames with points and, for distorted scans, per-point ``time_s``.
        min_range_m, max_range_m: range limits, m (the far one capped at 100 m).
        frames: which frames (default all). on_frame: ``on_frame(k)`` after each frame.

    Returns:
        ``tools.runners.MethodRun`` with sweep-start poses. Raises ``tools.peers.PeerUnavailable`` when kiss-icp
        is missing or too old.
    """
    require_peer("kiss-icp")
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    lo, hi = range_limits(min_range_m, max_range_m)
    config = KISSConfig()
    config.data.min_range, config.data.max_range = lo, hi
    config.mapping.voxel_size = hi / 100.0  # its load_config's default rule
    odometry = KissICP(config)
    identity = np.eye(4)

    def register(points: np.ndarray, times: np.ndarray | None):
        deskews = times is not None and config.data.deskew and not np.array_equal(odometry.last_delta, identity)
        odometry.register_frame(points, np.zeros(0) if times is None else times)
        return odometry.last_pose, pose_instant(times, KISS_DESKEW_INSTANT if deskews else None)

    return run_frames("kiss-icp", sequence, register, config.model_dump(), frames, on_frame)
