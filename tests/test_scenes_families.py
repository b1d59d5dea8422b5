"""The suburb and canyon scenes and the generalisation suite's families, against constructed truth.

Suburb: the terrain's height field (the trajectory's ``surface_height``) is the
truth the road, the poses and every object must follow. Canyon: the tunnel's
requested length and bore, measured by casting rays. Families: seeded draws that
always build a world long enough for a 250-frame sequence. Small variants keep
the scene builds to a tenth of a second where the property does not need the
defaults.
"""

from __future__ import annotations

import functools
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial import ConvexHull, cKDTree

import scenes
from scenes import build_scene, families, paths
from scenes.families import FAMILIES, Choice, Family, Integers, Uniform, draw_family_params, family_scene
from simlidar.degeneracy import degeneracy
from simlidar.raycast import Raycaster
from simlidar.sensor import load_sensor
from simlidar.sweep import SweepSimulator
from simlidar.world import World

MIN_DURATION_S = 25.0  # 250 frames at 10 Hz
SMALL_SUBURB = {"loop_length_m": 350.0}
SMALL_CANYON = {"street_length_m": 60.0, "tunnel_length_m": 80.0, "exit_m": 30.0}


@functools.cache
def default_scene(name: str):
    return build_scene(name, seed=0)


def objects(scene, labels: tuple[str, ...]):
    """(label, (k, 3) vertices) of every object whose label is in ``labels``."""
    order = np.argsort(scene.face_object_id, kind="stable")
    ids = scene.face_object_id[order]
    for chunk in np.split(order, np.flatnonzero(np.diff(ids)) + 1):
        label = scene.object_labels[scene.face_object_id[chunk[0]]]
        if label in labels:
            yield label, scene.vertices[np.unique(scene.faces[chunk])]


def column_feet(v: np.ndarray) -> np.ndarray:
    """(c, 3) the lowest vertex of each vertical column (same x, y) of (k, 3) vertices."""
    _, inv = np.unique(np.round(v[:, :2], 6), axis=0, return_inverse=True)
    inv = inv.ravel()
    low = np.full(inv.max() + 1, np.inf)
    np.minimum.at(low, inv, v[:, 2])
    xy = np.zeros((len(low), 2))
    xy[inv] = v[:, :2]
    return np.column_stack([xy, low])


def path_grades(path: np.ndarray) -> np.ndarray:
    """(n,) rise over horizontal run of each segment of a closed path (n, 3)."""
    nxt = np.roll(path, -1, axis=0)
    return (nxt[:, 2] - path[:, 2]) / np.linalg.norm(nxt[:, :2] - path[:, :2], axis=1)


# ---------------------------------------------------------------- both scenes
@pytest.mark.parametrize("name, small", [("suburb", SMALL_SUBURB), ("canyon", SMALL_CANYON)])
def test_same_seed_same_world_other_seed_other_world(name, small):
    a, b = build_scene(name, seed=4, **small), build_scene(name, seed=4, **small)
    assert a.mesh_hash() == b.mesh_hash()
    t = np.linspace(0.0, a.trajectory.duration_s, 40)
    np.testing.assert_array_equal(a.trajectory.pose_at(t), b.trajectory.pose_at(t))
    assert build_scene(name, seed=5, **small).mesh_hash() != a.mesh_hash()


@pytest.mark.slow
def test_hashes_and_draws_are_the_same_in_a_fresh_interpreter():
    # Catches anything that depends on the process: set order, Python's salted str hash.
    code = ("import scenes; from scenes.families import draw_family_params as d; "
            "print(scenes.build_scene('suburb', seed=3, loop_length_m=350).mesh_hash()); "
            "print(scenes.build_scene('canyon', seed=3, street_length_m=60).mesh_hash()); "
            "print(sorted(d('canyon', 11).items())); "
            "print(scenes.build_scene('garage', seed=3, levels=2).mesh_hash()); "
            "print(scenes.build_scene('bridge', seed=3).mesh_hash())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == [
        build_scene("suburb", seed=3, loop_length_m=350).mesh_hash(),
        build_scene("canyon", seed=3, street_length_m=60).mesh_hash(),
        str(sorted(draw_family_params("canyon", 11).items())),
        build_scene("garage", seed=3, levels=2).mesh_hash(),
        build_scene("bridge", seed=3).mesh_hash(),
    ]


