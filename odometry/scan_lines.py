"""Neighbourhoods across scan lines: a normal of a spinning lidar's scan needs two of them.

A spinning lidar samples a surface along its rings: densely along a ring (an
azimuth step of 0.1-0.4 deg), sparsely across them (a ring pitch of 0.3-2 deg).
On the ground a few metres out, the k nearest raw points of a return are then
all points of its own ring: they lie on that ring's cone, their best plane
contains the beams, and its normal is perpendicular to the beams, not to the
ground (tilted by up to the beam's depression). A pitch or a climb of the
sensor moves ground returns along their own beams, which such a normal cannot
see, so scan-to-scan registration turns the tilt into a pitch bias every frame
(vertical drift); the sensor-aware NCF, seeing that the noise alone could
explain the neighbourhood's second axis, rejects those normals instead, and
the ground no longer constrains the height.

``widen_one_ring_neighbourhoods`` gives such a neighbourhood a second scan
line: its farther half is replaced by the points of the nearer adjacent ring
closest in azimuth, found in a range image of the raw scan (a cell per ring
and azimuth column), when they lie within a given distance of the query
point. Two lines a gap apart span the plane between them, and the NCF's
covariance of that normal (noise along each point's beam) is then small where
the plane is well determined. Neighbourhoods that already hold two rings keep
their k nearest neighbours (the paper's kNN).
"""

from __future__ import annotations

import numpy as np

from .kernels.range_image import adjacent_ring_neighbourhoods, fill_range_image


def azimuth_columns(points: np.ndarray, n_columns: int) -> np.ndarray:
    """(N,) int column in [0, n_columns) of each (N, 3) point's azimuth ``atan2(y, x)`` (sensor frame)."""
    az = np.arctan2(points[:, 1], points[:, 0])
    return np.floor((az + np.pi) * (n_columns / (2.0 * np.pi))).astype(np.int64) % n_columns


def range_image(rings: np.ndarray, points: np.ndarray, n_rings: int, n_columns: int) -> np.ndarray:
    """(n_rings, n_columns) int: the row of a raw point in each (ring, azimuth column) cell, -1 where none.

    rings: (N,) int in [0, n_rings), ring 0 the lowest; points: (N, 3) as measured, sensor frame, m.
    Two points in one cell (a column finer than the sensor's, or laser azimuth offsets): one is kept.
    """
    rings = np.asarray(rings, dtype=np.int64)
    if len(rings) and (rings.min() < 0 or rings.max() >= n_rings):
        raise ValueError(f"ring {int(rings.max()) if rings.max() >= n_rings else int(rings.min())} is not "
                         f"one of the sensor's {n_rings} rings")
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.shape != (len(rings), 3):
        raise ValueError(f"need ({len(rings)}, 3) points, one per ring, got {points.shape}")
    return fill_range_image(rings, points, int(n_rings), int(n_columns))  # (one compiled pass, atan2 per point)


def widen_one_ring_neighbourhoods(
    cloud: np.ndarray,
    rings: np.ndarray,
    query_points: np.ndarray,
    neighbour_indices: np.ndarray,
    n_rings: int,
    n_columns: int,
    max_distance_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """kNN neighbourhoods that hold one ring only: the farther half replaced by the nearer adjacent ring's points.

    Args:
        cloud: (N, 3) the raw scan as measured (sensor frame: azimuths are taken about its z axis), m.
        rings: (N,) int ring of each raw point, 0 the lowest.
        query_points: (M, 3) the points the neighbourhoods belong to (e.g. voxel centroids), m.
        neighbour_indices: (M, k) rows of ``cloud``, nearest first (``normals.knn``).
        n_rings, n_columns: the range image's size: the sensor's rings and azimuth columns per sweep.
        max_distance_m: the adjacent ring's points must all lie this close to the query point, m.

    Returns:
        (M, k) neighbour rows (a copy; the k - k // 2 nearest of a widened neighbourhood stay, its last
        k // 2 are the adjacent ring's points nearest in azimuth), and (M,) bool: which were widened.
    """
    idx = np.ascontiguousarray(neighbour_indices, dtype=np.intp)
    rings = np.ascontiguousarray(rings, dtype=np.int64)  # a driver's uint16 rings would wrap at ring - 1
    image = range_image(rings, cloud, n_rings, n_columns)
    # (one compiled pass over the neighbourhoods: ``kernels.range_image.adjacent_ring_neighbourhoods`` has the rule)
    return adjacent_ring_neighbourhoods(np.ascontiguousarray(cloud, dtype=np.float64), rings, image,
                                        np.ascontiguousarray(query_points, dtype=np.float64), idx,
                                        float(max_distance_m))
