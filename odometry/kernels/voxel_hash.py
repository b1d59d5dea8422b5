"""Voxel keys and hashing: packed keys, per-voxel sums, distinct keys grouped by a hash table, keys near
others (``odometry.voxels``, ``odometry.local_map``; numpy references: ``np.unique``, ``np.add.at``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def packed_voxel_keys(points: np.ndarray, voxel_size_m: float, key_bits: int) -> tuple[np.ndarray, bool]:
    """((N,) int64 keys of the cubic voxels holding (N, 3) points, all inside the grid).

    A key packs the three indices ``floor(p / voxel_size_m) + 2^(key_bits - 1)``, ``key_bits``
    bits each, x highest (``odometry.voxels.voxel_keys`` is the caller and raises when one
    falls outside: the second value is False, or a coordinate is not finite).
    """
    offset = 1 << (key_bits - 1)
    mask = (1 << key_bits) - 1
    keys = np.empty(points.shape[0], dtype=np.int64)
    inside = True
    for r in range(points.shape[0]):
        key = np.int64(0)
        for c in range(3):
            x = points[r, c] / voxel_size_m
            # (checked on the float, before it becomes an integer: also false for nan)
            if not (x >= -offset and x < mask + 1 - offset):
                inside = False
                x = 0.0
            key = (key << key_bits) | (np.int64(math.floor(x)) + offset)
        keys[r] = key
    return keys, inside


@njit(cache=True, nogil=True, error_model="numpy")
def voxel_sums(slot: np.ndarray, k: int, points: np.ndarray, values: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per voxel: (k, 3) sum of the points in it, (k,) of their values, (k,) counts.

    slot: (N,) int voxel (0 .. k - 1) of each (N, 3) point; values: (N,) or (0,).
    Sums run in row order (as ``numpy.bincount`` adds).
    """
    sums = np.zeros((k, 3))
    value_sums = np.zeros(k)
    counts = np.zeros(k, dtype=np.int64)
    with_values = values.shape[0] > 0
    for r in range(slot.shape[0]):
        v = slot[r]
        sums[v, 0] += points[r, 0]
        sums[v, 1] += points[r, 1]
        sums[v, 2] += points[r, 2]
        counts[v] += 1
        if with_values:
            value_sums[v] += values[r]
    return sums, value_sums, counts


@njit(cache=True, nogil=True, inline="always")
def _table_shift(entries: int) -> tuple[int, np.uint64]:
    """(size, shift) of an open-addressing hash table for ``entries`` keys: a power of two at least
    twice as many slots (short probe runs), and the shift that maps a 64-bit hash onto them."""
    size = 2
    while size < 2 * entries:
        size *= 2
    return size, np.uint64(64 - max(int(np.log2(size)), 1))


@njit(cache=True, nogil=True, inline="always")
def _probe(table_key: np.ndarray, table_id: np.ndarray, key: np.int64, shift: np.uint64) -> int:
    """The slot of ``key`` in an open-addressing table (Fibonacci hashing, linear probing), or the
    free slot (``table_id < 0``) where it goes."""
    mask = table_key.shape[0] - 1
    h = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> shift)
    while table_id[h] >= 0 and table_key[h] != key:
        h = (h + 1) & mask
    return h


@njit(cache=True, nogil=True, inline="always")
def _key_table(keys: np.ndarray, count: int, entries: int) -> tuple[np.ndarray, np.ndarray, np.uint64]:
    """(keys, ids, shift) of an open-addressing table with room for ``entries`` keys, holding the first
    ``count`` of the distinct int64 ``keys``, each with its position among them (``_probe`` finds them)."""
    size, shift = _table_shift(entries)
    table_key = np.empty(size, dtype=np.int64)
    table_id = np.full(size, -1, dtype=np.int64)
    for i in range(count):
        h = _probe(table_key, table_id, keys[i], shift)
        table_key[h] = keys[i]
        table_id[h] = i
    return table_key, table_id, shift


@njit(cache=True, nogil=True)
def _insert_keys(keys: np.ndarray, start: int, entries: int, table_key: np.ndarray, table_id: np.ndarray,
                 shift: np.uint64, first: np.ndarray, provisional: np.ndarray, k: int) -> tuple[int, int]:
    """``group_keys``' pass from row ``start`` until the table holds ``entries`` keys: (the row where it
    stopped (N: done), the distinct keys found)."""
    for r in range(start, keys.shape[0]):
        key = keys[r]
        h = _probe(table_key, table_id, key, shift)
        if table_id[h] < 0:
            if k == entries:
                return r, k
            table_key[h] = key
            table_id[h] = k
            first[k] = key
            k += 1
        provisional[r] = table_id[h]
    return keys.shape[0], k