@pytest.mark.parametrize("name", ["suburb", "canyon"])
def test_default_scene_holds_a_250_frame_sequence(name):
    s = default_scene(name)
    assert s.trajectory.duration_s >= MIN_DURATION_S
    assert s.n_triangles <= scenes.resolve_params(name).max_triangles
    if name == "canyon":  # the default start reaches the tunnel within 220 frames
        assert s.trajectory.time_at_distance(s.metadata["portal_s"][0])[0] <= 22.0


# ---------------------------------------------------------------- suburb
@pytest.mark.parametrize("max_grade_pct", [2.0, 6.0])
def test_suburb_road_climbs_and_falls_within_the_configured_grade(max_grade_pct):
    s = build_scene("suburb", seed=2, max_grade_pct=max_grade_pct, **SMALL_SUBURB)
    g = max_grade_pct / 100
    grade = path_grades(s.path)
    # the terrain is scaled so the lane's steepest grade is the bound itself
    assert np.abs(grade).max() <= g * (1 + 1e-9)
    assert np.abs(grade).max() >= 0.999 * g
    assert grade.max() >= g / 2 and grade.min() <= -g / 2  # uphill and downhill
    assert np.ptp(s.path[:, 2]) >= 25.0 * g  # metres of relief, not a tilted plane's wobble
    # The road's mesh is at the path's height: rays cast down from 3 m above the path
    # land on the road 3 m below (to the width of the mesh's interpolation).
    rc = Raycaster(s.vertices, s.faces, threads=1)
    pts = s.path[::10]
    hits = rc.cast(pts + [0.0, 0.0, 3.0], np.tile([0.0, 0.0, -1.0], (len(pts), 1)), 10.0)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.distance, 3.0, atol=0.02)
    assert set(np.asarray(s.object_labels)[s.face_object_id[hits.face]]) == {"road"}


def test_suburb_pose_pitch_follows_the_grade():
    # Cruising (no squat or dive: acceleration and curves within reach of 10 m/s at once),
    # no suspension: the lidar's forward axis rises at the grade of the terrain itself,
    # measured along the direction of travel from the height field.
    s = build_scene("suburb", seed=3, max_grade_pct=6.0, accel_m_s2=10.0, lateral_accel_m_s2=10.0,
                    suspension_pitch_deg=0.0, suspension_heave_m=0.0, **SMALL_SUBURB)
    tr = s.trajectory
    t = np.arange(5.0, tr.duration_s - 5.0, 0.5)
    np.testing.assert_allclose(tr.speed_at(t), s.params["speed_m_s"], atol=1e-9)
    T = tr.pose_at(t)
    fwd = T[:, :2, 0] / np.linalg.norm(T[:, :2, 0], axis=1, keepdims=True)
    p = tr.road_point_at(tr.distance_at(t))[:, :2]
    h, d = tr.surface_height, 0.25
    grade = (h(*(p + d * fwd).T) - h(*(p - d * fwd).T)) / (2 * d)
    pitch_up = np.degrees(np.arcsin(T[:, 2, 0]))
    np.testing.assert_allclose(pitch_up, np.degrees(np.arctan(grade)), atol=0.05)
    assert np.ptp(pitch_up) > 4.0  # degrees: the road really climbs and falls


def test_suburb_ground_mesh_is_the_height_field():
    # Rays cast down onto the ground away from the road meet the mesh at the height field's
    # value (a 4 m grid of a smooth field: within centimetres).
    s = build_scene("suburb", seed=6, max_grade_pct=8.0, **SMALL_SUBURB)
    rng = np.random.default_rng(0)
    lo, hi = s.vertices[:, :2].min(axis=0) + 10.0, s.vertices[:, :2].max(axis=0) - 10.0
    xy = rng.uniform(lo, hi, size=(400, 2))
    z0 = s.vertices[:, 2].max() + 5.0
    hits = Raycaster(s.vertices, s.faces, threads=1).cast(
        np.column_stack([xy, np.full(len(xy), z0)]), np.tile([0.0, 0.0, -1.0], (len(xy), 1)), 1e3)
    # (beside the sidewalks the ground dips under the road's edge: keep 5 m clear of it)
    p = s.params
    clear = cKDTree(s.path[:, :2]).query(xy)[0] > p["road_width_m"] / 2 + p["sidewalk_width_m"] + p["lane_offset_m"] + 5
    on_ground = clear & hits.hit & (np.asarray(s.object_labels)[s.face_object_id[np.maximum(hits.face, 0)]]
                                    == "ground")
    assert on_ground.sum() > 200
    z_hit = z0 - hits.distance[on_ground]
    np.testing.assert_allclose(z_hit, s.trajectory.surface_height(*xy[on_ground].T), atol=0.03)


