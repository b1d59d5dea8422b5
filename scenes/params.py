"""Scene parameters: frozen dataclasses whose fields carry help text and bounds.

Every scene has a ``Params`` class deriving from ``CommonParams`` (seed, the
trajectory's speed profile, mount height, suspension, face budget). A field's
``metadata`` holds ``help`` and optional ``min`` / ``max`` / ``choices``;
``resolve`` turns user overrides (strings from the command line or values from
YAML) into a validated instance, and every error is a ``ValueError`` that
names the parameter.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any


def param(default: Any, help: str, min: float | None = None, max: float | None = None,
          choices: tuple[str, ...] | None = None) -> Any:
    """A dataclass field with help text and bounds (inclusive) for validation."""
    meta = {"help": help, "min": min, "max": max, "choices": choices}
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class CommonParams:
    """Parameters shared by every scene: seed, trajectory and budget."""

    seed: int = param(0, "random seed: the same seed and parameters give an identical mesh", min=0)
    speed_m_s: float = param(10.0, "cruise speed of the vehicle, m/s", min=0.5, max=60.0)
    accel_m_s2: float = param(1.5, "longitudinal acceleration and braking limit, m/s^2", min=0.1, max=10.0)
    lateral_accel_m_s2: float = param(
        2.0, "lateral acceleration allowed in turns (slows the vehicle in curves), m/s^2", min=0.1, max=10.0
    )
    mount_height_m: float = param(1.9, "lidar height above the road (roof mount), m", min=0.3, max=5.0)
    suspension_pitch_deg: float = param(
        0.3, "amplitude of the body's pitch/roll oscillation at cruise speed, deg", min=0.0, max=5.0
    )
    suspension_heave_m: float = param(
        0.01, "amplitude of the body's vertical oscillation at cruise speed, m", min=0.0, max=0.2
    )
    max_triangles: int = param(1_000_000, "face budget: building a larger mesh is an error", min=1000)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            _check_value(type(self).__name__, f, getattr(self, f.name))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _check_value(owner: str, f: dataclasses.Field, value: Any) -> None:
    meta = f.metadata
    if meta.get("choices") is not None:
        if value not in meta["choices"]:
            raise ValueError(f"parameter {f.name}: {value!r} is not one of {', '.join(meta['choices'])}")
        return
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ValueError(f"parameter {f.name}: {value!r} is not a finite number")
        if meta.get("min") is not None and value < meta["min"]:
            raise ValueError(f"parameter {f.name}: {value!r} is below the minimum {meta['min']}")
        if meta.get("max") is not None and value > meta["max"]:
            raise ValueError(f"parameter {f.name}: {value!r} is above the maximum {meta['max']}")


def _coerce(name: str, type_name: str, value: Any) -> Any:
    """Convert a command-line string or YAML value to the field's type; errors name the field."""
    t = type_name if isinstance(type_name, str) else getattr(type_name, "__name__", str(type_name))
    try:
        if t == "bool":
            if isinstance(value, bool):
                return value
            if isinstance(value, str) and value.strip().lower() in ("1", "true", "yes", "on"):
                return True
            if isinstance(value, str) and value.strip().lower() in ("0", "false", "no", "off"):
                return False
            if isinstance(value, int) and value in (0, 1):
                return bool(value)
            raise ValueError
        if t == "int":
            if isinstance(value, bool):
                raise ValueError
            if isinstance(value, float):
                if not value.is_integer():
                    raise ValueError
                return int(value)
            return int(str(value).replace("_", ""))
        if t == "float":
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        if t == "str":
            return str(value)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name}: {value!r} is not a valid {t}") from None
    return value


def resolve(cls: type[CommonParams], overrides: dict[str, Any] | None = None) -> CommonParams:
    """Defaults of ``cls`` with ``overrides`` applied, converted and validated.

    Unknown names and bad values raise ``ValueError`` naming the parameter.
    """
    overrides = dict(overrides or {})
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in overrides.items():
        if key not in fields:
            raise ValueError(
                f"parameter {key}: unknown for {cls.__module__.rsplit('.', 1)[-1]} "
                f"(known: {', '.join(sorted(fields))})"
            )
        kwargs[key] = _coerce(key, fields[key].type, value)
    return cls(**kwargs)


@dataclass(frozen=True)
class ParamInfo:
    """One parameter as listed by ``salo scenes``."""

    name: str
    default: Any
    type: str
    help: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None


def describe(cls: type[CommonParams]) -> list[ParamInfo]:
    """The parameters of a scene, scene-specific first then the common ones."""
    common = {f.name for f in dataclasses.fields(CommonParams)}
    out = []
    for f in dataclasses.fields(cls):
        t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        m = f.metadata
        out.append(ParamInfo(f.name, f.default, t, m.get("help", ""), m.get("min"), m.get("max"),
                             m.get("choices")))
    return [p for p in out if p.name not in common] + [p for p in out if p.name in common]
