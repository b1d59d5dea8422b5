"""Odometry over a sequence: the variants BL, NCF and SALO of the paper's table, scan-to-scan or scan-to-map.

``Odometry.register`` reads as the paper's steps (each a function of this module,
``odometry.filters`` or ``odometry.icp``; the class holds only ``OdometryState``)::

    clean      drop non-finite points and points outside the range limits
    de-skew    undo motion distortion with the constant-velocity motion (times known)
    filter     voxel grid -> kNN normals in the raw scan -> NCF -> curvature; poles (map variants)
    init       linear extrapolation: the last relative motion
    align      ICP: match in the previous scan or the local map (and poles in recent poles), reject,
               point-to-plane, until converged
    update     pose_i = pose_{i-1} T_{i-1,i}; remember the motion; this scan becomes the target / joins the map

Clean and filter read no state (``Odometry.prepare``; with per-point times and a raw target the filter
follows the de-skew, in the registration); the rest does (``Odometry.register_prepared``).
``register_frames`` (and ``run_sequence`` over it) prepares the next scans on threads of their own
while the current one registers: the same poses, both cores at work.
"""

from __future__ import annotations

import csv
import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from simlidar import se3
from simlidar.formats.atomic import atomic_write_text
from simlidar.formats.scan_folders import Sequence
from simlidar.sensor import LidarModel
from simlidar.sequence import DEFAULT_FRAME_PERIOD_S, Frame, deskew_times

from .cold_start import choose_start
from .config import OdometryConfig
from .deskew import deskew, redeskew, twist_of
from .filters import FilteredScan, filter_scan, scan_normals_needed
from .gcr import correct_kitti_vertical_angle, gcr_threshold_m, ring_of_points
from .icp import RegistrationResult, Source, Target, match, register, rejectors_for
from .kdtree import KDTree
from .local_map import LocalMap
from .normals import estimate_normals
from .poles import PoleMap, extract_poles, pole_translation

log = logging.getLogger(__name__)


# The stages timed in the diagnostics, in the order a frame passes them.
STAGES = ("deskew", "voxel", "normals", "ncf_curvature", "poles", "match", "reject", "estimate", "map")


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
    weakest_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    remapped: int = 0
    degenerate: bool = False
    singular: bool = False
    too_few_points: bool = False
    implausible: bool = False
    deskewed: bool = False
    seconds: dict = field(default_factory=dict)
    # Open-loop runs only (``Odometry.register(true_motion=...)``): the frame's own estimate of its
    # motion T_prev_cur (4, 4), which the state did not take (it took the true motion).
    estimated_motion: np.ndarray | None = None

    @property
    def extrapolated(self) -> bool:
        """The pose is the constant-velocity guess, not an ICP result."""
        return self.frame > 0 and (self.singular or self.too_few_points or self.implausible)


CSV_COLUMNS = (
    ["frame", "points_raw", "points_nonfinite", "points_in_range", "voxels", "after_ncf", "after_curvature",
     "candidates", "after_distance", "after_gcr", "after_trimmed", "pole_matches", "iterations", "converged",
     "rms_m"]
    + [f"eig{k}" for k in range(6)] + ["t_eig0", "t_eig1", "t_eig2", "weak_x", "weak_y", "weak_z", "remapped",
                                        "restored"]
    + ["degenerate", "singular", "too_few_points", "implausible", "extrapolated", "deskewed"]
    + [f"s_{stage}" for stage in STAGES] + ["s_total"]
)


def diagnostics_row(d: FrameDiagnostics) -> list:
    fc, m, s = d.filter_counts, d.matches, d.seconds
    return (
        [d.frame, d.points_raw, d.points_nonfinite, d.points_in_range, fc.get("voxels", ""), fc.get("ncf", ""),
         fc.get("curvature", ""), m.get("candidates", ""), m.get("distance", ""), m.get("gcr", ""),
         m.get("trimmed", ""), m.get("poles", ""), d.iterations, int(d.converged), f"{d.rms_m:.6g}"]
        + [f"{v:.6g}" for v in d.info_eigenvalues] + [f"{v:.6g}" for v in d.translation_eigenvalues]
        + [f"{v:.4f}" for v in d.weakest_direction] + [d.remapped, fc.get("restored", "")]
        + [int(d.degenerate), int(d.singular), int(d.too_few_points), int(d.implausible), int(d.extrapolated),
           int(d.deskewed)]
        + [f"{s.get(k, 0.0):.6f}" for k in (*STAGES, "total")]
    )


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


def make_source(scan: FilteredScan, config: OdometryConfig, sensor: LidarModel | None, with_gcr: bool) -> Source:
    """The registration's source: the filtered points and normals (and poles), with GCR thresholds when used.

    The GCR's neighbour beam distances need the surface's normal at each point. Scans
    registered against a map have no normals of their own (``filters.scan_normals_needed``):
    the thresholds then come from the map's normal at each point's first match
    (``icp.register``), rotated into the scan's frame.

    Against a map, a true match is as far as the map's point spacing allows, not as far as
    the sensor's: near the sensor a scan samples surfaces more densely than a map of voxels
    holding at most ``map.points_per_voxel`` points (the rejector study measured true matches
    9 cm from the map at every range, where GCR's own bound is 10-12 cm within 20 m and
    rejected a third of them). The threshold is then at least the map's spacing,
    ``map.voxel_size_m / sqrt(map.points_per_voxel)``, or ``map.min_point_spacing_m`` when wider
    (``map_point_spacing_m``).
    """
    poles = None if scan.poles is None else scan.poles.points
    if not with_gcr:
        return Source(scan.points, scan.normals, poles=poles)
    rings = scan.rings if scan.rings is not None else ring_of_points(scan.points, sensor)
    floor = config.gcr.noise_floor_m
    if config.match.target == "map":
        floor = max(floor, map_point_spacing_m(config))

    def thresholds(points: np.ndarray, normals: np.ndarray, rows: np.ndarray) -> np.ndarray:
        thr = gcr_threshold_m(points, normals, rings[rows], sensor, config.gcr.formula, floor)
        thr[np.isnan(thr)] = np.inf  # no neighbour beam (or no normal) to bound the match: keep it
        return thr

    if np.isnan(scan.normals[:1]).any():
        return Source(scan.points, scan.normals, None, thresholds, poles)
    return Source(scan.points, scan.normals, thresholds(scan.points, scan.normals, np.arange(len(scan.points))),
                  poles=poles)


