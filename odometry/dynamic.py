"""The moving-object stage: returns where recent scans saw through are kept out of the registration and the map.

A static surface is never found where the lidar has just seen through. Each registered scan
leaves its free space behind as a range image (``FreeSpaceImage``: a row per ring, a column per
azimuth step of the sensor, each cell the nearest return's range; then the least over a small
window of cells around it). A new scan's point, placed in the world with the predicted pose, is
looked up in each of the recent images, moved into that scan's sensor frame at the firing time
of the column it falls in: if every return around its direction reached beyond it by more than
``dynamic.free_margin_m``, the lidar saw through that place then, and something has moved into it
since. Such points are dropped from the registration's source and from what the scan adds to the
map (``moving_points``, ``drop_rows``), so a car crossing in front neither pulls the estimate nor
leaves a trail of itself in the map for the next car to be matched against.

Conservative by construction: the window takes the nearest return around a direction (a thin
pole or an edge between two cells is not seen through; the returns of one ring fall into the
sensor's azimuth columns unevenly, so a cell may hold none while its neighbours hold two), a
window without any return (sky, glass, beyond the range limit) is unknown, a point outside the
rings' span is not judged. An object that
stops is judged static again once the images that saw its place free have left the history
(``dynamic.history_frames``). What it cannot see: a thing that moved along its own surface (a
lorry's side moving along itself leaves no free space where the side is now), or a place no recent
scan saw (it came out from behind something); both stay in.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import minimum_filter1d

from simlidar import se3
from simlidar.sensor import LidarModel

from .config import DynamicParams
from .deskew import screw_apply
from .filters import FilteredScan
from .kernels.free_space import nearest_per_cell, seen_through


@dataclass
class FreeSpaceImage:
    """One registered scan's free space: how far its beams reached around each direction.

    nearest_m: (R, C) per ring and azimuth column the least range of the returns within the
        window around that cell, m (0: no cell of the window had a return, unknown).
    column_time_fraction: (C,) each column's mean firing time over the frame period (0 without times).
    T_world_start: (4, 4) the scan's pose at its sweep's start. xi: (6,) its frame's motion as a twist
        (the sensor at fraction s of the sweep sits at ``T_world_start @ exp(s xi)``).
    """

    nearest_m: np.ndarray
    column_time_fraction: np.ndarray
    T_world_start: np.ndarray
    xi: np.ndarray


def checked_lags(history_frames: int) -> tuple[int, ...]:
    """The scans a point is checked against, in frames back: 1, 2, 4, 8, ... below ``history_frames``, and it.

    Recent scans catch fast things; only older ones saw free the place of a slow one, or of the middle of a
    long one (a bus's side stays where its side was a second ago); doubling the lag keeps the checks few."""
    lags, lag = [], 1
    while lag < history_frames:
        lags.append(lag)
        lag *= 2
    return (*lags, history_frames)


class FreeSpace:
    """The free space of the last ``history_frames`` registered scans, and the test of a new scan's points.

    Args:
        params: the ``dynamic`` section of the config.
        sensor: the lidar model: its ring elevations (rows) and azimuth step (columns).
    """

    def __init__(self, params: DynamicParams, sensor: LidarModel):
        self.params = params
        self.elevation_rad = np.sort(np.asarray(sensor.elevation_rad, dtype=np.float64))
        self.rows = len(self.elevation_rad)
        self.columns = int(sensor.columns_per_sweep)
        self.ring_mid_rad = 0.5 * (self.elevation_rad[1:] + self.elevation_rad[:-1])
        # A point beyond the outer rings by more than half the outer pitch is on no ring's cone
        pitch = np.diff(self.elevation_rad)
        half_end = 0.5 * (pitch[[0, -1]] if len(pitch) else np.array([0.01, 0.01]))
        self.elevation_span_rad = (float(self.elevation_rad[0] - half_end[0]),
                                   float(self.elevation_rad[-1] + half_end[1]))
        self.images: deque[FreeSpaceImage] = deque(maxlen=params.history_frames)
        self.lags = checked_lags(params.history_frames)

    def add(self, points: np.ndarray, times_s: np.ndarray | None, period_s: float, T_world_start: np.ndarray,
            motion: np.ndarray) -> None:
        """Keep a registered scan's free space.

        points: (N, 3) its clean returns as measured (each in the sensor frame at its firing time), m;
        times_s: (N,) their times since the sweep start, s, or None (the scan is de-skewed already);
        T_world_start: (4, 4) its pose; motion: (4, 4) its frame's motion ``T_prev_cur``.
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        low, high = self.elevation_span_rad
        with_times = times_s is not None and len(points) > 0 and period_s > 0
        times = np.ascontiguousarray(times_s, dtype=np.float64) / period_s if with_times else np.zeros(0)
        nearest, time_sums, time_counts = nearest_per_cell(points, times, self.ring_mid_rad, low, high, self.columns)
        # (a cell without a return says nothing: the window's returns decide; none at all: unknown, 0)
        p = self.params
        nearest = minimum_filter1d(nearest, 2 * p.window_rows + 1, axis=0, mode="nearest")
        nearest = minimum_filter1d(nearest, 2 * p.window_columns + 1, axis=1, mode="wrap")
        nearest[np.isinf(nearest)] = 0.0
        fraction = np.zeros(self.columns)
        seen = time_counts > 0
        if with_times and seen.any():  # (a column without returns takes its nearest neighbours' time)
            at = np.flatnonzero(seen)
            fraction = np.interp(np.arange(self.columns), at, time_sums[at] / time_counts[at], period=self.columns)
        self.images.append(FreeSpaceImage(nearest, fraction, np.asarray(T_world_start, float), se3.log(motion)))

    def seen_free(self, points_world: np.ndarray) -> np.ndarray:
        """(N,) how many of the checked images (``checked_lags``; the oldest kept while fewer are kept) saw
        through each (N, 3) world point by more than the margin."""
        points_world = np.ascontiguousarray(points_world, dtype=np.float64)
        count = np.zeros(len(points_world), dtype=np.int64)
        low, high = self.elevation_span_rad
        for lag in sorted({min(lag, len(self.images)) for lag in self.lags}):
            image = self.images[-lag]
            T = se3.inverse(image.T_world_start)
            seen_through(points_world, np.ascontiguousarray(T[:3, :3]), T[:3, 3].copy(), image.xi,
                         image.column_time_fraction, image.nearest_m, self.ring_mid_rad, low, high,
                         self.params.free_margin_m, count)
        return count

    def moving_points(self, points_world: np.ndarray) -> np.ndarray:
        """(N,) bool: the (N, 3) world points at places a checked scan saw through."""
        if len(self.images) == 0 or len(points_world) == 0:
            return np.zeros(len(points_world), dtype=bool)
        return self.seen_free(points_world) > 0


def sensor_frame_points(scan_points: np.ndarray, times_s: np.ndarray | None, period_s: float,
                        T_world_start: np.ndarray, motion: np.ndarray, measured: bool) -> np.ndarray:
    """(N, 3) a scan's points in the world: ``T_world_start @ exp(s xi) @ p`` for points as measured (s: each
    point's time over the period, xi the frame's motion), ``T_world_start @ p`` for points de-skewed already."""
    p = np.asarray(scan_points, dtype=np.float64)
    if measured and times_s is not None and period_s > 0:
        p = screw_apply(se3.log(motion), np.asarray(times_s, dtype=np.float64) / period_s, p)
    return se3.transform_points(T_world_start, p)


def drop_rows(scan: FilteredScan, keep_points: np.ndarray, keep_centroids: np.ndarray) -> None:
    """Keep only the rows ``keep_points`` (M,) bool of a filtered scan's ICP points (and their normals, rings,
    times, normal sigmas) and ``keep_centroids`` (V,) bool of its centroids, in place. Where the ICP points are
    the centroids themselves (a map variant's scan) they stay one array."""
    same = scan.points is scan.centroids
    rows = np.flatnonzero(keep_points)
    scan.points = scan.points.take(rows, axis=0)
    scan.normals = scan.normals.take(rows, axis=0)
    scan.normal_std_rad = scan.normal_std_rad.take(rows)
    if scan.rings is not None:
        scan.rings = scan.rings.take(rows)
    times_are_centroids = scan.times_s is scan.centroid_times_s
    if scan.times_s is not None:
        scan.times_s = scan.times_s.take(rows)
    if same:
        scan.centroids = scan.points
        if times_are_centroids:
            scan.centroid_times_s = scan.times_s
        return
    rows = np.flatnonzero(keep_centroids)
    scan.centroids = scan.centroids.take(rows, axis=0)
    if scan.centroid_times_s is not None:
        scan.centroid_times_s = scan.centroid_times_s.take(rows)


__all__ = ["FreeSpace", "FreeSpaceImage", "checked_lags", "drop_rows", "sensor_frame_points"]
