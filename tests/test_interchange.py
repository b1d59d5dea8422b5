"""Interchange: ROS 2 bags (written, read by rosbags itself and by our reader), PLY / PCD scans, TUM for evo.

One small simulated sequence (VLP-16 in a box room, moving and turning) is
exported and read back; bags in other drivers' layouts (Ouster, Nebula, Hesai,
a driver stamping the sweep's end) are built from the same frames, so every
read-back is compared with the simulator's own values.
"""

from __future__ import annotations

import argparse
import pickle
import sys

import numpy as np
import pytest
from helpers import box_room, constant_velocity
from rosbags.rosbag2 import Reader, StoragePlugin, Writer  # a dev dependency: the tests need it, never skip
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from simlidar import se3
from simlidar.dataset import open_sequence
from simlidar.formats.pcd import read_pcd, write_pcd
from simlidar.formats.points import point_record
from simlidar.formats.rosbag import BagError, PointFieldSpec, cloud_dtype, cloud_records, dtype_fields
from simlidar.sensor import load_preset
from simlidar.sequence import DatasetError
from simlidar.simulate import simulate_sequence
from tools.export import DEFAULT_EPOCH_S, ExportError, export_rosbag, export_scans, export_tum

FRAMES = 5
PC2 = "sensor_msgs/msg/PointCloud2"
TS = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture(scope="module")
def seq_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("interchange") / "seq"
    traj = constant_velocity(v=(1.0, 0.2, 0.0), yaw_rate=0.1, start=(-2.0, 0.5, 0.0))
    simulate_sequence(box_room(size=(16.0, 12.0, 5.0)), traj, load_preset("vlp16"), out, frames=FRAMES, seed=3)
    return out


@pytest.fixture(scope="module")
def seq(seq_dir):
    return open_sequence(seq_dir)


@pytest.fixture(scope="module")
def bag(seq, tmp_path_factory):
    return export_rosbag(seq, tmp_path_factory.mktemp("bags") / "sim_bag").path


def world_pose(seq, k):
    first = se3.kitti_lines_to_poses(np.array(seq.manifest["T_world_first_lidar"]))[0]
    return first @ seq.poses[k]


def stamp_ns(seq, k, epoch_s=DEFAULT_EPOCH_S):
    return int(round((epoch_s + seq.times[k]) * 1e9))


