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

from .yaml_file import read_yaml

REQUIRED_KEYS = (
    "name",
    "rings",
    "azimuth_step_deg",
    "rotation_hz",
    "range_noise_std_m",
    "min_range_m",
    "max_range_m",
)
OPTIONAL_KEYS = (
    "vertical_angles_deg",
    "ring_pitch_deg",
    "lowest_angle_deg",
    "azimuth_offsets_deg",
    "laser_interval_s",
    "start_azimuth_deg",
    "ring_bias_std_m",
    "angular_jitter_deg",
    "dropout_probability",
    "intensity_range_ref_m",
    "description",
    "source",
)


class SensorError(ValueError):
    """A sensor description is invalid; the message names the key and the problem."""


@dataclass(frozen=True)
class LidarModel:
    """A spinning multi-beam lidar.

    Attributes (degrees and metres as in YAML; radian views are properties):
        name: preset or user name.
        vertical_angles_deg: (rings,) elevation of each laser in laser-id order.
        azimuth_step_deg: phi, rotation between two firing columns.
        rotation_hz: spin rate; one sweep lasts ``1 / rotation_hz`` s.
        range_noise_std_m: standard deviation of Gaussian noise along the beam.
        min_range_m, max_range_m: returns outside this measured range are dropped.
        azimuth_offsets_deg: (rings,) per-laser horizontal offset (laser-id order).
        laser_interval_s: time between successive lasers within a column.
        start_azimuth_deg: azimuth of column 0.
        ring_bias_std_m: std of a fixed per-laser range bias drawn once per sensor
            seed (0 = off). Real lasers have one; it is a systematic error.
        angular_jitter_deg: std of Gaussian jitter on each beam's elevation and
            azimuth (0 = off).
        dropout_probability: chance that a return is lost (0 = off).
        intensity_range_ref_m: range beyond which intensity falls off as 1/r^2.
        description, source: free text; ``source`` cites where the figures come from.
    """

    name: str
    vertical_angles_deg: tuple[float, ...]
    azimuth_step_deg: float
    rotation_hz: float
    range_noise_std_m: float
    min_range_m: float
    max_range_m: float
    azimuth_offsets_deg: tuple[float, ...] | None = None
    laser_interval_s: float = 0.0
    start_azimuth_deg: float = 180.0
    ring_bias_std_m: float = 0.0
    angular_jitter_deg: float = 0.0
    dropout_probability: float = 0.0
    intensity_range_ref_m: float = 10.0
    description: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertical_angles_deg", tuple(float(a) for a in self.vertical_angles_deg))
        if self.azimuth_offsets_deg is not None:
            object.__setattr__(
                self, "azimuth_offsets_deg", tuple(float(a) for a in self.azimuth_offsets_deg)
            )
        _validate(self)

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

    def with_overrides(self, **changes) -> LidarModel:
        """A new validated model with some fields replaced (e.g. ``range_noise_std_m``)."""
        return dataclasses.replace(self, **changes)

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
        if self.azimuth_offsets_deg is not None:
            out["azimuth_offsets_deg"] = list(self.azimuth_offsets_deg)
        if self.description:
            out["description"] = self.description
        if self.source:
            out["source"] = self.source
        return out

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None, width=100)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_yaml())


