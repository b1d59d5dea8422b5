"""Worlds stacked on themselves (the garage and the bridge), against the geometry they are declared with.

Rays cast through the built mesh measure what the parameters say: floor-to-floor heights,
slab thickness, the clear height under the beams, the headroom over the drive, a helix's
turns and the stacked ramps one floor apart, open and closed sides; the bridge's deck above
the drive where it passes under and below it where it passes over. The drives climb and
turn within their design: no kink (a spike of curvature or of vertical curvature) anywhere.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from scenes import build_scene, paths
from scenes.families import draw_family_params, family_scene
from simlidar.raycast import Raycaster

UP, DOWN = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])


@functools.cache
def garage(**overrides):
    return build_scene("garage", seed=2, **overrides)


@functools.cache
def bridge(**overrides):
    return build_scene("bridge", seed=2, **overrides)


def cast(scene, origins, direction, far=1e3):
    """(distance (n,), label (n,)) of rays from (n, 3) ``origins`` along one ``direction`` (3,);
    distance inf and label "" where nothing is hit."""
    origins = np.atleast_2d(np.asarray(origins, dtype=float))
    hits = Raycaster(scene.vertices, scene.faces, threads=1).cast(origins, np.tile(direction, (len(origins), 1)), far)
    labels = np.where(hits.hit, np.asarray(scene.object_labels)[scene.face_object_id[np.maximum(hits.face, 0)]], "")
    return np.where(hits.hit, hits.distance, np.inf), labels


def aisle_a(scene) -> float:
    p = scene.params
    return p["stall_depth_m"] + p["aisle_width_m"] / 2


# ---------------------------------------------------------------- garage
def test_garage_floors_slabs_and_clear_height_are_the_declared_ones():
    s = garage()
    p, m = s.params, s.metadata
    t, b, clear = p["slab_thickness_m"], p["beam_depth_m"], p["clear_height_m"]
    floor_to_floor = clear + b + t
    np.testing.assert_allclose(m["levels_z"], floor_to_floor * np.arange(p["levels"]))
    x_top, y = m["ramp_x"][0], aisle_a(s)
    pillar_x = x_top + p["pillar_spacing_m"] * np.arange(p["bays"] + 1)
    mid_bay = pillar_x[:-1] + 0.3 * p["pillar_spacing_m"]  # clear of the beams and the lights
    for z in m["levels_z"][:-1]:
        # up from each covered floor: the slab's underside between the beams, the beams' at the pillar lines
        d, lab = cast(s, np.column_stack([mid_bay, np.full(len(mid_bay), y), np.full(len(mid_bay), z + 0.01)]), UP)
        np.testing.assert_allclose(d, clear + b - 0.01, atol=1e-6)
        assert set(lab) == {"building"}
        d, _ = cast(s, np.column_stack([pillar_x, np.full(len(pillar_x), y), np.full(len(pillar_x), z + 0.01)]), UP)
        np.testing.assert_allclose(d, clear - 0.01, atol=1e-6)
        # down from just under the next slab: this floor, clear + beam depth below
        top = np.column_stack([mid_bay, np.full(len(mid_bay), y), np.full(len(mid_bay), z + clear + b - 0.01)])
        d, lab = cast(s, top, DOWN)
        np.testing.assert_allclose(d, clear + b - 0.01, atol=1e-6)
        assert set(lab) == {"road"}
    # the roof deck is open to the sky and, from above, is the top slab
    roof = m["levels_z"][-1]
    d, lab = cast(s, np.column_stack([mid_bay, np.full(len(mid_bay), y), np.full(len(mid_bay), roof)]) + 0.01 * UP, UP)
    assert np.all(np.isinf(d))
    d, lab = cast(s, np.column_stack([mid_bay, np.full(len(mid_bay), y), np.full(len(mid_bay), roof + 50.0)]), DOWN)
    np.testing.assert_allclose(d, 50.0, atol=1e-6)
    assert set(lab) == {"road"}


@pytest.mark.parametrize("route", ["ramps_up", "helix_up"])
def test_garage_drive_keeps_its_headroom_and_rides_on_the_floors(route):
    # At every 10 Hz frame: the surface under the lidar is a floor, a ramp or the helix, at the
    # mount height; above it, where anything is, at least clear height - mount height.
    s = garage(route=route)
    p = s.params
    tr = s.trajectory
    poses = tr.pose_at(np.arange(0.0, tr.duration_s, 0.1))
    road = tr.road_point_at(tr.distance_at(np.arange(0.0, tr.duration_s, 0.1)))
    d, lab = cast(s, road + 0.5 * UP, DOWN)
    np.testing.assert_allclose(d, 0.5, atol=0.01)
    assert set(lab) == {"road"}
    d, lab = cast(s, poses[:, :3, 3], UP)
    covered = np.isfinite(d)
    assert covered.mean() > 0.3  # most of a garage drive is under a slab
    assert d[covered].min() >= p["clear_height_m"] - p["mount_height_m"] - 0.02  # suspension and pitch
    # slabs, beams, lights; a ramp or a turn above; the walls of the floor above the entrance
    assert set(lab[covered]) <= {"building", "light", "wall"}


def test_garage_drive_climbs_every_floor_and_comes_back_down():
    s = garage()
    p, m = s.params, s.metadata
    z = s.path[:, 2]
    floor_to_floor = m["levels_z"][1]
    assert z[0] == z[-1] == 0.0 and z.max() == pytest.approx(m["levels_z"][-1], abs=1e-9)
    # the drive dwells on every floor (level stretches: the aisles and the turns)
    for level in m["levels_z"]:
        assert np.sum(np.abs(z - level) < 1e-9) * 0.5 > 50.0
    # up the straight ramps at their grade, down the helix at its own
    s_h = paths.arc_length(s.path[:, :2])
    grade = np.diff(z) / np.diff(s_h)
    assert grade.max() == pytest.approx(p["ramp_grade_pct"] / 100, rel=1e-3)
    # (smoothing the turns' ends draws the helix's circle 0.1 m in: its horizontal run 1 % shorter)
    assert -grade.min() == pytest.approx(m["helix_grade"], rel=0.02)
    assert m["ramp_grade"] == pytest.approx(p["ramp_grade_pct"] / 100, rel=1e-9)
    # the helix: where the drive passes its tangent point it is a floor apart each turn
    cx, cy = m["helix_centre"]
    at_tangent = np.linalg.norm(s.path[:, :2] - [cx, cy + p["helix_radius_m"]], axis=1) < 0.3
    heights = np.unique(np.round(z[at_tangent], 6))
    np.testing.assert_allclose(np.diff(heights), floor_to_floor, atol=1e-6)
    assert len(heights) == p["levels"]
    # "helix_up" drives the same path the other way
    np.testing.assert_array_equal(garage(route="helix_up").path, s.path[::-1])


def test_garage_ramps_and_helix_turns_are_stacked_a_floor_apart():
    # Straight up from the drive on a lower ramp or helix turn: the next one's underside,
    # floor-to-floor minus the slab above the road.
    s = garage()
    p, m = s.params, s.metadata
    headroom = p["clear_height_m"] + p["beam_depth_m"]
    z = s.path[:, 2]
    top = m["levels_z"][-1]
    x_top, x_foot = m["ramp_x"]
    cx, cy = m["helix_centre"]
    in_helix = np.abs(np.linalg.norm(s.path[:, :2] - [cx, cy], axis=1) - p["helix_radius_m"]) < 0.5
    on_ramps = (s.path[:, 0] > x_top + 1.0) & (s.path[:, 0] < x_foot - 1.0) & (np.abs(s.path[:, 1] - aisle_a(s)) > 1)
    for where in (in_helix, on_ramps):
        below_top = where & (z < top - m["levels_z"][1] - 0.01)  # a turn or a ramp runs above these
        d, lab = cast(s, s.path[below_top] + 0.01 * UP, UP)
        np.testing.assert_allclose(d, headroom - 0.01, atol=0.01)
        assert set(lab) == {"building"}
        assert below_top.sum() > 40


@pytest.mark.parametrize("sides, walled", [("none", ()), ("ground", (0,)), ("covered", (0, 1))])
def test_garage_sides_are_walls_or_parapets(sides, walled):
    # Rays from aisle A at 1.5 m over each floor, straight out of the south side (no cars in the
    # way): a wall's inner face at the stalls' back, or over the parapet into the open.
    s = garage(closed_sides=sides, occupancy=0.0)
    m = s.metadata
    x = m["ramp_x"][0] + 0.3 * s.params["pillar_spacing_m"]
    for k, z in enumerate(m["levels_z"]):
        d, lab = cast(s, [[x, aisle_a(s), z + 1.5]], np.array([0.0, -1.0, 0.0]))
        if k in walled:
            assert d[0] == pytest.approx(aisle_a(s), abs=1e-6) and lab[0] == "wall"
        else:
            assert np.isinf(d[0])


def test_garage_parked_cars_are_car_sized_and_stand_on_the_floors():
    s = garage(occupancy=1.0)
    levels = np.array(s.metadata["levels_z"])
    cars = np.flatnonzero(np.asarray(s.object_labels) == "vehicle")
    assert len(cars) == s.metadata["parked_cars"] > 100
    for obj in cars:
        v = s.vertices[np.unique(s.faces[s.face_object_id == obj])]
        size = np.ptp(v, axis=0)
        length, width = max(size[:2]), min(size[:2])
        assert 4.2 <= length <= 4.8 and 1.75 <= width <= 1.9 and 1.4 <= size[2] <= 1.6
        assert np.min(np.abs(levels - v[:, 2].min())) < 0.02  # its wheels on a floor (10-sided)
    half = build_scene("garage", seed=2, occupancy=0.5).metadata["parked_cars"]
    assert 0.35 * len(cars) < half < 0.65 * len(cars)
    assert build_scene("garage", seed=2, occupancy=0.0).metadata["parked_cars"] == 0


def test_garage_rules_name_their_parameter():
    with pytest.raises(ValueError, match="clear_height_m"):
        build_scene("garage", clear_height_m=2.1, mount_height_m=1.9)  # no headroom for the lidar
    with pytest.raises(ValueError, match="bays"):
        build_scene("garage", bays=3)  # too short for a ramp
    with pytest.raises(ValueError, match="helix_radius_m"):
        build_scene("garage", helix_radius_m=6.0, clear_height_m=4.0)  # too steep


# ---------------------------------------------------------------- bridge
def test_bridge_drive_passes_under_the_deck_then_over_it():
    s = bridge()
    p, m = s.params, s.metadata
    tr = s.trajectory
    under, over = tr.road_point_at(np.array([m["under_s"], m["over_s"]]))
    # under: on A's level, the deck's underside (its girders or slab) clearance_m to deck depth above
    assert under[2] == 0.0
    d, lab = cast(s, [under + 0.01 * UP], UP)
    assert p["clearance_m"] - 0.01 - 1e-6 <= d[0] <= m["deck_z"] - 0.3 and lab[0] == "building"
    # over: on the deck's top, road A straight below it (its centre-line, y = 0)
    assert over[2] == pytest.approx(m["deck_z"], abs=1e-6) and abs(over[1]) < 0.3
    d, lab = cast(s, [over + 0.01 * UP], DOWN)
    assert d[0] == pytest.approx(0.01, abs=1e-6) and lab[0] == "road"
    d, lab = cast(s, [[over[0], 3.0, 0.5]], UP)  # from A's lane below it: the deck's underside
    assert p["clearance_m"] - 0.5 - 1e-6 <= d[0] <= m["deck_z"] - 0.3 - 0.5 + 1e-6 and lab[0] == "building"
    d, lab = cast(s, [[over[0], 3.0, 0.5]], DOWN)
    assert d[0] == pytest.approx(0.5, abs=1e-6) and lab[0] == "road"
    # the same deck: both points inside its footprint, one passed under, the other driven over
    b_half, w_r = p["road_b_width_m"] / 2, p["ramp_lane_width_m"]
    for q in (under, over):
        assert -b_half <= q[0] <= b_half + w_r
    assert tr.time_at_distance(m["over_s"])[0] > tr.time_at_distance(m["under_s"])[0]


def test_bridge_loop_climbs_onto_the_deck_smoothly_and_within_its_grade():
    s = bridge()
    m = s.metadata
    z = s.path[:, 2]
    s_h = paths.arc_length(s.path[:, :2])
    grade = np.gradient(z, s_h)
    # (smoothing the loop's ends draws its circle 0.1 m in: its horizontal run a little shorter)
    assert grade.max() <= 0.08 * 1.01 and grade.max() == pytest.approx(m["loop_grade"], rel=0.01)
    i0, i1 = np.searchsorted(s_h, m["loop_s"])
    assert z[i0] == 0.0 and z[i1] > 0.8 * m["deck_z"]
    assert np.all(np.diff(z[i0:i1 + 1]) >= -1e-12)  # climbing all the way round


@pytest.mark.parametrize("name", ["garage", "bridge"])
def test_drives_have_no_kink_in_plan_or_profile(name):
    # The speed profile slows the vehicle wherever the path's curvature peaks, so a kink shows as
    # a crawl: the vehicle never drops below what the tightest turn designed allows (the U-turns
    # and the helix, the loop) once under way. In profile, the vertical curvature stays within
    # the cosine grade transitions' (pi / 2 x grade change / transition length).
    s = build_scene(name, seed=2, accel_m_s2=10.0)
    p, tr = s.params, s.trajectory
    t = np.arange(1.0, tr.duration_s - 1.0, 0.05)
    if name == "garage":
        aw, sd = p["aisle_width_m"], p["stall_depth_m"]
        r_min = min((2 * sd + aw) / 2, p["helix_radius_m"])
        curve = np.pi / 2 * max(p["ramp_grade_pct"] / 100, s.metadata["helix_grade"]) / p["ramp_transition_m"]
    else:
        r_min = p["loop_radius_m"]
        # the loop's 15 m transitions (from level to its grade, from it to B's), B's 20 m ones
        curve = np.pi / 2 * max(s.metadata["loop_grade"], p["b_grade_pct"] / 100) / 15.0
    v_turn = min(p["speed_m_s"], np.sqrt(p["lateral_accel_m_s2"] * r_min))
    assert tr.speed_at(t).min() >= 0.97 * v_turn
    dist = np.arange(2.0, tr.length_m - 2.0, 0.1)
    zr = tr.road_point_at(dist)[:, 2]
    assert np.abs(np.diff(zr, 2)).max() / 0.1**2 <= 1.05 * curve


def test_bridge_rule_names_the_loop_radius():
    with pytest.raises(ValueError, match="loop_radius_m"):
        build_scene("bridge", loop_radius_m=14.0, clearance_m=6.0)


@pytest.mark.slow
def test_every_bridge_draw_passes_under_and_over_within_a_suite_sequence():
    # The suite's sequences are 20 s long and centred on the crossing: both must fit.
    for seed in range(20):
        s = build_scene(family_scene("bridge"), **draw_family_params("bridge", seed))
        m, tr = s.metadata, s.trajectory
        t_under, t_over = tr.time_at_distance(np.array([m["under_s"], m["over_s"]]))
        assert t_over - t_under <= 19.5, seed
