"""The moving objects' passes (``simlidar.actors``): which rays may meet each actor, and those rays in its frame.

``ray_windows`` finds, column by column, the rays whose direction passes within an actor's
bounding sphere at the column's instant (numpy: the same test on (actors, columns) arrays,
``tests/test_actors.py`` checks the result against casting every ray); ``rays_in_actor_frame``
moves each candidate ray into its actor's frame at the ray's time (the actor's pose between
knots: a cubic Hermite of positions and velocities, a constant-rate turn) and keeps those
that cross the actor's box.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def ray_windows(centre: np.ndarray, alive: np.ndarray, knot_t: np.ndarray, col_t: np.ndarray, Rc: np.ndarray,
                pc: np.ndarray, radius: np.ndarray, half_height: np.ndarray, spread: float, az_extra: float,
                col_az: np.ndarray, elevation: np.ndarray, max_range: float):
    """The rays (global firing indices, ascending) that may meet each actor.

    centre: (A, K, 3) each actor's box centre at the knots, world; alive: (A, K) it exists then; knot_t (K,),
    col_t (C,) s (equal times: a frozen, instantaneous scan); Rc (C, 3, 3), pc (C, 3): the sensor at each
    column; radius (A,): each actor's bounding sphere, grown by its motion within a column; half_height (A,):
    how far above and below its centre it reaches in any pose (the sensor's tilt included); spread: the
    beams' own spread (jitter, divergence), rad; az_extra: the lasers' azimuth offsets, rad; col_az (C,)
    the columns' azimuths; elevation (R,) the rings' elevations, ascending. Returns (counts (A,), rays).
    A ray of column c, ring r may meet actor a when the actor is alive then, its sphere within the
    maximum range, the ray's azimuth within the sphere's half-angle (plus margins) of its centre's
    direction in the sensor frame at the column's instant, and its elevation between those of the
    sphere's nearest horizontal reach at the centre's height plus and minus ``half_height``.
    """
    A, K = centre.shape[0], centre.shape[1]
    C, R = col_t.shape[0], elevation.shape[0]
    counts = np.zeros(A, np.int64)
    lo_ring = np.zeros((A, C), np.int64)
    hi_ring = np.zeros((A, C), np.int64)
    # the columns fall in runs of ``run`` whose azimuths span ``run`` steps: a run facing away from an actor
    # (its centre's azimuth at the run's ends more than the half-angle and the run's span away) is skipped whole
    run = 64
    step = abs(col_az[1] - col_az[0]) if C > 1 else 2 * math.pi
    for a in range(A):
        k = 0
        skip_to = -1
        for c in range(C):
            t = col_t[c]
            if c % run == 0 and C > run:
                c_end = min(c + run, C) - 1
                far = True
                for cc in (c, c_end):
                    kk = 0
                    while kk < K - 2 and knot_t[kk + 1] <= col_t[cc]:
                        kk += 1
                    x = centre[a, kk, 0] - pc[cc, 0]
                    y = centre[a, kk, 1] - pc[cc, 1]
                    z = centre[a, kk, 2] - pc[cc, 2]
                    rx = Rc[cc, 0, 0] * x + Rc[cc, 1, 0] * y + Rc[cc, 2, 0] * z
                    ry = Rc[cc, 0, 1] * x + Rc[cc, 1, 1] * y + Rc[cc, 2, 1] * z
                    rz = Rc[cc, 0, 2] * x + Rc[cc, 1, 2] * y + Rc[cc, 2, 2] * z
                    dist = math.sqrt(rx * rx + ry * ry + rz * rz)
                    if dist <= 2 * radius[a] + 1.0:
                        far = False
                        break
                    half = math.asin(min(2 * radius[a] / dist, 1.0)) + spread + az_extra + 0.02
                    d_az = abs((col_az[cc] - math.atan2(ry, rx) + math.pi) % (2 * math.pi) - math.pi)
                    if d_az <= half + run * step:
                        far = False
                        break
                if far:
                    skip_to = c_end
                else:
                    skip_to = -1
            if c <= skip_to:
                continue
            while k < K - 2 and knot_t[k + 1] <= t:
                k += 1
            if K > 1 and knot_t[k + 1] > knot_t[k]:
                u = min(max((t - knot_t[k]) / (knot_t[k + 1] - knot_t[k]), 0.0), 1.0)
            else:
                u = 0.0
            k1 = min(k + 1, K - 1)
            if not (alive[a, k] or alive[a, k1]):
                continue
            x = centre[a, k, 0] + (centre[a, k1, 0] - centre[a, k, 0]) * u - pc[c, 0]
            y = centre[a, k, 1] + (centre[a, k1, 1] - centre[a, k, 1]) * u - pc[c, 1]
            z = centre[a, k, 2] + (centre[a, k1, 2] - centre[a, k, 2]) * u - pc[c, 2]
            rx = Rc[c, 0, 0] * x + Rc[c, 1, 0] * y + Rc[c, 2, 0] * z
            ry = Rc[c, 0, 1] * x + Rc[c, 1, 1] * y + Rc[c, 2, 1] * z
            rz = Rc[c, 0, 2] * x + Rc[c, 1, 2] * y + Rc[c, 2, 2] * z
            dist = math.sqrt(rx * rx + ry * ry + rz * rz)
            r = radius[a]
            if dist - r > max_range:
                continue
            if dist <= r:  # the sensor inside the sphere: every ring of the column
                lo_ring[a, c], hi_ring[a, c] = 0, R
                counts[a] += R
                continue
            half = math.asin(r / dist) + spread
            d_az = abs((col_az[c] - math.atan2(ry, rx) + math.pi) % (2 * math.pi) - math.pi)
            if d_az > half + az_extra:
                continue
            near = max(math.sqrt(rx * rx + ry * ry) - r, 1e-3)  # the sphere's nearest reach across
            lo = math.atan2(rz - half_height[a], near) - spread
            hi = math.atan2(rz + half_height[a], near) + spread
            r0 = np.searchsorted(elevation, lo)
            r1 = np.searchsorted(elevation, hi, side="right")
            if r1 > r0:
                lo_ring[a, c], hi_ring[a, c] = r0, r1
                counts[a] += r1 - r0
    rays = np.empty(counts.sum(), np.int64)
    at = 0
    for a in range(A):
        for c in range(C):
            for ring in range(lo_ring[a, c], hi_ring[a, c]):
                rays[at] = c * R + ring
                at += 1
    return counts, rays


@njit(cache=True, nogil=True, error_model="numpy")
def rays_in_actor_frame(rows: np.ndarray, actor: np.ndarray, t: np.ndarray, origin: np.ndarray, offset: np.ndarray,
                        direction: np.ndarray, T: np.ndarray, vdt: np.ndarray, turn: np.ndarray, t0: float,
                        dt: float, box_lo: np.ndarray, box_hi: np.ndarray, max_distance: float,
                        nearer_ray: np.ndarray, nearer_distance: np.ndarray, shift: np.ndarray):
    """The candidate rays that cross their actor's box, in the actor's frame at each ray's time.

    rows (n,): the call's rays, actor (n,): the actor (of this sweep's) each may meet, t (n,): its time;
    origin + offset (3,), direction: (B, 3) the call's rays in the world, indexed by ``rows``; T (A, K, 4, 4)
    the actors'
    poses at knots t0 + k dt (dt 0: frozen at the first), vdt (A, K, 3) their velocities times dt, turn
    (A, K - 1, 3) the rotation vector from knot k to k + 1 in knot k's frame; box_lo, box_hi (A, 3) the box
    (with a margin) in the actor's frame. nearer_ray (h,), nearer_distance (h,): a hit each of these
    rays already has (the static world's); a ray whose hit lies before it enters the box is not kept, as no
    hit of the actor, at least the margin farther, could be the nearer (both may be empty). shift (A, 3): added to
    the kept rays' origins (where each actor's model lies in the BVH they are cast against). Returns keep (m,)
    indices into rows, o (m, 3) (shifted), d (m, 3) in the actor's frame, R (m, 3, 3) and p (m, 3) the actor's
    pose at the ray's time.
    """
    n = rows.shape[0]
    keep = np.empty(n, np.int64)
    o_out = np.empty((n, 3))
    d_out = np.empty((n, 3))
    R_out = np.empty((n, 3, 3))
    p_out = np.empty((n, 3))
    Ru = np.empty((3, 3))
    Rm = np.empty((3, 3))
    last_a, last_t = -1, np.nan
    px = py = pz = 0.0
    m = 0
    reach = np.full(origin.shape[0], max_distance)  # per ray of the call, how far a hit may lie to be the nearer
    for h in range(nearer_ray.shape[0]):
        reach[nearer_ray[h]] = min(reach[nearer_ray[h]], nearer_distance[h])
    for i in range(n):
        a = actor[i]
        b = rows[i]
        if a == last_a and t[i] == last_t:  # the same actor at the same instant (a column's rays): the same pose
            pass
        else:
            last_a, last_t = a, t[i]
            px, py, pz = _pose(a, t[i], T, vdt, turn, t0, dt, Ru, Rm)
        for r in range(3):
            for c in range(3):
                R_out[m, r, c] = Rm[r, c]
        # the ray in the actor's frame: R^T (o - p), R^T d
        qx, qy, qz = origin[b, 0] + offset[0] - px, origin[b, 1] + offset[1] - py, origin[b, 2] + offset[2] - pz
        ok = True
        t_in, t_out = 0.0, max_distance
        if reach[b] < t_out:
            t_out = reach[b]
        for c in range(3):
            oc = R_out[m, 0, c] * qx + R_out[m, 1, c] * qy + R_out[m, 2, c] * qz
            dc = R_out[m, 0, c] * direction[b, 0] + R_out[m, 1, c] * direction[b, 1] + R_out[m, 2, c] * direction[b, 2]
            o_out[m, c], d_out[m, c] = oc, dc
            if abs(dc) < 1e-15:
                if oc < box_lo[a, c] or oc > box_hi[a, c]:
                    ok = False
            else:
                s0, s1 = (box_lo[a, c] - oc) / dc, (box_hi[a, c] - oc) / dc
                if s0 > s1:
                    s0, s1 = s1, s0
                t_in, t_out = max(t_in, s0), min(t_out, s1)
        if ok and t_in <= t_out:
            for c in range(3):
                o_out[m, c] += shift[a, c]
            p_out[m, 0], p_out[m, 1], p_out[m, 2] = px, py, pz
            keep[m] = i
            m += 1
    return keep[:m], o_out[:m], d_out[:m], R_out[:m], p_out[:m]


@njit(cache=True, nogil=True, inline="always")
def _pose(a: int, t: float, T: np.ndarray, vdt: np.ndarray, turn: np.ndarray, t0: float, dt: float, Ru: np.ndarray,
          Rm: np.ndarray):
    """Actor ``a``'s pose at ``t`` between its knots: the rotation written into ``Rm`` (``Ru`` scratch), the
    position returned: a cubic Hermite of the knots' positions and velocities, a constant-rate turn."""
    K = T.shape[1]
    if dt > 0:
        x = min(max((t - t0) / dt, 0.0), K - 1 - 1e-12)
        k = int(x)
        u = x - k
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
        wx, wy, wz = turn[a, k, 0] * u, turn[a, k, 1] * u, turn[a, k, 2] * u
    else:
        k = 0
        h00, h10, h01, h11 = 1.0, 0.0, 0.0, 0.0
        wx, wy, wz = 0.0, 0.0, 0.0
    k1 = min(k + 1, K - 1)
    px = h00 * T[a, k, 0, 3] + h10 * vdt[a, k, 0] + h01 * T[a, k1, 0, 3] + h11 * vdt[a, k1, 0]
    py = h00 * T[a, k, 1, 3] + h10 * vdt[a, k, 1] + h01 * T[a, k1, 1, 3] + h11 * vdt[a, k1, 1]
    pz = h00 * T[a, k, 2, 3] + h10 * vdt[a, k, 2] + h01 * T[a, k1, 2, 3] + h11 * vdt[a, k1, 2]
    th = math.sqrt(wx * wx + wy * wy + wz * wz)
    if th < 1e-12:
        for r in range(3):
            for c in range(3):
                Ru[r, c] = 1.0 if r == c else 0.0
        Ru[0, 1], Ru[0, 2], Ru[1, 0] = -wz, wy, wz
        Ru[1, 2], Ru[2, 0], Ru[2, 1] = -wx, -wy, wx
    else:
        kx, ky, kz = wx / th, wy / th, wz / th
        s, c1 = math.sin(th), 1.0 - math.cos(th)
        Ru[0, 0], Ru[0, 1], Ru[0, 2] = 1 - c1 * (ky * ky + kz * kz), -s * kz + c1 * kx * ky, s * ky + c1 * kx * kz
        Ru[1, 0], Ru[1, 1], Ru[1, 2] = s * kz + c1 * kx * ky, 1 - c1 * (kx * kx + kz * kz), -s * kx + c1 * ky * kz
        Ru[2, 0], Ru[2, 1], Ru[2, 2] = -s * ky + c1 * kx * kz, s * kx + c1 * ky * kz, 1 - c1 * (kx * kx + ky * ky)
    for r in range(3):
        for c in range(3):
            Rm[r, c] = T[a, k, r, 0] * Ru[0, c] + T[a, k, r, 1] * Ru[1, c] + T[a, k, r, 2] * Ru[2, c]
    return px, py, pz




