"""Odometry over a sequence: the variants BL, NCF and SALO of the paper's table, scan-to-scan or scan-to-map.

One scan's registration is four stages, each a method of ``Odometry`` with its inputs and
outputs in its signature::

    prepare   clean, voxel grid, normals, NCF, curvature; poles       (odometry.preparation; no state)
    predict   the constant-velocity motion guess (with ``imu.enabled`` and the sequence's IMU: the
              preintegrated IMU's, odometry.inertial); the scan de-skewed with it
    align     the motion: the cold start (the second scan, odometry.cold_start) or tracking
              (ICP from the guess, the scan re-de-skewed at every step), then the de-skew
              refinements; an estimate far from the guess is no motion (extrapolated)
    update    pose = previous pose x motion; the motion prior (and the IMU's velocity and biases); the
              scan, de-skewed with the motion, becomes the next target or joins the map

``register_frames`` (and ``run_sequence`` over it) prepares the next scans on threads of their
own while the current one registers: the same poses, both cores at work. The open-loop harness
(``odometry.open_loop``) calls the same stages, but advances the state with the true motion.
"""

from __future__ import annotations

import functools
import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from simlidar import se3
from simlidar.formats.scan_folders import Sequence
from simlidar.sensor import LidarModel
from simlidar.sequence import DEFAULT_FRAME_PERIOD_S, Frame, deskew_times, method_frame

from .cold_start import better_constrained, coarse_config, first_registration
from .config import OdometryConfig
from .deskew import RedeskewMemo, redeskew_scan
from .diagnostics import FrameDiagnostics
from .dynamic import FreeSpace, drop_rows, sensor_frame_points
from .filters import FilteredScan, background, scan_normals_needed
from .icp import NearestCache, RegistrationResult, Source, Target, match, register, rejectors_for
from .inertial import InertialOdometry
from .kdtree import KDTree
from .local_map import LocalMap
from .poles import PoleMap, WeatherGate
from .preparation import PreparedScan, prepare_scan
from .rejectors import Rejector
from .targets import filtered_scan_target, make_source, map_points, new_local_map

log = logging.getLogger(__name__)


class OdometryError(ValueError):
    """The odometry cannot run on this input; the message says how to fix it."""


@dataclass
class OdometryState:
    """What the odometry carries from frame to frame.

    poses: ``T_world_lidar`` (4, 4) of every frame so far; the world is the first scan's frame.
    T_prev_cur: the last frame-to-frame motion (4, 4): the constant-velocity prediction.
    last_stamp_s, last_period_s: the previous sweep's start time and period, s.
    target_scan: the last scan that had points (scan-to-scan target; and the first
        scan until the first registration, for the cold start).
    target_frame: its frame index. target_motion: the motion its points are de-skewed with.
    target_tree: scan-to-scan: (the target's points, a future of the k-d tree over them), built on
        the background thread while the next scan is prepared; None before.
    local_map: the map of recent scans (``match.target: map``), else None.
    pole_map: the poles of recent frames (``poles.enabled``, with a sensor), else None.
    weather_gate: whether the scans are in weather, for the poles' clutter filter (``poles.clutter_filter``),
        else None.
    free_space: the free space of recent registered scans (``dynamic.enabled``), else None.
    """

    poses: list[np.ndarray] = field(default_factory=list)
    T_prev_cur: np.ndarray = field(default_factory=lambda: np.eye(4))
    last_stamp_s: float | None = None
    last_period_s: float | None = None
    target_scan: FilteredScan | None = None
    target_frame: int = 0
    target_motion: np.ndarray = field(default_factory=lambda: np.eye(4))
    target_tree: tuple[np.ndarray, Future] | None = None
    local_map: LocalMap | None = None
    pole_map: PoleMap | None = None
    weather_gate: WeatherGate | None = None
    free_space: FreeSpace | None = None


