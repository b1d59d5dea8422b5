"""Odometry methods as plug-ins: one interface for ours, the peers, external commands and packages.

A method turns a sequence's scans into poses. Four kinds, one interface (``Method``):

- ``ours``: a configuration of this project's odometry (``odometry.config``): the
  variants ``bl``, ``ncf``, ``salo``, ``bl-map``, ``ncf-map``, ``salo-map``,
  ``default`` (``salo odometry``'s default), each with ``--set`` overrides; run by
  ``tools.runners.run_method``.
- ``peer``: KISS-ICP, GenZ-ICP, the small_gicp scan-to-map pipeline
  (``tools.experiments.peer``; the optional ``peer`` extra), on our range limits.
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
  a ``Method`` subclass (or instance) for more control.

Every method sees only what a real sensor gives: ``run_staged`` hands it the
staged input of ``tools.staging`` (scans, the fields opted into, the sensor model,
times), never the folder that holds the ground truth. ``method_from_name`` resolves
a name of any kind; ``command_method`` makes a command one.
"""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
          "salo-map": "SALO map", "kiss-icp": "KISS-ICP", "genz-icp": "GenZ-ICP", "small-gicp": "small_gicp s2m"}


def method_label(name: str) -> str:
    """A method's label in tables and plots: ``LABELS``' for ours and the peers, else its name."""
    base, plus, rest = name.partition("+")
    return LABELS[base] + plus + rest if base in LABELS else name


class MethodError(ValueError):
    """A method cannot be resolved or failed to give poses; the message is for the user as it is."""


@dataclass
class MethodOutput:
    """What a method gave for a sequence.

    poses: (N, 4, 4) lidar poses at each sweep start in the first one's frame (NaN after a
    divergence). seconds: wall time of the method, s. degenerate: (N,) bool, frames the
    method itself flagged as weakly constrained, or None when it does not say.
    diagnostics: our odometry's ``FrameDiagnostics`` per frame, or None. settings: what ran
    (config, versions), JSON-able. note: one line about the run.
    """

    poses: np.ndarray
    seconds: float
    degenerate: np.ndarray | None = None
    diagnostics: list | None = None
    settings: dict = field(default_factory=dict)
    note: str = ""

    @property
    def frames_per_second(self) -> float:
        done = int(np.sum(np.all(np.isfinite(self.poses), axis=(1, 2))))
        return done / self.seconds if self.seconds > 0 else float("nan")


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

    def run_sequence(self, sequence, on_frame=None) -> MethodOutput:
        """Run over an opened sequence (frames, sensor, times; its poses are never read)."""
        raise MethodError(f"method {self.name}: runs only on a staged folder (tools.staging)")

    def run_staged(self, staged, *, workdir: str | Path | None = None, log_path: str | Path | None = None,
                   timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S, on_frame=None) -> MethodOutput:
        """Run over a staged input (``tools.staging.StagedInput``): in-process methods open it and run."""
        from simlidar.dataset import open_sequence

        return self.run_sequence(open_sequence(staged.root), on_frame=on_frame)


# ---------------------------------------------------------------- ours
class OursMethod(Method):
    """A configuration of this project's odometry (``odometry.config.OdometryConfig``)."""

    kind = "ours"

    def __init__(self, name: str, config, overrides: dict | None = None):
        self.name, self.config, self.overrides = name, config, dict(overrides or {})

    def identity(self) -> dict:
        return {"kind": self.kind, "config": self.config.to_dict()}

    def run_sequence(self, sequence, on_frame=None) -> MethodOutput:
        from odometry.pipeline import OdometryError
        from tools.runners import run_method

        try:
            run = run_method(sequence, self.config, on_frame=on_frame)
        except OdometryError as exc:
            raise MethodError(f"{self.name}: {exc}") from None
        degenerate = np.array([bool(d.degenerate or d.remapped) for d in run.run.diagnostics])
        return MethodOutput(run.poses, run.run.seconds, degenerate, run.run.diagnostics,
                            {"config": self.config.to_dict()}, self.config.name)


