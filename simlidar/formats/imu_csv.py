"""An IMU's samples and their truth as CSV files (``imu.csv``, ``imu_truth.csv`` of a sequence folder).

``imu.csv``: a header line, then one line per sample in time order, comma-separated,
every number ``%.12e``::

    time_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2

time: the sample's stamp, s, in the sequence's time base (``times.txt``'s); gyro: angular
rate, accel: specific force, both in the IMU frame (``simlidar.imu``).

``imu_truth.csv``: the same lines' truth (``simlidar.imu.ImuTruth``), same order::

    time_s,true_time_s,gyro_x_rad_s,...,accel_z_m_s2,gyro_bias_x_rad_s,...,accel_bias_z_m_s2,
    position_x_m,position_y_m,position_z_m,orientation_qx,orientation_qy,orientation_qz,orientation_qw,
    velocity_x_m_s,velocity_y_m_s,velocity_z_m_s

``docs/sequence-format.md`` is the specification. Readers check the header and the
column count and name the file and line of anything else.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..imu import ImuSamples, ImuTruth
from ..sequence import DatasetError

IMU_FILE = "imu.csv"
IMU_TRUTH_FILE = "imu_truth.csv"

_XYZ = ("x", "y", "z")
SAMPLE_COLUMNS = ("time_s", *(f"gyro_{a}_rad_s" for a in _XYZ), *(f"accel_{a}_m_s2" for a in _XYZ))
TRUTH_COLUMNS = (
    "time_s", "true_time_s",
    *(f"gyro_{a}_rad_s" for a in _XYZ), *(f"accel_{a}_m_s2" for a in _XYZ),
    *(f"gyro_bias_{a}_rad_s" for a in _XYZ), *(f"accel_bias_{a}_m_s2" for a in _XYZ),
    *(f"position_{a}_m" for a in _XYZ), *(f"orientation_q{a}" for a in (*_XYZ, "w")),
    *(f"velocity_{a}_m_s" for a in _XYZ),
)


def _format(columns: tuple[str, ...], table: np.ndarray) -> str:
    buf = io.StringIO()
    buf.write(",".join(columns) + "\n")
    np.savetxt(buf, table, fmt="%.12e", delimiter=",")
    return buf.getvalue()


def format_imu_csv(samples: ImuSamples) -> str:
    """``imu.csv``'s text."""
    return _format(SAMPLE_COLUMNS, np.column_stack([samples.time_s, samples.angular_velocity,
                                                    samples.specific_force]))


def format_imu_truth_csv(truth: ImuTruth) -> str:
    """``imu_truth.csv``'s text."""
    return _format(TRUTH_COLUMNS, np.column_stack([
        truth.time_s, truth.true_time_s, truth.angular_velocity, truth.specific_force, truth.gyroscope_bias,
        truth.accelerometer_bias, truth.position, truth.orientation, truth.velocity]))


def _read(path: Path, columns: tuple[str, ...], what: str) -> np.ndarray:
    try:
        text = path.read_text()
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read {what} ({exc.strerror})") from None
    lines = text.splitlines()
    if not lines or lines[0].strip() != ",".join(columns):
        raise DatasetError(f"{path}: the first line must be the header {','.join(columns)}")
    if len(lines) < 2:
        raise DatasetError(f"{path}: no samples")
    try:
        table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        raise DatasetError(f"{path}: {_bad_line(lines, len(columns))} ({exc})") from None
    if table.shape[1] != len(columns):
        raise DatasetError(f"{path}: {len(columns)} columns expected, found {table.shape[1]}")
    if not np.all(np.isfinite(table)):
        raise DatasetError(f"{path}: non-finite numbers")
    if np.any(np.diff(table[:, 0]) <= 0):
        k = int(np.flatnonzero(np.diff(table[:, 0]) <= 0)[0]) + 3
        raise DatasetError(f"{path}:{k}: time_s does not increase")
    return table


def _bad_line(lines: list[str], count: int) -> str:
    for k, line in enumerate(lines[1:], 2):
        parts = line.split(",")
        if len(parts) != count:
            return f"line {k} has {len(parts)} values, not {count}"
        try:
            [float(p) for p in parts]
        except ValueError:
            return f"line {k} holds something that is not a number"
    return "cannot parse the numbers"


def read_imu_csv(path: str | Path, frame_id: str = "imu") -> ImuSamples:
    """``imu.csv`` -> ``ImuSamples``; DatasetError naming the file (and line) when malformed."""
    t = _read(Path(path), SAMPLE_COLUMNS, "IMU samples")
    return ImuSamples(t[:, 0].copy(), t[:, 1:4].copy(), t[:, 4:7].copy(), frame_id)


def read_imu_truth_csv(path: str | Path, gravity: np.ndarray) -> ImuTruth:
    """``imu_truth.csv`` -> ``ImuTruth`` (gravity: (3,) in the first scan's frame, m/s^2, from the manifest)."""
    t = _read(Path(path), TRUTH_COLUMNS, "IMU truth")
    cols = [t[:, 0], t[:, 1], *(t[:, i:i + 3] for i in (2, 5, 8, 11, 14)), t[:, 17:21], t[:, 21:24]]
    return ImuTruth(*(np.ascontiguousarray(c) for c in cols), np.asarray(gravity, dtype=float))


__all__ = ["IMU_FILE", "IMU_TRUTH_FILE", "SAMPLE_COLUMNS", "TRUTH_COLUMNS", "format_imu_csv",
           "format_imu_truth_csv", "read_imu_csv", "read_imu_truth_csv"]
