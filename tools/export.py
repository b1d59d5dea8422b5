"""Export a sequence for other tools: a ROS 2 bag, PLY or PCD scans, a TUM trajectory.

Every writer takes any sequence ``simlidar.dataset.open_sequence`` opens (a
simulated folder, real KITTI, a scan folder, a ROS 2 bag) and an optional frame
slice, and writes atomically: a hidden sibling is filled and renamed into place,
so a failed export leaves nothing that looks complete. An existing output is
only replaced with ``force=True``.

**ROS 2 bag** (``export_rosbag``; needs the optional ``rosbags`` package). A
rosbag2 folder (metadata version 8, MCAP storage by default, or SQLite3) with
the sequence's ``sensor.yaml`` inside:

- ``/points`` ``sensor_msgs/PointCloud2``, frame ``lidar``, one per sweep,
  unorganized (height 1), little-endian, packed like the ROS 2
  velodyne_pointcloud driver's XYZIRT cloud::

      x f32 @0, y f32 @4, z f32 @8, intensity f32 @12, ring u16 @16, time f32 @18  (22 bytes)

  ``ring``: 0 = lowest beam; ``time``: s since the header stamp, the sweep
  start (as the Velodyne driver). Points are as measured: in the sensor frame
  at each point's firing time (motion-distorted). Simulated sequences add their
  per-point ground truth after these (``truth=False`` leaves it out)::

      azimuth_index u32 @22, true_range_m f32 @26, true_x/true_y/true_z f32 @30..38,
      normal_x/normal_y/normal_z f32 @42..50, object_id i32 @54  (58 bytes)

  (``true_*`` is the noise-free point in the sweep-start frame, ``normal_*`` the
  true surface normal, ``object_id`` the world object hit: the sidecar's fields.)
- ``/ground_truth/odometry`` ``nav_msgs/Odometry``, frame ``map`` -> child
  ``lidar``: the true pose at each sweep start in the world frame of the
  simulation (``manifest.json``'s ``T_world_first_lidar`` times ``poses.txt``;
  the first frame's pose for other sequences), zero covariances, and the twist
  of the motion to the next sweep (body frame, m/s and rad/s).
- ``/tf`` ``tf2_msgs/TFMessage``: the same pose as ``map`` -> ``lidar``.

Stamps (header and log time alike) are ``epoch_s`` + the sequence's
``times.txt`` (default epoch 2020-01-01T00:00:00Z, because ROS tools read a zero
stamp as "no time"); the same input gives the same bytes.

**PLY / PCD scans** (``export_scans``): one file per frame, named by its frame
index, with the same fields (PLY names the normal ``nx ny nz``, as mesh tools
expect), plus ``sensor.yaml``, ``poses.txt`` and ``times.txt`` (both relative
to the first exported frame), so ``open_sequence`` reads a PLY folder back.
PCD is v0.7, binary (the little-endian record) or ASCII.

**TUM** (``export_tum``): ``timestamp tx ty tz qx qy qz qw`` per frame, poses
relative to the first exported frame, timestamps the sequence's own (as
``salo odometry --tum`` writes them for the same ``--frames``, so evo associates
the two).
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simlidar import se3
from simlidar.bag import dtype_fields
from simlidar.dataset import (
    DatasetError,
    Frame,
    atomic_write_bytes,
    atomic_write_text,
    format_kitti_poses,
    write_ply_scan,
)

log = logging.getLogger(__name__)

DEFAULT_EPOCH_S = 1_577_836_800  # 2020-01-01T00:00:00Z
POINTS_TOPIC = "/points"
ODOMETRY_TOPIC = "/ground_truth/odometry"
TF_TOPIC = "/tf"
LIDAR_FRAME = "lidar"
MAP_FRAME = "map"
FORMATS = ("rosbag", "ply", "pcd", "tum")
STORAGES = ("mcap", "sqlite3")

# the velodyne_pointcloud (ROS 2) XYZIRT layout, packed, then the simulator's ground truth
VELODYNE_FIELDS = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("time", "<f4")]
TRUTH_FIELDS = [("azimuth_index", "<u4"), ("true_range_m", "<f4"), ("true_x", "<f4"), ("true_y", "<f4"),
                ("true_z", "<f4"), ("normal_x", "<f4"), ("normal_y", "<f4"), ("normal_z", "<f4"),
                ("object_id", "<i4")]
PLY_NAMES = {"normal_x": "nx", "normal_y": "ny", "normal_z": "nz"}


class ExportError(DatasetError):
    """An export cannot be written; the message names the output and the problem."""


@dataclass
class ExportResult:
    """What an export wrote: its path, format, the frame indices and per-topic message counts (bags)."""

    path: Path
    format: str
    frames: np.ndarray
    messages: dict[str, int] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)


# ---------------------------------------------------------------- per-point records
def point_record(frame: Frame, truth: bool = True) -> np.ndarray:
    """One frame -> (N,) packed little-endian structured array in the export layout (module doc).

    x, y, z always; intensity, ring, time when the frame has them; the
    ground-truth fields when ``truth`` and the frame has all of them.
    """
    n = len(frame.points)
    columns: dict[str, np.ndarray] = {"x": frame.points[:, 0], "y": frame.points[:, 1], "z": frame.points[:, 2]}
    if frame.intensity is not None:
        columns["intensity"] = frame.intensity
    if frame.ring is not None:
        columns["ring"] = frame.ring
    if frame.time_s is not None:
        columns["time"] = frame.time_s
    names = frame.fields.dtype.names if frame.fields is not None and frame.fields.dtype.names else ()
    if truth and all(k in names for k in ("azimuth_index", "true_range_m", "true_xyz", "normal", "object_id")):
        columns["azimuth_index"] = frame.fields["azimuth_index"]
        columns["true_range_m"] = frame.fields["true_range_m"]
        for i, axis in enumerate("xyz"):
            columns[f"true_{axis}"] = frame.fields["true_xyz"][:, i]
            columns[f"normal_{axis}"] = frame.fields["normal"][:, i]
        columns["object_id"] = frame.fields["object_id"]
    dtype = [(name, t) for name, t in VELODYNE_FIELDS + TRUTH_FIELDS if name in columns]
    rec = np.empty(n, dtype=dtype)
    for name in rec.dtype.names:
        rec[name] = columns[name]
    return rec


# ---------------------------------------------------------------- PCD v0.7
_PCD_TYPES = {"f": "F", "u": "U", "i": "I"}


def write_pcd(path: str | Path, record: np.ndarray, binary: bool = True) -> None:
    """Write a PCD v0.7 file: one point per record of ``record`` ((N,) structured, scalar or vector fields).

    Binary data is the packed little-endian record; ASCII writes floats with
    enough digits to read back the same value (9 for float32, 17 for float64).
    """
    path = Path(path)
    rec = np.ascontiguousarray(record)
    names, sizes, types, counts, formats = [], [], [], [], []
    for name in rec.dtype.names:
        sub = rec.dtype.fields[name][0]
        base = sub.base
        if base.kind not in _PCD_TYPES or base.itemsize not in (1, 2, 4, 8):
            raise ExportError(f"{path}: field '{name}' has dtype {base}, which PCD cannot hold")
        count = int(np.prod(sub.shape)) if sub.shape else 1
        names.append(name)
        sizes.append(str(base.itemsize))
        types.append(_PCD_TYPES[base.kind])
        counts.append(str(count))
        fmt = "%.9g" if base == np.float32 else "%.17g" if base.kind == "f" else "%d"
        formats += [fmt] * count
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(names)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join(types)}\nCOUNT {' '.join(counts)}\n"
        f"WIDTH {len(rec)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(rec)}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    little = np.dtype([(n, rec.dtype.fields[n][0].newbyteorder("<")) for n in names])
    packed = rec.astype(little)  # drops any padding, fixes the byte order
    if binary:
        payload = packed.tobytes()
    else:
        columns = [packed[n].reshape(len(packed), -1).astype(np.float64 if packed[n].dtype.kind == "f" else np.int64)
                   for n in names]
        table = np.hstack(columns) if columns else np.zeros((len(packed), 0))
        lines = []
        for row in table:
            lines.append(" ".join(f % (v if f != "%d" else int(v)) for f, v in zip(formats, row, strict=True)))
        payload = ("\n".join(lines) + ("\n" if lines else "")).encode("ascii")
    _atomic_write_bytes(path, header.encode("ascii") + payload)


def read_pcd(path: str | Path) -> np.ndarray:
    """Read a PCD v0.7 file (ascii or binary; not binary_compressed) -> (N,) structured array of its fields."""
    path = Path(path)
    try:
        blob = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read PCD ({exc.strerror})") from None
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = blob.find(b"\n", pos)
        if end < 0:
            raise DatasetError(f"{path}: PCD header has no DATA line")
        line = blob[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    try:
        names = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(names))]
        n = int(header.get("POINTS", [0])[0]) or int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
    except (KeyError, ValueError, IndexError):
        raise DatasetError(f"{path}: PCD header lacks or garbles FIELDS / SIZE / TYPE / COUNT / POINTS") from None
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise DatasetError(f"{path}: PCD header FIELDS, SIZE, TYPE and COUNT differ in length")
    kinds = {"F": "f", "U": "u", "I": "i"}
    dtype = []
    for name, size, t, count in zip(names, sizes, types, counts, strict=True):
        if t.upper() not in kinds:
            raise DatasetError(f"{path}: PCD field '{name}' has unknown TYPE {t}")
        base = np.dtype(f"<{kinds[t.upper()]}{size}")
        dtype.append((name, base, (count,)) if count > 1 else (name, base))
    dtype = np.dtype(dtype)
    kind = header["DATA"][0].lower() if header["DATA"] else ""
    if kind == "binary":
        if len(blob) - pos < n * dtype.itemsize:
            raise DatasetError(f"{path}: PCD data holds {len(blob) - pos} bytes, {n} points need {n * dtype.itemsize}")
        return np.frombuffer(blob, dtype=dtype, count=n, offset=pos).copy()
    if kind == "ascii":
        text = blob[pos:].decode("ascii", errors="replace").split()
        width = sum(counts)
        if len(text) < n * width:
            raise DatasetError(f"{path}: PCD ascii data holds {len(text)} values, {n} points need {n * width}")
        table = np.array(text[: n * width], dtype=np.float64).reshape(n, width)
        rec = np.empty(n, dtype=dtype)
        col = 0
        for name, count in zip(names, counts, strict=True):
            block = table[:, col:col + count]
            rec[name] = block[:, 0] if count == 1 else block
            col += count
        return rec
    raise DatasetError(f"{path}: PCD DATA '{kind}' is not supported (ascii or binary)")


# ---------------------------------------------------------------- helpers
def frame_indices(seq, frames: slice | None) -> np.ndarray:
    """Indices of the frames a slice selects; an error when it selects none."""
    idx = np.arange(len(seq))[frames or slice(None)]
    if len(idx) == 0:
        raise ExportError(f"{seq.path}: no frames selected ({frames})")
    return idx


def sequence_times(seq) -> np.ndarray:
    """(N,) sweep start times, s: the sequence's own, else one sweep period apart (0.1 s without a sensor)."""
    if seq.times is not None and len(seq.times) >= len(seq):
        return np.asarray(seq.times, dtype=float)[: len(seq)]
    period = seq.sensor.sweep_period_s if seq.sensor is not None else 0.1
    return np.arange(len(seq)) * period


