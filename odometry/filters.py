"""Filtration of a raw scan into ICP points (Alg. 1, line 1): voxel grid, normals, NCF, curvature.

The steps, in the paper's order:

1. voxel grid: the centroid of the raw points in each occupied voxel;
2. a normal per centroid by PCA of its k nearest neighbours in the RAW scan
   (``odometry.normals``), and the normal covariance filter (``odometry.ncf``);
3. the curvature filter: PCL's ``lambda_min / sum(lambda)`` above a threshold.
"""

from __future__ import annotations

import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from simlidar.sensor import LidarModel

from .config import OdometryConfig
from .constraints import restore_constraints
from .kdtree import KDTree
from .ncf import IsotropicNoise, RangeNoise, normal_covariance_filter
from .normals import knn, neighbourhood_pca
from .poles import Poles
from .scan_lines import widen_one_ring_neighbourhoods
from .voxels import voxel_centroids

_background: dict[tuple[int, str], ThreadPoolExecutor] = {}
_background_lock = threading.Lock()


def background(queue: str = "scan") -> ThreadPoolExecutor:
    """This process's background thread for k-d tree builds of one ``queue`` (a forked child gets its own).

    Builds release the GIL, so they run on a second core beside numpy work on the first. The
    map's builds have a queue of their own ("map"): the scans prepared ahead on other threads
    (``odometry.pipeline.register_frames``) must not hold up the tree the next registration waits for.
    """
    key = (os.getpid(), queue)
    with _background_lock:  # (scans prepared on two threads may ask for it at once)
        if key not in _background:
            _background[key] = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"kdtree-{queue}")
        return _background[key]


def curvature_keep(curvature: np.ndarray, max_curvature: float) -> np.ndarray:
    """(M,) PCL curvatures -> (M,) bool, True where the surface is flat enough (nan: reject)."""
    with np.errstate(invalid="ignore"):
        return curvature <= max_curvature


@dataclass
class FilteredScan:
    """The ICP points of one scan, in its (de-skewed) sensor frame.

    points: (M, 3) voxel centroids that passed every filter, m.
    normals: (M, 3) unit normals, facing the sensor.
    rings: (M,) int ring of each point (that of its nearest raw point), or None.
    times_s: (M,) mean firing time of each point's voxel, s, or None.
    normal_std_rad: (M,) 1-sigma tilt of the normal about its least certain axis
        (NCF's prediction; nan when the NCF did not run).
    raw_points: (N, 3) the de-skewed raw points the normals were estimated from.
    raw_tree: k-d tree over ``raw_points`` (None when no normals were estimated).
    centroids: (V, 3) every voxel centroid, before the filters (what a map keeps).
    centroid_times_s: (V,) their mean firing times, s, or None.
    counts: points after each stage: raw, voxels, ncf, curvature, and "restored"
        (NCF-rejected points kept for a direction they alone constrain).
    seconds: time spent per stage.
    poles: the scan's poles (``odometry.poles``), de-skewed as ``points`` are, or None (not extracted).
    """

    points: np.ndarray
    normals: np.ndarray
    rings: np.ndarray | None
    times_s: np.ndarray | None
    normal_std_rad: np.ndarray
    raw_points: np.ndarray
    raw_tree: KDTree | None
    centroids: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    centroid_times_s: np.ndarray | None = None
    counts: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)
    poles: Poles | None = None

    def __len__(self) -> int:
        return len(self.points)


def ncf_noise_model(config: OdometryConfig, sensor_range_noise_std_m: float | None):
    """The NCF's noise model from the config (the sensor's range noise when not overridden)."""
    if config.ncf.noise_model == "isotropic":
        return IsotropicNoise(point_noise_std_m=config.ncf.point_noise_std_m)
    sigma = config.ncf.range_noise_std_m or sensor_range_noise_std_m
    if not sigma:
        raise ValueError(
            "the range-noise NCF needs a noise level: give a sensor (--sensor) or set ncf.range_noise_std_m"
        )
    return RangeNoise(range_noise_std_m=sigma)


def scan_normals_needed(config: OdometryConfig) -> bool:
    """Whether the scan's own normals are used: by the cost (scan-to-scan: the scan is the next
    target), or by the NCF on the scan. Registered against a map, the cost and the GCR use the
    map's normals, and the scan's points need none."""
    return config.match.target != "map" or (config.ncf.enabled and config.ncf.applies_to in ("scan", "both"))


