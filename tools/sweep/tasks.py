"""The two task functions every executor runs: simulate a sequence, run one odometry on it.

Both are plain top-level functions of picklable arguments returning JSON-able
dicts, so local processes and Dask workers run the very same code. Neither
raises for a failure of the run itself: the error goes into the returned
result (and the run's ``result.json``), so one bad run does not stop a sweep.
Workers must see the store's folder (for Dask: a shared filesystem).
"""

from __future__ import annotations

import json
import logging
import platform
import socket
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from odometry.config import OdometryConfig
from simlidar.formats.atomic import atomic_write_text
from simlidar.sensor import LidarModel
from tools.methods import DEFAULT_COMMAND_TIMEOUT_S, MethodError
from tools.staging import DEFAULT_FIELDS

from .store import PARAMS_FILE, Store

log = logging.getLogger(__name__)

COMMAND_LOG = "command.log"


@dataclass(frozen=True)
class SimJob:
    """Simulate one sequence into the store (or find it there), or describe it for the runs to simulate.

    scene_overrides: scene parameters (speed included); sensor: the model with
    its noise; frames: sweeps; start_s: path time of the first sweep, s.
    in_memory: nothing is written: each run task simulates the sequence into
    memory (``memory_sequence``) and runs on it.
    """

    store: str
    sim_key: str
    scene: str
    seed: int
    scene_overrides: dict
    sensor: LidarModel
    frames: int
    start_s: float
    motion_distortion: bool
    in_memory: bool = False


@dataclass(frozen=True)
class RunJob:
    """Run one odometry (a config, an external command template, or a named method of ``tools.methods``)
    over a simulated sequence, staged with the per-point ``fields`` and no ground truth (``tools.staging``)."""

    store: str
    key: str
    sim_key: str
    params: dict
    config: OdometryConfig | None
    command: str | None = None
    command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S
    workdir: str | None = None  # where an external command runs (the sweep's working folder)
    method: str | None = None
    fields: tuple[str, ...] = DEFAULT_FIELDS


def versions() -> dict:
    """Versions that can change a result: this package, numpy, scipy, Python."""
    import numpy
    import scipy

    try:
        from importlib.metadata import version

        package = version("salo-bench")
    except Exception:  # not installed as a distribution (a bare checkout)
        from simlidar import __version__ as package
    return {"package_version": package, "numpy_version": numpy.__version__, "scipy_version": scipy.__version__,
            "python_version": platform.python_version()}


def _now_utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


# ---------------------------------------------------------------- simulation
def simulate_task(job: SimJob, threads: int | None = None) -> dict:
    """Make sure the job's sequence exists in the store; simulate it if not.

    threads: Embree threads for this task (None: all cores; give cores / workers
    when several tasks share a machine). The result never depends on it.
    Returns ``{"sim_key", "ok", "error", "simulate_s", "cached", "path"}``.
    """
    store = Store(job.store)
    out = store.sequence_dir(job.sim_key)
    outcome = {"sim_key": job.sim_key, "ok": True, "error": None, "cached": True, "path": str(out)}
    if job.in_memory and not store.sequence_ready(job.sim_key):
        return {**outcome, "cached": False, "path": None, "in_memory": job, "simulate_s": None}
    if store.sequence_ready(job.sim_key):
        outcome["simulate_s"] = store.sequence_info(job.sim_key).get("simulate_s")
        return outcome
    t0 = time.perf_counter()
    try:
        _simulate(job, out, threads)
    except Exception as exc:
        log.warning("simulation %s failed: %s", job.sim_key, exc)
        return {**outcome, "ok": False, "cached": False, "error": f"simulation: {_error_text(exc)}",
                "simulate_s": time.perf_counter() - t0}
    seconds = time.perf_counter() - t0
    info = {"sim_key": job.sim_key, "scene": job.scene, "seed": job.seed, "scene_overrides": job.scene_overrides,
            "sensor": job.sensor.name, "noise_std_m": job.sensor.range_noise_std_m, "frames": job.frames,
            "start_s": job.start_s, "simulate_s": seconds, "host": socket.gethostname(), "finished_utc": _now_utc()}
    atomic_write_text(store.sequence_info_path(job.sim_key), json.dumps(info, indent=1, sort_keys=True) + "\n")
    return {**outcome, "cached": False, "simulate_s": seconds}


def _simulate(job: SimJob, out: Path, threads: int | None) -> None:
    from tools.runners import PathTooShort, simulate_scene
    from tools.worlds import build_scene_world

    scene = build_scene_world(job.scene, job.seed, job.scene_overrides)
    try:
        # force: a folder without a manifest here is debris (a complete one was caught above).
        simulate_scene(scene, job.sensor, out, job.frames, seed=job.seed, start_s=job.start_s,
                       motion_distortion=job.motion_distortion, force=True, threads=threads,
                       info={"command": "sweep", "sim_key": job.sim_key})
    except PathTooShort as exc:  # recorded as it always was: a ValueError of the simulation
        raise ValueError(str(exc)) from None


# ---------------------------------------------------------------- odometry run
def failed_result(job: RunJob, error: str, timings: dict | None = None) -> dict:
    """The result of a run that did not produce figures; ``error`` says why."""
    return {"key": job.key, "sim_key": job.sim_key, "params": job.params, "status": "failed", "error": error,
            "metrics": {}, "diagnostics": {}, "timings": timings or {}, "versions": versions(),
            "host": socket.gethostname(), "finished_utc": _now_utc()}