def _validate(m: LidarModel) -> None:
    def fail(key: str, problem: str) -> None:
        raise SensorError(f"sensor '{m.name}': key '{key}' {problem}")

    if not isinstance(m.name, str) or not m.name:
        fail("name", "must be a non-empty string")
    if m.rings < 1:
        fail("vertical_angles_deg", "must list at least one angle")
    angles = np.asarray(m.vertical_angles_deg)
    if not np.all(np.isfinite(angles)) or np.any(np.abs(angles) >= 90):
        fail("vertical_angles_deg", "must be finite angles strictly between -90 and 90 degrees")
    if len(np.unique(angles)) != len(angles):
        fail("vertical_angles_deg", "has repeated angles; every ring needs its own elevation")
    if not (m.azimuth_step_deg > 0) or m.azimuth_step_deg > 360:
        fail("azimuth_step_deg", f"must be in (0, 360], got {m.azimuth_step_deg}")
    if not (m.rotation_hz > 0):
        fail("rotation_hz", f"must be > 0, got {m.rotation_hz}")
    for key in ("range_noise_std_m", "ring_bias_std_m", "angular_jitter_deg", "laser_interval_s"):
        v = getattr(m, key)
        if not (np.isfinite(v) and v >= 0):
            fail(key, f"must be a non-negative number, got {v}")
    if not (0 <= m.dropout_probability < 1):
        fail("dropout_probability", f"must be in [0, 1), got {m.dropout_probability}")
    if not (m.min_range_m >= 0):
        fail("min_range_m", f"must be >= 0, got {m.min_range_m}")
    if not (m.min_range_m < m.max_range_m):
        fail("min_range_m", f"must be < max_range_m ({m.min_range_m} >= {m.max_range_m})")
    if not np.isfinite(m.max_range_m):
        fail("max_range_m", "must be finite")
    if not (m.intensity_range_ref_m > 0):
        fail("intensity_range_ref_m", f"must be > 0, got {m.intensity_range_ref_m}")
    if m.azimuth_offsets_deg is not None and len(m.azimuth_offsets_deg) != m.rings:
        fail(
            "azimuth_offsets_deg",
            f"has {len(m.azimuth_offsets_deg)} entries but there are {m.rings} rings",
        )
    if (m.rings - 1) * m.laser_interval_s >= m.column_period_s + 1e-12:
        fail(
            "laser_interval_s",
            f"{m.laser_interval_s} s x {m.rings} lasers does not fit in one column "
            f"({m.column_period_s:.3e} s at this azimuth step and rotation rate)",
        )


def from_dict(data: dict, origin: str = "sensor description") -> LidarModel:
    """Build a validated ``LidarModel`` from a YAML-style dict.

    Either ``vertical_angles_deg`` (one per ring) or ``ring_pitch_deg`` +
    ``lowest_angle_deg`` (uniform pitch) must be given together with ``rings``.
    Errors name ``origin`` (usually the file), the key and the problem.
    """
    if not isinstance(data, dict):
        raise SensorError(f"{origin}: expected a mapping of sensor keys, got {type(data).__name__}")
    name = data.get("name", "?")

    def fail(key: str, problem: str) -> None:
        raise SensorError(f"{origin} (sensor '{name}'): key '{key}' {problem}")

    unknown = sorted(set(data) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS))
    if unknown:
        fail(unknown[0], f"is not a sensor key (known: {', '.join(REQUIRED_KEYS + OPTIONAL_KEYS)})")
    for key in REQUIRED_KEYS:
        if key not in data:
            fail(key, "is missing")
    numeric = [k for k in REQUIRED_KEYS + OPTIONAL_KEYS if k not in ("name", "description", "source")]
    for key in numeric:
        if key in data and key not in ("vertical_angles_deg", "azimuth_offsets_deg"):
            if isinstance(data[key], bool) or not isinstance(data[key], int | float):
                fail(key, f"must be a number, got {data[key]!r}")
    rings = data["rings"]
    if not isinstance(rings, int) or rings < 1:
        fail("rings", f"must be a positive integer, got {rings!r}")
    if "vertical_angles_deg" in data:
        if "ring_pitch_deg" in data or "lowest_angle_deg" in data:
            fail("ring_pitch_deg", "cannot be given together with vertical_angles_deg")
        angles = data["vertical_angles_deg"]
        if not isinstance(angles, list | tuple) or not all(
            isinstance(a, int | float) and not isinstance(a, bool) for a in angles
        ):
            fail("vertical_angles_deg", "must be a list of numbers (degrees)")
        if len(angles) != rings:
            fail("rings", f"is {rings} but vertical_angles_deg lists {len(angles)} angles")
    else:
        for key in ("ring_pitch_deg", "lowest_angle_deg"):
            if key not in data:
                fail(key, "is missing (give vertical_angles_deg, or ring_pitch_deg and lowest_angle_deg)")
        if not data["ring_pitch_deg"] > 0:
            fail("ring_pitch_deg", f"must be > 0, got {data['ring_pitch_deg']}")
        angles = [data["lowest_angle_deg"] + k * data["ring_pitch_deg"] for k in range(rings)]
    kwargs = {
        k: data[k]
        for k in REQUIRED_KEYS + OPTIONAL_KEYS
        if k in data and k not in ("rings", "ring_pitch_deg", "lowest_angle_deg", "vertical_angles_deg")
    }
    try:
        return LidarModel(vertical_angles_deg=tuple(angles), **kwargs)
    except SensorError as exc:
        raise SensorError(f"{origin}: {exc}") from None


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