def test_suburb_houses_trees_and_cars_stand_on_the_terrain():
    # Steep ground (8 %) and dense houses, so a level foundation would float or sink.
    s = build_scene("suburb", seed=1, max_grade_pct=8.0, houses_per_100m=8.0, **SMALL_SUBURB)
    h = s.trajectory.surface_height
    counts = {}
    for label, v in objects(s, ("building", "wall", "vegetation", "vehicle", "pole")):
        counts[label] = counts.get(label, 0) + 1
        if label in ("building", "wall"):
            # Houses, garages, fences: every corner's foot 0.05-0.6 m in the ground, and so
            # the middle of every bottom edge between neighbouring corners (the ground sags).
            feet = column_feet(v)
            assert len(feet) >= 4
            depth = h(feet[:, 0], feet[:, 1]) - feet[:, 2]
            assert depth.min() >= 0.05 and depth.max() <= 0.6, (label, depth)
            ring = feet[ConvexHull(feet[:, :2]).vertices]
            mid = 0.5 * (ring + np.roll(ring, -1, axis=0))
            depth = h(mid[:, 0], mid[:, 1]) - mid[:, 2]
            assert depth.min() >= 0.05 and depth.max() <= 0.6, (label, depth)
        elif label == "vehicle":
            # a wheel in each quarter of the car (its own long and cross axes) on the road
            c = v[:, :2].mean(axis=0)
            local = (v[:, :2] - c) @ np.linalg.svd(v[:, :2] - c)[2].T
            clearance = v[:, 2] - h(v[:, 0], v[:, 1])
            for sx in (-1, 1):
                for sy in (-1, 1):
                    quarter = (np.sign(local[:, 0]) == sx) & (np.sign(local[:, 1]) == sy)
                    assert -0.05 <= clearance[quarter].min() <= 0.03
        else:  # trunks, hedges, lamp posts: the lowest ring in the ground, not deep
            feet = v[v[:, 2] < v[:, 2].min() + 0.01]
            depth = h(feet[:, 0], feet[:, 1]) - feet[:, 2]
            assert depth.min() >= 0.1 and depth.max() <= 0.45, (label, depth)
    assert counts["building"] >= 20 and counts["vehicle"] >= 5 and counts["vegetation"] >= 50
    assert counts.get("pole", 0) >= 3


def test_suburb_houses_keep_off_the_road_and_its_sidewalks():
    # Points spread over every house and roof triangle stay beyond the sidewalk's outer
    # edge: the centre-line is lane_offset_m left of the lane, the edge road_width_m / 2 +
    # sidewalk_width_m + 0.3 m (the sidewalk's bevel) from it.
    s = default_scene("suburb")
    p = s.params
    edge = p["road_width_m"] / 2 + p["sidewalk_width_m"] + 0.3
    lane = paths.resample(s.path[:, :2], 0.25, closed=True)
    tri = s.vertices[s.faces[np.isin(s.label_of_face(), ["building", "roof"])]]
    w = np.random.default_rng(0).dirichlet(np.ones(3), size=12)  # barycentric samples
    pts = np.einsum("sk,fkd->fsd", w, tri[:, :, :2]).reshape(-1, 2)
    dist = cKDTree(lane).query(np.vstack([pts, tri[:, :, :2].reshape(-1, 2)]))[0]
    assert dist.min() >= edge - p["lane_offset_m"] + 1.0  # a metre of garden at least (roof eaves)


def test_suburb_density_parameters_change_the_world():
    few = build_scene("suburb", seed=2, houses_per_100m=2.0, trees_per_100m=2.0, parked_cars_per_100m=1.0,
                      park_trees_per_ha=0.0, **SMALL_SUBURB)
    many = build_scene("suburb", seed=2, houses_per_100m=8.0, trees_per_100m=15.0, parked_cars_per_100m=8.0,
                       park_trees_per_ha=0.0, **SMALL_SUBURB)
    for key in ("houses", "trees", "parked_cars"):
        assert many.metadata[key] >= 2 * few.metadata[key] > 0, key
    park = build_scene("suburb", seed=2, houses_per_100m=2.0, trees_per_100m=2.0, parked_cars_per_100m=1.0,
                       park_trees_per_ha=40.0, **SMALL_SUBURB)
    assert park.metadata["trees"] >= few.metadata["trees"] + 100
    # houses: per 100 m of road and side, near the requested density where they fit
    per_100m = few.metadata["houses"] / (2 * few.metadata["loop_length_m"] / 100)
    assert per_100m == pytest.approx(2.0, rel=0.35)