def world_poses(seq) -> np.ndarray | None:
    """(N, 4, 4) ``T_world_lidar``: the manifest's first pose (if any) times the sequence's relative poses."""
    if seq.poses is None:
        return None
    first = np.eye(4)
    row = (seq.manifest or {}).get("T_world_first_lidar")
    if row is not None and len(row) == 12:
        first = se3.kitti_lines_to_poses(np.asarray(row, dtype=float))[0]
    return first @ np.asarray(seq.poses)


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    try:
        atomic_write_bytes(path, data)
    except OSError as exc:
        raise ExportError(f"{path}: cannot write ({exc.strerror})") from None


def _check_out(out: Path, force: bool) -> None:
    if out.exists() and not force:
        raise ExportError(f"{out}: already exists (use --force to replace it)")


def _stage(out: Path) -> Path:
    """A fresh hidden sibling folder of ``out`` to build the export in."""
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        tmp.mkdir(parents=True)
    except OSError as exc:
        raise ExportError(f"{out}: cannot create a folder beside it ({exc.strerror})") from None
    return tmp


def _commit(built: Path, out: Path) -> None:
    """Move the finished ``built`` into place at ``out``, replacing what was there only now."""
    if out.exists():
        trash = out.parent / f".{out.name}.old-{os.getpid()}"
        out.rename(trash)
        built.rename(out)
        if trash.is_dir():
            shutil.rmtree(trash, ignore_errors=True)
        else:
            trash.unlink()
    else:
        built.rename(out)


