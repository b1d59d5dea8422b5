"""The KITTI odometry benchmark's files: poses, times, the calibration's ``Tr`` and ``.bin`` scans.

- poses: one pose per line, 12 numbers, the 3x4 upper part of the 4x4 row-major;
- times: one number per line, s;
- ``calib.txt``: the ``Tr:`` line is velodyne -> cam0 (3x4 row-major);
- ``velodyne/NNNNNN.bin``: float32 x y z intensity per point, little-endian.

The reader of a whole KITTI sequence folder is ``simlidar.formats.scan_folders.open_kitti_folder``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .. import se3
from ..sequence import DatasetError
from .atomic import atomic_write_text
from .number_lines import read_number_lines

BIN_POINT_BYTES = 16  # float32 x y z intensity


# ---------------------------------------------------------------- poses and times
def read_kitti_poses(path: str | Path) -> np.ndarray:
    """Read a KITTI pose file (12 numbers per line) -> (N, 4, 4)."""
    path = Path(path)
    rows = read_number_lines(path, 12, "a KITTI pose line needs 12 numbers (3x4 row-major)", "pose file")
    poses = se3.kitti_lines_to_poses(rows)
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


def write_kitti_poses(path: str | Path, poses: np.ndarray) -> None:
    """Write (N, 4, 4) poses as a KITTI pose file, atomically."""
    atomic_write_text(path, format_kitti_poses(poses))


def read_times(path: str | Path) -> np.ndarray:
    """A times file (one number per line, s) -> (N,) float64."""
    path = Path(path)
    try:
        values = [float(x) for x in path.read_text().split()]
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read times file ({exc.strerror})") from None
    except ValueError:
        raise DatasetError(f"{path}: times file holds something that is not a number") from None
    return np.array(values)


def format_times(times_s: np.ndarray) -> str:
    """(N,) times, s -> times file text relative to the first (``%.9e`` per line)."""
    return "".join(f"{t - times_s[0]:.9e}\n" for t in times_s)


# ---------------------------------------------------------------- calibration
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


# ---------------------------------------------------------------- .bin scans
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
    """(N, 3) points, m, and (N,) intensity -> a KITTI ``.bin`` (float32 x y z intensity)."""
    data = np.empty((len(xyz), 4), dtype="<f4")
    data[:, :3] = xyz
    data[:, 3] = intensity
    data.tofile(path)


__all__ = ["BIN_POINT_BYTES", "camera_poses_to_lidar", "check_bin_size", "format_kitti_poses", "format_times",
           "read_bin", "read_kitti_calib_tr", "read_kitti_poses", "read_times", "write_bin", "write_kitti_poses"]