def map_point_spacing_m(config: OdometryConfig) -> float:
    """The spacing of a full map voxel's points on a surface through it, m: ``v / sqrt(n)``, or the
    map's least point spacing when that is wider."""
    return max(config.map.voxel_size_m / math.sqrt(config.map.points_per_voxel), config.map.min_point_spacing_m)


def filtered_scan_target(scan: FilteredScan) -> Target:
    """A scan's filtered points and their own normals as a target (its own frame): Alg. 1's target."""
    return Target(scan.points, scan.tree_of_points(), scan.normals)


def scan_target(scan: FilteredScan, config: OdometryConfig) -> Target:
    """A scan as the target of scan-to-scan registration (its own frame).

    ``match.target: filtered``: the filtered points and their normals (Alg. 1);
    ``raw``: every de-skewed raw point, normals estimated where matched.
    """
    if config.match.target == "filtered":
        return filtered_scan_target(scan)
    raw, tree, k = scan.raw_points, scan.raw_tree, config.filter.normal_neighbours

    def normals_of(rows: np.ndarray) -> tuple[np.ndarray, None]:
        return estimate_normals(raw, k=k, query_points=raw[rows], tree=tree).normals, None

    return Target(raw, tree, np.full(raw.shape, np.nan), normals_of)


def new_local_map(config: OdometryConfig, sensor: LidarModel | None) -> LocalMap:
    """An empty local map with the config's parameters (noise: the sensor's range sigma, else 2 cm)."""
    noise = config.ncf.range_noise_std_m or (sensor.range_noise_std_m if sensor is not None else None) or 0.02
    c_tau = (math.radians(config.ncf.max_normal_std_deg) ** 2
             if config.ncf.enabled and config.ncf.applies_to in ("map", "both") else None)
    return LocalMap(config.map.voxel_size_m, config.map.points_per_voxel,
                    config.map.max_distance_m or config.clean.max_range_m, config.filter.normal_neighbours, noise,
                    config.filter.max_curvature, c_tau, min_spacing_m=config.map.min_point_spacing_m)


def map_points(scan: FilteredScan, T_world_lidar: np.ndarray) -> np.ndarray:
    """(V, 3) the scan's voxel centroids in the world frame: what it adds to the map."""
    return se3.transform_points(T_world_lidar, scan.centroids)


def redeskew_scan(scan: FilteredScan, old_motion: np.ndarray, new_motion: np.ndarray, period_s: float,
                  centroids_motion: np.ndarray | None = None) -> None:
    """Re-do the de-skew of a filtered scan's points, normals and poles with a better motion (in place).

    The centroids (what a map takes) move with the points when they are the points. Otherwise
    they move only when ``centroids_motion`` (4, 4), the motion they are de-skewed with now, is
    given: the de-skew refinements leave them, since only the frame's final motion matters to the map.
    Motions are (4, 4) transforms or their (6,) twists (``deskew.redeskew``).
    """
    same = scan.points is scan.centroids  # (the ICP points are the centroids: move them once)
    old_motion, new_motion = twist_of(old_motion), twist_of(new_motion)  # (once for every array moved)
    # (a scan registered against a map has no normals of its own: nan rows, which stay nan)
    without_normals = len(scan.normals) > 0 and bool(np.isnan(scan.normals[:, 0]).all())
    scan.points, normals = redeskew(scan.points, None if without_normals else scan.normals, scan.times_s,
                                    old_motion, new_motion, period_s, scan.points_redeskew)
    if not without_normals:
        scan.normals = normals
    poles = scan.poles
    if poles is not None and poles.times_s is not None and len(poles):
        poles.points, _ = redeskew(poles.points, None, poles.times_s, old_motion, new_motion, period_s)
    if same:
        scan.centroids = scan.points
    elif centroids_motion is not None and scan.centroid_times_s is not None and len(scan.centroids):
        scan.centroids, _ = redeskew(scan.centroids, None, scan.centroid_times_s, centroids_motion, new_motion,
                                     period_s)


def filters_as_measured(config: OdometryConfig) -> bool:
    """Whether scans are filtered as measured, their ICP points de-skewed afterwards (``Odometry.prepare``),
    rather than de-skewed first: all but a raw target with the de-skew on (it keeps every de-skewed point)."""
    return config.match.target != "raw" or not config.deskew.enabled


@dataclass
class PreparedScan:
    """A scan cleaned and filtered as measured, before any state is used (``Odometry.prepare``).

    clean: its clean points. scan: its ICP points as measured (None until the filter has run:
    with per-point times and a raw target, ``register_prepared`` de-skews first). deskewing: per-point
    times are known and the de-skew is on. diag, seconds: the frame's diagnostics and stage times so
    far. seconds_spent: the time its preparation took, s (counted in the frame's total). registered:
    ``register_prepared`` has taken it (a scan is registered once: its points are de-skewed in place).
    """

    clean: CleanScan
    scan: FilteredScan | None
    deskewing: bool
    diag: FrameDiagnostics
    seconds: dict
    seconds_spent: float
    registered: bool = False


@dataclass
class OdometryState:
    """What the odometry carries from frame to frame.

    poses: ``T_world_lidar`` (4, 4) of every frame so far; the world is the first scan's frame.
    T_prev_cur: the last frame-to-frame motion (4, 4): the constant-velocity prediction.
    last_stamp_s, last_period_s: the previous sweep's start time and period, s.
    target_scan: the last scan that had points (scan-to-scan target; and the first
        scan until the first registration, for the cold start).
    target_frame: its frame index. target_motion: the motion its points are de-skewed with.
    local_map: the map of recent scans (``match.target: map``), else None.
    pole_map: the poles of recent frames (``poles.enabled``, with a sensor), else None.
    """

    poses: list[np.ndarray] = field(default_factory=list)
    T_prev_cur: np.ndarray = field(default_factory=lambda: np.eye(4))
    last_stamp_s: float | None = None
    last_period_s: float | None = None
    target_scan: FilteredScan | None = None
    target_frame: int = 0
    target_motion: np.ndarray = field(default_factory=lambda: np.eye(4))
    local_map: LocalMap | None = None
    pole_map: PoleMap | None = None


