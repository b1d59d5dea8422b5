"""Spinning-lidar sensor description: rings, angles, timing, noise; presets and YAML.

A ``LidarModel`` is frozen and validated when built. Lists given per laser
(``vertical_angles_deg``, ``azimuth_offsets_deg``) keep the order of the file,
which is the laser-id (firing) order; *ring indices* used everywhere else count
the beams by elevation, ring 0 being the lowest (as the common Velodyne driver
numbers its ``ring`` field).

Timing model: the head turns at ``rotation_hz``; one firing column every
``azimuth_step_deg`` of rotation, ``columns_per_sweep = floor(360 / phi)``
columns per sweep. Within a column the lasers fire in table order, one every
``laser_interval_s`` (0 means all lasers of a column fire together). The time
of a return within its sweep is ``column * column_period_s + slot * laser_interval_s``.

Azimuth convention (lidar frame: x forward, y left, z up): the sweep starts at
``start_azimuth_deg`` (180 = facing backwards, where KITTI cuts its scans) and
the head turns clockwise seen from above, as Velodyne and Ouster sensors do, so
column ``c`` looks at azimuth ``start - c * phi`` (plus the laser's own offset),
azimuth measured counter-clockwise from +x.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

from paramspec import Param, ParamError, Params, Section, param, schema, section

from .imu import ImuModel
from .weather import ReceiverParams, Weather
from .yaml_file import read_yaml


class SensorError(ParamError):
    """A sensor description is invalid; the message names the file or sensor, the key and the problem."""


def _non_empty(name: str) -> str | None:
    return None if name else "must be a non-empty string"


def _distinct(angles: tuple[float, ...]) -> str | None:
    if len(set(angles)) != len(angles):
        return "has repeated angles; every ring needs its own elevation"
    return None


@dataclass(frozen=True)
class LidarModel(Params):
    """A spinning multi-beam lidar (degrees and metres as in YAML; radian views are properties).

    Each field is a key of a sensor YAML file, declared with its type, unit,
    bounds and help (``salo sensors --keys``, ``docs/parameters.md``). Lists given
    per laser keep the file's (laser-id) order. ``ring_bias_std_m`` is a fixed
    per-laser range bias drawn once per sensor seed: real lasers have one, a
    systematic error. Rules between keys (ranges, per-laser lists, timing) are
    checked in ``__post_init__``.
    """

    error = SensorError
    section_name = "sensor"

    name: str = param(help="preset or user name", check=_non_empty)
    vertical_angles_deg: tuple[float, ...] = param(
        help="elevation of each laser, in laser-id (firing) order", above=-90.0, below=90.0, check=_distinct)
    azimuth_step_deg: float = param(help="phi: rotation of the head between two firing columns", above=0.0,
                                    max=360.0)
    rotation_hz: float = param(help="spin rate: one sweep lasts 1 / rotation_hz", above=0.0)
    range_noise_std_m: float = param(help="standard deviation of the Gaussian noise along the beam", min=0.0)
    min_range_m: float = param(help="returns measured nearer than this are dropped", min=0.0)
    max_range_m: float = param(help="returns measured farther than this are dropped", above=0.0)
    azimuth_offsets_deg: tuple[float, ...] | None = param(
        None, "horizontal offset of each laser, in laser-id order (null: none)")
    laser_interval_s: float = param(0.0, "time between successive lasers within a column (0: a column fires at "
                                    "once)", min=0.0)
    start_azimuth_deg: float = param(180.0, "azimuth of column 0 (180: facing backwards, where KITTI cuts its "
                                     "scans)")
    ring_bias_std_m: float = param(0.0, "standard deviation of a fixed per-laser range bias, drawn once per "
                                   "sensor seed (0: off)", min=0.0)
    angular_jitter_deg: float = param(0.0, "standard deviation of Gaussian jitter on each beam's elevation and "
                                      "azimuth (0: off)", min=0.0)
    dropout_probability: float = param(0.0, "chance that a return is lost (0: off)", min=0.0, below=1.0)
    intensity_range_ref_m: float = param(10.0, "range beyond which intensity falls off as 1/r^2", above=0.0)
    beam_divergence_deg: float = param(0.0, "full angle of the beam's cone: > 0 casts beam_subrays sub-rays over it "
                                       "and reports an echo of their hits (mixed pixels at depth edges) (0: off)",
                                       min=0.0, max=5.0)
    beam_subrays: int = param(16, "sub-rays over the divergence cone (a sunflower pattern: equal areas)", min=2,
                              max=256)
    return_mode: str = param("strongest", "the echo a beam reports when it has several (a divergent beam's, or a "
                             "surface's and the weather's): strongest (most power), first (nearest) or last "
                             "(farthest)", choices=("strongest", "first", "last"))
    echo_separation_m: float = param(0.5, "sub-ray hits nearer each other in range than this form one echo, at "
                                     "their power-weighted mean range (the pulse's range resolution)", min=0.0)
    incidence_noise_max_factor: float = param(1.0, "range noise std grows as range_noise_std_m / cos(incidence), up "
                                              "to this factor (1: off)", min=1.0)
    intensity_incidence_exponent: float = param(1.0, "k in intensity = reflectance x |cos incidence|^k x falloff "
                                                "(1: Lambertian)", min=0.0)
    receiver: ReceiverParams = section(ReceiverParams)
    weather: Weather = section(Weather)
    imu: ImuModel = section(ImuModel)
    description: str = param("", "free text")
    source: str = param("", "where the figures come from")

    def __post_init__(self) -> None:
        try:
            super().__post_init__()  # every key against its declaration
            _check_rules(self)
        except SensorError as exc:
            raise exc.at(f"sensor '{self.name}'") from None
        object.__setattr__(self, "vertical_angles_deg", tuple(float(a) for a in self.vertical_angles_deg))
        if self.azimuth_offsets_deg is not None:
            object.__setattr__(self, "azimuth_offsets_deg", tuple(float(a) for a in self.azimuth_offsets_deg))

    # ---- derived geometry, ring order (ring 0 = lowest beam) ----
    @property
    def rings(self) -> int:
        return len(self.vertical_angles_deg)

    @property
    def laser_of_ring(self) -> np.ndarray:
        """(rings,) int: laser id (table position) of each ring, rings by elevation."""
        return np.argsort(np.asarray(self.vertical_angles_deg), kind="stable")

    @property
    def elevation_rad(self) -> np.ndarray:
        """(rings,) float: elevation of each ring, ascending, radians."""
        return np.radians(np.asarray(self.vertical_angles_deg)[self.laser_of_ring])

    @property
    def ring_azimuth_offset_rad(self) -> np.ndarray:
        """(rings,) float: horizontal offset of each ring's laser, radians."""
        if self.azimuth_offsets_deg is None:
            return np.zeros(self.rings)
        return np.radians(np.asarray(self.azimuth_offsets_deg)[self.laser_of_ring])

    @property
    def ring_firing_slot(self) -> np.ndarray:
        """(rings,) int: position of each ring's laser in the firing sequence."""
        return self.laser_of_ring.copy()

    @property
    def ring_pitch_below_rad(self) -> np.ndarray:
        """(rings,) float: angle to the next ring below (nan for the lowest ring)."""
        el = self.elevation_rad
        return np.concatenate([[np.nan], np.diff(el)])

    @property
    def ring_pitch_above_rad(self) -> np.ndarray:
        """(rings,) float: angle to the next ring above (nan for the highest ring)."""
        el = self.elevation_rad
        return np.concatenate([np.diff(el), [np.nan]])

    @property
    def azimuth_step_rad(self) -> float:
        return math.radians(self.azimuth_step_deg)

    @property
    def columns_per_sweep(self) -> int:
        return int(math.floor(360.0 / self.azimuth_step_deg + 1e-9))

    @property
    def rays_per_sweep(self) -> int:
        return self.columns_per_sweep * self.rings

    @property
    def sweep_period_s(self) -> float:
        return 1.0 / self.rotation_hz

    @property
    def column_period_s(self) -> float:
        return self.azimuth_step_deg / (360.0 * self.rotation_hz)

    def column_azimuth_rad(self, columns: np.ndarray) -> np.ndarray:
        """Azimuth (rad, counter-clockwise from +x) the head faces at each column index."""
        return math.radians(self.start_azimuth_deg) - np.asarray(columns) * self.azimuth_step_rad

    def firing_time_s(self, rings: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Time within the sweep (s) at which ring ``rings`` fires in column ``columns``."""
        slot = self.ring_firing_slot[np.asarray(rings)]
        return np.asarray(columns) * self.column_period_s + slot * self.laser_interval_s

    def ring_of_elevation(self, elevation_rad: np.ndarray) -> np.ndarray:
        """Ring index (int) whose nominal elevation is closest to each given elevation."""
        el = self.elevation_rad
        mid = 0.5 * (el[1:] + el[:-1])
        return np.searchsorted(mid, np.asarray(elevation_rad)).astype(np.int32)

    def beam_pattern_rad(self) -> np.ndarray:
        """(beam_subrays, 2) angular offsets of the sub-rays from the beam's axis, rad: (across, up).

        A sunflower (Vogel) pattern: sub-ray s at radius ``half * sqrt((s + 0.5) / S)`` and angle
        ``s * 137.5 deg``, so each covers an equal share of the cone's disc (half: half the divergence).
        """
        S = self.beam_subrays
        k = np.arange(S)
        r = 0.5 * math.radians(self.beam_divergence_deg) * np.sqrt((k + 0.5) / S)
        phi = k * math.pi * (3.0 - math.sqrt(5.0))
        return np.column_stack([r * np.cos(phi), r * np.sin(phi)])

    def with_overrides(self, **changes) -> LidarModel:
        """A new validated model with some fields replaced (e.g. ``range_noise_std_m``)."""
        return dataclasses.replace(self, **changes)

    def clear_air(self) -> LidarModel:
        """The same sensor without weather (its receiver kept): what a method under test is told of it."""
        return self if not self.weather.on else dataclasses.replace(self, weather=Weather())

    # ---- YAML ----
    def to_dict(self) -> dict:
        out = {
            "name": self.name,
            "rings": self.rings,
            "vertical_angles_deg": list(self.vertical_angles_deg),
            "azimuth_step_deg": self.azimuth_step_deg,
            "rotation_hz": self.rotation_hz,
            "range_noise_std_m": self.range_noise_std_m,
            "min_range_m": self.min_range_m,
            "max_range_m": self.max_range_m,
            "laser_interval_s": self.laser_interval_s,
            "start_azimuth_deg": self.start_azimuth_deg,
            "ring_bias_std_m": self.ring_bias_std_m,
            "angular_jitter_deg": self.angular_jitter_deg,
            "dropout_probability": self.dropout_probability,
            "intensity_range_ref_m": self.intensity_range_ref_m,
        }
        # The effects below are written only when on, so that files of sensors without them stay as they were.
        defaults = {p.name: p.default for p in schema(LidarModel).members if isinstance(p, Param)}
        for key in ("beam_divergence_deg", "beam_subrays", "return_mode", "echo_separation_m",
                    "incidence_noise_max_factor", "intensity_incidence_exponent"):
            if getattr(self, key) != defaults[key] or (key in ("beam_subrays", "return_mode", "echo_separation_m")
                                                        and self.beam_divergence_deg > 0):
                out[key] = getattr(self, key)
        if self.receiver != ReceiverParams():
            out["receiver"] = dataclasses.asdict(self.receiver)
        if self.weather.to_dict():
            out["weather"] = self.weather.to_dict()
        if self.azimuth_offsets_deg is not None:
            out["azimuth_offsets_deg"] = list(self.azimuth_offsets_deg)
        if self.imu.enabled:  # the IMU's keys, all of them, only when it is on
            out["imu"] = self.imu.to_dict()
        if self.description:
            out["description"] = self.description
        if self.source:
            out["source"] = self.source
        return out

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None, width=100)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_yaml())


def _check_rules(m: LidarModel) -> None:
    """The rules between keys (each key's own bounds are in its declaration)."""
    if not (m.min_range_m < m.max_range_m):
        raise SensorError(f"must be < max_range_m ({m.min_range_m} >= {m.max_range_m})", "min_range_m")
    if m.azimuth_offsets_deg is not None and len(m.azimuth_offsets_deg) != m.rings:
        raise SensorError(f"has {len(m.azimuth_offsets_deg)} entries but there are {m.rings} rings",
                          "azimuth_offsets_deg")
    if (m.rings - 1) * m.laser_interval_s >= m.column_period_s + 1e-12:
        raise SensorError(f"is too long: {m.laser_interval_s} s x {m.rings} lasers does not fit in one column "
                          f"({m.column_period_s:.3e} s at this azimuth step and rotation rate)", "laser_interval_s")
    if m.weather.on and not m.receiver.enabled:
        on = [k for k in ("fog", "rain", "snow") if getattr(m.weather, k).enabled]
        raise SensorError(f"is false, but weather ({', '.join(on)}) acts on the received power: set receiver.enabled "
                          "(and its detection_range_m)", "receiver.enabled")


def _file_keys() -> Section:
    """The keys of a sensor YAML file: the model's, with the rings and the uniform-pitch form of the angles."""
    model = {p.name: p for p in schema(LidarModel).members}
    angles = dataclasses.replace(model["vertical_angles_deg"], default=None, nullable=True,
                                 help="elevation of each laser, in laser-id (firing) order (or give "
                                      "ring_pitch_deg and lowest_angle_deg)")
    rings = Param("rings", "int", help="number of lasers", min=1)
    pitch = Param("ring_pitch_deg", "float", None, "uniform elevation step between rings (with "
                  "lowest_angle_deg, instead of vertical_angles_deg)", "deg", above=0.0, nullable=True)
    lowest = Param("lowest_angle_deg", "float", None, "elevation of the lowest ring (with ring_pitch_deg)",
                   "deg", above=-90.0, below=90.0, nullable=True)
    order = ["name", rings, "azimuth_step_deg", "rotation_hz", "range_noise_std_m", "min_range_m", "max_range_m",
             angles, pitch, lowest, "azimuth_offsets_deg", "laser_interval_s", "start_azimuth_deg",
             "ring_bias_std_m", "angular_jitter_deg", "dropout_probability", "intensity_range_ref_m",
             "beam_divergence_deg", "beam_subrays", "return_mode", "echo_separation_m", "incidence_noise_max_factor",
             "intensity_incidence_exponent", "receiver", "weather", "imu", "description", "source"]
    members = tuple(model[k] if isinstance(k, str) else k for k in order)
    return Section("sensor", members, "a spinning lidar's rings, timing, ranges and noise", LidarModel)


# The keys of a sensor file (``salo sensors --keys``, docs/parameters.md).
SENSOR_FILE = _file_keys()


def from_dict(data: dict, origin: str = "sensor description") -> LidarModel:
    """Build a validated ``LidarModel`` from a YAML-style dict (``SENSOR_FILE``'s keys).

    Either ``vertical_angles_deg`` (one per ring) or ``ring_pitch_deg`` +
    ``lowest_angle_deg`` (uniform pitch) must be given together with ``rings``.
    Errors name ``origin`` (usually the file) and the sensor, the key and the problem.
    """
    where = f"{origin} (sensor '{data.get('name', '?')}')" if isinstance(data, dict) else origin
    values = SENSOR_FILE.read(data, where, error=SensorError)

    def fail(key: str, problem: str) -> SensorError:
        return SensorError(problem, key, where)

    rings = values.pop("rings")
    angles = values.pop("vertical_angles_deg", None)
    pitch, lowest = values.pop("ring_pitch_deg", None), values.pop("lowest_angle_deg", None)
    if angles is not None:
        if pitch is not None or lowest is not None:
            raise fail("ring_pitch_deg", "cannot be given together with vertical_angles_deg")
        if len(angles) != rings:
            raise fail("rings", f"is {rings} but vertical_angles_deg lists {len(angles)} angles")
    else:
        for key, value in (("ring_pitch_deg", pitch), ("lowest_angle_deg", lowest)):
            if value is None:
                raise fail(key, "is missing (give vertical_angles_deg, or ring_pitch_deg and lowest_angle_deg)")
        angles = tuple(lowest + k * pitch for k in range(rings))
    try:
        return LidarModel(vertical_angles_deg=angles, **values)
    except SensorError as exc:
        raise exc.at(where) from None


def load_sensor_file(path: str | Path) -> LidarModel:
    """Read and validate a sensor YAML file."""
    data = read_yaml(path, SensorError, "sensor file")
    return from_dict(data, origin=str(path))


def preset_names() -> list[str]:
    """Names of the sensor presets shipped with the package."""
    folder = resources.files("simlidar") / "presets"
    return sorted(p.name[: -len(".yaml")] for p in folder.iterdir() if p.name.endswith(".yaml"))


def load_preset(name: str) -> LidarModel:
    """A shipped preset by name (``salo32``, ``vlp16``, ``hdl32e``, ``hdl64e``, ``os1-64``)."""
    names = preset_names()
    if name not in names:
        raise SensorError(f"unknown sensor preset '{name}' (known presets: {', '.join(names)})")
    text = (resources.files("simlidar") / "presets" / f"{name}.yaml").read_text()
    return from_dict(yaml.safe_load(text), origin=f"preset {name}")


def load_sensor(spec: str | Path | LidarModel) -> LidarModel:
    """A preset name, a path to a sensor YAML file, or a model (returned unchanged)."""
    if isinstance(spec, LidarModel):
        return spec
    spec_str = str(spec)
    if spec_str in preset_names():
        return load_preset(spec_str)
    if spec_str.endswith((".yaml", ".yml")) or Path(spec_str).exists():
        return load_sensor_file(spec_str)
    return load_preset(spec_str)  # raises with the list of known presets
