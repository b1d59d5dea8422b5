"""What every command, sweep, experiment and the demo need around a run, written once.

- ``simulate_scene``: a built scene (``tools.worlds.SceneWorld``) to a simulated
  sequence folder: check that the path has room for the frames, record the
  scene and the noise in the manifest, simulate.
- ``MethodRun``: what a method's run gives, whichever the method (``tools.methods.run_method``
  makes it): poses, time, the frames it flagged (``FrameFlags``), its settings.
- ``RunFiles`` / ``write_run_files``: where a run's outputs go (KITTI poses, the per-frame
  diagnostics CSV, the resolved config, TUM) and writing them; ``evaluate_against_truth``
  and ``segment_errors_per_100m``: its figures against the sequence's ground truth.

``salo simulate`` / ``salo odometry``, the sweep tasks, the experiments'
sequence cache and table, and the demo call these; what differs between them
(where files go, what is printed) is in their arguments.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
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


# ---------------------------------------------------------------- a method's run
@dataclass(frozen=True)
class FrameFlags:
    """Frames a run flagged: ``extrapolated`` (its pose is the constant-velocity guess, no ICP result),
    ``degenerate`` (weakly constrained), ``remapped`` (the motion prior kept in a weak direction);
    None: not known (a table read back from its files keeps the first two only)."""

    extrapolated: int
    degenerate: int
    remapped: int | None

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


def segment_errors_per_100m(T_gt: np.ndarray, T_est: np.ndarray, length_m: float, step_frames: int) -> np.ndarray:
    """(M,) translational error of each ``length_m`` segment (KITTI protocol, starts every ``step_frames``),
    m per 100 m of path: the SALO paper's figure. T_gt, T_est: (N, 4, 4)."""
    from odometry.metrics import kitti_segment_errors

    s = kitti_segment_errors(T_gt, T_est, [length_m], step_frames)
    return s.t_err_ratio * 100.0


@dataclass
class MethodRun:
    """A method's run over a sequence: the one result of every method (ours, the peers, commands, plug-ins).

    method: the method's name (``tools.methods.Method.name``). poses: (N, 4, 4) lidar poses at
    each sweep start in the first one's frame, the first the identity, NaN from a divergence
    on; None when the method gave none (``error`` says why). seconds: wall time of the method,
    s (ours and the peers: the frame loop, reading the frames included). note: one line about
    the run (our configuration's name, a peer's version). error: why the run has no usable
    poses (not installed, failed, diverged), or None. settings: what ran, JSON-able (our
    config; a peer's settings, version and input: ``frames_with_times``, ``diverged_at_frame``).
    degenerate: (N,) bool, the frames the method itself flagged as weakly constrained, or None
    when it does not say. diagnostics: our odometry's ``FrameDiagnostics`` per frame, or None.
    odometry_run: ours: the odometry library's own result (``odometry.pipeline.OdometryRun``:
    frame indices, times, config), else None. method_poses (N, 4, 4), instants (N,): a peer's
    poses as it returned them and the instant each belongs to, sweep periods after its sweep's
    start (``tools.peers``), else None. flags: ``FrameFlags``, counted from ``diagnostics`` when
    not given. frames_per_second: frames registered (finite poses) per second of ``seconds``,
    worked out when not given (a run read back from a results file keeps its own figure).
    """

    method: str
    poses: np.ndarray | None
    seconds: float = float("nan")
    note: str = ""
    error: str | None = None
    settings: dict = field(default_factory=dict)
    degenerate: np.ndarray | None = None
    diagnostics: list | None = None
    odometry_run: object | None = None
    method_poses: np.ndarray | None = None
    instants: np.ndarray | None = None
    flags: FrameFlags | None = None
    frames_per_second: float | None = None

    def __post_init__(self) -> None:
        if self.flags is None and self.diagnostics is not None:
            self.flags = FrameFlags.of(self.diagnostics)
        if self.frames_per_second is None:
            done = 0 if self.poses is None else int(np.sum(np.all(np.isfinite(self.poses), axis=(1, 2))))
            self.frames_per_second = done / self.seconds if self.seconds > 0 else float("nan")

    @property
    def ok(self) -> bool:
        """True when the method gave poses and nothing is wrong with them."""
        return self.error is None and self.poses is not None


__all__ = ["FrameFlags", "MethodRun", "PathTooShort", "RunFiles", "SimulatedSequence", "evaluate_against_truth",
           "segment_errors_per_100m", "simulate_scene", "write_run_files"]