# ---------------------------------------------------------------- canyon
@pytest.mark.parametrize("section", ["box", "arch"])
def test_canyon_tunnel_has_the_requested_length_and_an_enclosed_bore(section):
    length, height, width = 80.0, 7.0, 10.5
    s = build_scene("canyon", seed=1, tunnel_cross_section=section, tunnel_height_m=height,
                    tunnel_width_m=width, **SMALL_CANYON)
    rc = Raycaster(s.vertices, s.faces, threads=1)
    labels = np.asarray(s.object_labels)
    # Rays straight up from the road along the whole path: a roof within the bore's height
    # over one stretch only, as long as the tunnel, where the portals are.
    s_path = paths.arc_length(s.path[:, :2])
    up = rc.cast(s.path + [0.0, 0.0, 0.5], np.tile([0.0, 0.0, 1.0], (len(s.path), 1)), 1e3)
    roofed = up.hit & (up.distance <= height)
    covered = s_path[roofed]
    assert np.all(np.diff(np.flatnonzero(roofed)) == 1)  # one stretch, no hole in the roof
    assert covered[-1] - covered[0] == pytest.approx(length, abs=1.0)
    assert covered[0] == pytest.approx(s.metadata["portal_s"][0], abs=1.0)
    assert not up.hit[s_path < covered[0] - 1.0].any()  # the street is open to the sky
    # Inside, a fan of rays across the bore from the sensor (up and to both sides, and
    # 20 degrees fore and aft of that plane) all meet the lining, a fitting or the
    # walkway within the bore: nothing lets a ray out of the tunnel.
    a, b = s.metadata["interior_s"]
    t = s.trajectory.time_at_distance(np.linspace(a + 5.0, b - 5.0, 5))
    bound = np.hypot(width / 2 + s.params["lane_offset_m"], height) / np.cos(np.radians(20.0)) + 0.1
    ang = np.radians(np.linspace(-5.0, 185.0, 39))
    for T in s.trajectory.pose_at(t):
        dirs = []
        for tilt in np.radians([-20.0, 0.0, 20.0]):
            local = np.stack([np.full_like(ang, np.sin(tilt)), np.cos(tilt) * np.cos(ang),
                              np.cos(tilt) * np.sin(ang)], 1)  # lidar frame: x ahead, y left, z up
            dirs.append(local @ T[:3, :3].T)
        dirs = np.vstack(dirs)
        hits = rc.cast(T[:3, 3], dirs, 1e3)
        assert hits.hit.all() and hits.distance.max() <= bound
        hit_labels = labels[s.face_object_id[hits.face]]
        assert set(hit_labels) <= {"wall", "light", "object", "sign", "sidewalk"}
        assert np.mean(hit_labels == "wall") > 0.8


def test_canyon_is_weak_along_the_street_and_degenerate_along_the_tunnel():
    # Scans of the default canyon (salo32): in the street the weakest translation is along
    # the direction of travel; in the tunnel along its axis, and at least five times weaker.
    s = default_scene("canyon")
    sim = SweepSimulator(World(s.vertices, s.faces, s.face_object_id, s.object_labels, "canyon"),
                         load_sensor("salo32"), seed=0)
    tr, md = s.trajectory, s.metadata
    axis = np.array([*md["axis_xy"], s.params["grade_pct"] / 100])
    axis /= np.linalg.norm(axis)

    def weakest(distances):
        out = []
        for t in tr.time_at_distance(np.asarray(distances)):
            scan = sim.sweep(tr, float(t))
            d = degeneracy(scan.true_xyz, scan.normal)
            R = tr.pose_at(np.array([t]))[0, :3, :3]
            out.append((d.translation_eigenvalues[0], d.weakest_translation, R))
        return out

    street = weakest(np.linspace(30.0, md["portal_s"][0] - 50.0, 3))
    bore = weakest(np.linspace(md["interior_s"][0] + 30.0, md["interior_s"][1] - 30.0, 3))
    for _, w, _ in street:
        assert abs(w[0]) > np.cos(np.radians(10))  # lidar x: ahead
    for _, w, R in bore:
        assert abs(w @ (R.T @ axis)) > np.cos(np.radians(5))
    assert max(lam for lam, _, _ in bore) * 5 <= min(lam for lam, _, _ in street)


