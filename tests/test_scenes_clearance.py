"""Nothing of a scene comes near the lidar anywhere along its trajectory, in every family.

``test_scenes.test_path_keeps_clear_of_all_geometry`` measures exact distances
for the default scenes; a family draws other widths, lengths, grades and curves,
and a defect can hide at one combination of them (a tunnel's portal whose hill
dropped onto the road when the portal fell between two alignment samples). So
every family is checked at many seeds, cheaply, with rays.

The rule, in the lidar's own frame (x ahead, y left, z up; the road is
``mount_height_m`` below the sensor along -z): the *clearance box*

    |x| < 0.8 m,  |y| < 0.8 m,  -0.8 * mount_height_m < z < OVERHEAD_M (0.3 m)

holds no part of the scene. The road itself lies at z = -mount_height_m, 20 %
below the box's floor (room for the suspension's heave and pitch, and a kerb
or a road's camber); everything else (walls, posts, a portal, the land, a car
ahead) must keep 0.8 m from the sensor horizontally; above it the vehicle
passes under anything higher than the lidar's housing and a margin
(``helpers.OVERHEAD_M``: a parking garage's beams are 0.4 m and more above a
roof-mounted lidar). It is
checked by casting ``N_RAYS`` directions spread evenly over the sphere from the
lidar at poses every ``POSE_SPACING_M`` of path: a hit point inside the box is
an intrusion. The box is convex and holds the sensor, so a ray meeting anything
in the box meets it (or something else in the box) first; what the rays can
miss is only a part thinner than their spacing (about 9 degrees: 12 cm at
0.8 m).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh
from helpers import OVERHEAD_M, scene_params

import scenes
from scenes import build_scene
from scenes.families import FAMILIES, draw_family_params, family_scene
from simlidar.raycast import Raycaster

BOX_HALF_M = 0.8  # ahead / behind / left / right of the sensor (above it: OVERHEAD_M)
FLOOR_FRACTION = 0.8  # the box reaches down to this share of the mount height (the road: 1.0)
N_RAYS = 500
POSE_SPACING_M = 1.0  # a portal's slope or a post is about a metre deep: 2 m could step over it
FAMILY_SEEDS = (0, 1, 2, 3, 4, 5, 101, 102, 103)
# Portals off the 0.5 m alignment sampling (the family draws' lengths are arbitrary reals),
# at both grade signs, steep and gentle.
OFF_GRID = {
    "tunnel": {"approach_m": 41.2, "length_m": 233.7, "curve_radius_m": 500.0},
    "canyon": {"street_length_m": 61.2, "tunnel_length_m": 83.7, "exit_m": 30.2},
}
GRADES_PCT = (-8.0, -3.0, 3.0, 8.0)


@functools.cache
def sphere_directions(n: int = N_RAYS) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def box_intrusions(rc: Raycaster, poses: np.ndarray, mount_height_m: float) -> tuple[np.ndarray, ...]:
    """Hits inside the clearance box of each pose (see the module's docstring).

    poses: (p, 4, 4) ``T_world_lidar``. Returns (pose index (m,), hit point in the lidar
    frame (m, 3), hit face (m,)) of every intruding ray.
    """
    d_local = sphere_directions()
    n = len(d_local)
    dirs = np.einsum("pij,nj->pni", poses[:, :3, :3], d_local).reshape(-1, 3)
    origins = np.repeat(poses[:, :3, 3], n, axis=0)
    floor = FLOOR_FRACTION * mount_height_m
    reach = np.sqrt(2 * BOX_HALF_M**2 + max(floor, BOX_HALF_M) ** 2) + 0.01  # the box's farthest corner
    hits = rc.cast(origins, dirs, reach)
    ray = np.flatnonzero(hits.hit)
    local = np.tile(d_local, (len(poses), 1))[ray] * hits.distance[ray, None]
    inside = ((np.abs(local[:, 0]) < BOX_HALF_M) & (np.abs(local[:, 1]) < BOX_HALF_M)
              & (local[:, 2] < OVERHEAD_M) & (local[:, 2] > -floor))
    ray = ray[inside]
    return ray // n, local[inside], hits.face[ray]


def assert_clear_along_the_trajectory(scene) -> None:
    tr = scene.trajectory
    dist = np.append(np.arange(0.0, tr.length_m, POSE_SPACING_M), tr.length_m)
    poses = tr.pose_at(tr.time_at_distance(dist))
    rc = Raycaster(scene.vertices, scene.faces, threads=1)
    try:
        pose, local, face = box_intrusions(rc, poses, scene.params["mount_height_m"])
    finally:
        rc.close()
    if len(pose):
        labels = np.asarray(scene.object_labels)[scene.face_object_id[face]]
        where = sorted({(round(float(dist[i]), 1), str(lab)) for i, lab in zip(pose, labels, strict=True)})
        worst = int(np.argmin(np.linalg.norm(local, axis=1)))
        pytest.fail(f"{len(np.unique(pose))} of {len(poses)} poses have scene geometry in the lidar's "
                    f"clearance box, at path m / label: {where[:12]}{' ...' if len(where) > 12 else ''}; "
                    f"nearest: {local[worst].round(2)} m (lidar frame) at {dist[pose[worst]]:.1f} m of path")


# ---------------------------------------------------------------- the rule itself
def test_box_intrusions_sees_the_road_only_below_the_floor_and_a_post_at_0_6_m():
    # Flat road at z = 0, a thin post 0.6 m left of a sensor mounted 1.9 m up: the road is
    # outside the box at 1.9 m, inside it when the sensor sinks to 1.4 m; the post intrudes.
    road_v = np.array([[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0]])
    road_f = np.array([[0, 1, 2], [0, 2, 3]])
    rc = Raycaster(road_v, road_f, threads=1)
    poses = np.tile(np.eye(4), (2, 1, 1))
    poses[0, 2, 3], poses[1, 2, 3] = 1.9, 1.4
    pose, local, _ = box_intrusions(rc, poses, 1.9)
    assert set(pose) == {1}
    np.testing.assert_allclose(local[:, 2], -1.4)
    post = trimesh.creation.box((0.1, 0.1, 4.0))
    post.apply_translation((3.0, 0.6, 2.0))
    v = np.vstack([road_v, post.vertices])
    f = np.vstack([road_f, np.asarray(post.faces) + 4])
    far, near = np.eye(4), np.eye(4)
    far[:3, 3] = (0.0, 0.0, 1.9)  # the post 3 m ahead: clear
    near[:3, 3] = (3.0, 0.0, 1.9)  # beside it
    pose, local, _ = box_intrusions(Raycaster(v, f, threads=1), np.stack([far, near]), 1.9)
    assert set(pose) == {1} and np.all(np.abs(local[:, 1] - 0.55) < 0.01)


# ---------------------------------------------------------------- the scenes
@pytest.mark.parametrize("name", scene_params(scenes.SCENES))
def test_default_scene_keeps_the_lidar_clear(name):
    assert_clear_along_the_trajectory(build_scene(name, seed=0))


@pytest.mark.parametrize("grade", GRADES_PCT)
@pytest.mark.parametrize("name", sorted(OFF_GRID))
def test_tunnel_portals_keep_the_lidar_clear_at_any_grade(name, grade):
    # A portal between two alignment samples, on a rising and a falling road.
    assert_clear_along_the_trajectory(build_scene(name, seed=3, grade_pct=grade, **OFF_GRID[name]))


@pytest.mark.slow
@pytest.mark.slow
@pytest.mark.parametrize("seed", FAMILY_SEEDS)
@pytest.mark.parametrize("family", FAMILIES)
def test_family_draws_keep_the_lidar_clear(family, seed):
    assert_clear_along_the_trajectory(build_scene(family_scene(family), **draw_family_params(family, seed)))
