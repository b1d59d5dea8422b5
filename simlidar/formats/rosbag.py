"""ROS 2 bags: read as a sequence (``sensor_msgs/PointCloud2`` scans, ``nav_msgs/Odometry`` ground truth) and written.

A bag is a rosbag2 folder (``metadata.yaml`` beside ``.mcap`` or ``.db3``
storage files) or a single ``.mcap`` / ``.db3`` file; the pure-Python
``rosbags`` package reads it (an optional dependency: ``pip install
salo-bench[ros]``). ``RosbagSequence`` behaves like ``simlidar.formats.scan_folders.Sequence``
(``len``, indexing, iteration, ``times``, ``poses``, ``sensor``), so the
odometry runs on a recorded bag unchanged.

Per-point fields, as the common ROS drivers name them (any order, any offsets,
either byte order; the first name found wins):

=============  ===========================================  ==========================================
what           accepted names (datatypes)                   drivers
=============  ===========================================  ==========================================
position       x, y, z (float32 / float64)                  all
intensity      intensity (any numeric, read as float32)     all
ring           ring, channel, laser_id (any integer)        velodyne_pointcloud ``ring`` uint16;
                                                            ouster-ros ``ring`` uint16 (uint8 before
                                                            ouster-ros PR 40); Autoware/Nebula
                                                            ``channel`` uint16
time           time, t, timestamp, time_stamp               velodyne_pointcloud ``time`` float32 s
                                                            relative to the header stamp; ouster-ros
                                                            ``t`` uint32 ns relative; Nebula
                                                            ``time_stamp`` uint32 ns relative; Hesai /
                                                            RoboSense ``timestamp`` float64 absolute s
=============  ===========================================  ==========================================

How the fields are mapped (decided once per bag, from its first cloud, so every
frame is read the same way; each can be forced in ``RosbagSequence``):

- **time unit**: the one (s, ms, us, ns) in which the first cloud's time span is
  a plausible sweep duration, 1 ms to 1 s (the candidate units are 1000x apart,
  so at most one fits); failing that, seconds for float fields and nanoseconds
  for integer fields.
- **absolute or relative**: absolute when the first cloud's earliest time is
  nearer its header stamp than zero; absolute times are made relative to the
  stamp (in integer arithmetic for integer fields, so nanosecond stamps keep
  their precision).
- **sweep start**: the header stamp, which velodyne_pointcloud (ROS 2) and
  ouster-ros put at the sweep's start. A driver that stamps the sweep's end
  gives negative relative times; then every frame's sweep start moves by the
  first cloud's earliest point time, and ``time_s`` counts from there.
- **ring order**: this project numbers rings by elevation, 0 the lowest beam
  (as velodyne_pointcloud does). Ouster numbers ring 0 as the top beam. The
  order is detected from the rank correlation between ring index and the median
  elevation of each ring's points: ascending is kept, descending is flipped
  (``rings - 1 - ring``, with the sensor's ring count, else the first cloud's
  largest ring + 1), and an unordered field (a laser id in firing order) is
  mapped through the sensor's vertical-angle table, or dropped (with a warning)
  when no sensor is known, so that the odometry assigns rings from elevation.

``Frame.fields`` holds ``ring`` (uint16, 0 = lowest beam) and ``time_s``
(float64, s since the sweep start) when the cloud has them, and every other
per-point field under its own name (e.g. Ouster's ``reflectivity``). The
ground-truth fields of ``simlidar.formats.points`` (what ``BagWriter`` writes) are regrouped as in a simulated
sequence's sidecar: ``true_x/true_y/true_z`` -> ``true_xyz`` and
``normal_x/normal_y/normal_z`` -> ``normal``.

Ground truth: the ``nav_msgs/Odometry`` topic (the only one, or one named with
``ground_truth``), its poses taken at the frames' sweep starts (exact stamps, or
interpolated on SE(3) between neighbouring messages) and made relative to the
first frame. The sensor model comes from ``sensor.yaml`` inside a bag folder or
beside a bag file, unless one is passed.

IMU: a ``sensor_msgs/Imu`` topic (the only one, or ``/imu``) is read whole when the
bag is opened, as ``imu`` (``simlidar.imu.ImuSamples``: header stamps relative to the
first sweep's start, so in the time base of ``times``; angular velocity and linear
acceleration, the message's frame; its orientation is ignored). ``BagWriter`` writes one
(``/imu``, frame ``imu``) when asked.

Reading streams: opening the bag reads the cloud topic once (only each
message's header stamp is decoded) and the odometry topic; frames are decoded
one at a time when asked for, consecutive frames from one open cursor.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import se3
from ..imu import ImuSamples
from ..sensor import LidarModel, load_sensor_file
from ..sequence import DatasetError, Frame
from .kitti import read_kitti_poses
from .points import VECTOR_FIELDS

log = logging.getLogger(__name__)

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
ODOMETRY = "nav_msgs/msg/Odometry"
TFMESSAGE = "tf2_msgs/msg/TFMessage"
IMU = "sensor_msgs/msg/Imu"
BAG_SUFFIXES = (".mcap", ".db3")
STORAGES = ("mcap", "sqlite3")

# sensor_msgs/PointField datatype codes -> numpy type codes (byte order added when read)
POINTFIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
POINTFIELD_CODES = {v: k for k, v in POINTFIELD_TYPES.items()}

TIME_FIELDS = ("time", "t", "timestamp", "time_stamp")
RING_FIELDS = ("ring", "channel", "laser_id")
INTENSITY_FIELDS = ("intensity",)

TIME_UNITS_NS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
MIN_SWEEP_S = 1e-3  # plausible time span of one sweep's points
MAX_SWEEP_S = 1.0
RING_ORDERS = ("auto", "ascending", "descending", "laser_id")


class BagError(DatasetError):
    """A ROS 2 bag cannot be read as a lidar sequence, or written; the message names the bag and the problem."""


def require_rosbags(doing: str = "reading"):
    """rosbags' ``rosbag2`` module and its ROS 2 Humble type store; BagError with the install hint without it.

    doing: starts the message ("reading", or "<bag>: reading", "writing").
    """
    try:
        import rosbags.rosbag2 as rosbag2
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError(f"{doing} ROS 2 bags needs the optional 'rosbags' package: pip install 'salo-bench[ros]'"
                       ) from None
    return rosbag2, get_typestore(Stores.ROS2_HUMBLE)


def is_bag(path: str | Path) -> bool:
    """A rosbag2 folder (holding ``metadata.yaml``) or an ``.mcap`` / ``.db3`` file."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in BAG_SUFFIXES