@njit(cache=True, nogil=True)
def merge_nearest(static_ray: np.ndarray, static_distance: np.ndarray, actor_ray: np.ndarray,
                  actor_distance: np.ndarray):
    """The nearer of the static world's hit and an actor's hit per ray, both lists sorted by ray.

    Returns (from_static, from_actor) (m,): for each row of the merged list, in ray order, the index of
    the static hit or of the actor hit it takes (-1 for the other). numpy: an actor hit wins where its
    distance is below the static hit's (or the ray missed the static world).
    """
    n_s, n_a = static_ray.shape[0], actor_ray.shape[0]
    from_static = np.empty(n_s + n_a, np.int64)
    from_actor = np.empty(n_s + n_a, np.int64)
    i = j = m = 0
    while i < n_s or j < n_a:
        if j >= n_a or (i < n_s and static_ray[i] < actor_ray[j]):
            from_static[m], from_actor[m] = i, -1
            i += 1
        elif i >= n_s or actor_ray[j] < static_ray[i]:
            from_static[m], from_actor[m] = -1, j
            j += 1
        else:  # both hit the ray: the nearer
            if actor_distance[j] < static_distance[i]:
                from_static[m], from_actor[m] = -1, j
            else:
                from_static[m], from_actor[m] = i, -1
            i += 1
            j += 1
        m += 1
    return from_static[:m], from_actor[:m]


