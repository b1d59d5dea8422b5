"""Moving objects seen as a spinning lidar sees them: each ray meets an actor where it is at the ray's own time.

The analytic case: a box driving at a known speed past a static sensor. Every ray is a
horizontal half-line from the origin; the box's near face lies in the plane y = 9 m
and spans x_c(t) - 2 .. x_c(t) + 2 m at time t. So the set of rays that hit it, and
where, follow from each ray's firing time alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh

from simlidar import se3
from simlidar.formats.tracks import read_tracks
from simlidar.formats.truth import ACTOR_CLASSES
from simlidar.sensor import LidarModel
from simlidar.simulate import simulate_sequence
from simlidar.sweep import SweepSimulator
from simlidar.trajectory import SampledTrajectory
from simlidar.world import World


@dataclass
class Model:
    name: str
    vertices: np.ndarray
    faces: np.ndarray
    box_centre: np.ndarray
    box_size: np.ndarray


def box_model(name: str, size=(4.0, 2.0, 2.0)) -> Model:
    b = trimesh.creation.box(extents=size)
    b.apply_translation((0.0, 0.0, size[2] / 2))
    return Model(name, np.asarray(b.vertices), np.asarray(b.faces), np.array([0.0, 0.0, size[2] / 2]),
                 np.asarray(size, float))


class Mover:
    """A rigid body on a screw motion: T(t) = T0 exp(t xi) (constant velocity and turn rate in its own frame)."""

    label, behaviour = "vehicle", "test"

    def __init__(self, model: Model, T0: np.ndarray, xi: np.ndarray, kind: str = "car", span=(-100.0, 100.0)):
        self.model, self.T0, self.xi, self.kind, self.time_span_s = model, T0, np.asarray(xi, float), kind, span

    def motion_at(self, times):
        t = np.atleast_1d(np.asarray(times, float))
        T = self.T0 @ se3.exp(t[:, None] * self.xi[None])
        # velocity of the origin and angular velocity, in the world: the body twist turned into the world
        R = T[:, :3, :3]
        return T, R @ self.xi[:3], R @ self.xi[3:]


def ground_world(actors) -> World:
    g = trimesh.creation.box((600.0, 600.0, 1.0))
    g.apply_translation((0.0, 0.0, -30.0))  # far below: horizontal rays never meet it
    return World(g.vertices, g.faces, np.zeros(len(g.faces), np.int32), ["ground"], "test", actors=actors)


def flat_sensor(rings: int = 1, step_deg: float = 0.1, **more) -> LidarModel:
    angles = tuple(np.linspace(-1.0, 1.0, rings)) if rings > 1 else (0.0,)
    return LidarModel(name="flat", vertical_angles_deg=angles, azimuth_step_deg=step_deg, rotation_hz=10.0,
                      range_noise_std_m=0.0, min_range_m=0.1, max_range_m=150.0, **more)


STILL = SampledTrajectory(np.array([0.0]), np.eye(4)[None])


def translating_box(x0: float, y: float, v: float) -> Mover:
    T0 = np.eye(4)
    T0[:3, 3] = (x0, y, -1.0)  # its origin on the ground 1 m below the beam: the beam meets its middle
    return Mover(box_model("box"), T0, np.array([v, 0, 0, 0, 0, 0.0]))


def analytic_hits(sensor: LidarModel, sim: SweepSimulator, t0: float, x0: float, y: float, v: float):
    """(columns whose horizontal ray meets the moving 4 x 2 m box, where: x on the near face or far side)."""
    cols = np.arange(sensor.columns_per_sweep)
    phi = sensor.column_azimuth_rad(cols)
    t = t0 + sim.ray_time_s[cols * sensor.rings]
    d = np.stack([np.cos(phi), np.sin(phi)], 1)
    lo = np.stack([x0 + v * t - 2.0, np.full(len(t), y - 1.0)], 1)
    hi = np.stack([x0 + v * t + 2.0, np.full(len(t), y + 1.0)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = lo / d, hi / d
    t_near = np.nanmax(np.minimum(a, b), axis=1)
    t_far = np.nanmin(np.maximum(a, b), axis=1)
    hit = (t_far >= np.maximum(t_near, 0.0))
    return cols[hit], d[hit] * t_near[hit, None]


@pytest.mark.parametrize("v", [20.0, -20.0, 0.0])
def test_a_box_driving_past_a_still_sensor_is_met_where_it_is_at_each_rays_time(v):
    x0, y, t0 = -8.0, 10.0, 0.0
    sensor = flat_sensor()
    world = ground_world([translating_box(x0, y, v)])
    sim = SweepSimulator(world, sensor, seed=0)
    scan = sim.sweep(STILL, t0)
    cols, where = analytic_hits(sensor, sim, t0, x0, y, v)
    on = scan.object_id == 1
    assert np.array_equal(np.sort(scan.azimuth_index[on]), cols)  # exactly the rays the analysis says
    assert np.allclose(scan.xyz[on, :2], where, atol=1e-9)  # where the box was at each ray's instant
    x_c = x0 + v * (t0 + scan.time_s[on])
    near = np.abs(scan.xyz[on, 1] - (y - 1.0)) < 1e-9
    assert near.sum() > 10 and np.all(np.abs(scan.xyz[on][near, 0] - x_c[near]) <= 2.0 + 1e-9)
    # the truth: the car's class, its velocity in the sweep-start frame (the sensor's, still), moving or not
    assert np.all(scan.object_class[on] == ACTOR_CLASSES.index("car"))
    assert np.allclose(scan.velocity[on], [v, 0.0, 0.0])
    assert np.all(scan.moving[on] == (v != 0))
    assert np.all(scan.object_class[~on] == 0) and not scan.moving[~on].any()


def test_the_scan_is_stretched_by_the_motion_as_a_still_snapshot_is_not():
    """Seen while it moves (each ray at its time) the face's extent in the scan differs from its length by the
    distance it drives while the beam crosses it; the instantaneous scan (no motion distortion) shows it where
    it was at the sweep's start."""
    x0, y, v = -4.0, 10.0, 25.0
    sensor = flat_sensor(step_deg=0.05)
    world = ground_world([translating_box(x0, y, v)])
    extent = {}
    for distortion in (True, False):
        sim = SweepSimulator(world, sensor, seed=0, motion_distortion=distortion)
        scan = sim.sweep(STILL, 0.0)
        near = (scan.object_id == 1) & (np.abs(scan.xyz[:, 1] - (y - 1.0)) < 1e-9)
        xs = scan.xyz[near, 0]
        extent[distortion] = (xs.min(), xs.max())
    # frozen at t0: the face spans x0 - 2 .. x0 + 2 (to the column spacing at 9 m: 9 * 0.05 deg < 1 cm)
    assert extent[False][0] == pytest.approx(x0 - 2.0, abs=0.02) and extent[False][1] == pytest.approx(x0 + 2.0,
                                                                                                      abs=0.02)
    # moving: its front and back are where they were when the rays that saw them fired
    sim = SweepSimulator(world, sensor, seed=0)
    scan = sim.sweep(STILL, 0.0)
    near = (scan.object_id == 1) & (np.abs(scan.xyz[:, 1] - (y - 1.0)) < 1e-9)
    first, last = np.argmin(scan.xyz[near, 0]), np.argmax(scan.xyz[near, 0])
    t = scan.time_s[near]
    assert scan.xyz[near, 0][first] == pytest.approx(x0 + v * t[first] - 2.0, abs=0.02)
    assert scan.xyz[near, 0][last] == pytest.approx(x0 + v * t[last] + 2.0, abs=0.02)
    # so the face's extent is its length plus the distance it drove while the beam crossed it
    stretch = v * (t[last] - t[first])
    assert stretch > 0.1
    assert extent[True][1] - extent[True][0] == pytest.approx(4.0 + stretch, abs=0.02)