# ---------------------------------------------------------------- PointCloud2 layout
@dataclass(frozen=True)
class PointFieldSpec:
    """One ``sensor_msgs/PointField``: name, byte offset in a point, datatype code, element count."""

    name: str
    offset: int
    datatype: int
    count: int = 1


def cloud_dtype(fields: list[PointFieldSpec], point_step: int, big_endian: bool = False,
                where: str = "cloud") -> np.dtype:
    """The numpy structured dtype of one point of a PointCloud2 (itemsize ``point_step``, padding kept out).

    A field with ``count`` > 1 becomes a subarray field of that length.
    """
    order = ">" if big_endian else "<"
    names, formats, offsets = [], [], []
    for f in fields:
        code = POINTFIELD_TYPES.get(int(f.datatype))
        if code is None:
            raise BagError(f"{where}: field '{f.name}' has unknown PointField datatype {f.datatype}")
        if f.name in names:
            raise BagError(f"{where}: field '{f.name}' appears twice")
        base = np.dtype(order + code)
        fmt = base if f.count <= 1 else np.dtype((base, (int(f.count),)))
        if f.offset < 0 or f.offset + fmt.itemsize > point_step:
            raise BagError(
                f"{where}: field '{f.name}' ({fmt.itemsize} bytes at offset {f.offset}) does not fit in "
                f"point_step {point_step}"
            )
        names.append(f.name)
        formats.append(fmt)
        offsets.append(int(f.offset))
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": int(point_step)})


def dtype_fields(dtype: np.dtype) -> list[PointFieldSpec]:
    """PointFields describing a structured dtype (the inverse of ``cloud_dtype``), for writers."""
    out = []
    for name in dtype.names:
        sub, offset = dtype.fields[name][:2]
        count = int(np.prod(sub.shape)) if sub.shape else 1
        code = sub.base.str.lstrip("<>|=")
        if code not in POINTFIELD_CODES:
            raise ValueError(f"field '{name}': dtype {sub.base} has no PointField datatype")
        out.append(PointFieldSpec(name, int(offset), POINTFIELD_CODES[code], count))
    return out


def cloud_records(msg, where: str = "cloud") -> np.ndarray:
    """A deserialized PointCloud2 -> (height * width,) structured array, one record per point.

    Row padding (``row_step`` > ``width * point_step``) is skipped; the record
    keeps the message's byte order.
    """
    fields = [PointFieldSpec(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    dtype = cloud_dtype(fields, msg.point_step, bool(msg.is_bigendian), where)
    height, width, step, row_step = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    n = height * width
    if n == 0:
        return np.zeros(0, dtype=dtype)
    row_step = max(row_step, width * step)  # some writers leave row_step 0 for unorganized clouds
    if len(data) < (height - 1) * row_step + width * step:
        raise BagError(
            f"{where}: data holds {len(data)} bytes, fewer than {height} x {width} points of {step} bytes need"
        )
    if row_step == width * step:
        return np.ascontiguousarray(data[: n * step]).view(dtype)
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, width * step), strides=(row_step, 1))
    return np.ascontiguousarray(rows).reshape(-1).view(dtype)


