"""The simulator's sequence folder: the KITTI odometry layout plus per-point truth and a manifest.

The layout (``kind == "salo"``), format version 2 (3 when the truth carries optional blocks)::

    DIR/
      velodyne/000000.bin   float32 x y z intensity per point (KITTI odometry format)
      sidecar/000000.truth  the compact truth of every point of the .bin, same order: firing
                            index, true range, octahedral normal, object id, and the sensor's
                            motion during the sweep (``simlidar.formats.truth``: 14 bytes a return);
                            in weather (version 3) also each return's kind: surface, fog, rain, snow
      poses.txt             3x4 row-major T_first_lidar per frame (line 0 is identity)
      times.txt             sweep start time per frame, s (first is 0)
      sensor.yaml           the sensor model (simlidar.sensor keys)
      degeneracy.csv        per frame: eigenvalues of the point-to-plane information from the
                            returns' true normals (``simlidar.degeneracy``)
      imu.csv               with an IMU (``sensor.yaml``'s ``imu``): its samples, and
      imu_truth.csv         their truth (``simlidar.formats.imu_csv``)
      manifest.json         written last: parameters, versions, frame count, sha256 per file

Format version 1 (sequences written before) had ``sidecar/000000.npy`` instead: a
structured array of 50 bytes a return (``simlidar.formats.truth.SIDECAR_DTYPE``).
``open_salo`` reads all three, told apart by the manifest's ``format_version``; either
way a frame's ``fields`` are that version-1 record, rebuilt from the compact truth
for versions 2 and 3 (within the bounds ``simlidar.formats.truth`` states), with the
field ``weather`` when the truth has the weather block. Version 3 is written only
when some frame's truth has an optional block (a sensor with weather); without,
the folder is version 2, byte for byte as before.

``SequenceWriter`` builds it in a ``simlidar.formats.atomic.StagedFolder`` (a
hidden sibling holding an ``INCOMPLETE`` marker, renamed into place only when
every file and the manifest are on disk), each frame encoded and written by a
background thread while the caller simulates the next (a queue of two frames
bounds the memory), each file in one write, its sha256 taken from the bytes in
memory; ``open_salo`` reads it back.
"""

from __future__ import annotations

import functools
import json
import queue
import threading
from pathlib import Path

import numpy as np

from .. import __version__, se3
from ..degeneracy import CSV_HEADER, csv_row, degeneracy
from ..kernels.files import pack_points
from ..sensor import LidarModel, load_sensor_file
from ..sequence import DatasetError
from . import tracks, truth
from .atomic import StagedFolder, sha256_file, write_checksummed
from .imu_csv import IMU_FILE, IMU_TRUTH_FILE, format_imu_csv, format_imu_truth_csv, read_imu_csv, read_imu_truth_csv
from .kitti import format_kitti_poses, format_times, read_kitti_poses, read_times
from .scan_folders import Sequence, check_bin_sizes

