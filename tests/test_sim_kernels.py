"""The simulator's compiled passes (``simlidar.kernels``) against the numpy expressions they replace, bit for bit.

The numpy references here are the sweep's and the writer's code before they were compiled;
the kernels round in the same order (numpy's 3-term dot ``(a0 + a2) + a1``, BLAS's fused
multiply-adds), so a simulated sequence's files keep their sha256.
"""

from __future__ import annotations

import numpy as np
import pytest

from simlidar.degeneracy import information_matrix
from simlidar.formats.truth import octahedral_encode
from simlidar.kernels.actors import rays_by_block
from simlidar.kernels.files import fill_body, octahedral_codes, pack_points
from simlidar.kernels.information import information_sums
from simlidar.kernels.sweep import block_rays, fill_actor_rows, fill_rows, measure_block, solve_hits

RNG = np.random.default_rng(7)


def unit(n: int) -> np.ndarray:
    v = RNG.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rotations(n: int) -> np.ndarray:
    return np.linalg.qr(RNG.normal(size=(n, 3, 3)))[0]


def same(a, b) -> bool:
    return np.array_equal(np.asarray(a).view(np.uint8), np.asarray(b).view(np.uint8))


def test_block_rays_round_as_numpys_matmul_and_einsum():
    rings, cols = 32, 300
    dir_local = unit(rings * cols)
    R, t, offset = rotations(cols), RNG.normal(size=(cols, 3)) * 100, RNG.normal(size=3) * 500
    o, d, o32, d32 = block_rays(dir_local, R, t, np.empty(0, np.int64), rings, offset)
    assert same(d, np.matmul(dir_local.reshape(cols, rings, 3), R.transpose(0, 2, 1)).reshape(-1, 3))
    assert same(o, np.repeat(t - offset, rings, axis=0))
    assert same(o32, o.astype(np.float32)) and same(d32, d.astype(np.float32))
    pose = RNG.integers(0, cols, rings * cols)
    o, d, _, _ = block_rays(dir_local, R, t, pose, rings, offset)
    assert same(d, np.einsum("nij,nj->ni", R[pose], dir_local))
    assert same(o, t[pose] - offset)


def test_solve_hits_is_the_plane_solve():
    n, F = 5000, 400
    prim = RNG.integers(-1, F, n).astype(np.int32)
    origins, directions = RNG.normal(size=(n, 3)) * 30, unit(n)
    face_normal, face_offset = unit(F), RNG.normal(size=F) * 20
    face_normal[3] = directions[np.flatnonzero(prim == 3)[0]] * 0  # a degenerate triangle: a zero normal
    ray, face, t, denom, grazing = solve_hits(prim, origins, directions, face_normal, face_offset)
    ref_ray = np.flatnonzero(prim >= 0)
    ref_face = prim[ref_ray].astype(np.int64)
    n_f = np.take(face_normal, ref_face, axis=0)
    ref_denom = np.einsum("ij,ij->i", np.take(directions, ref_ray, axis=0), n_f)
    num = np.take(face_offset, ref_face) - np.einsum("ij,ij->i", np.take(origins, ref_ray, axis=0), n_f)
    ref_grazing = np.abs(ref_denom) < 1e-9
    assert same(ray, ref_ray) and same(face, ref_face) and same(denom, ref_denom)
    assert np.array_equal(grazing, ref_grazing) and ref_grazing.any()
    assert same(t, num / np.where(ref_grazing, 1.0, ref_denom))


