"""Scan-to-scan odometry over a sequence: the variants BL, NCF and SALO of the paper's table.

``Odometry.register`` reads as the paper's steps::

    clean      drop non-finite points and points outside the range limits
    de-skew    undo motion distortion with the constant-velocity motion (times known)
    filter     voxel grid -> kNN normals in the raw scan -> NCF -> curvature
    init       linear extrapolation: the last relative motion
    align      ICP: match in the previous scan, reject, point-to-plane, until converged
    update     pose_i = pose_{i-1} T_{i-1,i}; remember the motion and this scan
"""

from __future__ import annotations

import csv
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from simlidar import se3
from simlidar.dataset import Frame, Sequence, atomic_write_text, format_kitti_poses
from simlidar.sensor import LidarModel

from .config import OdometryConfig
from .deskew import deskew, redeskew
from .filters import FilteredScan, filter_scan
from .gcr import correct_kitti_vertical_angle, gcr_threshold_m, ring_of_points
from .icp import RegistrationResult, Source, Target, register, rejectors_for

log = logging.getLogger(__name__)


class OdometryError(ValueError):
    """The odometry cannot run on this input; the message says how to fix it."""


@dataclass
class FrameDiagnostics:
    """What happened to one frame (one row of the diagnostics CSV).

    ``iterations`` and the ICP stage ``seconds`` add up every registration of the
    frame (the first and the de-skew refinements); matches, convergence, residual
    and eigenvalues are those of the last.
    """

    frame: int
    points_raw: int = 0
    points_nonfinite: int = 0
    points_in_range: int = 0
    filter_counts: dict = field(default_factory=dict)
    matches: dict = field(default_factory=dict)
    iterations: int = 0
    converged: bool = False
    rms_m: float = float("nan")
    info_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    translation_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    degenerate: bool = False
    singular: bool = False
    too_few_points: bool = False
    implausible: bool = False
    deskewed: bool = False
    seconds: dict = field(default_factory=dict)

    @property
    def extrapolated(self) -> bool:
        """The pose is the constant-velocity guess, not an ICP result."""
        return self.frame > 0 and (self.singular or self.too_few_points or self.implausible)


CSV_COLUMNS = (
    ["frame", "points_raw", "points_nonfinite", "points_in_range", "voxels", "after_ncf", "after_curvature",
     "candidates", "after_distance", "after_gcr", "after_trimmed", "iterations", "converged", "rms_m"]
    + [f"eig{k}" for k in range(6)] + ["t_eig0", "t_eig1", "t_eig2"]
    + ["degenerate", "singular", "too_few_points", "implausible", "extrapolated", "deskewed"]
    + ["s_deskew", "s_voxel", "s_normals", "s_ncf_curvature", "s_match", "s_reject", "s_estimate", "s_total"]
)


def diagnostics_row(d: FrameDiagnostics) -> list:
    fc, m, s = d.filter_counts, d.matches, d.seconds
    return (
        [d.frame, d.points_raw, d.points_nonfinite, d.points_in_range, fc.get("voxels", ""), fc.get("ncf", ""),
         fc.get("curvature", ""), m.get("candidates", ""), m.get("distance", ""), m.get("gcr", ""),
         m.get("trimmed", ""), d.iterations, int(d.converged), f"{d.rms_m:.6g}"]
        + [f"{v:.6g}" for v in d.info_eigenvalues] + [f"{v:.6g}" for v in d.translation_eigenvalues]
        + [int(d.degenerate), int(d.singular), int(d.too_few_points), int(d.implausible), int(d.extrapolated),
           int(d.deskewed)]
        + [f"{s.get(k, 0.0):.6f}" for k in ("deskew", "voxel", "normals", "ncf_curvature", "match", "reject",
                                           "estimate", "total")]
    )