def header_stamp_ns(raw: bytes | memoryview) -> int:
    """The ``header.stamp`` of a CDR-serialized stamped message (the header comes first), ns.

    Reads 8 bytes instead of deserializing the message: opening a bag needs every
    cloud's stamp but none of its points.
    """
    little = bool(raw[1])
    sec, nanosec = struct.unpack_from("<iI" if little else ">iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


# ---------------------------------------------------------------- field conventions
@dataclass(frozen=True)
class CloudLayout:
    """How a bag's clouds map onto this project's per-point fields (one decision per bag).

    time_field / ring_field / intensity_field: the source field names, or None.
    time_unit_ns: nanoseconds per unit of the time field. time_absolute: the
    field holds absolute stamps (else times relative to the header stamp).
    sweep_offset_ns: sweep start minus header stamp (negative when the driver
    stamps the sweep's end). ring_order: "ascending" (0 = lowest beam),
    "descending" (0 = highest) or "laser_id" (firing order, mapped through the
    sensor table). ring_count: rings of the sensor (for flipping), or None.
    """

    time_field: str | None
    time_unit_ns: int
    time_absolute: bool
    sweep_offset_ns: int
    ring_field: str | None
    ring_order: str
    ring_count: int | None
    intensity_field: str | None


def _first_present(names: tuple[str, ...], available: tuple[str, ...]) -> str | None:
    return next((n for n in names if n in available), None)


def detect_time_unit_ns(values: np.ndarray) -> int:
    """Nanoseconds per unit of per-point times (N,) of one sweep, from their span (see the module doc)."""
    finite = values[np.isfinite(values)] if values.dtype.kind == "f" else values
    if len(finite) > 1:
        span = float(np.max(finite)) - float(np.min(finite))
        for ns in TIME_UNITS_NS.values():
            if MIN_SWEEP_S <= span * ns * 1e-9 < MAX_SWEEP_S:
                return ns
    return TIME_UNITS_NS["s"] if values.dtype.kind == "f" else TIME_UNITS_NS["ns"]


def times_since_stamp(values: np.ndarray, unit_ns: int, absolute: bool, stamp_ns: int) -> np.ndarray:
    """Per-point times (N,) in the field's unit -> (N,) float64 s since the header stamp."""
    if values.dtype.kind in "iu":
        v = values.astype(np.int64)
        if not absolute:
            return v * (unit_ns * 1e-9)
        whole, rest = divmod(stamp_ns, unit_ns)  # integer difference first: no float rounding of the epoch
        return (v - whole) * (unit_ns * 1e-9) - rest * 1e-9
    v = values.astype(np.float64)
    if not absolute:
        return v * (unit_ns * 1e-9)
    return (v - stamp_ns / unit_ns) * (unit_ns * 1e-9)


def detect_ring_order(rings: np.ndarray, points: np.ndarray, min_points: int = 5) -> str:
    """"ascending", "descending" or "laser_id" from ring indices (N,) and points (N, 3).

    Spearman rank correlation between each ring's index and the median
    elevation of its points; fewer than two rings with ``min_points`` points
    cannot tell and count as ascending.
    """
    ok = np.all(np.isfinite(points), axis=1) & (np.linalg.norm(points, axis=1) > 0)
    rings, points = rings[ok], points[ok]
    elevation = np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1]))
    ids, counts = np.unique(rings, return_counts=True)
    ids = ids[counts >= min_points]
    if len(ids) < 2:
        return "ascending"
    medians = np.array([np.median(elevation[rings == r]) for r in ids])
    rank_e = np.argsort(np.argsort(medians))
    rho = np.corrcoef(np.arange(len(ids)), rank_e)[0, 1]
    if rho > 0.9:
        return "ascending"
    if rho < -0.9:
        return "descending"
    return "laser_id"