def filter_scan(
    raw_points: np.ndarray,
    config: OdometryConfig,
    raw_rings: np.ndarray | None = None,
    sensor: LidarModel | None = None,
    raw_times_s: np.ndarray | None = None,
    with_normals: bool | None = None,
) -> FilteredScan:
    """Filter a raw scan (N, 3), as measured or de-skewed, into ICP points with normals (see module doc).

    raw_rings: (N,) int ring per point, or None. sensor: the lidar model (its range noise for the
    NCF; its rings and azimuth columns for ``filter.adjacent_ring_reach_m``, which also needs the
    rings), or None. raw_times_s: (N,) firing times, s, or None (the centroids' mean times).
    When the scan's normals are not needed (``scan_normals_needed``, unless ``with_normals``
    says otherwise), the ICP points are the voxel centroids themselves, with nan normals, no
    rings and no raw k-d tree.
    """
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    if not (scan_normals_needed(config) if with_normals is None else with_normals):
        centroids, centroid_times = (voxel_centroids(raw_points, config.filter.voxel_size_m), None) \
            if raw_times_s is None else voxel_centroids(raw_points, config.filter.voxel_size_m, raw_times_s)
        seconds["voxel"] = time.perf_counter() - t
        n = len(centroids)
        return FilteredScan(centroids, np.full((n, 3), np.nan), None, centroid_times, np.full(n, np.nan),
                            raw_points, None, centroids, centroid_times,
                            {"raw": len(raw_points), "voxels": n, "ncf": n, "curvature": n}, seconds)
    # The raw k-d tree (for the normals) is built on a second core while this one
    # computes the voxel grid: both release the GIL, and the two take about as long.
    building = background().submit(KDTree, raw_points)
    if raw_times_s is None:
        centroids, centroid_times = voxel_centroids(raw_points, config.filter.voxel_size_m), None
    else:
        centroids, centroid_times = voxel_centroids(raw_points, config.filter.voxel_size_m, raw_times_s)
    tree = building.result()
    seconds["voxel"] = time.perf_counter() - t
    counts = {"raw": len(raw_points), "voxels": len(centroids)}

    t = time.perf_counter()
    k = min(config.filter.normal_neighbours, len(raw_points))
    if k < 3:
        empty = np.zeros((0, 3))
        return FilteredScan(empty, empty, None, None, np.zeros(0), raw_points, tree, centroids, centroid_times,
                            {**counts, "ncf": 0, "curvature": 0}, seconds)
    idx = knn(raw_points, centroids, k, tree=tree)
    reach = config.filter.adjacent_ring_reach_m
    if reach is not None and raw_rings is not None and sensor is not None:
        idx, widened = widen_one_ring_neighbourhoods(raw_points, raw_rings, centroids, idx, sensor.rings,
                                                     sensor.columns_per_sweep, reach)
        counts["widened"] = int(widened.sum())
    hoods = raw_points.take(idx, axis=0)  # (V, k, 3): gathered once for the PCA and the NCF (take: numpy's fast gather)
    est = neighbourhood_pca(raw_points, idx, centroids, neighbourhoods=hoods)
    seconds["normals"] = time.perf_counter() - t

    t = time.perf_counter()
    keep = np.ones(len(centroids), dtype=bool)
    normal_std = np.full(len(centroids), np.nan)
    if config.ncf.enabled and config.ncf.applies_to in ("scan", "both"):
        noise = ncf_noise_model(config, sensor.range_noise_std_m if sensor is not None else None)
        keep, cov = normal_covariance_filter(
            hoods, noise,
            c_tau_rad2=math.radians(config.ncf.max_normal_std_deg) ** 2, pca=est,
            noise_free_gaps=config.ncf.noise_free_gaps,
        )
        normal_std = cov.max_std_rad
    counts["ncf"] = int(keep.sum())
    flat = curvature_keep(est.curvature, config.filter.max_curvature)
    keep &= flat
    weak = config.degeneracy
    if config.ncf.enabled and config.ncf.applies_to in ("scan", "both") and weak.min_constraint_eigenvalue > 0:
        # the NCF may not take away the last evidence of a direction of motion
        guarded = restore_constraints(centroids, est.normals, flat, keep, weak.min_constraint_eigenvalue,
                                      weak.rotation_scale_m)
        counts["restored"] = int((guarded & ~keep).sum())
        keep = guarded
    counts["curvature"] = int(keep.sum())
    seconds["ncf_curvature"] = time.perf_counter() - t

    rings = None if raw_rings is None else np.asarray(raw_rings)[est.neighbour_indices[keep, 0]]
    # (np.compress: boolean indexing of an (M, 3) array is several times slower in numpy)
    return FilteredScan(
        points=np.compress(keep, centroids, axis=0),
        normals=np.compress(keep, est.normals, axis=0),
        rings=rings,
        times_s=None if centroid_times is None else centroid_times[keep],
        normal_std_rad=normal_std[keep],
        raw_points=raw_points,
        raw_tree=tree,
        centroids=centroids,
        centroid_times_s=centroid_times,
        counts=counts,
        seconds=seconds,
    )