def brute_force(world: World, sensor: LidarModel, trajectory, t0: float):
    """Per ray, the nearest actor hit with each actor posed exactly at the ray's time (no culling, no knots)."""
    from simlidar.raycast import Raycaster

    sim = SweepSimulator(world.without_actors(), sensor, seed=0)
    T = trajectory.pose_at(t0 + sim.ray_time_s)
    o = T[:, :3, 3]
    d = np.einsum("nij,nj->ni", T[:, :3, :3], sim._dir_local)
    best = np.full(len(o), np.inf)
    who = np.full(len(o), -1)
    for i, a in enumerate(world.actors):
        Ta, _, _ = a.motion_at(t0 + sim.ray_time_s)
        R = Ta[:, :3, :3]
        oa = np.einsum("nji,nj->ni", R, o - Ta[:, :3, 3])
        da = np.einsum("nji,nj->ni", R, d)
        rc = Raycaster(a.model.vertices, a.model.faces, threads=1)
        h = rc.cast_compact(oa - rc.offset, da, sensor.max_range_m + 1.0)
        closer = h.distance < best[h.ray]
        best[h.ray[closer]], who[h.ray[closer]] = h.distance[closer], i
    return best, who


def test_the_culled_cast_meets_every_actor_a_brute_force_cast_meets():
    """Around a moving, turning sensor, boxes driving and turning at various speeds: the sweep (only rays near each
    actor cast, its pose between knots interpolated) finds the same actor on every ray as casting every ray
    against every actor posed at the ray's exact time, at the same range to a micrometre."""
    rng = np.random.default_rng(4)
    actors = []
    for k in range(8):
        T0 = np.eye(4)
        yaw = rng.uniform(-np.pi, np.pi)
        T0[:3, :3] = se3.exp(np.array([0, 0, 0, 0, 0, yaw]))[:3, :3]
        T0[:3, 3] = (*rng.uniform(-40, 40, 2), -1.5)
        xi = np.array([rng.uniform(-15, 25), 0.0, 0.0, 0.0, 0.0, rng.uniform(-0.6, 0.6)])
        actors.append(Mover(box_model(f"box{k}", (rng.uniform(1, 12), rng.uniform(0.5, 2.5), 3.0)), T0, xi,
                            kind=("car", "lorry", "pedestrian")[k % 3]))
    world = ground_world(actors)
    sensor = flat_sensor(rings=16, step_deg=0.2, laser_interval_s=2e-6)
    times = np.linspace(0.0, 2.0, 21)
    T = np.stack([se3.exp(np.array([8.0 * t, 0, 0, 0, 0, 0.3 * t])) for t in times])
    trajectory = SampledTrajectory(times, T)
    sim = SweepSimulator(world, sensor, seed=0)
    for t0 in (0.3, 1.1):
        scan = sim.sweep(trajectory, t0)
        best, who = brute_force(world, sensor, trajectory, t0)
        ray = scan.azimuth_index * sensor.rings + scan.ring
        on_actor = scan.object_id >= 1
        expect = np.flatnonzero(np.isfinite(best))
        assert set(ray[on_actor]) == set(expect)
        assert np.array_equal(scan.object_id[on_actor] - 1, who[ray[on_actor]])
        assert np.allclose(scan.true_range_m[on_actor], best[ray[on_actor]], atol=2e-6)


