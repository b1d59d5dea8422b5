"""A scan-to-map odometry over small_gicp's Python API (Koide, JOSS 2024): the peer "small_gicp s2m".

Per frame: the points within our range limits are downsampled on a 0.25 m voxel grid
and given covariances from their 10 nearest neighbours (``small_gicp.preprocess_points``);
the scan is registered with the GICP cost against the covariances of a
``small_gicp.GaussianVoxelMap`` of 1 m voxels (``small_gicp.align(voxel_map, scan, guess)``,
small_gicp's VGICP), from the constant-velocity guess (last pose times last motion);
then the registered scan is ``insert``-ed into the map, which forgets voxels no insert
has touched for ``lru_horizon_frames`` inserts (checked every ``lru_clear_cycle_frames``,
``GaussianVoxelMap.set_lru``). The first scan only seeds the map (its pose is the identity).

small_gicp has no de-skew: a scan with per-point times is registered as measured and
its pose belongs to mid-sweep (``tools.peers.UNDESKEWED_INSTANT``); a scan without times is
registered in its own frame (instant 0).
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from simlidar import se3
from tools.runners import MethodRun

from . import PEER_MAX_RANGE_M, pose_instant, range_limits, require_peer, run_frames

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SmallGicpConfig:
    """Settings of the pipeline (small_gicp's own defaults where it has one).

    downsampling_m: voxel grid of each scan, m. num_neighbors: for the covariances.
    map_voxel_m: voxel of the Gaussian map, m. lru_horizon_frames, lru_clear_cycle_frames:
    the map's forgetting (inserts). max_correspondence_m: m. max_iterations: per frame.
    rotation_epsilon_rad, translation_epsilon_m: convergence. num_threads: OpenMP threads
    (default: all cores, as KISS-ICP and GenZ-ICP use through TBB).
    """

    downsampling_m: float = 0.25
    num_neighbors: int = 10
    map_voxel_m: float = 1.0
    lru_horizon_frames: int = 100
    lru_clear_cycle_frames: int = 10
    max_correspondence_m: float = 1.0
    max_iterations: int = 20
    rotation_epsilon_rad: float = math.radians(0.1)
    translation_epsilon_m: float = 1e-3
    num_threads: int = field(default_factory=lambda: os.cpu_count() or 1)


def run_small_gicp(sequence, min_range_m: float = 2.5, max_range_m: float = PEER_MAX_RANGE_M,
                   config: SmallGicpConfig | None = None, frames: slice | None = None, on_frame=None) -> MethodRun:
    """Run the small_gicp scan-to-map pipeline over (a slice of) a sequence (``simlidar.sequence``).

    Args:
        sequence: frames with points (per-point times only decide the pose instant).
        min_range_m, max_range_m: range limits, m (the far one capped at 100 m, as for the other peers).
        config: the pipeline's settings (default ``SmallGicpConfig()``).
        frames: which frames (default all). on_frame: ``on_frame(k)`` after each frame.

    Returns:
        ``tools.runners.MethodRun`` with sweep-start poses. Raises ``tools.peers.PeerUnavailable`` when small_gicp
        is missing or too old.
    """
    require_peer("small-gicp")
    import small_gicp

    cfg = config or SmallGicpConfig()
    lo, hi = range_limits(min_range_m, max_range_m)
    voxel_map = small_gicp.GaussianVoxelMap(cfg.map_voxel_m)
    voxel_map.set_lru(horizon=cfg.lru_horizon_frames, clear_cycle=cfg.lru_clear_cycle_frames)
    T_map_lidar, motion = np.eye(4), np.eye(4)
    not_converged = 0

    def register(points: np.ndarray, times: np.ndarray | None):
        nonlocal T_map_lidar, motion, not_converged
        r = np.linalg.norm(points, axis=1)
        scan, _ = small_gicp.preprocess_points(points[(r > lo) & (r < hi)], downsampling_resolution=cfg.downsampling_m,
                                               num_neighbors=cfg.num_neighbors, num_threads=cfg.num_threads)
        if voxel_map.size() > 0:
            result = small_gicp.align(voxel_map, scan, T_map_lidar @ motion,
                                      max_correspondence_distance=cfg.max_correspondence_m,
                                      num_threads=cfg.num_threads, max_iterations=cfg.max_iterations,
                                      rotation_epsilon=cfg.rotation_epsilon_rad,
                                      translation_epsilon=cfg.translation_epsilon_m)
            not_converged += not result.converged
            # align keeps its guess's rounding off orthonormality, and the guess is built from its last
            # result: unprojected, the error doubled every frame (1e-2 after 38 frames, then divergence).
            T_new = se3.make(Rotation.from_matrix(result.T_target_source[:3, :3]).as_matrix(),
                             result.T_target_source[:3, 3])
            motion = se3.inverse(T_map_lidar) @ T_new
            T_map_lidar = T_new
        voxel_map.insert(scan, T_map_lidar)
        return T_map_lidar, pose_instant(times, None)

    used = {**asdict(cfg), "range_m": [lo, hi], "registration": "GICP against GaussianVoxelMap (VGICP)",
            "guess": "constant velocity", "deskew": False}
    run = run_frames("small-gicp", sequence, register, used, frames, on_frame)
    if not_converged:
        log.info("small_gicp: %d of %d registrations stopped at max_iterations", not_converged, len(run.poses) - 1)
    return run