def better_constrained(starts: list[tuple[str, Target, RegistrationResult]]
                       ) -> tuple[str, Target, RegistrationResult]:
    """Of first registrations ``(kind, target, result)``, the one whose weakest direction of
    translation is best constrained: the largest smallest eigenvalue of its information per
    match (``RegistrationResult.translation_eigenvalues``); a singular result only when all are;
    on a tie the earlier. A registration that slid along a weakly constrained direction (a map
    of one scan on open ground, whose single-ring ground has no normals) has the smaller one.
    """
    def weakest(start) -> float:
        result = start[2]
        w = float(result.translation_eigenvalues[0])
        return -math.inf if result.singular or not math.isfinite(w) else w

    return max(starts, key=weakest)  # (max keeps the first of equal keys)


class Odometry:
    """ICP odometry (Alg. 1) with the paper's filters and rejectors, scan-to-scan or scan-to-map.

    Args:
        config: the variant's parameters (``odometry.config``).
        sensor: the lidar model; needed by the GCR (ring pitches, azimuth step),
            and by the sensor-aware NCF for its range noise unless the config sets it.

    ``register`` returns the pose ``T_world_lidar`` (4, 4) of each scan in the
    first scan's frame; ``last`` holds the latest ``FrameDiagnostics``. Each frame
    goes through the stages below, functions of this module, ``odometry.filters``
    and ``odometry.icp``::

        clean        clean_scan: finite points within the range limits
        de-skew      deskew with the constant-velocity motion (per-point times known)
        filter       filter_scan: voxel grid -> kNN normals -> NCF -> curvature; poles.extract_poles
        source       make_source: points, normals, GCR thresholds
        target       the previous scan (scan_target) or the local map (LocalMap.target)
        register     icp.register from the constant-velocity prediction (deskew.joint: the scan
                     re-de-skewed at every step, halfway towards the estimate's motion)
        refine       re-de-skew with the frame's own estimate and register again
        update       pose, motion, next target / map insertion
    """

    def __init__(self, config: OdometryConfig, sensor: LidarModel | None = None):
        if config.gcr.enabled and sensor is None:
            raise OdometryError(
                f"variant '{config.name}' uses the geometric correspondence rejector, which needs the "
                "sensor's ring table: pass --sensor PRESET|FILE (or use a sequence folder with sensor.yaml)"
            )
        self.config = config
        self.sensor = sensor
        # (poles need the sensor's range image: its rings and azimuth columns)
        self.state = OdometryState(
            local_map=new_local_map(config, sensor) if config.match.target == "map" else None,
            pole_map=PoleMap(config.poles.frames_kept) if config.poles.enabled and sensor is not None else None)
        self.diagnostics: list[FrameDiagnostics] = []
        # The rejection chains, built once: with GCR, and without (the first registration)
        self._chain_with_gcr = rejectors_for(config)
        self._chain_without_gcr = rejectors_for(config.replace(gcr={"enabled": False}))
        # The first registration's coarse pass: a wide bound, no trimming, no GCR
        self._coarse_config = config.replace(gcr={"enabled": False}, match={
            "max_correspondence_distance_m": config.match.initial_correspondence_distance_m, "trim_fraction": 0.0})
        self._chain_coarse = rejectors_for(self._coarse_config)
        # The de-skew refinements' ICP (deskew.refinement_iterations: a cap on its iterations)
        capped = config.deskew.refinement_iterations
        self._refine_config = config if capped is None else config.replace(icp={"max_iterations": capped})
        # A map variant's first registration is against the map of the first scan, its own points and
        # normals (map.cold_start_target: scan), or both, keeping the better constrained (better): a
        # map of one scan has a normal only where two scan lines meet, which on open ground leaves
        # the direction of travel to a few objects (README).
        # (scan-to-scan: its usual target, the first scan; "map" stands for that below)
        self._cold_start_kinds: tuple[str, ...] = ("map",)
        if config.match.target == "map":
            better = config.map.cold_start_target == "better"
            self._cold_start_kinds = ("map", "scan") if better else (config.map.cold_start_target,)
        self._scan_cold_start = "scan" in self._cold_start_kinds

    @property
    def poses(self) -> list[np.ndarray]:
        return self.state.poses

    @property
    def last(self) -> FrameDiagnostics | None:
        return self.diagnostics[-1] if self.diagnostics else None

    def register_frame(self, frame: Frame, stamp_s: float | None = None) -> np.ndarray:
        """``register`` with a ``simlidar.sequence.Frame`` (uses its ring and time fields)."""
        return self.register(frame.points, times_s=frame.time_s, rings=frame.ring, stamp_s=stamp_s)

    def register(
        self,
        points: np.ndarray,
        times_s: np.ndarray | None = None,
        rings: np.ndarray | None = None,
        stamp_s: float | None = None,
        true_motion: np.ndarray | None = None,
    ) -> np.ndarray:
        """Register the next scan and return its pose ``T_world_lidar`` (4, 4).

        points: (N, 3) as measured, m. times_s: (N,) per-point time since the sweep
        start, s (enables de-skew). rings: (N,) int ring per point (else from the
        elevation and the sensor table). stamp_s: the sweep's start time, s.

        true_motion: (4, 4) this frame's true motion ``T_prev_cur``, for an open-loop
        evaluation (the simulator knows it): the frame is registered as always and its
        estimate kept in ``FrameDiagnostics.estimated_motion`` (the constant-velocity guess
        when the frame was extrapolated), but the pose, the motion prior, the de-skew and
        the map advance with the true motion. Every frame is then registered against a
        target built from true poses (except that with per-point times the first scan
        keeps the de-skew the first registration's refinements gave it), which separates
        the error a registration makes from the drift its errors feed back
        (``tools.open_loop``).
        """
        prepared = self.prepare(points, times_s, rings, first=not self.state.poses)
        return self.register_prepared(prepared, stamp_s=stamp_s, true_motion=true_motion)

    def prepare(self, points: np.ndarray, times_s: np.ndarray | None = None, rings: np.ndarray | None = None,
                first: bool = False) -> PreparedScan:
        """Clean and filter a scan as measured: the part of ``register`` that needs no state.

        points: (N, 3) m; times_s, rings: (N,) or None, as ``register`` takes them. first: the
        sequence's first scan (a map variant with ``map.cold_start_target: scan`` gives it normals).
        Reads only the config and the sensor, so it may run on another thread while ``register_prepared``
        registers the previous scan (``register_frames``). With per-point times and a raw target the
        filter needs the de-skewed points: it is left to ``register_prepared``.
        """
        cfg = self.config
        t_start = time.perf_counter()
        diag = FrameDiagnostics(frame=-1)
        seconds: dict[str, float] = {}
        clean = clean_scan(points, times_s, rings, cfg, diag)
        deskewing = cfg.deskew.enabled and clean.times_s is not None
        # The scan is voxelised and its normals and NCF computed as measured, and then its ICP points,
        # normals and centroids are de-skewed, each with its voxel's mean firing time: a voxel's and
        # a normal's neighbours fire within microseconds of each other (except at the sweep's seam),
        # so they move rigidly, and the beams the NCF's noise follows start at the sensor's origin
        # only in the measured frame. Far fewer points to move. (A raw target keeps every de-skewed point.)
        prepared = PreparedScan(clean, None, deskewing, diag, seconds, 0.0)
        if not deskewing or filters_as_measured(cfg):
            self._filter(prepared, first)
        prepared.seconds_spent = time.perf_counter() - t_start
        return prepared

    def _filter(self, prepared: PreparedScan, first: bool) -> None:
        """The filter stage of ``prepare``: ``prepared.scan`` from its clean points."""
        cfg, clean = self.config, prepared.clean
        # (with map.cold_start_target: scan, a map variant's first scan gets its own normals: ``_cold_start_target``)
        normals = scan_normals_needed(cfg) or (self._scan_cold_start and first)
        rings_needed = cfg.gcr.enabled or cfg.filter.adjacent_ring_reach_m is not None
        if clean.rings is None and rings_needed and normals and self.sensor is not None:
            clean.rings = ring_of_points(clean.points, self.sensor)
        scan = filter_scan(clean.points, cfg, clean.rings, self.sensor,
                           raw_times_s=clean.times_s if prepared.deskewing else None, with_normals=normals)
        if self.state.pole_map is not None:
            t = time.perf_counter()
            rings = clean.rings if clean.rings is not None else ring_of_points(clean.points, self.sensor)
            scan.poles = extract_poles(clean.points, rings, self.sensor.rings, self.sensor.columns_per_sweep,
                                       cfg.poles.max_width_m, clean.times_s if prepared.deskewing else None)
            scan.counts["poles"] = len(scan.poles)
            scan.seconds["poles"] = time.perf_counter() - t
        prepared.diag.filter_counts = scan.counts
        prepared.seconds.update(scan.seconds)
        prepared.scan = scan

    def register_prepared(self, prepared: PreparedScan, stamp_s: float | None = None,
                          true_motion: np.ndarray | None = None) -> np.ndarray:
        """``register`` of a scan ``prepare`` cleaned and filtered (once: its scan is de-skewed in place)."""
        cfg, st = self.config, self.state
        if prepared.registered:
            raise OdometryError("this prepared scan was registered already (its points are de-skewed in place): "
                                "prepare it again")
        prepared.registered = True
        t_start = time.perf_counter()
        diag = prepared.diag
        diag.frame = len(st.poses)
        seconds = prepared.seconds
        clean = prepared.clean
        period = self._frame_period(stamp_s)
        T_guess = self._predicted_motion(period)
        deskewing = prepared.deskewing
        diag.deskewed = deskewing

        t = time.perf_counter()
        if prepared.scan is None:  # de-skewed before the filter (a raw target keeps every de-skewed point)
            clean.points = deskew(clean.points, clean.times_s, T_guess, period)
            seconds["deskew"] = time.perf_counter() - t
            self._filter(prepared, first=not st.poses)
        else:
            if deskewing:  # filtered as measured: its ICP points, normals and centroids follow the motion
                redeskew_scan(prepared.scan, np.eye(4), T_guess, period, centroids_motion=np.eye(4))
            seconds["deskew"] = time.perf_counter() - t
        scan = prepared.scan
        diag.too_few_points = len(scan) < cfg.filter.min_points

        T_deskew = T_guess  # the motion the scan is de-skewed with now
        target = None  # what the scan was registered against
        if not st.poses:
            T = np.eye(4)
        elif diag.too_few_points or (st.target_scan is None and st.local_map is None):
            T = T_guess
        else:
            T, T_deskew, target = self._align(scan, T_guess, period, deskewing, diag, seconds)
        if true_motion is not None and st.poses:
            diag.estimated_motion = T
            T = np.asarray(true_motion, dtype=float)

        self._update(scan, T, T_deskew, T_guess, clean.times_s if deskewing else None, period, diag, seconds,
                     target)
        # (a frame's time includes its preparation, wherever it ran)
        seconds["total"] = time.perf_counter() - t_start + prepared.seconds_spent
        diag.seconds = seconds
        self.diagnostics.append(diag)
        if diag.extrapolated:
            why = ("too few points after filtering" if diag.too_few_points else "singular system" if diag.singular
                   else "estimate too far from the constant-velocity prediction")
            # INFO, not WARNING: a degenerate stretch flags frame after frame, which would bury a
            # progress bar; the diagnostics carry the flags and the commands print their count.
            log.info("frame %d: %s; pose extrapolated", diag.frame, why)
        return st.poses[-1]

    # ---- stages
    def _align(self, scan: FilteredScan, T_guess: np.ndarray, period: float, deskewing: bool,
               diag: FrameDiagnostics, seconds: dict) -> tuple[np.ndarray, np.ndarray, Target]:
        """Register, refine the de-skew, check plausibility: (T_prev_cur, the motion the scan is de-skewed with,
        the target it was registered against)."""
        cfg, st = self.config, self.state
        first = len(st.poses) == 1
        # GCR bounds matches by the sensor's sampling spacing (cm to dm), so it needs a close
        # initial guess; the first registration has no motion to extrapolate and starts from
        # identity, so it runs without GCR.
        chain = self._chain_with_gcr if cfg.gcr.enabled and not first else self._chain_without_gcr
        # Transforms into the target's frame: the world for a map; for scan-to-scan the target
        # scan, usually the previous frame (then exactly the identity: rounding must not feed back).
        T_world_prev = st.poses[-1]
        previous_is_target = st.local_map is None and st.target_frame == len(st.poses) - 1
        if st.local_map is not None:
            T_target_prev = T_world_prev
        elif previous_is_target:
            T_target_prev = np.eye(4)
        else:
            T_target_prev = se3.inverse(st.poses[st.target_frame]) @ T_world_prev
        source = make_source(scan, cfg, self.sensor, chain is self._chain_with_gcr)
        T_init = T_target_prev @ T_guess
        runs: list[RegistrationResult] = []  # (every registration run: their time and iterations count)
        T_deskew = T_guess  # the motion the scan is de-skewed with now
        xi_deskew = se3.log(T_deskew)  # (its twist, kept beside it: the re-de-skews take it)

        def motion_of(T_target_cur: np.ndarray) -> np.ndarray:
            return T_target_cur if previous_is_target else se3.inverse(T_target_prev) @ T_target_cur

        if first:
            # Against each cold-start target; the better constrained one is kept (``better_constrained``)
            starts = []
            for kind in self._cold_start_kinds:
                target = self._cold_start_target(kind)
                starts.append((kind, target, self._first_registration(source, target, T_init, chain, T_target_prev,
                                                                      deskewing, runs)))
            first_kind, target, result = better_constrained(starts)
            if len(starts) > 1:
                log.info("first registration against the %s (weakest translational information per match: %s)",
                         "first scan" if first_kind == "scan" else "map of the first scan",
                         ", ".join(f"{k} {r.translation_eigenvalues[0]:.3g}" for k, _, r in starts))
        else:
            target = self._target()
            reskew = None
            if deskewing and cfg.deskew.joint:
                # (the damped update of the refinements below, at every step: the de-skew motion moves
                # halfway towards the estimate's, and the step and that move must both be small to stop)
                def reskew(T_target_cur: np.ndarray) -> np.ndarray:
                    nonlocal T_deskew, xi_deskew
                    old, xi_old = T_deskew, xi_deskew
                    T_deskew = se3.exp(0.5 * (xi_old + se3.log(motion_of(T_target_cur))))
                    xi_deskew = se3.log(T_deskew)
                    redeskew_scan(scan, xi_old, xi_deskew, period)
                    source.points = scan.points
                    source.poles = None if scan.poles is None else scan.poles.points
                    return se3.log(se3.inverse(old) @ T_deskew)

            result = register(source, target, T_init, cfg, chain, T_target_prev, reskew=reskew)
            runs.append(result)
        icp_seconds = {stage: sum(r.seconds.get(stage, 0.0) for r in runs) for stage in runs[-1].seconds}
        icp_iterations = sum(r.iterations for r in runs)

        # The de-skew used the previous frame's motion. The estimate responds to the de-skew
        # motion with a gain near -1 (a too-fast de-skew makes the scan look closer), so plain
        # re-use of the estimate oscillates: move the de-skew motion halfway towards the
        # estimate (a damped fixed-point iteration) and refine. Only the filtered points move.
        for _ in range(cfg.deskew.refinements if deskewing else 0):
            if result.singular:
                break
            motion = motion_of(result.T_target_source)
            if first and st.target_scan is not None and st.target_scan.times_s is not None:
                # Cold start: the first scan was de-skewed as if standing still. It is
                # re-de-skewed with the estimate too, so source and target share one motion
                # model and the estimate can be taken as it is.
                M = motion
                redeskew_scan(st.target_scan, st.target_motion, M, period, centroids_motion=st.target_motion)
                st.target_motion = M
                if st.local_map is not None:
                    st.local_map = new_local_map(cfg, self.sensor)
                    st.local_map.update(map_points(st.target_scan, st.poses[0]), st.poses[0][:3, 3])
                if st.pole_map is not None and st.target_scan.poles is not None:
                    st.pole_map = PoleMap(cfg.poles.frames_kept)
                    st.pole_map.add(se3.transform_points(st.poses[0], st.target_scan.poles.points))
                target = self._cold_start_target(first_kind)
            else:
                M = se3.exp(0.5 * (xi_deskew + se3.log(motion)))
            xi_M = se3.log(M)
            redeskew_scan(scan, xi_deskew, xi_M, period)
            T_deskew, xi_deskew = M, xi_M
            # The GCR thresholds scale with range and incidence, which a re-de-skew by a
            # few centimetres does not change: they are reused. (The poles were re-de-skewed too.)
            source = Source(scan.points, scan.normals, source.gcr_threshold_m,
                            poles=None if scan.poles is None else scan.poles.points)
            refined = register(source, target, result.T_target_source, self._refine_config, chain, T_target_prev,
                               not first)
            # (a capped refinement is a fixed number of steps from a converged estimate: it inherits that)
            refined.converged |= self._refine_config is not cfg and result.converged
            for stage, spent in refined.seconds.items():  # stage times and iterations cover every registration
                icp_seconds[stage] += spent
            icp_iterations += refined.iterations
            if refined.singular:  # keep the last good estimate: the frame is not extrapolated
                break
            result = refined
        self._record(diag, result)
        diag.iterations = icp_iterations
        seconds.update(icp_seconds)
        T = T_guess if result.singular else se3.orthonormalize(motion_of(result.T_target_source))
        # A car cannot change its motion by metres within one frame: such an estimate is
        # a failed registration (degenerate scene, wrong local minimum), not motion.
        deviation = se3.inverse(T_guess) @ T
        if not first and (np.linalg.norm(deviation[:3, 3]) > cfg.icp.max_prediction_error_m
                          or np.degrees(se3.rotation_angle(deviation)) > cfg.icp.max_prediction_error_deg):
            diag.implausible = True
            T = T_guess
        return T, T_deskew, target

    def _update(self, scan: FilteredScan, T: np.ndarray, T_deskew: np.ndarray, T_guess: np.ndarray,
                raw_times_s: np.ndarray | None, period: float, diag: FrameDiagnostics, seconds: dict,
                target: Target | None = None) -> None:
        """Pose and motion; the scan, de-skewed with the motion just estimated, becomes the next
        target or joins the map, so that source and target share one motion model.

        T: this frame's motion T_prev_cur; T_deskew: the motion its filtered points are
        de-skewed with now; T_guess: the one its raw points are; raw_times_s: (N,) or None;
        target: what the scan was registered against (None: it was not).
        """
        cfg, st = self.config, self.state
        # (re-orthonormalised: with a map, T = previous^-1 x estimate feeds rounding back)
        pose = se3.orthonormalize(st.poses[-1] @ T) if st.poses else np.eye(4)
        if st.poses:
            st.T_prev_cur = T
        st.poses.append(pose)
        st.last_period_s = period
        if diag.too_few_points:
            return
        t = time.perf_counter()
        redo = raw_times_s is not None and len(st.poses) > 1
        if redo:
            redeskew_scan(scan, T_deskew, T, period, centroids_motion=T_guess)  # (the centroids are at T_guess)
            if cfg.match.target == "raw":
                scan.raw_points, _ = redeskew(scan.raw_points, None, raw_times_s, T_guess, T, period)
                scan.raw_tree = KDTree(scan.raw_points)
        st.target_scan = scan
        if st.local_map is None and cfg.match.target == "filtered":
            scan.start_points_tree()  # (built while the next scan is cleaned and filtered)
        st.target_frame = len(st.poses) - 1
        st.target_motion = T if redo else T_deskew
        if st.local_map is not None:
            points_world = map_points(scan, pose)
            st.local_map.update(points_world, pose[:3, 3], nearest_m=self._map_nearest_m(scan, points_world, target))
        if st.pole_map is not None and scan.poles is not None:
            st.pole_map.add(se3.transform_points(pose, scan.poles.points))
        stage = "map" if st.local_map is not None else "deskew"  # (the re-de-skew counts with the map's update)
        seconds[stage] = seconds.get(stage, 0.0) + time.perf_counter() - t

    def _map_nearest_m(self, scan: FilteredScan, points_world: np.ndarray, target: Target | None
                       ) -> np.ndarray | None:
        """(N,) each world point's distance to its nearest map point, inf beyond the match bound, m: the
        map's spacing check without a search of its own where the ICP's last one still holds
        (``icp.match``: the points moved by millimetres since; a thinned source's points are some of the
        centroids, the rest are searched). None when ``target`` is not the map as it stands, or the
        bound is below the map's point spacing (the answer would not decide)."""
        st, bound = self.state, self.config.match.max_correspondence_distance_m
        if (target is None or st.local_map is None or target.points is not st.local_map.points
                or st.local_map.min_spacing_m > bound):
            return None
        nearest = np.full(len(points_world), np.inf)
        rows = scan.centroid_rows
        if rows is None or len(rows) == len(points_world):
            m = match(points_world, target, bound)
            nearest[m.source_index] = m.distance_m
            return nearest
        m = match(points_world.take(rows, axis=0), target, bound)
        nearest[rows[m.source_index]] = m.distance_m
        others = np.setdiff1d(np.arange(len(points_world)), rows, assume_unique=True)
        nearest[others], _ = target.tree.query(points_world.take(others, axis=0), k=1, distance_upper_bound=bound)
        return nearest

    def _target(self) -> Target:
        st = self.state
        target = st.local_map.target() if st.local_map is not None else scan_target(st.target_scan, self.config)
        return self._with_poles(target)

    def _with_poles(self, target: Target) -> Target:
        """``target`` with the recent frames' poles in its frame (the world for a map, else the target scan's)."""
        st = self.state
        if st.pole_map is not None:
            into = None if st.local_map is not None else se3.inverse(st.poses[st.target_frame])
            target.poles = st.pole_map.target(into)
        return target

    def _cold_start_target(self, kind: str) -> Target:
        """A first registration's target: the first scan's own points and normals (in the world
        frame, which is its frame) for ``kind`` scan, else the usual target (the map of that scan)."""
        scan = self.state.target_scan
        if kind == "scan" and scan is not None and len(scan.points):
            return self._with_poles(filtered_scan_target(scan))
        return self._target()

    def _first_registration(self, source: Source, target: Target, T_init: np.ndarray, chain,
                            T_target_prev: np.ndarray, deskewing: bool,
                            runs: list[RegistrationResult]) -> RegistrationResult:
        """A sequence's first registration of ``source`` on ``target``: the coarse pass, then the ICP
        (each run appended to ``runs``)."""
        cfg = self.config
        result = None
        # (motion_prior=False: T_init is a guess, not a known motion, so no direction is held to it)
        # With poles on both sides, the horizontal offset most of them agree on is the guess, and the ICP
        # starts there: where poles are the evidence along the road, the coarse pass below would let the
        # rails' and the ground's sampling pattern (the same in both scans) pull it back to standing still.
        if source.poles is not None and target.poles is not None:
            moved = se3.transform_points(T_init, source.poles)
            offset = pole_translation(moved, target.poles, cfg.match.initial_correspondence_distance_m)
            if offset is not None:
                T_start = T_init.copy()
                T_start[:3, 3] += offset
                result = register(source, target, T_start, cfg, chain, T_target_prev, motion_prior=False)
                runs.append(result)
                if not result.singular:
                    return result
                result = None
        # No motion to extrapolate yet: the sensor may already move by metres per frame, beyond
        # the correspondence bound, and the points that see it (few, in a corridor) would be
        # trimmed first. A coarse registration with a wide bound and no trimming comes first.
        coarse = register(source, target, T_init, self._coarse_config, self._chain_coarse, T_target_prev,
                          motion_prior=False)
        runs.append(coarse)
        if not coarse.singular:
            result = register(source, target, coarse.T_target_source, cfg, chain, T_target_prev, motion_prior=False)
            runs.append(result)
        # From the guess when the coarse pass failed, or, with match.cold_start_from_rest, as a
        # second start (odometry/cold_start.py). Not with per-point times: both scans are de-skewed
        # as if standing still until the refinements re-de-skew them with the estimate, and such
        # scans favour standing still.
        if result is None or (cfg.match.cold_start_from_rest and not deskewing):
            from_guess = register(source, target, T_init, cfg, chain, T_target_prev, motion_prior=False)
            runs.append(from_guess)
            result = from_guess if result is None else choose_start(
                source.points, target, from_guess, result, cfg.match.max_correspondence_distance_m)
        return result

    def _frame_period(self, stamp_s: float | None) -> float:
        st = self.state
        if stamp_s is not None and st.last_stamp_s is not None and stamp_s > st.last_stamp_s:
            period = stamp_s - st.last_stamp_s
        elif self.sensor is not None:
            period = self.sensor.sweep_period_s
        else:
            period = DEFAULT_FRAME_PERIOD_S
        st.last_stamp_s = stamp_s
        return period

    def _predicted_motion(self, period: float) -> np.ndarray:
        """The last relative motion rescaled to a frame of ``period`` seconds."""
        st = self.state
        if st.last_period_s is None or abs(period - st.last_period_s) < 1e-9:
            return st.T_prev_cur.copy()
        return se3.exp(se3.log(st.T_prev_cur) * (period / st.last_period_s))

    @staticmethod
    def _record(diag: FrameDiagnostics, result: RegistrationResult) -> None:
        diag.matches = result.matches
        diag.iterations = result.iterations
        diag.converged = result.converged
        diag.rms_m = result.rms_m
        diag.info_eigenvalues = result.info_eigenvalues
        diag.translation_eigenvalues = result.translation_eigenvalues
        diag.weakest_direction = result.weakest_direction
        diag.remapped = result.remapped
        diag.degenerate = result.degenerate
        diag.singular = result.singular


