"""A simulated sequence held in memory: sweeps straight to odometry, nothing written to disk.

``simulate_in_memory`` runs the same sweeps as ``simlidar.simulate.simulate_sequence``
(same simulator, seeds and poses) and keeps the frames in memory as an
``InMemorySequence``, which reads like ``simlidar.formats.scan_folders.Sequence``: ``len``,
indexing and iteration give ``Frame`` objects, ``poses`` are ``T_first_lidar``,
``times`` the sweep starts relative to the first, ``sensor`` the model. For
suites of many short sequences (the generalisation experiment) this saves
writing and reading gigabytes of truth nobody keeps.

What a frame carries is chosen with ``fields``:

- ``"simulated"``: ring and per-point time, as a simulated sequence folder's
  sidecar gives them (the same float64 times: an odometry run gives the same
  poses on the frames in memory as on the folder);
- ``"truth"``: the whole per-point record a folder's reader gives
  (``simlidar.formats.truth.SIDECAR_DTYPE``: true range, point, normal, object, and
  ``weather`` when the sensor has weather), for studies that judge against the
  truth (50 bytes a return: short sequences);
- ``"real"``: nothing beyond x, y, z, as real KITTI scans (rings must then
  come from the elevation, and there are no per-point times to de-skew with).

Per-frame degeneracy figures of the true normals (``simlidar.degeneracy``) are
kept either way: they describe the world, not what a method is shown. With the
sensor's IMU on, ``imu`` holds its samples and ``imu_truth`` their truth, as a
sequence folder's ``imu.csv`` and ``imu_truth.csv`` give them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import se3
from .degeneracy import Degeneracy, degeneracy
from .imu import ImuSamples, ImuTruth
from .inside import check_poses
from .sensor import LidarModel
from .sequence import Frame
from .simulate import frame_start_times, sequence_imu
from .sweep import SweepSimulator
from .trajectory import Trajectory
from .world import World

FIELD_SETS = ("simulated", "truth", "real")
_SIMULATED_DTYPE = np.dtype([("ring", "<u2"), ("time_s", "<f8")])


@dataclass
class InMemorySequence:
    """Frames of a simulated sequence in memory (reads like ``simlidar.formats.scan_folders.Sequence``).

    points: per frame (N_k, 3) float32 measured points, m. fields: per frame a
    structured (N_k,) array (ring, time_s) or None. poses: (F, 4, 4) ``T_first_lidar``.
    times: (F,) sweep start times, s, the first 0. degeneracy: per-frame true-normal figures.
    imu, imu_truth: the IMU's samples and their truth, or None (no IMU).
    """

    path: Path
    sensor: LidarModel
    points: list[np.ndarray]
    fields: list[np.ndarray | None]
    poses: np.ndarray
    times: np.ndarray
    degeneracy: list[Degeneracy]
    manifest: dict = field(default_factory=dict)
    kind: str = "memory"
    imu: ImuSamples | None = None
    imu_truth: ImuTruth | None = None

    def __len__(self) -> int:
        return len(self.points)

    def __getitem__(self, k: int) -> Frame:
        if not -len(self) <= k < len(self):
            raise IndexError(f"{self.path}: frame {k} out of range (0..{len(self) - 1})")
        k = k % len(self)
        return Frame(k, self.points[k].astype(np.float64), None, self.fields[k], self.path / f"{k:06d}")

    def frame(self, k: int, truth: bool = True) -> Frame:
        """Frame ``k`` (its fields are in memory: the truth costs nothing to leave in)."""
        return self[k]

    def __iter__(self):
        for k in range(len(self)):
            yield self[k]


def simulate_in_memory(
    world: World,
    trajectory: Trajectory,
    sensor: LidarModel,
    frames: int,
    seed: int = 0,
    t_start: float = 0.0,
    fields: str = "simulated",
    name: str = "memory",
    on_frame: Callable[[int], None] | None = None,
    motion_distortion: bool | None = None,
    simulator: SweepSimulator | None = None,
    info: dict | None = None,
) -> InMemorySequence:
    """Simulate ``frames`` sweeps into an ``InMemorySequence``.

    ``fields="simulated"``: motion distortion on, ring and time kept (a simulated
    sequence); ``"truth"``: the whole per-point record. ``fields="real"``: motion
    distortion off and no per-point fields, as real, motion-compensated scans.
    motion_distortion: overrides what ``fields`` implies. The noise seed and the
    poses are those of ``simulate_sequence`` with the same arguments. simulator:
    a ``SweepSimulator`` to reuse (its seed and motion distortion then rule).
    info: more manifest entries (a sweep's key, a suite spec).
    """
    if fields not in FIELD_SETS:
        raise ValueError(f"fields must be one of {', '.join(FIELD_SETS)}, got {fields!r}")
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    if motion_distortion is None:
        motion_distortion = fields != "real"
    sim = simulator or SweepSimulator(world, sensor, seed=seed, motion_distortion=motion_distortion)
    t0 = frame_start_times(sensor, frames, t_start)
    poses = trajectory.pose_at(t0)
    check_poses(sim.raycaster, poses, strict=world.normals_reliable, source=world.source)
    imu = sequence_imu(trajectory, sensor, frames, int(sim.seed), float(t0[0]))
    points, extra, degen = [], [], []
    for k in range(frames):
        scan = sim.sweep(trajectory, float(t0[k]), frame_index=k)
        points.append(scan.xyz.astype(np.float32))
        if fields == "simulated":
            rec = np.empty(len(scan.xyz), dtype=_SIMULATED_DTYPE)
            rec["ring"], rec["time_s"] = scan.ring, scan.time_s
            extra.append(rec)
        elif fields == "truth":
            extra.append(scan.sidecar())
        else:
            extra.append(None)
        surface = scan.surface_returns  # the world's figures: returns off a surface
        degen.append(degeneracy(scan.true_xyz[surface], scan.normal[surface]))
        if on_frame is not None:
            on_frame(k)
    rel = se3.inverse(poses[0]) @ poses
    rel[0] = np.eye(4)
    return InMemorySequence(Path(name), sensor, points, extra, rel, t0 - t0[0], degen,
                            {"seed": int(sim.seed), "fields": fields, "frames": int(frames),
                             "t_start_s": float(t_start), "motion_distortion": bool(sim.motion_distortion),
                             **(info or {})},
                            imu=None if imu is None else imu[0], imu_truth=None if imu is None else imu[1])
