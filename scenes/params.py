"""Scene parameters: frozen dataclasses declared with ``paramspec``.

Every scene has a ``Params`` class deriving from ``CommonParams`` (seed, the
trajectory's speed profile, mount height, suspension, face budget), each field
a ``param(default, help, min=, max=, choices=)`` whose unit is its name's
suffix. ``resolve`` turns user overrides (command-line text or YAML values)
into a validated instance; every error is a ``ParamError`` (a ``ValueError``)
naming the scene and the parameter. Rules between parameters live in a scene's
``__post_init__`` and raise ``ParamError(problem, key)`` too.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

from paramspec import Param, ParamError, Params, Section, build, param, schema, section

from .traffic import TrafficParams

# What ``salo scenes`` lists per parameter (name, type, default, unit, help, min, max, choices).
ParamInfo = Param


@dataclass(frozen=True)
class CommonParams(Params):
    """Parameters shared by every scene: seed, trajectory and budget."""

    section_name = "scene"

    seed: int = param(0, "random seed: the same seed and parameters give an identical mesh", min=0)
    speed_m_s: float = param(10.0, "cruise speed of the vehicle", min=0.5, max=60.0)
    accel_m_s2: float = param(1.5, "longitudinal acceleration and braking limit", min=0.1, max=10.0)
    lateral_accel_m_s2: float = param(
        2.0, "lateral acceleration allowed in turns (slows the vehicle in curves)", min=0.1, max=10.0
    )
    accel_smoothing_s: float = param(
        0.0, "length of a triangular moving average over the speed profile, which makes the acceleration and the "
        "jerk continuous, and the body's pitch and roll response a cubic spline (what an IMU needs; the motion "
        "lags the raw profile by half of it) (0: off, the poses as they always were)", min=0.0, max=5.0)
    mount_height_m: float = param(1.9, "lidar height above the road (roof mount)", min=0.3, max=5.0)
    suspension_pitch_deg: float = param(
        0.3, "amplitude of the body's pitch/roll oscillation at cruise speed", min=0.0, max=5.0
    )
    suspension_heave_m: float = param(0.01, "amplitude of the body's vertical oscillation at cruise speed",
                                      min=0.0, max=0.2)
    max_triangles: int = param(1_000_000, "face budget: building a larger mesh is an error", min=1000)
    traffic: TrafficParams = section(TrafficParams)

    # Parameters added after sequences were made and cached: ``to_dict`` (a scene's ``params``, a manifest's
    # ``scene_params``, a sweep's cache key) writes them only when they differ from their default, so that what
    # was made before keeps its keys (a sensor file's effects follow the same rule).
    # The traffic section is one of them: a scene without traffic keeps the keys it had before there was any.
    written_when_set: ClassVar[tuple[str, ...]] = ("accel_smoothing_s", "traffic")

    def to_dict(self) -> dict:
        out = super().to_dict()
        for key in self.written_when_set:
            if getattr(self, key) == _default(self, key):
                del out[key]
        return out


def _default(params: Params, name: str) -> Any:
    """The declared default of ``params``'s field ``name`` (a section's: a new instance of its class)."""
    f = {f.name: f for f in dataclasses.fields(params)}[name]
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def default_of(cls: type[CommonParams], name: str, default: Any) -> Any:
    """A field declaring ``cls``'s parameter ``name`` again with another default (help, bounds kept): a
    scene that is another's with other defaults (``scenes.bare_tunnel``)."""
    declared = {f.name: f for f in dataclasses.fields(cls)}[name]
    return dataclasses.field(default=default, metadata=declared.metadata)


def resolve(cls: type[CommonParams], overrides: dict[str, Any] | None = None,
            origin: str | None = None) -> CommonParams:
    """Defaults of ``cls`` with ``overrides`` applied, converted and validated.

    Values may be command-line text ('250', 'true'). Unknown names and bad
    values raise ``ParamError`` naming ``origin`` (default: the scene's module) and the parameter.
    """
    if origin is None:
        origin = f"scene {cls.__module__.rsplit('.', 1)[-1]}"
    # read in listing order, so that an unknown name's message lists the scene's own parameters first
    values = scene_section("scene", cls).read(dict(overrides or {}), origin, coerce=True)
    return build(cls, values, origin=origin)


def describe(cls: type[CommonParams]) -> list[Param]:
    """The parameters of a scene, scene-specific first then the common ones."""
    common = set(schema(CommonParams).names)
    members = schema(cls).members
    return [p for p in members if p.name not in common] + [p for p in members if p.name in common]


def scene_section(name: str, cls: type[CommonParams], description: str = "") -> Section:
    """A scene's parameters as a ``paramspec.Section`` in ``describe`` order (for listings and docs)."""
    return Section(name, tuple(describe(cls)), description, cls)


__all__ = ["CommonParams", "ParamError", "ParamInfo", "default_of", "describe", "param", "resolve", "scene_section"]