@dataclass
class FrameInProgress:
    """One scan on its way through ``predict``, ``align`` and ``update``.

    prepared: the scan cleaned and filtered (``prepare``). period_s: the frame's period, s.
    T_guess: (4, 4) the constant-velocity prediction of its motion ``T_prev_cur``.
    T_deskew: (4, 4) the motion its ICP points are de-skewed with now (the guess, until the
    alignment moves it); xi_deskew: its (6,) twist. memo: the points' re-de-skew memo
    (``deskew.redeskew``). started_s: when ``predict`` began (``time.perf_counter``).
    sweep_correction: with the IMU's prediction, (4, 4) ``T_guess^-1 S`` (S: the IMU's motion over
    the scan's own sweep), which a frame motion is composed with to de-skew the sweep; None: the
    frame's motion is the sweep's (constant velocity).
    """

    prepared: PreparedScan
    period_s: float
    T_guess: np.ndarray
    T_deskew: np.ndarray
    xi_deskew: np.ndarray
    memo: RedeskewMemo
    started_s: float
    sweep_correction: np.ndarray | None = None

    @property
    def scan(self) -> FilteredScan:
        return self.prepared.scan

    @property
    def diag(self) -> FrameDiagnostics:
        return self.prepared.diag

    @property
    def seconds(self) -> dict:
        return self.prepared.seconds

    @property
    def deskewing(self) -> bool:
        return self.prepared.deskewing

    def sweep_motion(self, motion: np.ndarray) -> np.ndarray:
        """The sweep's motion (4, 4) for a frame motion ``T_prev_cur`` (4, 4): the same (constant velocity),
        or with the IMU, the frame motion changed as the IMU says the sweep's differs from it."""
        return motion if self.sweep_correction is None else motion @ self.sweep_correction

    def deskew_with(self, motion: np.ndarray) -> None:
        """Re-de-skew the scan's ICP points, normals and poles with ``motion`` (4, 4) instead of ``T_deskew``."""
        xi = se3.log(motion)
        redeskew_scan(self.scan, self.xi_deskew, xi, self.period_s, memo=self.memo)
        self.T_deskew, self.xi_deskew = motion, xi


@dataclass
class Placement:
    """Where the previous pose sits in a registration's target frame: the world for a map; for
    scan-to-scan the target scan's frame, usually the previous frame's (then exactly the identity:
    rounding must not feed back).

    T_target_prev: (4, 4). previous_is_target: the target is the previous scan.
    """

    T_target_prev: np.ndarray
    previous_is_target: bool

    def motion_of(self, T_target_cur: np.ndarray) -> np.ndarray:
        """The motion ``T_prev_cur`` (4, 4) of a registration's estimate ``T_target_cur``."""
        return T_target_cur if self.previous_is_target else se3.inverse(self.T_target_prev) @ T_target_cur


@dataclass
class Registration:
    """The ICP runs of one frame's alignment against one target.

    result: the latest estimate. runs: every ICP run of the frame (their iterations and times add
    up in the diagnostics). cold_start_kind: the cold start's target ("map": the map of the first
    scan, or for scan-to-scan the first scan; "scan": a map variant's first scan itself), None
    when tracking. cold_starts: the cold start's first registration against each of its targets.
    """

    place: Placement
    source: Source
    target: Target
    nearest: NearestCache
    chain: list[Rejector]
    result: RegistrationResult
    runs: list[RegistrationResult]
    cold_start_kind: str | None = None
    cold_starts: dict[str, RegistrationResult] = field(default_factory=dict)


@dataclass
class Alignment:
    """What ``align`` gives ``update``: the frame's motion ``T_prev_cur`` (4, 4), and the target it was
    registered against with that target's search cache (None: it was not registered)."""

    motion: np.ndarray
    target: Target | None = None
    nearest: NearestCache | None = None


def plausible(T_guess: np.ndarray, T: np.ndarray, config: OdometryConfig) -> bool:
    """Whether a motion estimate ``T`` (4, 4) is within ``icp.max_prediction_error_*`` of the guess: a car
    cannot change its motion by metres within one frame, so a larger change is a failed registration
    (a degenerate scene, a wrong local minimum), not motion."""
    deviation = se3.inverse(T_guess) @ T
    return not (np.linalg.norm(deviation[:3, 3]) > config.icp.max_prediction_error_m
                or np.degrees(se3.rotation_angle(deviation)) > config.icp.max_prediction_error_deg)


