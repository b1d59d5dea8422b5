"""Sequences read from folders of scan files: the ``Sequence`` type, real KITTI, plain scan folders.

``Sequence`` reads its frames lazily, one ``.bin`` (KITTI) or ``.ply`` file per
frame, with an optional ``.npy`` sidecar of per-point fields each. Its readers:

- ``open_kitti_folder``: a KITTI odometry sequence (``velodyne/*.bin`` beside
  ``calib.txt``), ground truth from the camera-frame poses file converted to
  the lidar frame with ``calib.txt``'s ``Tr``, the sensor KITTI's HDL-64E unless told otherwise;
- ``open_pcd_folder``: a folder of ``.pcd`` scans (``salo export --format pcd``);
- ``open_scan_folder``: a folder of ``.bin`` / ``.ply`` scans (or its
  ``velodyne/``), with ``sensor.yaml``, ``poses.txt``, ``times.txt``, per-point
  fields (``fields/NNNNNN.npy``, a structured array per scan: ``ring``, ``time_s``,
  ...) and an IMU's ``imu.csv`` (``simlidar.formats.imu_csv``) when present.

The simulator's own folder layout is ``simlidar.formats.salo``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from .. import se3
from ..sensor import LidarModel, load_sensor, load_sensor_file
from ..sequence import DatasetError, Frame
from .atomic import sha256_file
from .imu_csv import IMU_FILE, read_imu_csv
from .kitti import camera_poses_to_lidar, check_bin_size, read_bin, read_kitti_calib_tr, read_kitti_poses, read_times
from .pcd import read_pcd
from .ply import read_ply_scan


class Sequence:
    """A readable sequence: ``len``, indexing and iteration give ``Frame`` objects.

    Attributes:
        path: the folder. kind: "salo", "kitti", "pcd" or "scans".
        scan_files: one ``.bin`` or ``.ply`` per frame. sidecar_files: one per frame, or None: ``.npy``
            structured arrays, or whatever ``read_sidecar(file, xyz, with_truth)`` turns into one (given
            the frame's (N, 3) float32 points; the simulator's compact truth, its truth read or not).
        sensor: LidarModel or None. poses: (N, 4, 4) ``T_first_lidar`` or None.
        times: (N,) s or None. manifest: dict (simulated sequences) or {}.
        imu: ``simlidar.imu.ImuSamples`` or None; imu_truth: ``simlidar.imu.ImuTruth`` or None (simulated
            sequences). Either may be given as a function that reads it, called when first asked for.
    """

    def __init__(self, path: Path, kind: str, scan_files: list[Path], sensor, poses, times,
                 manifest: dict | None = None, sidecar_files: list[Path] | None = None,
                 read_sidecar: Callable[[Path, np.ndarray, bool], np.ndarray] | None = None,
                 imu=None, imu_truth=None):
        self.path = path
        self.kind = kind
        self.scan_files = scan_files
        self.sidecar_files = sidecar_files
        self.sensor = sensor
        self.poses = poses
        self.times = times
        self.manifest = manifest or {}
        self.read_sidecar = read_sidecar
        self._imu = {"imu": imu, "imu_truth": imu_truth}

    def _loaded(self, key: str):
        value = self._imu[key]
        if callable(value):
            value = self._imu[key] = value()
        return value

    @property
    def imu(self):
        """The IMU's samples (``simlidar.imu.ImuSamples``), or None."""
        return self._loaded("imu")

    @property
    def imu_truth(self):
        """The IMU samples' truth (``simlidar.imu.ImuTruth``), or None."""
        return self._loaded("imu_truth")

    def __len__(self) -> int:
        return len(self.scan_files)

    def __iter__(self) -> Iterator[Frame]:
        for k in range(len(self)):
            yield self[k]

    def __getitem__(self, k: int) -> Frame:
        return self.frame(k)

    def frame(self, k: int, truth: bool = True) -> Frame:
        """Frame ``k``; truth=False: a simulated sequence's per-return truth is left unread (its fields are
        the firing ones, ``simlidar.formats.truth.FIRING_DTYPE``: what a method may read)."""
        if not -len(self) <= k < len(self):
            raise IndexError(f"{self.path}: frame {k} out of range (0..{len(self) - 1})")
        k = k % len(self)
        f = self.scan_files[k]
        if f.suffix == ".ply":
            pts, inten, record = read_ply_scan(f)
            return Frame(k, pts, inten, record, f)
        if f.suffix == ".pcd":
            return _pcd_frame(k, f)
        data = read_bin(f)
        fields = None
        if self.sidecar_files is not None:
            car = self.sidecar_files[k]
            if self.read_sidecar is not None:
                fields = self.read_sidecar(car, data[:, :3], truth)
            else:
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


