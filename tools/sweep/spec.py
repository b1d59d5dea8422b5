"""A sweep's specification: YAML in, validated, expanded into runs with stable keys.

A spec names axes (scenes, seeds, sensors, noise levels, variants); the sweep is
their cross product, one run per combination. Every axis is optional::

    name: noise-study
    scenes: [city, tunnel]            # default [city]
    seeds: [0, 1]                     # default [0]: seeds the scene and the sensor noise
    sensors: [salo32]                 # presets or YAML files (relative to the spec); default [salo32]
    noise_std_m: [0.01, 0.02, 0.04]   # range noise std, m; default: each sensor's own
    variants: [bl, ncf, salo]         # default all three
    frames: 200                       # sweeps per sequence (default 100)
    speed_m_s: 8                      # cruise speed (default: the scene's)
    start_s: 0                        # time along the path of the first sweep, s
    scene_params: {city: {route_blocks: 4}}
    odometry: {voxel_size_m: 0.5}     # overrides for every built-in variant
    configs: {salo-v04: {base: salo, voxel_size_m: 0.4}}   # extra named variants
    commands: {mine: "my_odometry {sequence} {out}"}        # external odometries as variants

A run's key is a stable hash of its *resolved* parameters (the scene's full
parameter set, the sensor's full model, the odometry's full config or the
external command), so two specs that mean the same run share it. The
simulation's key leaves the odometry out: variants of one sequence share one
simulated sequence. Keys hash parameters, not code: after changing the code,
sweep into a fresh folder (or pass ``--rerun``).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from odometry.config import VARIANTS, ConfigError, OdometryConfig, config_from_dict, variant
from simlidar.formats.salo import FORMAT_VERSION
from simlidar.sensor import LidarModel, SensorError, load_sensor
from simlidar.yaml_file import read_yaml

DEFAULT_SCENES = ("city",)
DEFAULT_SEEDS = (0,)
DEFAULT_SENSORS = ("salo32",)
DEFAULT_VARIANTS = ("bl", "ncf", "salo")
DEFAULT_FRAMES = 100
KEY_LENGTH = 16  # hex digits of sha256: 64 bits, no collision in any sweep a person runs

SPEC_KEYS = (
    "name", "scenes", "seeds", "sensors", "noise_std_m", "variants", "frames", "speed_m_s", "start_s",
    "motion_distortion", "scene_params", "odometry", "configs", "commands", "keep_sequences",
)
# Placeholders an external odometry command must contain.
COMMAND_FIELDS = ("{sequence}", "{out}")


class SpecError(ValueError):
    """A sweep spec is invalid; the message names the file and the key."""


def stable_hash(data: Any) -> str:
    """Hex sha256 prefix of ``data`` as canonical JSON (sorted keys, no whitespace, repr floats)."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:KEY_LENGTH]


@dataclass(frozen=True)
class SimParams:
    """Everything that determines one simulated sequence.

    scene_overrides: the scene parameters as given (``speed_m_s`` included);
    scene_resolved: the scene's full validated parameter set (seed included);
    sensor: preset name or absolute YAML path; sensor_model: its model with the
    noise applied; noise_std_m: range noise std, m; start_s: path time of frame 0, s.
    """

    scene: str
    seed: int
    scene_overrides: dict
    scene_resolved: dict
    sensor: str
    sensor_model: LidarModel
    noise_std_m: float
    frames: int
    start_s: float
    motion_distortion: bool

    def key_data(self) -> dict:
        sensor = {k: v for k, v in self.sensor_model.to_dict().items() if k not in ("source", "description")}
        return {
            "format_version": FORMAT_VERSION,
            "scene": self.scene,
            "scene_params": self.scene_resolved,
            "sensor": sensor,
            "frames": self.frames,
            "start_s": self.start_s,
            "motion_distortion": self.motion_distortion,
        }

    @property
    def key(self) -> str:
        """Cache key of the simulated sequence (no odometry in it)."""
        return stable_hash(self.key_data())


