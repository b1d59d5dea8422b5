"""Sequence folders on disk: the simulator's KITTI-compatible layout, real KITTI, scan folders.

The simulator's layout (``kind == "salo"``)::

    DIR/
      velodyne/000000.bin   float32 x y z intensity per point (KITTI odometry format)
      sidecar/000000.npy    structured array, one record per point of the .bin, same order:
                            ring, azimuth_index, time_s, range_m, true_range_m, true_xyz,
                            normal, object_id (see ``simlidar.sweep.SIDECAR_DTYPE``)
      poses.txt             3x4 row-major T_first_lidar per frame (line 0 is identity)
      times.txt             sweep start time per frame, s (first is 0)
      sensor.yaml           the sensor model (simlidar.sensor keys)
      degeneracy.csv        per frame: eigenvalues of the point-to-plane information from the
                            returns' true normals (``simlidar.degeneracy``)
      manifest.json         written last: parameters, versions, frame count, sha256 per file

A sequence is written in a hidden sibling folder holding an ``INCOMPLETE``
marker and renamed into place only when every file and the manifest are on
disk, so an interrupted run never leaves a folder that looks complete.

Readers (``open_sequence``) also take a real KITTI odometry sequence (poses in
the camera frame plus ``calib.txt``'s ``Tr``, converted to the lidar frame) and
a plain folder of ``.bin`` / ``.ply`` scans with a sensor file.
"""

from __future__ import annotations

import glob
import hashlib
import json
import logging
import os
import shutil
import socket
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import __version__, se3
from .degeneracy import CSV_HEADER, csv_row, degeneracy
from .sensor import LidarModel, SensorError, load_sensor, load_sensor_file

log = logging.getLogger(__name__)

FORMAT_NAME = "salo-sequence"
FORMAT_VERSION = 1
INCOMPLETE_MARKER = "INCOMPLETE"
SIDECAR_FIELDS = (
    "ring",
    "azimuth_index",
    "time_s",
    "range_m",
    "true_range_m",
    "true_xyz",
    "normal",
    "object_id",
)


class DatasetError(ValueError):
    """A sequence or scan file cannot be read or written; the message names the file."""


# ---------------------------------------------------------------- small file formats
def read_kitti_poses(path: str | Path) -> np.ndarray:
    """Read a KITTI pose file (12 numbers per line) -> (N, 4, 4)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read pose file ({exc.strerror})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 12:
            raise DatasetError(
                f"{path}:{lineno}: a KITTI pose line needs 12 numbers (3x4 row-major), "
                f"found {len(parts)}"
            )
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise DatasetError(f"{path}:{lineno}: not a number in {line.strip()!r}") from None
    if not rows:
        raise DatasetError(f"{path}: no poses in the file")
    poses = se3.kitti_lines_to_poses(np.array(rows))
    if not np.all(np.isfinite(poses)):
        raise DatasetError(f"{path}: poses contain non-finite numbers")
    R = poses[:, :3, :3]
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero(err > 1e-3)
    if len(bad):
        raise DatasetError(
            f"{path}: pose on line {bad[0] + 1} is not a rotation (|R R^T - I| = {err[bad[0]]:.2e})"
        )
    return poses


def format_kitti_poses(poses: np.ndarray) -> str:
    """(N, 4, 4) -> KITTI pose file text."""
    lines = se3.poses_to_kitti_lines(poses)
    return "".join(" ".join(f"{v:.12e}" for v in row) + "\n" for row in lines)


def read_times(path: str | Path) -> np.ndarray:
    path = Path(path)
    try:
        values = [float(x) for x in path.read_text().split()]
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read times file ({exc.strerror})") from None
    except ValueError:
        raise DatasetError(f"{path}: times file holds something that is not a number") from None
    return np.array(values)


def read_kitti_calib_tr(path: str | Path) -> np.ndarray:
    """The ``Tr`` (velodyne -> cam0) line of a KITTI ``calib.txt`` as a (4, 4)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read calibration ({exc.strerror})") from None
    for line in lines:
        key, _, rest = line.partition(":")
        if key.strip() == "Tr":
            vals = rest.split()
            if len(vals) != 12:
                raise DatasetError(f"{path}: 'Tr:' needs 12 numbers, found {len(vals)}")
            return se3.kitti_lines_to_poses(np.array([float(v) for v in vals]))[0]
    raise DatasetError(f"{path}: no 'Tr:' line (velodyne to camera) in the calibration")