@pytest.mark.parametrize("factor, dropout", [(1.0, 0.0), (5.0, 0.2)])
def test_measure_block_is_noise_window_and_dropouts(factor, dropout):
    m, B, rings = 3000, 4000, 16
    ray = np.sort(RNG.choice(B, m, replace=False))
    echo, cos = RNG.uniform(0.0, 150.0, m), RNG.uniform(-1, 1, m)
    ring_of_ray, bias = np.tile(np.arange(rings), B // rings), RNG.normal(size=rings) * 0.01
    z, u = RNG.standard_normal(m), RNG.random(m)
    ring, measured, keep = measure_block(ray, echo, cos, ring_of_ray, bias, z, 0.02, factor, 0.5, 120.0, u, dropout)
    ref_ring = ring_of_ray[ray]
    sigma = 0.02
    if factor > 1:
        sigma = sigma * np.minimum(1.0 / np.maximum(np.abs(cos), 1e-12), factor)
    ref = echo + bias[ref_ring] + z * sigma
    ok = (ref >= 0.5) & (ref <= 120.0)
    if dropout > 0:
        ok &= u >= dropout
    assert same(ring, ref_ring) and same(measured, ref) and np.array_equal(keep, np.flatnonzero(ok))


def test_fill_rows_writes_the_scans_rows():
    B, m, F, first = 2000, 1500, 300, 64000
    ray = np.sort(RNG.choice(B, m, replace=False))
    face = RNG.integers(0, F, m)
    distance, cos, measured = RNG.uniform(1, 100, m), RNG.uniform(-1, 1, m), RNG.uniform(1, 100, m)
    ring = RNG.integers(0, 32, m)
    dir_local, o_bvh, d_bvh = unit(B), RNG.normal(size=(B, 3)) * 10, unit(B)
    t_ref, R_ref = RNG.normal(size=3), rotations(1)[0]
    face_normals, face_obj = unit(F), RNG.integers(0, 50, F).astype(np.int32)
    refl, ray_column, ray_time = RNG.uniform(0, 1, 50), np.arange(first + B) // 32, RNG.random(first + B)
    out = {k: np.empty((m, 3)) for k in ("xyz", "true_xyz", "normal")}
    out.update(intensity=np.empty(m, np.float32), ring=np.empty(m, np.int64), az=np.empty(m, np.int64),
               time=np.empty(m), range=np.empty(m), true_range=np.empty(m), obj=np.empty(m, np.int32))
    fill_rows(0, first, ray, face, distance, cos, measured, ring, dir_local, o_bvh, d_bvh, t_ref, R_ref, face_normals,
              face_obj, refl, np.empty(0), 10.0, ray_column, ray_time, np.empty(0, np.int64), np.empty((0, 3)), 0,
              out["xyz"], out["intensity"], out["ring"], out["az"], out["time"], out["range"], out["true_range"],
              out["true_xyz"], out["normal"], out["obj"])

    def rows_times(x):  # numpy's batches of 32 rows, the remainder by einsum (the sweep's former _rows_times)
        y = np.empty_like(x)
        k = len(x) - len(x) % 32
        np.matmul(x[:k].reshape(-1, 32, 3), R_ref, out=y[:k].reshape(-1, 32, 3))
        np.einsum("ni,ij->nj", x[k:], R_ref, out=y[k:])
        return y

    hit = np.take(d_bvh, ray, axis=0) * distance[:, None] + np.take(o_bvh, ray, axis=0) - t_ref
    normal = rows_times(np.take(face_normals, face, axis=0)) * -np.sign(cos)[:, None]
    obj = face_obj[face]
    falloff = np.minimum(1.0, (10.0 / np.maximum(measured, 1e-6)) ** 2)
    assert same(out["xyz"], measured[:, None] * dir_local[ray])
    assert same(out["true_xyz"], rows_times(hit)) and same(out["normal"], normal)
    assert same(out["intensity"], (refl[obj] * np.abs(cos) * falloff).astype(np.float32))
    assert same(out["obj"], obj) and same(out["ring"], ring) and same(out["az"], ray_column[first + ray])
    assert same(out["time"], ray_time[first + ray]) and same(out["range"], measured)
    assert same(out["true_range"], distance)


def test_the_frame_files_passes():
    n = 20000
    normal = unit(n)
    normal[:10] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0.6, 0.8, 0], [0, 0.6, -0.8],
                   [1, 1, 1], [-1, -1, -1]] / np.linalg.norm(
        [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0.6, 0.8, 0], [0, 0.6, -0.8], [1, 1, 1],
         [-1, -1, -1]], axis=1, keepdims=True)
    assert same(octahedral_codes(normal), octahedral_encode(normal))
    ray, rng_m, ids = RNG.integers(0, 1 << 20, n), RNG.uniform(0, 200, n), RNG.integers(0, 60000, n)
    rng_m[::7] = np.nan  # weather echoes without a surface
    views = np.empty(n, "<u4"), np.empty(n, "<f4"), np.empty(2 * n, "<i2"), np.empty(n, "<u2")
    fill_body(ray, rng_m, normal, ids, True, *views)
    bare = np.isnan(rng_m)
    ref_normal, ref_ids = normal.copy(), ids.copy()
    ref_normal[bare], ref_ids[bare] = 0, 0
    assert same(views[0], ray.astype("<u4")) and same(views[1], rng_m.astype("<f4"))
    assert same(views[2], octahedral_encode(ref_normal).ravel()) and same(views[3], ref_ids.astype("<u2"))
    xyz, intensity = RNG.normal(size=(n, 3)) * 50, RNG.random(n).astype(np.float32)
    out = np.empty((n, 4), "<f4")
    pack_points(xyz, intensity, out)
    ref = np.empty((n, 4), "<f4")
    ref[:, :3], ref[:, 3] = xyz, intensity
    assert same(out, ref)