# ---------------------------------------------------------------- the sequence
class RosbagSequence:
    """A ROS 2 bag's PointCloud2 topic as a sequence of ``simlidar.sequence.Frame``.

    Args:
        path: rosbag2 folder, or ``.mcap`` / ``.db3`` file.
        sensor: the lidar model (default: ``sensor.yaml`` in the bag folder or beside the file).
        topic: the PointCloud2 topic (default: the only one, else ``/points``).
        ground_truth_topic: the nav_msgs/Odometry topic (default: the only one, else one whose
            name holds ``ground_truth``); "" for none.
        poses_file: a KITTI pose file (one line per cloud) used as ground truth instead.
        imu_topic: the sensor_msgs/Imu topic (default: the only one, else ``/imu``); "" for none.
        time_field, time_unit ("s", "ms", "us", "ns"), ring_field, ring_order (``RING_ORDERS``):
            force what is otherwise detected from the first cloud (see the module doc).

    Attributes:
        path, kind ("rosbag2"), topic, frame_id (of the first cloud), sensor (LidarModel or None),
        times: (N,) sweep starts relative to the first, s. stamps_ns: (N,) int64 header stamps, ns.
        poses: (N, 4, 4) ``T_first_lidar`` or None. layout: ``CloudLayout``. manifest: {}.
        imu: ``simlidar.imu.ImuSamples`` (stamps in the time base of ``times``) or None. imu_topic: its topic.
        imu_truth: None (a bag carries none).
    """

    kind = "rosbag2"

    def __init__(self, path: str | Path, sensor: LidarModel | None = None, topic: str | None = None,
                 ground_truth_topic: str | None = None, poses_file: str | Path | None = None, *,
                 imu_topic: str | None = None, time_field: str | None = None, time_unit: str | None = None,
                 ring_field: str | None = None, ring_order: str = "auto"):
        self.path = Path(path)
        self.manifest: dict = {}
        if ring_order not in RING_ORDERS:
            raise ValueError(f"ring_order must be one of {RING_ORDERS}, got {ring_order!r}")
        if time_unit is not None and time_unit not in TIME_UNITS_NS:
            raise ValueError(f"time_unit must be one of {tuple(TIME_UNITS_NS)}, got {time_unit!r}")
        if not self.path.exists():
            raise BagError(f"{self.path}: no such bag (a rosbag2 folder, or an .mcap / .db3 file)")
        self._rosbags()  # fail early, with the install hint, when rosbags is missing
        self._reader = None
        self._cursor = None  # (next frame index, message generator) for streaming consecutive frames
        self.sensor = sensor if sensor is not None else self._sensor_beside()

        reader = self._open_reader()
        try:
            self.topic = self._cloud_topic(reader, topic)
            self._conns = self._topic_connections(reader)
            gt_conn = self._odometry_connection(reader, ground_truth_topic)
            self.ground_truth_topic = gt_conn.topic if gt_conn is not None else None
            imu_conns = self._imu_connections(reader, imu_topic)
            self.imu_topic = imu_conns[0].topic if imu_conns else None
            log_ns, stamps, gt, first_raw, imu = self._scan(reader, gt_conn, imu_conns)
        finally:
            self._close_reader()
        if not stamps:
            raise BagError(f"{self.path}: topic {self.topic} holds no messages")
        self._log_ns = np.array(log_ns, dtype=np.int64)
        # the n-th message among those logged at the same time, to find it again by time
        self._ordinal = np.zeros(len(log_ns), dtype=np.int64)
        for k in range(1, len(log_ns)):
            if log_ns[k] == log_ns[k - 1]:
                self._ordinal[k] = self._ordinal[k - 1] + 1
        self.stamps_ns = np.array(stamps, dtype=np.int64)
        if np.any(np.diff(self.stamps_ns) <= 0):
            log.warning("%s: header stamps of %s are not increasing; times may be wrong", self.path, self.topic)

        first = self._decode(first_raw, 0)
        self.frame_id = first.header.frame_id
        self.layout = self._detect_layout(first, time_field, time_unit, ring_field, ring_order)
        sweep_ns = self.stamps_ns + self.layout.sweep_offset_ns
        self.times = (sweep_ns - sweep_ns[0]) * 1e-9
        self.poses = self._ground_truth(gt, sweep_ns, poses_file)
        self.imu_truth = None
        self.imu = self._imu_samples(imu, int(sweep_ns[0]))

    # ---- sequence protocol
    def __len__(self) -> int:
        return len(self.stamps_ns)

    def __iter__(self):
        for k in range(len(self)):
            yield self[k]

    def __getitem__(self, k: int) -> Frame:
        if not -len(self) <= k < len(self):
            raise IndexError(f"{self.path}: frame {k} out of range (0..{len(self) - 1})")
        k = int(k) % len(self)
        return self._frame(k, self._raw_message(k))

    def frame(self, k: int, truth: bool = True) -> Frame:
        """Frame ``k`` (a bag carries no per-return truth)."""
        return self[k]

    def close(self) -> None:
        """Close the bag file (reopened when a frame is asked for again)."""
        self._close_reader()

    def __enter__(self) -> RosbagSequence:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self._close_reader()
        except Exception:  # interpreter shutdown: nothing left to report to
            pass

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        # an open file, and rosbags' generated types, do not travel to another process: reopened there
        for key in ("_reader", "_cursor", "_conns", "_typestore"):
            state[key] = None
        return state

    def verify(self) -> None:
        """Nothing to check: a bag carries no checksums (``Sequence.verify`` compatibility)."""

    # ---- opening
    def _rosbags(self):
        return require_rosbags(f"{self.path}: reading")

    def _open_reader(self):
        if self._reader is None:
            rosbag2, self._typestore = self._rosbags()
            try:
                reader = rosbag2.Reader(self.path)
                reader.open()
            except Exception as exc:  # rosbags, apsw and the YAML parser each raise their own types
                raise BagError(f"{self.path}: cannot read the bag ({type(exc).__name__}: {exc})") from None
            self._reader = reader
            if hasattr(self, "topic"):  # reopened: connections belong to their reader
                self._conns = self._topic_connections(reader)
        return self._reader

    def _topic_connections(self, reader) -> list:
        # a topic may be recorded through several connections (e.g. different QoS): read them all
        return [c for c in reader.connections if c.topic == self.topic and c.msgtype == POINTCLOUD2]

    def _close_reader(self) -> None:
        self._cursor = None
        if getattr(self, "_reader", None) is not None:
            reader, self._reader = self._reader, None
            reader.close()

    def _sensor_beside(self) -> LidarModel | None:
        folder = self.path if self.path.is_dir() else self.path.parent
        candidates = [folder / "sensor.yaml"]
        if not self.path.is_dir():
            candidates.insert(0, self.path.with_suffix(".sensor.yaml"))
        for f in candidates:
            if f.is_file():
                return load_sensor_file(f)
        return None

    def _cloud_topic(self, reader, topic: str | None) -> str:
        clouds = [c for c in reader.connections if c.msgtype == POINTCLOUD2]
        listing = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"
        if topic is not None:
            match = [c for c in reader.connections if c.topic == topic]
            if not match:
                raise BagError(f"{self.path}: no topic {topic} (topics: {listing})")
            if match[0].msgtype != POINTCLOUD2:
                raise BagError(f"{self.path}: topic {topic} is {match[0].msgtype}, not {POINTCLOUD2}")
            return topic
        if not clouds:
            raise BagError(f"{self.path}: no {POINTCLOUD2} topic (topics: {listing})")
        if len({c.topic for c in clouds}) > 1:
            named = [c for c in clouds if c.topic == "/points"]
            if named:
                return "/points"
            raise BagError(
                f"{self.path}: several PointCloud2 topics ({', '.join(sorted({c.topic for c in clouds}))}); "
                "choose one with topic=... (salo: --topic)"
            )
        return clouds[0].topic

    def _odometry_connection(self, reader, topic: str | None):
        if topic == "":
            return None
        odom = [c for c in reader.connections if c.msgtype == ODOMETRY]
        if topic is not None:
            match = [c for c in odom if c.topic == topic]
            if not match:
                raise BagError(f"{self.path}: no {ODOMETRY} topic {topic} "
                               f"(odometry topics: {', '.join(c.topic for c in odom) or 'none'})")
            return match[0]
        if len(odom) == 1:
            return odom[0]
        named = [c for c in odom if "ground_truth" in c.topic]
        if len(named) == 1:
            return named[0]
        if odom:
            log.warning("%s: several odometry topics and none named ground_truth; no ground truth read", self.path)
        return None

    def _scan(self, reader, gt_conn, imu_conns):
        """One pass over the cloud (and ground-truth and IMU) topics: log times, header stamps, odometry
        poses, IMU samples (stamp ns, angular velocity, linear acceleration, frame id)."""
        log_ns, stamps, gt, first_raw, imu = [], [], [], None, []
        conns = self._conns + ([gt_conn] if gt_conn is not None else []) + imu_conns
        try:
            for conn, t, raw in reader.messages(connections=conns):
                if conn.topic == self.topic and conn.msgtype == POINTCLOUD2:
                    if len(raw) < 12:
                        raise BagError(f"{self.path}: topic {self.topic} message {len(stamps)} is truncated")
                    if first_raw is None:
                        first_raw = bytes(raw)
                    log_ns.append(t)
                    stamps.append(header_stamp_ns(raw))
                elif conn.msgtype == IMU:
                    msg = self._typestore.deserialize_cdr(raw, IMU)
                    w, a = msg.angular_velocity, msg.linear_acceleration
                    imu.append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                                (w.x, w.y, w.z), (a.x, a.y, a.z), msg.header.frame_id))
                else:
                    msg = self._typestore.deserialize_cdr(raw, ODOMETRY)
                    p, q = msg.pose.pose.position, msg.pose.pose.orientation
                    gt.append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                               (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), msg.child_frame_id))
        except BagError:
            raise
        except Exception as exc:  # rosbags raises several types for a damaged file
            raise BagError(f"{self.path}: cannot read the messages ({type(exc).__name__}: {exc})") from None
        return log_ns, stamps, gt, first_raw, imu

    def _imu_connections(self, reader, topic: str | None) -> list:
        if topic == "":
            return []
        imus = [c for c in reader.connections if c.msgtype == IMU]
        names = sorted({c.topic for c in imus})
        if topic is not None:
            if topic not in names:
                raise BagError(f"{self.path}: no {IMU} topic {topic} (IMU topics: {', '.join(names) or 'none'})")
        elif len(names) == 1:
            topic = names[0]
        elif IMU_TOPIC in names:
            topic = IMU_TOPIC
        elif names:
            log.warning("%s: several IMU topics (%s) and none named %s; no IMU read (choose one with imu_topic)",
                        self.path, ", ".join(names), IMU_TOPIC)
            return []
        return [c for c in imus if c.topic == topic]

    def _imu_samples(self, imu: list, origin_ns: int) -> ImuSamples | None:
        """The IMU messages, sorted by stamp, as samples in the time base of ``times`` (s since ``origin_ns``)."""
        if not imu:
            return None
        imu.sort(key=lambda m: m[0])
        stamps = np.array([m[0] for m in imu], dtype=np.int64)
        if np.any(np.diff(stamps) <= 0):
            log.warning("%s: %s has repeated stamps; kept once each", self.path, self.imu_topic)
            keep = np.concatenate([[True], np.diff(stamps) > 0])
            imu = [m for m, k in zip(imu, keep, strict=True) if k]
            stamps = stamps[keep]
        return ImuSamples((stamps - origin_ns) * 1e-9, np.array([m[1] for m in imu], dtype=float),
                          np.array([m[2] for m in imu], dtype=float), imu[0][3] or "imu")

    def _decode(self, raw, k: int):
        try:
            return self._typestore.deserialize_cdr(raw, POINTCLOUD2)
        except Exception as exc:  # SerdeError and friends
            raise BagError(f"{self.path}: {self.topic} frame {k}: cannot decode ({exc})") from None

    def _detect_layout(self, msg, time_field, time_unit, ring_field, ring_order) -> CloudLayout:
        where = f"{self.path}: {self.topic} frame 0"
        rec = cloud_records(msg, where)
        names = rec.dtype.names
        for axis in ("x", "y", "z"):
            if axis not in names:
                raise BagError(f"{where}: the cloud has no '{axis}' field (fields: {', '.join(names)})")
        for given, what in ((time_field, "time"), (ring_field, "ring")):
            if given is not None and given not in names:
                raise BagError(f"{where}: no {what} field '{given}' (fields: {', '.join(names)})")
        tf = time_field or _first_present(TIME_FIELDS, names)
        rf = ring_field or _first_present(RING_FIELDS, names)
        stamp = int(self.stamps_ns[0])
        unit_ns, absolute, offset_ns = TIME_UNITS_NS["s"], False, 0
        if tf is not None:
            values = rec[tf]
            unit_ns = TIME_UNITS_NS[time_unit] if time_unit else detect_time_unit_ns(values)
            if len(values):
                earliest_s = float(np.min(values)) * unit_ns * 1e-9
                absolute = abs(earliest_s - stamp * 1e-9) < abs(earliest_s)
                rel = times_since_stamp(values, unit_ns, absolute, stamp)
                if rel.min() < 0:  # the driver stamps the sweep's end: start the sweep at its first point
                    offset_ns = int(np.floor(rel.min() * 1e9))
        order, count = "ascending", None
        if rf is not None:
            rings = rec[rf].astype(np.int64)
            order = ring_order if ring_order != "auto" else detect_ring_order(rings, _xyz(rec))
            if self.sensor is not None:
                count = self.sensor.rings
            elif len(rings):
                count = int(rings.max()) + 1
            if order == "laser_id" and self.sensor is None:
                log.warning("%s: ring field '%s' is not ordered by elevation and no sensor model maps laser ids "
                            "to rings; it is ignored (rings come from elevation)", self.path, rf)
                rf = None
        intensity = _first_present(INTENSITY_FIELDS, names)
        layout = CloudLayout(tf, unit_ns, absolute, offset_ns, rf, order, count, intensity)
        log.info("%s: %s read with %s", self.path, self.topic, layout)
        return layout

    def _ground_truth(self, gt, sweep_ns: np.ndarray, poses_file) -> np.ndarray | None:
        if poses_file is not None:
            poses = read_kitti_poses(poses_file)
            if len(poses) < len(sweep_ns):
                raise BagError(f"{poses_file}: {len(poses)} poses for {len(sweep_ns)} clouds in {self.path}")
            return se3.inverse(poses[0]) @ poses[: len(sweep_ns)]
        if not gt:
            return None
        from scipy.spatial.transform import Rotation

        gt.sort(key=lambda g: g[0])
        t = np.array([g[0] for g in gt], dtype=np.int64)
        T = np.tile(np.eye(4), (len(gt), 1, 1))
        T[:, :3, 3] = [g[1] for g in gt]
        T[:, :3, :3] = Rotation.from_quat([g[2] for g in gt]).as_matrix()  # x y z w, normalized
        child = gt[0][3].lstrip("/")
        if child and self.frame_id and child != self.frame_id.lstrip("/"):
            log.warning("%s: ground truth is of frame '%s', the clouds are in '%s'; used as the lidar's pose",
                        self.path, child, self.frame_id)
        tol_ns = 1000
        if sweep_ns[0] < t[0] - tol_ns or sweep_ns[-1] > t[-1] + tol_ns:
            log.warning("%s: %s covers %.3f..%.3f s, the clouds %.3f..%.3f s; no ground truth", self.path,
                        self.ground_truth_topic, t[0] * 1e-9, t[-1] * 1e-9, sweep_ns[0] * 1e-9, sweep_ns[-1] * 1e-9)
            return None
        i = np.clip(np.searchsorted(t, sweep_ns), 1, max(len(t) - 1, 1))
        poses = np.empty((len(sweep_ns), 4, 4))
        for k, (s, j) in enumerate(zip(sweep_ns, i, strict=True)):
            if len(t) == 1 or abs(s - t[j - 1]) <= tol_ns:
                poses[k] = T[j - 1] if len(t) > 1 else T[0]
            elif abs(s - t[j]) <= tol_ns:
                poses[k] = T[j]
            else:
                poses[k] = se3.interpolate(T[j - 1], T[j], (s - t[j - 1]) / (t[j] - t[j - 1]))
        return se3.inverse(poses[0]) @ poses

    # ---- frames
    def _raw_message(self, k: int):
        reader = self._open_reader()
        if self._cursor is not None and self._cursor[0] == k:
            gen = self._cursor[1]
        else:
            gen = reader.messages(connections=self._conns, start=int(self._log_ns[k]))
            for _ in range(int(self._ordinal[k])):  # messages logged at the same instant, before this one
                next(gen, None)
        item = next(gen, None)
        if item is None:
            self._cursor = None
            raise BagError(f"{self.path}: {self.topic} frame {k} is missing (the bag changed while open?)")
        self._cursor = (k + 1, gen)
        return item[2]

    def _frame(self, k: int, raw) -> Frame:
        where = f"{self.path}: {self.topic} frame {k}"
        msg = self._decode(raw, k)
        rec = cloud_records(msg, where)
        names = rec.dtype.names
        for axis in ("x", "y", "z"):
            if axis not in names:
                raise BagError(f"{where}: the cloud has no '{axis}' field (fields: {', '.join(names)})")
        lay = self.layout
        points = _xyz(rec)
        intensity = None
        if lay.intensity_field in names:
            intensity = rec[lay.intensity_field].astype(np.float32)

        out_fields: list[tuple] = []
        values: dict[str, np.ndarray] = {}
        used = {"x", "y", "z", lay.intensity_field}
        if lay.ring_field in names:
            values["ring"] = self._rings(rec[lay.ring_field], points, where)
            out_fields.append(("ring", "<u2"))
            used.add(lay.ring_field)
        if lay.time_field in names:
            stamp = header_stamp_ns(raw)
            rel = times_since_stamp(rec[lay.time_field], lay.time_unit_ns, lay.time_absolute, stamp)
            values["time_s"] = rel - lay.sweep_offset_ns * 1e-9
            out_fields.append(("time_s", "<f8"))
            used.add(lay.time_field)
        groups = {parts[0]: (group, parts) for group, parts in VECTOR_FIELDS.items()
                  if all(p in names for p in parts) and group not in names}
        for name in names:
            if name in groups:  # the first of a vector's three scalar fields: the vector goes here
                group, parts = groups[name]
                values[group] = np.stack([rec[p] for p in parts], axis=1).astype(np.float32)
                out_fields.append((group, "<f4", (3,)))
                used.update(parts)
            if name in used or name in values:
                continue
            sub = rec.dtype.fields[name][0]
            out_fields.append((name, sub.base.newbyteorder("<"), sub.shape) if sub.shape
                              else (name, sub.newbyteorder("<")))
            values[name] = rec[name]
        fields = None
        if out_fields:
            fields = np.empty(len(rec), dtype=out_fields)
            for name in fields.dtype.names:
                fields[name] = values[name]
        return Frame(k, points, intensity, fields, self.path)

    def _rings(self, raw: np.ndarray, points: np.ndarray, where: str) -> np.ndarray:
        """Ring field (N,) -> (N,) uint16 rings numbered by elevation, 0 = lowest (see the module doc)."""
        lay = self.layout
        r = raw.astype(np.int64)
        if len(r) and r.min() < 0:
            raise BagError(f"{where}: negative ring index {r.min()} in '{lay.ring_field}'")
        if lay.ring_order == "descending":
            r = lay.ring_count - 1 - r
            if len(r) and r.min() < 0:
                raise BagError(f"{where}: ring index {lay.ring_count - 1 - r.min()} in '{lay.ring_field}' beyond "
                               f"the {lay.ring_count} rings the ring order was detected with")
        elif lay.ring_order == "laser_id":
            if len(r) and r.max() >= self.sensor.rings:
                raise BagError(f"{where}: laser id {r.max()} but sensor '{self.sensor.name}' has "
                               f"{self.sensor.rings} lasers")
            ring_of_laser = np.argsort(self.sensor.laser_of_ring)
            r = ring_of_laser[r]
        if self.sensor is not None and len(r) and r.max() >= self.sensor.rings:
            raise BagError(f"{where}: ring {r.max()} but sensor '{self.sensor.name}' has {self.sensor.rings} rings "
                           "(wrong sensor model?)")
        return r.astype(np.uint16)