def test_rays_that_meet_the_world_before_an_actors_box_are_not_cast_against_it(monkeypatch):
    """Boxes driving behind a wall: where the wall hides them the rays are not cast against them (no actor hit
    comes back there), and the scan is the one casting every candidate ray against them gives."""
    from simlidar.actors import SweepActors

    wall = trimesh.creation.box((1.0, 12.0, 6.0))
    wall.apply_translation((15.0, 0.0, 0.0))
    ground = trimesh.creation.box((600.0, 600.0, 1.0))
    ground.apply_translation((0.0, 0.0, -30.0))
    both = trimesh.util.concatenate([ground, wall])
    actors = [translating_box(x, y, v) for x, y, v in ((25.0, -20.0, 8.0), (30.0, 5.0, -6.0), (40.0, 12.0, 10.0))]
    world = World(both.vertices, both.faces, np.r_[np.zeros(len(ground.faces), np.int32),
                                                   np.ones(len(wall.faces), np.int32)], ["ground", "wall"], "test",
                  actors=actors)
    sensor = flat_sensor(rings=8, step_deg=0.2)
    original = SweepActors.cast
    scans, actor_hits = {}, {}
    for culled in (True, False):
        found = []

        def cast(self, *args, nearer=None, _culled=culled, _found=found):
            out = original(self, *args, nearer=nearer if _culled else None)
            _found.append(0 if out is None else len(out.ray))
            return out

        monkeypatch.setattr(SweepActors, "cast", cast)
        scans[culled] = SweepSimulator(world, sensor, seed=0).sweep(STILL, 0.0)
        actor_hits[culled] = sum(found)
    for field in ("xyz", "true_range_m", "object_id", "object_class", "velocity", "normal"):
        assert np.array_equal(getattr(scans[True], field), getattr(scans[False], field)), field
    on_actor = scans[True].object_id >= 2
    assert on_actor.sum() > 50 and (scans[True].object_id == 1).sum() > 50  # some seen beside the wall, some hidden
    assert actor_hits[True] == on_actor.sum() < actor_hits[False]