@njit(cache=True, nogil=True, error_model="numpy")
def nearest_actor_hits(n_rays: int, rows: np.ndarray, keep: np.ndarray, hit: np.ndarray, distance: np.ndarray,
                       cos: np.ndarray, face: np.ndarray, face_normals: np.ndarray, R: np.ndarray, p: np.ndarray,
                       actor: np.ndarray, t: np.ndarray, actor_index: np.ndarray, origin: np.ndarray,
                       offset: np.ndarray, direction: np.ndarray, v: np.ndarray, w: np.ndarray, t0: float, dt: float):
    """Per ray of a call (``n_rays``), the nearest of the actors' hits, in ray order.

    rows (n,), actor (n,), t (n,): the call's candidate rays, their actor and time; keep (m,): those cast in the
    actors' frames (``rays_in_actor_frame``), R (m, 3, 3), p (m, 3) the actor's pose then; hit (h,) the cast
    rays that hit (indices into keep), at distance (h,), cos (h,), on triangle face (h,) of the models' BVH
    (face_normals (F, 3)); actor_index (A,) an actor's index in its set; origin + offset (3,), direction
    (n_rays, 3) in the world; v, w (A, K, 3) the actors' velocities at the knots t0 + k dt. Returns ray (q,),
    distance (q,), cos (q,), normal (q, 3) outward in the world, actor (q,) in its set, velocity (q, 3) of the
    point hit (v + w x (hit - p), linear between knots). numpy: the lexsort by ray then distance, its first per
    ray, ``R @ n``.
    """
    best = np.full(n_rays, -1, np.int64)
    for i in range(hit.shape[0]):
        r = rows[keep[hit[i]]]
        if best[r] < 0 or distance[i] < distance[best[r]]:
            best[r] = i
    q = 0
    for r in range(n_rays):
        if best[r] >= 0:
            q += 1
    ray = np.empty(q, np.int64)
    dist = np.empty(q)
    cs = np.empty(q)
    normal = np.empty((q, 3))
    who = np.empty(q, np.int64)
    vel = np.empty((q, 3))
    K = v.shape[1]
    o = 0
    for r in range(n_rays):
        i = best[r]
        if i < 0:
            continue
        k_row = hit[i]
        a = actor[keep[k_row]]
        ray[o], dist[o], cs[o], who[o] = r, distance[i], cos[i], actor_index[a]
        f = face[i]
        for c in range(3):
            normal[o, c] = (R[k_row, c, 0] * face_normals[f, 0] + R[k_row, c, 1] * face_normals[f, 1]
                            + R[k_row, c, 2] * face_normals[f, 2])
        if dt > 0:
            x = min(max((t[keep[k_row]] - t0) / dt, 0.0), K - 1 - 1e-12)
            k = int(x)
            u = x - k
        else:
            k, u = 0, 0.0
        k1 = min(k + 1, K - 1)
        hx = origin[r, 0] + offset[0] + direction[r, 0] * distance[i] - p[k_row, 0]
        hy = origin[r, 1] + offset[1] + direction[r, 1] * distance[i] - p[k_row, 1]
        hz = origin[r, 2] + offset[2] + direction[r, 2] * distance[i] - p[k_row, 2]
        wx = w[a, k, 0] * (1 - u) + w[a, k1, 0] * u
        wy = w[a, k, 1] * (1 - u) + w[a, k1, 1] * u
        wz = w[a, k, 2] * (1 - u) + w[a, k1, 2] * u
        vel[o, 0] = v[a, k, 0] * (1 - u) + v[a, k1, 0] * u + (wy * hz - wz * hy)
        vel[o, 1] = v[a, k, 1] * (1 - u) + v[a, k1, 1] * u + (wz * hx - wx * hz)
        vel[o, 2] = v[a, k, 2] * (1 - u) + v[a, k1, 2] * u + (wx * hy - wy * hx)
        o += 1
    return ray, dist, cs, normal, who, vel


