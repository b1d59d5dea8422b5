"""Open a sequence of any supported kind: the registry of sequence readers.

``open_sequence`` asks each reader of ``READERS``, in order, whether it
recognises the path (``detect``) and opens it with the first that does:

=========  ==========================================  =========================================
kind       recognised by                               reader
=========  ==========================================  =========================================
rosbag2    a folder with ``metadata.yaml``, or an      ``simlidar.formats.rosbag.open_bag``
           ``.mcap`` / ``.db3`` file
salo       a folder with ``manifest.json``             ``simlidar.formats.salo.open_salo``
kitti      ``calib.txt`` beside ``velodyne/``          ``simlidar.formats.scan_folders.open_kitti_folder``
pcd        a folder (or its ``velodyne/``) of          ``simlidar.formats.scan_folders.open_pcd_folder``
           ``.pcd`` scans only
scans      any other folder (``.bin`` / ``.ply``)      ``simlidar.formats.scan_folders.open_scan_folder``
=========  ==========================================  =========================================

A sequence's IMU, when it has one (a simulated folder's ``imu.csv``, a scan folder's, a
bag's ``sensor_msgs/Imu`` topic), is its ``imu`` (``simlidar.imu.ImuSamples``, in the
time base of its ``times``); a simulated one's truth is its ``imu_truth``.

A new format: write its reader (``open(path, sensor, poses, topic)`` returning a
sequence, ``simlidar.sequence``) and its ``detect(path)`` in a module of
``simlidar.formats``, and add a ``SequenceReader`` to ``READERS`` before the
catch-all ``scans``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .formats import rosbag, salo, scan_folders
from .formats.atomic import INCOMPLETE_MARKER
from .sensor import LidarModel, load_sensor
from .sequence import DatasetError


@dataclass(frozen=True)
class SequenceReader:
    """One kind of sequence: its name (the sequence's ``kind``), how to recognise it, how to open it.

    detect(path) -> bool. open(path, sensor, poses, topic) -> a sequence; sensor: a
    ``LidarModel`` or None (the source's own); poses: a ground-truth pose file or None;
    topic: a bag's PointCloud2 topic or None. A reader ignores what does not apply to it.
    """

    name: str
    detect: Callable[[Path], bool]
    open: Callable[..., object]


READERS: tuple[SequenceReader, ...] = (
    SequenceReader("rosbag2", rosbag.is_bag, rosbag.open_bag),
    SequenceReader("salo", salo.is_salo, salo.open_salo),
    SequenceReader("kitti", scan_folders.is_kitti_folder, scan_folders.open_kitti_folder),
    SequenceReader("pcd", scan_folders.is_pcd_folder, scan_folders.open_pcd_folder),
    SequenceReader("scans", Path.is_dir, scan_folders.open_scan_folder),
)


def open_sequence(
    path: str | Path,
    sensor: str | Path | LidarModel | None = None,
    poses: str | Path | None = None,
    topic: str | None = None,
):
    """Open a sequence of any supported kind (detected from its files, see the module doc).

    sensor: preset, file or model overriding the source's own ``sensor.yaml``.
    poses: ground-truth pose file; for real KITTI, the camera-frame file
        (default ``<sequences>/../poses/NN.txt`` when present).
    topic: for a ROS 2 bag, the PointCloud2 topic to read
        (``simlidar.formats.rosbag.RosbagSequence``, which behaves like a ``Sequence``).
    A folder an interrupted write left (its ``INCOMPLETE`` marker) is refused.
    """
    path = Path(path)
    if path.is_dir() and (path / INCOMPLETE_MARKER).exists():
        raise DatasetError(f"{path}: an unfinished sequence (an interrupted write left it)")
    for reader in READERS:
        if reader.detect(path):
            model = load_sensor(sensor) if sensor is not None else None
            return reader.open(path, sensor=model, poses=poses, topic=topic)
    raise DatasetError(f"{path}: not a folder")


__all__ = ["READERS", "SequenceReader", "open_sequence"]
