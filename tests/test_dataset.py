"""Sequence files: write/read round trip, real KITTI and scan folders, determinism, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import box_room, constant_velocity

from simlidar import se3
from simlidar.dataset import open_sequence
from simlidar.formats.atomic import remove_stale_partials, sha256_file
from simlidar.formats.kitti import camera_poses_to_lidar, format_kitti_poses, read_bin, read_kitti_poses, write_bin
from simlidar.formats.ply import write_ply_scan
from simlidar.sensor import load_preset
from simlidar.sequence import DatasetError
from simlidar.simulate import simulate_sequence
from simlidar.sweep import SweepSimulator
from simlidar.world import save_world_ply
from tools.cli import main as salo


def simulate(out, frames=4, seed=1, force=False, sensor="vlp16", **kw):
    traj = constant_velocity(v=(3.0, 0.5, 0.0), yaw_rate=0.2, start=(-5.0, 0.0, 0.0))
    return simulate_sequence(
        box_room(), traj, load_preset(sensor), out, frames=frames, seed=seed, force=force, **kw
    )


def test_round_trip(tmp_path):
    out = tmp_path / "seq"
    frames = []
    simulate(out, on_frame=lambda k, scan: frames.append(scan))
    seq = open_sequence(out)
    assert seq.kind == "salo" and len(seq) == 4
    assert seq.sensor == load_preset("vlp16")
    seq.verify()
    for k, frame in enumerate(seq):
        scan = frames[k]
        assert np.allclose(frame.points, scan.xyz, atol=1e-5)  # float32 on disk
        assert np.array_equal(frame.intensity, scan.intensity)
        assert np.array_equal(frame.ring, scan.ring)
        assert np.array_equal(frame.field("azimuth_index"), scan.azimuth_index)
        assert np.array_equal(frame.time_s, scan.time_s)
        assert np.allclose(frame.field("true_xyz"), scan.true_xyz, atol=1e-5)
        # octahedral normals on disk: within 0.01 deg (1.75e-4 rad; tests/test_truth_format.py checks the bounds)
        assert np.allclose(frame.field("normal"), scan.normal, atol=1.75e-4)
        assert np.array_equal(frame.field("object_id"), scan.object_id)
    # poses relative to the first frame, at the sweep start times
    traj = constant_velocity(v=(3.0, 0.5, 0.0), yaw_rate=0.2, start=(-5.0, 0.0, 0.0))
    T = traj.pose_at(seq.times)
    assert np.allclose(seq.poses, se3.inverse(T[0]) @ T, atol=1e-9)
    assert np.allclose(seq.poses[0], np.eye(4))
    assert np.allclose(np.diff(seq.times), 0.1)
    m = seq.manifest
    assert m["frames"] == 4 and m["seed"] == 1 and m["package_version"]
    assert set(m["files"]) >= {"poses.txt", "times.txt", "sensor.yaml", "velodyne/000003.bin"}
    deg = np.loadtxt(out / "degeneracy.csv", delimiter=",", skiprows=1)
    assert deg.shape == (4, 14)


def test_same_arguments_give_byte_identical_files(tmp_path):
    simulate(tmp_path / "a")
    simulate(tmp_path / "b")
    simulate(tmp_path / "c", seed=2)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) > 10
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a/velodyne/000000.bin").read_bytes() != (tmp_path / "c/velodyne/000000.bin").read_bytes()


def test_interrupted_write_leaves_nothing_that_looks_complete(tmp_path):
    out = tmp_path / "seq"

    def boom(k, scan):
        if k == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        simulate(out, on_frame=boom)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []
    # an existing sequence survives a failed --force rewrite untouched
    simulate(out)
    before = (out / "manifest.json").read_bytes()
    with pytest.raises(KeyboardInterrupt):
        simulate(out, force=True, seed=9, on_frame=boom)
    assert (out / "manifest.json").read_bytes() == before
    open_sequence(out).verify()
    with pytest.raises(DatasetError, match="already exists"):
        simulate(out)
    simulate(out, force=True, seed=9)
    assert json.loads((out / "manifest.json").read_text())["seed"] == 9


def test_unfinished_or_damaged_folders_are_refused(tmp_path):
    out = tmp_path / "seq"
    simulate(out)
    (out / "INCOMPLETE").write_text("")
    with pytest.raises(DatasetError, match="unfinished"):
        open_sequence(out)
    (out / "INCOMPLETE").unlink()
    (out / "sidecar/000002.truth").unlink()
    with pytest.raises(DatasetError, match="000002.truth: missing"):
        open_sequence(out)
    simulate(tmp_path / "s2")
    with open(tmp_path / "s2/velodyne/000001.bin", "r+b") as fh:  # same size, other content
        fh.seek(100)
        fh.write(b"\xff" * 4)
    with pytest.raises(DatasetError, match="checksum"):
        open_sequence(tmp_path / "s2").verify()
    with open(tmp_path / "s2/velodyne/000001.bin", "ab") as fh:
        fh.write(b"\0" * 5)
    with pytest.raises(DatasetError, match="000001.bin: size .* not a whole number"):
        open_sequence(tmp_path / "s2")



def test_open_sequence_asks_the_readers_in_order_and_each_names_its_kind(tmp_path):
    from simlidar.dataset import READERS
    from tools.export import export_rosbag, export_scans

    assert [r.name for r in READERS] == ["rosbag2", "salo", "kitti", "pcd", "scans"]  # the catch-all reader last
    sim = simulate(tmp_path / "sim", frames=2)
    seq = open_sequence(sim)
    kitti = tmp_path / "kitti"
    (kitti / "velodyne").mkdir(parents=True)
    (kitti / "calib.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    write_bin(kitti / "velodyne" / "000000.bin", np.ones((3, 3)), np.zeros(3))
    sources = {"salo": sim, "kitti": kitti, "scans": export_scans(seq, tmp_path / "ply", "ply").path,
               "pcd": export_scans(seq, tmp_path / "pcd", "pcd").path,
               "rosbag2": export_rosbag(seq, tmp_path / "bag").path}
    for reader in READERS:
        path = sources[reader.name]
        first = next(r for r in READERS if r.detect(path))
        assert first is reader and open_sequence(path).kind == reader.name
    with pytest.raises(DatasetError, match="not a folder"):
        open_sequence(tmp_path / "nothing_here")

def test_kitti_camera_to_lidar_hand_made():
    rng = np.random.default_rng(0)
    Tr = se3.exp(np.r_[rng.normal(0, 0.3, 3), rng.normal(0, 1.0, 3)])  # velodyne -> cam0
    L = se3.exp(np.c_[rng.normal(0, 5, (5, 3)), rng.normal(0, 0.2, (5, 3))])  # lidar poses
    P = Tr @ L @ se3.inverse(Tr)  # the same motion seen by the camera
    P = se3.inverse(P[0]) @ P  # KITTI: first camera pose is identity
    got = camera_poses_to_lidar(P, Tr)
    assert np.allclose(got, se3.inverse(L[0]) @ L, atol=1e-12)


@pytest.mark.parametrize("seq_id", ["05", "01"])
def test_real_kitti_sequence(real_data, seq_id):
    seq = open_sequence(real_data / "kitti/sequences" / seq_id)
    assert seq.kind == "kitti" and len(seq) == 10
    expected = read_kitti_poses(real_data / "kitti/lidar_frame_poses" / f"{seq_id}.txt")
    assert np.abs(seq.poses - expected).max() < 1e-6
    frame = seq[0]
    assert frame.points.shape[1] == 3 and len(frame.points) > 100_000
    assert frame.ring is None and frame.time_s is None
    assert 0 <= frame.intensity.min() and frame.intensity.max() <= 1.0
    # explicit pose file gives the same
    seq2 = open_sequence(real_data / "kitti/sequences" / seq_id, poses=real_data / f"kitti/poses/{seq_id}.txt")
    assert np.allclose(seq2.poses, seq.poses)


def test_real_hdl32_scan_folder(real_data, tmp_path):
    seq = open_sequence(real_data / "hdl32-pair", sensor="hdl32e")
    assert seq.kind == "scans" and len(seq) == 2 and seq.sensor.name == "hdl32e"
    T = np.loadtxt(real_data / "hdl32-pair/T_target_source.txt")
    assert np.allclose(seq.poses[1], T, atol=1e-6)
    pts = seq[1].points
    r = np.linalg.norm(pts, axis=1)
    assert (r == 0).any() and np.median(r[r > 0]) < 30  # close-range campus scan


def test_ply_scan_folder(tmp_path):
    rng = np.random.default_rng(1)
    pts = rng.normal(0, 10, (500, 3))
    for k in range(3):
        write_ply_scan(
            tmp_path / f"{k:03d}.ply",
            pts + k,
            {"intensity": rng.random(500).astype(np.float32), "ring": np.arange(500, dtype=np.uint16) % 16,
             "time": np.linspace(0, 0.1, 500).astype(np.float32)},
        )
    load_preset("vlp16").save(tmp_path / "sensor.yaml")
    seq = open_sequence(tmp_path)
    assert seq.kind == "scans" and len(seq) == 3 and seq.sensor.name == "vlp16"
    f = seq[2]
    assert np.allclose(f.points, pts + 2, atol=1e-5)
    assert np.array_equal(f.ring, np.arange(500) % 16)
    assert f.time_s is not None and f.intensity is not None


def test_malformed_pose_files(tmp_path):
    p = tmp_path / "poses.txt"
    p.write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(DatasetError, match=r"poses.txt:1: .*12 numbers.*found 11"):
        read_kitti_poses(p)
    p.write_text("1 0 0 0 0 1 0 0 0 0 1 x\n")
    with pytest.raises(DatasetError, match="poses.txt:1: not a number"):
        read_kitti_poses(p)
    p.write_text("2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(DatasetError, match="not a rotation"):
        read_kitti_poses(p)
    with pytest.raises(DatasetError, match="cannot read"):
        read_kitti_poses(tmp_path / "nope.txt")


# ------------------------------------------------------------------ the command line
def _mesh_and_poses(tmp_path, frames=5):
    save_world_ply(box_room(), tmp_path / "room.ply")
    T = np.tile(np.eye(4), (frames, 1, 1))
    T[:, 0, 3] = np.linspace(-3, 3, frames)
    (tmp_path / "poses.txt").write_text(format_kitti_poses(T))
    return tmp_path / "room.ply", tmp_path / "poses.txt"


def test_cli_simulate_with_mesh_and_poses(tmp_path):
    mesh, poses = _mesh_and_poses(tmp_path)
    out = tmp_path / "seq"
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--sensor", "vlp16",
                 "--noise-std", "0.01", "--seed", "5", "--out", str(out)]) == 0
    seq = open_sequence(out)
    assert len(seq) == 5 and seq.sensor.range_noise_std_m == 0.01
    assert np.allclose(seq.poses[:, 0, 3], np.linspace(0, 6, 5))
    assert seq.manifest["mesh"] == str(mesh.resolve())
    assert seq.manifest["mesh_sha256"] == sha256_file(mesh)
    assert seq.manifest["poses_file"] == str(poses.resolve())
    assert "extrapolated" not in seq.manifest


def test_cli_manifest_paths_are_absolute(tmp_path, monkeypatch):
    _mesh_and_poses(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert salo(["simulate", "--mesh", "room.ply", "--poses", "poses.txt", "--sensor", "vlp16", "--out", "seq"]) == 0
    m = open_sequence(tmp_path / "seq").manifest
    assert m["mesh"] == str(tmp_path / "room.ply") and m["poses_file"] == str(tmp_path / "poses.txt")


def test_cli_bad_input(tmp_path, capsys):
    mesh, poses = _mesh_and_poses(tmp_path)
    out = tmp_path / "seq"
    (tmp_path / "broken.ply").write_text("not a mesh")
    bad_poses = tmp_path / "bad.txt"
    bad_poses.write_text("1 0 0\n")
    import trimesh

    trimesh.creation.box((4, 4, 4)).export(tmp_path / "block.ply")  # sensor at the origin inside it
    tunnel = tmp_path / "tunnel.yaml"
    assert salo(["scenes", "tunnel", "--yaml"]) == 0
    tunnel.write_text(capsys.readouterr().out)  # holds seed: 0
    scene = ["--scene", "tunnel", "--set", "length_m=100", "--set", "approach_m=50"]
    cases = [
        (["--mesh", str(tmp_path / "broken.ply"), "--poses", str(poses)], "broken.ply"),
        (["--mesh", str(tmp_path / "missing.ply"), "--poses", str(poses)], "missing.ply: mesh file does not exist"),
        (["--mesh", str(mesh), "--poses", str(bad_poses)], "bad.txt:1"),
        (["--mesh", str(tmp_path / "block.ply"), "--poses", str(poses), "--strict-inside-check"],
         "frame 1: sensor at (-1.50, 0.00, 0.00) m is inside geometry: 200 of 200 probe rays hit the back face"),
        (["--mesh", str(mesh), "--poses", str(poses), "--sensor", "nope"], "unknown sensor preset 'nope'"),
        (["--mesh", str(mesh), "--poses", str(poses), "--frames", "200"],
         "poses.txt: 5 poses cover 0.4 s; 200 frames need 19.9 s (at most 5 frames fit"),
        (["--mesh", str(mesh), "--poses", str(poses), "--speed", "3"], "--speed applies to --scene"),
        (["--mesh", str(mesh), "--poses", str(poses), "--set", "seed=1"], "--set applies to --scene"),
        ([*scene, "--extrapolate"], "--extrapolate applies to --mesh/--poses"),
        ([*scene, "--scene-params", str(tunnel), "--seed", "3"],
         f"--seed 3 and seed: 0 in {tunnel} differ: both set the scene seed, give one"),
        ([*scene, "--set", "seed=5", "--seed", "3"], "--seed 3 and --set seed=5 differ"),
        ([*scene, "--set", "seed=abc"], "--set seed=abc: key 'seed' must be an integer >= 0, got 'abc'"),
        ([*scene, "--set", "seed=1.5"], "--set seed=1.5: key 'seed' must be an integer >= 0, got '1.5'"),
        ([*scene, "--set", "seed=-2"], "--set seed=-2: key 'seed' must be an integer >= 0, got -2"),
        ([*scene, "--set", "length_m=long"],
         "scene tunnel: key 'length_m' must be a number in [50, 10000] (m), got 'long'"),
        ([*scene, "--seed", "-1"], "argument --seed: must be at least 0, got -1"),
    ]
    for extra, words in cases:
        try:
            code = salo(["simulate", *extra, "--out", str(out)])
        except SystemExit as exc:  # argparse refuses some before any work
            code = exc.code
        err = capsys.readouterr().err
        assert code == 2 and words in err, (extra, err)
        assert len(err.strip().splitlines()) == 1 or err.startswith("usage:"), err  # one line, no traceback
        assert not out.exists()
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--out", str(out)]) == 0
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["simulate", "--scene", "city", "--frames", "0"], "argument --frames: must be at least 1, got 0"),
        (["simulate", "--scene", "city", "--noise-std", "-0.01"], "argument --noise-std: must be at least 0"),
        (["simulate", "--scene", "city", "--speed", "0"], "argument --speed: must be above 0"),
        (["simulate", "--scene", "city", "--start", "nan"], "argument --start: must be finite"),
        (["demo", "--frames", "1"], "argument --frames: must be at least 2, got 1"),
        (["experiment", "rejectors", "--pairs", "zero"], "argument --pairs: not a whole number: 'zero'"),
        (["sweep", "spec.yaml", "--workers", "-1"], "argument --workers: must be at least 0, got -1"),
        (["regress", "--timeout", "0"], "argument --timeout: must be above 0, got 0"),
        (["export", "seq", "--format", "tum", "--epoch", "nan"], "argument --epoch: must be finite"),
    ],
)
def test_cli_refuses_bad_numbers_before_any_work(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_:
        salo([*argv, "--out", str(out)])
    assert exit_.value.code == 2 and words in capsys.readouterr().err
    assert not out.exists()


def test_cli_refuses_a_bad_set_before_any_work(tmp_path, capsys):
    cases = [
        ("filter.voxel_size_m=[", "--set: key 'filter.voxel_size_m' must be a number > 0 (m), got '['"),
        ("voxel_size_m=0.5", "--set: key 'voxel_size_m' is unknown; did you mean 'filter.voxel_size_m'?"),
        ("ncf=false", "--set: key 'ncf' must be a mapping of ncf keys, got str; did you mean 'ncf.enabled'?"),
        ("ncf.applies_to=map", "--set: key 'ncf.applies_to' 'map' needs match.target: map"),
        ("deskew.enabled", "--set 'deskew.enabled': expected KEY=VALUE"),
    ]
    for pair, words in cases:
        code = salo(["odometry", str(tmp_path / "seq"), "--variant", "salo", "--set", pair,
                     "--out", str(tmp_path / "p.txt")])
        assert code == 2 and words in capsys.readouterr().err, pair
    assert not (tmp_path / "p.txt").exists()


def test_check_clear_uses_each_frame(tmp_path):
    # a path that enters a solid block at frame 3 is refused before anything is written
    import trimesh

    from simlidar.world import World

    b = trimesh.creation.box((2, 2, 2))
    b.apply_translation((6, 0, 0))
    room = box_room()
    world = World(np.vstack([room.vertices, b.vertices]), np.vstack([room.faces, b.faces + len(room.vertices)]),
                  np.r_[np.zeros(len(room.faces)), np.ones(12)], ["wall", "building"])
    traj = constant_velocity(v=(20.0, 0, 0))
    from simlidar.sweep import SensorInsideGeometry

    with pytest.raises(SensorInsideGeometry, match="frame 3"):
        simulate_sequence(world, traj, load_preset("vlp16"), tmp_path / "s", frames=5)
    assert list(tmp_path.iterdir()) == []
    assert SweepSimulator  # imported for the error type's module


# ------------------------------------------------------------------ enclosed worlds from a user's mesh
@pytest.mark.parametrize("winding", ["outward", "inward"])
def test_cli_simulates_a_closed_room_of_either_winding(tmp_path, capsys, caplog, winding):
    # A 10 x 8 x 3 m room, floor at z = 0, the lidar at 1.8 m moving along x: modelled as a solid box
    # (trimesh's outward normals, every wall seen from behind) or with its faces turned inwards.
    import trimesh

    m = trimesh.creation.box((10.0, 8.0, 3.0))
    m.apply_translation((0.0, 0.0, 1.5))
    if winding == "inward":
        m.invert()
    m.export(tmp_path / "room.ply")
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 0, 3] = np.linspace(-2.0, 2.0, 4)
    T[:, 1, 3] = 0.7
    T[:, 2, 3] = 1.8
    (tmp_path / "poses.txt").write_text(format_kitti_poses(T))
    lo, hi = np.array([-5.0, -4.0, 0.0]), np.array([5.0, 4.0, 3.0])
    sigma = 0.02
    out = tmp_path / "seq"
    assert salo(["simulate", "--mesh", str(tmp_path / "room.ply"), "--poses", str(tmp_path / "poses.txt"),
                 "--sensor", "vlp16", "--noise-std", str(sigma), "--no-motion-distortion", "--seed", "2",
                 "--out", str(out)]) == 0
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    seq = open_sequence(out)
    check = seq.manifest["inside_check"]
    assert check["mode"] == "warn"
    if winding == "outward":
        assert check["enclosed_frames"] == 4 and check["probe_rays_back_face"] == 200
        assert len(warned) == 1 and "sees mostly back faces at 4 of 4 frames" in warned[0]
        assert "sensor at (-2.00, 0.70, 1.80) m, 200 of 200 probe rays hit the back face" in warned[0]
    else:
        assert check["enclosed_frames"] == 0 and warned == []
    T_first = np.eye(4)
    T_first[:3, :4] = np.reshape(seq.manifest["T_world_first_lidar"], (3, 4))
    residuals = []
    for k, frame in enumerate(seq):
        assert len(frame.points) == seq.sensor.rays_per_sweep  # closed room: every beam returns
        T_k = T_first @ seq.poses[k]
        assert np.allclose(T_k, T[k], atol=1e-9)
        d = frame.points / np.linalg.norm(frame.points, axis=1, keepdims=True)  # beams, sensor frame
        d_world = d @ T_k[:3, :3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            t_axis = np.where(d_world > 0, (hi - T_k[:3, 3]) / d_world,
                              np.where(d_world < 0, (lo - T_k[:3, 3]) / d_world, np.inf))
        wall = t_axis.min(axis=1)  # distance to the wall along each beam
        axis = t_axis.argmin(axis=1)
        assert np.abs(frame.field("true_range_m") - wall).max() < 1e-4  # float32 on disk
        residuals.append(frame.field("range_m") - wall)
        # the normal is the wall's, turned to face the sensor
        n = frame.field("normal")
        n_true = np.zeros_like(n)
        rows = np.arange(len(n))
        n_true[rows, axis] = -np.sign(d[rows] @ T_k[:3, :3].T)[rows, axis]
        assert np.abs(n @ T_k[:3, :3].T - n_true).max() < 1e-5
        assert np.all(np.einsum("ij,ij->i", n, frame.field("true_xyz")) < 0)
    res = np.concatenate(residuals)
    assert abs(res.mean()) < 5 * sigma / np.sqrt(len(res))
    assert abs(res.std() / sigma - 1) < 0.05


# ------------------------------------------------------------------ poses, frames and extrapolation
def test_cli_frames_beyond_the_poses_need_extrapolate(tmp_path, capsys):
    mesh, poses = _mesh_and_poses(tmp_path)  # 5 poses, 1.5 m apart, 0.1 s apart
    out = tmp_path / "seq"
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--sensor", "vlp16", "--frames", "8",
                 "--out", str(out)]) == 2
    assert "5 poses cover 0.4 s; 8 frames need 0.7 s" in capsys.readouterr().err and not out.exists()
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--sensor", "vlp16", "--frames", "8",
                 "--extrapolate", "--out", str(out)]) == 0
    assert "extrapolating 0.3 s beyond the last pose" in capsys.readouterr().err
    seq = open_sequence(out)
    assert len(seq) == 8 and np.allclose(seq.poses[:, 0, 3], 1.5 * np.arange(8))  # the last velocity, continued
    ex = seq.manifest["extrapolated"]
    assert ex["poses_cover_s"] == pytest.approx(0.4) and ex["frames_need_s"] == pytest.approx(0.7)
    assert ex["beyond_last_pose_s"] == pytest.approx(0.3)
    # exactly as many frames as poses is no extrapolation
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(poses), "--sensor", "vlp16", "--frames", "5",
                 "--out", str(tmp_path / "five")]) == 0
    assert "extrapolated" not in open_sequence(tmp_path / "five").manifest


def test_cli_pose_times_that_do_not_start_at_zero(tmp_path, capsys):
    # the first sweep starts at the first pose, wherever its clock starts
    mesh, poses = _mesh_and_poses(tmp_path)  # 5 poses, 1.5 m apart
    times = tmp_path / "times.txt"
    times.write_text("".join(f"{100 + 0.2 * k:.3f}\n" for k in range(5)))
    base = ["simulate", "--mesh", str(mesh), "--poses", str(poses), "--times", str(times), "--sensor", "vlp16"]
    assert salo([*base, "--frames", "10", "--out", str(tmp_path / "ten")]) == 2
    assert "5 poses cover 0.8 s; 10 frames need 0.9 s (at most 9 frames fit" in capsys.readouterr().err
    assert salo([*base, "--out", str(tmp_path / "seq")]) == 0  # by default, as many frames as the poses cover
    seq = open_sequence(tmp_path / "seq")
    assert len(seq) == 9
    assert np.allclose(np.reshape(seq.manifest["T_world_first_lidar"], (3, 4))[:, 3], [-3.0, 0.0, 0.0])
    assert np.allclose(seq.poses[:, 0, 3], 0.75 * np.arange(9))
    assert seq.manifest["times_file"] == str(times.resolve())


# ------------------------------------------------------------------ scene seeds
def test_cli_scene_seed_from_a_parameter_file_or_set(tmp_path, capsys):
    assert salo(["scenes", "tunnel", "--yaml"]) == 0
    params = tmp_path / "tunnel.yaml"
    params.write_text(capsys.readouterr().out.replace("seed: 0", "seed: 4"))
    small = ["--scene", "tunnel", "--set", "length_m=100", "--set", "approach_m=50", "--sensor", "vlp16",
             "--frames", "1"]
    runs = {
        "file": (["--scene-params", str(params)], 4),
        "set": (["--set", "seed=5"], 5),
        "file+set": (["--scene-params", str(params), "--set", "seed=6"], 6),  # --set wins over the file
        "agree": (["--scene-params", str(params), "--seed", "4"], 4),
        "default": ([], 0),
    }
    for name, (extra, seed) in runs.items():
        assert salo(["simulate", *small, *extra, "--out", str(tmp_path / name)]) == 0, name
        m = open_sequence(tmp_path / name).manifest
        assert m["scene_seed"] == seed and m["seed"] == seed and m["scene_params"]["seed"] == seed, name


# ------------------------------------------------------------------ .bin files
def test_bin_whose_size_is_not_whole_points_is_refused_on_every_path(tmp_path, capsys):
    rng = np.random.default_rng(0)
    good = rng.normal(0, 10, (6250, 3))
    bad_bytes = np.zeros(100_003, dtype=np.uint8).tobytes()  # np.fromfile alone made 6,250 points of it
    words = "size 100,003 bytes is not a whole number of 16-byte points"
    # a plain scan folder
    scans = tmp_path / "scans"
    scans.mkdir()
    write_bin(scans / "000000.bin", good, np.zeros(6250))
    (scans / "000001.bin").write_bytes(bad_bytes)
    with pytest.raises(DatasetError, match=f"000001.bin: {words}"):
        open_sequence(scans, sensor="vlp16")
    with pytest.raises(DatasetError, match=f"000001.bin: {words}"):
        read_bin(scans / "000001.bin")
    assert read_bin(scans / "000000.bin").shape == (6250, 4)
    # a KITTI sequence folder
    kitti = tmp_path / "kitti"
    (kitti / "velodyne").mkdir(parents=True)
    (kitti / "calib.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    write_bin(kitti / "velodyne/000000.bin", good, np.zeros(6250))
    (kitti / "velodyne/000001.bin").write_bytes(bad_bytes)
    with pytest.raises(DatasetError, match=f"000001.bin: {words}"):
        open_sequence(kitti)
    # a simulated sequence
    simulate(tmp_path / "sim")
    (tmp_path / "sim/velodyne/000002.bin").write_bytes(bad_bytes)
    with pytest.raises(DatasetError, match=f"000002.bin: {words}"):
        open_sequence(tmp_path / "sim")
    # the command line: one line, exit status 2, nothing written
    out = tmp_path / "poses_out.txt"
    for folder in (scans, kitti, tmp_path / "sim"):
        code = salo(["odometry", str(folder), "--sensor", "vlp16", "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()


# ------------------------------------------------------------------ leftovers of killed runs
def _dead_pid() -> int:
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_sigkilled_simulation_leaves_a_partial_folder_the_next_run_removes(tmp_path, caplog):
    import os
    import signal
    import subprocess
    import sys
    import time

    mesh, poses = _mesh_and_poses(tmp_path, frames=400)
    out = tmp_path / "seq"
    argv = [sys.executable, "-m", "tools.cli", "simulate", "--mesh", str(mesh), "--poses", str(poses),
            "--sensor", "vlp16", "--out", str(out)]
    repo = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen(argv, cwd=repo, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = tmp_path / f".seq.partial-{proc.pid}"
    deadline = time.monotonic() + 60
    while not list((partial / "velodyne").glob("*.bin")) and time.monotonic() < deadline:
        assert proc.poll() is None, "the simulation ended before it could be killed"
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert partial.is_dir() and not out.exists()  # what SIGKILL leaves
    # a live writer's folder (this test's parent process stands in for it) is never touched
    live = tmp_path / f".seq.partial-{os.getppid()}"
    (live / "velodyne").mkdir(parents=True)
    frames = 3
    (tmp_path / "short.txt").write_text("".join(poses.read_text().splitlines(keepends=True)[:frames]))
    assert salo(["simulate", "--mesh", str(mesh), "--poses", str(tmp_path / "short.txt"), "--sensor", "vlp16",
                 "--out", str(out)]) == 0
    assert not partial.exists() and live.is_dir() and len(open_sequence(out)) == frames
    said = [r.getMessage() for r in caplog.records if "removed" in r.getMessage()]
    assert len(said) == 1 and str(partial) in said[0] and f"process {proc.pid}, which is no longer running" in said[0]


def test_stale_folders_left_alone_when_they_may_still_matter(tmp_path):
    import os

    out = tmp_path / "seq"
    dead = _dead_pid()
    foreign = tmp_path / f".seq.partial-{dead}"  # written by a process on another host (shared disk)
    foreign.mkdir()
    (foreign / "INCOMPLETE").write_text("a sequence is being written here\nhost: elsewhere.example\npid: 1\n")
    mine = tmp_path / f".seq.partial-{os.getpid()}"  # this process's own (the writer reuses it)
    mine.mkdir()
    old = tmp_path / f".seq.old-{dead}"  # killed between the two renames of a --force swap
    old.mkdir()
    other = tmp_path / f".other.partial-{dead}"  # another output's
    other.mkdir()
    assert remove_stale_partials(out) == []
    assert foreign.is_dir() and mine.is_dir() and old.is_dir() and other.is_dir()
    out.mkdir()  # once the sequence is in place, the old copy is just trash
    stale = tmp_path / f".seq.partial-{dead}x"  # not a PID: not ours
    stale.mkdir()
    assert remove_stale_partials(out) == [old]
    assert stale.is_dir()