@dataclass(frozen=True)
class DegenerateStretch:
    """Consecutive frames whose registration was weakly constrained (flagged degenerate or remapped).

    first, last: frame numbers (inclusive). direction: (3,) unit mean weakest translation
    direction over the stretch, in the lidar frame. min_eigenvalue: the smallest translational
    eigenvalue per match in it. remapped: frames whose update kept the prior in a direction.
    """

    first: int
    last: int
    direction: np.ndarray
    min_eigenvalue: float
    remapped: int

    def describe(self) -> str:
        x, y, z = self.direction
        axis = ("along x (forward)", "along y (sideways)", "along z (up)")[int(np.nanargmax(np.abs(self.direction)))]
        span = f"frame {self.first}" if self.first == self.last else f"frames {self.first}-{self.last}"
        return (f"{span}: weakest direction ({x:+.2f}, {y:+.2f}, {z:+.2f}), mostly {axis}; smallest eigenvalue "
                f"{self.min_eigenvalue:.2g}" + (f"; prior kept on {self.remapped} frames" if self.remapped else ""))


def degenerate_stretches(diagnostics: list[FrameDiagnostics], min_gap: int = 1) -> list[DegenerateStretch]:
    """The runs of degenerate (or remapped) frames, merged across gaps shorter than ``min_gap`` frames."""
    return stretches_of(np.array([d.frame for d in diagnostics], dtype=int),
                        np.array([bool(d.degenerate or d.remapped) for d in diagnostics], dtype=bool),
                        np.array([d.weakest_direction for d in diagnostics], dtype=float).reshape(-1, 3),
                        np.array([d.translation_eigenvalues[0] for d in diagnostics], dtype=float),
                        np.array([d.remapped > 0 for d in diagnostics], dtype=bool), min_gap)