# ---------------------------------------------------------------- the bag, as rosbags reads it
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bag_read_by_rosbags(seq, tmp_path, storage):
    result = export_rosbag(seq, tmp_path / "bag", storage=storage)
    assert result.messages == {"/points": FRAMES, "/ground_truth/odometry": FRAMES, "/tf": FRAMES}
    assert (tmp_path / "bag" / "sensor.yaml").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging left behind
    with Reader(tmp_path / "bag") as reader:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert topics == {"/points": (PC2, FRAMES), "/ground_truth/odometry": ("nav_msgs/msg/Odometry", FRAMES),
                          "/tf": ("tf2_msgs/msg/TFMessage", FRAMES)}
        clouds, odoms, tfs = [], [], []
        for conn, t, raw in reader.messages():
            msg = TS.deserialize_cdr(raw, conn.msgtype)
            {"/points": clouds, "/ground_truth/odometry": odoms, "/tf": tfs}[conn.topic].append((t, msg))

    # the Velodyne driver's packed XYZIRT layout, then the ground truth
    expected = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1), ("ring", 16, 4, 1),
                ("time", 18, 7, 1), ("azimuth_index", 22, 6, 1), ("true_range_m", 26, 7, 1), ("true_x", 30, 7, 1),
                ("true_y", 34, 7, 1), ("true_z", 38, 7, 1), ("normal_x", 42, 7, 1), ("normal_y", 46, 7, 1),
                ("normal_z", 50, 7, 1), ("object_id", 54, 5, 1)]
    for k, (t, cloud) in enumerate(clouds):
        assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == expected
        assert cloud.point_step == 58 and cloud.height == 1 and not cloud.is_bigendian and cloud.is_dense
        assert cloud.header.frame_id == "lidar"
        assert t == cloud.header.stamp.sec * 10**9 + cloud.header.stamp.nanosec == stamp_ns(seq, k)
        frame = seq[k]
        assert cloud.width == len(frame.points) and cloud.row_step == 58 * cloud.width
        # decoded here with a hand-written dtype, independent of simlidar.formats.rosbag
        dt = np.dtype({"names": ["x", "y", "z", "intensity", "ring", "time", "true_x", "object_id"],
                       "formats": ["<f4", "<f4", "<f4", "<f4", "<u2", "<f4", "<f4", "<i4"],
                       "offsets": [0, 4, 8, 12, 16, 18, 30, 54], "itemsize": 58})
        rec = np.frombuffer(bytes(cloud.data), dtype=dt)
        assert np.array_equal(np.column_stack([rec["x"], rec["y"], rec["z"]]), frame.points.astype(np.float32))
        assert np.array_equal(rec["intensity"], frame.intensity)
        assert np.array_equal(rec["ring"], frame.ring)
        assert np.array_equal(rec["time"], frame.time_s.astype(np.float32))
        assert np.array_equal(rec["true_x"], frame.field("true_xyz")[:, 0])
        assert np.array_equal(rec["object_id"], frame.field("object_id"))
    for k, ((_, odom), (_, tf)) in enumerate(zip(odoms, tfs, strict=True)):
        assert (odom.header.frame_id, odom.child_frame_id) == ("map", "lidar")
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        T = se3.make(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), np.array([p.x, p.y, p.z]))
        assert np.allclose(T, world_pose(seq, k), atol=1e-9)
        (tr,) = tf.transforms
        assert (tr.header.frame_id, tr.child_frame_id) == ("map", "lidar")
        assert tr.transform.translation.x == p.x and tr.transform.rotation.w == q.w
        # twist: body-frame velocity of the simulated motion (1.02 m/s forward-ish, 0.1 rad/s yaw)
        v = odom.twist.twist
        assert np.hypot(v.linear.x, v.linear.y) == pytest.approx(np.hypot(1.0, 0.2), rel=1e-3)
        assert v.angular.z == pytest.approx(0.1, rel=1e-3)


def test_bag_bytes_are_reproducible(seq, bag, tmp_path):
    again = export_rosbag(seq, tmp_path / "sim_bag").path
    assert (again / "sim_bag.mcap").read_bytes() == (bag / "sim_bag.mcap").read_bytes()


# ---------------------------------------------------------------- the bag, as simlidar reads it
def test_bag_read_back_through_open_sequence(seq, bag):
    b = open_sequence(bag)
    assert b.kind == "rosbag2" and len(b) == FRAMES and b.topic == "/points" and b.frame_id == "lidar"
    assert b.sensor == seq.sensor  # from sensor.yaml inside the bag folder
    assert b.manifest == {}
    assert np.allclose(b.times, seq.times, atol=1e-9)
    assert np.allclose(b.poses, seq.poses, atol=1e-9)
    assert b.layout.time_field == "time" and b.layout.time_unit_ns == 10**9 and not b.layout.time_absolute
    assert b.layout.ring_order == "ascending"
    for k in (0, 3, 1, 2, 4):  # random access, then the streaming cursor
        f, g = seq[k], b[k]
        assert g.index == k and g.points.dtype == np.float64 and g.points.shape == f.points.shape
        assert np.array_equal(g.points, f.points.astype(np.float32).astype(np.float64))
        assert np.array_equal(g.intensity, f.intensity)
        assert np.array_equal(g.ring, f.ring) and g.ring.dtype == np.uint16
        assert np.array_equal(g.time_s, f.time_s.astype(np.float32).astype(np.float64))
        for name in ("azimuth_index", "true_range_m", "true_xyz", "normal", "object_id"):
            assert np.array_equal(g.field(name), f.field(name)), name
    assert [fr.index for fr in b] == list(range(FRAMES))
    b.close()
    # closed or sent to another process, it reopens the bag when asked for a frame
    assert np.array_equal(b[2].points, pickle.loads(pickle.dumps(b))[2].points)


