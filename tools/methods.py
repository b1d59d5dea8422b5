"""Odometry methods as plug-ins: one interface for ours, the peers, external commands and packages.

A method turns a sequence's scans into poses. Four kinds, one interface (``Method``):

- ``ours``: a configuration of this project's odometry (``odometry.config``): the
  variants ``bl``, ``ncf``, ``salo``, ``bl-map``, ``ncf-map``, ``salo-map``,
  ``default`` (``salo odometry``'s default), each with ``--set`` overrides; run by
  ``odometry.pipeline.run_sequence``.
- ``peer``: KISS-ICP, GenZ-ICP, the small_gicp scan-to-map pipeline
  (``tools.peers``; the optional ``peer`` extra), on our range limits.
- ``command``: an external program, a shell command with placeholders
  (``{scans}``: the folder of ``NNNNNN.bin`` scans, ``{sensor}``: ``sensor.yaml``,
  ``{times}``: ``times.txt``, ``{fields}``: the per-point fields' folder,
  ``{sequence}``: the folder holding them all, ``{out}``: the KITTI poses file to write).
- ``plugin``: a Python package's own method, registered under the entry-point
  group ``salo.methods`` (``PLUGIN_GROUP``)::

      [project.entry-points."salo.methods"]
      my-odometry = "my_package.salo_plugin:run"

  The object named is a function ``run(sequence) -> poses`` (the sequence as
  ``simlidar.dataset.open_sequence`` reads the staged folder: frames with points,
  intensity and the opted-in per-point fields, ``sensor``, ``times``, no ``poses``;
  it returns (N, 4, 4) lidar poses at each sweep start, the first the identity), or
  a ``Method`` subclass (or instance) for more control (its ``run_sequence`` returns a
  ``tools.runners.MethodRun``).

``run_method`` is the one way to run any of them, and ``tools.runners.MethodRun`` the
one result (poses, time, the frames the method flagged, its settings). Every method
sees only what a real sensor gives: ``run_method`` hands it the staged input of
``tools.staging`` (scans, the fields opted into, the sensor model, times), never the
folder that holds the ground truth. ``method_from_name`` resolves a name of any kind;
``CommandMethod`` makes a command one.
"""

from __future__ import annotations

import hashlib
import json
import logging
import re
import shlex
import subprocess
import time
from pathlib import Path

import numpy as np

from tools.runners import MethodRun

log = logging.getLogger(__name__)

PLUGIN_GROUP = "salo.methods"
DEFAULT_COMMAND_TIMEOUT_S = 3600.0
# Placeholders of an external command, and what they stand for (``tools.staging.StagedInput``).
PLACEHOLDERS = {
    "scans": "the folder of NNNNNN.bin scans (float32 x y z intensity, lidar frame)",
    "sensor": "sensor.yaml, the sensor model",
    "times": "times.txt, the sweep start of each scan, s",
    "fields": "the folder of per-point fields (NNNNNN.npy, when any are opted into)",
    "sequence": "the folder holding velodyne/, times.txt, sensor.yaml and fields/",
    "out": "the KITTI poses file to write (one 3x4 row-major line per scan, first the identity)",
}
INPUT_PLACEHOLDERS = ("scans", "sequence")
# Table and plot labels of the built-in methods.
LABELS = {"default": "default", "bl": "BL", "ncf": "NCF", "salo": "SALO", "bl-map": "BL map", "ncf-map": "NCF map",
          "salo-map": "SALO map", "default-imu": "default + IMU",
          "kiss-icp": "KISS-ICP", "genz-icp": "GenZ-ICP", "small-gicp": "small_gicp s2m"}


def method_label(name: str) -> str:
    """A method's label in tables and plots: ``LABELS``' for ours and the peers, else its name."""
    base, plus, rest = name.partition("+")
    return LABELS[base] + plus + rest if base in LABELS else name


class MethodError(ValueError):
    """A method cannot be resolved or failed to give poses; the message is for the user as it is."""