def _pcd_frame(k: int, path: Path) -> Frame:
    """A PCD scan as a frame: x y z (required), intensity, and every field as its record (``ring``, ``time``)."""
    record = read_pcd(path)
    names = record.dtype.names or ()
    if not all(n in names for n in "xyz"):
        raise DatasetError(f"{path}: a PCD scan needs fields x, y and z (it has {', '.join(names)})")
    points = np.column_stack([record[n] for n in "xyz"]).astype(np.float64)
    intensity = np.asarray(record["intensity"], dtype=np.float32) if "intensity" in names else None
    return Frame(k, points, intensity, record, path)


def check_bin_sizes(scans: list[Path]) -> None:
    """Refuse, when a sequence is opened, a ``.bin`` that is not whole 16-byte points (one stat each)."""
    for f in scans:
        if f.suffix == ".bin":
            check_bin_size(f, f.stat().st_size)


def _scan_list(folder: Path, exts: tuple[str, ...]) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix in exts and not p.name.startswith("."))


# ---------------------------------------------------------------- real KITTI
def is_kitti_folder(path: Path) -> bool:
    """A KITTI odometry sequence folder: ``calib.txt`` beside ``velodyne/``."""
    return path.is_dir() and (path / "calib.txt").is_file() and (path / "velodyne").is_dir()


# The sensor of the KITTI odometry benchmark (a preset of simlidar/presets).
KITTI_SENSOR = "hdl64e"


def open_kitti_folder(path: Path, sensor: LidarModel | None = None, poses: str | Path | None = None,
                      topic: str | None = None) -> Sequence:
    """A KITTI odometry sequence. poses: the camera-frame ground truth (default
    ``<sequences>/../poses/NN.txt`` when present). sensor: default the folder's ``sensor.yaml``,
    else ``KITTI_SENSOR`` (KITTI's HDL-64E). topic: does not apply."""
    scans = _scan_list(path / "velodyne", (".bin",))
    if not scans:
        raise DatasetError(f"{path / 'velodyne'}: no .bin scans")
    check_bin_sizes(scans)
    times = read_times(path / "times.txt") if (path / "times.txt").is_file() else None
    lidar_poses = None
    if poses is None:
        guess = path.parent.parent / "poses" / f"{path.name}.txt"
        poses = guess if guess.is_file() else None
    if poses is not None:
        cam = read_kitti_poses(poses)
        Tr = read_kitti_calib_tr(path / "calib.txt")
        if len(cam) < len(scans):
            raise DatasetError(f"{poses}: {len(cam)} poses for {len(scans)} scans")
        lidar_poses = camera_poses_to_lidar(cam[: len(scans)], Tr)
    if sensor is None:
        # KITTI's own sensor unless the folder says otherwise: the GCR and the NCF need the ring table
        sensor = load_sensor_file(path / "sensor.yaml") if (path / "sensor.yaml").is_file() else load_sensor(
            KITTI_SENSOR)
    return Sequence(path, "kitti", scans, sensor, lidar_poses, times)


# ---------------------------------------------------------------- plain scan folders
FIELDS_FOLDER = "fields"


