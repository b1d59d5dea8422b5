"""What a method under test is handed: what a real sensor gives, and never the ground truth.

A simulated sequence folder holds the truth beside the scans (``poses.txt``, the
sidecar's true points and normals, ``degeneracy.csv``, the manifest). A method
run by ``salo regress`` or ``salo bench`` gets a *staged* copy instead, a folder
of its own outside the sequence's::

    STAGE/input/                 {sequence}
      velodyne/NNNNNN.bin        {scans}: float32 x y z intensity, as measured (copies)
      times.txt                  {times}: sweep start per frame, s
      sensor.yaml                {sensor}: the sensor model (without its weather: a real sensor does not report it)
      fields/NNNNNN.npy          per-point fields the run opts into (``SENSOR_FIELDS``), one array per scan
      imu.csv                    the IMU's samples, when the sequence has an IMU (not their truth)
    STAGE/output/poses.txt       {out}: where the method writes its KITTI poses
    STAGE/work/                  where a method's process runs (its working folder), empty at the start

Every file there is a copy of its own: no symbolic link (it would name the
sequence's folder) and no hard link (another name of the same file, which
``find -samefile`` finds beside ``poses.txt``), so nothing leads from what a
method is handed to the truth. ``staged`` makes STAGE a fresh folder of the
system's temporary folder, outside the run's output tree, removed after the run:
``cp {sequence}/poses.txt {out}`` finds nothing to copy, and walking up from
any path handed over finds no sequence folder. The per-point fields are what a lidar driver
reports: ``ring``, ``time_s`` (s since the sweep start), ``azimuth_index``,
``range_m``; the truth fields (``TRUTH_FIELDS``) are refused. A sequence simulated
without motion distortion gets no ``time_s``: its scans are instantaneous, as a
motion-compensated real scan is, and times would invite a de-skew that distorts them.

``open_sequence(staged.root)`` reads the folder back (the ``scans`` reader, with
its ``fields/``), so in-process methods read exactly what a command does. A
sequence simulated into memory is handed to an in-process method as
``sensor_view``: the same frames, fields and sensor, with the truth left out,
so nothing is written to disk for it.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simlidar.sequence import DatasetError, method_frame

# Per-point fields a lidar driver reports (the simulator's sidecar names).
SENSOR_FIELDS = ("ring", "time_s", "azimuth_index", "range_m")
# The default: what the Velodyne driver's XYZIRT cloud carries besides x y z intensity.
DEFAULT_FIELDS = ("ring", "time_s")
# The simulator's truth: never handed to a method.
TRUTH_FIELDS = ("true_range_m", "true_xyz", "normal", "object_id", "weather", "object_class", "moving", "velocity")


class StagingError(DatasetError):
    """The input of a method cannot be staged (a truth field asked for, an unknown field, no sensor)."""


def parse_fields(text: str | None) -> tuple[str, ...]:
    """``--fields ring,time_s`` (or ``none``) -> the field names; StagingError naming a bad one."""
    if text is None:
        return DEFAULT_FIELDS
    names = tuple(dict.fromkeys(t.strip() for t in text.split(",") if t.strip()))
    if names in ((), ("none",)):
        return ()
    return check_fields(names, "--fields")


def check_fields(names, origin: str = "fields") -> tuple[str, ...]:
    """The field names, checked: sensor fields only (a truth field is refused with why)."""
    names = tuple(names)
    for name in names:
        if name in TRUTH_FIELDS:
            raise StagingError(f"{origin}: {name!r} is the simulator's ground truth, which a method under test "
                               f"never sees (sensor fields: {', '.join(SENSOR_FIELDS)})")
        if name not in SENSOR_FIELDS:
            raise StagingError(f"{origin}: unknown per-point field {name!r} (sensor fields: "
                               f"{', '.join(SENSOR_FIELDS)}, or none)")
    return names


@dataclass(frozen=True)
class StagedInput:
    """A staged input (see the module notes).

    root: the input folder ({sequence}). out: the poses file the method writes ({out}).
    fields: the per-point fields staged (possibly none). frames: scans staged.
    """

    root: Path
    out: Path
    fields: tuple[str, ...]
    frames: int

    @property
    def workdir(self) -> Path:
        """The folder a method's process runs in (empty when staged)."""
        return self.root.parent / "work"

    @property
    def scans(self) -> Path:
        return self.root / "velodyne"

    @property
    def sensor(self) -> Path:
        return self.root / "sensor.yaml"

    @property
    def times(self) -> Path:
        return self.root / "times.txt"

    def placeholders(self) -> dict[str, Path]:
        """What an external command's placeholders stand for."""
        return {"sequence": self.root, "scans": self.scans, "sensor": self.sensor, "times": self.times,
                "fields": self.root / "fields", "out": self.out}


def _place(src: Path, dst: Path) -> None:
    """A copy of its own (never a link: a hard link is another name of the sequence's file, one
    ``find -samefile`` leads back to the folder holding the truth)."""
    shutil.copyfile(src, dst)


