"""Open: wasteland with a few rocks and shrubs, a dirt-track loop; the other feature-poor case.

Rolling terrain (``roughness_m``) over a square of ``size_m``; a closed track
of mean radius ``loop_radius_m`` wanders round its middle (a smooth random
loop); rocks and shrubs are scattered sparsely, none within
``track_clearance_m`` of the track. The track is the bare ground itself: roll
and pitch follow the terrain's slope under the wheels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import geometry as g
from . import paths, props
from .base import MeshBuilder, Scene, check_budget
from .params import CommonParams, ParamError, param
from .trajectory import PathTrajectory

DESCRIPTION = "open wasteland with sparse rocks and shrubs, a dirt-track loop"

STEP_M = 0.5


@dataclass(frozen=True)
class Params(CommonParams):
    speed_m_s: float = param(8.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    size_m: float = param(700.0, "side of the square of land", min=200.0, max=5000.0)
    roughness_m: float = param(1.5, "standard deviation of the terrain's relief", min=0.0, max=20.0)
    loop_radius_m: float = param(110.0, "mean radius of the track loop", min=30.0, max=2000.0)
    rocks: int = param(40, "number of rocks", min=0, max=100000)
    shrubs: int = param(80, "number of shrubs", min=0, max=100000)
    track_clearance_m: float = param(4.0, "no rock or shrub closer to the track's centre than this",
                                     min=2.5, max=100.0)
    grid_m: float = param(4.0, "terrain mesh spacing", min=0.5, max=20.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.loop_radius_m * 1.5 > self.size_m / 2 - 10.0:
            raise ParamError("is too large: the loop does not fit in the land (see size_m)", "loop_radius_m")


def random_loop(rng: np.random.Generator, radius_m: float, step_m: float,
                wiggle: tuple[float, float] = (0.03, 0.12)) -> np.ndarray:
    """(n, 2) a smooth closed loop of mean radius ``radius_m``, counter-clockwise: a radius
    with random Fourier harmonics 2-4, each of relative amplitude drawn from ``wiggle``
    (by default wiggles up to a third of the radius), sampled ``step_m`` apart."""
    theta = np.linspace(0, 2 * np.pi, 2048, endpoint=False)
    r = np.ones_like(theta)
    for k in (2, 3, 4):
        r += rng.uniform(*wiggle) * np.cos(k * theta + rng.uniform(0, 2 * np.pi))
    pts = radius_m * r[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)
    return paths.resample(pts, step_m, closed=True)


def build(p: Params) -> Scene:
    rng = np.random.default_rng([p.seed, 0x09E4])
    terrain = g.SmoothField(rng, p.roughness_m, (80.0, 400.0))
    half = p.size_m / 2
    n = int(np.ceil(p.size_m / p.grid_m)) + 1
    axis = np.linspace(-half, half, n)
    mb = MeshBuilder()
    mb.add_object(*g.heightfield(axis, axis, terrain), "ground")

    loop = random_loop(rng, p.loop_radius_m, STEP_M)
    tree = cKDTree(loop)

    def scatter(count: int, make, label: str, size_range) -> int:
        placed = 0
        for _ in range(count * 20):
            if placed == count:
                break
            q = rng.uniform(-half + 10, half - 10, 2)
            size = rng.uniform(*size_range)
            if tree.query(q)[0] < p.track_clearance_m + size / 2:
                continue
            z = float(terrain(q[:1], q[1:])[0])
            mb.add_object(*g.place(make(rng, size), rng.uniform(0, 2 * np.pi), (*q, z - 0.1)), label)
            placed += 1
        return placed

    n_rocks = scatter(p.rocks, props.rock, "rock", (0.5, 2.5))
    n_shrubs = scatter(p.shrubs, props.shrub, "vegetation", (0.6, 2.0))

    path = np.column_stack([loop, terrain(loop[:, 0], loop[:, 1])])
    traj = PathTrajectory(
        path, True, p.speed_m_s, p.accel_m_s2, p.lateral_accel_m_s2, p.mount_height_m,
        np.radians(p.suspension_pitch_deg), p.suspension_heave_m, p.seed, surface_height=terrain,
        accel_smoothing_s=p.accel_smoothing_s,
    )
    check_budget(mb.n_faces, p.max_triangles)
    v, f, ids, labels = mb.arrays()
    return Scene("open", v, f, ids, labels, path, traj, p.to_dict(),
                 {"path_length_m": traj.length_m, "rocks": n_rocks, "shrubs": n_shrubs})