def stretches_of(frames: np.ndarray, weak: np.ndarray, directions: np.ndarray, eigenvalues: np.ndarray,
                 remapped: np.ndarray | None = None, min_gap: int = 1) -> list[DegenerateStretch]:
    """The runs of ``weak`` frames, merged across gaps shorter than ``min_gap`` frames.

    frames: (N,) frame numbers, ascending. weak: (N,) bool. directions: (N, 3) weakest
    translational direction per frame (lidar frame; sign arbitrary). eigenvalues: (N,) the
    smallest translational eigenvalue per frame. remapped: (N,) bool, frames whose update kept
    the prior (default none). Used for a run's own diagnostics (``degenerate_stretches``) and
    for the simulator's truth (a sequence's ``degeneracy.csv``).
    """
    remapped = np.zeros(len(frames), dtype=bool) if remapped is None else np.asarray(remapped, dtype=bool)
    out: list[list[int]] = []
    for i in np.flatnonzero(weak):
        if out and frames[i] - frames[out[-1][-1]] <= min_gap:
            out[-1].append(int(i))
        else:
            out.append([int(i)])
    stretches = []
    for run in out:
        dirs = directions[run]
        dirs = dirs[np.all(np.isfinite(dirs), axis=1)]
        if len(dirs):
            dirs = dirs * np.sign(dirs @ dirs[0])[:, None]  # eigenvectors have no sign: align them first
            mean = dirs.mean(axis=0)
            mean /= np.linalg.norm(mean)
        else:
            mean = np.full(3, np.nan)
        eig = eigenvalues[run]
        eig = eig[np.isfinite(eig)]
        stretches.append(DegenerateStretch(int(frames[run[0]]), int(frames[run[-1]]), mean,
                                           float(eig.min()) if len(eig) else float("nan"), int(remapped[run].sum())))
    return stretches


