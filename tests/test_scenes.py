"""Scenes against their own truth: determinism, budget, winding, clearance, scans, degeneracy.

Every default scene is built once per test session (a few seconds in all) and
shared by the tests below through ``default_scene``.
"""

from __future__ import annotations

import functools
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from helpers import OVERHEAD_M, scene_params

import scenes
from scenes import LABELS, build_scene
from scenes.families import draw_family_params
from simlidar.degeneracy import degeneracy
from simlidar.raycast import Raycaster
from simlidar.sensor import load_sensor
from simlidar.sweep import SensorInsideGeometry, SweepSimulator
from simlidar.world import World

NAMES = list(scenes.SCENES)
FACE_BUDGET = 1_000_000  # the budget for a default scene
FRAME_DT = 0.1  # 10 Hz frames, the presets' rotation rate


@functools.cache
def default_scene(name: str):
    return build_scene(name, seed=0)


@functools.cache
def simulator(name: str, sensor: str = "salo32") -> SweepSimulator:
    s = default_scene(name)
    world = World(s.vertices, s.faces, s.face_object_id, s.object_labels, name)
    return SweepSimulator(world, load_sensor(sensor), seed=0)


def frame_poses(scene) -> np.ndarray:
    """(n, 4, 4) the lidar pose at every 10 Hz frame of the whole trajectory."""
    return scene.trajectory.pose_at(np.arange(0.0, scene.trajectory.duration_s, FRAME_DT))


