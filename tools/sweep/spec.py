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
    odometry: {filter: {voxel_size_m: 0.5}}   # overrides for every built-in variant (odometry.config's keys)
    configs: {salo-v04: {base: salo, filter: {voxel_size_m: 0.4}}}   # extra named variants
    commands: {mine: "my_odometry {scans} {sensor} {out}"}  # external odometries as variants (tools.methods)
    fields: [ring, time_s]            # per-point fields handed to every method (default; [none]: x y z only)

Variants name our configurations, ``configs``, ``commands``, or any other method
``tools.methods`` knows: a peer (``kiss-icp``, ``genz-icp``, ``small-gicp``) or an
installed plug-in (entry-point group ``salo.methods``). Every method runs on a
staged copy of the sequence without its ground truth (``tools.staging``).

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from odometry.config import SALO, VARIANTS, OdometryConfig, config_from_dict, variant
from paramspec import ParamError, Params, differences, param, schema
from simlidar.formats.salo import FORMAT_VERSION
from simlidar.sensor import LidarModel, SensorError, load_sensor
from simlidar.yaml_file import read_yaml
from tools.staging import DEFAULT_FIELDS, SENSOR_FIELDS, StagingError, check_fields

DEFAULT_SCENES = ("city",)
DEFAULT_SEEDS = (0,)
DEFAULT_SENSORS = ("salo32",)
DEFAULT_VARIANTS = ("bl", "ncf", "salo")
DEFAULT_FRAMES = 100
KEY_LENGTH = 16  # hex digits of sha256: 64 bits, no collision in any sweep a person runs


class SpecError(ParamError):
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
    """One run: a simulated sequence and one odometry (a built-in config, an external command, or a
    named method of ``tools.methods``: a peer or a plug-in), handed the per-point ``fields``."""

    sim: SimParams
    variant: str
    config: OdometryConfig | None
    command: str | None = None
    method: str | None = None
    fields: tuple[str, ...] = DEFAULT_FIELDS

    @property
    def sim_key(self) -> str:
        return self.sim.key

    @property
    def key(self) -> str:
        if self.command is not None:
            odometry = {"command": self.command}
        elif self.method is not None:
            from tools.methods import method_from_name

            odometry = {"method": method_from_name(self.method).identity()}
        else:
            odometry = {"config": self.config.to_dict()}
        return stable_hash({"sim": self.sim.key_data(), "variant": self.variant, "fields": list(self.fields),
                            **odometry})

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
            "odometry": self.command if self.command is not None else self.method if self.method is not None
            else json.dumps(_config_changes(self.config), sort_keys=True),
        }


def _config_changes(config: OdometryConfig) -> dict:
    """The dotted keys where ``config`` differs from its base variant (short, readable rows)."""
    base = VARIANTS.get(config.name)
    return config.to_dict() if base is None else differences(config, base)


def _fields_problem(fields: tuple[str, ...]) -> str | None:
    if fields == ("none",):
        return None
    try:
        check_fields(fields)
    except StagingError as exc:
        return str(exc).removeprefix("fields: ")
    return None


def _sweep_name(name: str) -> str | None:
    return None if name and "/" not in name else f"must be a non-empty string without '/', got {name!r}"