# ---------------------------------------------------------------- sequences and files
class ScanInput(NamedTuple):
    """One scan for ``register_frames``: ``Odometry.register``'s arguments.

    points: (N, 3) m; times_s, rings: (N,) or None; stamp_s: the sweep's start, s, or None;
    true_motion: (4, 4) or None (an open-loop run).
    """

    points: np.ndarray
    times_s: np.ndarray | None = None
    rings: np.ndarray | None = None
    stamp_s: float | None = None
    true_motion: np.ndarray | None = None


# Scans prepared ahead by default (``register_frames``). Where a scan's preparation holds its normals and
# NCF (scan-to-scan, about as long as its registration) two threads preparing the next two keep both cores
# busy; one ahead left the registering thread waiting. Where it is a voxel grid and poles only (the map
# variants: their normals are the map's) one: with the registration's steps compiled, its ~5 ms a frame
# beside the registration gained in each of five interleaved comparisons (100 city frames, 4-8 rounds:
# the default at 0.90-1.00x against 0.92-1.07x KISS-ICP's time on hdl32e with one ahead and none in
# three, 0.76-0.80x against 0.83-0.84x on salo32 in two; two ahead no better; README, "Benchmarks").
# (When more of the frame was Python, one ahead slowed the registering thread by about as much as it saved.)
PREFETCH_SCANS = 2
PREFETCH_SCANS_WITHOUT_NORMALS = 1
# The environment variable that overrides both (a worker pool whose processes have a core each sets 0).
PREFETCH_ENV = "SALO_PREFETCH_SCANS"