def min_distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                         radius: float, ups: np.ndarray | None = None, overhead: float = np.inf,
                         underfoot: float = np.inf) -> np.ndarray:
    """(n,) exact distance from each point to the nearest triangle, capped at ``radius``.

    Candidate triangles are those whose bounding box comes within ``radius`` of a
    chunk of consecutive points; trimesh computes the exact closest points. With ``ups``
    ((n, 3) unit vectors), a triangle whose closest point lies at least ``overhead`` m above
    the point along its up vector does not count (a ceiling the vehicle passes under), nor
    one whose closest point lies ``underfoot`` m or more below it (what the wheels roll over).
    """
    tri = vertices[faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    out = np.full(len(points), float(radius))
    for chunk in np.array_split(np.arange(len(points)), max(1, len(points) // 12)):
        p = points[chunk]
        cand = np.flatnonzero(np.all(hi >= p.min(0) - radius, 1) & np.all(lo <= p.max(0) + radius, 1))
        if len(cand) == 0:
            continue
        P = np.repeat(p, len(cand), axis=0)
        closest = trimesh.triangles.closest_point(np.tile(tri[cand], (len(p), 1, 1)), P)
        d = np.linalg.norm(closest - P, axis=1)
        if ups is not None:
            above = np.einsum("ij,ij->i", closest - P, np.repeat(ups[chunk], len(cand), axis=0))
            d = np.where((above >= overhead) | (above <= -underfoot), radius, d)
        out[chunk] = np.minimum(out[chunk], d.reshape(len(p), len(cand)).min(axis=1))
    return out


# ---------------------------------------------------------------- registry and parameters
def test_registry_lists_every_scene_with_documented_parameters():
    assert set(NAMES) >= {"city", "tunnel", "highway", "open"} and len(NAMES) >= 5
    for name in NAMES:
        params = scenes.scene_parameters(name)
        names = [p.name for p in params]
        assert len(names) == len(set(names))
        for common in ("seed", "speed_m_s", "mount_height_m", "accel_m_s2", "lateral_accel_m_s2",
                       "suspension_pitch_deg", "max_triangles"):
            assert common in names, (name, common)
        assert all(p.help for p in params), name
        resolved = scenes.resolve_params(name).to_dict()
        # keys added later are written only when set (what was made before keeps its keys)
        later = scenes.SCENES[name].Params.written_when_set
        assert {p.name: p.default for p in params if p.name not in later} == resolved
        assert scenes.resolve_params(name, accel_smoothing_s=0.5).to_dict()["accel_smoothing_s"] == 0.5


@pytest.mark.parametrize(
    "name, overrides, word",
    [
        ("city", {"no_such_param": 1}, "no_such_param"),
        ("city", {"streets_x": "three"}, "streets_x"),
        ("city", {"streets_x": 1}, "streets_x"),  # below its minimum
        ("city", {"building_height_max_m": 5.0}, "building_height_max_m"),  # below the min height
        ("tunnel", {"cross_section": "round"}, "cross_section"),
        ("tunnel", {"length_m": float("nan")}, "length_m"),
        ("highway", {"lane": 4}, "lane"),  # 3 lanes by default
        ("open", {"rocks": 2.5}, "rocks"),
        ("forest", {"mount_height_m": -1}, "mount_height_m"),
    ],
)
def test_bad_parameters_raise_naming_the_parameter(name, overrides, word):
    with pytest.raises(ValueError, match=word):
        build_scene(name, **overrides)


def test_unknown_scene_raises():
    with pytest.raises(ValueError, match="unknown scene 'mars'"):
        build_scene("mars")


def test_string_overrides_are_converted():
    p = scenes.resolve_params("tunnel", seed=2, length_m="250", cross_section="box")
    assert p.length_m == 250.0 and p.cross_section == "box" and p.seed == 2
    assert scenes.resolve_params("city", closed_loop="false").closed_loop is False


# ---------------------------------------------------------------- mesh
@pytest.mark.parametrize("name", scene_params(NAMES))
def test_mesh_is_well_formed_and_within_budget(name):
    s = default_scene(name)
    assert s.vertices.dtype == np.float64 and s.vertices.shape[1] == 3
    assert s.faces.dtype == np.int64 and s.faces.min() >= 0 and s.faces.max() < len(s.vertices)
    assert s.face_object_id.dtype == np.int32 and s.face_object_id.shape == (len(s.faces),)
    assert np.all(np.isfinite(s.vertices))
    assert s.face_object_id.min() >= 0 and s.face_object_id.max() < len(s.object_labels)
    assert set(s.object_labels) <= set(LABELS)
    assert 1000 < s.n_triangles < FACE_BUDGET
    assert s.path.shape[1] == 3 and np.all(np.isfinite(s.path))


def test_face_budget_is_enforced():
    with pytest.raises(ValueError, match="max_triangles"):
        build_scene("city", max_triangles=10_000)


@pytest.mark.parametrize("name", scene_params(NAMES))
def test_surfaces_to_drive_and_walk_on_face_up(name):
    s = default_scene(name)
    tri = s.vertices[s.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    labels = s.label_of_face()
    surface = np.isin(labels, ["road", "sidewalk", "ground"]) & (area2 > 1e-6)
    nz = n[surface, 2] / area2[surface]
    assert surface.sum() > 100
    # None faces down (kerb-like vertical faces of a walkway are allowed), nearly all up.
    assert np.all(nz > -1e-9), f"{(nz <= -1e-9).sum()} ground triangles face down"
    assert np.mean(nz > 0.5) > 0.9


@pytest.mark.parametrize("name", [pytest.param("city", marks=pytest.mark.slow), "tunnel"])
def test_same_seed_same_mesh_other_seed_other_mesh(name):
    a = default_scene(name)
    b = build_scene(name, seed=0)
    assert a.mesh_hash() == b.mesh_hash()
    t = np.linspace(0, a.trajectory.duration_s, 50)
    np.testing.assert_array_equal(a.trajectory.pose_at(t), b.trajectory.pose_at(t))
    assert build_scene(name, seed=1).mesh_hash() != a.mesh_hash()


@pytest.mark.slow
def test_mesh_hash_is_the_same_in_a_fresh_interpreter():
    # Catches order that depends on the process (set iteration of strings, id()s).
    code = "import scenes; print(scenes.build_scene('open', seed=5).mesh_hash())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == build_scene("open", seed=5).mesh_hash()


@pytest.mark.parametrize("name", ["highway", pytest.param("forest", marks=pytest.mark.slow), "garage", "bridge"])
def test_other_scenes_are_deterministic(name):
    a, b = build_scene(name, seed=3), build_scene(name, seed=3)
    assert a.mesh_hash() == b.mesh_hash()
    t = np.linspace(0, a.trajectory.duration_s, 50)
    np.testing.assert_array_equal(a.trajectory.pose_at(t), b.trajectory.pose_at(t))
    assert build_scene(name, seed=4).mesh_hash() != a.mesh_hash()


# ---------------------------------------------------------------- the sensor's clearance
@pytest.mark.parametrize("name", scene_params(NAMES))
def test_sensor_is_never_inside_geometry(name):
    # The simulator's own check at every frame, and the margin: probe rays from the
    # sensor must not see the inside (back) of surfaces. The meshes are wound outward
    # everywhere, so the only back-face hits possible are rays grazing a convex corner
    # exactly (Embree may report the far wall): isolated, at most 1% of the probes
    # (the check fires at 50%).
    s, sim = default_scene(name), simulator(name)
    golden = np.pi * (3.0 - np.sqrt(5.0))
    k = np.arange(400) + 0.5
    z = 1 - 2 * k / 400
    dirs = np.stack([np.sqrt(1 - z**2) * np.cos(golden * k), np.sqrt(1 - z**2) * np.sin(golden * k), z], 1)
    worst = 0
    for i, pose in enumerate(frame_poses(s)):
        sim.check_clear(pose, where=f"frame {i}: ")
        hits = sim.raycaster.cast(pose[:3, 3], dirs, 1e6)
        worst = max(worst, int(hits.back_face.sum()))
    assert worst <= 0.01 * len(dirs)


def test_check_clear_fires_under_the_ground():
    # The counter-test: the same probe must notice a sensor pushed below the road.
    s, sim = default_scene("city"), simulator("city")
    pose = frame_poses(s)[100].copy()
    pose[2, 3] -= s.params["mount_height_m"] + 1.0
    with pytest.raises(SensorInsideGeometry):
        sim.check_clear(pose)


# Clearances (m): the sensor keeps a car's half width (0.95 m) plus 0.5 m for mirrors and
# the rack from every surface (the road itself is the mount height, 1.9 m, below it);
# points of the body at 0.5 m and 1.2 m above the road keep the half width from everything
# that is not a drivable surface and stands above the road (a kerb counts; the edge of a
# slab flush with the deck the vehicle drives onto does not: within ROAD_LEVEL_M of the road).
# What lies ``OVERHEAD_M`` or more above the lidar (a garage's beams, a bridge deck) the
# vehicle passes under: it counts for neither.
SENSOR_CLEARANCE_M = 1.45
BODY_HALF_WIDTH_M = 0.95
DRIVABLE = ("road", "ground")
ROAD_LEVEL_M = 0.05


@pytest.mark.parametrize("name", scene_params(NAMES))
def test_path_keeps_clear_of_all_geometry(name):
    s = default_scene(name)
    poses = frame_poses(s)
    ups = poses[:, :3, 2]
    d_sensor = min_distance_to_mesh(poses[:, :3, 3], s.vertices, s.faces, 3.0, ups, OVERHEAD_M)
    assert d_sensor.min() >= SENSOR_CLEARANCE_M, f"frame {int(d_sensor.argmin())}: {d_sensor.min():.2f} m"
    solid = ~np.isin(s.label_of_face(), DRIVABLE)
    mount = s.params["mount_height_m"]
    for h in (0.5, 1.2):  # over these points the lidar's overhead line is mount - h higher
        body = poses[:, :3, 3] - poses[:, :3, 2] * (mount - h)
        d_body = min_distance_to_mesh(body, s.vertices, s.faces[solid], 3.0, ups, mount - h + OVERHEAD_M,
                                      h - ROAD_LEVEL_M)
        assert d_body.min() >= BODY_HALF_WIDTH_M, f"{h} m up, frame {int(d_body.argmin())}: {d_body.min():.2f} m"


def test_clearance_helper_measures_exact_distances():
    # A unit box: a point 2 m above its top is 2 m away, one at a corner's diagonal sqrt(3).
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    pts = np.array([[0.0, 0.0, 2.5], [1.5, 1.5, 1.5], [0.0, 0.0, 9.0]])
    d = min_distance_to_mesh(pts, np.asarray(box.vertices), np.asarray(box.faces), 5.0)
    np.testing.assert_allclose(d, [2.0, np.sqrt(3.0), 5.0], atol=1e-9)
    # Seen from below, the box is overhead: 1 m above a point under it, out of the count from
    # 1 m of overhead up, and in it from 1.01 m; to a point beside it, it is not overhead.
    below = np.array([[0.0, 0.0, -1.5], [1.5, 0.0, 0.0]])
    ups = np.tile([0.0, 0.0, 1.0], (2, 1))
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    np.testing.assert_allclose(min_distance_to_mesh(below, v, f, 5.0, ups, 1.0), [5.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(min_distance_to_mesh(below, v, f, 5.0, ups, 1.01), [1.0, 1.0], atol=1e-9)
    # ... and to a point 1 m above it, underfoot from 1 m down
    above = np.array([[0.0, 0.0, 1.5]])
    np.testing.assert_allclose(min_distance_to_mesh(above, v, f, 5.0, ups[:1], underfoot=1.0), [5.0], atol=1e-9)
    np.testing.assert_allclose(min_distance_to_mesh(above, v, f, 5.0, ups[:1], underfoot=1.01), [1.0], atol=1e-9)


# ---------------------------------------------------------------- scans
def ground_ray_fraction(sensor, height_m: float) -> float:
    """Share of a sweep's rays that meet flat ground within the maximum range from ``height_m``."""
    below = sensor.elevation_rad < -np.arctan2(height_m, sensor.max_range_m)
    return float(below.mean())


@pytest.mark.parametrize("name", scene_params(NAMES))
def test_a_scan_returns_a_realistic_point_count(name):
    # At least 90% of the rays that would meet flat ground within range return (slopes
    # and a pitching body move the far rings a little), more where walls catch the rest.
    s, sim = default_scene(name), simulator(name)
    t0 = 0.5 * s.trajectory.duration_s
    scan = sim.sweep(s.trajectory, t0)
    expected = ground_ray_fraction(sim.sensor, s.params["mount_height_m"])
    assert len(scan) >= 0.9 * expected * sim.sensor.rays_per_sweep
    assert np.all(scan.range_m <= sim.sensor.max_range_m)


@pytest.mark.parametrize("sensor", ["hdl64e", "vlp16"])
def test_other_sensors_see_the_city(sensor):
    s, sim = default_scene("city"), simulator("city", sensor)
    scan = sim.sweep(s.trajectory, 0.5 * s.trajectory.duration_s)
    expected = ground_ray_fraction(sim.sensor, s.params["mount_height_m"])
    assert len(scan) >= 0.9 * expected * sim.sensor.rays_per_sweep
    seen = set(np.asarray(s.object_labels)[scan.object_id])
    assert {"road", "building", "vehicle", "sidewalk"} <= seen


def test_city_scan_sees_the_street_furniture():
    s, sim = default_scene("city"), simulator("city")
    labels = np.asarray(s.object_labels)
    seen = set()
    for t in np.linspace(5.0, s.trajectory.duration_s - 5.0, 4):
        seen |= set(labels[sim.sweep(s.trajectory, float(t)).object_id])
    assert {"road", "sidewalk", "kerb", "building", "vehicle", "pole", "vegetation"} <= seen


# ---------------------------------------------------------------- degeneracy
def _degeneracy_at(name: str, times: np.ndarray, scene=None, sim=None):
    s = scene or default_scene(name)
    sim = sim or simulator(name)
    out = []
    for t in times:
        scan = sim.sweep(s.trajectory, float(t))
        out.append(degeneracy(scan.true_xyz, scan.normal))
    return out


def _tunnel_axis_in_lidar(scene, t: float) -> np.ndarray:
    ax, ay = scene.metadata["axis_xy"]
    axis = np.array([ax, ay, scene.params["grade_pct"] / 100.0])
    R = scene.trajectory.pose_at(np.array([t]))[0, :3, :3]
    return R.T @ (axis / np.linalg.norm(axis))


def test_tunnel_is_degenerate_along_its_axis_and_the_city_is_not():
    tunnel, city = default_scene("tunnel"), default_scene("city")
    a, b = tunnel.metadata["interior_s"]
    t_tunnel = tunnel.trajectory.time_at_distance(np.linspace(a + 50.0, b - 50.0, 9))
    t_city = np.linspace(0.1, 0.9, 9) * city.trajectory.duration_s
    d_tunnel = _degeneracy_at("tunnel", t_tunnel)
    d_city = _degeneracy_at("city", t_city)
    lam_tunnel = np.array([d.translation_eigenvalues[0] for d in d_tunnel])
    lam_city = np.array([d.translation_eigenvalues[0] for d in d_city])
    for t, d in zip(t_tunnel, d_tunnel, strict=True):
        # the weakest translation lies along the bore's axis (within 5 degrees)
        assert abs(d.weakest_translation @ _tunnel_axis_in_lidar(tunnel, float(t))) > np.cos(np.radians(5))
    # "orders of magnitude": the typical tunnel frame is at least 100 times weaker than the
    # typical city frame, and even the tunnel frame nearest a fitting 10 times weaker than
    # the city's weakest frame.
    assert np.median(lam_tunnel) * 100 <= np.median(lam_city)
    assert lam_tunnel.max() * 10 <= lam_city.min()
    # The city is not degenerate: every frame keeps at least 5% of the normals' squared
    # length in its weakest direction (an isotropic scene has 1/3).
    assert lam_city.min() >= 0.05


def test_bare_straight_bore_constrains_its_axis_only_through_the_grade():
    # Truth: in a straight bore without fittings, walls are vertical and parallel to the
    # axis, and the road and roof normals lean by the grade angle only, so the information
    # along the axis is at most sin^2(atan(grade)); the scan mid-bore sees no portal
    # (both are farther than the sensor's 200 m range).
    grade = 0.02
    s = build_scene("tunnel", feature_spacing_m=0, grade_pct=grade * 100, length_m=500.0)
    world = World(s.vertices, s.faces, s.face_object_id, s.object_labels, "bare bore")
    sim = SweepSimulator(world, load_sensor("salo32"))
    a, b = s.metadata["interior_s"]
    t = float(s.trajectory.time_at_distance((a + b) / 2)[0])
    (d,) = _degeneracy_at("tunnel", [t], scene=s, sim=sim)
    assert d.translation_eigenvalues[0] <= np.sin(np.arctan(grade)) ** 2 * (1 + 1e-6)
    assert abs(d.weakest_translation @ _tunnel_axis_in_lidar(s, t)) > np.cos(np.radians(1))


# ---------------------------------------------------------------- posts
@pytest.mark.parametrize("name, family_seed", [("tunnel", None), ("tunnel", 0), ("canyon", None), ("canyon", 101)])
def test_posts_beside_the_road_stand_in_the_ground(name, family_seed):
    # Every lamp post and sign post ("pole") reaches the surface under it, whatever that is
    # (a sidewalk, the land beyond a ditch, on a grade and a curve), and is not sunk deeper
    # than 0.45 m: rays cast down at each vertex of its lowest ring, through everything but
    # posts, plates and lamps, meet the surface 0 - 0.45 m above the vertex.
    s = default_scene(name) if family_seed is None else build_scene(name, **draw_family_params(name, family_seed))
    keep = ~np.isin(s.label_of_face(), ["pole", "sign", "light"])
    rc = Raycaster(s.vertices, s.faces[keep], threads=1)
    poles = np.flatnonzero(np.asarray(s.object_labels) == "pole")
    assert len(poles) >= 4
    for obj in poles:
        v = s.vertices[np.unique(s.faces[s.face_object_id == obj])]
        feet = v[v[:, 2] < v[:, 2].min() + 0.01]
        hits = rc.cast(feet + [0.0, 0.0, 5.0], np.tile([0.0, 0.0, -1.0], (len(feet), 1)), 20.0)
        depth = 5.0 - hits.distance  # the surface's height above the foot
        assert depth.min() >= -0.01 and depth.max() <= 0.45, (obj, feet.mean(axis=0).round(1), depth.round(3))