# ---------------------------------------------------------------- peers
class PeerMethod(Method):
    """A peer odometry (``tools.experiments.peer.PEERS``) on our default configuration's range limits."""

    kind = "peer"

    def __init__(self, name: str):
        self.name = name

    def unavailable(self) -> str | None:
        from tools.experiments.peer import peer_unavailable_reason

        return peer_unavailable_reason(self.name)

    def identity(self) -> dict:
        from tools.experiments.peer import peer_version

        return {"kind": self.kind, "name": self.name, "version": peer_version(self.name),
                "range_m": list(self._ranges())}

    @staticmethod
    def _ranges() -> tuple[float, float]:
        from odometry.config import DEFAULT_VARIANT, variant

        clean = variant(DEFAULT_VARIANT).clean
        return clean.min_range_m, clean.max_range_m

    def run_sequence(self, sequence, on_frame=None) -> MethodOutput:
        from tools.experiments import peer

        lo, hi = self._ranges()
        try:
            run = peer.run_peer(self.name, sequence, min_range_m=lo, max_range_m=hi,
                                on_frame=None if on_frame is None else (lambda k: on_frame(k, None)))
        except peer.PeerUnavailable as exc:
            raise MethodError(str(exc)) from None
        return MethodOutput(run.poses, run.seconds, None, None, dict(run.config),
                            f"{self.name} {peer.peer_version(self.name)}")


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

    def run_staged(self, staged, *, workdir=None, log_path=None, timeout_s=DEFAULT_COMMAND_TIMEOUT_S,
                   on_frame=None) -> MethodOutput:
        from simlidar.formats.kitti import read_kitti_poses

        log_path = Path(log_path) if log_path is not None else staged.out.with_name("command.log")
        seconds = run_command(self.template, staged, log_path, timeout_s, workdir)
        poses = read_kitti_poses(staged.out)
        if len(poses) != staged.frames:
            raise MethodError(f"external odometry wrote {len(poses)} poses, the sequence has {staged.frames} frames")
        return MethodOutput(poses, seconds, settings={"command": self.template})


# ---------------------------------------------------------------- plug-ins
class FunctionMethod(Method):
    """A plug-in function ``run(sequence) -> poses (N, 4, 4)`` registered under ``PLUGIN_GROUP``."""

    kind = "plugin"

    def __init__(self, name: str, function, source: str = "", version: str | None = None):
        self.name, self.function, self.source, self.version = name, function, source, version

    def identity(self) -> dict:
        return {"kind": self.kind, "name": self.name, "source": self.source, "version": self.version}

    def run_sequence(self, sequence, on_frame=None) -> MethodOutput:
        t0 = time.perf_counter()
        poses = np.asarray(self.function(sequence), dtype=np.float64)
        seconds = time.perf_counter() - t0
        if poses.shape != (len(sequence), 4, 4):
            raise MethodError(f"plug-in {self.name} ({self.source}) returned poses of shape {poses.shape}, "
                              f"expected ({len(sequence)}, 4, 4)")
        return MethodOutput(poses, seconds, settings={"plugin": self.source, "version": self.version})


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
    method.entry_point = entry_point.name  # run_method_staged runs it in a process of its own (tools.isolation)
    return method


# ---------------------------------------------------------------- names
def builtin_names() -> tuple[str, ...]:
    """Our configurations' names: ``default`` and the variants."""
    from odometry.config import VARIANTS

    return ("default", *VARIANTS)


def known_names() -> dict[str, tuple[str, ...]]:
    """Every method name by kind (ours, peers, plug-ins installed here)."""
    from tools.experiments.peer import PEERS

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
    from tools.experiments.peer import PEERS

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


def run_method_staged(method: Method, sequence, *, fields=None, workdir=None, log_path=None,
                      timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S, on_frame=None) -> MethodOutput:
    """Stage ``sequence`` (``tools.staging.staged``: no ground truth) and run ``method`` on it.

    A sequence in memory goes to an in-process method as ``tools.staging.sensor_view``
    (nothing written); a program gets it staged on disk as always, and so does a plug-in of
    ``PLUGIN_GROUP``, run in a process of its own (``tools.isolation``).
    """
    from tools.staging import DEFAULT_FIELDS, sensor_view, staged

    reason = method.unavailable()
    if reason:
        raise MethodError(f"{method.label}: {reason}")
    if getattr(method, "entry_point", None) is not None:  # a plug-in: in a process of its own
        from tools.isolation import IsolatedRunError, run_plugin_isolated

        with staged(sequence, DEFAULT_FIELDS if fields is None else fields) as stage:
            try:
                got = run_plugin_isolated(method.entry_point, method.name, stage, log_path=log_path,
                                          timeout_s=timeout_s)
            except IsolatedRunError as exc:
                raise MethodError(str(exc)) from None
        return MethodOutput(got.poses, got.seconds, got.degenerate, None, got.settings, got.note)
    in_process = type(method).run_sequence is not Method.run_sequence
    if in_process and getattr(sequence, "kind", None) == "memory":
        view = sensor_view(sequence, DEFAULT_FIELDS if fields is None else fields)
        return method.run_sequence(view, on_frame=on_frame)
    with staged(sequence, DEFAULT_FIELDS if fields is None else fields) as stage:
        return method.run_staged(stage, workdir=workdir, log_path=log_path, timeout_s=timeout_s, on_frame=on_frame)


__all__ = ["DEFAULT_COMMAND_TIMEOUT_S", "LABELS", "PLACEHOLDERS", "PLUGIN_GROUP", "CommandMethod", "FunctionMethod",
           "Method", "MethodError", "MethodOutput", "OursMethod", "PeerMethod", "builtin_names", "check_command",
           "command_problem", "fill_command", "known_names", "load_plugin", "method_from_name", "method_label",
           "our_config", "plugin_entry_points", "run_command", "run_method_staged"]