def default_prefetch(config: OdometryConfig | None = None) -> int:
    """Scans prepared ahead when the caller does not say: ``$SALO_PREFETCH_SCANS``, else ``PREFETCH_SCANS``
    (``PREFETCH_SCANS_WITHOUT_NORMALS`` for a ``config`` whose preparation holds no normals of the scan)."""
    text = os.environ.get(PREFETCH_ENV)
    if text is None or not text.strip():
        # (a scan filtered after its de-skew is filtered in the registration: only its cleaning goes ahead)
        if config is None or (scan_normals_needed(config) and filters_as_measured(config)):
            return PREFETCH_SCANS
        return PREFETCH_SCANS_WITHOUT_NORMALS
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise OdometryError(f"environment variable {PREFETCH_ENV}={text!r}: expected a whole number of scans >= 0")
    return value


_prefetchers: dict[tuple[int, int], ThreadPoolExecutor] = {}
_prefetchers_lock = threading.Lock()


def _prefetcher(threads: int) -> ThreadPoolExecutor:
    """This process's threads that prepare the scans ahead (a forked child gets its own).

    Not ``filters.background()``: a preparation waits on the k-d tree builds queued there.
    """
    key = (os.getpid(), threads)
    with _prefetchers_lock:
        if key not in _prefetchers:
            _prefetchers[key] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="prepare")
        return _prefetchers[key]


