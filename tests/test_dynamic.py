"""The moving-object stage (``odometry.dynamic``, ``dynamic.enabled``) against the simulator's truth.

A car-sized box drives past a still sensor in a walled yard: the stage must drop most of its returns
(once a recent scan saw its place free), few static ones, and the estimate must stay where the noise
alone would leave it. The compiled passes against their numpy references; the rows a scan keeps.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from odometry.config import DynamicParams, variant
from odometry.dynamic import FreeSpace, checked_lags, drop_rows
from odometry.filters import FilteredScan
from odometry.kernels.free_space import nearest_per_cell, seen_through
from odometry.pipeline import Odometry, OdometryError
from simlidar import se3
from simlidar.sensor import LidarModel
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.world import World
from tools.moving_returns import RejectionCounts, returns_dropped

SENSOR_HEIGHT_M = 1.8
CAR_SIZE_M = (4.5, 1.8, 1.5)


class _Model:
    def __init__(self, size):
        b = trimesh.creation.box(extents=size)
        b.apply_translation((0.0, 0.0, size[2] / 2))
        self.name, self.vertices, self.faces = "car", np.asarray(b.vertices), np.asarray(b.faces)
        self.box_centre, self.box_size = np.array([0.0, 0.0, size[2] / 2]), np.asarray(size, float)


class _Driving:
    """A car on the ground driving along x at a constant speed: T(t) = T0 exp(t xi)."""

    label, behaviour, kind, time_span_s = "vehicle", "test", "car", (-100.0, 100.0)

    def __init__(self, x0: float, y: float, speed_m_s: float):
        self.model = _Model(CAR_SIZE_M)
        self.T0 = np.eye(4)
        self.T0[:3, 3] = (x0, y, -SENSOR_HEIGHT_M)
        self.xi = np.array([speed_m_s, 0, 0, 0, 0, 0.0])

    def motion_at(self, times):
        t = np.atleast_1d(np.asarray(times, float))
        T = self.T0 @ se3.exp(t[:, None] * self.xi[None])
        R = T[:, :3, :3]
        return T, R @ self.xi[:3], R @ self.xi[3:]


def _yard(actors) -> World:
    """Ground 1.8 m below the sensor, walls 20 m away all round, and posts: enough to hold a pose."""
    parts = []
    ground = trimesh.creation.box((80.0, 80.0, 1.0))
    ground.apply_translation((0.0, 0.0, -SENSOR_HEIGHT_M - 0.5))
    parts.append(ground)
    for x, y, sx, sy in ((20.0, 0.0, 0.5, 40.0), (-20.0, 0.0, 0.5, 40.0), (0.0, 20.0, 40.0, 0.5),
                         (0.0, -20.0, 40.0, 0.5)):
        wall = trimesh.creation.box((sx, sy, 6.0))
        wall.apply_translation((x, y, 3.0 - SENSOR_HEIGHT_M))
        parts.append(wall)
    rng = np.random.default_rng(3)
    for x, y in rng.uniform(-17.0, 17.0, (12, 2)):
        if abs(y - 7.0) < 3.0 or math.hypot(x, y) < 4.0:  # (not on the car's lane, not at the sensor)
            continue
        post = trimesh.creation.box((0.6, 0.6, 4.0))
        post.apply_translation((x, y, 2.0 - SENSOR_HEIGHT_M))
        parts.append(post)
    mesh = trimesh.util.concatenate(parts)
    return World(mesh.vertices, mesh.faces, np.zeros(len(mesh.faces), np.int32), ["building"], "yard",
                 actors=actors)


def _sensor(noise_m: float) -> LidarModel:
    # 16 rings from -8 to +8 deg: the lowest meets the ground 12.8 m out, behind the car's lane (7 m)
    return LidarModel(name="yard16", vertical_angles_deg=tuple(np.linspace(-8.0, 8.0, 16)), azimuth_step_deg=0.4,
                      rotation_hz=10.0, range_noise_std_m=noise_m, min_range_m=0.5, max_range_m=100.0)


STILL = SampledTrajectory(np.array([0.0]), np.eye(4)[None])
FRAMES = 30
SPEED_M_S = 8.0


def _sweeps(with_car: bool, noise_m: float = 0.02):
    world = _yard([_Driving(-14.0, 7.0, SPEED_M_S)] if with_car else [])
    sensor = _sensor(noise_m)
    sim = SweepSimulator(world, sensor, seed=5)
    return sensor, [sim.sweep(STILL, k * sensor.sweep_period_s, frame_index=k) for k in range(FRAMES)]


def _run(sensor, sweeps, enabled: bool):
    """The default with the stage on or off over the sweeps; (poses (N, 4, 4), counts of the truth's verdicts
    per frame: a ``RejectionCounts`` each, the odometry's last frames' diagnostics)."""
    config = variant("salo-map").replace(dynamic={"enabled": enabled})
    odo = Odometry(config, sensor)
    counts = []
    for k, scan in enumerate(sweeps):
        prepared = odo.prepare(scan.xyz, scan.time_s, scan.ring, first=k == 0)
        odo.register_prepared(prepared, stamp_s=k * sensor.sweep_period_s)
        c = RejectionCounts()
        rows = prepared.clean.kept_rows
        moving = np.zeros(len(scan.xyz), bool) if scan.moving is None else scan.moving
        c.add(moving[rows], returns_dropped(prepared.clean.points, prepared.moving,
                                                 config.filter.voxel_size_m), None)
        counts.append(c)
    return np.stack(odo.poses), counts, odo.diagnostics


@pytest.fixture(scope="module")
def passing_car():
    sensor, sweeps = _sweeps(with_car=True)
    return sensor, sweeps, _run(sensor, sweeps, enabled=True)


def test_the_stage_drops_the_passing_cars_returns_and_few_static_ones(passing_car):
    sensor, sweeps, (_, counts, _) = passing_car
    # Once the history holds a scan from before the car reached its place (its length and the window's
    # reach behind it: 8 frames at 8 m/s is 6.4 m), every one of its returns stands where a checked scan
    # saw the ground or a wall far behind it (the lowest ring meets the ground 12.8 m out, the car's
    # far side is within 10 m): the stage should drop all of them but the odd return at a window's edge.
    settled = 1 + max(lag for lag in checked_lags(DynamicParams().history_frames) if lag * 0.1 * SPEED_M_S
                      <= CAR_SIZE_M[0] + 2.0)
    late = RejectionCounts()
    for c in counts[settled + 1:]:
        late.moving += c.moving
        late.moving_dropped += c.moving_dropped
        late.static += c.static
        late.static_dropped += c.static_dropped
    assert late.moving > 1000  # (the car is in view all along)
    assert late.moving_kept_fraction < 0.05
    # Even the first frames after the first drop most: the car's front moves into space seen free a frame ago
    early = sum(c.moving_dropped for c in counts[2:settled + 1]) / sum(c.moving for c in counts[2:settled + 1])
    assert early > 0.3
    # Static returns are never where a beam went through, unless they share a voxel with the car (its
    # centroid dropped): the ground beside its wheels. The range noise (2 cm) is 25 sigma below the margin.
    assert late.static_dropped_fraction < 0.005
    assert counts[0].moving_dropped == counts[1].moving_dropped == 0  # (nothing to compare the first two with)


def _standstill_bound_m(diagnostics, noise_m: float) -> float:
    """Five sigma of a frame's translation error from the noise alone: the range noise over the root of the
    information the weakest translational direction holds (matches x its eigenvalue per match), doubled for
    the map's own noisy points, floored by the ICP's termination step (1 mm: it stops below that)."""
    sigma = max(noise_m * math.sqrt(2.0) / math.sqrt(d.matches["trimmed"] * d.translation_eigenvalues[0])
                for d in diagnostics[2:])
    return 5.0 * sigma + 1e-3


def test_the_estimate_stands_still_within_the_noise_while_the_car_passes(passing_car):
    sensor, sweeps, (poses, _, diagnostics) = passing_car
    bound = _standstill_bound_m(diagnostics, sensor.range_noise_std_m)
    drift = np.linalg.norm(poses[:, :3, 3], axis=1)
    assert drift.max() < bound, (drift.max(), bound)


def test_without_the_stage_the_poses_are_those_of_the_default_bit_for_bit():
    sensor, sweeps = _sweeps(with_car=True)
    off, _, _ = _run(sensor, sweeps[:8], enabled=False)
    odo = Odometry(variant("salo-map"), sensor)
    for k, scan in enumerate(sweeps[:8]):
        odo.register(scan.xyz, scan.time_s, scan.ring, stamp_s=k * sensor.sweep_period_s)
    assert np.array_equal(off, np.stack(odo.poses))


def test_the_stage_needs_the_sensor():
    with pytest.raises(OdometryError, match="dynamic.enabled"):
        Odometry(variant("salo-map").replace(dynamic={"enabled": True}, gcr={"enabled": False}), None)


# ---- the compiled passes against their numpy references
def _reference_image(points, times, elevations, low, high, columns):
    mid = 0.5 * (elevations[1:] + elevations[:-1])
    el = np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1]))
    col = np.minimum(((np.arctan2(points[:, 1], points[:, 0]) + np.pi) * (columns / (2 * np.pi))).astype(int),
                     columns - 1)
    inside = (el >= low) & (el <= high)
    image = np.full((len(elevations), columns), np.inf)
    np.minimum.at(image, (np.searchsorted(mid, el)[inside], col[inside]), np.linalg.norm(points, axis=1)[inside])
    return image, np.bincount(col, times, columns), np.bincount(col, minlength=columns)


def test_the_compiled_image_is_numpys():
    rng = np.random.default_rng(0)
    points = rng.normal(0, 10, (5000, 3))
    times = rng.uniform(0, 1, 5000)
    elevations = np.radians(np.linspace(-20, 10, 24))
    mid = 0.5 * (elevations[1:] + elevations[:-1])
    got = nearest_per_cell(points, times, mid, -0.4, 0.2, 360)
    want = _reference_image(points, times, elevations, -0.4, 0.2, 360)
    assert np.array_equal(np.isinf(got[0]), np.isinf(want[0]))
    assert np.allclose(got[0][np.isfinite(got[0])], want[0][np.isfinite(want[0])], rtol=1e-12, atol=0)
    assert np.allclose(got[1], want[1]) and np.array_equal(got[2], want[2])


def test_the_compiled_test_is_numpys():
    rng = np.random.default_rng(1)
    points = rng.normal(0, 15, (4000, 3))
    elevations = np.radians(np.linspace(-20, 10, 24))
    mid = 0.5 * (elevations[1:] + elevations[:-1])
    nearest = rng.uniform(0, 40, (24, 360))
    fraction = rng.uniform(0, 1, 360)
    xi = np.array([0.8, 0.1, 0.0, 0.0, 0.0, 0.05])
    T = se3.exp(np.array([1.0, -2.0, 0.3, 0.0, 0.01, 0.2]))
    count = np.zeros(len(points), dtype=np.int64)
    seen_through(points, np.ascontiguousarray(T[:3, :3]), T[:3, 3].copy(), xi, fraction, nearest, mid, -0.4, 0.2,
                 0.5, count)
    # numpy: into the sweep-start frame, then back along the frame's motion to the column's time (first order)
    p = se3.transform_points(T, points)
    col = np.minimum(((np.arctan2(p[:, 1], p[:, 0]) + np.pi) * (360 / (2 * np.pi))).astype(int), 359)
    s = fraction[col][:, None]
    p = p - s * (xi[:3] + np.cross(xi[3:], p))
    el = np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]))
    col = np.minimum(((np.arctan2(p[:, 1], p[:, 0]) + np.pi) * (360 / (2 * np.pi))).astype(int), 359)
    row = np.minimum(np.searchsorted(mid, el), 23)
    want = (el >= -0.4) & (el <= 0.2) & (nearest[row, col] > np.linalg.norm(p, axis=1) + 0.5)
    assert np.array_equal(count, want.astype(np.int64))
    assert 0 < want.sum() < len(want)


def test_a_place_seen_through_is_moving_and_one_seen_at_is_not():
    """A sensor with a wall 30 m ahead: a point 10 m ahead was seen through, one on the wall was not, one behind
    the wall (never seen) was not."""
    sensor = _sensor(0.0)
    fs = FreeSpace(DynamicParams(), sensor)
    az = np.radians(np.arange(-30, 30, 0.4))
    el = np.radians(np.linspace(-8, 8, 16))
    A, E = np.meshgrid(az, el)
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    wall = d * (30.0 / d[:, :1])  # (the plane x = 30)
    fs.add(wall, None, 0.1, np.eye(4), np.eye(4))
    probes = np.array([[10.0, 0.0, 0.0], [30.0, 1.0, 0.5], [35.0, 0.0, 0.0], [10.0, 0.0, 5.0]])
    assert fs.moving_points(probes).tolist() == [True, False, False, False]  # (the last: above the rings)


def test_checked_lags_double_up_to_the_history():
    assert checked_lags(30) == (1, 2, 4, 8, 16, 30)
    assert checked_lags(1) == (1,)
    assert checked_lags(8) == (1, 2, 4, 8)


def test_dropping_rows_keeps_a_map_scans_points_and_centroids_one_array():
    pts = np.arange(15.0).reshape(5, 3)
    times = np.arange(5.0)
    scan = FilteredScan(pts, np.full((5, 3), np.nan), None, times, np.full(5, np.nan), pts, None, pts, times)
    keep = np.array([True, False, True, True, False])
    drop_rows(scan, keep, keep)
    assert scan.points is scan.centroids and scan.times_s is scan.centroid_times_s
    assert np.array_equal(scan.points, pts[keep]) and np.array_equal(scan.times_s, times[keep])
