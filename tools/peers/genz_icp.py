"""GenZ-ICP (Lee, Lim and Han, RA-L 2025) as a peer, through its Python API (``genz_icp.genz_icp.GenZICP``).

A fork of KISS-ICP whose registration splits the correspondences by the planarity
of their map neighbourhood and weights point-to-plane against point-to-point
residuals by the share of planar ones; the voxel size adapts per frame to keep about
``desired_num_voxelized_points`` in the scan.

Configuration: the package's own "general outdoor environments" preset
(``genz_icp/config/pretuned/outdoor.yaml``: voxel 0.6 m, 3000 desired points,
planarity threshold 0.2, 3 points per voxel, 100 iterations, convergence 1e-4)
through its ``load_config``, with our range limits and de-skew on. Its bare
``GenZConfig()`` defaults (voxel 0.3 m, 2000 points, 1 point per voxel, de-skew off)
are ``preset=None``; on a 40-frame VLP-16 city drive they did not follow the first
six frames (4 cm of 60 cm motion per frame), 3.5 m off after 20 m, where the
preset stays within 0.3 m.

Pose instants (``tools.peers`` notes). With de-skew on and timestamps given, its
C++ pipeline (``GenZICP::RegisterFrame``) de-skews from its fourth frame on (it needs
two poses for a velocity) with ``DeSkewScan``: each point moves by
``exp((t - 0.5) log(delta))``, delta the last frame-to-frame motion, t the timestamp
*as given* (it does not normalise them): the pose is the sensor pose at mid-sweep
when t is the fraction of the sweep, which is what we pass (``time_s`` divided by the
sweep period). Frames before that, or with de-skew off, are registered as measured
(instant ``UNDESKEWED_INSTANT``, also mid-sweep). Without timestamps it does not
de-skew; the pose is the scan's own frame's (instant 0).

Not reproducible run to run in one process: the C++ keeps the adaptive voxel size in
a function-level static, so a run starts from the voxel size the previous run
(any ``GenZICP`` object) ended with; two runs over the same frames differed by 3 cm.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from tools.runners import MethodRun

from . import PEER_MAX_RANGE_M, pose_instant, range_limits, require_peer, run_frames

GENZ_DESKEW_INSTANT = 0.5
# GenZICP::RegisterFrame de-skews only when it holds more than two poses.
GENZ_FIRST_DESKEWED_FRAME = 3
DEFAULT_PRESET = "outdoor.yaml"


def sweep_fractions(times_s: np.ndarray, sweep_period_s: float | None) -> np.ndarray:
    """(N,) per-point times, s -> (N,) fractions of the sweep (time / period; without a
    period, mapped to [0, 1] by their minimum and maximum)."""
    if sweep_period_s:
        return times_s / float(sweep_period_s)
    lo, hi = float(np.min(times_s)), float(np.max(times_s))
    return (times_s - lo) / (hi - lo)


def run_genz_icp(sequence, min_range_m: float = 2.5, max_range_m: float = PEER_MAX_RANGE_M,
                 preset: str | None = DEFAULT_PRESET, deskew: bool = True,
                 frames: slice | None = None, on_frame=None) -> MethodRun:
    """Run GenZ-ICP over (a slice of) a sequence (``simlidar.sequence``).

    Args:
        sequence: frames with points and, for distorted scans, per-point ``time_s``;
            its ``sensor.sweep_period_s`` turns times into sweep fractions.
        min_range_m, max_range_m: range limits, m (the far one capped at 100 m).
        preset: a pre-tuned YAML file shipped with genz-icp (None: ``GenZConfig()``'s defaults).
        deskew: GenZ-ICP's de-skew (only acts on frames with per-point times).
        frames: which frames (default all). on_frame: ``on_frame(k)`` after each frame.

    Returns:
        ``tools.runners.MethodRun`` with sweep-start poses. Raises ``tools.peers.PeerUnavailable`` when genz-icp
        is missing or too old.
    """
    require_peer("genz-icp")
    from genz_icp.config import GenZConfig, load_config
    from genz_icp.genz_icp import GenZICP

    if preset is None:
        config = GenZConfig()
    else:  # the packaged file by its full path: a file of that name in the working folder must not win
        config = load_config(Path(str(resources.files("genz_icp.config").joinpath("pretuned", preset))))
    config.data.min_range, config.data.max_range = range_limits(min_range_m, max_range_m)
    config.data.deskew = bool(deskew)
    odometry = GenZICP(config)
    sensor = getattr(sequence, "sensor", None)
    period = sensor.sweep_period_s if sensor is not None else None
    registered = 0

    def register(points: np.ndarray, times: np.ndarray | None):
        nonlocal registered
        fractions = None if times is None else sweep_fractions(times, period)
        odometry.register_frame(points, fractions)
        deskewed = fractions is not None and config.data.deskew and registered >= GENZ_FIRST_DESKEWED_FRAME
        registered += 1
        return odometry.last_pose, pose_instant(times, GENZ_DESKEW_INSTANT if deskewed else None)

    used = {**config.model_dump(), "preset": preset, "timestamps": "time_s / sweep period"}
    return run_frames("genz-icp", sequence, register, used, frames, on_frame)