def test_bag_slice_and_epoch(seq, tmp_path):
    out = export_rosbag(seq, tmp_path / "slice", frames=slice(1, 4), epoch_s=1.7e9, truth=False, storage="sqlite3")
    assert list(out.frames) == [1, 2, 3]
    b = open_sequence(out.path)
    assert len(b) == 3
    assert b.stamps_ns[0] == stamp_ns(seq, 1, 1.7e9)
    assert np.allclose(b.times, seq.times[1:4] - seq.times[1], atol=1e-9)
    assert np.allclose(b.poses, se3.inverse(seq.poses[1]) @ seq.poses[1:4], atol=1e-9)
    assert b[0].fields.dtype.names == ("ring", "time_s")  # no ground-truth fields


def test_odometry_runs_on_the_bag(seq, bag, tmp_path):
    from odometry.config import variant
    from odometry.pipeline import run_sequence

    frames = slice(0, 4)
    on_bag = run_sequence(open_sequence(bag), variant("bl"), frames=frames)
    on_folder = run_sequence(seq, variant("bl"), frames=frames)
    assert np.allclose(on_bag.poses, on_folder.poses, atol=1e-6)  # the same input, read from the bag
    gt = seq.poses[:4]
    travelled = np.linalg.norm(gt[-1, :3, 3])
    err = np.linalg.norm(on_bag.poses[:, :3, 3] - gt[:, :3, 3], axis=1)
    assert travelled > 0.3 and err[-1] < 0.4 * travelled  # it tracked the motion, not stood still
    assert np.degrees(se3.rotation_angle(se3.inverse(on_bag.poses[-1]) @ gt[-1])) < 1.0


def test_salo_odometry_on_an_exported_bag(seq_dir, tmp_path):
    from tools.cli import export as cli_export
    from tools.cli import main as salo

    parser = argparse.ArgumentParser()
    cli_export.add_commands(parser.add_subparsers(dest="command"))
    bag = tmp_path / "cli_bag"
    args = parser.parse_args(["export", str(seq_dir), "--format", "rosbag", "--out", str(bag), "--frames", "0:3"])
    assert args.func(args) == 0
    out = tmp_path / "est" / "poses.txt"
    assert salo(["odometry", str(bag), "--variant", "bl", "--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 3
    args = parser.parse_args(["export", str(seq_dir), "--format", "rosbag", "--out", str(bag)])
    with pytest.raises(ExportError, match="already exists"):
        args.func(args)


# ---------------------------------------------------------------- other drivers' layouts
def odometry_msg(stamp_ns, P, frame_id="map", child="lidar"):
    T = TS.types
    sec, nsec = divmod(stamp_ns, 10**9)
    q = Rotation.from_matrix(P[:3, :3]).as_quat()
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T["nav_msgs/msg/Odometry"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                        frame_id=frame_id),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=P[0, 3], y=P[1, 3], z=P[2, 3]),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])),
            covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))