def run_task(job: RunJob, sim: dict) -> dict:
    """Run the odometry of ``job`` over the sequence ``sim`` (``simulate_task``'s outcome), evaluate, commit.

    Writes the artifacts into ``runs/<key>/`` (``params.json`` first, ``result.json``
    last and atomically) and returns the result dict: ``key``, ``sim_key``, ``params``,
    ``status`` ("ok" | "failed"), ``error``, ``metrics`` (``TrajectoryMetrics.to_dict``),
    ``diagnostics`` (frame counts), ``timings`` (s), ``versions``, ``host``, ``finished_utc``.
    """
    store = Store(job.store)
    t_start = time.perf_counter()
    timings = {"simulate_s": sim.get("simulate_s"), "sim_cached": bool(sim.get("cached"))}
    run_dir = store.run_dir(job.key)
    try:
        if not sim.get("ok"):
            raise _Failure(sim.get("error") or "simulation failed")
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / PARAMS_FILE, json.dumps(
            {"key": job.key, "sim_key": job.sim_key, "params": job.params, "sequence": sim["path"],
             "config": None if job.config is None else job.config.to_dict(), "command": job.command,
             "method": job.method, "fields": list(job.fields)},
            indent=1, sort_keys=True) + "\n")
        if sim.get("in_memory") is not None:
            t0 = time.perf_counter()
            try:
                sequence = memory_sequence(sim["in_memory"])
            except Exception as exc:  # reported as a failed simulation, as on disk
                raise _Failure(f"simulation: {_error_text(exc)}") from None
            timings["simulate_s"] = time.perf_counter() - t0  # 0 when this process had it already
            result = _run_and_evaluate(job, sequence, run_dir, timings)
        else:
            result = _run_and_evaluate(job, Path(sim["path"]), run_dir, timings)
    except Exception as exc:
        error = str(exc) if isinstance(exc, (_Failure, MethodError)) else _error_text(exc)
        if not isinstance(exc, (_Failure, MethodError)):
            run_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(run_dir / "error.txt", traceback.format_exc())
        result = failed_result(job, error, timings)
    result["timings"]["run_s"] = time.perf_counter() - t_start
    store.write_result(result)
    return result


class _Failure(Exception):
    """A run failure whose message is already user-facing (no exception type prefix)."""


_MEMORY: dict[str, object] = {}  # this process's last in-memory sequence, by sim key


def memory_sequence(job: SimJob):
    """``job``'s sequence simulated into memory (``simlidar.in_memory``), kept for the next run of this process.

    The same simulator, seeds and poses as ``simulate_task`` writes, and the same per-point
    fields the folder's reader gives to the odometry (ring, float64 time): the same poses result.
    """
    if job.sim_key in _MEMORY:
        return _MEMORY[job.sim_key]
    from simlidar.in_memory import simulate_in_memory
    from tools.runners import PathTooShort
    from tools.worlds import build_scene_world

    _MEMORY.clear()  # one at a time: a 300-frame salo32 sequence is about 800 MB
    scene = build_scene_world(job.scene, job.seed, job.scene_overrides)
    available = scene.sweeps_available(job.sensor, job.start_s)
    if job.frames > available:
        raise ValueError(str(PathTooShort(job.scene, float(scene.trajectory.duration_s), available, job.start_s,
                                          job.frames)))
    seq = simulate_in_memory(scene.world, scene.trajectory, job.sensor, job.frames, seed=job.seed,
                             t_start=job.start_s, motion_distortion=job.motion_distortion, name=job.sim_key,
                             info={"sim_key": job.sim_key, **scene.info})
    _MEMORY[job.sim_key] = seq
    return seq


def job_method(job: RunJob):
    """The ``tools.methods.Method`` a job runs."""
    from tools.methods import CommandMethod, OursMethod, method_from_name

    if job.command is not None:
        return CommandMethod(job.params["variant"], job.command)
    if job.method is not None:
        return method_from_name(job.method)
    return OursMethod(job.params["variant"], job.config)


def _run_and_evaluate(job: RunJob, sequence, run_dir: Path, timings: dict) -> dict:
    """Run the job's method on the sensor's view of ``sequence`` (a folder, or a sequence in memory) and
    evaluate its poses against the truth, which the method never sees."""
    from simlidar.dataset import open_sequence
    from tools.methods import run_method
    from tools.runners import FrameFlags, RunFiles, evaluate_against_truth, write_run_files

    sequence_dir = Path(sequence) if isinstance(sequence, (str, Path)) else None
    seq = open_sequence(sequence_dir) if sequence_dir is not None else sequence
    method = job_method(job)
    out = run_method(method, seq, fields=job.fields, workdir=job.workdir, log_path=run_dir / COMMAND_LOG,
                     timeout_s=job.command_timeout_s)
    files = RunFiles.in_folder(run_dir)
    write_run_files(files, out.poses, out.diagnostics, job.config)
    diagnostics = {}
    if out.diagnostics is not None:
        flags = FrameFlags.of(out.diagnostics)
        diagnostics = {"extrapolated_frames": flags.extrapolated, "degenerate_frames": flags.degenerate}
    t0 = time.perf_counter()
    metrics = evaluate_against_truth(seq, out.poses)
    evaluate_s = time.perf_counter() - t0
    timings["odometry_s"] = out.seconds
    timings["frames_per_s"] = len(out.poses) / out.seconds if out.seconds > 0 else None
    timings["evaluate_s"] = evaluate_s
    metrics = metrics.to_dict()
    atomic_write_text(run_dir / "metrics.json", json.dumps(metrics, indent=1) + "\n")
    return {"key": job.key, "sim_key": job.sim_key, "params": job.params, "status": "ok", "error": None,
            "metrics": metrics, "diagnostics": diagnostics, "timings": timings, "versions": versions(),
            "host": socket.gethostname(), "finished_utc": _now_utc()}


__all__ = ["RunJob", "SimJob", "failed_result", "job_method", "memory_sequence", "run_task", "simulate_task",
           "versions"]
