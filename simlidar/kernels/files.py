"""A frame's files in one pass each: the scan's float32 records, the truth's sections and octahedral normal codes
(``simlidar.formats.salo``, ``simlidar.formats.truth``)."""

from __future__ import annotations

import numpy as np
from numba import njit

_ONE = np.float32(1.0)
_TINY = np.float32(1e-30)
_SCALE = np.float32(32767.0)


@njit(cache=True, nogil=True, inline="always")
def _code(x: np.float32, y: np.float32, z: np.float32):
    l1 = max((abs(x) + abs(y)) + abs(z), _TINY)
    px, py = x / l1, y / l1
    if z < 0:
        sx = _ONE if px >= 0 else -_ONE
        sy = _ONE if py >= 0 else -_ONE
        px, py = (_ONE - abs(py)) * sx, (_ONE - abs(px)) * sy
    px, py = px * _SCALE, py * _SCALE
    px = min(max(px, -_SCALE), _SCALE)
    py = min(max(py, -_SCALE), _SCALE)
    return np.int16(np.rint(px)), np.int16(np.rint(py))


@njit(cache=True, nogil=True)
def octahedral_codes(normal: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors -> (N, 2) int16 octahedral codes, scale 32767, rounded half to even.

    numpy (``simlidar.formats.truth.octahedral_encode``, in float32): ``p = (x, y) / (|x| + |y| + |z|)``;
    below the equator (z < 0) ``p = ((1 - |py|) sgn px, (1 - |px|) sgn py)`` with sgn 0 = +1;
    ``rint(clip(32767 p, -32767, 32767))``.
    """
    n = normal.shape[0]
    out = np.empty((n, 2), np.int16)
    for i in range(n):
        out[i, 0], out[i, 1] = _code(np.float32(normal[i, 0]), np.float32(normal[i, 1]), np.float32(normal[i, 2]))
    return out


@njit(cache=True, nogil=True)
def fill_body(ray: np.ndarray, true_range: np.ndarray, normal: np.ndarray, object_id: np.ndarray, bare_zero: bool,
              ray_out: np.ndarray, range_out: np.ndarray, codes_out: np.ndarray, ids_out: np.ndarray) -> None:
    """A truth file's per-return sections, written into their (N,) views: the firing index (u4), the true
    range (f4), the octahedral normal (2 N i2; skipped when ``normal`` is empty) and the object id.

    bare_zero: a return whose true range is NaN (a weather echo without a surface) gets normal code
    and object id 0. numpy: ``ray.astype("<u4")``, ``true_range.astype("<f4")``, ``octahedral_encode``,
    ``object_id.astype(ids_out.dtype)``.
    """
    n = ray.shape[0]
    codes = normal.shape[0] == n
    for i in range(n):
        ray_out[i] = ray[i]
        r = true_range[i]
        range_out[i] = r
        if bare_zero and r != r:
            ids_out[i] = 0
            if codes:
                codes_out[2 * i] = 0
                codes_out[2 * i + 1] = 0
            continue
        ids_out[i] = object_id[i]
        if codes:
            codes_out[2 * i], codes_out[2 * i + 1] = _code(np.float32(normal[i, 0]), np.float32(normal[i, 1]),
                                                          np.float32(normal[i, 2]))


@njit(cache=True, nogil=True)
def pack_points(xyz: np.ndarray, intensity: np.ndarray, out: np.ndarray) -> None:
    """The KITTI ``.bin`` records: ``out[:, :3] = xyz``, ``out[:, 3] = intensity`` ((N, 4) float32; numpy's casts)."""
    for i in range(xyz.shape[0]):
        out[i, 0] = xyz[i, 0]
        out[i, 1] = xyz[i, 1]
        out[i, 2] = xyz[i, 2]
        out[i, 3] = intensity[i]


__all__ = ["fill_body", "octahedral_codes", "pack_points"]