def write_cloud_bag(path, records, stamps_ns, topic="/points", frame_id="lidar", height=1,
                    plugin=StoragePlugin.MCAP, odometry=()):
    """A bag of one PointCloud2 topic holding the given (N,) structured records (their padding kept).

    odometry: (stamp_ns, (4, 4) pose) pairs written as nav_msgs/Odometry on /ground_truth/odometry.
    """
    T = TS.types
    with Writer(path, version=8, storage_plugin=plugin) as w:
        if odometry:
            c_odom = w.add_connection("/ground_truth/odometry", "nav_msgs/msg/Odometry", typestore=TS)
            for stamp, P in odometry:
                w.write(c_odom, stamp, TS.serialize_cdr(odometry_msg(stamp, P), "nav_msgs/msg/Odometry"))
        conn = w.add_connection(topic, PC2, typestore=TS)
        for rec, stamp in zip(records, stamps_ns, strict=True):
            h = height if len(rec) % height == 0 else 1
            fields = [T["sensor_msgs/msg/PointField"](name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                      for f in dtype_fields(rec.dtype)]
            sec, nsec = divmod(stamp, 10**9)
            msg = T[PC2](header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                                         frame_id=frame_id),
                         height=h, width=len(rec) // h, fields=fields, is_bigendian=False,
                         point_step=rec.dtype.itemsize, row_step=rec.dtype.itemsize * (len(rec) // h),
                         data=np.frombuffer(rec.tobytes(), dtype=np.uint8), is_dense=True)
            w.write(conn, stamp, TS.serialize_cdr(msg, PC2))
    return path


def padded(specs, point_step):
    """A structured dtype at explicit offsets: [(name, offset, datatype)]."""
    return cloud_dtype([PointFieldSpec(n, o, d) for n, o, d in specs], point_step)

def xyz_record(frame, dtype):
    """(N,) structured array of ``dtype`` with the frame's x, y, z filled (other fields zero)."""
    rec = np.zeros(len(frame.points), dtype=dtype)
    for i, axis in enumerate("xyz"):
        rec[axis] = frame.points[:, i]
    return rec



@pytest.mark.parametrize("style", ["ouster_uint8_ring", "ouster_uint16_ring", "nebula"])
def test_nanosecond_time_and_ring_variants(seq, tmp_path, style):
    """Ouster (t uint32 ns, ring 0 = top beam, uint8 or uint16, padded like PCL) and Nebula (time_stamp, channel)."""
    if style.startswith("ouster"):
        ring_type = 2 if style == "ouster_uint8_ring" else 4
        dtype = padded([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 16, 7), ("t", 20, 6),
                        ("reflectivity", 24, 4), ("ring", 26, ring_type), ("ambient", 28, 4), ("range", 32, 6)], 48)
        time_name, ring_name, top_first = "t", "ring", True
    else:
        dtype = padded([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 2), ("return_type", 13, 2),
                        ("channel", 14, 4), ("azimuth", 16, 7), ("elevation", 20, 7), ("distance", 24, 7),
                        ("time_stamp", 28, 6)], 32)
        time_name, ring_name, top_first = "time_stamp", "channel", False
    records, stamps = [], []
    for k in range(3):
        f = seq[k]
        rec = xyz_record(f, dtype)
        rec["intensity"] = f.intensity * (255 if style == "nebula" else 1)
        rec[ring_name] = 15 - f.ring if top_first else f.ring
        rec[time_name] = np.round(f.time_s * 1e9)
        records.append(rec)
        stamps.append(stamp_ns(seq, k))
    path = write_cloud_bag(tmp_path / "drv.mcap", records, stamps, height=16, topic="/sensor/points")
    b = open_sequence(path)  # no sensor known: the ring count comes from the data
    assert b.layout.time_unit_ns == 1 and not b.layout.time_absolute and b.layout.time_field == time_name
    assert b.layout.ring_order == ("descending" if top_first else "ascending") and b.layout.ring_count == 16
    assert np.allclose(b.times, seq.times[:3], atol=1e-9) and b.poses is None and b.sensor is None
    for k in range(3):
        f, g = seq[k], b[k]
        assert np.array_equal(g.ring, f.ring)
        assert np.allclose(g.time_s, f.time_s, atol=1e-9, rtol=0)
        assert np.array_equal(g.points, f.points.astype(np.float32).astype(np.float64))
        assert time_name not in g.fields.dtype.names and ring_name not in g.fields.dtype.names[1:]
        if style != "nebula":
            assert "reflectivity" in g.fields.dtype.names and "ambient" in g.fields.dtype.names
    # with the sensor model, the ring count is the sensor's
    b = open_sequence(path, sensor="vlp16")
    assert b.layout.ring_count == 16 and np.array_equal(b[1].ring, seq[1].ring)


def test_absolute_float_timestamps(seq, tmp_path):
    """Hesai / RoboSense style: ``timestamp`` float64 absolute seconds, ring uint16, intensity uint8."""
    dtype = padded([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 2), ("ring", 14, 4),
                    ("timestamp", 16, 8)], 24)
    records, stamps = [], []
    for k in range(2):
        f = seq[k]
        rec = xyz_record(f, dtype)
        rec["ring"] = f.ring
        rec["timestamp"] = DEFAULT_EPOCH_S + seq.times[k] + f.time_s
        records.append(rec)
        stamps.append(stamp_ns(seq, k))
    b = open_sequence(write_cloud_bag(tmp_path / "hesai", records, stamps, plugin=StoragePlugin.SQLITE3))
    assert b.layout.time_absolute and b.layout.time_unit_ns == 10**9
    for k in range(2):
        assert np.allclose(b[k].time_s, seq[k].time_s, atol=1e-6, rtol=0)  # float64 epoch seconds: ~0.2 us
        assert np.array_equal(b[k].ring, seq[k].ring)


