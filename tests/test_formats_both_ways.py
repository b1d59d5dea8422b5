"""Formats both ways, and degeneracy in the open: what one command writes, another reads.

- ``salo export --format pcd`` -> ``salo odometry`` (the ``pcd`` reader);
- ``salo export --format tum`` / ``salo odometry --tum`` -> ``salo evaluate`` (KITTI or TUM, said which);
- KITTI's camera-frame ground truth -> ``salo evaluate --calib``, and the warning without it;
- a KITTI folder -> the HDL-64E by default;
- ``salo scene --path-out`` -> ``salo simulate --mesh --poses --times``;
- the truth's weak frames printed by ``salo simulate`` and ``salo evaluate``, shaded in its plot.

Every check compares with what the simulator knows (its poses, its degeneracy).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import box_room, constant_velocity

from simlidar import se3
from simlidar.dataset import open_sequence
from simlidar.formats.kitti import read_kitti_poses, write_bin, write_kitti_poses
from simlidar.formats.tum import read_tum, write_tum
from simlidar.sensor import load_preset
from simlidar.simulate import simulate_sequence
from tools.cli import main as salo
from tools.export import export_scans, export_tum

# KITTI's velodyne -> cam0 of sequences 04-10 (calib.txt's Tr), rounded.
TR = np.array([[-1.857e-03, -9.999e-01, -8.039e-03, -4.784e-03],
               [-6.481e-03, 8.052e-03, -9.999e-01, -7.337e-02],
               [9.999e-01, -1.805e-03, -6.496e-03, -3.339e-01],
               [0.0, 0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def seq_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("formats") / "seq"
    traj = constant_velocity(v=(3.0, 0.4, 0.0), yaw_rate=0.1, start=(-6.0, 0.0, 0.0))
    simulate_sequence(box_room(), traj, load_preset("vlp16"), out, frames=5, seed=2)
    return out


def _run(capsys, *args) -> tuple[int, str]:
    code = salo([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out + out.err


def test_odometry_reads_the_pcd_folder_export_writes(seq_dir, tmp_path, capsys):
    seq = open_sequence(seq_dir)
    export_scans(seq, tmp_path / "pcd", "pcd")
    back = open_sequence(tmp_path / "pcd")
    assert back.kind == "pcd" and len(back) == 5 and back.sensor == seq.sensor
    np.testing.assert_array_equal(back[3].points, seq[3].points.astype(np.float32))
    np.testing.assert_array_equal(back[3].ring, seq[3].ring)
    np.testing.assert_array_equal(back[3].time_s, seq[3].time_s.astype(np.float32))
    code, text = _run(capsys, "odometry", tmp_path / "pcd", "--variant", "bl", "--out", tmp_path / "pcd_est.txt")
    assert code == 0, text
    code, text = _run(capsys, "odometry", seq_dir, "--variant", "bl", "--out", tmp_path / "bin_est.txt")
    assert code == 0, text
    from_pcd, from_bin = read_kitti_poses(tmp_path / "pcd_est.txt"), read_kitti_poses(tmp_path / "bin_est.txt")
    # the same scans and fields (PCD's times are float32): the same poses to a millimetre
    assert len(from_pcd) == 5 and np.abs(from_pcd[:, :3, 3] - from_bin[:, :3, 3]).max() < 1e-3


def test_evaluate_reads_tum_and_kitti_and_says_which(seq_dir, tmp_path, capsys):
    seq = open_sequence(seq_dir)
    export_tum(seq, tmp_path / "gt.tum")
    est = seq.poses.copy()
    est[1:, 0, 3] += 0.1  # 10 cm along x from frame 1 on
    write_kitti_poses(tmp_path / "est.txt", est)
    code, text = _run(capsys, "evaluate", tmp_path / "gt.tum", tmp_path / "est.txt", "--json")
    assert code == 0, text
    doc = json.loads(text)
    assert doc["read"][0].endswith("gt.tum as TUM (5 poses)") and doc["read"][1].endswith("est.txt as KITTI (5 poses)")
    assert doc["ate_rmse_m"] == pytest.approx(0.1 * np.sqrt(4 / 5), abs=1e-6)
    # two TUM files of different lengths pair by time stamp
    times, poses = read_tum(tmp_path / "gt.tum")
    write_tum(tmp_path / "est.tum", est[[0, 2, 4]], times[[0, 2, 4]])
    code, text = _run(capsys, "evaluate", tmp_path / "gt.tum", tmp_path / "est.tum", "--json")
    doc = json.loads(text)
    assert code == 0 and "paired by time stamp: 3 poses (of 5 and 3)" in doc["read"][2]
    assert doc["ate_rmse_m"] == pytest.approx(0.1 * np.sqrt(2 / 3), abs=1e-6)
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    code, text = _run(capsys, "evaluate", tmp_path / "gt.tum", tmp_path / "bad.txt")
    assert code == 2 and "neither KITTI poses (12 numbers a line) nor a TUM trajectory" in text


def test_camera_frame_truth_warns_and_calib_converts_it(tmp_path, capsys):
    # A lidar drive 1 m per frame forward, turning; KITTI's ground truth is the camera's view of it.
    L = se3.exp(np.column_stack([np.full(30, 1.0) * np.arange(30), 0.02 * np.arange(30) ** 1.5, np.zeros(30),
                                 np.zeros(30), np.zeros(30), 0.01 * np.arange(30)]))
    L = se3.inverse(L[0]) @ L
    P = TR @ L @ np.linalg.inv(TR)
    write_kitti_poses(tmp_path / "cam.txt", np.linalg.inv(P[0]) @ P)
    write_kitti_poses(tmp_path / "lidar.txt", L)
    (tmp_path / "calib.txt").write_text("Tr: " + " ".join(f"{v:.6e}" for v in TR[:3].ravel()) + "\n")
    code, text = _run(capsys, "evaluate", tmp_path / "cam.txt", tmp_path / "lidar.txt")
    assert code == 0 and "warning: the first motions disagree by" in text
    assert "looks like KITTI's camera frame" in text and "--calib calib.txt" in text
    code, text = _run(capsys, "evaluate", tmp_path / "cam.txt", tmp_path / "lidar.txt", "--calib",
                      tmp_path / "calib.txt", "--json")
    doc = json.loads(text)
    assert code == 0 and doc["ate_rmse_m"] < 1e-4 and not any("warning" in n for n in doc["notes"])
    assert "converted from KITTI's camera frame" in doc["read"][2]
    # the other way round: a camera-frame estimate against lidar-frame truth
    code, text = _run(capsys, "evaluate", tmp_path / "lidar.txt", tmp_path / "cam.txt")
    assert "the estimate looks like KITTI's camera frame" in text


def test_real_kitti_camera_truth_against_lidar_poses(real_data, capsys):
    kitti = real_data / "kitti"
    code, text = _run(capsys, "evaluate", kitti / "poses/05.txt", kitti / "lidar_frame_poses/05.txt")
    assert code == 0 and "give --calib calib.txt" in text
    code, text = _run(capsys, "evaluate", kitti / "poses/05.txt", kitti / "lidar_frame_poses/05.txt", "--calib",
                      kitti / "sequences/05/calib.txt", "--json")
    assert json.loads(text)["ate_rmse_m"] < 1e-5


def test_a_kitti_folder_uses_the_hdl64e_unless_told(tmp_path):
    kitti = tmp_path / "kitti"
    (kitti / "velodyne").mkdir(parents=True)
    (kitti / "calib.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    write_bin(kitti / "velodyne" / "000000.bin", np.ones((3, 3)), np.zeros(3))
    assert open_sequence(kitti).sensor == load_preset("hdl64e")
    assert open_sequence(kitti, sensor="vlp16").sensor == load_preset("vlp16")


def test_scene_path_out_is_what_simulate_reads(tmp_path, capsys):
    code, text = _run(capsys, "scene", "tunnel", "--out", tmp_path / "tunnel.ply", "--path-out",
                      tmp_path / "path.txt", "--path-period", "0.1")
    assert code == 0 and "salo simulate --mesh" in text
    import scenes

    trajectory = scenes.build_scene("tunnel", seed=0).trajectory
    poses = read_kitti_poses(tmp_path / "path.txt")
    np.testing.assert_allclose(poses[25], trajectory.pose_at(np.array([2.5]))[0], atol=1e-9)
    code, text = _run(capsys, "simulate", "--mesh", tmp_path / "tunnel.ply", "--poses", tmp_path / "path.txt",
                      "--times", tmp_path / "path_times.txt", "--frames", "3", "--sensor", "vlp16",
                      "--out", tmp_path / "seq")
    assert code == 0, text
    seq = open_sequence(tmp_path / "seq")
    first = se3.kitti_lines_to_poses(np.array(seq.manifest["T_world_first_lidar"]))[0]
    np.testing.assert_allclose(first @ seq.poses[2], poses[2], atol=1e-6)


def test_simulate_and_evaluate_print_the_truths_weak_frames(tmp_path, capsys):
    # Deep in the default tunnel: the bore constrains nothing along its axis.
    code, text = _run(capsys, "simulate", "--scene", "tunnel", "--sensor", "vlp16", "--frames", "4", "--start", "20",
                      "--out", tmp_path / "tunnel")
    assert code == 0, text
    assert "weakly constrained frames" in text and "frames 0-3" in text and "mostly along x (forward)" in text
    from tools.degenerate import truth_constraints

    truth = truth_constraints(tmp_path / "tunnel")
    assert truth.weak.all() and np.abs(truth.directions[:, 0]).min() > 0.9
    code, text = _run(capsys, "evaluate", tmp_path / "tunnel" / "poses.txt", tmp_path / "tunnel" / "poses.txt",
                      "--plot", tmp_path / "eval.png")
    assert code == 0 and "weakly constrained frames, by the truth" in text and "frames 0-3" in text
    assert (tmp_path / "eval.png").stat().st_size > 10_000