def test_information_sums_are_the_information_matrix():
    p, n = RNG.normal(size=(50000, 3)) * 30, unit(50000)
    H = information_sums(p, n)
    assert np.allclose(H, information_matrix(p, n), rtol=1e-12, atol=1e-9) and np.array_equal(H, H.T)


def test_rays_by_block_is_a_stable_sort_by_block():
    counts = np.array([0, 40, 7, 300, 1])
    rays = np.concatenate([np.sort(RNG.choice(1000, c, replace=False)) for c in counts])
    actor = np.repeat(np.arange(len(counts)), counts)
    bounds = np.array([0, 96, 250, 251, 600, 1000])
    block = np.searchsorted(bounds, rays, side="right") - 1
    order = np.argsort(block, kind="stable")
    rows, who, starts = rays_by_block(rays, counts, bounds)
    assert np.array_equal(rows, rays[order] - bounds[block[order]]) and np.array_equal(who, actor[order])
    assert np.array_equal(starts, np.searchsorted(block[order], np.arange(len(bounds))))


def test_fill_actor_rows_writes_the_moving_objects_truth():
    m, off = 500, 7
    actor = np.where(RNG.random(m) < 0.3, RNG.integers(0, 5, m), -1)
    k = int((actor >= 0).sum())
    codes = np.array([1, 2, 5, 6, 3], np.uint8)
    velocity, fast = RNG.normal(size=(k, 3)), RNG.random(k) < 0.5
    out = np.full(m + 20, 9, np.uint8), np.ones(m + 20, bool), np.full((m + 20, 3), 9.0)
    fill_actor_rows(off, m, actor, codes, velocity, fast, *out)
    on = np.flatnonzero(actor >= 0)
    ref = np.zeros(m, np.uint8), np.zeros(m, bool), np.zeros((m, 3))
    ref[0][on], ref[1][on], ref[2][on] = codes[actor[on]], fast, velocity
    for got, want in zip(out, ref, strict=True):
        assert same(got[off:off + m], want) and np.all(got[:off] == got.flat[0])
    fill_actor_rows(off, m, np.zeros(0, np.int64), codes, np.zeros((0, 3)), np.zeros(0, bool), *out)  # none hit
    assert not out[0][off:off + m].any() and not out[1][off:off + m].any() and not out[2][off:off + m].any()
