"""The two jobs every command, sweep, experiment and the demo do, written once.

- ``simulate_scene``: a built scene (``tools.worlds.SceneWorld``) to a simulated
  sequence folder: check that the path has room for the frames, record the
  scene and the noise in the manifest, simulate.
- ``run_method``: our odometry over a sequence: run it, write its outputs
  (KITTI poses, the per-frame diagnostics CSV, the resolved config, TUM), count
  the frames it flagged, evaluate against the ground truth.

``salo simulate`` / ``salo odometry``, the sweep tasks, the experiments'
sequence cache and table, and the demo call these; what differs between them
(where files go, what is printed) is in their arguments.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


# ---------------------------------------------------------------- scene to sequence
class PathTooShort(ValueError):
    """The scene's path has room for fewer sweeps than asked after the start.

    scene: its name. duration_s: the trajectory's duration, s. available: whole
    sweeps after ``start_s`` (s). frames: sweeps asked for.
    """

    def __init__(self, scene: str, duration_s: float, available: int, start_s: float, frames: int):
        self.scene, self.duration_s, self.available, self.start_s, self.frames = (
            scene, duration_s, available, start_s, frames)
        super().__init__(f"scene {scene}: its path lasts {duration_s:.1f} s, room for {available} sweeps after "
                         f"start_s {start_s:g} s, not {frames}")


@dataclass(frozen=True)
class SimulatedSequence:
    """What ``simulate_scene`` wrote: the sequence folder, its frame count, the wall time, s."""

    path: Path
    frames: int
    seconds: float


def simulate_scene(scene, sensor, out: str | Path, frames: int, *, seed: int, start_s: float = 0.0,
                   motion_distortion: bool = True, info: dict | None = None, force: bool = False,
                   on_frame=None, threads: int | None = None, compress_truth: bool = False) -> SimulatedSequence:
    """Simulate ``frames`` sweeps of ``sensor`` along a built scene into the sequence folder ``out``.

    scene: ``tools.worlds.SceneWorld``. seed: the simulator's noise seed.
    start_s: time along the scene's path of the first sweep, s. info: more
    manifest entries (the command, a cache key); the scene's own (``scene.info``)
    and ``noise_std_m`` are added. force: replace an existing ``out``.
    on_frame(k, scan) after each sweep. threads: Embree threads (None: all
    cores; the result never depends on it). compress_truth: zlib the truth files. Raises PathTooShort
    before anything
    is written when the path has room for fewer sweeps.
    """
    from simlidar.simulate import simulate_sequence
    from simlidar.sweep import SweepSimulator

    available = scene.sweeps_available(sensor, start_s)
    if frames > available:
        raise PathTooShort(scene.info["scene"], float(scene.trajectory.duration_s), available, start_s, frames)
    t0 = time.perf_counter()
    simulator = SweepSimulator(scene.world, sensor, seed=seed, motion_distortion=motion_distortion, threads=threads)
    path = simulate_sequence(scene.world, scene.trajectory, sensor, out, frames=frames, seed=seed, t_start=start_s,
                             motion_distortion=motion_distortion, simulator=simulator, force=force,
                             on_frame=on_frame, compress_truth=compress_truth,
                             info={**scene.info, **(info or {}), "noise_std_m": sensor.range_noise_std_m})
    return SimulatedSequence(Path(path), frames, time.perf_counter() - t0)


# ---------------------------------------------------------------- a method over a sequence
@dataclass(frozen=True)
class FrameFlags:
    """Frames a run flagged: ``extrapolated`` (its pose is the constant-velocity guess, no ICP result),
    ``degenerate`` (weakly constrained), ``remapped`` (the motion prior kept in a weak direction)."""

    extrapolated: int
    degenerate: int
    remapped: int

    @classmethod
    def of(cls, diagnostics) -> FrameFlags:
        """Counted over ``odometry.diagnostics.FrameDiagnostics``, one per frame."""
        return cls(sum(d.extrapolated for d in diagnostics), sum(d.degenerate for d in diagnostics),
                   sum(d.remapped > 0 for d in diagnostics))


@dataclass(frozen=True)
class RunFiles:
    """Where a run's outputs go (None: not written).

    poses: KITTI poses, one 3x4 line per frame (first = identity). diagnostics:
    the per-frame CSV (``odometry.diagnostics.CSV_COLUMNS``). config: the resolved
    odometry config, YAML. tum: the trajectory in TUM format.
    """

    poses: Path
    diagnostics: Path | None = None
    config: Path | None = None
    tum: Path | None = None

    @classmethod
    def beside(cls, poses: str | Path, diagnostics: bool = True, config: bool = True, tum: bool = False) -> RunFiles:
        """Named after the poses file ``NAME.txt``: ``NAME_diagnostics.csv``, ``NAME_config.yaml``, ``NAME.tum``."""
        p = Path(poses)
        return cls(p, p.with_name(p.stem + "_diagnostics.csv") if diagnostics else None,
                   p.with_name(p.stem + "_config.yaml") if config else None, p.with_suffix(".tum") if tum else None)

    @classmethod
    def in_folder(cls, folder: str | Path) -> RunFiles:
        """A run folder of its own: ``poses.txt``, ``diagnostics.csv``, ``config.yaml``."""
        f = Path(folder)
        return cls(f / "poses.txt", f / "diagnostics.csv", f / "config.yaml")


def write_run_files(files: RunFiles, poses: np.ndarray, diagnostics: list | None = None, config=None,
                    times_s: np.ndarray | None = None, sensor=None) -> None:
    """Write a run's outputs, each atomically, where ``files`` says (and what there is to write).

    poses: (N, 4, 4) ``T_first_lidar``. diagnostics: ``FrameDiagnostics`` per frame.
    config: the ``OdometryConfig``. times_s: (N,) sweep starts for TUM, s (None:
    one frame period of ``sensor`` apart, ``simlidar.sequence.frame_times``).
    """
    from simlidar.formats.atomic import atomic_write_text
    from simlidar.formats.kitti import write_kitti_poses

    write_kitti_poses(files.poses, poses)
    if files.diagnostics is not None and diagnostics is not None:
        from odometry.diagnostics import write_diagnostics_csv

        write_diagnostics_csv(files.diagnostics, diagnostics)
    if files.config is not None and config is not None:
        atomic_write_text(files.config, config.to_yaml())
    if files.tum is not None:
        from simlidar.formats.tum import write_tum
        from simlidar.sequence import frame_times

        write_tum(files.tum, poses, times_s if times_s is not None else frame_times(len(poses), sensor))


def evaluate_against_truth(sequence, poses: np.ndarray, frame_indices: np.ndarray | None = None):
    """``odometry.metrics.TrajectoryMetrics`` of ``poses`` (N, 4, 4) against the sequence's ground truth.

    frame_indices: the frames the poses belong to (default all); the ground truth
    is then taken relative to the first of them. None when the sequence has no
    ground truth.
    """
    from odometry.metrics import evaluate_trajectory

    if sequence.poses is None:
        return None
    gt = sequence.poses
    if frame_indices is not None and not np.array_equal(frame_indices, np.arange(len(sequence))):
        from simlidar import se3

        gt = np.asarray(gt)[frame_indices]
        gt = se3.inverse(gt[0]) @ gt
    return evaluate_trajectory(gt, poses)


@dataclass
class MethodRun:
    """One odometry run over a sequence and what came of it.

    run: ``odometry.pipeline.OdometryRun`` (poses (N, 4, 4) ``T_first_lidar``, frame
    indices, times, per-frame diagnostics, config, seconds). flags: ``FrameFlags``.
    metrics: ``odometry.metrics.TrajectoryMetrics`` against the ground truth, or None
    (not asked, or none known). files: what was written, or None. run_s: wall time of
    the run and its files, s; evaluate_s: of the evaluation, s.
    """

    run: object
    flags: FrameFlags
    metrics: object | None
    files: RunFiles | None
    run_s: float
    evaluate_s: float = 0.0

    @property
    def poses(self) -> np.ndarray:
        return self.run.poses

    @property
    def frames_per_second(self) -> float:
        return self.run.frames_per_second


def run_method(sequence, config, *, frames: slice | None = None, on_frame=None, files: RunFiles | None = None,
               evaluate: bool = False) -> MethodRun:
    """Run our odometry with ``config`` over (a slice of) ``sequence``, write ``files``, count flags, evaluate.

    on_frame(k, diagnostics) after each frame. evaluate: figures against the
    sequence's ground truth (``evaluate_against_truth``). Raises
    ``odometry.pipeline.OdometryError`` when the odometry cannot run on the input.
    """
    from odometry.pipeline import run_sequence

    t0 = time.perf_counter()
    run = run_sequence(sequence, config, frames=frames, on_frame=on_frame)
    if files is not None:
        write_run_files(files, run.poses, run.diagnostics, config, run.times_s, sequence.sensor)
    run_s = time.perf_counter() - t0
    result = MethodRun(run, FrameFlags.of(run.diagnostics), None, files, run_s)
    if evaluate:
        t0 = time.perf_counter()
        result.metrics = evaluate_against_truth(sequence, run.poses, None if frames is None else run.frame_indices)
        result.evaluate_s = time.perf_counter() - t0
    return result


__all__ = ["FrameFlags", "MethodRun", "PathTooShort", "RunFiles", "SimulatedSequence", "evaluate_against_truth",
           "run_method", "simulate_scene", "write_run_files"]
