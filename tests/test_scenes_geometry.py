"""Mesh parts against constructed truth: winding, areas, the builder's object ids."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import MeshBuilder
from scenes import geometry as g
from simlidar.raycast import Raycaster


def _fibonacci(n: int) -> np.ndarray:
    golden = np.pi * (3.0 - np.sqrt(5.0))
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(golden * k), r * np.sin(golden * k), z], axis=1)


def test_l_shaped_prism_faces_outward():
    # An L of two 10 m arms, 6 m tall: rays from outside see only front faces, rays from
    # inside (in the L's corner cell, mid-height) only back faces (the base is open).
    xs, ys = np.array([0.0, 5.0, 10.0]), np.array([0.0, 5.0, 10.0])
    mask = np.array([[1, 1], [1, 0]], dtype=bool)
    v, f = g.grid_prism(xs, ys, mask, 0.0, 6.0)
    rc = Raycaster(v, f, threads=1)
    dirs = _fibonacci(500)
    for origin in ([-20.0, 3.0, 3.0], [8.0, 8.0, 3.0], [5.0, -15.0, 10.0], [8.0, 8.0, 20.0]):
        hits = rc.cast(np.array(origin), dirs, 1e3)
        assert hits.hit.any() and not hits.back_face[hits.hit].any()
    hits = rc.cast(np.array([2.5, 2.5, 3.0]), dirs, 1e3)
    up_and_sideways = dirs[:, 2] > -0.2
    assert np.all(hits.hit[up_and_sideways]) and np.all(hits.back_face[hits.hit])
    # the top covers the three occupied cells (75 m^2), the wall runs the L's 40 m perimeter
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    top = tri[:, :, 2].min(axis=1) == 6.0
    assert area[top].sum() == pytest.approx(75.0) and area[~top].sum() == pytest.approx(40.0 * 6.0)


def test_sweep_orientation_rules():
    # Along +x: a profile running right-to-left (l increasing) faces up; one running up faces right.
    centres = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    lefts = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    for profile, expected in (([[-1.0, 0.0], [1.0, 0.0]], [0, 0, 1]), ([[0.0, 0.0], [0.0, 1.0]], [0, -1, 0])):
        v, f = g.sweep(centres, lefts, np.array(profile))
        tri = v[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        np.testing.assert_allclose(n / np.linalg.norm(n, axis=1, keepdims=True), np.tile(expected, (len(f), 1)),
                                   atol=1e-12)


def test_wall_strip_faces_out_of_a_counter_clockwise_loop():
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    v, f = g.wall_strip(square, 0.0, 1.0, closed=True)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = tri.mean(axis=1)[:, :2] - [2.0, 2.0]
    assert len(f) == 8 and np.all(np.einsum("ij,ij->i", n[:, :2], outward) > 0)


def test_stitched_band_tiles_the_region_between_two_arcs():
    # Half-annulus between radii 1 and 2: area 3 pi / 2 (polygons: slightly less), no fold.
    a = np.linspace(np.pi, 0.0, 60)
    inner = np.stack([np.cos(a), np.sin(a)], 1)
    b = np.linspace(np.pi, 0.0, 21)
    outer = 2.0 * np.stack([np.cos(b), np.sin(b)], 1)
    faces = g.stitch_chains(inner, outer, np.array([0.0, 0.0]))
    pts = np.vstack([inner, outer])
    e1, e2 = pts[faces[:, 1]] - pts[faces[:, 0]], pts[faces[:, 2]] - pts[faces[:, 0]]
    signed = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert np.all(signed < 0) or np.all(signed > 0)  # one orientation: nothing folds over
    poly_area = 0.5 * (4.0 * 20 * np.sin(np.pi / 20) - 59 * np.sin(np.pi / 59))  # outer - inner polygons
    assert np.abs(signed).sum() == pytest.approx(poly_area, rel=1e-9)


def test_builder_assigns_object_ids_and_rejects_unknown_labels():
    mb = MeshBuilder()
    a = mb.add_object(*g.box((1, 1, 1)), "vehicle")
    b = mb.new_object("pole")
    mb.add(*g.cylinder(0.1, 3.0), b)
    mb.add(*g.box((0.2, 0.2, 0.2), (0, 0, 3)), b)
    v, f, ids, labels = mb.arrays()
    assert labels == ["vehicle", "pole"] and (a, b) == (0, 1)
    assert (ids == 0).sum() == 12 and (ids == 1).sum() == len(f) - 12
    assert f.max() == len(v) - 1
    with pytest.raises(ValueError, match="tree"):
        mb.new_object("tree")


def test_smooth_field_has_the_requested_spread():
    # Eight plane waves with random directions: over a wide area the field's standard
    # deviation is the requested amplitude (the sum of the waves' mean squares).
    field = g.SmoothField(np.random.default_rng(0), 0.5, (50.0, 200.0))
    x, y = np.meshgrid(np.linspace(-5000, 5000, 400), np.linspace(-5000, 5000, 400))
    z = field(x.ravel(), y.ravel())
    assert z.std() == pytest.approx(0.5, rel=0.05)
    assert np.abs(z.mean()) < 0.05


def test_smooth_field_gradient_and_scaling_are_exact():
    # The analytic slope against central differences (a smooth field: 1e-3 m steps leave
    # ~1e-7 of truncation), and a scaled copy's values and slopes scale with it.
    field = g.SmoothField(np.random.default_rng(1), 2.0, (60.0, 300.0))
    xy = np.random.default_rng(2).uniform(-500.0, 500.0, size=(50, 2))
    h = 1e-3
    fd = np.stack([(field(xy[:, 0] + h, xy[:, 1]) - field(xy[:, 0] - h, xy[:, 1])) / (2 * h),
                   (field(xy[:, 0], xy[:, 1] + h) - field(xy[:, 0], xy[:, 1] - h)) / (2 * h)], axis=1)
    np.testing.assert_allclose(field.gradient(xy[:, 0], xy[:, 1]), fd, atol=1e-7)
    assert np.abs(fd).max() > 0.01  # the field does slope
    half = field.scaled(0.5)
    np.testing.assert_allclose(half(xy[:, 0], xy[:, 1]), 0.5 * field(xy[:, 0], xy[:, 1]), rtol=1e-12)
    np.testing.assert_allclose(half.gradient(xy[:, 0], xy[:, 1]), 0.5 * fd, atol=1e-7)


def test_tilted_part_lies_on_the_slope():
    # A flat 4 m x 2 m plate pitched by -atan(0.1) and rolled by atan(0.05), heading 30 deg:
    # its corners lie on the plane rising 0.1 per metre ahead and 0.05 per metre to the left.
    plate = (np.array([[-2.0, -1.0, 0.0], [2.0, -1.0, 0.0], [2.0, 1.0, 0.0], [-2.0, 1.0, 0.0]]),
             np.array([[0, 1, 2], [0, 2, 3]]))
    yaw = np.radians(30.0)
    v, _ = g.place_tilted(plate, yaw, -np.arctan(0.1), np.arctan(0.05), (5.0, 6.0, 1.0))
    fwd, left = np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])
    rel = v[:, :2] - [5.0, 6.0]
    # exact for pitch alone; rolling after pitching tilts the forward slope by a second-order term
    np.testing.assert_allclose(v[:, 2], 1.0 + 0.1 * (rel @ fwd) + 0.05 * (rel @ left), atol=2e-3)
    same, _ = g.place_tilted(plate, yaw, 0.0, 0.0, (5.0, 6.0, 1.0))
    np.testing.assert_allclose(same, g.place(plate, yaw, (5.0, 6.0, 1.0))[0], atol=1e-12)