def _xyz(rec: np.ndarray) -> np.ndarray:
    """(N,) cloud records -> (N, 3) float64 points, m."""
    out = np.empty((len(rec), 3))
    for i, axis in enumerate(("x", "y", "z")):
        out[:, i] = rec[axis]
    return out


def open_bag(path: str | Path, sensor: LidarModel | None = None, poses: str | Path | None = None,
             topic: str | None = None) -> RosbagSequence:
    """``open_sequence``'s entry for ROS 2 bags (see ``RosbagSequence``)."""
    return RosbagSequence(path, sensor=sensor, topic=topic, poses_file=poses)


# ---------------------------------------------------------------- writing
POINTS_TOPIC = "/points"
ODOMETRY_TOPIC = "/ground_truth/odometry"
TF_TOPIC = "/tf"
IMU_TOPIC = "/imu"
IMU_FRAME = "imu"
LIDAR_FRAME = "lidar"
MAP_FRAME = "map"


def _quaternion_xyzw(T: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # not at import: `salo --help` loads the export's formats

    return Rotation.from_matrix(T[:3, :3]).as_quat()


class BagWriter:
    """Write lidar frames as a rosbag2 folder (metadata version 8: read by more ROS 2 releases than 9).

    Use as a context manager around ``write_frame`` calls. Topics:

    - ``/points`` ``sensor_msgs/PointCloud2``, frame ``lidar``, one per sweep,
      unorganized (height 1), little-endian, one record per point (the layout of
      ``simlidar.formats.points``);
    - with ``poses``: ``/ground_truth/odometry`` ``nav_msgs/Odometry``, frame
      ``map`` -> child ``lidar``, the pose at the sweep start, zero covariances
      and the body-frame twist given; ``/tf`` ``tf2_msgs/TFMessage``, the same pose;
    - with ``imu``: ``/imu`` ``sensor_msgs/Imu``, frame ``imu``, one message per sample
      (``write_imu``): angular velocity and linear acceleration (specific force), the
      orientation unknown (covariance[0] = -1, as the message's definition says), the
      covariances diagonal, the white noise's variance per sample when known (else zero: unknown).

    Args:
        path: the bag folder to create (must not exist; the storage file is named after it).
        storage: "mcap" or "sqlite3". poses: write the odometry and tf topics.
        custom_data: key -> text stored in the bag's metadata.
        imu: write the IMU topic.
    Attributes:
        counts: messages written per topic.
    """

    def __init__(self, path: str | Path, storage: str = "mcap", poses: bool = True,
                 custom_data: dict[str, str] | None = None, imu: bool = False):
        rosbag2, self._ts = require_rosbags("writing")
        plugin = rosbag2.StoragePlugin.MCAP if storage == "mcap" else rosbag2.StoragePlugin.SQLITE3
        self._writer = rosbag2.Writer(Path(path), version=8, storage_plugin=plugin)
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(key, value)
        self._poses = poses
        self._imu = imu
        self.counts = {POINTS_TOPIC: 0}

    def __enter__(self) -> BagWriter:
        ts, writer = self._ts, self._writer
        writer.open()
        try:
            self._c_points = writer.add_connection(POINTS_TOPIC, POINTCLOUD2, typestore=ts)
            if self._poses:
                self._c_odom = writer.add_connection(ODOMETRY_TOPIC, ODOMETRY, typestore=ts)
                self._c_tf = writer.add_connection(TF_TOPIC, TFMESSAGE, typestore=ts)
                self.counts[ODOMETRY_TOPIC] = self.counts[TF_TOPIC] = 0
            if self._imu:
                self._c_imu = writer.add_connection(IMU_TOPIC, IMU, typestore=ts)
                self.counts[IMU_TOPIC] = 0
        except BaseException:
            writer.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()

    def write_frame(self, stamp_ns: int, record: np.ndarray, T_world_lidar: np.ndarray | None = None,
                    twist: np.ndarray | None = None) -> None:
        """One sweep: (N,) point records, stamped ``stamp_ns`` (header and log time); with poses, its
        (4, 4) ``T_world_lidar`` and (6,) body twist (m/s, rad/s)."""
        ts, T = self._ts, self._ts.types

        def header(frame_id: str):
            sec, nanosec = divmod(stamp_ns, 1_000_000_000)
            return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                            frame_id=frame_id)

        def vec(cls: str, v) -> object:
            return T[cls](x=float(v[0]), y=float(v[1]), z=float(v[2]))

        def quat(q) -> object:
            return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

        pfields = [T["sensor_msgs/msg/PointField"](name=f.name, offset=f.offset, datatype=f.datatype,
                                                   count=f.count) for f in dtype_fields(record.dtype)]
        xyz_ok = np.isfinite(record["x"]) & np.isfinite(record["y"]) & np.isfinite(record["z"])
        cloud = T[POINTCLOUD2](
            header=header(LIDAR_FRAME), height=1, width=len(record), fields=pfields,
            is_bigendian=False, point_step=record.dtype.itemsize, row_step=record.dtype.itemsize * len(record),
            data=np.frombuffer(record.tobytes(), dtype=np.uint8), is_dense=bool(np.all(xyz_ok)),
        )
        self._writer.write(self._c_points, stamp_ns, ts.serialize_cdr(cloud, POINTCLOUD2))
        self.counts[POINTS_TOPIC] += 1
        if not self._poses:
            return
        P = T_world_lidar
        pose = T["geometry_msgs/msg/Pose"](position=vec("geometry_msgs/msg/Point", P[:3, 3]),
                                           orientation=quat(_quaternion_xyzw(P)))
        odom = T[ODOMETRY](
            header=header(MAP_FRAME), child_frame_id=LIDAR_FRAME,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=vec("geometry_msgs/msg/Vector3", twist[:3]),
                                                   angular=vec("geometry_msgs/msg/Vector3", twist[3:])),
                covariance=np.zeros(36)),
        )
        self._writer.write(self._c_odom, stamp_ns, ts.serialize_cdr(odom, ODOMETRY))
        tf = T[TFMESSAGE](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=header(MAP_FRAME), child_frame_id=LIDAR_FRAME,
            transform=T["geometry_msgs/msg/Transform"](
                translation=vec("geometry_msgs/msg/Vector3", P[:3, 3]),
                rotation=quat(_quaternion_xyzw(P))))])
        self._writer.write(self._c_tf, stamp_ns, ts.serialize_cdr(tf, TFMESSAGE))
        self.counts[ODOMETRY_TOPIC] += 1
        self.counts[TF_TOPIC] += 1

    def write_imu(self, stamps_ns: np.ndarray, angular_velocity: np.ndarray, linear_acceleration: np.ndarray,
                  gyro_variance: float = 0.0, accel_variance: float = 0.0) -> None:
        """IMU samples: (n,) int stamps, ns (header and log time), (n, 3) rad/s, (n, 3) m/s^2; the per-sample
        variance of each axis' noise (0: unknown)."""
        ts, T = self._ts, self._ts.types
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0
        cov_w, cov_a = np.diag([gyro_variance] * 3).ravel(), np.diag([accel_variance] * 3).ravel()
        for stamp, w, a in zip(stamps_ns, angular_velocity, linear_acceleration, strict=True):
            sec, nanosec = divmod(int(stamp), 1_000_000_000)
            msg = T[IMU](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                                frame_id=IMU_FRAME),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=no_orientation,
                angular_velocity=T["geometry_msgs/msg/Vector3"](x=float(w[0]), y=float(w[1]), z=float(w[2])),
                angular_velocity_covariance=cov_w,
                linear_acceleration=T["geometry_msgs/msg/Vector3"](x=float(a[0]), y=float(a[1]), z=float(a[2])),
                linear_acceleration_covariance=cov_a,
            )
            self._writer.write(self._c_imu, int(stamp), ts.serialize_cdr(msg, IMU))
        self.counts[IMU_TOPIC] += len(stamps_ns)


__all__ = [
    "BagError",
    "BagWriter",
    "CloudLayout",
    "PointFieldSpec",
    "RosbagSequence",
    "cloud_dtype",
    "cloud_records",
    "dtype_fields",
    "is_bag",
    "open_bag",
    "require_rosbags",
]