class Odometry:
    """ICP odometry (Alg. 1) with the paper's filters and rejectors, scan-to-scan or scan-to-map.

    Args:
        config: the variant's parameters (``odometry.config``).
        sensor: the lidar model; needed by the GCR (ring pitches, azimuth step),
            and by the sensor-aware NCF for its range noise unless the config sets it.
        imu: the sequence's IMU samples (``simlidar.imu.ImuSamples``, the stamps' time base), or None;
            used with ``imu.enabled`` (``odometry.inertial``: its mounting from the sensor's ``imu``
            section), and only for scans registered with their ``stamp_s``.

    ``register`` returns the pose ``T_world_lidar`` (4, 4) of each scan in the first scan's
    frame; ``last`` holds the latest ``FrameDiagnostics``. The stages: the module's docstring.
    """

    def __init__(self, config: OdometryConfig, sensor: LidarModel | None = None, imu=None):
        if config.gcr.enabled and sensor is None:
            raise OdometryError(
                f"variant '{config.name}' uses the geometric correspondence rejector, which needs the "
                "sensor's ring table: pass --sensor PRESET|FILE (or use a sequence folder with sensor.yaml)"
            )
        if config.dynamic.enabled and sensor is None:
            raise OdometryError(
                f"variant '{config.name}' uses the moving-object stage (dynamic.enabled), which needs the sensor's "
                "rings and azimuth step: pass --sensor PRESET|FILE (or use a sequence folder with sensor.yaml)")
        self.config = config
        self.sensor = sensor
        # (poles need the sensor's range image: its rings and azimuth columns)
        self.with_poles = config.poles.enabled and sensor is not None
        self.state = OdometryState(local_map=new_local_map(config, sensor) if config.match.target == "map" else None,
                                   pole_map=self._new_pole_map() if self.with_poles else None,
                                   weather_gate=WeatherGate() if self.with_poles and config.poles.clutter_filter
                                   else None,
                                   free_space=FreeSpace(config.dynamic, sensor) if config.dynamic.enabled else None)
        self.diagnostics: list[FrameDiagnostics] = []
        self.inertial = None
        if config.imu.enabled and imu is not None and len(imu) >= 2:
            from simlidar.imu import ImuModel

            self.inertial = InertialOdometry(imu, sensor.imu if sensor is not None else ImuModel(), config.imu)
        # The rejection chains, built once: with GCR, and without (the cold start: GCR needs a close guess)
        self._chain_with_gcr = rejectors_for(config)
        self._chain_without_gcr = rejectors_for(config.replace(gcr={"enabled": False}))
        self._coarse_config = coarse_config(config)
        self._chain_coarse = rejectors_for(self._coarse_config)
        # A map variant's cold start registers against the map of the first scan and the scan itself
        # (``odometry.cold_start``); scan-to-scan against its usual target, the first scan.
        self._cold_start_kinds = ("map", "scan") if config.match.target == "map" else ("map",)

    @property
    def poses(self) -> list[np.ndarray]:
        return self.state.poses

    @property
    def last(self) -> FrameDiagnostics | None:
        return self.diagnostics[-1] if self.diagnostics else None

    def register_frame(self, frame: Frame, stamp_s: float | None = None) -> np.ndarray:
        """``register`` with a ``simlidar.sequence.Frame`` (uses its ring and time fields)."""
        return self.register(frame.points, times_s=frame.time_s, rings=frame.ring, stamp_s=stamp_s)

    def register(self, points: np.ndarray, times_s: np.ndarray | None = None, rings: np.ndarray | None = None,
                 stamp_s: float | None = None) -> np.ndarray:
        """Register the next scan and return its pose ``T_world_lidar`` (4, 4).

        points: (N, 3) as measured, m. times_s: (N,) per-point time since the sweep
        start, s (enables de-skew). rings: (N,) int ring per point (else from the
        elevation and the sensor table). stamp_s: the sweep's start time, s.
        """
        return self.register_prepared(self.prepare(points, times_s, rings, first=not self.poses), stamp_s)

    def register_prepared(self, prepared: PreparedScan, stamp_s: float | None = None) -> np.ndarray:
        """``register`` of a scan ``prepare`` cleaned and filtered (once: it is de-skewed in place)."""
        frame = self.predict(prepared, stamp_s)  # the constant-velocity guess; the scan de-skewed with it
        alignment = self.align(frame)  # the frame's motion: cold start or tracking, de-skew refined
        self.update(frame, alignment)  # pose, motion prior, the next target or the map
        self.conclude(frame)  # the frame's diagnostics
        return self.poses[-1]

    # ---- the stages
    def prepare(self, points: np.ndarray, times_s: np.ndarray | None = None, rings: np.ndarray | None = None,
                first: bool = False) -> PreparedScan:
        """Clean and filter a scan as measured (``odometry.preparation``): the stage that reads no state.

        points: (N, 3) m; times_s, rings: (N,) or None, as ``register`` takes them. first: the
        sequence's first scan (a map variant's cold start needs its normals). Reads only the config
        and the sensor, so it may run on another thread while the previous scan registers.
        """
        with_normals = scan_normals_needed(self.config) or ("scan" in self._cold_start_kinds and first)
        return prepare_scan(points, times_s, rings, self.config, self.sensor, with_normals, self.with_poles)

    def predict(self, prepared: PreparedScan, stamp_s: float | None = None) -> FrameInProgress:
        """The frame's period and constant-velocity motion guess; the scan's ICP points, normals and
        centroids de-skewed with that guess (with per-point times)."""
        if prepared.registered:
            raise OdometryError("this prepared scan was registered already (its points are de-skewed in place): "
                                "prepare it again")
        prepared.registered = True
        started = time.perf_counter()
        prepared.diag.frame = len(self.poses)
        previous_stamp = self.state.last_stamp_s
        period = self._frame_period(stamp_s)
        T_guess, correction = self._predicted_motion(period), None
        if self.inertial is not None and self.poses:
            imu = self.inertial.predict(self.poses[-1], previous_stamp, stamp_s, period)
            if imu is not None:
                T_guess, correction = imu.motion, se3.inverse(imu.motion) @ imu.sweep
        T_sweep = T_guess if correction is None else T_guess @ correction
        self._drop_weather_poles(prepared)
        self._drop_moving(prepared, T_guess, period)
        prepared.diag.deskewed = prepared.deskewing
        t = time.perf_counter()
        memo = RedeskewMemo()
        if prepared.deskewing:  # (filtered as measured: its ICP points, normals and centroids follow the motion)
            redeskew_scan(prepared.scan, np.eye(4), T_sweep, period, centroids_motion=np.eye(4), memo=memo)
        prepared.seconds["deskew"] = time.perf_counter() - t
        prepared.diag.too_few_points = len(prepared.scan) < self.config.filter.min_points
        return FrameInProgress(prepared, period, T_guess, T_sweep, se3.log(T_sweep), memo, started, correction)

    def align(self, frame: FrameInProgress) -> Alignment:
        """The frame's motion ``T_prev_cur``: the identity for the first scan, the guess for a scan that
        cannot be registered, else the cold start (the second scan) or tracking, then the de-skew
        refinements, and the guess again for a failed registration (singular, or implausible)."""
        st = self.state
        if not st.poses:
            return Alignment(np.eye(4))
        if frame.diag.too_few_points or (st.target_scan is None and st.local_map is None):
            return Alignment(frame.T_guess)
        cold = len(st.poses) == 1
        reg = self.cold_start(frame) if cold else self.track(frame)
        self.refine(frame, reg)
        frame.diag.record(reg.result)
        frame.diag.iterations = sum(r.iterations for r in reg.runs)
        frame.seconds.update({stage: sum(r.seconds.get(stage, 0.0) for r in reg.runs)
                              for stage in reg.runs[-1].seconds})
        if reg.result.singular:
            return Alignment(frame.T_guess, reg.target, reg.nearest)
        T = se3.orthonormalize(reg.place.motion_of(reg.result.T_target_source))
        if not cold and not plausible(frame.T_guess, T, self.config):
            frame.diag.implausible = True
            T = frame.T_guess
        return Alignment(T, reg.target, reg.nearest)

    def cold_start(self, frame: FrameInProgress) -> Registration:
        """The sequence's first registration (``odometry.cold_start``), against each cold-start target,
        keeping the better constrained; without GCR, which needs a close guess."""
        place = self._placement()
        source = make_source(frame.scan, self.config, self.sensor, with_gcr=False)
        T_init = place.T_target_prev @ frame.T_guess
        starts, runs = [], []
        for kind in self._cold_start_kinds:
            target, nearest = self._cold_start_target(kind), NearestCache()
            result, tried = first_registration(source, target, T_init, self.config, self._chain_without_gcr,
                                               self._coarse_config, self._chain_coarse, place.T_target_prev, nearest)
            starts.append((kind, target, nearest, result))
            runs += tried
        kind, target, nearest, result = starts[better_constrained([s[3] for s in starts])]
        if len(starts) > 1:
            log.info("first registration against the %s (weakest translational information per match: %s)",
                     "first scan" if kind == "scan" else "map of the first scan",
                     ", ".join(f"{k} {r.translation_eigenvalues[0]:.3g}" for k, _, _, r in starts))
        return Registration(place, source, target, nearest, self._chain_without_gcr, result, runs, kind,
                            {s[0]: s[3] for s in starts})

    def track(self, frame: FrameInProgress) -> Registration:
        """Register the scan against the previous scan or the map from the constant-velocity guess. With
        per-point times the scan is re-de-skewed at every ICP step, its de-skew motion moving halfway
        towards the estimate's (the damped update of ``refine``); the ICP stops when its step and that
        move are both below the termination thresholds."""
        cfg = self.config
        place = self._placement()
        chain = self._chain_with_gcr if cfg.gcr.enabled else self._chain_without_gcr
        source = make_source(frame.scan, cfg, self.sensor, with_gcr=cfg.gcr.enabled)
        target, nearest = self._target(), NearestCache()
        reskew = None
        if frame.deskewing:
            def reskew(T_target_cur: np.ndarray) -> np.ndarray:
                before = frame.T_deskew
                frame.deskew_with(halfway(frame.xi_deskew, frame.sweep_motion(place.motion_of(T_target_cur))))
                source.points = frame.scan.points
                source.poles = None if frame.scan.poles is None else frame.scan.poles.points
                return se3.log(se3.inverse(before) @ frame.T_deskew)

        result = register(source, target, place.T_target_prev @ frame.T_guess, cfg, chain, place.T_target_prev,
                          reskew=reskew, nearest=nearest)
        return Registration(place, source, target, nearest, chain, result, [result])

    def refine(self, frame: FrameInProgress, reg: Registration) -> None:
        """The de-skew refinements (``deskew.refinements``, with per-point times): re-de-skew the scan with
        the frame's own estimate and register again from it (``reg`` takes the new result).

        The estimate responds to the de-skew motion with a gain near -1 (a too-fast de-skew makes the
        scan look closer), so plain re-use of the estimate oscillates: the de-skew motion moves halfway
        towards the estimate's (a damped fixed-point iteration). At the cold start the first scan was
        de-skewed as if standing still: both scans take the estimate as it is, so that source and
        target share one motion model. Only the filtered points move; the GCR thresholds scale with
        range and incidence, which a re-de-skew by centimetres does not change, and are reused.
        """
        st = self.state
        for _ in range(self.config.deskew.refinements if frame.deskewing else 0):
            if reg.result.singular:
                break
            motion = reg.place.motion_of(reg.result.T_target_source)
            if reg.cold_start_kind is not None and st.target_scan is not None and st.target_scan.times_s is not None:
                self._redeskew_first_scan(motion, frame.period_s)
                reg.target, reg.nearest = self._cold_start_target(reg.cold_start_kind), NearestCache()
                frame.deskew_with(motion)
            else:
                frame.deskew_with(halfway(frame.xi_deskew, frame.sweep_motion(motion)))
            scan = frame.scan
            reg.source = Source(scan.points, scan.normals, reg.source.gcr_threshold_m,
                                poles=None if scan.poles is None else scan.poles.points)
            refined = register(reg.source, reg.target, reg.result.T_target_source, self.config, reg.chain,
                               reg.place.T_target_prev, reg.cold_start_kind is None, nearest=reg.nearest)
            reg.runs.append(refined)
            if refined.singular:  # keep the last good estimate: the frame is not extrapolated
                break
            reg.result = refined

    def update(self, frame: FrameInProgress, alignment: Alignment) -> None:
        """Pose and motion prior from the frame's motion; the scan, de-skewed with that motion, becomes the
        next target or joins the map (and its poles the pole map), so that source and target share one
        motion model."""
        st = self.state
        T, scan = alignment.motion, frame.scan
        # (re-orthonormalised: with a map, T = previous^-1 x estimate feeds rounding back)
        pose = se3.orthonormalize(st.poses[-1] @ T) if st.poses else np.eye(4)
        if self.inertial is not None:
            self._update_inertial(frame, pose)
        if st.poses:
            st.T_prev_cur = T
        st.poses.append(pose)
        st.last_period_s = frame.period_s
        if frame.diag.too_few_points:
            return
        t = time.perf_counter()
        redo = frame.deskewing and len(st.poses) > 1
        T_sweep = frame.sweep_motion(T)
        if redo:  # (its centroids are still de-skewed with the guess)
            centroids = frame.sweep_motion(frame.T_guess)
            redeskew_scan(scan, frame.T_deskew, T_sweep, frame.period_s, centroids_motion=centroids, memo=frame.memo)
        st.target_scan = scan
        st.target_frame = len(st.poses) - 1
        st.target_motion = T_sweep if redo else frame.T_deskew
        if st.local_map is None:  # (the next target's tree, built while the next scan is prepared)
            st.target_tree = (scan.points, background().submit(KDTree, scan.points))
        else:
            points_world = map_points(scan, pose)
            st.local_map.update(points_world, pose[:3, 3], nearest_m=self._map_nearest_m(points_world, alignment))
        if st.pole_map is not None and scan.poles is not None:
            st.pole_map.add(se3.transform_points(pose, scan.poles.points), scan.poles.cluttered)
        # (the first scan's motion within its sweep is unknown when it is kept: its free space is not)
        if st.free_space is not None and not (frame.deskewing and len(st.poses) == 1):
            clean = frame.prepared.clean
            st.free_space.add(clean.points, clean.times_s if frame.deskewing else None, frame.period_s, pose, T)
        stage = "map" if st.local_map is not None else "deskew"  # (the re-de-skew counts with the map's update)
        frame.seconds[stage] = frame.seconds.get(stage, 0.0) + time.perf_counter() - t

    def _update_inertial(self, frame: FrameInProgress, pose: np.ndarray) -> None:
        """The IMU's filter takes the frame's pose (4, 4) (before ``update`` moves the target), with the
        registration's information on its translation per match, from its target's frame to the world, and
        the pose the registration started from (its guess, held to in weak directions; none at the cold start,
        whose registration holds to nothing)."""
        st, diag = self.state, frame.diag
        info = None
        if np.all(np.isfinite(diag.translation_information)):
            R_world_target = (np.eye(3) if st.local_map is not None or not st.poses
                              else st.poses[st.target_frame][:3, :3])
            info = R_world_target @ diag.translation_information @ R_world_target.T
        # (the cold start, the second scan, holds its registration to no prediction: all it moved is the data's)
        predicted = st.poses[-1] @ frame.T_guess if len(st.poses) > 1 else None
        deg = self.config.degeneracy
        self.inertial.update(pose, st.last_stamp_s, info, not diag.extrapolated, predicted,
                             deg.min_constraint_eigenvalue, deg.weak_direction_update)

    def conclude(self, frame: FrameInProgress) -> None:
        """The frame's diagnostics: its total time (its preparation's included, wherever that ran), kept
        in ``diagnostics``; an extrapolated pose is logged."""
        diag = frame.diag
        frame.seconds["total"] = time.perf_counter() - frame.started_s + frame.prepared.seconds_spent
        diag.seconds = frame.seconds
        self.diagnostics.append(diag)
        if diag.extrapolated:
            why = ("too few points after filtering" if diag.too_few_points else "singular system" if diag.singular
                   else "estimate too far from the constant-velocity prediction")
            # INFO, not WARNING: a degenerate stretch flags frame after frame, which would bury a
            # progress bar; the diagnostics carry the flags and the commands print their count.
            log.info("frame %d: %s; pose extrapolated", diag.frame, why)

    def _drop_weather_poles(self, prepared: PreparedScan) -> None:
        """The poles' clutter filter (``poles.clutter_filter``): on a scan in weather (``poles.WeatherGate``, which
        remembers the scans before) the poles weather would make leave the scan's poles, and those left wait
        for the pole map's confirmation; a clear scan's stay as they are."""
        poles, gate = prepared.scan.poles, self.state.weather_gate
        if poles is None or gate is None:
            return
        if gate.update(poles.clutter_per_beam):
            prepared.scan.poles = poles.without_suspects()
        prepared.scan.counts["poles_weather"] = prepared.scan.poles.dropped

    def _drop_moving(self, prepared: PreparedScan, T_guess: np.ndarray, period_s: float) -> None:
        """The moving-object stage (``odometry.dynamic``, ``dynamic.enabled``): the scan's points (as measured)
        at places a recent scan saw through, placed with the predicted pose, leave its ICP points and centroids;
        ``prepared.moving`` keeps the verdict on each centroid. Nothing is dropped where too few points would
        stay (the frame is then flagged as it would be), nor at the cold start: its guess is no motion at all, and
        a scan placed a metre off would stand in the free space its own surfaces left."""
        st = self.state
        if st.free_space is None or len(st.poses) < 2:
            return
        t = time.perf_counter()
        scan = prepared.scan
        T_world_start = st.poses[-1] @ T_guess
        times = scan.centroid_times_s if prepared.deskewing else None
        moving_c = st.free_space.moving_points(
            sensor_frame_points(scan.centroids, times, period_s, T_world_start, T_guess, measured=True))
        if scan.points is scan.centroids:
            moving_p = moving_c
        else:
            times = scan.times_s if prepared.deskewing else None
            moving_p = st.free_space.moving_points(
                sensor_frame_points(scan.points, times, period_s, T_world_start, T_guess, measured=True))
        if len(moving_p) - int(moving_p.sum()) < self.config.filter.min_points:
            moving_p, moving_c = np.zeros(len(moving_p), dtype=bool), np.zeros(len(moving_c), dtype=bool)
        prepared.moving = moving_c
        if moving_p.any():
            drop_rows(scan, ~moving_p, ~moving_c)
        scan.counts["moving"] = int(moving_p.sum())
        poles = scan.poles
        if poles is not None and len(poles):  # (a narrow moving thing is no pole to hold the pose by)
            times = poles.times_s if prepared.deskewing else None
            still = ~st.free_space.moving_points(
                sensor_frame_points(poles.points, times, period_s, T_world_start, T_guess, measured=True))
            scan.poles = poles.subset(still)
            scan.counts["moving_poles"] = int((~still).sum())
        prepared.seconds["dynamic"] = time.perf_counter() - t

    # ---- what the stages read of the state
    def _new_pole_map(self) -> PoleMap:
        return PoleMap(self.config.poles.frames_kept, confirmed_only=self.config.poles.clutter_filter)

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

    def _placement(self) -> Placement:
        st = self.state
        T_world_prev = st.poses[-1]
        if st.local_map is not None:
            return Placement(T_world_prev, False)
        if st.target_frame == len(st.poses) - 1:
            return Placement(np.eye(4), True)
        return Placement(se3.inverse(st.poses[st.target_frame]) @ T_world_prev, False)

    def _target(self) -> Target:
        """The previous scan (its own frame) or the map (the world frame), with the recent poles."""
        st = self.state
        if st.local_map is not None:
            return self._with_poles(st.local_map.target())
        pending = st.target_tree
        tree = pending[1].result() if pending is not None and pending[0] is st.target_scan.points else None
        return self._with_poles(filtered_scan_target(st.target_scan, tree))

    def _with_poles(self, target: Target) -> Target:
        """``target`` with the recent frames' poles in its frame (the world for a map, else the target scan's)."""
        st = self.state
        if st.pole_map is not None:
            into = None if st.local_map is not None else se3.inverse(st.poses[st.target_frame])
            target.poles = st.pole_map.target(into)
        return target

    def _cold_start_target(self, kind: str) -> Target:
        """A cold-start target: the first scan's own points and normals (in the world frame, which is its
        frame) for ``kind`` scan, else the usual target (the map of that scan, or the scan)."""
        scan = self.state.target_scan
        if kind == "scan" and scan is not None and len(scan.points):
            return self._with_poles(filtered_scan_target(scan))
        return self._target()

    def _redeskew_first_scan(self, motion: np.ndarray, period_s: float) -> None:
        """The cold start's refinement: the first scan, de-skewed as if standing still, re-de-skewed with
        ``motion`` (4, 4); its map and poles rebuilt from it."""
        cfg, st = self.config, self.state
        redeskew_scan(st.target_scan, st.target_motion, motion, period_s, centroids_motion=st.target_motion)
        st.target_motion = motion
        if st.local_map is not None:
            st.local_map = new_local_map(cfg, self.sensor)
            st.local_map.update(map_points(st.target_scan, st.poses[0]), st.poses[0][:3, 3])
        if st.pole_map is not None and st.target_scan.poles is not None:
            st.pole_map = self._new_pole_map()
            st.pole_map.add(se3.transform_points(st.poses[0], st.target_scan.poles.points),
                            st.target_scan.poles.cluttered)

    def _map_nearest_m(self, points_world: np.ndarray, alignment: Alignment) -> np.ndarray | None:
        """(N,) each world point's distance to its nearest map point, inf beyond the match bound, m: the
        map's spacing check without a search of its own where the ICP's last one still holds (``icp.match``
        with the alignment's cache: the points moved by millimetres since). None when the alignment's
        target is not the map as it stands, or the bound is below the map's point spacing (the answer
        would not decide)."""
        st, bound, target = self.state, self.config.match.max_correspondence_distance_m, alignment.target
        if (target is None or st.local_map is None or target.points is not st.local_map.points
                or st.local_map.min_spacing_m > bound):
            return None
        nearest = np.full(len(points_world), np.inf)
        m = match(points_world, target, bound, alignment.nearest)
        nearest[m.source_index] = m.distance_m
        return nearest


