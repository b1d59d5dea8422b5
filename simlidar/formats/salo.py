"""The simulator's sequence folder: the KITTI odometry layout plus per-point truth and a manifest.

The layout (``kind == "salo"``)::

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

``SequenceWriter`` builds it in a ``simlidar.formats.atomic.StagedFolder`` (a
hidden sibling holding an ``INCOMPLETE`` marker, renamed into place only when
every file and the manifest are on disk); ``open_salo`` reads it back.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import __version__, se3
from ..degeneracy import CSV_HEADER, csv_row, degeneracy
from ..sensor import LidarModel, load_sensor_file
from ..sequence import DatasetError
from .atomic import StagedFolder, sha256_file
from .kitti import format_kitti_poses, format_times, read_kitti_poses, read_times, write_bin
from .scan_folders import Sequence, check_bin_sizes

FORMAT_NAME = "salo-sequence"
FORMAT_VERSION = 1
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


# ---------------------------------------------------------------- writer
class SequenceWriter:
    """Streams frames of a simulated sequence to disk and commits it atomically.

    Use as a context manager; ``add`` writes each frame as it comes (memory stays
    flat), leaving the context without error renames the finished folder into
    place, an exception removes the partial folder. An existing ``out_dir`` is
    only replaced with ``force=True`` (and only once the new one is complete).
    """

    def __init__(self, out_dir: str | Path, sensor: LidarModel, info: dict, force: bool = False):
        self.out_dir = Path(out_dir)
        self._stage = StagedFolder(self.out_dir, force)  # refuses an existing folder now
        self.tmp = self._stage.path
        self.sensor = sensor
        self.info = info
        self._poses: list[np.ndarray] = []
        self._times: list[float] = []
        self._checksums: dict[str, str] = {}
        self._degeneracy_rows: list[str] = []
        self._points = 0

    def __enter__(self) -> SequenceWriter:
        self._stage.__enter__()
        (self.tmp / "velodyne").mkdir()
        (self.tmp / "sidecar").mkdir()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                self._commit()
        finally:
            self._stage.__exit__(exc_type, exc, tb)

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
            raise DatasetError(f"{self.out_dir}: no frames were written")
        poses_world = np.stack(self._poses)
        rel = se3.inverse(poses_world[0]) @ poses_world
        rel[0] = np.eye(4)
        texts = {
            "poses.txt": format_kitti_poses(rel),
            "times.txt": format_times(self._times),
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
        self._stage.commit()


# ---------------------------------------------------------------- reader
def is_salo(path: Path) -> bool:
    """A folder with a ``manifest.json`` (the simulator's layout)."""
    return path.is_dir() and (path / "manifest.json").is_file()


def open_salo(path: Path, sensor: LidarModel | None = None, poses: str | Path | None = None,
              topic: str | None = None) -> Sequence:
    """A simulated sequence folder. sensor: overrides its ``sensor.yaml``. poses, topic: do not
    apply (the folder holds its own ground truth)."""
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
    check_bin_sizes(scans)
    gt = read_kitti_poses(path / "poses.txt")
    times = read_times(path / "times.txt")
    if len(gt) != n or len(times) != n:
        raise DatasetError(
            f"{path}: manifest says {n} frames, poses.txt has {len(gt)}, times.txt {len(times)}"
        )
    if sensor is None:
        sensor = load_sensor_file(path / "sensor.yaml")
    return Sequence(path, "salo", scans, sensor, gt, times, manifest, cars)


__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "SIDECAR_FIELDS", "SequenceWriter", "is_salo", "open_salo"]
