"""Procedural, seeded worlds with drivable paths and smooth 6-DoF lidar trajectories.

Each scene module has a frozen ``Params`` dataclass (fields declared with
``scenes.params.param``: default, help, bounds), a one-line ``DESCRIPTION`` and
``build(params) -> Scene``. This
package knows nothing of the simulator: it makes a mesh and poses.

    from scenes import build_scene, scene_parameters
    scene = build_scene("tunnel", seed=3, length_m=600)

``scenes.families`` draws randomised parameters of scene families for a
held-out generalisation suite.
"""

from __future__ import annotations

import logging
import time
from types import ModuleType
from typing import Any

from . import (
    bare_tunnel,
    bridge,
    canyon,
    city,
    forest,
    garage,
    highway,
    lead_vehicle,
    open_field,
    overtaking_lorry,
    red_light,
    suburb,
    traffic,
    traffic_jam,
    tunnel,
)
from .base import LABELS, MeshBuilder, Scene
from .params import ParamInfo, describe, resolve, scene_section

log = logging.getLogger(__name__)

SCENES: dict[str, ModuleType] = {
    "city": city,
    "tunnel": tunnel,
    "highway": highway,
    "open": open_field,
    "forest": forest,
    "suburb": suburb,
    "canyon": canyon,
    "garage": garage,
    "bridge": bridge,
    "bare-tunnel": bare_tunnel,
    "red_light": red_light,
    "traffic_jam": traffic_jam,
    "overtaking_lorry": overtaking_lorry,
    "lead_vehicle": lead_vehicle,
}


def _module(name: str) -> ModuleType:
    try:
        return SCENES[name]
    except KeyError:
        raise ValueError(f"unknown scene {name!r} (known: {', '.join(SCENES)})") from None


def scene_parameters(name: str) -> list[ParamInfo]:
    """The parameters of scene ``name`` with defaults, types, units, bounds and help text."""
    return describe(_module(name).Params)


def scene_schema(name: str):
    """The parameters of scene ``name`` as a ``paramspec.Section`` (named after the scene, its description as help)."""
    module = _module(name)
    return scene_section(name, module.Params, module.DESCRIPTION)


def resolve_params(name: str, seed: int = 0, **overrides: Any):
    """The validated ``Params`` of scene ``name`` (a ``ParamError``, a ``ValueError``, names a bad parameter)."""
    return resolve(_module(name).Params, {"seed": seed, **overrides}, origin=f"scene {name}")


def build_scene(name: str, seed: int = 0, **overrides: Any) -> Scene:
    """Build scene ``name`` with ``seed`` and parameter overrides (strings are converted)."""
    params = resolve_params(name, seed, **overrides)
    start = time.perf_counter()
    scene = _module(name).build(params)
    if scene.actors is None:  # the scene placed none itself: the traffic of its densities, or nothing
        scene.actors = traffic.populate(scene, params.traffic, params.seed) if params.traffic.enabled else []
    log.info("built %s (seed %d): %d triangles, %d objects, %d moving, %.1f s of trajectory in %.2f s",
             name, params.seed, scene.n_triangles, len(scene.object_labels), len(scene.actors),
             scene.trajectory.duration_s, time.perf_counter() - start)
    return scene


__all__ = ["LABELS", "SCENES", "MeshBuilder", "ParamInfo", "Scene", "build_scene", "resolve_params",
           "scene_parameters", "scene_schema"]
