"""Cubic voxel grids aligned to the frame's origin: keys, centroids, one point per voxel.

A voxel's key packs its three integer indices into one int64 (``_KEY_BITS`` bits per
axis), so that sorting keys sorts voxels by x, then y, then z index, and a grid needs
no bounding box: the scan's voxel grid (``odometry.filters``) and the local map
(``odometry.local_map``) share it.
"""

from __future__ import annotations

import numpy as np

from .kernels.voxel_hash import group_keys, packed_voxel_keys, voxel_sums

_KEY_BITS = 21  # voxel index bits per axis: +-2^20 voxels
_KEY_OFFSET = 1 << (_KEY_BITS - 1)
_KEY_MASK = (1 << _KEY_BITS) - 1


def voxel_keys(points: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """(N, 3) points -> (N,) int64 key of the cubic voxel holding each point."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"need (N, 3) points, got {points.shape}")
    keys, inside = packed_voxel_keys(points, float(voxel_size_m), _KEY_BITS)
    if not inside:
        raise ValueError(f"points beyond +-{_KEY_OFFSET * voxel_size_m:.3g} m (or not finite) cannot be put in a "
                         f"voxel grid of {voxel_size_m:g} m")
    return keys


def neighbour_key_steps() -> np.ndarray:
    """(27,) int64 differences between a voxel's key and the keys of itself and its 26 neighbours."""
    d = np.array([-1, 0, 1], dtype=np.int64)
    di, dj, dk = np.meshgrid(d, d, d, indexing="ij")
    return ((di << (2 * _KEY_BITS)) + (dj << _KEY_BITS) + dk).ravel()


def voxel_centres(keys: np.ndarray, voxel_size_m: float) -> np.ndarray:
    """(K,) voxel keys -> (K, 3) centres of the voxels, m."""
    ijk = np.stack([(keys >> (2 * _KEY_BITS)) & _KEY_MASK, (keys >> _KEY_BITS) & _KEY_MASK, keys & _KEY_MASK], axis=1)
    return (ijk - _KEY_OFFSET + 0.5) * voxel_size_m


def voxel_centroids(points: np.ndarray, voxel_size_m: float, values: np.ndarray | None = None):
    """(N, 3) points -> (M, 3) centroids of the points in each occupied cubic voxel.

    The output is ordered by voxel key (by x, then y, then z index: deterministic).
    With ``values`` (N,), also returns their (M,) mean per voxel (e.g. the firing time
    of each centroid).
    """
    if len(points) == 0:
        return np.zeros((0, 3)) if values is None else (np.zeros((0, 3)), np.zeros(0))
    points = np.ascontiguousarray(points, dtype=np.float64)
    keys = voxel_keys(points, voxel_size_m)
    voxels, slot = group_keys(keys)
    v = np.zeros(0) if values is None else np.ascontiguousarray(values, dtype=np.float64)
    if values is not None and v.shape != (len(points),):
        raise ValueError(f"need one value per point ({len(points)},), got {v.shape}")
    sums, value_sums, counts = voxel_sums(slot, len(voxels), points, v)
    if values is None:
        return sums / counts[:, None]
    return sums / counts[:, None], value_sums / counts