def _quaternion_xyzw(T: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # not at import: `salo --help` loads this module

    return Rotation.from_matrix(T[:3, :3]).as_quat()


# ---------------------------------------------------------------- ROS 2 bag
def export_rosbag(
    seq,
    out: str | Path,
    frames: slice | None = None,
    *,
    storage: str = "mcap",
    epoch_s: float = DEFAULT_EPOCH_S,
    truth: bool = True,
    force: bool = False,
    on_frame: Callable[[int], None] | None = None,
) -> ExportResult:
    """Write a sequence (or a slice) as a ROS 2 bag folder; the layout is in the module doc.

    storage: "mcap" or "sqlite3". epoch_s: the ROS time of the sequence's t = 0, s.
    truth: add the simulator's per-point ground truth fields. on_frame(k) after each frame.
    """
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ExportError("writing ROS 2 bags needs the optional 'rosbags' package: "
                          "pip install 'salo-bench[ros]'") from None
    if storage not in STORAGES:
        raise ExportError(f"{out}: storage must be one of {', '.join(STORAGES)}, not {storage!r}")
    out = Path(out)
    _check_out(out, force)
    idx = frame_indices(seq, frames)
    times = sequence_times(seq)
    stamps_ns = [int(round((epoch_s + times[k]) * 1e9)) for k in idx]
    if any(b <= a for a, b in zip(stamps_ns, stamps_ns[1:], strict=False)):
        raise ExportError(f"{seq.path}: sweep times are not increasing; a bag needs increasing stamps")
    poses = world_poses(seq)

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    cloud_t, odom_t, tf_t = "sensor_msgs/msg/PointCloud2", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"

    def header(stamp_ns: int, frame_id: str):
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                        frame_id=frame_id)

    def vec(cls: str, v) -> object:
        return T[cls](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(q) -> object:
        return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    staging = _stage(out)
    bag_dir = staging / out.name
    counts = {POINTS_TOPIC: 0}
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    try:
        writer = Writer(bag_dir, version=8, storage_plugin=plugin)  # 8: read by more ROS 2 releases than 9
        writer.set_custom_data("salo.source", str(seq.path))
        writer.set_custom_data("salo.epoch_s", repr(float(epoch_s)))
        with writer:
            c_points = writer.add_connection(POINTS_TOPIC, cloud_t, typestore=ts)
            if poses is not None:
                c_odom = writer.add_connection(ODOMETRY_TOPIC, odom_t, typestore=ts)
                c_tf = writer.add_connection(TF_TOPIC, tf_t, typestore=ts)
                counts[ODOMETRY_TOPIC] = counts[TF_TOPIC] = 0
            for j, k in enumerate(idx):
                stamp = stamps_ns[j]
                rec = point_record(seq[int(k)], truth)
                pfields = [T["sensor_msgs/msg/PointField"](name=f.name, offset=f.offset, datatype=f.datatype,
                                                           count=f.count) for f in dtype_fields(rec.dtype)]
                xyz_ok = np.isfinite(rec["x"]) & np.isfinite(rec["y"]) & np.isfinite(rec["z"])
                cloud = T[cloud_t](
                    header=header(stamp, LIDAR_FRAME), height=1, width=len(rec), fields=pfields,
                    is_bigendian=False, point_step=rec.dtype.itemsize, row_step=rec.dtype.itemsize * len(rec),
                    data=np.frombuffer(rec.tobytes(), dtype=np.uint8), is_dense=bool(np.all(xyz_ok)),
                )
                writer.write(c_points, stamp, ts.serialize_cdr(cloud, cloud_t))
                counts[POINTS_TOPIC] += 1
                if poses is not None:
                    P = poses[int(k)]
                    twist = _body_twist(poses, times, idx, j)
                    pose = T["geometry_msgs/msg/Pose"](position=vec("geometry_msgs/msg/Point", P[:3, 3]),
                                                       orientation=quat(_quaternion_xyzw(P)))
                    odom = T[odom_t](
                        header=header(stamp, MAP_FRAME), child_frame_id=LIDAR_FRAME,
                        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](
                            twist=T["geometry_msgs/msg/Twist"](linear=vec("geometry_msgs/msg/Vector3", twist[:3]),
                                                               angular=vec("geometry_msgs/msg/Vector3", twist[3:])),
                            covariance=np.zeros(36)),
                    )
                    writer.write(c_odom, stamp, ts.serialize_cdr(odom, odom_t))
                    tf = T[tf_t](transforms=[T["geometry_msgs/msg/TransformStamped"](
                        header=header(stamp, MAP_FRAME), child_frame_id=LIDAR_FRAME,
                        transform=T["geometry_msgs/msg/Transform"](
                            translation=vec("geometry_msgs/msg/Vector3", P[:3, 3]),
                            rotation=quat(_quaternion_xyzw(P))))])
                    writer.write(c_tf, stamp, ts.serialize_cdr(tf, tf_t))
                    counts[ODOMETRY_TOPIC] += 1
                    counts[TF_TOPIC] += 1
                if on_frame is not None:
                    on_frame(int(k))
        if seq.sensor is not None:
            (bag_dir / "sensor.yaml").write_text(seq.sensor.to_yaml())
        _commit(bag_dir, out)
    except OSError as exc:
        raise ExportError(f"{out}: cannot write the bag ({exc})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ExportResult(out, "rosbag", idx, counts)


def _body_twist(poses: np.ndarray, times: np.ndarray, idx: np.ndarray, j: int) -> np.ndarray:
    """(6,) linear (m/s) and angular (rad/s) velocity in the lidar frame over the step to the next exported frame.

    The last frame keeps the previous step's; a single frame has none (zeros).
    """
    if len(idx) < 2:
        return np.zeros(6)
    a, b = (j, j + 1) if j + 1 < len(idx) else (j - 1, j)
    ka, kb = int(idx[a]), int(idx[b])
    dt = times[kb] - times[ka]
    return se3.log(se3.inverse(poses[ka]) @ poses[kb]) / dt


# ---------------------------------------------------------------- PLY / PCD scans, TUM
def export_scans(
    seq,
    out: str | Path,
    fmt: str,
    frames: slice | None = None,
    *,
    binary: bool = True,
    truth: bool = True,
    force: bool = False,
    on_frame: Callable[[int], None] | None = None,
) -> ExportResult:
    """Write one PLY or PCD file per frame into folder ``out`` (``NNNNNN.ply``/``.pcd``, the frame index).

    Beside them: ``sensor.yaml`` (when known), ``poses.txt`` and ``times.txt``
    relative to the first exported frame (when known). binary: PCD binary
    (else ASCII; PLY is always binary little-endian).
    """
    if fmt not in ("ply", "pcd"):
        raise ExportError(f"{out}: scan format must be ply or pcd, not {fmt!r}")
    out = Path(out)
    _check_out(out, force)
    idx = frame_indices(seq, frames)
    staging = _stage(out)
    built = staging / out.name
    files = []
    try:
        built.mkdir()
        for k in idx:
            rec = point_record(seq[int(k)], truth)
            path = built / f"{int(k):06d}.{fmt}"
            if fmt == "pcd":
                write_pcd(path, rec, binary=binary)
            else:
                xyz = np.column_stack([rec["x"], rec["y"], rec["z"]])
                write_ply_scan(path, xyz, {PLY_NAMES.get(n, n): rec[n] for n in rec.dtype.names[3:]})
            files.append(out / path.name)
            if on_frame is not None:
                on_frame(int(k))
        if seq.sensor is not None:
            atomic_write_text(built / "sensor.yaml", seq.sensor.to_yaml())
        if seq.poses is not None:
            P = np.asarray(seq.poses)[idx]
            atomic_write_text(built / "poses.txt", format_kitti_poses(se3.inverse(P[0]) @ P))
        if seq.times is not None:
            t = sequence_times(seq)[idx]
            atomic_write_text(built / "times.txt", "".join(f"{v - t[0]:.9e}\n" for v in t))
        _commit(built, out)
    except OSError as exc:
        raise ExportError(f"{out}: cannot write the scans ({exc})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ExportResult(out, fmt, idx, files=files)


def export_tum(seq, out: str | Path, frames: slice | None = None, *, force: bool = False) -> ExportResult:
    """Write the ground-truth trajectory in TUM format (see the module doc) with ``odometry.pipeline.format_tum``."""
    from odometry.pipeline import format_tum

    out = Path(out)
    _check_out(out, force)
    if seq.poses is None:
        raise ExportError(f"{seq.path}: no ground-truth poses to write as a trajectory")
    idx = frame_indices(seq, frames)
    P = np.asarray(seq.poses)[idx]
    try:
        atomic_write_text(out, format_tum(se3.inverse(P[0]) @ P, sequence_times(seq)[idx]))
    except OSError as exc:
        raise ExportError(f"{out}: cannot write ({exc.strerror})") from None
    return ExportResult(out, "tum", idx, files=[out])


def export(seq, fmt: str, out: str | Path, frames: slice | None = None, **options) -> ExportResult:
    """Dispatch to ``export_rosbag`` / ``export_scans`` / ``export_tum`` by format name (``FORMATS``)."""
    if fmt == "rosbag":
        return export_rosbag(seq, out, frames, **options)
    if fmt in ("ply", "pcd"):
        return export_scans(seq, out, fmt, frames, **options)
    if fmt == "tum":
        return export_tum(seq, out, frames, **options)
    raise ExportError(f"{out}: unknown export format {fmt!r} (one of {', '.join(FORMATS)})")


__all__ = [
    "DEFAULT_EPOCH_S",
    "ExportError",
    "ExportResult",
    "export",
    "export_rosbag",
    "export_scans",
    "export_tum",
    "point_record",
    "read_pcd",
    "write_pcd",
]
