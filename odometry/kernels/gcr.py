"""The geometric correspondence rejector's neighbour-beam distances (``odometry.gcr``; numpy reference:
``gcr.neighbour_beam_distances``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def neighbour_beam_distance_table(points: np.ndarray, normals: np.ndarray, pitch_below: np.ndarray,
                                  pitch_above: np.ndarray, azimuth_step_rad: float, offsets: np.ndarray,
                                  printed: bool) -> np.ndarray:
    """(M, 4) the GCR's neighbour beam distances d_kl of (M, 3) points with (M, 3) unit normals, m.

    pitch_below, pitch_above: (M,) the ring pitch to the ring below / above each point, rad (nan: none);
    offsets: (4, 2) int (vertical side, azimuth side) of each column. With r = |p|, rho = |p_xy|, the
    beam p^ = p / r, u = (-y, x, 0) / rho, v = p^ x u, L_h = rho phi, L_v = r pitch, |p_kl|^2 =
    L_h^2 + L_v^2 and p_kl . n = s_h L_h (u . n) + s_v L_v (v . n): ``printed`` False (the beam form)
    gives sqrt(|p_kl|^2 + (p_kl . n)^2 / (p^ . n)^2), True the paper's printed
    |p_kl|^2 / sqrt(|p_kl|^2 - (p_kl . n)^2); inf where the denominator is not positive, nan where
    the ring has no neighbour on that side (``odometry.gcr.neighbour_beam_distances`` is the caller).
    """
    m = points.shape[0]
    out = np.empty((m, 4))
    for i in range(m):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        r = math.sqrt(x * x + y * y + z * z)
        rho = math.hypot(x, y)
        bx, by, bz = x / r, y / r, z / r
        ux, uy = -y / rho, x / rho
        vx, vy, vz = -bz * uy, bz * ux, bx * uy - by * ux  # p^ x u, u having no z
        n_b = bx * nx + by * ny + bz * nz
        n_u = ux * nx + uy * ny
        n_v = vx * nx + vy * ny + vz * nz
        L_h = rho * azimuth_step_rad
        for col in range(4):
            s_v, s_h = offsets[col, 0], offsets[col, 1]
            L_v = r * (pitch_below[i] if s_v < 0 else pitch_above[i])
            len2 = L_h * L_h + L_v * L_v
            pn = s_h * L_h * n_u + s_v * L_v * n_v
            if printed:
                den2 = len2 - pn * pn
                d = len2 / math.sqrt(den2) if den2 > 0 else np.inf
            else:
                den = n_b * n_b
                d = math.sqrt(len2 + pn * pn / den) if den > 0 else np.inf
            out[i, col] = np.nan if math.isnan(L_v) else d
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def row_max_with_floor(table: np.ndarray, floor: float) -> np.ndarray:
    """(M,) ``numpy.nanmax(table, axis=1)`` of an (M, C) table, raised to at least ``floor`` (nan where a
    row has no number: stays nan). ``odometry.gcr.gcr_threshold_m``'s max over the neighbour beams."""
    out = np.empty(table.shape[0])
    for i in range(table.shape[0]):
        best = np.nan
        for c in range(table.shape[1]):
            v = table[i, c]
            if not math.isnan(v) and (math.isnan(best) or v > best):
                best = v
        out[i] = floor if best < floor else best  # (a nan compares false: it stays nan)
    return out
