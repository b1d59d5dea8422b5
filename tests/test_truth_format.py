"""The compact truth of a sequence folder (format version 2) against the simulator's float64 truth.

What the format promises (``simlidar.formats.truth``): ring, azimuth index, time and
object exact; the true point within 4e-7 x range + 1 micrometre; the normal within
0.01 deg; the measured range to float32 rounding. Old sequences (format version 1,
``.npy`` sidecars) still read, with the same fields.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from simlidar.dataset import open_sequence
from simlidar.formats import truth
from simlidar.formats.salo import SequenceWriter
from simlidar.sensor import load_sensor
from simlidar.sequence import DatasetError
from simlidar.simulate import simulate_sequence
from simlidar.world import World
from tests.helpers import constant_velocity


def _street_world() -> World:
    """Ground, two rows of boxes and a tilted slab: many objects, normals of every kind, ranges to 60 m."""
    parts = [trimesh.creation.box((200.0, 200.0, 1.0)).apply_translation((0, 0, -0.5))]
    rng = np.random.default_rng(5)
    for x in np.arange(-50.0, 60.0, 12.0):
        for side in (-1, 1):
            b = trimesh.creation.box(rng.uniform(3, 9, 3))
            b.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(0, 1), (0, 0, 1)))
            parts.append(b.apply_translation((x, side * rng.uniform(8, 14), 2.0)))
    slab = trimesh.creation.box((6.0, 6.0, 0.3))
    slab.apply_transform(trimesh.transformations.rotation_matrix(0.6, (1, 1, 0)))
    parts.append(slab.apply_translation((25.0, 0.0, 3.0)))
    verts, faces, ids, base = [], [], [], 0
    for k, m in enumerate(parts):
        verts.append(m.vertices)
        faces.append(m.faces + base)
        ids.append(np.full(len(m.faces), k))
        base += len(m.vertices)
    labels = ["ground"] + ["building"] * (len(parts) - 1)
    return World(np.vstack(verts), np.vstack(faces), np.concatenate(ids), labels, "street")


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) angles between rows of a and b, deg (atan2: exact near 0, where arccos is not)."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b)))


def _simulate(tmp_path, sensor, motion=True, frames=2, **writer):
    world = _street_world()
    traj = constant_velocity(v=(12.0, 1.5, 0.2), yaw_rate=0.8, start=(-20.0, 0.0, 1.9), duration=5.0)
    scans = []
    out = tmp_path / f"seq-{sensor.name}-{motion}"
    simulate_sequence(world, traj, sensor, out, frames=frames, seed=4, motion_distortion=motion,
                      on_frame=lambda k, scan: scans.append(scan))
    return open_sequence(out), scans


@pytest.mark.parametrize("preset, jitter", [("vlp16", 0.0), ("salo32", 0.0), ("vlp16", 0.05)])
def test_compact_truth_round_trip_within_its_bounds(tmp_path, preset, jitter):
    # vlp16 fires its lasers one after another (knots interpolated within a column); salo32 fires a
    # column at once; jitter moves every beam off the sensor's table.
    sensor = load_sensor(preset).with_overrides(angular_jitter_deg=jitter)
    seq, scans = _simulate(tmp_path, sensor)
    assert seq.manifest["format_version"] == 2
    for frame, scan in zip(seq, scans, strict=True):
        f = frame.fields
        assert len(f) == len(scan) > 1000
        assert np.array_equal(f["ring"], scan.ring) and np.array_equal(f["azimuth_index"], scan.azimuth_index)
        assert np.array_equal(f["time_s"], scan.time_s)
        assert np.array_equal(f["object_id"], scan.object_id)
        assert np.abs(f["true_range_m"] - scan.true_range_m).max() <= 6e-8 * scan.true_range_m.max()
        assert np.all(np.abs(f["range_m"] - scan.range_m) <= 2e-7 * scan.range_m)
        err = np.linalg.norm(f["true_xyz"].astype(np.float64) - scan.true_xyz, axis=1)
        bound = truth.TRUE_XYZ_REL_BOUND * scan.true_range_m + truth.TRUE_XYZ_ABS_BOUND_M
        assert np.all(err <= bound), (err / bound).max()
        # the motion matters: without the knots the points would be off by the sweep's travel
        assert np.linalg.norm(scan.true_xyz - scan.xyz, axis=1).max() > 0.5
        assert _angle_deg(f["normal"].astype(np.float64), scan.normal).max() < truth.NORMAL_BOUND_DEG


def test_compact_truth_without_motion_distortion_has_no_knots(tmp_path):
    seq, scans = _simulate(tmp_path, load_sensor("vlp16"), motion=False, frames=1)
    data = (seq.path / "sidecar" / "000000.truth").read_bytes()
    n, knots, width, _ = truth.read_header(data, "x")
    assert (n, knots, width) == (len(scans[0]), 0, 1)  # 30 objects: one byte each
    assert len(data) == truth.HEADER_BYTES + 13 * n
    err = np.linalg.norm(seq[0].fields["true_xyz"] - scans[0].true_xyz, axis=1)
    assert np.all(err <= truth.TRUE_XYZ_REL_BOUND * scans[0].true_range_m + truth.TRUE_XYZ_ABS_BOUND_M)


def test_compressed_truth_reads_the_same(tmp_path):
    world = _street_world()
    sensor = load_sensor("vlp16")
    traj = constant_velocity(v=(8.0, 0.0, 0.0), yaw_rate=0.3, start=(-20.0, 0.0, 1.9))
    for compress in (False, True):
        simulate_sequence(world, traj, sensor, tmp_path / str(compress), frames=2, seed=2, compress_truth=compress)
    plain, packed = open_sequence(tmp_path / "False"), open_sequence(tmp_path / "True")
    for a, b in zip(plain, packed, strict=True):
        assert np.array_equal(a.fields, b.fields)
    size = {c: (tmp_path / str(c) / "sidecar" / "000001.truth").stat().st_size for c in (False, True)}
    assert size[True] < 0.6 * size[False]
    car = tmp_path / "True" / "sidecar" / "000001.truth"
    data = car.read_bytes()
    car.write_bytes(data[:-10])
    with pytest.raises(DatasetError, match=r"000001\.truth: damaged compressed truth"):
        packed[1]


def test_octahedral_normals_within_a_hundredth_of_a_degree():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200_000, 3))
    n = np.vstack([n / np.linalg.norm(n, axis=1, keepdims=True), np.eye(3), -np.eye(3)])
    back = truth.octahedral_decode(truth.octahedral_encode(n))
    assert _angle_deg(n, back).max() < 0.004  # docs/sequence-format.md states 0.0037 deg measured, 0.01 deg promised


@pytest.mark.parametrize("count, width", [(1, 1), (256, 1), (257, 2), (65536, 2), (65537, 4)])
def test_object_ids_take_the_fewest_bytes_the_world_needs(count, width):
    assert truth.object_id_bytes(count) == width


def test_old_sequences_still_read_with_the_same_fields(tmp_path):
    # A version-1 folder (.npy sidecars, 50 bytes a return), as sequences already on users' disks.
    sensor = load_sensor("vlp16")
    world = _street_world()
    traj = constant_velocity(v=(12.0, 0.0, 0.0), yaw_rate=0.5, start=(-20.0, 0.0, 1.9), duration=5.0)
    for version in (1, 2):
        from simlidar.sweep import SweepSimulator

        sim = SweepSimulator(world, sensor, seed=1)
        with SequenceWriter(tmp_path / f"v{version}", sensor, {}, n_objects=len(world.object_labels),
                            format_version=version) as w:
            for k in range(2):
                w.add(sim.sweep(traj, 0.1 * k, frame_index=k), traj.pose_at(np.array([0.1 * k]))[0], 0.1 * k)
    old, new = open_sequence(tmp_path / "v1"), open_sequence(tmp_path / "v2")
    assert old.manifest["format_version"] == 1 and (tmp_path / "v1" / "sidecar" / "000000.npy").is_file()
    for a, b in zip(old, new, strict=True):
        assert a.fields.dtype == b.fields.dtype
        assert np.array_equal(a.points, b.points)
        for name in ("ring", "azimuth_index", "time_s", "object_id"):
            assert np.array_equal(a.fields[name], b.fields[name]), name
        assert np.abs(a.fields["true_xyz"] - b.fields["true_xyz"]).max() < 1e-4
    size = {v: sum(p.stat().st_size for p in (tmp_path / f"v{v}" / "sidecar").iterdir()) for v in (1, 2)}
    assert size[2] < 0.35 * size[1]


def test_a_damaged_or_unknown_truth_file_is_a_one_line_error(tmp_path):
    seq, _ = _simulate(tmp_path, load_sensor("vlp16"), motion=True, frames=1)
    car = seq.path / "sidecar" / "000000.truth"
    data = car.read_bytes()
    car.write_bytes(data[:-3])
    with pytest.raises(DatasetError, match=r"000000\.truth: .* bytes, the header's .* returns and .* knots need"):
        open_sequence(seq.path)[0]
    car.write_bytes(b"NOTTRUTH" + data[8:])
    with pytest.raises(DatasetError, match=r"000000\.truth: not a truth file"):
        open_sequence(seq.path)[0]
    car.write_bytes(data[:18] + bytes([0x04]) + data[19:])  # an optional block this version does not know
    with pytest.raises(DatasetError, match=r"000000\.truth: optional truth blocks 0x04 this version does not read"):
        open_sequence(seq.path)[0]
    manifest = json.loads((seq.path / "manifest.json").read_text())
    manifest["format_version"] = 4
    (seq.path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match=r"manifest.json: format_version 4 is not one this version reads"):
        open_sequence(seq.path)


def test_a_failing_writer_leaves_nothing(tmp_path, monkeypatch):
    sensor = load_sensor("vlp16")
    world = _street_world()
    traj = constant_velocity(v=(5.0, 0.0, 0.0), start=(-20.0, 0.0, 1.9))

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(truth, "encode", broken)
    with pytest.raises(OSError, match="No space left"):
        simulate_sequence(world, traj, sensor, tmp_path / "seq", frames=3)
    assert list(tmp_path.iterdir()) == []


def test_a_method_reads_the_firing_fields_without_decoding_the_truth(tmp_path):
    """``method_frame``: what a method is handed (the odometry, the peers, the staging) is the firing fields
    only, the same values as the whole record's; the truth is not decoded (and not handed over)."""
    from odometry.config import variant
    from odometry.pipeline import run_sequence
    from simlidar.sequence import method_frame

    seq, _ = _simulate(tmp_path, load_sensor("vlp16"), frames=3)
    for k in range(len(seq)):
        whole, firing = seq[k], method_frame(seq, k)
        assert firing.fields.dtype == truth.FIRING_DTYPE
        assert set(firing.fields.dtype.names).isdisjoint({"true_xyz", "true_range_m", "normal", "object_id"})
        for name in firing.fields.dtype.names:
            assert np.array_equal(firing.fields[name], whole.fields[name]), name
        assert np.array_equal(firing.points, whole.points) and np.array_equal(firing.intensity, whole.intensity)
    frames = [seq[0]]
    assert method_frame(frames, 0) is frames[0]  # a plain list of frames: indexed as it is
    # the odometry's poses are those it gives when it reads the whole record (the same inputs)
    firing_run = run_sequence(seq, variant("salo"), seq.sensor)
    seq.frame = lambda k, truth=True: type(seq).frame(seq, k)  # (every read decodes the truth)
    whole_run = run_sequence(seq, variant("salo"), seq.sensor)
    assert np.isfinite(firing_run.poses).all() and np.array_equal(firing_run.poses, whole_run.poses)