def test_canyon_facade_relief_adds_along_track_structure():
    # Flat facades are plain walls: every building face is vertical along the street or
    # horizontal; with relief, piers, shop fronts and balconies add faces across it.
    def across_share(relief):
        s = build_scene("canyon", seed=2, facade_relief=relief, **SMALL_CANYON)
        tri = s.vertices[s.faces[s.label_of_face() == "building"]]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = np.linalg.norm(n, axis=1)
        facing_x = np.abs(n[:, 0]) / np.maximum(area, 1e-12) > 0.9  # the street runs along x
        # seen from the street: faces whose centre is within 3 m of the building line, past the
        # building closing the street's end (x = 0) and before the portal
        bl = s.params["street_width_m"] / 2 + s.params["sidewalk_width_m"]
        c = tri.mean(axis=1)
        front = (np.abs(np.abs(c[:, 1]) - bl) < 3.0) & (c[:, 0] > 1.0) & (c[:, 0] < s.metadata["portal_s"][0])
        return area[facing_x & front].sum() / area[front].sum()

    assert across_share(0.0) < 0.005 < 0.04 < across_share(1.0)


# ---------------------------------------------------------------- families
def test_families_are_the_suite_and_their_ranges_fit_the_scenes():
    # appended at the end: a family's place in the tuple sets its suite sensors (tools.family_suite)
    assert FAMILIES == ("city", "suburb", "canyon", "tunnel", "highway", "open", "forest", "garage", "bridge")
    for name in FAMILIES:
        fam = families.family(name)
        assert family_scene(name) == fam.scene and fam.scene in scenes.SCENES
        info = {p.name: p for p in scenes.scene_parameters(fam.scene)}
        assert len(fam.ranges) >= 4 and "speed_m_s" in fam.ranges
        for key, rng in fam.ranges.items():
            p = info[key]  # a parameter of the scene
            values = list(rng.options) if isinstance(rng, Choice) else [rng.lo, rng.hi]
            if p.choices:
                assert set(values) <= set(p.choices), (name, key)
            else:
                assert (p.min is None or min(values) >= p.min) and (p.max is None or max(values) <= p.max)
    with pytest.raises(ValueError, match="'mars'"):
        draw_family_params("mars", 0)


def test_draws_are_deterministic_vary_with_the_seed_and_cover_the_ranges():
    for name in FAMILIES:
        draws = [draw_family_params(name, seed) for seed in range(20)]
        assert draws == [draw_family_params(name, seed) for seed in range(20)]
        assert [d["seed"] for d in draws] == list(range(20))
        assert len({tuple(sorted((k, v) for k, v in d.items() if k != "seed")) for d in draws}) == 20
        for key, rng in families.family(name).ranges.items():
            values = [d[key] for d in draws]
            if isinstance(rng, Choice):
                assert set(values) <= set(rng.options)
            else:
                assert min(values) >= rng.lo and max(values) <= rng.hi
                assert max(values) - min(values) >= 0.5 * (rng.hi - rng.lo), (name, key)
                if isinstance(rng, Integers):
                    assert all(type(v) is int for v in values)
        for d in draws:
            scenes.resolve_params(family_scene(name), **d)  # valid, cross-checks included


def test_draws_are_clipped_to_the_parameter_bounds(monkeypatch):
    wide = Family("open", {"roughness_m": Uniform(-100.0, 120.0), "rocks": Uniform(-10.0, 0.4),
                           "speed_m_s": Choice((200.0,))})
    monkeypatch.setitem(families._FAMILIES, "wide", wide)
    draws = [draw_family_params("wide", seed) for seed in range(20)]
    assert {d["speed_m_s"] for d in draws} == {60.0}  # the scene's maximum
    assert all(0.0 <= d["roughness_m"] <= 20.0 for d in draws) and {0.0, 20.0} <= {d["roughness_m"] for d in draws}
    assert {d["rocks"] for d in draws} == {0} and all(type(d["rocks"]) is int for d in draws)


@pytest.mark.slow
@pytest.mark.parametrize("name", FAMILIES)
def test_every_draw_builds_a_world_for_a_250_frame_sequence(name):
    for seed in range(20):
        overrides = draw_family_params(name, seed)
        s = build_scene(family_scene(name), **overrides)
        assert s.trajectory.duration_s >= MIN_DURATION_S, (seed, overrides)