def register_frames(odometry: Odometry, scans: Iterable[ScanInput], prefetch: int | None = None
                    ) -> Iterator[np.ndarray]:
    """Register ``scans`` in order with ``odometry``; yield each pose ``T_world_lidar`` (4, 4).

    prefetch: scans prepared ahead (``Odometry.prepare``: clean, voxel grid, normals, NCF), each on
    a thread of its own, while this thread registers the current one (0: none, one thing at a
    time; None: ``default_prefetch`` of the odometry's config). The poses are those of
    ``Odometry.register`` frame after frame: a preparation reads no state. ``scans`` is advanced
    by this thread only; an error it raises (a file that cannot be read) comes after the poses
    of the scans before it.
    """
    prefetch = default_prefetch(odometry.config) if prefetch is None else prefetch
    if prefetch < 0:
        raise ValueError(f"prefetch must be >= 0 scans, got {prefetch}")
    it = iter(scans)
    pool = _prefetcher(prefetch) if prefetch > 0 else None
    pending: deque = deque()  # (scan, its preparation: a future, or None to prepare here, first?), in order
    first = not odometry.state.poses
    ended = False  # the scans are exhausted, or raised ``error``
    error: Exception | None = None

    def top_up() -> None:
        nonlocal first, ended, error
        while not ended and len(pending) < max(prefetch, 1):
            try:
                scan = next(it)
            except StopIteration:
                ended = True
                return
            except Exception as exc:  # noqa: BLE001 - raised in its turn, after the poses before it
                ended, error = True, exc
                return
            job = None if pool is None else pool.submit(odometry.prepare, scan.points, scan.times_s, scan.rings,
                                                        first=first)
            pending.append((scan, job, first))
            first = False

    try:
        top_up()
        while pending:
            scan, job, is_first = pending.popleft()
            prepared = (job.result() if job is not None
                        else odometry.prepare(scan.points, scan.times_s, scan.rings, first=is_first))
            if pool is not None:
                top_up()  # (the next preparations start before this registration)
            yield odometry.register_prepared(prepared, stamp_s=scan.stamp_s, true_motion=scan.true_motion)
            if pool is None:
                top_up()  # (one thing at a time: the next scan is read after this one is registered)
    finally:  # (an error, or a caller that stops early: the preparations not started are dropped)
        for _, job, _ in pending:
            if job is not None:
                job.cancel()
    if error is not None:
        raise error


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
    true_poses: np.ndarray | None = None,
    prefetch: int | None = None,
) -> OdometryRun:
    """Run the odometry over (a slice of) a sequence; ``on_frame(k, diagnostics)`` after each frame.

    The poses are relative to the first frame run. The sensor defaults to the sequence's own.
    true_poses: (F, 4, 4) the sequence's true poses, for an open-loop run (``Odometry.register``'s
    ``true_motion``): the state follows the truth, each frame's estimate is in its diagnostics.
    prefetch: scans prepared ahead on threads of their own (``register_frames``; 0: none; None: the default).
    """
    sensor = sensor or sequence.sensor
    idx = np.arange(len(sequence))[frames or slice(None)]
    if len(idx) == 0:
        raise OdometryError(f"{sequence.path}: no frames selected")
    if true_poses is not None and len(true_poses) != len(sequence):
        raise OdometryError(f"{sequence.path}: {len(true_poses)} true poses for {len(sequence)} frames")
    odo = Odometry(config, sensor)

    def scans() -> Iterator[ScanInput]:
        for j, k in enumerate(idx):
            frame = sequence[int(k)]
            stamp = float(sequence.times[k]) if sequence.times is not None and k < len(sequence.times) else None
            truth = None if true_poses is None or j == 0 else se3.inverse(true_poses[idx[j - 1]]) @ true_poses[k]
            yield ScanInput(frame.points, deskew_times(sequence, frame), frame.ring, stamp, truth)

    t0 = time.perf_counter()
    for k, _ in zip(idx, register_frames(odo, scans(), prefetch), strict=True):
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


__all__ = ["DegenerateStretch", "Odometry", "OdometryError", "PreparedScan", "ScanInput", "degenerate_stretches",
           "register_frames", "run_sequence", "stretches_of"]