class Odometry:
    """Scan-to-scan ICP odometry (Alg. 1) with the paper's filters and rejectors.

    Args:
        config: the variant's parameters (``odometry.config``).
        sensor: the lidar model; needed by the GCR (ring pitches, azimuth step),
            and by the sensor-aware NCF for its range noise unless the config sets it.

    ``register`` returns the pose ``T_first_lidar`` (4, 4) of each scan in the
    first scan's frame; ``last`` holds the latest ``FrameDiagnostics``.
    """

    def __init__(self, config: OdometryConfig, sensor: LidarModel | None = None):
        if config.gcr and sensor is None:
            raise OdometryError(
                f"variant '{config.name}' uses the geometric correspondence rejector, which needs the "
                "sensor's ring table: pass --sensor PRESET|FILE (or use a sequence folder with sensor.yaml)"
            )
        self.config = config
        self.sensor = sensor
        self.poses: list[np.ndarray] = []
        self.diagnostics: list[FrameDiagnostics] = []
        self._previous: FilteredScan | None = None
        self._target: Target | None = None
        self._motion = np.eye(4)  # last T_{i-1, i}: the constant-velocity guess
        self._last_stamp: float | None = None
        self._last_period: float | None = None
        self._use_gcr = False
        # The rejection chains, built once: with GCR, and without (the first registration)
        self._chain_with_gcr = rejectors_for(config)
        self._chain_without_gcr = rejectors_for(config.replace(gcr=False))
        self._previous_motion = np.eye(4)  # the motion the stored target was de-skewed with
        self._target_pose = np.eye(4)  # pose of the target scan (T_first_lidar) and its frame index
        self._target_frame = 0

    @property
    def last(self) -> FrameDiagnostics | None:
        return self.diagnostics[-1] if self.diagnostics else None

    def register_frame(self, frame: Frame, stamp_s: float | None = None) -> np.ndarray:
        """``register`` with a ``simlidar.dataset.Frame`` (uses its ring and time fields)."""
        return self.register(frame.points, times_s=frame.time_s, rings=frame.ring, stamp_s=stamp_s)

    def register(
        self,
        points: np.ndarray,
        times_s: np.ndarray | None = None,
        rings: np.ndarray | None = None,
        stamp_s: float | None = None,
    ) -> np.ndarray:
        """Register the next scan and return its pose ``T_first_lidar`` (4, 4).

        points: (N, 3) as measured, m. times_s: (N,) per-point time since the sweep
        start, s (enables de-skew). rings: (N,) int ring per point (else from the
        elevation and the sensor table). stamp_s: the sweep's start time, s.
        """
        cfg = self.config
        t_start = time.perf_counter()
        diag = FrameDiagnostics(frame=len(self.poses), points_raw=len(points))
        seconds: dict[str, float] = {}

        # clean
        points = np.asarray(points, dtype=np.float64)
        finite = np.all(np.isfinite(points), axis=1)
        diag.points_nonfinite = int((~finite).sum())
        safe = np.where(finite[:, None], points, 0.0)
        r = np.sqrt(np.einsum("ij,ij->i", safe, safe))
        keep = finite & (r >= cfg.min_range_m) & (r <= cfg.max_range_m)
        points = points[keep]
        times_s = None if times_s is None else np.asarray(times_s, dtype=np.float64)[keep]
        rings = None if rings is None else np.asarray(rings)[keep]
        diag.points_in_range = len(points)
        if cfg.kitti_vertical_correction_deg:
            points = correct_kitti_vertical_angle(points, cfg.kitti_vertical_correction_deg)

        # de-skew with the constant-velocity motion over this frame's period
        period = self._frame_period(stamp_s)
        T_guess = self._motion_over(period)
        t = time.perf_counter()
        deskewing = cfg.deskew and times_s is not None
        if deskewing:
            points = deskew(points, times_s, T_guess, period)
            diag.deskewed = True
        seconds["deskew"] = time.perf_counter() - t

        # filter
        if rings is None and cfg.gcr:
            rings = ring_of_points(points, self.sensor)
        scan = filter_scan(points, cfg, rings, self.sensor.range_noise_std_m if self.sensor else None,
                           raw_times_s=times_s if deskewing else None)
        diag.filter_counts = scan.counts
        seconds.update(scan.seconds)
        diag.too_few_points = len(scan) < cfg.min_points

        # init + align
        T_deskew = T_guess  # the motion the scan is currently de-skewed with
        if not self.poses:
            T = np.eye(4)
        elif diag.too_few_points or self._target is None:
            T = T_guess
        else:
            # GCR bounds matches by the sensor's sampling spacing (cm to dm), so it needs a
            # close initial guess; the first registration has no motion to extrapolate and
            # starts from identity, so it runs without GCR.
            self._use_gcr = cfg.gcr and len(self.poses) > 1
            # The target is the last scan that had points: usually the previous frame, else
            # older; poses go through it (T_target_source) and back to a per-frame motion.
            to_frame = (np.eye(4) if self._target_frame == len(self.poses) - 1  # previous frame <- target
                        else np.linalg.inv(self.poses[-1]) @ self._target_pose)
            T_init = se3.inverse(to_frame) @ T_guess
            source = self._source(scan)
            result = register(source, self._target, T_init, cfg, self._rejectors())
            icp_seconds, icp_iterations = dict(result.seconds), result.iterations
            # The de-skew used the previous frame's motion. The estimate responds to the
            # de-skew motion with a gain near -1 (a too-fast de-skew makes the scan look
            # closer), so plain re-use of the estimate oscillates: move the de-skew motion
            # halfway towards the estimate (a damped fixed-point iteration) and refine.
            # Only the filtered points are moved, so this is cheap.
            first = len(self.poses) == 1
            for _ in range(cfg.deskew_refinements if deskewing else 0):
                if result.singular:
                    break
                motion = to_frame @ result.T_target_source  # this frame's estimated motion
                if first and self._previous.times_s is not None and cfg.match_target == "filtered":
                    # Cold start: the first two scans were de-skewed as if standing still. Both
                    # are re-de-skewed with the estimate, so source and target stay consistent
                    # and the estimate can be taken as it is.
                    M = motion
                    prev = self._previous
                    prev.points, prev.normals = redeskew(prev.points, prev.normals, prev.times_s,
                                                         self._previous_motion, M, period)
                    self._previous_motion = M
                    self._target = self._make_target(prev)
                else:
                    M = se3.exp(0.5 * (se3.log(T_deskew) + se3.log(motion)))
                scan.points, scan.normals = redeskew(scan.points, scan.normals, scan.times_s, T_deskew, M, period)
                T_deskew = M
                # The GCR thresholds scale with range and incidence, which a re-de-skew by a
                # few centimetres does not change: they are reused.
                source = Source(scan.points, scan.normals, source.gcr_threshold_m)
                refined = register(source, self._target, result.T_target_source, cfg, self._rejectors())
                for stage, spent in refined.seconds.items():  # stage times and iterations cover every registration
                    icp_seconds[stage] += spent
                icp_iterations += refined.iterations
                if refined.singular:  # keep the last good estimate: the frame is not extrapolated
                    break
                result = refined
            self._record(diag, result)
            diag.iterations = icp_iterations
            seconds.update(icp_seconds)
            T = to_frame @ result.T_target_source
            # A car cannot change its motion by metres within one frame: such an estimate is
            # a failed registration (degenerate scene, wrong local minimum), not motion.
            deviation = se3.inverse(T_guess) @ T
            if not first and (np.linalg.norm(deviation[:3, 3]) > cfg.max_prediction_error_m
                              or np.degrees(se3.rotation_angle(deviation)) > cfg.max_prediction_error_deg):
                diag.implausible = True
                T = T_guess

        # update; the next target is this scan de-skewed with the motion just estimated,
        # so that source and target of the next registration share one motion model
        pose = self.poses[-1] @ T if self.poses else np.eye(4)
        if self.poses:
            self._motion = T
        self.poses.append(pose)
        if not diag.too_few_points:
            if deskewing and len(self.poses) > 1:
                t = time.perf_counter()
                scan.points, scan.normals = redeskew(scan.points, scan.normals, scan.times_s, T_deskew, T, period)
                if cfg.match_target == "raw":
                    scan.raw_points = deskew(deskew(points, times_s, se3.inverse(T_guess), period), times_s, T,
                                             period)
                    scan.raw_tree = cKDTree(scan.raw_points, balanced_tree=False, compact_nodes=False)
                seconds["deskew"] += time.perf_counter() - t
            self._previous = scan
            self._previous_motion = T if deskewing and len(self.poses) > 1 else T_deskew
            self._target = self._make_target(scan)
            self._target_pose = pose
            self._target_frame = len(self.poses) - 1
        self._last_period = period
        seconds["total"] = time.perf_counter() - t_start
        diag.seconds = seconds
        self.diagnostics.append(diag)
        if diag.extrapolated:
            why = ("too few points after filtering" if diag.too_few_points else "singular system" if diag.singular
                   else "estimate too far from the constant-velocity prediction")
            # INFO, not WARNING: a degenerate stretch flags frame after frame, which would bury a
            # progress bar; the diagnostics carry the flags and the commands print their count.
            log.info("frame %d: %s; pose extrapolated", diag.frame, why)
        return pose

    # ---- helpers
    def _frame_period(self, stamp_s: float | None) -> float:
        if stamp_s is not None and self._last_stamp is not None and stamp_s > self._last_stamp:
            period = stamp_s - self._last_stamp
        elif self.sensor is not None:
            period = self.sensor.sweep_period_s
        else:
            period = 0.1
        self._last_stamp = stamp_s
        return period

    def _motion_over(self, period: float) -> np.ndarray:
        """The last relative motion rescaled to a frame of ``period`` seconds."""
        if self._last_period is None or abs(period - self._last_period) < 1e-9:
            return self._motion.copy()
        return se3.exp(se3.log(self._motion) * (period / self._last_period))

    def _rejectors(self):
        return self._chain_with_gcr if self._use_gcr else self._chain_without_gcr

    def _source(self, scan: FilteredScan) -> Source:
        threshold = None
        if self._use_gcr:
            threshold = gcr_threshold_m(scan.points, scan.normals, scan.rings, self.sensor,
                                        self.config.gcr_formula, self.config.gcr_noise_floor_m)
            threshold[np.isnan(threshold)] = np.inf  # no neighbour beam to bound the match: keep it
        return Source(scan.points, scan.normals, threshold)

    def _make_target(self, scan: FilteredScan) -> Target:
        if self.config.match_target == "filtered":
            return Target(scan.points, cKDTree(scan.points), scan.normals)
        # the raw (de-skewed) scan; its normals are estimated only where matched
        from .normals import estimate_normals

        raw, tree, k = scan.raw_points, scan.raw_tree, self.config.normal_neighbours

        def normals_of(rows: np.ndarray) -> np.ndarray:
            return estimate_normals(raw, k=k, query_points=raw[rows], tree=tree).normals

        return Target(raw, tree, np.full(raw.shape, np.nan), normals_of)

    @staticmethod
    def _record(diag: FrameDiagnostics, result: RegistrationResult) -> None:
        diag.matches = result.matches
        diag.iterations = result.iterations
        diag.converged = result.converged
        diag.rms_m = result.rms_m
        diag.info_eigenvalues = result.info_eigenvalues
        diag.translation_eigenvalues = result.translation_eigenvalues
        diag.degenerate = result.degenerate
        diag.singular = result.singular


