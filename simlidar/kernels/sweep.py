"""The sweep's per-return passes: the plane solve after Embree, the measured ranges, the scan's rows.

``solve_hits`` is ``simlidar.raycast.Raycaster.cast_compact``'s float64 distance, ``measure_block``
the range noise, range window and dropouts of ``simlidar.sweep.SweepSimulator._cast_block``,
``fill_rows`` the rows ``SweepSimulator._fill_block`` writes into the scan. Their numpy
references (``tests/test_sim_kernels.py`` compares them bit for bit) are written out in each
docstring; the dot products round as numpy's did (see ``simlidar.kernels``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .fma import fma

# The rows of a block rotated into the scan frame as numpy's batches of 32 did (BLAS's fused
# multiply-adds); the remainder as einsum's plain sum.
BATCH_ROWS = 32


@njit(cache=True, nogil=True, error_model="numpy")
def solve_hits(prim: np.ndarray, origins: np.ndarray, directions: np.ndarray, face_normal: np.ndarray,
               face_offset: np.ndarray):
    """The rays that hit, and where: the float64 distance to the hit triangle's plane.

    prim: (n,) Embree's triangle per ray (-1: a miss). origins, directions: (n, 3) float64 in the
    BVH's frame. face_normal: (F, 3) unit normals; face_offset: (F,) ``n . v0``.
    Returns ray (m,) int64, face (m,) int64, distance (m,), denom (m,) ``d . n`` and grazing (m,)
    bool (``|d . n| < 1e-9``: the distance there is ``num / 1``, for the caller to ask Embree's).
    numpy: ``ray = flatnonzero(prim >= 0)``, ``denom = einsum("ij,ij->i", d[ray], n[face])``,
    ``t = (offset[face] - einsum("ij,ij->i", o[ray], n[face])) / where(grazing, 1, denom)``.
    """
    n = prim.shape[0]
    m = 0
    for i in range(n):
        if prim[i] >= 0:
            m += 1
    ray = np.empty(m, np.int64)
    face = np.empty(m, np.int64)
    t = np.empty(m)
    denom = np.empty(m)
    grazing = np.zeros(m, np.bool_)
    j = 0
    for i in range(n):
        f = prim[i]
        if f < 0:
            continue
        nx, ny, nz = face_normal[f, 0], face_normal[f, 1], face_normal[f, 2]
        den = (directions[i, 0] * nx + directions[i, 2] * nz) + directions[i, 1] * ny
        on = (origins[i, 0] * nx + origins[i, 2] * nz) + origins[i, 1] * ny
        num = face_offset[f] - on
        ray[j] = i
        face[j] = f
        denom[j] = den
        if abs(den) < 1e-9:
            grazing[j] = True
            t[j] = num
        else:
            t[j] = num / den
        j += 1
    return ray, face, t, denom, grazing


@njit(cache=True, nogil=True, error_model="numpy")
def measure_block(ray: np.ndarray, echo: np.ndarray, cos_incidence: np.ndarray, ring_of_ray: np.ndarray,
                  ring_bias: np.ndarray, z: np.ndarray, sigma0: float, max_factor: float, min_range: float,
                  max_range: float, dropout_u: np.ndarray, dropout_p: float):
    """The measured range of each hit and the hits kept.

    ray: (m,) ray within the block; echo: (m,) range before noise, m; cos_incidence: (m,);
    ring_of_ray: (B,) ring of each ray of the block; ring_bias: (R,) m; z: (m,) standard normal
    draws; dropout_u: (m,) uniform draws (read when ``dropout_p`` > 0).
    Returns ring (m,) int64, measured (m,) and keep (k,) int64, the kept rows in order.
    numpy: ``sigma = sigma0 * minimum(1 / maximum(|cos|, 1e-12), max_factor)`` (when max_factor > 1),
    ``measured = echo + ring_bias[ring] + z * sigma``, kept where ``min_range <= measured <= max_range``
    and ``u >= dropout_p``.
    """
    m = ray.shape[0]
    ring = np.empty(m, np.int64)
    measured = np.empty(m)
    keep = np.empty(m, np.int64)
    k = 0
    for i in range(m):
        r = ring_of_ray[ray[i]]
        ring[i] = r
        sigma = sigma0
        if max_factor > 1.0:
            c = abs(cos_incidence[i])
            sigma = sigma0 * min(1.0 / max(c, 1e-12), max_factor)
        v = (echo[i] + ring_bias[r]) + z[i] * sigma
        measured[i] = v
        ok = v >= min_range and v <= max_range
        if dropout_p > 0.0:
            ok = ok and dropout_u[i] >= dropout_p
        if ok:
            keep[k] = i
            k += 1
    return ring, measured, keep[:k]


@njit(cache=True, nogil=True, inline="always")
def _rotate_row(x0: float, x1: float, x2: float, M: np.ndarray, out: np.ndarray, row: int, fused: bool) -> None:
    """out[row] = (x0, x1, x2) @ M, rounded as numpy's batched matmul (fused) or einsum (plain)."""
    for c in range(3):
        if fused:
            out[row, c] = fma(x2, M[2, c], fma(x1, M[1, c], x0 * M[0, c]))
        else:
            out[row, c] = (x0 * M[0, c] + x1 * M[1, c]) + x2 * M[2, c]


@njit(cache=True, nogil=True, error_model="numpy")
def fill_rows(off: int, first_ray: int, ray: np.ndarray, face: np.ndarray, distance: np.ndarray,
              cos_incidence: np.ndarray, measured: np.ndarray, ring: np.ndarray, dir_local: np.ndarray,
              origin_bvh: np.ndarray, direction_bvh: np.ndarray, t_ref: np.ndarray, R_ref: np.ndarray,
              face_normals: np.ndarray, face_object_id: np.ndarray, reflectance: np.ndarray, cosk_pow: np.ndarray,
              range_ref: float, ray_column: np.ndarray, ray_time: np.ndarray, row_actor: np.ndarray,
              row_normal: np.ndarray, first_actor_object: int,
              xyz: np.ndarray, intensity: np.ndarray, ring_out: np.ndarray, azimuth_out: np.ndarray,
              time_out: np.ndarray, range_out: np.ndarray, true_range_out: np.ndarray, true_xyz: np.ndarray,
              normal: np.ndarray, object_out: np.ndarray) -> None:
    """Write a block's m returns into rows off:off+m of a scan's arrays.

    ray, face, distance, cos_incidence, measured, ring: (m,) the block's kept returns (``ray`` within
    the block, ``face`` the triangle, ``distance`` the true range, m). dir_local, origin_bvh,
    direction_bvh: (B, 3) the block's beams in the sensor frame and rays in the BVH's frame.
    t_ref (3,), R_ref (3, 3): the reference pose (its translation in the BVH's frame).
    cosk_pow: (m,) ``|cos|^k`` when the intensity's exponent k is not 1, else empty (|cos| is used).
    row_actor: (m,) the moving object a row hit (``simlidar.actors``; -1: the static world), or empty;
    an actor's row takes its normal from row_normal (k, 3) (outward, in the world; a row per actor row,
    in order) and its object id ``first_actor_object + row_actor``.
    numpy: ``xyz = measured * dir_local[ray]``; ``true_xyz = (d_bvh[ray] * distance + o_bvh[ray] - t_ref)
    @ R_ref``; ``normal = (face_normals[face] @ R_ref) * -sign(cos)``; ``object = face_object_id[face]``;
    ``intensity = reflectance[object] * cosk * minimum(1, (range_ref / maximum(measured, 1e-6))^2)``;
    ring, azimuth (``ray_column``), time (``ray_time``) of ray ``first_ray + ray``. The products with
    ``R_ref`` round as numpy's batches of 32 rows did (``BATCH_ROWS``; the block's remainder plain).
    """
    m = ray.shape[0]
    fused_rows = m - m % BATCH_ROWS
    use_pow = cosk_pow.shape[0] == m and m > 0
    actors = row_actor.shape[0] == m and m > 0
    slot = 0
    for i in range(m):
        o = off + i
        b = ray[i]
        g = first_ray + b
        v = measured[i]
        xyz[o, 0] = v * dir_local[b, 0]
        xyz[o, 1] = v * dir_local[b, 1]
        xyz[o, 2] = v * dir_local[b, 2]
        t = distance[i]
        h0 = (direction_bvh[b, 0] * t + origin_bvh[b, 0]) - t_ref[0]
        h1 = (direction_bvh[b, 1] * t + origin_bvh[b, 1]) - t_ref[1]
        h2 = (direction_bvh[b, 2] * t + origin_bvh[b, 2]) - t_ref[2]
        fused = i < fused_rows
        _rotate_row(h0, h1, h2, R_ref, true_xyz, o, fused)
        f = face[i]
        if actors and row_actor[i] >= 0:
            _rotate_row(row_normal[slot, 0], row_normal[slot, 1], row_normal[slot, 2], R_ref, normal, o, fused)
            obj = first_actor_object + row_actor[i]
            slot += 1
        else:
            _rotate_row(face_normals[f, 0], face_normals[f, 1], face_normals[f, 2], R_ref, normal, o, fused)
            obj = face_object_id[f]
        c = cos_incidence[i]
        s = -np.sign(c)
        normal[o, 0] *= s
        normal[o, 1] *= s
        normal[o, 2] *= s
        object_out[o] = obj
        ck = cosk_pow[i] if use_pow else abs(c)
        q = v if v > 1e-6 or v != v else 1e-6
        r = range_ref / q
        fall = r * r
        fall = fall if fall < 1.0 or fall != fall else 1.0
        intensity[o] = (reflectance[obj] * ck) * fall
        ring_out[o] = ring[i]
        azimuth_out[o] = ray_column[g]
        time_out[o] = ray_time[g]
        range_out[o] = v
        true_range_out[o] = t


@njit(cache=True, nogil=True)
def fill_actor_rows(off: int, m: int, row_actor: np.ndarray, class_code: np.ndarray, velocity: np.ndarray,
                    fast: np.ndarray, object_class: np.ndarray, moving: np.ndarray, velocity_out: np.ndarray) -> None:
    """The moving objects' truth of a block's m rows off:off+m of a scan: class, moving, velocity.

    row_actor: (m,) the actor each row hit (-1: the static world), or empty (none did); class_code (A,) uint8;
    velocity (k, 3), fast (k,): per actor row in order, its velocity in the scan frame (m/s) and whether it
    moves. numpy: rows of the static world 0, False, 0; an actor's ``class_code[actor]``, ``fast``, ``velocity``.
    """
    actors = row_actor.shape[0] == m
    slot = 0
    for i in range(m):
        o = off + i
        if actors and row_actor[i] >= 0:
            object_class[o] = class_code[row_actor[i]]
            moving[o] = fast[slot]
            velocity_out[o, 0], velocity_out[o, 1], velocity_out[o, 2] = (velocity[slot, 0], velocity[slot, 1],
                                                                          velocity[slot, 2])
            slot += 1
        else:
            object_class[o] = 0
            moving[o] = False
            velocity_out[o, 0] = velocity_out[o, 1] = velocity_out[o, 2] = 0.0


__all__ = ["BATCH_ROWS", "block_rays", "fill_actor_rows", "fill_rows", "measure_block", "solve_hits"]


@njit(cache=True, nogil=True)
def block_rays(dir_local: np.ndarray, R: np.ndarray, t: np.ndarray, pose_of_ray: np.ndarray, rings: int,
               offset: np.ndarray):
    """A block's rays in the BVH's frame (the world shifted by ``-offset``), float64 and Embree's float32.

    dir_local: (B, 3) unit beams in the sensor frame. R: (P, 3, 3), t: (P, 3) the sensor's poses in
    the world. pose_of_ray: (B,) the pose each ray fires from, or empty: ray i fires from pose
    ``i // rings`` (a column fires at once). Returns origin, direction (B, 3) float64 and their float32
    copies. numpy: per column ``matmul(dir_local.reshape(C, rings, 3), R.transpose(0, 2, 1))`` (fused
    multiply-adds, as BLAS rounds), per ray ``einsum("nij,nj->ni", R[pose], dir_local)``;
    ``origin = t[pose] - offset``.
    """
    n = dir_local.shape[0]
    per_column = pose_of_ray.shape[0] == 0
    o = np.empty((n, 3))
    d = np.empty((n, 3))
    o32 = np.empty((n, 3), np.float32)
    d32 = np.empty((n, 3), np.float32)
    for i in range(n):
        p = i // rings if per_column else pose_of_ray[i]
        x0, x1, x2 = dir_local[i, 0], dir_local[i, 1], dir_local[i, 2]
        for k in range(3):
            if per_column:
                v = fma(x2, R[p, k, 2], fma(x1, R[p, k, 1], x0 * R[p, k, 0]))
            else:
                v = (R[p, k, 0] * x0 + R[p, k, 2] * x2) + R[p, k, 1] * x1
            d[i, k] = v
            d32[i, k] = v
            w = t[p, k] - offset[k]
            o[i, k] = w
            o32[i, k] = w
    return o, d, o32, d32