def camera_poses_to_lidar(poses_cam: np.ndarray, Tr_cam_velo: np.ndarray) -> np.ndarray:
    """KITTI ground truth (cam0 poses in the first cam0 frame) -> lidar poses, first = identity.

    ``L_i = Tr^-1 P_i Tr``, then ``L_0^-1 L_i``. KITTI's numbers carry 7 significant
    digits, so their rotations are orthonormal only to ~1e-7: general matrix
    inverses are used, not the rigid-transform shortcut.
    """
    L = np.linalg.inv(Tr_cam_velo) @ poses_cam @ Tr_cam_velo
    return np.linalg.inv(L[0]) @ L


BIN_POINT_BYTES = 16  # float32 x y z intensity


def check_bin_size(path: Path, size: int) -> None:
    """Refuse a ``.bin`` of ``size`` bytes that is not a whole number of 16-byte points."""
    if size % BIN_POINT_BYTES:
        raise DatasetError(
            f"{path}: size {size:,} bytes is not a whole number of {BIN_POINT_BYTES}-byte points "
            f"(float32 x y z intensity): {size // BIN_POINT_BYTES:,} points and {size % BIN_POINT_BYTES} "
            "bytes over (truncated or not a KITTI scan?)"
        )


def read_bin(path: str | Path) -> np.ndarray:
    """A KITTI ``.bin`` scan -> (N, 4) float32 x y z intensity.

    The file's size must be a multiple of 16 bytes (``np.fromfile`` alone would
    silently drop a partial float at the end).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            check_bin_size(path, os.fstat(fh.fileno()).st_size)
            raw = np.fromfile(fh, dtype="<f4")
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read scan ({exc.strerror})") from None
    check_bin_size(path, raw.size * 4)  # the file changed under us
    return raw.reshape(-1, 4)


def write_bin(path: Path, xyz: np.ndarray, intensity: np.ndarray) -> None:
    data = np.empty((len(xyz), 4), dtype="<f4")
    data[:, :3] = xyz
    data[:, 3] = intensity
    data.tofile(path)


def read_ply_scan(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A PLY point cloud -> (points (N, 3) float64, intensity (N,) or None, vertex record or None).

    The vertex record keeps every per-point property of the file (``ring``,
    ``time``, ...), as named there.
    """
    import trimesh

    path = Path(path)
    try:
        cloud = trimesh.load(str(path), process=False)
    except Exception as exc:
        raise DatasetError(f"{path}: cannot read PLY ({type(exc).__name__}: {exc})") from None
    points = np.asarray(getattr(cloud, "vertices", np.zeros((0, 3))), dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise DatasetError(f"{path}: no x y z vertices in the PLY file")
    raw = cloud.metadata.get("_ply_raw", {}) if isinstance(cloud.metadata, dict) else {}
    record = raw.get("vertex", {}).get("data") if isinstance(raw, dict) else None
    intensity = None
    if record is not None and record.dtype.names:
        for name in ("intensity", "reflectance", "scalar_intensity"):
            if name in record.dtype.names:
                intensity = np.asarray(record[name], dtype=np.float32).reshape(-1)
                break
    return points, intensity, record


def write_ply_scan(path: str | Path, xyz: np.ndarray, fields: dict[str, np.ndarray]) -> None:
    """Binary little-endian PLY of points with extra per-point scalar properties.

    fields: name -> (N,) array (its dtype decides the PLY type: f4, f8, u1, u2, u4, i4).
    """
    types = {"f4": "float", "f8": "double", "u1": "uchar", "u2": "ushort", "u4": "uint",
             "i4": "int", "i2": "short", "i1": "char"}
    cols = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    for name, arr in fields.items():
        code = np.asarray(arr).dtype.str.lstrip("<>|=")
        if code == "i8":
            code = "i4"
        if code == "u8":
            code = "u4"
        if code not in types:
            raise DatasetError(f"{path}: field '{name}' has unsupported dtype {arr.dtype}")
        cols.append((name, "<" + code))
    rec = np.empty(len(xyz), dtype=cols)
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    for name, arr in fields.items():
        rec[name] = arr
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {len(xyz)}\n"
    header += "".join(f"property {types[t.lstrip('<')]} {n}\n" for n, t in cols)
    header += "end_header\n"
    atomic_write_bytes(path, header.encode("ascii") + rec.tobytes())


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write a file so that readers see the old content or the new, never a part.

    Written beside the target, synced, then renamed over it; a failed write leaves
    no temporary file behind (the OSError propagates).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        tmp.replace(path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """``atomic_write_bytes`` of UTF-8 text."""
    atomic_write_bytes(path, text.encode("utf-8"))


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ---------------------------------------------------------------- writer
def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this machine (a process we may not signal counts as alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def remove_stale_partials(out_dir: str | Path) -> list[Path]:
    """Remove the hidden work folders a killed writer of ``out_dir`` left; returns them.

    A writer builds ``.NAME.partial-PID`` beside ``out_dir`` (and, replacing an
    old sequence, moves that to ``.NAME.old-PID`` for a moment). A process
    killed with SIGKILL cannot clean up, so the next writer of the same
    ``out_dir`` removes those whose process no longer runs, logging a warning
    for each. Left alone: a folder of a live process (another writer at work),
    of this process, with no PID in its name, whose ``INCOMPLETE`` marker names
    another host (a shared file system: its PID means nothing here), or an
    ``old`` one while ``out_dir`` is missing (the swap was cut between its two
    renames: that folder is the only copy of the previous sequence).
    """
    out_dir = Path(out_dir)
    removed: list[Path] = []
    if not out_dir.parent.is_dir():
        return removed
    host = socket.gethostname()
    for kind in ("partial", "old"):
        for folder in sorted(out_dir.parent.glob(f".{glob.escape(out_dir.name)}.{kind}-*")):
            pid_text = folder.name.rsplit("-", 1)[1]
            if not folder.is_dir() or not pid_text.isdigit():
                continue
            pid = int(pid_text)
            if pid == os.getpid() or _pid_alive(pid) or _marker_host(folder) not in (None, host):
                continue
            if kind == "old" and not out_dir.exists():  # killed mid-swap: the only copy of the old sequence
                log.warning("%s holds the sequence that process %d was replacing when it stopped; %s is "
                            "missing, so it is left for you to rename back", folder, pid, out_dir)
                continue
            shutil.rmtree(folder, ignore_errors=True)
            if not folder.exists():
                removed.append(folder)
                log.warning("removed %s, left by process %d, which is no longer running (an interrupted "
                            "write of %s)", folder, pid, out_dir.name)
    return removed


def _marker_host(folder: Path) -> str | None:
    """The host named in a work folder's ``INCOMPLETE`` marker, or None (no marker, or none named)."""
    try:
        text = (folder / INCOMPLETE_MARKER).read_text(errors="replace")
    except OSError:
        return None
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() == "host":
            return value.strip()
    return None


class SequenceWriter:
    """Streams frames of a simulated sequence to disk and commits it atomically.

    Use as a context manager; ``add`` writes each frame as it comes (memory stays
    flat), leaving the context without error renames the finished folder into
    place, an exception removes the partial folder. An existing ``out_dir`` is
    only replaced with ``force=True`` (and only once the new one is complete).
    """

    def __init__(self, out_dir: str | Path, sensor: LidarModel, info: dict, force: bool = False):
        self.out_dir = Path(out_dir)
        if self.out_dir.exists() and not force:
            raise DatasetError(f"{self.out_dir}: already exists (use --force to replace it)")
        self.sensor = sensor
        self.info = info
        self.force = force
        self.tmp = self.out_dir.parent / f".{self.out_dir.name}.partial-{os.getpid()}"
        self._poses: list[np.ndarray] = []
        self._times: list[float] = []
        self._checksums: dict[str, str] = {}
        self._degeneracy_rows: list[str] = []
        self._points = 0

    def __enter__(self) -> SequenceWriter:
        self.out_dir.parent.mkdir(parents=True, exist_ok=True)
        self.removed_stale = remove_stale_partials(self.out_dir)
        if self.tmp.exists():
            shutil.rmtree(self.tmp)
        (self.tmp / "velodyne").mkdir(parents=True)
        (self.tmp / "sidecar").mkdir()
        (self.tmp / INCOMPLETE_MARKER).write_text(
            f"a sequence is being written here\nhost: {socket.gethostname()}\npid: {os.getpid()}\n")
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self._commit()
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def add(self, scan, T_world_lidar: np.ndarray, time_s: float) -> None:
        """Write one frame: a ``simlidar.sweep.Scan`` and its reference pose and time."""
        k = len(self._poses)
        name = f"{k:06d}"
        bin_path = self.tmp / "velodyne" / f"{name}.bin"
        car_path = self.tmp / "sidecar" / f"{name}.npy"
        write_bin(bin_path, scan.xyz, scan.intensity)
        np.save(car_path, scan.sidecar(), allow_pickle=False)
        self._checksums[f"velodyne/{name}.bin"] = sha256_file(bin_path)
        self._checksums[f"sidecar/{name}.npy"] = sha256_file(car_path)
        self._poses.append(np.asarray(T_world_lidar, dtype=float))
        self._times.append(float(time_s))
        self._points += len(scan.xyz)
        self._degeneracy_rows.append(csv_row(k, degeneracy(scan.true_xyz, scan.normal)))

    def _commit(self) -> None:
        if not self._poses:
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise DatasetError(f"{self.out_dir}: no frames were written")
        poses_world = np.stack(self._poses)
        rel = se3.inverse(poses_world[0]) @ poses_world
        rel[0] = np.eye(4)
        texts = {
            "poses.txt": format_kitti_poses(rel),
            "times.txt": "".join(f"{t - self._times[0]:.9e}\n" for t in self._times),
            "sensor.yaml": self.sensor.to_yaml(),
            "degeneracy.csv": CSV_HEADER + "\n" + "".join(r + "\n" for r in self._degeneracy_rows),
        }
        for fname, text in texts.items():
            (self.tmp / fname).write_text(text)
            self._checksums[fname] = sha256_file(self.tmp / fname)
        manifest = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "package_version": __version__,
            "frames": len(self._poses),
            "points": self._points,
            "sensor": self.sensor.name,
            "T_world_first_lidar": [round(float(v), 12) for v in poses_world[0, :3, :4].ravel()],
            **self.info,
            "files": dict(sorted(self._checksums.items())),
        }
        (self.tmp / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
        (self.tmp / INCOMPLETE_MARKER).unlink()
        if self.out_dir.exists():
            trash = self.out_dir.parent / f".{self.out_dir.name}.old-{os.getpid()}"
            self.out_dir.rename(trash)
            self.tmp.rename(self.out_dir)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            self.tmp.rename(self.out_dir)


# ---------------------------------------------------------------- readers
@dataclass
class Frame:
    """One scan as read from disk.

    points: (N, 3) float64 metres, lidar frame. intensity: (N,) float32 or None.
    fields: per-point record (ring, time_s, true_xyz, ...) or None when the
        source has none (real KITTI). NaN / infinite points are kept here; the
        odometry drops and counts them.
    """

    index: int
    points: np.ndarray
    intensity: np.ndarray | None
    fields: np.ndarray | None
    path: Path

    def field(self, name: str) -> np.ndarray | None:
        if self.fields is None or self.fields.dtype.names is None:
            return None
        return self.fields[name] if name in self.fields.dtype.names else None

    @property
    def ring(self) -> np.ndarray | None:
        return self.field("ring")

    @property
    def time_s(self) -> np.ndarray | None:
        """Per-point time since the sweep start, s (None when the source has none)."""
        t = self.field("time_s")
        if t is None:
            t = self.field("time")  # common name in PLY / ROS clouds
        return t


class Sequence:
    """A readable sequence: ``len``, indexing and iteration give ``Frame`` objects.

    Attributes:
        path: the folder. kind: "salo", "kitti" or "scans".
        sensor: LidarModel or None. poses: (N, 4, 4) ``T_first_lidar`` or None.
        times: (N,) s or None. manifest: dict (simulated sequences) or {}.
    """

    def __init__(self, path: Path, kind: str, scan_files: list[Path], sensor, poses, times,
                 manifest: dict | None = None, sidecar_files: list[Path] | None = None):
        self.path = path
        self.kind = kind
        self.scan_files = scan_files
        self.sidecar_files = sidecar_files
        self.sensor = sensor
        self.poses = poses
        self.times = times
        self.manifest = manifest or {}

    def __len__(self) -> int:
        return len(self.scan_files)

    def __iter__(self) -> Iterator[Frame]:
        for k in range(len(self)):
            yield self[k]

    def __getitem__(self, k: int) -> Frame:
        if not -len(self) <= k < len(self):
            raise IndexError(f"{self.path}: frame {k} out of range (0..{len(self) - 1})")
        k = k % len(self)
        f = self.scan_files[k]
        if f.suffix == ".ply":
            pts, inten, record = read_ply_scan(f)
            return Frame(k, pts, inten, record, f)
        data = read_bin(f)
        fields = None
        if self.sidecar_files is not None:
            car = self.sidecar_files[k]
            try:
                fields = np.load(car, allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise DatasetError(f"{car}: cannot read sidecar ({exc})") from None
            if len(fields) != len(data):
                raise DatasetError(
                    f"{car}: {len(fields)} records but {f.name} has {len(data)} points"
                )
        return Frame(k, data[:, :3].astype(np.float64), data[:, 3].copy(), fields, f)

    def verify(self) -> None:
        """Check every file against the manifest's sha256 (simulated sequences only)."""
        for rel, digest in self.manifest.get("files", {}).items():
            p = self.path / rel
            if not p.is_file():
                raise DatasetError(f"{p}: listed in the manifest but missing")
            if sha256_file(p) != digest:
                raise DatasetError(f"{p}: checksum differs from the manifest (file changed?)")


def deskew_times(sequence, frame: Frame) -> np.ndarray | None:
    """A frame's per-point times since its sweep start, (N,) float64 s, or None for an undistorted scan.

    None when the frame has no times, when they are all equal (nothing to de-skew
    with), or when the sequence's manifest says it was simulated without motion
    distortion: those times are the firing times of an instantaneous scan, and
    de-skewing it with them would distort it. Every method (ours and the peers)
    decides this here.
    """
    manifest = getattr(sequence, "manifest", None) or {}
    if manifest.get("motion_distortion") is False:
        return None
    t = frame.time_s
    if t is None:
        return None
    t = np.asarray(t, dtype=np.float64)
    finite = t[np.isfinite(t)]
    if len(finite) == 0 or not finite.max() > finite.min():
        return None
    return t


def open_sequence(
    path: str | Path,
    sensor: str | Path | LidarModel | None = None,
    poses: str | Path | None = None,
    topic: str | None = None,
) -> Sequence:
    """Open a sequence folder of any supported kind (detected from its files).

    sensor: preset, file or model overriding the folder's own ``sensor.yaml``.
    poses: ground-truth pose file; for real KITTI, the camera-frame file
        (default ``<sequences>/../poses/NN.txt`` when present).
    topic: for a ROS 2 bag (a rosbag2 folder with ``metadata.yaml``, or an
        ``.mcap`` / ``.db3`` file), the PointCloud2 topic to read
        (``simlidar.bag.RosbagSequence``, which behaves like a ``Sequence``).
    """
    path = Path(path)
    from .bag import is_bag, open_bag  # bag.py imports rosbags only when a bag is opened

    if is_bag(path):

        return open_bag(path, load_sensor(sensor) if sensor is not None else None, poses, topic=topic)
    if not path.is_dir():
        raise DatasetError(f"{path}: not a folder")
    if (path / INCOMPLETE_MARKER).exists():
        raise DatasetError(f"{path}: an unfinished sequence (an interrupted write left it)")
    model = load_sensor(sensor) if sensor is not None else None
    if (path / "manifest.json").is_file():
        return _open_salo(path, model)
    if (path / "calib.txt").is_file() and (path / "velodyne").is_dir():
        return _open_kitti(path, model, poses)
    return _open_scans(path, model, poses)


def _scan_list(folder: Path, exts: tuple[str, ...]) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix in exts and not p.name.startswith("."))


def _check_bin_sizes(scans: list[Path]) -> None:
    """Refuse, when a sequence is opened, a ``.bin`` that is not whole 16-byte points (one stat each)."""
    for f in scans:
        if f.suffix == ".bin":
            check_bin_size(f, f.stat().st_size)


def _open_salo(path: Path, sensor: LidarModel | None) -> Sequence:
    try:
        manifest = json.loads((path / "manifest.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path / 'manifest.json'}: cannot read manifest ({exc})") from None
    if manifest.get("format") != FORMAT_NAME:
        raise DatasetError(f"{path / 'manifest.json'}: not a {FORMAT_NAME} manifest")
    n = int(manifest.get("frames", -1))
    scans = [path / "velodyne" / f"{k:06d}.bin" for k in range(n)]
    cars = [path / "sidecar" / f"{k:06d}.npy" for k in range(n)]
    missing = [p for p in scans + cars if not p.is_file()]
    if missing:
        raise DatasetError(f"{missing[0]}: missing, the manifest lists {n} frames")
    _check_bin_sizes(scans)
    poses = read_kitti_poses(path / "poses.txt")
    times = read_times(path / "times.txt")
    if len(poses) != n or len(times) != n:
        raise DatasetError(
            f"{path}: manifest says {n} frames, poses.txt has {len(poses)}, times.txt {len(times)}"
        )
    if sensor is None:
        sensor = load_sensor_file(path / "sensor.yaml")
    return Sequence(path, "salo", scans, sensor, poses, times, manifest, cars)


def _open_kitti(path: Path, sensor: LidarModel | None, poses_file) -> Sequence:
    scans = _scan_list(path / "velodyne", (".bin",))
    if not scans:
        raise DatasetError(f"{path / 'velodyne'}: no .bin scans")
    _check_bin_sizes(scans)
    times = read_times(path / "times.txt") if (path / "times.txt").is_file() else None
    poses = None
    if poses_file is None:
        guess = path.parent.parent / "poses" / f"{path.name}.txt"
        poses_file = guess if guess.is_file() else None
    if poses_file is not None:
        cam = read_kitti_poses(poses_file)
        Tr = read_kitti_calib_tr(path / "calib.txt")
        if len(cam) < len(scans):
            raise DatasetError(f"{poses_file}: {len(cam)} poses for {len(scans)} scans")
        poses = camera_poses_to_lidar(cam[: len(scans)], Tr)
    if sensor is None and (path / "sensor.yaml").is_file():
        sensor = load_sensor_file(path / "sensor.yaml")
    return Sequence(path, "kitti", scans, sensor, poses, times)


def _open_scans(path: Path, sensor: LidarModel | None, poses_file) -> Sequence:
    folder = path / "velodyne" if (path / "velodyne").is_dir() else path
    scans = _scan_list(folder, (".bin", ".ply"))
    if not scans:
        raise DatasetError(f"{path}: no .bin or .ply scans (and no manifest.json or calib.txt)")
    _check_bin_sizes(scans)
    if sensor is None:
        for name in ("sensor.yaml", "sensor.yml"):
            if (path / name).is_file():
                sensor = load_sensor_file(path / name)
                break
    poses = None
    pf = Path(poses_file) if poses_file is not None else path / "poses.txt"
    if pf.is_file():
        poses = read_kitti_poses(pf)
        if len(poses) < len(scans):
            raise DatasetError(f"{pf}: {len(poses)} poses for {len(scans)} scans")
        poses = se3.inverse(poses[0]) @ poses[: len(scans)]
    times = read_times(path / "times.txt") if (path / "times.txt").is_file() else None
    return Sequence(path, "scans", scans, sensor, poses, times)


__all__ = [
    "DatasetError",
    "Frame",
    "Sequence",
    "SequenceWriter",
    "SensorError",
    "open_sequence",
    "read_kitti_poses",
    "read_bin",
    "camera_poses_to_lidar",
]