class Method:
    """One odometry method. Subclasses set ``name``, ``kind``, and implement ``run_sequence`` (in-process)
    or ``run_staged`` (a program over the staged folder)."""

    name: str = "method"
    kind: str = "plugin"

    @property
    def label(self) -> str:
        """The name shown in tables and plots (``method_label``)."""
        return method_label(self.name)

    def unavailable(self) -> str | None:
        """Why the method cannot run here (a sentence), or None."""
        return None

    def identity(self) -> dict:
        """What determines the method's result (hashed into result keys): its settings and versions."""
        return {"kind": self.kind, "name": self.name}

    @property
    def key(self) -> str:
        """A short stable hash of ``identity``."""
        text = json.dumps(self.identity(), sort_keys=True, separators=(",", ":"), default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def run_sequence(self, sequence, frames: slice | None = None, on_frame=None) -> MethodRun:
        """Run over an opened sequence (frames, sensor, times; its poses are never read).

        frames: which frames (default all). on_frame(k, diagnostics or None) after each frame.
        """
        raise MethodError(f"method {self.name}: runs only on a staged folder (tools.staging)")

    def run_staged(self, staged, *, frames: slice | None = None, workdir: str | Path | None = None,
                   log_path: str | Path | None = None, timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S,
                   on_frame=None) -> MethodRun:
        """Run over a staged input (``tools.staging.StagedInput``): in-process methods open it and run."""
        from simlidar.dataset import open_sequence

        return self.run_sequence(open_sequence(staged.root), on_frame=on_frame, **_chosen(frames))


def _chosen(frames: slice | None) -> dict:
    """``frames`` as a keyword only when some are chosen: a plug-in's own ``run_sequence`` or ``run_staged``
    may not take it."""
    return {} if frames is None else {"frames": frames}


# ---------------------------------------------------------------- ours
class OursMethod(Method):
    """A configuration of this project's odometry (``odometry.config.OdometryConfig``).

    prefetch: scans prepared ahead on threads of their own (``odometry.pipeline.register_frames``;
    None: the config's default, 0: one thing at a time); the poses do not depend on it.
    """

    kind = "ours"

    def __init__(self, name: str, config, overrides: dict | None = None, prefetch: int | None = None):
        self.name, self.config, self.overrides, self.prefetch = name, config, dict(overrides or {}), prefetch

    def identity(self) -> dict:
        return {"kind": self.kind, "config": self.config.to_dict()}

    def run_sequence(self, sequence, frames: slice | None = None, on_frame=None) -> MethodRun:
        from odometry.pipeline import OdometryError, run_sequence

        try:
            run = run_sequence(sequence, self.config, frames=frames, on_frame=on_frame, prefetch=self.prefetch)
        except OdometryError as exc:
            raise MethodError(f"{self.name}: {exc}") from None
        degenerate = np.array([bool(d.degenerate or d.remapped) for d in run.diagnostics])
        return MethodRun(self.name, run.poses, run.seconds, note=self.config.name,
                         settings={"config": self.config.to_dict()}, degenerate=degenerate,
                         diagnostics=run.diagnostics, odometry_run=run)


# ---------------------------------------------------------------- peers
class PeerMethod(Method):
    """A peer odometry (``tools.peers.PEERS``) on our range limits.

    min_range_m, max_range_m: the range limits, m (default: our default configuration's; the
    far one is capped at ``tools.peers.PEER_MAX_RANGE_M`` when the peer runs).
    """

    kind = "peer"

    def __init__(self, name: str, min_range_m: float | None = None, max_range_m: float | None = None):
        from odometry.config import DEFAULT_VARIANT, variant

        clean = variant(DEFAULT_VARIANT).clean
        self.name = name
        self.min_range_m = clean.min_range_m if min_range_m is None else float(min_range_m)
        self.max_range_m = clean.max_range_m if max_range_m is None else float(max_range_m)

    def unavailable(self) -> str | None:
        from tools.peers import peer_unavailable_reason

        return peer_unavailable_reason(self.name)

    def identity(self) -> dict:
        from tools.peers import peer_version

        return {"kind": self.kind, "name": self.name, "version": peer_version(self.name),
                "range_m": [self.min_range_m, self.max_range_m]}

    def run_sequence(self, sequence, frames: slice | None = None, on_frame=None) -> MethodRun:
        from tools.peers import PeerUnavailable, run_peer

        try:
            return run_peer(self.name, sequence, min_range_m=self.min_range_m, max_range_m=self.max_range_m,
                            frames=frames, on_frame=None if on_frame is None else (lambda k: on_frame(k, None)))
        except PeerUnavailable as exc:
            raise MethodError(str(exc)) from None


# ---------------------------------------------------------------- external commands
def command_problem(template) -> str | None:
    """What is wrong with an external command template (a predicate: "has no {out} ..."), or None."""
    if not isinstance(template, str) or not template.strip():
        return f"must be a command line, got {template!r}"
    used = set(re.findall(r"\{(\w+)\}", template)) & set(PLACEHOLDERS)
    missing = [p for p in ("out",) if p not in used]
    if not used & set(INPUT_PLACEHOLDERS):
        missing.append("scans")
    if not missing:
        return None
    names = " and ".join("{" + p + "}" for p in missing)
    return (f"has no {names}: a method command reads the scans from {{scans}} (or {{sequence}}) and writes its "
            "poses to {out}; placeholders: " + ", ".join("{" + p + "}" for p in PLACEHOLDERS))


def check_command(template: str, origin: str = "the command") -> str:
    """An external command template, checked (``command_problem``); MethodError naming ``origin``."""
    problem = command_problem(template)
    if problem:
        raise MethodError(f"{origin} {template!r} {problem}")
    return template


def fill_command(template: str, values: dict[str, Path]) -> str:
    """The command with every known placeholder replaced by its shell-quoted path."""
    return re.sub(r"\{(\w+)\}", lambda m: shlex.quote(str(values[m.group(1)])) if m.group(1) in values
                  else m.group(0), template)


def run_command(template: str, staged, log_path: str | Path, timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S,
                workdir: str | Path | None = None) -> float:
    """Run an external odometry over a staged input through the shell; its output goes to ``log_path``.

    workdir: where it runs (default: the stage's empty ``work`` folder, ``tools.isolation``).
    Returns its wall time, s. Raises MethodError (quoting the command's last lines) on a non-zero
    exit, a timeout or no poses written.
    """
    from tools.isolation import method_environment

    command = fill_command(template, staged.placeholders())
    staged.out.unlink(missing_ok=True)
    log_path = Path(log_path)
    t0 = time.perf_counter()
    with open(log_path, "w") as log_file:
        log_file.write(f"$ {command}\n")
        log_file.flush()
        cwd = workdir if workdir is not None and Path(workdir).is_dir() else staged.workdir
        try:
            proc = subprocess.run(command, shell=True, cwd=cwd, stdout=log_file, stderr=subprocess.STDOUT,
                                  timeout=timeout_s, stdin=subprocess.DEVNULL, env=method_environment(cwd))
        except subprocess.TimeoutExpired:
            raise MethodError(f"external odometry timed out after {timeout_s:g} s: {command}") from None
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = " | ".join(log_path.read_text().strip().splitlines()[-3:])
        raise MethodError(f"external odometry exited with status {proc.returncode}: {tail}"
                          + _relative_paths_hint(template, cwd))
    if not staged.out.is_file():
        raise MethodError(f"external odometry wrote no poses to {{out}} (command: {command})")
    return seconds


def _relative_paths_hint(template: str, cwd) -> str:
    """A hint when the command names files by paths relative to the caller's folder, which it does not run in."""
    here = Path.cwd()
    try:
        words = shlex.split(re.sub(r"\{\w+\}", "", template))
    except ValueError:  # unbalanced quotes: the shell said what it had to
        return ""
    relative = [w for w in words if not w.startswith(("/", "-", "~")) and "/" in w and (here / w).exists()
                and not (Path(cwd) / w).exists()]
    if not relative:
        return ""
    return (f" (the command runs in a folder of its own, {cwd}, not in {here}: give {relative[0]} by an absolute "
            "path)")


class CommandMethod(Method):
    """An external program: a shell command with placeholders (``PLACEHOLDERS``)."""

    kind = "command"

    def __init__(self, name: str, template: str):
        self.name, self.template = name, check_command(template, f"method {name}")

    def identity(self) -> dict:
        return {"kind": self.kind, "command": self.template}

    def run_staged(self, staged, *, frames=None, workdir=None, log_path=None, timeout_s=DEFAULT_COMMAND_TIMEOUT_S,
                   on_frame=None) -> MethodRun:
        from simlidar.formats.kitti import read_kitti_poses

        if frames is not None:
            raise MethodError(f"method {self.name}: a command runs over the whole sequence (no frames to choose)")
        log_path = Path(log_path) if log_path is not None else staged.out.with_name("command.log")
        seconds = run_command(self.template, staged, log_path, timeout_s, workdir)
        poses = read_kitti_poses(staged.out)
        if len(poses) != staged.frames:
            raise MethodError(f"external odometry wrote {len(poses)} poses, the sequence has {staged.frames} frames")
        return MethodRun(self.name, poses, seconds, settings={"command": self.template})


# ---------------------------------------------------------------- plug-ins
class FunctionMethod(Method):
    """A plug-in function ``run(sequence) -> poses (N, 4, 4)`` registered under ``PLUGIN_GROUP``."""

    kind = "plugin"

    def __init__(self, name: str, function, source: str = "", version: str | None = None):
        self.name, self.function, self.source, self.version = name, function, source, version

    def identity(self) -> dict:
        return {"kind": self.kind, "name": self.name, "source": self.source, "version": self.version}

    def run_sequence(self, sequence, frames: slice | None = None, on_frame=None) -> MethodRun:
        if frames is not None:
            raise MethodError(f"plug-in {self.name}: a plug-in function runs over the whole sequence")
        t0 = time.perf_counter()
        poses = np.asarray(self.function(sequence), dtype=np.float64)
        seconds = time.perf_counter() - t0
        if poses.shape != (len(sequence), 4, 4):
            raise MethodError(f"plug-in {self.name} ({self.source}) returned poses of shape {poses.shape}, "
                              f"expected ({len(sequence)}, 4, 4)")
        return MethodRun(self.name, poses, seconds, settings={"plugin": self.source, "version": self.version})


def plugin_entry_points() -> dict:
    """The installed entry points of ``PLUGIN_GROUP``, by name."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=PLUGIN_GROUP)}


def load_plugin(entry_point) -> Method:
    """The ``Method`` an entry point of ``PLUGIN_GROUP`` names (a function becomes a ``FunctionMethod``)."""
    try:
        obj = entry_point.load()
    except Exception as exc:  # noqa: BLE001 - any import error of a third-party package: say which
        raise MethodError(f"plug-in {entry_point.name} ({entry_point.value}) does not load: "
                          f"{type(exc).__name__}: {exc}") from None
    version = entry_point.dist.version if getattr(entry_point, "dist", None) is not None else None
    if isinstance(obj, Method):
        method = obj
    elif isinstance(obj, type) and issubclass(obj, Method):
        method = obj()
    elif callable(obj):
        method = FunctionMethod(entry_point.name, obj, entry_point.value, version)
    else:
        raise MethodError(f"plug-in {entry_point.name} ({entry_point.value}) is neither a function nor a Method")
    method.entry_point = entry_point.name  # run_method runs it in a process of its own (tools.isolation)
    return method


# ---------------------------------------------------------------- names
def builtin_names() -> tuple[str, ...]:
    """Our configurations' names: ``default`` and the variants."""
    from odometry.config import VARIANTS

    return ("default", *VARIANTS)


def known_names() -> dict[str, tuple[str, ...]]:
    """Every method name by kind (ours, peers, plug-ins installed here)."""
    from tools.peers import PEERS

    return {"ours": builtin_names(), "peers": tuple(PEERS), "plug-ins": tuple(plugin_entry_points())}


def our_config(name: str, overrides: dict | None = None):
    """Our odometry config a name stands for (``default``: ``salo odometry``'s), with nested overrides."""
    from odometry.config import DEFAULT_VARIANT, config_from_dict, variant

    config = variant(DEFAULT_VARIANT if name == "default" else name)
    return config_from_dict(overrides, base=config, origin="--set") if overrides else config


def method_from_name(name: str, overrides: dict | None = None) -> Method:
    """The method ``name`` stands for: one of ours (with ``overrides``, nested by stage), a peer, a plug-in.

    An overridden configuration of ours is named ``NAME+HASH`` (the overrides' hash), so its
    results are kept apart from the plain one's. Raises MethodError for an unknown name
    (listing the known ones) or overrides given to a method that is not ours.
    """
    from tools.peers import PEERS

    if name in builtin_names():
        config = our_config(name, overrides)
        shown = name
        if overrides:
            digest = hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()[:6]
            shown = f"{name}+{digest}"
        return OursMethod(shown, config, overrides)
    if overrides:
        raise MethodError(f"method {name}: --set changes our odometry's configurations only "
                          f"({', '.join(builtin_names())})")
    if name in PEERS:
        return PeerMethod(name)
    plugins = plugin_entry_points()
    if name in plugins:
        return load_plugin(plugins[name])
    known = known_names()
    listing = "; ".join(f"{kind}: {', '.join(names) or '(none installed)'}" for kind, names in known.items())
    raise MethodError(f"unknown method {name!r} ({listing}; an external program: a command with {{scans}} and "
                      "{out})")


def run_method(method: Method, sequence, *, stage: bool = True, frames: slice | None = None, fields=None,
               workdir=None, log_path=None, timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S, on_frame=None,
               keep_failures: bool = False) -> MethodRun:
    """Run ``method`` over ``sequence``: the one way the commands, benches, experiments and the leaderboard
    run a method, whichever its kind.

    stage: hand the method the sensor's data only (``tools.staging``, no ground truth): a sequence
    in memory goes to an in-process method as ``sensor_view`` (nothing written), anything else is
    staged on disk with the per-point ``fields`` (default ``DEFAULT_FIELDS``); a plug-in of
    ``PLUGIN_GROUP`` runs on its staged copy in a process of its own (``tools.isolation``). False:
    an in-process method reads ``sequence`` as it is (``salo odometry`` on the user's data; a view already
    without the truth); a command is staged either way. frames: which frames (in-process methods
    only; default all). on_frame(k, diagnostics or None) after each frame. workdir, log_path,
    timeout_s: a command's (``run_command``). keep_failures: a method other than ours that cannot
    run here or fails gives a run without poses whose ``error`` says why (a table's row), where
    ours still raises (its failure is a bug to see).

    Raises MethodError when the method cannot run here or fails to give poses.
    """
    if keep_failures and method.kind != "ours":
        reason = method.unavailable()
        if reason:
            return MethodRun(method.name, None, error=reason)
        try:
            return run_method(method, sequence, stage=stage, frames=frames, fields=fields, workdir=workdir,
                              log_path=log_path, timeout_s=timeout_s, on_frame=on_frame)
        except MethodError as exc:
            return MethodRun(method.name, None, error=str(exc))
        except Exception as exc:  # noqa: BLE001 - one method failing must not end a long run; its row says why
            log.warning("%s failed on %s: %s", method.label, getattr(sequence, "path", "the sequence"), exc)
            return MethodRun(method.name, None, error=f"failed: {type(exc).__name__}: {exc}")
    from tools.staging import DEFAULT_FIELDS, sensor_view, staged

    reason = method.unavailable()
    if reason:
        raise MethodError(f"{method.label}: {reason}")
    if getattr(method, "entry_point", None) is not None:  # a plug-in: in a process of its own
        from tools.isolation import IsolatedRunError, run_plugin_isolated

        with staged(sequence, DEFAULT_FIELDS if fields is None else fields) as stage_dir:
            try:
                got = run_plugin_isolated(method.entry_point, method.name, stage_dir, log_path=log_path,
                                          timeout_s=timeout_s)
            except IsolatedRunError as exc:
                raise MethodError(str(exc)) from None
        return MethodRun(method.name, got.poses, got.seconds, note=got.note, settings=got.settings,
                         degenerate=got.degenerate)
    in_process = type(method).run_sequence is not Method.run_sequence
    fields = DEFAULT_FIELDS if fields is None else fields
    if in_process and not stage:
        return method.run_sequence(sequence, on_frame=on_frame, **_chosen(frames))
    if in_process and getattr(sequence, "kind", None) == "memory":
        return method.run_sequence(sensor_view(sequence, fields), on_frame=on_frame, **_chosen(frames))
    with staged(sequence, fields) as stage_dir:
        return method.run_staged(stage_dir, workdir=workdir, log_path=log_path, timeout_s=timeout_s,
                                 on_frame=on_frame, **_chosen(frames))


__all__ = ["DEFAULT_COMMAND_TIMEOUT_S", "LABELS", "PLACEHOLDERS", "PLUGIN_GROUP", "CommandMethod", "FunctionMethod",
           "Method", "MethodError", "OursMethod", "PeerMethod", "builtin_names", "check_command", "command_problem",
           "fill_command", "known_names", "load_plugin", "method_from_name", "method_label", "our_config",
           "plugin_entry_points", "run_command", "run_method"]