def stage_input(sequence, folder: str | Path, fields=DEFAULT_FIELDS) -> StagedInput:
    """Write the sensor's view of ``sequence`` (an opened sequence) into ``folder``/input (see the module notes).

    fields: per-point fields to hand over (``check_fields``); those the sequence lacks
    are left out, and so is ``time_s`` of a sequence simulated without motion distortion.
    Raises StagingError when the sequence has no sensor model.
    """
    from simlidar.formats.kitti import format_times, write_bin
    from simlidar.sequence import sweep_start_times

    fields = _fields_to_hand_over(sequence, fields)
    folder = Path(folder)
    root, out_dir = folder / "input", folder / "output"
    (root / "velodyne").mkdir(parents=True)
    out_dir.mkdir()
    (folder / "work").mkdir()
    scan_files = getattr(sequence, "scan_files", None)
    staged_fields: set[str] = set()
    for k in range(len(sequence)):
        name = f"{k:06d}"
        src = scan_files[k] if scan_files is not None else None
        frame = method_frame(sequence, k) if fields or src is None or src.suffix != ".bin" else None
        if frame is None:
            _place(src, root / "velodyne" / f"{name}.bin")
        else:
            intensity = frame.intensity if frame.intensity is not None else np.zeros(len(frame.points), np.float32)
            if src is not None and src.suffix == ".bin":
                _place(src, root / "velodyne" / f"{name}.bin")
            else:
                write_bin(root / "velodyne" / f"{name}.bin", frame.points, intensity)
            record = _sensor_record(frame.fields, fields)
            if record is not None:
                (root / "fields").mkdir(exist_ok=True)
                np.save(root / "fields" / f"{name}.npy", record, allow_pickle=False)
                staged_fields.update(record.dtype.names)
    sensor_file = Path(sequence.path) / "sensor.yaml"
    if sensor_file.is_file() and not sequence.sensor.weather.on:
        shutil.copyfile(sensor_file, root / "sensor.yaml")
    else:
        (root / "sensor.yaml").write_text(sequence.sensor.clear_air().to_yaml())
    (root / "times.txt").write_text(format_times(sweep_start_times(sequence)))
    imu = getattr(sequence, "imu", None)
    if imu is not None:
        from simlidar.formats.imu_csv import IMU_FILE, format_imu_csv

        (root / IMU_FILE).write_text(format_imu_csv(imu))
    return StagedInput(root, out_dir / "poses.txt", tuple(f for f in fields if f in staged_fields), len(sequence))


def sensor_view(sequence, fields=DEFAULT_FIELDS):
    """What ``stage_input`` would hand over, kept in memory: an in-memory sequence
    (``simlidar.in_memory.InMemorySequence``) without poses, truth figures, the IMU's truth or manifest,
    its per-point fields cut to ``fields`` (less ``time_s`` without motion distortion),
    its sensor without the weather.

    Raises StagingError when the sequence has no sensor model.
    """
    from dataclasses import replace

    fields = _fields_to_hand_over(sequence, fields)
    return replace(sequence, fields=[_sensor_record(r, fields) for r in sequence.fields], poses=None,
                   degeneracy=[], manifest={}, imu_truth=None, sensor=sequence.sensor.clear_air())


def _fields_to_hand_over(sequence, fields) -> tuple[str, ...]:
    """The checked ``fields``, less ``time_s`` for a sequence simulated without motion distortion;
    StagingError when the sequence has no sensor model."""
    fields = check_fields(fields)
    if sequence.sensor is None:
        raise StagingError(f"{sequence.path}: no sensor model to hand to the method (give the sequence a "
                           "sensor.yaml)")
    if (getattr(sequence, "manifest", None) or {}).get("motion_distortion") is False:
        fields = tuple(f for f in fields if f != "time_s")
    return fields


def _sensor_record(record: np.ndarray | None, fields: tuple[str, ...]) -> np.ndarray | None:
    """A frame's (N,) per-point record cut to ``fields`` (those it has, a packed copy), or None when it
    has none of them."""
    from numpy.lib.recfunctions import repack_fields

    names = () if record is None else record.dtype.names or ()
    have = [f for f in fields if f in names]
    return repack_fields(record[have]) if have else None


@contextmanager
def staged(sequence, fields=DEFAULT_FIELDS, parent: str | Path | None = None) -> Iterator[StagedInput]:
    """``stage_input`` into a fresh temporary folder (under ``parent``, default the system's: outside any run's
    output folder), removed after."""
    folder = Path(tempfile.mkdtemp(prefix="salo-input-", dir=parent))
    try:
        yield stage_input(sequence, folder, fields)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


__all__ = ["DEFAULT_FIELDS", "SENSOR_FIELDS", "TRUTH_FIELDS", "StagedInput", "StagingError", "check_fields",
           "parse_fields", "sensor_view", "stage_input", "staged"]
