"""A simulated sequence: sweep after sweep along a trajectory, streamed to disk."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .formats.salo import SequenceWriter
from .imu import ImuUnavailable, simulate_imu
from .inside import check_poses
from .sensor import LidarModel
from .sweep import Scan, SweepSimulator
from .trajectory import Trajectory
from .world import World

log = logging.getLogger(__name__)


def frame_start_times(sensor: LidarModel, frames: int, t_start: float = 0.0) -> np.ndarray:
    """(frames,) start time of each sweep, s: one sweep per rotation."""
    return t_start + np.arange(frames) * sensor.sweep_period_s


def sequence_imu(trajectory, sensor: LidarModel, frames: int, seed: int, t_start: float = 0.0):
    """The IMU of a sequence of ``frames`` sweeps from ``t_start`` (its samples and their truth, to the last
    sweep's end; ``simlidar.imu.simulate_imu``), or None when the sensor has no IMU on."""
    if not sensor.imu.enabled:
        return None
    try:
        return simulate_imu(trajectory, sensor.imu, t_start, frames * sensor.sweep_period_s, seed)
    except ImuUnavailable as exc:
        raise ImuUnavailable(f"sensor '{sensor.name}': {exc}") from None


def simulate_sequence(
    world: World,
    trajectory: Trajectory,
    sensor: LidarModel,
    out_dir: str | Path,
    frames: int,
    seed: int = 0,
    t_start: float = 0.0,
    motion_distortion: bool = True,
    info: dict | None = None,
    force: bool = False,
    on_frame: Callable[[int, Scan], None] | None = None,
    simulator: SweepSimulator | None = None,
    strict_inside: bool | None = None,
    compress_truth: bool = False,
) -> Path:
    """Simulate ``frames`` consecutive sweeps and write them as a sequence folder.

    Every frame's reference pose is first probed for being inside geometry
    (``simlidar.inside``): with ``strict_inside`` (default: when the world's
    normals are reliable, as a procedural scene's are) an enclosed pose raises
    ``SensorInsideGeometry`` before anything is written; otherwise one warning
    is logged with the evidence, the simulation goes on, and the manifest's
    ``inside_check`` records it. ``info`` goes into the manifest (scene, mesh,
    parameters). ``on_frame(k, scan)`` is called after each frame is simulated
    and queued for writing (progress bars); a background thread writes it while
    the next is simulated. compress_truth: zlib the truth files (``simlidar.formats.truth``).
    With the sensor's IMU on, its samples and truth (``sequence_imu``, from the same seed) are written
    beside the scans. Returns the finished folder.
    """
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    sim = simulator or SweepSimulator(world, sensor, seed=seed, motion_distortion=motion_distortion)
    t0 = frame_start_times(sensor, frames, t_start)
    poses = trajectory.pose_at(t0)
    imu = sequence_imu(trajectory, sensor, frames, seed, float(t0[0]))  # before anything is written: may refuse
    writer = SequenceWriter(out_dir, sensor, {}, force=force, n_objects=world.object_count,
                            compress_truth=compress_truth, imu=imu)  # refuses an existing folder now
    strict = world.normals_reliable if strict_inside is None else bool(strict_inside)
    inside_record = check_poses(sim.raycaster, poses, strict, source=world.source)
    manifest_info = {
        "seed": int(seed),
        "motion_distortion": bool(motion_distortion),
        "reference_time": "sweep start",
        "world_source": world.source,
        "world_faces": int(len(world.faces)),
        "object_labels": world.all_object_labels,
        "inside_check": inside_record,
        **(info or {}),
    }
    if sim.actors is not None:  # the moving objects: their ids, classes, boxes (their boxes per frame: tracks.csv)
        manifest_info["actors"] = sim.actors.describe()
    writer.info = manifest_info
    with writer:
        for k in range(frames):
            scan = sim.sweep(trajectory, float(t0[k]), frame_index=k)
            writer.add(scan, poses[k], float(t0[k]))
            if on_frame is not None:
                on_frame(k, scan)
    return Path(out_dir)
