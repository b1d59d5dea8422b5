"""The rejector study's map target: earlier scans in the odometry's local map, and the truth of each map point.

The map is built with the odometry's own code (``odometry.targets.new_local_map``
and ``map_points``, ``LocalMap.update``, ``LocalMap.target``): scans filtered as
the odometry filters them for a map target, their voxel centroids inserted
oldest first, each with the sensor position it was seen from, into 1 m voxels
of at most 20 points (the config's). Two differences from the odometry, both
deliberate: the scans are placed at their TRUE poses (the study measures the
rejectors, not the drift of the poses the map was built from), and the map holds
the ``frames`` scans before the source only (the odometry's holds every earlier
scan still within range; a voxel fills within two or three scans, so the near
map is about the same).

Frame: the world (the sequence's first sweep-start frame), as in the odometry,
which registers a scan against its map from ``T_world_previous @ T_guess`` with
``T_target_previous = T_world_previous``.

Truth: each map point is a voxel centroid of one earlier scan, so it takes the
truth of the raw return nearest to it in that scan (``truth.truth_of_points``,
as the filtered target's points do), moved into the world by that scan's true
pose. Which scan and which centroid a map point is travels with it as the
map's payload (``LocalMap.update(..., payload=)``): a row into the
concatenated truth of the inserted scans, through the voxel caps and the
pruning.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .truth import PointTruth, concatenate_truth


@dataclass(frozen=True)
class MapFrame:
    """One earlier scan as the map takes it.

    scan: ``odometry.filters.FilteredScan`` (its ``centroids`` (V, 3), sweep-start frame, m, join the map).
    truth: ``PointTruth`` of those V centroids, in the scan's own frame.
    T_world_scan: (4, 4) the scan's true pose in the world.
    """

    scan: object
    truth: PointTruth
    T_world_scan: np.ndarray


@dataclass
class MapTarget:
    """The map as a registration target, with the truth of its points.

    target: ``odometry.icp.Target`` over the map's (P, 3) world points (normals on demand).
    truth: ``PointTruth`` of those P points, world frame.
    local_map: the ``odometry.local_map.LocalMap`` behind it. frames: scans inserted.
    """

    target: object
    truth: PointTruth
    local_map: object
    frames: int


def build_map_target(frames: Sequence[MapFrame], config, sensor) -> MapTarget:
    """Insert ``frames`` (oldest first) into a new local map of ``config``'s and return it as a target.

    Args:
        frames: at least one ``MapFrame``.
        config: an ``OdometryConfig`` with ``match.target: map`` (its map parameters, and the
            map NCF when ``ncf.applies_to`` is map or both).
        sensor: ``simlidar.sensor.LidarModel`` (the map's range noise).
    """
    from odometry.targets import map_points, new_local_map

    if not frames:
        raise ValueError("a map target needs at least one earlier scan")
    local_map = new_local_map(config, sensor)
    parts, offset = [], 0
    for f in frames:
        points = map_points(f.scan, f.T_world_scan)
        if len(f.truth) != len(points):
            raise ValueError(f"a map frame's truth has {len(f.truth)} rows for {len(points)} centroids")
        local_map.update(points, f.T_world_scan[:3, 3], payload=offset + np.arange(len(points)))
        parts.append(f.truth.transformed(f.T_world_scan))
        offset += len(points)
    truth = concatenate_truth(parts).take(local_map.payload)
    return MapTarget(local_map.target(), truth, local_map, len(frames))