# ---------------------------------------------------------------- sequences and files
@dataclass
class OdometryRun:
    """Poses (N, 4, 4) ``T_first_lidar`` of the frames run, their indices, times and diagnostics."""

    poses: np.ndarray
    frame_indices: np.ndarray
    times_s: np.ndarray | None
    diagnostics: list[FrameDiagnostics]
    config: OdometryConfig
    seconds: float

    @property
    def frames_per_second(self) -> float:
        return len(self.poses) / self.seconds if self.seconds > 0 else float("nan")


def run_sequence(
    sequence: Sequence,
    config: OdometryConfig,
    sensor: LidarModel | None = None,
    frames: slice | None = None,
    on_frame=None,
) -> OdometryRun:
    """Run the odometry over (a slice of) a sequence; ``on_frame(k, diagnostics)`` after each frame.

    The poses are relative to the first frame run. The sensor defaults to the sequence's own.
    """
    sensor = sensor or sequence.sensor
    idx = np.arange(len(sequence))[frames or slice(None)]
    if len(idx) == 0:
        raise OdometryError(f"{sequence.path}: no frames selected")
    odo = Odometry(config, sensor)
    t0 = time.perf_counter()
    for k in idx:
        frame = sequence[int(k)]
        stamp = float(sequence.times[k]) if sequence.times is not None and k < len(sequence.times) else None
        odo.register_frame(frame, stamp_s=stamp)
        if on_frame is not None:
            on_frame(int(k), odo.last)
    times = None if sequence.times is None else np.asarray(sequence.times)[idx]
    return OdometryRun(np.stack(odo.poses), idx, times, odo.diagnostics, config, time.perf_counter() - t0)


def write_diagnostics_csv(path: str | Path, diagnostics: list[FrameDiagnostics]) -> None:
    from io import StringIO

    buf = StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for d in diagnostics:
        w.writerow(diagnostics_row(d))
    atomic_write_text(path, buf.getvalue())


def write_kitti_poses(path: str | Path, poses: np.ndarray) -> None:
    atomic_write_text(path, format_kitti_poses(poses))


def format_tum(poses: np.ndarray, times_s: np.ndarray) -> str:
    """TUM trajectory text: ``timestamp tx ty tz qx qy qz qw`` per line."""
    q = Rotation.from_matrix(poses[:, :3, :3]).as_quat()  # x y z w
    rows = np.column_stack([times_s, poses[:, :3, 3], q])
    return "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in rows)


def write_tum(path: str | Path, poses: np.ndarray, times_s: np.ndarray) -> None:
    atomic_write_text(path, format_tum(poses, times_s))


def default_times(n: int, sensor: LidarModel | None) -> np.ndarray:
    period = sensor.sweep_period_s if sensor is not None else 0.1
    return np.arange(n) * period


__all__ = ["Odometry", "OdometryError", "run_sequence"]