@njit(cache=True, nogil=True)
def merge_rows(s_ray: np.ndarray, s_face: np.ndarray, s_dist: np.ndarray, s_cos: np.ndarray, a_ray: np.ndarray,
               a_dist: np.ndarray, a_cos: np.ndarray, a_actor: np.ndarray):
    """The merged hits of ``merge_nearest``, written out: ray, face (-1 on an actor), distance, cos, actor (-1 on
    the static world), and the actor hits taken, in order (indices into the ``a_`` arrays)."""
    from_s, from_a = merge_nearest(s_ray, s_dist, a_ray, a_dist)
    m = from_s.shape[0]
    ray = np.empty(m, np.int64)
    face = np.empty(m, np.int64)
    dist = np.empty(m)
    cos = np.empty(m)
    actor = np.empty(m, np.int64)
    taken = np.empty(m, np.int64)
    k = 0
    for o in range(m):
        i, j = from_s[o], from_a[o]
        if i >= 0:
            ray[o], face[o], dist[o], cos[o], actor[o] = s_ray[i], s_face[i], s_dist[i], s_cos[i], -1
        else:
            ray[o], face[o], dist[o], cos[o], actor[o] = a_ray[j], -1, a_dist[j], a_cos[j], a_actor[j]
            taken[k] = j
            k += 1
    return ray, face, dist, cos, actor, taken[:k]


