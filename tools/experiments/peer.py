"""KISS-ICP (Vizzo et al., RA-L 2023) as the peer method of the table, through its Python API.

Optional: install the ``peer`` extra (``pip install -e '.[peer]'``, which pulls
``kiss-icp`` from PyPI). ``kiss_icp_available()`` says whether it imports; the
table's KISS-ICP row says "not installed" otherwise.

It runs on the same frames as our odometry: the measured points of each sweep
and their per-point firing times, with its default configuration (voxel size
max_range / 100, adaptive threshold, de-skew on), except that the range limits
are ours (``min_range_m`` / ``max_range_m`` of the odometry config, capped at
KISS-ICP's 100 m default), so both see the same points.

Which instant a KISS-ICP pose belongs to. KISS-ICP (1.x) de-skews a sweep to
its *last* firing: it maps the firing times to [0, 1] and moves each point by
``exp((s - 1) log(delta))``, with delta its last frame-to-frame motion. The
pose it returns for sweep k is therefore the sensor pose at the end of sweep k,
which is (to one azimuth step) the start of sweep k + 1; our ground truth and
our odometry give the pose at the *start* of each sweep. So the pose of sweep
k's start is KISS-ICP's pose of sweep k - 1. Sweep 0 has no predecessor; its
start is put one constant-velocity step (KISS-ICP's own motion estimate of
the next frame) before the end of sweep 0, and the trajectory is re-expressed
relative to it, so ``poses[0]`` is the identity as everywhere else. Without
this shift every pose would lead the truth by one frame (about 1 m at 10 m/s).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from simlidar import se3

log = logging.getLogger(__name__)

KISS_DEFAULT_MAX_RANGE_M = 100.0


def kiss_icp_available() -> bool:
    """True when ``kiss_icp`` imports."""
    try:
        import kiss_icp.kiss_icp  # noqa: F401
    except ImportError:
        return False
    return True


def kiss_icp_version() -> str | None:
    try:
        from importlib.metadata import version

        return version("kiss-icp")
    except Exception:  # noqa: BLE001 - any failure means "unknown"
        return None


@dataclass
class PeerRun:
    """Poses (N, 4, 4) ``T_first_lidar`` at each sweep's start, the config used and the run time."""

    poses: np.ndarray
    config: dict
    seconds: float

    @property
    def frames_per_second(self) -> float:
        return len(self.poses) / self.seconds if self.seconds > 0 else float("nan")


def end_poses_to_start_poses(end_poses: np.ndarray) -> np.ndarray:
    """KISS-ICP's sweep-end poses (N, 4, 4) -> sweep-start poses (N, 4, 4), the first the identity.

    ``start[k] = end[k - 1]`` for k >= 1; ``start[0] = end[0] delta^-1`` with
    ``delta = end[0]^-1 end[1]`` (one constant-velocity step back); then all are
    re-expressed relative to ``start[0]``. See the module notes.
    """
    end_poses = np.asarray(end_poses, dtype=np.float64)
    n = len(end_poses)
    if n == 1:
        return np.eye(4)[None]
    delta = se3.inverse(end_poses[0]) @ end_poses[1]
    start = np.empty_like(end_poses)
    start[0] = end_poses[0] @ se3.inverse(delta)
    start[1:] = end_poses[:-1]
    return se3.inverse(start[0]) @ start


def run_kiss_icp(sequence, min_range_m: float = 2.5, max_range_m: float = KISS_DEFAULT_MAX_RANGE_M,
                 frames: slice | None = None, on_frame=None) -> PeerRun:
    """Run KISS-ICP over (a slice of) a ``simlidar.dataset.Sequence``.

    Args:
        sequence: frames with points and per-point ``time_s`` (de-skew is off
            for frames without times).
        min_range_m, max_range_m: range limits, m (max capped at 100 m, KISS-ICP's default).
        frames: which frames (default all).
        on_frame: ``on_frame(k)`` after each frame (progress).

    Returns:
        ``PeerRun`` with sweep-start poses. Raises ImportError when kiss-icp is missing.
    """
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    version = kiss_icp_version() or ""
    if version.startswith("0."):
        # 0.x de-skews to mid-sweep, not to the sweep's end: the pose shift below would be wrong.
        raise ImportError(f"kiss-icp {version} is too old (the table needs kiss-icp >= 1.0)")
    max_range = min(float(max_range_m), KISS_DEFAULT_MAX_RANGE_M)
    config = KISSConfig()
    config.data.min_range = float(min_range_m)
    config.data.max_range = max_range
    config.mapping.voxel_size = max_range / 100.0  # its load_config's default rule
    odometry = KissICP(config)
    idx = np.arange(len(sequence))[frames or slice(None)]
    ends = []
    t0 = time.perf_counter()
    for k in idx:
        frame = sequence[int(k)]
        pts = np.ascontiguousarray(frame.points, dtype=np.float64)
        finite = np.all(np.isfinite(pts), axis=1)
        times = frame.time_s
        stamps = np.zeros(0) if times is None else np.asarray(times, dtype=np.float64)[finite]
        odometry.register_frame(pts[finite], stamps)
        ends.append(odometry.last_pose.copy())
        if on_frame is not None:
            on_frame(int(k))
    seconds = time.perf_counter() - t0
    used = config.model_dump() if hasattr(config, "model_dump") else {}
    used["kiss_icp_version"] = kiss_icp_version()
    return PeerRun(end_poses_to_start_poses(np.stack(ends)), used, seconds)
