"""Forest road: a winding gravel road through mixed woodland on hilly ground.

The road follows a random smooth curvature profile (radius at least
``min_curve_radius_m``) over rolling terrain; the ground's triangles within
the road's half width are the road. Trees stand on both sides in a band
``forest_depth_m`` deep, at ``tree_density_per_ha`` with a minimum spacing
(conifers and broadleaves, random sizes), none closer to the road's
centre-line than ``road_width_m / 2 + verge_m``; low shrubs and a few rocks
make the undergrowth. Unstructured returns: trunks, crowns, sloping ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import alignment as al
from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, param
from .trajectory import PathTrajectory

DESCRIPTION = "winding gravel road through mixed forest on hilly ground"

STEP_M = 0.5


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(12.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    length_m: float = param(800.0, "length of the road", min=100.0, max=10000.0)
    road_width_m: float = param(6.0, "road width", min=3.0, max=15.0)
    verge_m: float = param(2.5, "tree-free verge beside the road", min=0.5, max=30.0)
    min_curve_radius_m: float = param(80.0, "smallest curve radius", min=20.0, max=1e6)
    forest_depth_m: float = param(70.0, "depth of the forest on each side of the road", min=10.0, max=500.0)
    tree_density_per_ha: float = param(250.0, "trees per hectare", min=0.0, max=2000.0)
    conifer_fraction: float = param(0.6, "share of conifers among the trees", min=0.0, max=1.0)
    roughness_m: float = param(2.0, "standard deviation of the ground's relief", min=0.0, max=20.0)
    shrubs_per_ha: float = param(60.0, "undergrowth shrubs per hectare", min=0.0, max=2000.0)


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0xF0E5])
    terrain = g.SmoothField(rng, p.roughness_m, (100.0, 400.0))
    s = np.arange(0.0, p.length_m + STEP_M / 2, STEP_M)
    kappa = al.random_curves(rng, s, p.min_curve_radius_m, 90.0, 25.0)
    road = al.integrate(s, kappa, np.zeros_like(s))
    centre = road.xyz[:, :2]
    tree = cKDTree(centre)

    # Ground over the road's bounding box plus the forest band, on a 3 m grid.
    margin = p.forest_depth_m + p.road_width_m
    lo, hi = centre.min(axis=0) - margin, centre.max(axis=0) + margin
    xs = np.linspace(lo[0], hi[0], int(np.ceil((hi[0] - lo[0]) / 3.0)) + 1)
    ys = np.linspace(lo[1], hi[1], int(np.ceil((hi[1] - lo[1]) / 3.0)) + 1)
    v, f = g.heightfield(xs, ys, terrain)
    # Keep the whole rectangle of ground (a ragged band would let low rays slip under
    # distant ground), except triangles wholly under the road strip, which is meshed
    # as its own band following the road, 1 m along and across (both sample the same
    # surface, so where they overlap they agree to millimetres).
    half_w = p.road_width_m / 2 + 1.0
    v_dist, v_near = tree.query(v[:, :2])
    # (beyond the road's ends the band stops: keep the ground there)
    v_dist = np.where((v_near > 0) & (v_near < len(centre) - 1), v_dist, np.inf)
    under_road = v_dist[f].max(axis=1) < half_w
    mb = MeshBuilder()
    mb.add(v, f[~under_road], mb.new_object("ground"))
    k = int(round(1.0 / STEP_M))
    idx = np.arange(0, len(s), k)
    lat = np.linspace(-half_w, half_w, int(np.ceil(2 * half_w)) + 1)
    xy = centre[idx, None, :] + lat[None, :, None] * road.left[idx, None, :2]
    prof = np.stack([np.broadcast_to(lat, xy.shape[:2]), terrain(xy[..., 0], xy[..., 1])], -1)
    base = np.column_stack([centre[idx], np.zeros(len(idx))])
    mb.add(*g.sweep(base, road.left[idx], prof), mb.new_object("road"))

    # Trees: random positions at the density, a minimum spacing, clear of the road.
    clear = p.road_width_m / 2 + p.verge_m
    band = tree.query(v[f].mean(axis=1)[:, :2])[0] <= margin
    area_ha = band.sum() / len(f) * (hi[0] - lo[0]) * (hi[1] - lo[1]) / 1e4
    n_try = int(p.tree_density_per_ha * area_ha * 1.6)
    cand = rng.uniform(lo, hi, size=(n_try, 2))
    d_cand = tree.query(cand)[0]
    cand = cand[(d_cand > clear + 1.0) & (d_cand < margin - 2.0)]
    kept = _thin(cand, 2.5)[: int(p.tree_density_per_ha * area_ha)]
    for q in kept:
        z = float(terrain(q[:1], q[1:])[0]) - 0.2
        room = tree.query(q)[0] - clear  # crowns must not reach over the verge
        if rng.random() < p.conifer_fraction:
            trunk, crown = props.conifer(rng, rng.uniform(12.0, 26.0), min(rng.uniform(1.8, 3.2), room))
        else:
            trunk, crown = props.tree(rng, rng.uniform(9.0, 18.0), min(rng.uniform(2.0, 4.0), room))
        obj = mb.new_object("vegetation")
        mb.add(*g.place(trunk, 0.0, (*q, z)), obj)
        mb.add(*g.place(crown, rng.uniform(0, 2 * np.pi), (*q, z)), obj)
    n_shrubs = int(p.shrubs_per_ha * area_ha)
    cand = rng.uniform(lo, hi, size=(n_shrubs * 2, 2))
    d_cand = tree.query(cand)[0]
    cand = cand[(d_cand > p.road_width_m / 2 + 1.5) & (d_cand < margin - 2.0)][:n_shrubs]
    for q in cand:
        z = float(terrain(q[:1], q[1:])[0]) - 0.1
        size = rng.uniform(0.6, 1.6)
        size = min(size, 2 * (tree.query(q)[0] - p.road_width_m / 2 - 0.5) / 1.3)
        kind = props.rock if rng.random() < 0.15 else props.shrub
        mb.add_object(*g.place(kind(rng, size), rng.uniform(0, 2 * np.pi), (*q, z)),
                      "rock" if kind is props.rock else "vegetation")

    lane = paths.smooth(centre - p.road_width_m / 4 * road.left[:, :2], 1.0, STEP_M, closed=False)
    path = np.column_stack([lane, terrain(lane[:, 0], lane[:, 1])])
    traj = PathTrajectory(
        path, False, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed, surface_height=terrain,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    return Scene("forest", v, f, ids, labels, path, traj, p.to_dict(),
                 {"path_length_m": traj.length_m, "trees": int(len(kept))})


def _thin(points: np.ndarray, min_spacing: float) -> np.ndarray:
    """Greedy dart throwing: keep points (in order) no closer than ``min_spacing`` to a kept one."""
    cell = min_spacing / np.sqrt(2)
    keys = np.floor(points / cell).astype(np.int64)
    grid: dict[tuple[int, int], int] = {}
    kept = []
    for i, (kx, ky) in enumerate(keys):
        ok = True
        for dx in (-2, -1, 0, 1, 2):
            for dy in (-2, -1, 0, 1, 2):
                j = grid.get((kx + dx, ky + dy))
                if j is not None and np.hypot(*(points[i] - points[j])) < min_spacing:
                    ok = False
                    break
            if not ok:
                break
        if ok:
            grid[(kx, ky)] = i
            kept.append(i)
    return points[kept]
