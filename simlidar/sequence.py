"""What every sequence reader returns: frames, the error readers raise, frame times.

A *sequence* is anything with ``len``, indexing and iteration giving ``Frame``
objects, and the attributes ``path``, ``kind``, ``sensor`` (``LidarModel`` or
None), ``poses`` ((N, 4, 4) ``T_first_lidar`` or None), ``times`` ((N,) sweep
starts, s, or None) and ``manifest`` (dict, {} when there is none); optionally
``imu`` (``simlidar.imu.ImuSamples`` in the same time base as ``times``, or None)
and ``imu_truth`` (``simlidar.imu.ImuTruth``, simulated sequences; read them with
``getattr(sequence, "imu", None)``). The readers
of ``simlidar.formats`` (opened through ``simlidar.dataset.open_sequence``) and
``simlidar.in_memory`` all give one; the odometry reads nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .sensor import LidarModel

# The frame period when neither time stamps nor a sensor give one (10 Hz, the common spin rate), s.
DEFAULT_FRAME_PERIOD_S = 0.1


class DatasetError(ValueError):
    """A sequence or scan file cannot be read or written; the message names the file."""


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


def method_frame(sequence, k: int) -> Frame:
    """Frame ``k`` as a method under test reads it: points, intensity and the firing fields (ring, time),
    without the simulator's per-return truth where a sequence can leave it unread (``frame(k, truth=False)``;
    decoding it cost a simulated frame about a hundred times its scan's read)."""
    frame = getattr(sequence, "frame", None)
    return frame(k, truth=False) if frame is not None else sequence[k]


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


def frame_period_s(sensor: LidarModel | None) -> float:
    """One sweep of ``sensor``, s, or ``DEFAULT_FRAME_PERIOD_S`` when the sensor is unknown."""
    return sensor.sweep_period_s if sensor is not None else DEFAULT_FRAME_PERIOD_S


def frame_times(n: int, sensor: LidarModel | None) -> np.ndarray:
    """(n,) sweep start times one frame period apart from 0, s (for sources without time stamps)."""
    return np.arange(n) * frame_period_s(sensor)


def sweep_start_times(sequence) -> np.ndarray:
    """(N,) sweep start times of a sequence, s: its own, else one frame period apart (``frame_times``)."""
    if sequence.times is not None and len(sequence.times) >= len(sequence):
        return np.asarray(sequence.times, dtype=float)[: len(sequence)]
    return frame_times(len(sequence), sequence.sensor)


__all__ = ["DEFAULT_FRAME_PERIOD_S", "DatasetError", "Frame", "deskew_times", "frame_period_s", "frame_times",
           "method_frame", "sweep_start_times"]