FORMAT_NAME = "salo-sequence"
FORMAT_VERSION = 2
FORMAT_VERSIONS = (1, 2, 3)  # what the reader reads
# Written instead of 2 when some frame's truth has an optional block (``simlidar.formats.truth``).
FORMAT_VERSION_BLOCKS = 3
SIDECAR_SUFFIX = {1: ".npy", 2: ".truth", 3: ".truth"}
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

    Use as a context manager; ``add`` hands each frame to a background writer
    thread (at most ``queue_frames`` frames wait, so memory stays flat) and
    returns; leaving the context without error waits for the writer and renames
    the finished folder into place, an exception (in the caller or the writer)
    removes the partial folder. An existing ``out_dir`` is only replaced with
    ``force=True`` (and only once the new one is complete).

    n_objects: the world's object count, which sets the width of the object ids
    (1, 2 or 4 bytes; None: 4). format_version: 2 (compact truth, the default) or
    1 (the old ``.npy`` sidecar, kept to test the reader of old sequences).
    compress_truth: zlib the truth files (a third of the size, 45 ms more a salo32 frame).
    imu: the sequence's IMU samples and their truth (``simlidar.imu.simulate_imu``), written at the end.
    """

    def __init__(self, out_dir: str | Path, sensor: LidarModel, info: dict, force: bool = False,
                 n_objects: int | None = None, format_version: int = FORMAT_VERSION, queue_frames: int = 2,
                 compress_truth: bool = False, imu=None):
        if format_version not in FORMAT_VERSIONS:
            raise ValueError(f"format_version must be one of {FORMAT_VERSIONS}, got {format_version}")
        self.out_dir = Path(out_dir)
        self._stage = StagedFolder(self.out_dir, force)  # refuses an existing folder now
        self.tmp = self._stage.path
        self.sensor = sensor
        self.info = info
        self.format_version = format_version
        self.compress_truth = bool(compress_truth)
        self.imu = imu
        self.id_bytes = 4 if n_objects is None else truth.object_id_bytes(n_objects)
        self._poses: list[np.ndarray] = []
        self._times: list[float] = []
        self._checksums: dict[str, str] = {}
        self._degeneracy_rows: dict[int, str] = {}
        self._points = 0
        self._blocks = False  # some frame's truth has an optional block: the folder is version 3
        self._scratch: dict = {}  # the writer thread's buffers, reused frame after frame
        self._tracks: dict[int, str] = {}  # per frame, the moving objects' rows of tracks.csv
        self._bytes = {"velodyne": 0, "sidecar": 0}
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, queue_frames))
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def __enter__(self) -> SequenceWriter:
        self._stage.__enter__()
        (self.tmp / "velodyne").mkdir()
        (self.tmp / "sidecar").mkdir()
        self._thread = threading.Thread(target=self._work, name=f"write {self.out_dir.name}", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self._stop()
            if exc_type is None:
                if self._error is not None:
                    raise self._error
                self._commit()
        finally:
            self._stage.__exit__(exc_type, exc, tb)  # removes the work folder unless committed

    def add(self, scan, T_world_lidar: np.ndarray, time_s: float) -> None:
        """Queue one frame for writing: a ``simlidar.sweep.Scan`` (not changed afterwards) and its reference
        pose and time. Raises the writer thread's error, if it had one."""
        if self._error is not None:
            raise self._error
        if self._thread is None:
            raise RuntimeError("SequenceWriter.add outside its with-block")
        k = len(self._poses)
        self._poses.append(np.asarray(T_world_lidar, dtype=float))
        self._times.append(float(time_s))
        self._points += len(scan.xyz)
        self._queue.put((k, scan))

    @property
    def bytes_written(self) -> dict[str, int]:
        """Bytes of the frames' files so far: ``velodyne`` (scans) and ``sidecar`` (truth)."""
        return dict(self._bytes)

    # -------------------------------------------------------- the writer thread
    def _stop(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is None:  # after an error, keep taking frames so that add() never blocks
                try:
                    self._write_frame(*item)
                except BaseException as exc:  # handed to the caller's thread by add() / __exit__
                    self._error = exc

    def _write_frame(self, k: int, scan) -> None:
        name = f"{k:06d}"
        # the frame's bytes are built in buffers kept from frame to frame: no new memory to touch each frame
        points = self._scratch.get("points")
        if points is None or len(points) < len(scan.xyz):
            points = self._scratch["points"] = np.empty((int(1.25 * len(scan.xyz)) + 1, 4), dtype="<f4")
        points = points[:len(scan.xyz)]
        pack_points(np.asarray(scan.xyz, np.float64), np.asarray(scan.intensity, np.float32), points)
        if self.format_version == 1:
            import io

            buf = io.BytesIO()
            np.save(buf, scan.sidecar(), allow_pickle=False)
            car = buf.getvalue()
        else:
            knots = None if scan.motion is None else truth.motion_knots(scan.motion)
            ray = np.asarray(scan.azimuth_index, dtype=np.int64) * self.sensor.rings + scan.ring
            weather = getattr(scan, "weather", None)
            actors = None if getattr(scan, "object_class", None) is None else (scan.object_class, scan.moving,
                                                                                scan.velocity)
            car = truth.encode(ray, scan.true_range_m, scan.normal, scan.object_id, knots, self.id_bytes,
                               compress=self.compress_truth, weather=weather, actors=actors, scratch=self._scratch)
            self._blocks |= weather is not None or actors is not None
        if getattr(scan, "tracks", None) is not None:
            self._tracks[k] = tracks.format_rows(k, scan.tracks)
        for rel, data in ((f"velodyne/{name}.bin", memoryview(points).cast("B")),
                          (f"sidecar/{name}{SIDECAR_SUFFIX[self.format_version]}", car)):
            self._checksums[rel] = write_checksummed(self.tmp / rel, data)
            self._bytes[rel.split("/")[0]] += len(data)
        surface = getattr(scan, "surface_returns", slice(None))  # the world's figures: returns off a surface
        self._degeneracy_rows[k] = csv_row(k, degeneracy(scan.true_xyz[surface], scan.normal[surface]))

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
            "degeneracy.csv": CSV_HEADER + "\n" + "".join(self._degeneracy_rows[k] + "\n"
                                                          for k in sorted(self._degeneracy_rows)),
        }
        if self._tracks:
            texts[tracks.FILE] = tracks.HEADER + "\n" + "".join(self._tracks[k] for k in sorted(self._tracks))
        imu_info = {}
        if self.imu is not None:
            samples, imu_truth = self.imu
            texts[IMU_FILE] = format_imu_csv(samples)
            texts[IMU_TRUTH_FILE] = format_imu_truth_csv(imu_truth)
            imu_info = {"imu": {"samples": len(samples), "frame_id": samples.frame_id,
                                "gravity_first_m_s2": [round(float(g), 12) for g in imu_truth.gravity]}}
        for fname, text in texts.items():
            (self.tmp / fname).write_text(text)
            self._checksums[fname] = sha256_file(self.tmp / fname)
        manifest = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION_BLOCKS if self._blocks else self.format_version,
            "package_version": __version__,
            "frames": len(self._poses),
            "points": self._points,
            "sensor": self.sensor.name,
            "T_world_first_lidar": [round(float(v), 12) for v in poses_world[0, :3, :4].ravel()],
            **self.info,
            **imu_info,
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
    version = manifest.get("format_version")
    if version not in FORMAT_VERSIONS:
        raise DatasetError(f"{path / 'manifest.json'}: format_version {version!r} is not one this version reads "
                           f"({', '.join(map(str, FORMAT_VERSIONS))}; written by a newer salo-bench?)")
    n = int(manifest.get("frames", -1))
    scans = [path / "velodyne" / f"{k:06d}.bin" for k in range(n)]
    cars = [path / "sidecar" / f"{k:06d}{SIDECAR_SUFFIX[version]}" for k in range(n)]
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
    own = load_sensor_file(path / "sensor.yaml")  # the firing table the truth was written with
    reader = None
    if version in (2, 3):
        def reader(car: Path, xyz: np.ndarray, with_truth: bool = True) -> np.ndarray:
            try:
                data = car.read_bytes()
            except OSError as exc:
                raise DatasetError(f"{car}: cannot read truth ({exc.strerror})") from None
            return truth.decode(data, xyz, own, where=car, truth=with_truth)
    imu = imu_truth = None
    if "imu" in manifest:
        for f in (IMU_FILE, IMU_TRUTH_FILE):
            if not (path / f).is_file():
                raise DatasetError(f"{path / f}: missing, the manifest lists an IMU")
        frame_id = str(manifest["imu"].get("frame_id", "imu"))
        gravity = manifest["imu"].get("gravity_first_m_s2")
        imu = functools.partial(read_imu_csv, path / IMU_FILE, frame_id)  # read when asked for
        imu_truth = functools.partial(read_imu_truth_csv, path / IMU_TRUTH_FILE, gravity)
    return Sequence(path, "salo", scans, sensor or own, gt, times, manifest, cars, read_sidecar=reader, imu=imu,
                    imu_truth=imu_truth)


__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "FORMAT_VERSIONS", "FORMAT_VERSION_BLOCKS", "SIDECAR_FIELDS",
           "SequenceWriter", "is_salo", "open_salo"]