@dataclass(frozen=True)
class RunParams:
    """One run: a simulated sequence and one odometry (a built-in config or an external command)."""

    sim: SimParams
    variant: str
    config: OdometryConfig | None
    command: str | None = None

    @property
    def sim_key(self) -> str:
        return self.sim.key

    @property
    def key(self) -> str:
        odometry = {"command": self.command} if self.command is not None else {"config": self.config.to_dict()}
        return stable_hash({"sim": self.sim.key_data(), "variant": self.variant, **odometry})

    @property
    def label(self) -> str:
        """Readable identity, e.g. ``city/seed0/salo32/noise0.02/salo`` (unique within a sweep)."""
        s = self.sim
        return f"{s.scene}/seed{s.seed}/{Path(s.sensor).stem}/noise{s.noise_std_m:g}/{self.variant}"

    def describe(self) -> dict:
        """The run's parameters as flat JSON-able columns (the result row's first columns)."""
        s = self.sim
        return {
            "label": self.label,
            "scene": s.scene,
            "seed": s.seed,
            "sensor": s.sensor,
            "noise_std_m": s.noise_std_m,
            "variant": self.variant,
            "frames": s.frames,
            "speed_m_s": s.scene_resolved.get("speed_m_s"),
            "start_s": s.start_s,
            "motion_distortion": s.motion_distortion,
            "scene_params": json.dumps(s.scene_overrides, sort_keys=True),
            "odometry": self.command if self.command is not None else json.dumps(
                _config_changes(self.config), sort_keys=True),
        }


def _config_changes(config: OdometryConfig) -> dict:
    """The fields where ``config`` differs from its base variant (short, readable rows)."""
    base = VARIANTS.get(config.name)
    full = config.to_dict()
    if base is None:
        return full
    ref = base.to_dict()
    return {k: v for k, v in full.items() if ref.get(k) != v}


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep specification (see the module docstring for the YAML).

    ``noise_std_m`` is None when the spec leaves each sensor's own noise.
    ``configs`` maps extra variant names to resolved configs; ``commands`` maps
    external variant names to command templates.
    """

    name: str = "sweep"
    scenes: tuple[str, ...] = DEFAULT_SCENES
    seeds: tuple[int, ...] = DEFAULT_SEEDS
    sensors: tuple[str, ...] = DEFAULT_SENSORS
    noise_std_m: tuple[float, ...] | None = None
    variants: tuple[str, ...] = DEFAULT_VARIANTS
    frames: int = DEFAULT_FRAMES
    speed_m_s: float | None = None
    start_s: float = 0.0
    motion_distortion: bool = True
    scene_params: dict = field(default_factory=dict)
    odometry: dict = field(default_factory=dict)
    configs: dict = field(default_factory=dict)
    commands: dict = field(default_factory=dict)
    keep_sequences: bool = True

    def to_dict(self) -> dict:
        """The spec as YAML-ready data (configs as their parameter overrides)."""
        return {
            "name": self.name,
            "scenes": list(self.scenes),
            "seeds": list(self.seeds),
            "sensors": list(self.sensors),
            "noise_std_m": None if self.noise_std_m is None else list(self.noise_std_m),
            "variants": list(self.variants),
            "frames": self.frames,
            "speed_m_s": self.speed_m_s,
            "start_s": self.start_s,
            "motion_distortion": self.motion_distortion,
            "scene_params": self.scene_params,
            "odometry": self.odometry,
            "configs": {k: v.to_dict() for k, v in self.configs.items()},
            "commands": self.commands,
            "keep_sequences": self.keep_sequences,
        }

    def runs(self) -> list[RunParams]:
        """The cross product scenes x seeds x sensors x noise x variants, in that nesting order."""
        import scenes as scene_lib

        out = []
        for scene, seed, sensor in itertools.product(self.scenes, self.seeds, self.sensors):
            overrides = dict(self.scene_params.get(scene, {}))
            if self.speed_m_s is not None:
                overrides["speed_m_s"] = self.speed_m_s
            resolved = scene_lib.resolve_params(scene, seed, **overrides).to_dict()
            model = load_sensor(sensor)
            for noise in self.noise_std_m if self.noise_std_m is not None else (model.range_noise_std_m,):
                sim = SimParams(scene, seed, overrides, resolved, sensor,
                                model.with_overrides(range_noise_std_m=float(noise)), float(noise), self.frames,
                                self.start_s, self.motion_distortion)
                for name in self.variants:
                    if name in self.commands:
                        out.append(RunParams(sim, name, None, self.commands[name]))
                    else:
                        out.append(RunParams(sim, name, self._config(name)))
        return out

    def _config(self, name: str) -> OdometryConfig:
        if name in self.configs:
            return self.configs[name]
        return variant(name).replace(**self.odometry) if self.odometry else variant(name)


# ---------------------------------------------------------------- parsing
def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec YAML file; sensor files are relative to its folder."""
    path = Path(path)
    data = read_yaml(path, SpecError, "the sweep spec")
    return spec_from_dict(data if data is not None else {}, origin=str(path), base_dir=path.parent)