@njit(cache=True, nogil=True)
def group_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((K,) the distinct keys ascending, (N,) the slot of each key among them):
    ``numpy.unique(keys, return_inverse=True)`` for (N,) int64 keys.

    The keys are grouped by a hash table in one pass and only the K distinct ones are sorted
    (a scan has several points per voxel: sorting the N keys took most of a voxel grid's time).
    """
    n = keys.shape[0]
    first = np.empty(n, dtype=np.int64)  # the distinct keys, in order of first appearance
    provisional = np.empty(n, dtype=np.int64)
    # The table starts small and doubles when half full: sized by the distinct keys, not by N, it
    # stays in the cache and its memory is reused (a table of N slots, megabytes, came fresh from
    # the system every scan: a page fault per 4 kB).
    entries = min(n, 2048)
    r = k = 0
    while r < n:
        table_key, table_id, shift = _key_table(first, k, entries)
        r, k = _insert_keys(keys, r, entries, table_key, table_id, shift, first, provisional, k)
        entries *= 2
    order = np.argsort(first[:k])
    rank = np.empty(k, dtype=np.int64)
    for i in range(k):
        rank[order[i]] = i
    slot = np.empty(n, dtype=np.int64)
    for r in range(n):
        slot[r] = rank[provisional[r]]
    return first[:k][order], slot


@njit(cache=True, nogil=True)
def keys_near(keys: np.ndarray, around: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(M,) bool: which of (M,) int64 voxel keys lie within ``steps`` of one of the (K,) keys ``around``:
    ``numpy.isin(keys, numpy.unique(around[:, None] + steps))`` (steps: (S,) key differences, e.g. a
    voxel's 27 neighbours, ``odometry.voxels.neighbour_key_steps``), by a hash set of the K x S keys."""
    size, shift = _table_shift(around.shape[0] * steps.shape[0])
    table_key = np.empty(size, dtype=np.int64)
    table_id = np.full(size, -1, dtype=np.int64)
    for a in range(around.shape[0]):
        for s in range(steps.shape[0]):
            key = around[a] + steps[s]
            h = _probe(table_key, table_id, key, shift)
            table_key[h] = key
            table_id[h] = 0
    near = np.empty(keys.shape[0], dtype=np.bool_)
    for r in range(keys.shape[0]):
        near[r] = table_id[_probe(table_key, table_id, keys[r], shift)] >= 0
    return near


@njit(cache=True, nogil=True, error_model="numpy")
def within_reach_of_any(points: np.ndarray, keys: np.ndarray, reach_m: np.ndarray, others: np.ndarray,
                        other_keys: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(M,) bool: one of the (K, 3) ``others`` lies within ``reach_m`` (M,) of each (M, 3) point, m.

    Only the others in the voxels ``keys + steps`` are looked at (keys: (M,) and other_keys: (K,) the
    int64 voxel keys of both; steps: (S,) key differences): with a voxel and its 26 neighbours, the
    answer is exact for reaches up to the voxel's edge, ``k-d tree distance to the nearest other <= reach``
    (distances as ``sqrt((dx^2 + dy^2) + dz^2)``, as the k-d tree computes them).
    """
    distinct, slot = group_keys(other_keys)
    g = distinct.shape[0]
    start = np.zeros(g + 1, dtype=np.int64)  # the others of voxel v: order[start[v]:start[v + 1]]
    for c in range(slot.shape[0]):
        start[slot[c] + 1] += 1
    for v in range(g):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(slot.shape[0], dtype=np.int64)
    for c in range(slot.shape[0]):
        order[fill[slot[c]]] = c
        fill[slot[c]] += 1
    table_key, table_id, shift = _key_table(distinct, g, g)
    found = np.zeros(points.shape[0], dtype=np.bool_)
    for i in range(points.shape[0]):
        x, y, z, r = points[i, 0], points[i, 1], points[i, 2], reach_m[i]
        for s in range(steps.shape[0]):
            v = table_id[_probe(table_key, table_id, keys[i] + steps[s], shift)]
            if v < 0:
                continue
            for j in range(start[v], start[v + 1]):
                c = order[j]
                dx, dy, dz = x - others[c, 0], y - others[c, 1], z - others[c, 2]
                if math.sqrt((dx * dx + dy * dy) + dz * dz) <= r:
                    found[i] = True
                    break
            if found[i]:
                break
    return found
