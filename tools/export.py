"""Export a sequence for other tools: a ROS 2 bag, PLY or PCD scans, a TUM trajectory.

The library behind ``salo export``: which files an export writes, from any
sequence ``simlidar.dataset.open_sequence`` opens (a simulated folder, real
KITTI, a scan folder, a ROS 2 bag) and an optional frame slice. The formats
themselves are ``simlidar.formats``'s. Every export is written atomically (a
``simlidar.formats.atomic.StagedFolder``, or an atomic file), so a failed export
leaves nothing that looks complete. An existing output is only replaced with
``force=True``.

**ROS 2 bag** (``export_rosbag``; needs the optional ``rosbags`` package). A
rosbag2 folder (``simlidar.formats.rosbag.BagWriter``: MCAP storage by default,
or SQLite3) with the sequence's ``sensor.yaml`` inside: ``/points`` one cloud
per sweep in the layout of ``simlidar.formats.points`` (``truth=False`` leaves
the ground-truth fields out); ``/ground_truth/odometry`` and ``/tf``: the true
pose at each sweep start in the world frame of the simulation
(``manifest.json``'s ``T_world_first_lidar`` times ``poses.txt``; the first
frame's pose for other sequences), with the twist of the motion to the next
sweep (body frame, m/s and rad/s); with an IMU (``seq.imu``), ``/imu``
``sensor_msgs/Imu`` with its samples from the first exported sweep's start to the
last one's end (``sensor.yaml``'s ``imu`` keeps its mounting and noise). Stamps
(header and log time alike) are
``epoch_s`` + the sequence's ``times.txt`` (and the IMU's own stamps) (default epoch 2020-01-01T00:00:00Z,
because ROS tools read a zero stamp as "no time"); the same input gives the
same bytes.

**PLY / PCD scans** (``export_scans``): one file per frame, named by its frame
index, with the same fields (PLY names the normal ``nx ny nz``, as mesh tools
expect), plus ``sensor.yaml``, ``poses.txt`` and ``times.txt`` (both relative
to the first exported frame), so ``open_sequence`` reads a PLY folder back.
PCD is v0.7, binary (the little-endian record) or ASCII. An IMU's samples over the
exported sweeps go into ``imu.csv`` (``simlidar.formats.imu_csv``), stamped from the
first exported sweep's start.

**TUM** (``export_tum``): ``timestamp tx ty tz qx qy qz qw`` per frame, poses
relative to the first exported frame, timestamps the sequence's own (as
``salo odometry --tum`` writes them for the same ``--frames``, so evo associates
the two).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simlidar import se3
from simlidar.formats import rosbag
from simlidar.formats.atomic import StagedFolder, atomic_write_text
from simlidar.formats.imu_csv import IMU_FILE, format_imu_csv
from simlidar.formats.kitti import format_kitti_poses, format_times
from simlidar.formats.pcd import write_pcd
from simlidar.formats.ply import PLY_FIELD_NAMES, write_ply_scan
from simlidar.formats.points import point_record
from simlidar.formats.tum import format_tum
from simlidar.sequence import DatasetError, frame_period_s, sweep_start_times

log = logging.getLogger(__name__)

DEFAULT_EPOCH_S = 1_577_836_800  # 2020-01-01T00:00:00Z
FORMATS = ("rosbag", "ply", "pcd", "tum")
STORAGES = rosbag.STORAGES


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


# ---------------------------------------------------------------- helpers
def slice_text(frames: slice | None) -> str:
    """A frame range as typed: ``A:B`` or ``A:B:STEP`` (``:`` for all)."""
    if frames is None:
        return ":"
    text = f"{'' if frames.start is None else frames.start}:{'' if frames.stop is None else frames.stop}"
    return text + (f":{frames.step}" if frames.step not in (None, 1) else "")


def frame_indices(seq, frames: slice | None) -> np.ndarray:
    """Indices of the frames a slice selects; an error when it selects none."""
    idx = np.arange(len(seq))[frames or slice(None)]
    if len(idx) == 0:
        raise ExportError(f"{seq.path}: frames {slice_text(frames)} select none of its {len(seq)} frames")
    return idx


def world_poses(seq) -> np.ndarray | None:
    """(N, 4, 4) ``T_world_lidar``: the manifest's first pose (if any) times the sequence's relative poses."""
    if seq.poses is None:
        return None
    first = np.eye(4)
    row = (seq.manifest or {}).get("T_world_first_lidar")
    if row is not None and len(row) == 12:
        first = se3.kitti_lines_to_poses(np.asarray(row, dtype=float))[0]
    return first @ np.asarray(seq.poses)


def exported_imu(seq, idx: np.ndarray):
    """The sequence's IMU samples (``simlidar.imu.ImuSamples``) from the first selected sweep's start to the last
    one's end, or None without an IMU."""
    imu = getattr(seq, "imu", None)
    if imu is None:
        return None
    times = sweep_start_times(seq)
    return imu.between(float(times[idx[0]]), float(times[idx[-1]]) + frame_period_s(seq.sensor) + 1e-9)


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
    rosbag.require_rosbags("writing")  # before anything else: the install hint
    if storage not in STORAGES:
        raise ExportError(f"{out}: storage must be one of {', '.join(STORAGES)}, not {storage!r}")
    out = Path(out)
    stage = StagedFolder(out, force, ExportError)
    idx = frame_indices(seq, frames)
    times = sweep_start_times(seq)
    epoch_ns = int(round(epoch_s * 1e9))  # apart from the times: ns since 1970 are beyond float64's ns resolution
    stamps_ns = [epoch_ns + int(round(times[k] * 1e9)) for k in idx]
    if any(b <= a for a, b in zip(stamps_ns, stamps_ns[1:], strict=False)):
        raise ExportError(f"{seq.path}: sweep times are not increasing; a bag needs increasing stamps")
    poses = world_poses(seq)
    imu = exported_imu(seq, idx)
    imu_ns = np.zeros(0, dtype=np.int64) if imu is None else epoch_ns + np.round(imu.time_s * 1e9).astype(np.int64)
    gyro_var = accel_var = 0.0
    if imu is not None and seq.sensor is not None and seq.sensor.imu.enabled:
        model = seq.sensor.imu  # the white noise's variance per sample
        gyro_var = model.gyroscope_noise_density**2 * model.update_rate
        accel_var = model.accelerometer_noise_density**2 * model.update_rate

    def write_imu_until(writer, j: int, stamp: int | None) -> int:  # samples j.. stamped up to stamp (None: all)
        end = len(imu_ns) if stamp is None else int(np.searchsorted(imu_ns, stamp, side="right"))
        if end > j:
            writer.write_imu(imu_ns[j:end], imu.angular_velocity[j:end], imu.specific_force[j:end], gyro_var,
                             accel_var)
        return max(j, end)

    try:
        with stage:
            bag_dir = stage.path / out.name  # the bag's storage file is named after its folder
            writer = rosbag.BagWriter(bag_dir, storage, poses=poses is not None, imu=imu is not None,
                                      custom_data={"salo.source": str(seq.path), "salo.epoch_s": repr(float(epoch_s))})
            with writer:
                done = 0  # IMU samples written: in time order with the clouds
                for j, k in enumerate(idx):
                    pose = twist = None
                    if poses is not None:
                        pose, twist = poses[int(k)], _body_twist(poses, times, idx, j)
                    if imu is not None:
                        done = write_imu_until(writer, done, stamps_ns[j])
                    writer.write_frame(stamps_ns[j], point_record(seq[int(k)], truth), pose, twist)
                    if on_frame is not None:
                        on_frame(int(k))
                if imu is not None:
                    write_imu_until(writer, done, None)
            if seq.sensor is not None:
                (bag_dir / "sensor.yaml").write_text(seq.sensor.to_yaml())
            stage.commit(bag_dir)
    except OSError as exc:
        raise ExportError(f"{out}: cannot write the bag ({exc})") from None
    return ExportResult(out, "rosbag", idx, writer.counts)


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
    stage = StagedFolder(out, force, ExportError)
    idx = frame_indices(seq, frames)
    files = []
    try:
        with stage:
            for k in idx:
                rec = point_record(seq[int(k)], truth)
                path = stage.path / f"{int(k):06d}.{fmt}"
                if fmt == "pcd":
                    write_pcd(path, rec, binary=binary)
                else:
                    xyz = np.column_stack([rec["x"], rec["y"], rec["z"]])
                    write_ply_scan(path, xyz, {PLY_FIELD_NAMES.get(n, n): rec[n] for n in rec.dtype.names[3:]})
                files.append(out / path.name)
                if on_frame is not None:
                    on_frame(int(k))
            if seq.sensor is not None:
                atomic_write_text(stage.path / "sensor.yaml", seq.sensor.to_yaml())
            if seq.poses is not None:
                P = np.asarray(seq.poses)[idx]
                atomic_write_text(stage.path / "poses.txt", format_kitti_poses(se3.inverse(P[0]) @ P))
            if seq.times is not None:
                atomic_write_text(stage.path / "times.txt", format_times(sweep_start_times(seq)[idx]))
            imu = exported_imu(seq, idx)
            if imu is not None:
                imu.time_s = imu.time_s - sweep_start_times(seq)[idx[0]]
                atomic_write_text(stage.path / IMU_FILE, format_imu_csv(imu))
            stage.commit()
    except OSError as exc:
        raise ExportError(f"{out}: cannot write the scans ({exc})") from None
    return ExportResult(out, fmt, idx, files=files)


def export_tum(seq, out: str | Path, frames: slice | None = None, *, force: bool = False) -> ExportResult:
    """Write the ground-truth trajectory in TUM format (see the module doc)."""
    out = Path(out)
    if out.exists() and not force:
        raise ExportError(f"{out}: already exists (replace it with --force, or force=True in Python)")
    if seq.poses is None:
        raise ExportError(f"{seq.path}: no ground-truth poses to write as a trajectory")
    idx = frame_indices(seq, frames)
    P = np.asarray(seq.poses)[idx]
    try:
        atomic_write_text(out, format_tum(se3.inverse(P[0]) @ P, sweep_start_times(seq)[idx]))
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
]
