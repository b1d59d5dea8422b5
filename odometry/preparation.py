"""The registration's first stage, which reads no state: clean a scan and filter it as measured.

clean     drop non-finite points and points outside the range limits (KITTI's angle fix); with
          ``clean.drop_isolated``, returns alone in the air leave the surfaces (``odometry.isolation``;
          only on a scan in weather by the poles' clutter statistic, ``clean.isolated_only_in_weather``)
filter    voxel grid -> kNN normals in the raw scan -> NCF -> curvature (``odometry.filters``)
poles     narrow objects clear of their background (``odometry.poles``; the map variants)

A scan is filtered as measured, and its ICP points, normals and centroids are de-skewed
afterwards (``odometry.pipeline``), each with its voxel's mean firing time: a voxel's and a
normal's neighbours fire within microseconds of each other (except at the sweep's seam), so
they move rigidly, and the beams the NCF's noise follows start at the sensor's origin only in
the measured frame. Far fewer points to move. Since nothing here reads the odometry's state,
the next scans are prepared on threads of their own while one registers
(``odometry.pipeline.register_frames``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from simlidar.sensor import LidarModel

from .config import OdometryConfig
from .diagnostics import FrameDiagnostics
from .filters import FilteredScan, filter_scan
from .gcr import correct_kitti_vertical_angle, ring_of_points
from .isolation import isolated_returns
from .poles import cluttered, extract_poles


@dataclass
class CleanScan:
    """A scan with the unusable points removed (``clean_scan``).

    points: (N, 3) finite points within the range limits, sensor frame, m.
    times_s: (N,) per-point time since the sweep start, s, or None.
    rings: (N,) int ring per point, or None.
    kept_rows: (N,) the rows of the input they came from.
    """

    points: np.ndarray
    times_s: np.ndarray | None
    rings: np.ndarray | None
    kept_rows: np.ndarray


def clean_scan(points: np.ndarray, times_s: np.ndarray | None, rings: np.ndarray | None, config: OdometryConfig,
               diag: FrameDiagnostics | None = None) -> CleanScan:
    """Drop non-finite points and those outside ``[min_range_m, max_range_m]``; KITTI's vertical-angle fix.

    points: (N, 3) as measured, m; times_s, rings: (N,) or None. Counts go into ``diag``.
    """
    points = np.asarray(points, dtype=np.float64)
    # (per column and np.compress: np.all(axis=1) and boolean row indexing of an (N, 3) array
    # are several times slower, and this runs on every raw point)
    finite_xyz = np.isfinite(points)
    finite = finite_xyz[:, 0] & finite_xyz[:, 1] & finite_xyz[:, 2]
    safe = points if finite.all() else np.where(finite[:, None], points, 0.0)
    r = np.sqrt(np.einsum("ij,ij->i", safe, safe))
    keep = finite & (r >= config.clean.min_range_m) & (r <= config.clean.max_range_m)
    out = CleanScan(np.compress(keep, points, axis=0),
                    None if times_s is None else np.asarray(times_s, dtype=np.float64)[keep],
                    None if rings is None else np.asarray(rings)[keep], np.flatnonzero(keep))
    if config.clean.kitti_vertical_correction_deg:
        out.points = correct_kitti_vertical_angle(out.points, config.clean.kitti_vertical_correction_deg)
    if diag is not None:
        diag.points_raw, diag.points_nonfinite = len(points), int((~finite).sum())
        diag.points_in_range = len(out.points)
    return out


@dataclass
class PreparedScan:
    """A scan cleaned and filtered as measured (``prepare_scan``), before any state is used.

    clean: its clean points. scan: its ICP points as measured (de-skewed in place when registered).
    deskewing: per-point times are known and the de-skew is on. diag, seconds: the frame's
    diagnostics and stage times so far. seconds_spent: the time its preparation took, s (counted in
    the frame's total). registered: the odometry has taken it (a scan is registered once).
    moving: (V,) bool per voxel centroid as prepared (``scan.centroids`` before the stage drops any): the
    moving-object stage's verdict (``odometry.dynamic``), None when the stage did not judge it.
    """

    clean: CleanScan
    scan: FilteredScan
    deskewing: bool
    diag: FrameDiagnostics
    seconds: dict
    seconds_spent: float
    registered: bool = False
    moving: np.ndarray | None = None


def prepare_scan(points: np.ndarray, times_s: np.ndarray | None, rings: np.ndarray | None, config: OdometryConfig,
                 sensor: LidarModel | None, with_normals: bool, with_poles: bool) -> PreparedScan:
    """Clean and filter a scan as measured.

    points: (N, 3) m; times_s, rings: (N,) or None. with_normals: the scan's own normals are
    computed (``filters.scan_normals_needed``, or a map variant's first scan, a cold-start
    target). with_poles: its poles are extracted (needs the sensor's range image).
    """
    t_start = time.perf_counter()
    diag = FrameDiagnostics(frame=-1)
    clean = clean_scan(points, times_s, rings, config, diag)
    deskewing = config.deskew.enabled and clean.times_s is not None
    rings_needed = config.gcr.enabled or config.filter.adjacent_ring_reach_m is not None
    if clean.rings is None and rings_needed and with_normals and sensor is not None:
        clean.rings = ring_of_points(clean.points, sensor)
    times = clean.times_s if deskewing else None
    # (the range image's rows, inferred once for the isolation and the poles when the scan has no ring field)
    image_rings = clean.rings
    if image_rings is None and sensor is not None and (with_poles or config.clean.drop_isolated):
        image_rings = ring_of_points(clean.points, sensor)
    # (the isolation in weather only waits for the poles' clutter statistic; they are found in the whole scan)
    gated = config.clean.drop_isolated and config.clean.isolated_only_in_weather and sensor is not None
    poles, poles_seconds = None, 0.0
    if with_poles or gated:
        t = time.perf_counter()
        poles = extract_poles(clean.points, image_rings, sensor.rings, sensor.columns_per_sweep,
                              config.poles.max_width_m, times, clutter_filter=config.poles.clutter_filter or gated,
                              clutter_reach=config.poles.clutter_reach)
        poles_seconds = time.perf_counter() - t
    surface, surface_times, surface_rings, isolated = clean.points, times, clean.rings, 0
    if config.clean.drop_isolated and (not gated or cluttered(poles.clutter_per_beam)):
        c = config.clean
        # (without a sensor, no range image: every return judged by its nearest beams in direction)
        n_rings, n_columns = (sensor.rings, sensor.columns_per_sweep) if sensor is not None else (0, 0)
        alone = isolated_returns(clean.points, image_rings, n_rings, n_columns, c.isolation_columns,
                                 c.isolation_neighbours, c.isolation_min_m, c.isolation_fraction)
        isolated = int(alone.sum())
        if isolated:
            kept = ~alone
            surface = np.compress(kept, clean.points, axis=0)
            surface_times = None if times is None else times[kept]
            surface_rings = None if clean.rings is None else clean.rings[kept]
    scan = filter_scan(surface, config, surface_rings, sensor, raw_times_s=surface_times, with_normals=with_normals)
    if config.clean.drop_isolated:
        scan.counts["isolated"] = isolated
    if with_poles:
        scan.poles = poles
        scan.counts["poles"] = len(scan.poles)
        scan.seconds["poles"] = poles_seconds
    diag.filter_counts = scan.counts
    return PreparedScan(clean, scan, deskewing, diag, dict(scan.seconds), time.perf_counter() - t_start)
