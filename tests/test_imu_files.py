"""The IMU wherever a sequence goes: the sequence folder, memory, a method's staged input, PLY scans, ROS 2 bags."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from helpers import box_room, constant_velocity
from rosbags.rosbag2 import Reader, Writer  # a dev dependency: the tests need it, never skip
from rosbags.typesys import Stores, get_typestore

from scenes.trajectory import PathTrajectory
from simlidar.dataset import open_sequence
from simlidar.formats.imu_csv import IMU_FILE, IMU_TRUTH_FILE, format_imu_csv, read_imu_csv
from simlidar.formats.rosbag import BagError
from simlidar.imu import ImuUnavailable, simulate_imu
from simlidar.in_memory import simulate_in_memory
from simlidar.sensor import load_preset
from simlidar.sequence import DatasetError
from simlidar.simulate import simulate_sequence
from tools.export import DEFAULT_EPOCH_S, export_rosbag, export_scans
from tools.staging import sensor_view, stage_input

FRAMES, T_START, SEED = 5, 1.0, 4
TS = get_typestore(Stores.ROS2_HUMBLE)
IMU_KEYS = {"enabled": True, "lever_arm_m": [0.1, -0.05, -0.2], "rotation_rpy_deg": [0.0, 0.0, 90.0],
            "time_offset_s": 0.002, "gyroscope_turn_on_bias": 0.003, "accelerometer_turn_on_bias": 0.05}


def room_drive() -> PathTrajectory:
    """A straight drive along a 40 m room's floor (z = -4), smoothed, with the suspension's oscillation."""
    x = np.arange(-15.0, 15.01, 0.5)
    path = np.column_stack([x, np.zeros_like(x), np.full_like(x, -4.0)])
    return PathTrajectory(path, False, 5.0, 1.5, 2.0, 1.9, math.radians(0.3), 0.01, seed=1, accel_smoothing_s=0.5)


def sensor(imu: bool = True):
    base = load_preset("vlp16")
    return base.with_overrides(imu=IMU_KEYS) if imu else base


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("imu") / "seq"
    simulate_sequence(box_room(), room_drive(), sensor(), out, frames=FRAMES, seed=SEED, t_start=T_START)
    return out


@pytest.fixture(scope="module")
def seq(folder):
    return open_sequence(folder)


def test_the_sequence_folder_holds_the_imu_and_its_truth(folder, seq):
    expected, truth = simulate_imu(room_drive(), sensor().imu, T_START, FRAMES * 0.1, SEED)
    m = seq.manifest
    assert m["imu"]["samples"] == len(expected) == FRAMES * 20 + 1 and m["imu"]["frame_id"] == "imu"
    assert {IMU_FILE, IMU_TRUTH_FILE} <= set(m["files"])
    seq.verify()  # their checksums too
    assert seq.sensor.imu.enabled and seq.sensor.imu.lever_arm_m == (0.1, -0.05, -0.2)
    # %.12e on disk: 13 significant digits
    np.testing.assert_allclose(seq.imu.time_s, expected.time_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(seq.imu.specific_force, expected.specific_force, rtol=1e-12)
    np.testing.assert_allclose(seq.imu.angular_velocity, expected.angular_velocity, rtol=1e-12, atol=1e-16)
    t = seq.imu_truth
    for name in ("true_time_s", "angular_velocity", "specific_force", "gyroscope_bias", "accelerometer_bias",
                 "position", "orientation", "velocity"):
        np.testing.assert_allclose(getattr(t, name), getattr(truth, name), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(t.gravity, truth.gravity, atol=1e-12)
    # the same time base as times.txt: a sample at every sweep start, the last at the last sweep's end
    assert np.all(np.isin(np.round(seq.times / 0.005), np.round(seq.imu.time_s / 0.005)))
    assert seq.imu.time_s[-1] == pytest.approx(seq.times[-1] + 0.1)
    # the header says what the columns are
    assert (folder / IMU_FILE).read_text().splitlines()[0] == (
        "time_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2")
    # sensor.yaml gets the IMU's keys, all of them
    written = yaml.safe_load((folder / "sensor.yaml").read_text())["imu"]
    assert written["enabled"] is True and written["update_rate"] == 200.0 and len(written) == 12


def test_the_imu_changes_nothing_of_the_lidars_files(folder, tmp_path):
    off = tmp_path / "off"
    simulate_sequence(box_room(), room_drive(), sensor(imu=False), off, frames=FRAMES, seed=SEED, t_start=T_START)
    on_files, off_files = open_sequence(folder).manifest["files"], open_sequence(off).manifest["files"]
    assert set(on_files) - set(off_files) == {IMU_FILE, IMU_TRUTH_FILE}
    differ = {f for f in off_files if off_files[f] != on_files[f]}
    assert differ == {"sensor.yaml"}  # scans, truth, poses, times, degeneracy: the same bytes
    assert "imu" not in yaml.safe_load((off / "sensor.yaml").read_text())
    assert (off / "sensor.yaml").read_text() == load_preset("vlp16").to_yaml()
    assert "imu" not in open_sequence(off).manifest and open_sequence(off).imu is None


def test_in_memory_staged_and_exported_scans_carry_the_imu(seq, tmp_path):
    memory = simulate_in_memory(box_room(), room_drive(), sensor(), FRAMES, seed=SEED, t_start=T_START)
    np.testing.assert_allclose(memory.imu.specific_force, seq.imu.specific_force, rtol=1e-12)
    np.testing.assert_allclose(memory.imu_truth.position, seq.imu_truth.position, rtol=1e-12, atol=1e-15)
    view = sensor_view(memory, ("ring",))  # what a method is handed: the samples, not their truth
    assert view.imu is memory.imu and view.imu_truth is None
    staged = stage_input(seq, tmp_path / "stage")
    assert (staged.root / IMU_FILE).is_file() and not (staged.root / IMU_TRUTH_FILE).exists()
    again = open_sequence(staged.root)
    assert again.imu_truth is None
    np.testing.assert_array_equal(again.imu.specific_force, seq.imu.specific_force)
    # PLY scans of frames 1..3: the IMU over those sweeps, from the first one's start
    export_scans(seq, tmp_path / "ply", "ply", slice(1, 4))
    ply = open_sequence(tmp_path / "ply")
    assert ply.imu.time_s[0] == 0.0 and ply.imu.time_s[-1] == pytest.approx(0.3)
    np.testing.assert_array_equal(ply.imu.specific_force, seq.imu.between(0.1, 0.4 + 1e-9).specific_force)


def test_a_bag_holds_the_imu_as_sensor_msgs_imu(seq, tmp_path):
    result = export_rosbag(seq, tmp_path / "bag")
    n = len(seq.imu)
    assert result.messages["/imu"] == n and result.messages["/points"] == FRAMES
    epoch_ns = DEFAULT_EPOCH_S * 10**9
    model = seq.sensor.imu
    with Reader(tmp_path / "bag") as reader:
        conns = {c.topic: c for c in reader.connections}
        assert conns["/imu"].msgtype == "sensor_msgs/msg/Imu" and conns["/imu"].msgcount == n
        log_times, msgs = [], []
        for conn, t, raw in reader.messages():
            log_times.append(t)
            if conn.topic == "/imu":
                msgs.append((t, TS.deserialize_cdr(raw, conn.msgtype)))
    assert log_times == sorted(log_times)  # interleaved with the clouds in time
    for k, (t, msg) in enumerate(msgs):
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert stamp == t == epoch_ns + round(seq.imu.time_s[k] * 1e9)
        assert msg.header.frame_id == "imu"
        w, a = msg.angular_velocity, msg.linear_acceleration
        assert [w.x, w.y, w.z] == list(seq.imu.angular_velocity[k])
        assert [a.x, a.y, a.z] == list(seq.imu.specific_force[k])
        assert msg.orientation_covariance[0] == -1.0  # no orientation estimate
        assert msg.angular_velocity_covariance[0] == pytest.approx(model.gyroscope_noise_density**2 * 200)
        assert msg.linear_acceleration_covariance[8] == pytest.approx(model.accelerometer_noise_density**2 * 200)
        assert msg.linear_acceleration_covariance[1] == 0.0
    back = open_sequence(tmp_path / "bag")
    assert back.imu_topic == "/imu" and back.imu.frame_id == "imu" and back.imu_truth is None
    np.testing.assert_allclose(back.imu.time_s, seq.imu.time_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(back.imu.specific_force, seq.imu.specific_force)
    assert back.sensor.imu == model  # the mounting and noise, in the bag's sensor.yaml
    # a slice: the samples over its sweeps, stamped in the sequence's clock (relative to its first sweep)
    export_rosbag(seq, tmp_path / "slice", slice(2, 4))
    part = open_sequence(tmp_path / "slice")
    assert len(part.imu) == 2 * 20 + 1 and part.imu.time_s[0] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_array_equal(part.imu.angular_velocity, seq.imu.between(0.2, 0.4 + 1e-9).angular_velocity)


def write_driver_bag(path, imu_topics=("/imu/data",)):
    """A bag as a driver records it: clouds on /os_cloud_node/points and 100 Hz IMU topics (frame imu_link)
    starting 0.3 s before the first cloud."""
    cloud_t = 1_700_000_000_000_000_000 + np.arange(3) * 100_000_000
    rec = np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    rec["x"] = [5.0, 6.0, 7.0, 8.0]
    T = TS.types
    with Writer(path, version=8) as w:
        pc = w.add_connection("/os_cloud_node/points", "sensor_msgs/msg/PointCloud2", typestore=TS)
        imus = [w.add_connection(t, "sensor_msgs/msg/Imu", typestore=TS) for t in imu_topics]
        imu_t = cloud_t[0] - 300_000_000 + np.arange(60) * 10_000_000
        events = [(int(s), "imu", i) for i, s in enumerate(imu_t)]
        events += [(int(s), "cloud", i) for i, s in enumerate(cloud_t)]
        for stamp, kind, i in sorted(events):
            sec, ns = divmod(stamp, 10**9)
            header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=ns),
                                              frame_id="imu_link" if kind == "imu" else "os_sensor")
            if kind == "cloud":
                fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * j, datatype=7, count=1)
                          for j, n in enumerate("xyz")]
                msg = T["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=4, fields=fields,
                                                       is_bigendian=False, point_step=12, row_step=48,
                                                       data=np.frombuffer(rec.tobytes(), np.uint8), is_dense=True)
                w.write(pc, stamp, TS.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
                continue
            vec = T["geometry_msgs/msg/Vector3"]
            msg = T["sensor_msgs/msg/Imu"](
                header=header, orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9), angular_velocity=vec(x=0.01 * i, y=0.0, z=0.1),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9))
            for c in imus:
                w.write(c, stamp, TS.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    return path


def test_a_drivers_bag_with_an_imu_topic_is_read(tmp_path):
    bag = open_sequence(write_driver_bag(tmp_path / "drv"))
    assert bag.imu_topic == "/imu/data" and bag.imu.frame_id == "imu_link" and len(bag.imu) == 60
    # relative to the first sweep's start, as times: the first samples came before it
    np.testing.assert_allclose(bag.imu.time_s, -0.3 + 0.01 * np.arange(60), atol=1e-9)
    np.testing.assert_allclose(bag.imu.angular_velocity[:, 0], 0.01 * np.arange(60))
    assert np.all(bag.imu.specific_force[:, 2] == 9.81)
    # several IMU topics: /imu if there is one, else the one asked for, else none (with a warning)
    two = write_driver_bag(tmp_path / "two", ("/imu/data", "/imu/raw"))
    assert open_sequence(two).imu is None
    from simlidar.formats.rosbag import RosbagSequence

    assert RosbagSequence(two, imu_topic="/imu/raw").imu_topic == "/imu/raw"
    assert RosbagSequence(two, imu_topic="").imu is None
    with pytest.raises(BagError, match="no sensor_msgs/msg/Imu topic /nope .*IMU topics: /imu/data, /imu/raw"):
        RosbagSequence(two, imu_topic="/nope")


def test_bad_imu_files_are_named(folder, tmp_path):
    good = (folder / IMU_FILE).read_text().splitlines()
    bad = tmp_path / "imu.csv"
    bad.write_text("\n".join(["time,gx,gy,gz,ax,ay,az", *good[1:]]) + "\n")
    with pytest.raises(DatasetError, match=f"{bad}: the first line must be the header time_s,gyro_x_rad_s"):
        read_imu_csv(bad)
    bad.write_text("\n".join([good[0], good[2], good[1], *good[3:]]) + "\n")
    with pytest.raises(DatasetError, match=f"{bad}:3: time_s does not increase"):
        read_imu_csv(bad)
    bad.write_text("\n".join([good[0], good[1], good[2] + ",7"]) + "\n")
    with pytest.raises(DatasetError, match=f"{bad}: line 3 has 8 values, not 7"):
        read_imu_csv(bad)
    # a sequence whose manifest lists an IMU but has lost its file
    copy = tmp_path / "copy"
    import shutil

    shutil.copytree(folder, copy)
    (copy / IMU_TRUTH_FILE).unlink()
    with pytest.raises(DatasetError, match=f"{copy / IMU_TRUTH_FILE}: missing, the manifest lists an IMU"):
        open_sequence(copy)
    assert format_imu_csv(read_imu_csv(folder / IMU_FILE)) == (folder / IMU_FILE).read_text()


def test_an_imu_along_poses_from_a_file_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "seq"
    with pytest.raises(ImuUnavailable, match="no continuous acceleration"):
        simulate_sequence(box_room(), constant_velocity(v=(1.0, 0.0, 0.0)), sensor(), out, frames=2)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_salo_simulate_takes_an_imu_grade(tmp_path):
    """``salo simulate --imu tactical``: the sequence's sensor file holds the grade's keys, and imu.csv its samples."""
    from simlidar.imu import IMU_GRADES
    from tools.cli import main as salo

    out = tmp_path / "seq"
    assert salo(["simulate", "--scene", "city", "--frames", "2", "--sensor", "vlp16", "--imu", "tactical",
                 "--out", str(out)]) == 0
    written = open_sequence(out)
    assert written.sensor.imu.enabled and len(written.imu) > 0.2 * 200
    assert all(getattr(written.sensor.imu, k) == v for k, v in IMU_GRADES["tactical"].items())
    with pytest.raises(SystemExit):
        salo(["simulate", "--scene", "city", "--frames", "2", "--imu", "navigation", "--out", str(tmp_path / "x")])