def halfway(xi_deskew: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """The damped de-skew update: the motion (4, 4) halfway from the de-skew twist ``xi_deskew`` (6,) to
    ``motion`` (4, 4), in the tangent space."""
    return se3.exp(0.5 * (xi_deskew + se3.log(motion)))


# ---------------------------------------------------------------- sequences and files
class ScanInput(NamedTuple):
    """One scan for ``register_frames``: ``Odometry.register``'s arguments.

    points: (N, 3) m; times_s, rings: (N,) or None; stamp_s: the sweep's start, s, or None.
    """

    points: np.ndarray
    times_s: np.ndarray | None = None
    rings: np.ndarray | None = None
    stamp_s: float | None = None


# Scans prepared ahead by default (``register_frames``). Where a scan's preparation holds its normals and
# NCF (scan-to-scan, about as long as its registration) two threads preparing the next two keep both cores
# busy; one ahead left the registering thread waiting. Where it is a voxel grid and poles only (the map
# variants: their normals are the map's) one: with the registration's steps compiled, its ~5 ms a frame
# beside the registration gained in each of five interleaved comparisons (100 city frames, 4-8 rounds:
# the default at 0.90-1.00x against 0.92-1.07x KISS-ICP's time on hdl32e with one ahead and none in
# three, 0.76-0.80x against 0.83-0.84x on salo32 in two; two ahead no better; docs/speed-history.md).
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
        if config is None or scan_normals_needed(config):
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


def _read_and_prepare(odometry: Odometry, scan, first: bool) -> tuple[ScanInput, PreparedScan]:
    """A scan (read first when it is a function that reads it) and its preparation."""
    scan = scan() if callable(scan) else scan
    return scan, odometry.prepare(scan.points, scan.times_s, scan.rings, first=first)


def prepared_scans(odometry: Odometry, scans: Iterable[ScanInput | Callable[[], ScanInput]],
                   prefetch: int | None = None) -> Iterator[tuple[ScanInput, PreparedScan]]:
    """Each of ``scans`` in order with its preparation (``Odometry.prepare``), for the caller to register.

    scans: ScanInputs, or functions that read one (``scan_inputs``: read ahead with the preparation).
    prefetch: scans prepared ahead, each on a thread of its own, while the caller registers the
    current one (0: none, one thing at a time; None: ``default_prefetch`` of the odometry's config).
    A preparation reads no state, so the poses are those of one scan after another. ``scans`` is
    advanced by this thread only; an error it raises (a file that cannot be read) comes after the
    scans before it.
    """
    prefetch = default_prefetch(odometry.config) if prefetch is None else prefetch
    if prefetch < 0:
        raise ValueError(f"prefetch must be >= 0 scans, got {prefetch}")
    it = iter(scans)
    pool = _prefetcher(prefetch) if prefetch > 0 else None
    pending: deque = deque()  # (scan, its preparation: a future, or None to prepare here, first?), in order
    first = not odometry.poses
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
            except Exception as exc:  # noqa: BLE001 - raised in its turn, after the scans before it
                ended, error = True, exc
                return
            job = None if pool is None else pool.submit(_read_and_prepare, odometry, scan, first)
            pending.append((scan, job, first))
            first = False

    try:
        top_up()
        while pending:
            scan, job, is_first = pending.popleft()
            scan, prepared = job.result() if job is not None else _read_and_prepare(odometry, scan, is_first)
            if pool is not None:
                top_up()  # (the next preparations start before this registration)
            yield scan, prepared
            if pool is None:
                top_up()  # (one thing at a time: the next scan is read after this one is registered)
    finally:  # (an error, or a caller that stops early: the preparations not started are dropped)
        for _, job, _ in pending:
            if job is not None:
                job.cancel()
    if error is not None:
        raise error


def register_frames(odometry: Odometry, scans: Iterable[ScanInput], prefetch: int | None = None
                    ) -> Iterator[np.ndarray]:
    """Register ``scans`` in order with ``odometry``; yield each pose ``T_world_lidar`` (4, 4).

    prefetch: scans prepared ahead on threads of their own (``prepared_scans``). The poses are those of
    ``Odometry.register`` frame after frame.
    """
    for scan, prepared in prepared_scans(odometry, scans, prefetch):
        yield odometry.register_prepared(prepared, stamp_s=scan.stamp_s)


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


def frames_of(sequence: Sequence, frames: slice | None = None) -> np.ndarray:
    """The indices of a slice of ``sequence``'s frames (all by default); OdometryError when none."""
    idx = np.arange(len(sequence))[frames or slice(None)]
    if len(idx) == 0:
        raise OdometryError(f"{sequence.path}: no frames selected")
    return idx


def scan_inputs(sequence: Sequence, idx: np.ndarray) -> Iterator[Callable[[], ScanInput]]:
    """The frames ``idx`` of a sequence as the odometry takes them: for each, a function that reads it
    (``prepared_scans`` calls it on a preparing thread, so reading overlaps the registration; the reads
    are taken one at a time, as a reader with one open file needs)."""
    lock = threading.Lock()

    def read(k: int) -> ScanInput:
        with lock:
            frame = method_frame(sequence, k)
        stamp = float(sequence.times[k]) if sequence.times is not None and k < len(sequence.times) else None
        return ScanInput(frame.points, deskew_times(sequence, frame), frame.ring, stamp)

    for k in idx:
        yield functools.partial(read, int(k))


def run_sequence(
    sequence: Sequence,
    config: OdometryConfig,
    sensor: LidarModel | None = None,
    frames: slice | None = None,
    on_frame: Callable[[int, FrameDiagnostics], None] | None = None,
    prefetch: int | None = None,
) -> OdometryRun:
    """Run the odometry over (a slice of) a sequence; ``on_frame(k, diagnostics)`` after each frame.

    The poses are relative to the first frame run. The sensor defaults to the sequence's own. With
    ``imu.enabled``, the sequence's IMU (``sequence.imu``, when it has one) goes to the odometry.
    prefetch: scans prepared ahead on threads of their own (``register_frames``; 0: none; None: the default).
    """
    idx = frames_of(sequence, frames)
    imu = getattr(sequence, "imu", None) if config.imu.enabled else None
    odo = Odometry(config, sensor or sequence.sensor, imu=imu)
    t0 = time.perf_counter()
    for k, _ in zip(idx, register_frames(odo, scan_inputs(sequence, idx), prefetch), strict=True):
        if on_frame is not None:
            on_frame(int(k), odo.last)
    times = None if sequence.times is None else np.asarray(sequence.times)[idx]
    return OdometryRun(np.stack(odo.poses), idx, times, odo.diagnostics, config, time.perf_counter() - t0)


__all__ = ["Odometry", "OdometryError", "OdometryRun", "PreparedScan", "ScanInput", "prepared_scans",
           "register_frames", "run_sequence"]