def test_stamp_at_sweep_end(seq, tmp_path):
    """A driver stamping the sweep's end (negative relative times): the sweep start moves back."""
    dtype = padded([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4),
                    ("time", 18, 7)], 22)
    period = seq.sensor.sweep_period_s
    records, stamps = [], []
    for k in range(3):
        f = seq[k]
        rec = xyz_record(f, dtype)
        rec["ring"] = f.ring
        rec["time"] = f.time_s - period
        records.append(rec)
        stamps.append(stamp_ns(seq, k) + int(round(period * 1e9)))
    b = open_sequence(write_cloud_bag(tmp_path / "end.mcap", records, stamps), sensor="vlp16")
    assert -period * 1e9 - 2 <= b.layout.sweep_offset_ns <= -period * 1e9 + 2
    assert np.allclose(b.times, seq.times[:3], atol=1e-8)
    for k in range(3):
        assert np.allclose(b[k].time_s, seq[k].time_s, atol=1e-7, rtol=0)


def test_cloud_records_padding_and_byte_order():
    """Row padding (row_step > width * point_step) is skipped; big-endian clouds are read."""
    from types import SimpleNamespace

    rng = np.random.default_rng(0)
    height, width = 3, 4
    for big in (False, True):
        o = ">" if big else "<"
        dt = np.dtype({"names": ["x", "y", "z", "ring"], "formats": [o + "f4"] * 3 + [o + "u2"],
                       "offsets": [0, 4, 8, 12], "itemsize": 16})
        rec = np.zeros((height, width), dtype=dt)
        for a in "xyz":
            rec[a] = rng.normal(size=(height, width))
        rec["ring"] = np.arange(height)[:, None]
        rows = [rec[r].tobytes() + b"\xee" * 8 for r in range(height)]  # 8 bytes of padding per row
        fields = [SimpleNamespace(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                  for f in dtype_fields(dt.newbyteorder("<"))]
        msg = SimpleNamespace(height=height, width=width, point_step=16, row_step=16 * width + 8, is_bigendian=big,
                              fields=fields, data=np.frombuffer(b"".join(rows), dtype=np.uint8))
        out = cloud_records(msg)
        assert len(out) == height * width
        assert np.array_equal(out["x"], rec["x"].reshape(-1))
        assert np.array_equal(out["ring"], np.repeat(np.arange(height), width))


# ---------------------------------------------------------------- errors
def test_bag_errors(seq, bag, tmp_path, monkeypatch):
    with pytest.raises(BagError, match="no such bag"):
        open_sequence(tmp_path / "missing.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(BagError, match=r"junk\.mcap: cannot read the bag"):
        open_sequence(junk)
    junk = tmp_path / "junk.db3"
    junk.write_bytes(b"not a database either" * 100)
    with pytest.raises(BagError, match=r"junk\.db3: cannot read the bag"):
        open_sequence(junk)
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(BagError, match="broken: cannot read the bag"):
        open_sequence(tmp_path / "broken")
    with pytest.raises(BagError, match="no topic /lidar"):
        open_sequence(bag, topic="/lidar")
    with pytest.raises(BagError, match="is nav_msgs/msg/Odometry, not sensor_msgs/msg/PointCloud2"):
        open_sequence(bag, topic="/ground_truth/odometry")

    # no PointCloud2 at all
    with Writer(tmp_path / "odom_only", version=8) as w:
        c = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TS)
        w.write(c, 1, TS.serialize_cdr(odometry_msg(1, np.eye(4)), "nav_msgs/msg/Odometry"))
    with pytest.raises(BagError, match=r"odom_only: no sensor_msgs/msg/PointCloud2 topic \(topics: /odom"):
        open_sequence(tmp_path / "odom_only")

    # a cloud without z
    rec = np.zeros(10, dtype=[("x", "<f4"), ("y", "<f4"), ("intensity", "<f4")])
    flat = write_cloud_bag(tmp_path / "flat.mcap", [rec], [10**9])
    with pytest.raises(BagError, match=r"flat\.mcap: /points frame 0: the cloud has no 'z' field"):
        open_sequence(flat)

    # rings beyond the sensor's
    rec = np.zeros(64, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ring", "<u2")])
    rec["x"], rec["z"], rec["ring"] = 10.0, np.linspace(-1, 1, 64), np.arange(64)
    wide = write_cloud_bag(tmp_path / "wide.mcap", [rec], [10**9])
    with pytest.raises(BagError, match="ring 63 but sensor 'vlp16' has 16 rings"):
        open_sequence(wide, sensor="vlp16")[0]

    # rosbags not installed: a clear message, not an ImportError
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)
    with pytest.raises(DatasetError, match=r"pip install 'salo-bench\[ros\]'"):
        open_sequence(bag)
    with pytest.raises(BagError, match="writing ROS 2 bags needs the optional 'rosbags' package"):
        export_rosbag(seq, tmp_path / "no_rosbags")


# ---------------------------------------------------------------- PLY, PCD, TUM
def test_ply_folder_round_trip(seq, tmp_path):
    result = export_scans(seq, tmp_path / "ply", "ply", frames=slice(1, 4))
    assert [p.name for p in result.files] == ["000001.ply", "000002.ply", "000003.ply"]
    back = open_sequence(tmp_path / "ply")
    assert back.kind == "scans" and len(back) == 3 and back.sensor == seq.sensor
    assert np.allclose(back.poses, se3.inverse(seq.poses[1]) @ seq.poses[1:4], atol=1e-9)
    assert np.allclose(back.times, seq.times[1:4] - seq.times[1], atol=1e-9)
    for j, k in enumerate(range(1, 4)):
        f, g = seq[k], back[j]
        assert np.array_equal(g.points, f.points.astype(np.float32).astype(np.float64))
        assert np.array_equal(g.ring, f.ring)
        assert np.array_equal(g.time_s, f.time_s.astype(np.float32))
        assert np.array_equal(g.intensity, f.intensity)
        assert np.array_equal(g.field("nx"), f.field("normal")[:, 0])
        assert np.array_equal(g.field("object_id"), f.field("object_id"))
    with pytest.raises(ExportError, match="already exists"):
        export_scans(seq, tmp_path / "ply", "ply")
    export_scans(seq, tmp_path / "ply", "ply", frames=slice(0, 1), force=True)
    assert sorted(p.name for p in (tmp_path / "ply").glob("*.ply")) == ["000000.ply"]


@pytest.mark.parametrize("binary", [True, False])
def test_pcd_round_trip(seq, tmp_path, binary):
    export_scans(seq, tmp_path / "pcd", "pcd", frames=slice(0, 2), binary=binary)
    rec = read_pcd(tmp_path / "pcd" / "000001.pcd")
    expected = point_record(seq[1])
    assert rec.dtype.names == expected.dtype.names
    for name in expected.dtype.names:
        assert rec[name].dtype == expected[name].dtype and np.array_equal(rec[name], expected[name]), name
    text = (tmp_path / "pcd" / "000001.pcd").read_bytes().split(b"DATA")[0].decode()
    assert "VERSION 0.7" in text and "FIELDS x y z intensity ring time azimuth_index" in text
    assert "SIZE 4 4 4 4 2 4 4" in text and "TYPE F F F F U F U" in text
    assert f"POINTS {len(expected)}" in text and "HEIGHT 1" in text


def test_pcd_vector_fields_and_errors(tmp_path):
    rec = np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("normal", "<f4", (3,)), ("id", "<i2")])
    rec["normal"] = np.arange(9).reshape(3, 3)
    rec["id"] = [-1, 0, 7]
    for binary in (True, False):
        write_pcd(tmp_path / "v.pcd", rec, binary=binary)
        back = read_pcd(tmp_path / "v.pcd")
        assert np.array_equal(back["normal"], rec["normal"]) and np.array_equal(back["id"], rec["id"])
    data = (tmp_path / "v.pcd").read_bytes()
    write_pcd(tmp_path / "b.pcd", rec)
    (tmp_path / "b.pcd").write_bytes((tmp_path / "b.pcd").read_bytes()[:-5])
    with pytest.raises(DatasetError, match=r"b\.pcd: PCD data holds"):
        read_pcd(tmp_path / "b.pcd")
    (tmp_path / "c.pcd").write_bytes(data.replace(b"DATA ascii", b"DATA binary_compressed"))
    with pytest.raises(DatasetError, match="binary_compressed' is not supported"):
        read_pcd(tmp_path / "c.pcd")
    with pytest.raises(DatasetError, match="'s' has dtype"):
        write_pcd(tmp_path / "s.pcd", np.zeros(2, dtype=[("x", "<f4"), ("s", "S4")]))