def _scan_folder(path: Path) -> Path:
    return path / "velodyne" if (path / "velodyne").is_dir() else path


def is_pcd_folder(path: Path) -> bool:
    """A folder (or its ``velodyne/``) of ``.pcd`` scans and no ``.bin`` / ``.ply`` ones (``salo export``'s)."""
    if not path.is_dir() or not _scan_folder(path).is_dir():
        return False
    names = {p.suffix for p in _scan_folder(path).iterdir() if not p.name.startswith(".")}
    return ".pcd" in names and not names & {".bin", ".ply"}


def open_pcd_folder(path: Path, sensor: LidarModel | None = None, poses: str | Path | None = None,
                    topic: str | None = None) -> Sequence:
    """A folder of PCD scans (binary or ASCII v0.7; fields x y z, and intensity, ring, time when there), with
    ``sensor.yaml``, ``poses.txt`` and ``times.txt`` when present, as ``salo export --format pcd`` writes it."""
    return _open_folder(path, (".pcd",), "pcd", sensor, poses)


def open_scan_folder(path: Path, sensor: LidarModel | None = None, poses: str | Path | None = None,
                     topic: str | None = None) -> Sequence:
    """A folder of ``.bin`` / ``.ply`` scans. poses: a KITTI pose file (default ``poses.txt`` in the
    folder), made relative to its first pose. topic: does not apply.

    Per-point fields of ``.bin`` scans: ``fields/<scan stem>.npy`` beside ``velodyne/`` (or
    the scans), one structured array per scan with one record per point (``ring``,
    ``time_s``, ...; ``Frame.field``); all scans must have one, or none."""
    return _open_folder(path, (".bin", ".ply"), "scans", sensor, poses)


def _open_folder(path: Path, exts: tuple[str, ...], kind: str, sensor: LidarModel | None,
                 poses: str | Path | None) -> Sequence:
    scans = _scan_list(_scan_folder(path), exts)
    if not scans:
        raise DatasetError(f"{path}: no {' or '.join(exts)} scans (and no manifest.json or calib.txt)")
    check_bin_sizes(scans)
    if sensor is None:
        for name in ("sensor.yaml", "sensor.yml"):
            if (path / name).is_file():
                sensor = load_sensor_file(path / name)
                break
    rel_poses = None
    pf = Path(poses) if poses is not None else path / "poses.txt"
    if pf.is_file():
        rel_poses = read_kitti_poses(pf)
        if len(rel_poses) < len(scans):
            raise DatasetError(f"{pf}: {len(rel_poses)} poses for {len(scans)} scans")
        rel_poses = se3.inverse(rel_poses[0]) @ rel_poses[: len(scans)]
    times = read_times(path / "times.txt") if (path / "times.txt").is_file() else None
    fields = _field_files(path, scans) if kind == "scans" else None
    imu = functools.partial(read_imu_csv, path / IMU_FILE) if (path / IMU_FILE).is_file() else None
    return Sequence(path, kind, scans, sensor, rel_poses, times, sidecar_files=fields, imu=imu)


def _field_files(path: Path, scans: list[Path]) -> list[Path] | None:
    """``fields/<stem>.npy`` of every ``.bin`` scan, or None when the folder has no ``fields/``."""
    folder = path / FIELDS_FOLDER
    if not folder.is_dir():
        return None
    files = [folder / f"{s.stem}.npy" for s in scans]
    missing = [f for f, s in zip(files, scans, strict=True) if s.suffix != ".bin" or not f.is_file()]
    if missing:
        raise DatasetError(f"{missing[0]}: missing; {folder} must hold one .npy of per-point fields per .bin scan")
    return files


__all__ = ["FIELDS_FOLDER", "KITTI_SENSOR", "Sequence", "check_bin_sizes", "is_kitti_folder", "is_pcd_folder",
           "open_kitti_folder", "open_pcd_folder", "open_scan_folder"]