@dataclass(frozen=True)
class SweepSpec(Params):
    """A validated sweep specification (see the module docstring for the YAML).

    Each field is a key of the YAML, declared with its type, unit, bounds and
    help (``salo sweep --help``, ``docs/parameters.md``). An axis (scenes, seeds,
    sensors, noise_std_m, variants) may be one value or a list. ``noise_std_m``
    is None when the spec leaves each sensor's own noise. ``configs`` maps extra
    variant names to resolved configs; ``commands`` maps external variant names
    to command templates. ``spec_from_dict`` checks what the keys mean
    together (known scenes, sensors and variants, per-scene parameters).
    """

    error = SpecError
    section_name = "sweep spec"

    name: str = param("sweep", "the sweep's name (default output folder: out/sweeps/NAME)", check=_sweep_name)
    scenes: tuple[str, ...] = param(DEFAULT_SCENES, "procedural scenes (`salo scenes`)", one_or_more=True,
                                    unique=True)
    seeds: tuple[int, ...] = param(DEFAULT_SEEDS, "seeds: each seeds the scene and the sensor noise", min=0,
                                   one_or_more=True, unique=True)
    sensors: tuple[str, ...] = param(DEFAULT_SENSORS, "sensor presets (`salo sensors`) or YAML files, relative "
                                     "to the spec", one_or_more=True, unique=True)
    noise_std_m: tuple[float, ...] | None = param(None, "range noise standard deviations (null: each sensor's "
                                                  "own)", min=0.0, one_or_more=True, unique=True)
    variants: tuple[str, ...] = param(DEFAULT_VARIANTS, "odometry variants: built-in (bl, ncf, salo, ...), "
                                      "configs or commands", one_or_more=True, unique=True)
    frames: int = param(DEFAULT_FRAMES, "sweeps per sequence", min=2)
    speed_m_s: float | None = param(None, "cruise speed (null: the scene's own)", above=0.0)
    start_s: float = param(0.0, "time along the path of the first sweep", min=0.0)
    motion_distortion: bool = param(True, "simulate the sensor's motion during each sweep")
    scene_params: dict = param({}, "per scene, parameter overrides: {SCENE: {KEY: VALUE}} (`salo scenes NAME`)")
    odometry: dict = param({}, "odometry parameter overrides for every built-in variant")
    configs: dict = param({}, "extra variants: {NAME: {base: VARIANT, KEY: VALUE, ...}}")
    commands: dict = param({}, "external odometries as variants: {NAME: \"command with {scans} (or {sequence}) "
                           "and {out}\"}; also {sensor}, {times}, {fields}")
    fields: tuple[str, ...] = param(DEFAULT_FIELDS, "per-point fields every method is handed (none: x y z "
                                    f"intensity only; of {', '.join(SENSOR_FIELDS)})", one_or_more=True,
                                    unique=True, check=_fields_problem)
    sequences: str = param("memory", "where a sequence lives while its runs use it: memory (each worker "
                           "simulates it, nothing is written but the runs' poses and metrics) or disk (the store's "
                           "sequences/ folder); every method, an external command too, gets a staged copy of the "
                           "sensor's data either way (tools.staging)",
                           choices=("memory", "disk"))
    keep_sequences: bool = param(True, "with sequences: disk, keep the simulated sequences for reuse (false: "
                                 "delete each once its runs are done)")

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
            "fields": list(self.fields) or ["none"],
            "sequences": self.sequences,
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
                        out.append(RunParams(sim, name, None, self.commands[name], fields=self.fields))
                    elif name in self.configs or name in VARIANTS:
                        out.append(RunParams(sim, name, self._config(name), fields=self.fields))
                    else:  # a peer or a plug-in (checked by spec_from_dict)
                        out.append(RunParams(sim, name, None, method=name, fields=self.fields))
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
    """Validate a spec mapping; every error names ``origin`` and the offending key.

    Each key's type and range come from ``SweepSpec``'s declarations; here the
    rules that need the scenes, the sensors and the variants.
    """
    import scenes as scene_lib

    def fail(key: str, problem: str) -> SpecError:
        return SpecError(problem, key, origin)

    v = {**_defaults(), **schema(SweepSpec).read(data, origin, error=SpecError)}
    for s in v["scenes"]:
        if s not in scene_lib.SCENES:
            raise fail("scenes", f"names an unknown scene {s!r} (known: {', '.join(scene_lib.SCENES)})")

    sensors = []
    for s in v["sensors"]:
        if s.endswith((".yaml", ".yml")) and base_dir is not None and not Path(s).is_absolute():
            s = str((Path(base_dir) / s).resolve())
        try:
            load_sensor(s)
        except SensorError as exc:
            raise fail("sensors", f"is invalid: {exc}") from None
        sensors.append(s)
    stems = [Path(s).stem for s in sensors]
    if len(set(stems)) != len(stems):
        raise fail("sensors", "names two sensors alike (runs are labelled by the file's stem)")
    v["sensors"] = tuple(sensors)

    if v["noise_std_m"] is not None:
        v["noise_std_m"] = tuple(float(n) for n in v["noise_std_m"])
        for s in sensors:
            for n in v["noise_std_m"]:
                try:
                    load_sensor(s).with_overrides(range_noise_std_m=n)
                except SensorError as exc:
                    raise fail("noise_std_m", f"has {n:g}, invalid for sensor {s}: {exc}") from None
    speed = v["speed_m_s"]
    v["speed_m_s"], v["start_s"] = None if speed is None else float(speed), float(v["start_s"])

    for scene, params in v["scene_params"].items():
        key = f"scene_params.{scene}"
        if scene not in v["scenes"]:
            raise fail(key, f"is not a scene of this sweep (scenes: {', '.join(v['scenes'])})")
        if params is not None and not (isinstance(params, dict) and all(isinstance(k, str) for k in params)):
            raise fail(key, f"must be a mapping of names to values, got {type(params).__name__}")
        params = v["scene_params"][scene] = dict(params or {})
        if "seed" in params:
            raise fail(f"{key}.seed", "is not a scene parameter here: the seed is an axis, use the top-level 'seeds'")
        try:
            scene_lib.resolve_params(scene, 0, **{**params, **({"speed_m_s": speed} if speed else {})})
        except ParamError as exc:
            raise exc.within(key).as_(SpecError).at(origin) from None

    odometry = v["odometry"]
    if "name" in odometry:
        raise fail("odometry.name", "is not an override: the variant is an axis, use 'variants' (or 'configs' for "
                                    "new ones)")
    try:
        config_from_dict(odometry, base=SALO)
    except ParamError as exc:
        raise exc.within("odometry").as_(SpecError).at(origin) from None

    from tools.methods import command_problem, known_names

    for cname, template in v["commands"].items():
        problem = command_problem(template)
        if problem:
            raise fail(f"commands.{cname}", problem)
    v["fields"] = () if v["fields"] == ("none",) else tuple(v["fields"])
    configs = {}
    for cname, params in v["configs"].items():
        if params is not None and not isinstance(params, dict):
            raise fail(f"configs.{cname}", f"must be a mapping of names to values, got {type(params).__name__}")
        params = dict(params or {})
        base_name = params.pop("base", "salo")
        if base_name not in VARIANTS:
            raise fail(f"configs.{cname}.base", f"must be one of {', '.join(VARIANTS)}, got {base_name!r}")
        try:  # the overrides for every variant, then the config's own
            configs[cname] = config_from_dict({**params, "name": cname}, base=variant(base_name).replace(**odometry))
        except ParamError as exc:
            raise exc.within(f"configs.{cname}").as_(SpecError).at(origin) from None
    clash = set(v["commands"]) & (set(configs) | set(VARIANTS)) or set(configs) & set(VARIANTS)
    if clash:
        raise fail("configs" if set(configs) & set(VARIANTS) else "commands",
                   f"names {sorted(clash)[0]!r}, which is already a variant")
    v["configs"] = configs

    others = known_names()
    named = [*others["peers"], *others["plug-ins"]]
    known = [*VARIANTS, *configs, *v["commands"]]
    for name in v["variants"]:
        if name not in known and name not in named:
            raise fail("variants", f"names an unknown variant {name!r} (known: {', '.join(known + named)})")
    return SweepSpec(**v)


def _defaults() -> dict:
    """The declared defaults (the mappings copied: the declaration's own stay empty)."""
    return {p.name: dict(p.default) if isinstance(p.default, dict) else p.default for p in schema(SweepSpec).members}


__all__ = ["RunParams", "SimParams", "SpecError", "SweepSpec", "load_spec", "spec_from_dict", "stable_hash"]