@njit(cache=True, nogil=True)
def rays_by_block(rays: np.ndarray, counts: np.ndarray, bounds: np.ndarray):
    """The candidate rays of every actor cut at a sweep's block bounds, block after block.

    rays: (N,) global firing indices, ``counts`` (A,) per actor in turn, each actor's ascending; bounds: (K + 1,)
    the blocks' first rays and the sweep's end, ascending. Returns rows (N,) within their block, actor (N,)
    and starts (K + 1,): block k's rows are ``starts[k]:starts[k + 1]``, by actor, then ray. numpy: a stable
    argsort by ``searchsorted(bounds, rays, side="right") - 1`` of the rays and their actors.
    """
    A, K = counts.shape[0], bounds.shape[0] - 1
    first = np.zeros(A + 1, np.int64)
    for a in range(A):
        first[a + 1] = first[a] + counts[a]
    cut = np.empty((A, K + 1), np.int64)  # where each actor's rays reach each bound
    for a in range(A):
        seg = rays[first[a]:first[a + 1]]
        for k in range(K + 1):
            cut[a, k] = first[a] + np.searchsorted(seg, bounds[k])
    starts = np.zeros(K + 1, np.int64)
    rows = np.empty(first[A], np.int64)
    actor = np.empty(first[A], np.int64)
    o = 0
    for k in range(K):
        starts[k] = o
        for a in range(A):
            for i in range(cut[a, k], cut[a, k + 1]):
                rows[o] = rays[i] - bounds[k]
                actor[o] = a
                o += 1
    starts[K] = o
    return rows[:o], actor[:o], starts


__all__ = ["merge_nearest", "merge_rows", "nearest_actor_hits", "ray_windows", "rays_by_block",
           "rays_in_actor_frame"]
