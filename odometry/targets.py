"""What a registration matches: its source (the scan) and its target (the previous scan or the local map).

The source is a scan's filtered points with their normals, poles and GCR thresholds
(``make_source``). The target is the previous scan's filtered points and their own normals
(Alg. 1, ``filtered_scan_target``), or the local map of recent scans (``new_local_map``,
``map_points``: what a scan adds to it). ``raw_scan_target`` (every raw point, normals where
matched) is no registration's target; the rejector study compares it with the two that are.
"""

from __future__ import annotations

import math

import numpy as np

from simlidar import se3
from simlidar.sensor import LidarModel

from .config import OdometryConfig
from .filters import FilteredScan
from .gcr import gcr_threshold_m, ring_of_points
from .icp import Source, Target
from .kdtree import KDTree
from .local_map import LocalMap
from .normals import estimate_normals


def make_source(scan: FilteredScan, config: OdometryConfig, sensor: LidarModel | None, with_gcr: bool) -> Source:
    """The registration's source: the filtered points and normals (and poles), with GCR thresholds when used.

    The GCR's neighbour beam distances need the surface's normal at each point. Scans
    registered against a map have no normals of their own (``filters.scan_normals_needed``):
    the thresholds then come from the map's normal at each point's first match
    (``icp.register``), rotated into the scan's frame.

    Against a map, a true match is as far as the map's point spacing allows, not as far as
    the sensor's: near the sensor a scan samples surfaces more densely than a map of voxels
    holding at most ``map.points_per_voxel`` points (the rejector study measured true matches
    9 cm from the map at every range, where GCR's own bound is 10-12 cm within 20 m and
    rejected a third of them). The threshold is then at least the map's spacing,
    ``map.voxel_size_m / sqrt(map.points_per_voxel)``, or ``map.min_point_spacing_m`` when wider
    (``map_point_spacing_m``).
    """
    poles = None if scan.poles is None else scan.poles.points
    if not with_gcr:
        return Source(scan.points, scan.normals, poles=poles)
    rings = scan.rings if scan.rings is not None else ring_of_points(scan.points, sensor)
    floor = config.gcr.noise_floor_m
    if config.match.target == "map":
        floor = max(floor, map_point_spacing_m(config))

    def thresholds(points: np.ndarray, normals: np.ndarray, rows: np.ndarray) -> np.ndarray:
        thr = gcr_threshold_m(points, normals, rings[rows], sensor, config.gcr.formula, floor)
        thr[np.isnan(thr)] = np.inf  # no neighbour beam (or no normal) to bound the match: keep it
        return thr

    if np.isnan(scan.normals[:1]).any():
        return Source(scan.points, scan.normals, None, thresholds, poles)
    return Source(scan.points, scan.normals, thresholds(scan.points, scan.normals, np.arange(len(scan.points))),
                  poles=poles)


def map_point_spacing_m(config: OdometryConfig) -> float:
    """The spacing of a full map voxel's points on a surface through it, m: ``v / sqrt(n)``, or the
    map's least point spacing when that is wider."""
    return max(config.map.voxel_size_m / math.sqrt(config.map.points_per_voxel), config.map.min_point_spacing_m)


def filtered_scan_target(scan: FilteredScan, tree: KDTree | None = None) -> Target:
    """A scan's filtered points and their own normals as a target (its own frame): Alg. 1's target.

    tree: a k-d tree over ``scan.points`` built already (else one is built here)."""
    return Target(scan.points, KDTree(scan.points) if tree is None else tree, scan.normals)


def raw_scan_target(scan: FilteredScan, normal_neighbours: int) -> Target:
    """Every de-skewed raw point of a filtered scan, with normals estimated where matched (its own frame)."""
    raw = scan.raw_points
    tree = scan.raw_tree if scan.raw_tree is not None else KDTree(raw)

    def normals_of(rows: np.ndarray) -> tuple[np.ndarray, None]:
        return estimate_normals(raw, k=normal_neighbours, query_points=raw[rows], tree=tree).normals, None

    return Target(raw, tree, np.full(raw.shape, np.nan), normals_of)


def new_local_map(config: OdometryConfig, sensor: LidarModel | None) -> LocalMap:
    """An empty local map with the config's parameters (noise: the sensor's range sigma, else 2 cm)."""
    noise = config.ncf.range_noise_std_m or (sensor.range_noise_std_m if sensor is not None else None) or 0.02
    c_tau = (math.radians(config.ncf.max_normal_std_deg) ** 2
             if config.ncf.enabled and config.ncf.applies_to in ("map", "both") else None)
    return LocalMap(config.map.voxel_size_m, config.map.points_per_voxel,
                    config.map.max_distance_m or config.clean.max_range_m, config.filter.normal_neighbours, noise,
                    config.filter.max_curvature, c_tau, min_spacing_m=config.map.min_point_spacing_m)


def map_points(scan: FilteredScan, T_world_lidar: np.ndarray) -> np.ndarray:
    """(V, 3) the scan's voxel centroids in the world frame: what it adds to the map."""
    return se3.transform_points(T_world_lidar, scan.centroids)