def test_a_sequence_with_actors_writes_their_truth_and_tracks_and_reads_them_back(tmp_path):
    x0, y, v = -30.0, 10.0, 15.0
    world = ground_world([translating_box(x0, y, v)])
    sensor = flat_sensor(rings=4, step_deg=0.2)
    out = simulate_sequence(world, STILL, sensor, tmp_path / "seq", frames=5, seed=1)
    from simlidar.dataset import open_sequence

    seq = open_sequence(out)
    assert seq.manifest["format_version"] == 3
    assert seq.manifest["object_labels"] == ["ground", "vehicle"]
    assert seq.manifest["actors"][0]["object_id"] == 1 and seq.manifest["actors"][0]["class"] == "car"
    sim = SweepSimulator(world, sensor, seed=1)
    frames, rows = read_tracks(out / "tracks.csv")
    for k in range(5):
        scan = sim.sweep(STILL, k * sensor.sweep_period_s, frame_index=k)
        rec = seq[k].fields
        assert np.array_equal(rec["object_class"], scan.object_class)
        assert np.array_equal(rec["moving"], scan.moving)
        assert np.allclose(rec["velocity"], scan.velocity, atol=0.005)  # stored to 1 cm/s
        row = rows[frames == k]
        assert len(row) == 1 and row["object_id"][0] == 1 and row["returns"][0] == np.sum(scan.object_id == 1)
        # the box's centre at the sweep's start: the origin x0 + v t, 1 m up, in the (still) sensor frame
        t = k * sensor.sweep_period_s
        assert np.allclose(row["centre"][0], [x0 + v * t, y, 0.0], atol=1e-4)
        assert np.allclose(row["velocity"][0], [v, 0, 0], atol=1e-4) and np.allclose(row["size"][0], [4, 2, 2])


def test_an_actor_that_comes_into_the_world_during_a_sweep_has_a_track_in_that_frame(tmp_path):
    """Two still boxes appear half-way through the first sweep, one left of the sensor and one right: the
    head turns clockwise from behind, so only the rays to the right fire after that and meet their box; the
    frame's tracks hold exactly the box hit, with its returns (every return's object has its track); from the
    next frame on both are in the world and both have one."""
    sensor = flat_sensor(rings=2, step_deg=0.5)
    half = 0.5 * sensor.sweep_period_s
    boxes = [Mover(box_model("box"), _at(0.0, y), np.zeros(6), span=(half, 100.0)) for y in (12.0, -12.0)]
    world = ground_world(boxes)
    out = simulate_sequence(world, STILL, sensor, tmp_path / "seq", frames=2, seed=1)
    from simlidar.dataset import open_sequence

    seq = open_sequence(out)
    frames, rows = read_tracks(out / "tracks.csv")
    ids = seq[0].fields["object_id"]
    hit = sorted(set(ids[ids >= 1].tolist()))
    assert hit == [2]  # the box on the right
    assert rows[frames == 0]["object_id"].tolist() == hit
    assert rows[frames == 0]["returns"][0] == np.sum(ids == hit[0]) > 0
    assert sorted(rows[frames == 1]["object_id"].tolist()) == [1, 2]


def _at(x: float, y: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, -1.0)
    return T


def test_a_world_without_actors_is_written_as_before(tmp_path):
    sensor = flat_sensor(rings=4, step_deg=1.0).with_overrides(vertical_angles_deg=(-30.0, -20.0, -10.0, -5.0))
    g = trimesh.creation.box((50.0, 50.0, 1.0))
    g.apply_translation((0, 0, -2.0))
    world = World(g.vertices, g.faces, np.zeros(len(g.faces), np.int32), ["ground"], "test")
    out = simulate_sequence(world, STILL, sensor, tmp_path / "seq", frames=2)
    from simlidar.dataset import open_sequence

    seq = open_sequence(out)
    assert seq.manifest["format_version"] == 2 and "actors" not in seq.manifest
    assert not (out / "tracks.csv").exists()
    assert "object_class" not in seq[0].fields.dtype.names


def test_an_actor_of_an_unknown_class_is_refused():
    from simlidar.actors import ActorError

    bad = translating_box(0.0, 10.0, 1.0)
    bad.kind = "tram"
    with pytest.raises(ActorError, match="tram"):
        SweepSimulator(ground_world([bad]), flat_sensor(), seed=0)