def test_tum_read_by_evo(seq, tmp_path):
    from evo.tools.file_interface import read_tum_trajectory_file

    export_tum(seq, tmp_path / "gt.tum", frames=slice(1, 5))
    traj = read_tum_trajectory_file(str(tmp_path / "gt.tum"))
    assert np.allclose(traj.timestamps, seq.times[1:5], atol=1e-9)
    expected = se3.inverse(seq.poses[1]) @ seq.poses[1:5]
    assert np.allclose(np.stack(traj.poses_se3), expected, atol=1e-8)
    # the bag's ground truth gives the same trajectory
    export_tum(open_sequence(export_rosbag(seq, tmp_path / "b").path), tmp_path / "bag.tum", frames=slice(1, 5))
    traj_b = read_tum_trajectory_file(str(tmp_path / "bag.tum"))
    assert np.allclose(np.stack(traj_b.poses_se3), expected, atol=1e-8)
    with pytest.raises(ExportError, match="already exists"):
        export_tum(seq, tmp_path / "gt.tum")


def test_tum_needs_poses(seq, tmp_path):
    export_scans(seq, tmp_path / "np", "ply", frames=slice(0, 2))
    (tmp_path / "np" / "poses.txt").unlink()
    with pytest.raises(ExportError, match="no ground-truth poses"):
        export_tum(open_sequence(tmp_path / "np"), tmp_path / "x.tum")
    # a bag without ground truth: only the cloud topic
    res = export_rosbag(open_sequence(tmp_path / "np"), tmp_path / "np_bag")
    assert res.messages == {"/points": 2}
    assert open_sequence(res.path).poses is None