def spec_from_dict(data: Any, origin: str = "sweep spec", base_dir: str | Path | None = None) -> SweepSpec:
    """Validate a spec mapping; every error names ``origin`` and the offending key."""

    def fail(key: str, problem: str) -> SpecError:
        return SpecError(f"{origin}: key '{key}': {problem}")

    if not isinstance(data, dict):
        raise SpecError(f"{origin}: expected a mapping of sweep keys (name, scenes, seeds, ...)")
    unknown = [k for k in data if k not in SPEC_KEYS]
    if unknown:
        raise fail(str(unknown[0]), f"unknown (known keys: {', '.join(SPEC_KEYS)})")
    get = data.get

    name = get("name", "sweep")
    if not isinstance(name, str) or not name or "/" in name:
        raise fail("name", f"must be a non-empty string without '/', got {name!r}")

    scenes = _str_list(get("scenes", list(DEFAULT_SCENES)), "scenes", fail)
    import scenes as scene_lib

    for s in scenes:
        if s not in scene_lib.SCENES:
            raise fail("scenes", f"unknown scene {s!r} (known: {', '.join(scene_lib.SCENES)})")

    seeds = _as_list(get("seeds", list(DEFAULT_SEEDS)), "seeds", fail)
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, int) or s < 0:
            raise fail("seeds", f"every seed must be an integer >= 0, got {s!r}")

    sensors = []
    for s in _str_list(get("sensors", list(DEFAULT_SENSORS)), "sensors", fail):
        if s.endswith((".yaml", ".yml")) and base_dir is not None and not Path(s).is_absolute():
            s = str((Path(base_dir) / s).resolve())
        try:
            load_sensor(s)
        except SensorError as exc:
            raise fail("sensors", str(exc)) from None
        sensors.append(s)
    stems = [Path(s).stem for s in sensors]
    if len(set(stems)) != len(stems):
        raise fail("sensors", "two sensors have the same name (runs are labelled by the file's stem)")

    noise = get("noise_std_m")
    if noise is not None:
        noise = _as_list(noise, "noise_std_m", fail)
        for n in noise:
            if isinstance(n, bool) or not isinstance(n, int | float) or not math.isfinite(n) or n < 0:
                raise fail("noise_std_m", f"every level must be a number >= 0 (metres), got {n!r}")
        noise = tuple(float(n) for n in noise)
        for s in sensors:
            for n in noise:
                try:
                    load_sensor(s).with_overrides(range_noise_std_m=n)
                except SensorError as exc:
                    raise fail("noise_std_m", f"{n:g} for sensor {s}: {exc}") from None

    frames = get("frames", DEFAULT_FRAMES)
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 2:
        raise fail("frames", f"must be an integer >= 2, got {frames!r}")
    speed = get("speed_m_s")
    if speed is not None and (isinstance(speed, bool) or not isinstance(speed, int | float) or not speed > 0):
        raise fail("speed_m_s", f"must be a number > 0 (m/s), got {speed!r}")
    start = get("start_s", 0.0)
    if isinstance(start, bool) or not isinstance(start, int | float) or not math.isfinite(start) or start < 0:
        raise fail("start_s", f"must be a number >= 0 (s), got {start!r}")
    for key in ("motion_distortion", "keep_sequences"):
        if not isinstance(get(key, True), bool):
            raise fail(key, f"must be true or false, got {get(key)!r}")

    scene_params = _mapping(get("scene_params", {}), "scene_params", fail)
    for scene, params in scene_params.items():
        if scene not in scenes:
            raise fail(f"scene_params.{scene}", f"not a scene of this sweep (scenes: {', '.join(scenes)})")
        params = _mapping(params, f"scene_params.{scene}", fail)
        if "seed" in params:
            raise fail(f"scene_params.{scene}.seed", "the seed is an axis: use the top-level 'seeds'")
        try:
            scene_lib.resolve_params(scene, 0, **{**params, **({"speed_m_s": speed} if speed else {})})
        except ValueError as exc:
            raise fail(f"scene_params.{scene}", str(exc)) from None

    odometry = _mapping(get("odometry", {}), "odometry", fail)
    if "name" in odometry:
        raise fail("odometry.name", "the variant is an axis: use 'variants' (or 'configs' for new ones)")
    try:
        variant("salo").replace(**odometry)
    except (ConfigError, TypeError) as exc:
        raise fail("odometry", str(exc)) from None

    commands = _mapping(get("commands", {}), "commands", fail)
    for cname, template in commands.items():
        if not isinstance(template, str) or not all(f in template for f in COMMAND_FIELDS):
            raise fail(f"commands.{cname}", f"must be a command line with {' and '.join(COMMAND_FIELDS)}, "
                                            f"got {template!r}")
    configs = {}
    for cname, params in _mapping(get("configs", {}), "configs", fail).items():
        params = dict(_mapping(params, f"configs.{cname}", fail))
        base_name = params.pop("base", "salo")
        if base_name not in VARIANTS:
            raise fail(f"configs.{cname}.base", f"must be one of {', '.join(VARIANTS)}, got {base_name!r}")
        try:
            configs[cname] = config_from_dict({**odometry, **params, "name": cname}, base=variant(base_name),
                                              origin=f"configs.{cname}")
        except ConfigError as exc:
            raise fail(f"configs.{cname}", str(exc)) from None
    clash = set(commands) & (set(configs) | set(VARIANTS)) or set(configs) & set(VARIANTS)
    if clash:
        raise fail("configs" if set(configs) & set(VARIANTS) else "commands",
                   f"name {sorted(clash)[0]!r} is already a variant")

    variants = _str_list(get("variants", list(DEFAULT_VARIANTS)), "variants", fail)
    known = [*VARIANTS, *configs, *commands]
    for v in variants:
        if v not in known:
            raise fail("variants", f"unknown variant {v!r} (known: {', '.join(known)})")

    for key, values in (("scenes", scenes), ("seeds", seeds), ("sensors", sensors), ("variants", variants),
                        ("noise_std_m", noise or ())):
        if len(set(values)) != len(values):
            raise fail(key, "lists a value twice")
    return SweepSpec(
        name=name, scenes=tuple(scenes), seeds=tuple(seeds), sensors=tuple(sensors), noise_std_m=noise,
        variants=tuple(variants), frames=frames, speed_m_s=None if speed is None else float(speed),
        start_s=float(start), motion_distortion=get("motion_distortion", True),
        scene_params={k: dict(v) for k, v in scene_params.items()}, odometry=dict(odometry), configs=configs,
        commands=dict(commands), keep_sequences=get("keep_sequences", True),
    )


def _as_list(value: Any, key: str, fail) -> list:
    """A scalar becomes a one-element axis; an empty list is an error (an empty sweep)."""
    values = value if isinstance(value, list | tuple) else [value]
    if not values:
        raise fail(key, "is empty (leave the key out for its default)")
    return list(values)


def _str_list(value: Any, key: str, fail) -> list[str]:
    values = _as_list(value, key, fail)
    for v in values:
        if not isinstance(v, str) or not v:
            raise fail(key, f"every entry must be a non-empty string, got {v!r}")
    return values


def _mapping(value: Any, key: str, fail) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise fail(key, f"must be a mapping of names to values, got {type(value).__name__}")
    return value


__all__ = ["RunParams", "SimParams", "SpecError", "SweepSpec", "load_spec", "spec_from_dict", "stable_hash"]