def test_laser_id_order_mapped_through_the_sensor(seq, tmp_path, caplog):
    """A ring field in firing (laser id) order, as the raw VLP-16 interleaves it: mapped with the sensor table."""
    sensor = seq.sensor
    dtype = padded([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("laser_id", 12, 4)], 14)
    f = seq[0]
    rec = xyz_record(f, dtype)
    rec["laser_id"] = sensor.laser_of_ring[f.ring]
    path = write_cloud_bag(tmp_path / "laser.mcap", [rec], [stamp_ns(seq, 0)])
    b = open_sequence(path, sensor=sensor)
    assert b.layout.ring_order == "laser_id" and np.array_equal(b[0].ring, f.ring)
    with caplog.at_level("WARNING", logger="simlidar.formats.rosbag"):
        b = open_sequence(path)  # no sensor: no table to map laser ids, so no ring
    assert b[0].ring is None and "not ordered by elevation" in caplog.text


def test_ground_truth_interpolated_between_odometry_messages(seq, tmp_path):
    """Ground truth at another rate than the clouds: poses taken on SE(3) between the neighbouring messages."""
    traj = constant_velocity(v=(1.0, 0.2, 0.0), yaw_rate=0.1, start=(-2.0, 0.5, 0.0))
    gt_times = np.arange(-0.013, 0.3, 0.02)  # 50 Hz, not aligned with the sweeps
    odometry = [(int(round((DEFAULT_EPOCH_S + t) * 1e9)), P) for t, P in zip(gt_times, traj.pose_at(gt_times),
                                                                             strict=True)]
    records = [point_record(seq[k], truth=False) for k in range(3)]
    path = write_cloud_bag(tmp_path / "gt_rate", records, [stamp_ns(seq, k) for k in range(3)], odometry=odometry)
    b = open_sequence(path)
    assert b.ground_truth_topic == "/ground_truth/odometry"
    # constant world velocity while yawing is not a constant screw: the interpolation is good to ~0.02 mm here
    assert np.allclose(b.poses, seq.poses[:3], atol=1e-4)  # the nearest message would be 1 cm off
