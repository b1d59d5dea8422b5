"""Scene families of a held-out generalisation suite, and seeded draws of their parameters.

A family is a scene and ranges for a handful of its parameters that change the
world in ways an odometry method could be tuned to (density, widths, grades,
lengths, curvature, speed). ``draw_family_params(family, seed)`` draws one
member: parameter overrides for ``scenes.build_scene`` / ``resolve_params``,
the scene's seed included, the same for the same family and seed on any
machine (the generator is seeded from a CRC of the family's name and the
seed, not from Python's salted ``hash``).

    from scenes import build_scene
    from scenes.families import FAMILIES, draw_family_params, family_scene
    params = draw_family_params("suburb", 7)
    scene = build_scene(family_scene("suburb"), **params)

The ranges keep every draw valid (cross-parameter checks included) and its
trajectory at least 25 s long (250 frames at 10 Hz); the tests build seeds 0-19
of every family to hold them to it.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import SCENES
from .params import describe


@dataclass(frozen=True)
class Uniform:
    """A real number drawn uniformly from [lo, hi]."""

    lo: float
    hi: float

    def draw(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.lo, self.hi))


@dataclass(frozen=True)
class Integers:
    """An integer drawn uniformly from lo to hi, both included."""

    lo: int
    hi: int

    def draw(self, rng: np.random.Generator) -> int:
        return int(rng.integers(self.lo, self.hi + 1))


@dataclass(frozen=True)
class Choice:
    """One of ``options`` (strings or numbers), equally likely."""

    options: tuple

    def draw(self, rng: np.random.Generator) -> Any:
        value = self.options[int(rng.integers(len(self.options)))]
        return value.item() if isinstance(value, np.generic) else value


Range = Uniform | Integers | Choice


@dataclass(frozen=True)
class Family:
    """A scene and the ranges of the parameters its members vary (the rest keep their defaults)."""

    scene: str
    ranges: dict[str, Range]


_SPEED = Uniform(6.0, 15.0)  # m/s: urban to fast suburban driving

_FAMILIES: dict[str, Family] = {
    "city": Family("city", {
        "streets_x": Integers(3, 5),
        "streets_y": Integers(3, 4),
        "block_length_m": Uniform(50.0, 110.0),
        "block_width_m": Uniform(40.0, 80.0),
        # at least 11 m: the default 9 m turns must clear the kerb corner with the lane 2 m right
        "street_width_m": Uniform(11.0, 16.0),
        "building_height_min_m": Uniform(5.0, 12.0),
        "building_height_max_m": Uniform(18.0, 60.0),
        "parked_car_fraction": Uniform(0.1, 0.8),
        "tree_spacing_m": Uniform(10.0, 30.0),
        "route_blocks": Integers(1, 4),
        "speed_m_s": Uniform(6.0, 12.0),
    }),
    "suburb": Family("suburb", {
        "loop_length_m": Uniform(450.0, 1000.0),
        "loop_wiggle": Uniform(0.0, 0.2),
        "road_width_m": Uniform(8.0, 12.0),
        "max_grade_pct": Uniform(1.0, 7.0),
        "hill_wavelength_m": Uniform(150.0, 500.0),
        "houses_per_100m": Uniform(2.0, 9.0),
        "setback_max_m": Uniform(8.0, 20.0),
        "trees_per_100m": Uniform(2.0, 15.0),
        "park_trees_per_ha": Uniform(0.0, 60.0),
        "parked_cars_per_100m": Uniform(0.0, 8.0),
        "speed_m_s": _SPEED,
    }),
    "canyon": Family("canyon", {
        "street_length_m": Uniform(120.0, 400.0),
        "street_width_m": Uniform(10.0, 20.0),
        "street_curve_radius_m": Choice((0.0, 0.0, 500.0, 1000.0)),
        "building_height_min_m": Uniform(10.0, 20.0),
        "building_height_max_m": Uniform(25.0, 60.0),
        "facade_relief": Uniform(0.0, 1.0),
        "gap_fraction": Uniform(0.0, 0.2),
        "parked_car_fraction": Uniform(0.0, 0.8),
        "tunnel_length_m": Uniform(60.0, 300.0),
        "tunnel_cross_section": Choice(("arch", "box")),
        "tunnel_width_m": Uniform(9.5, 12.0),
        "tunnel_height_m": Uniform(7.0, 8.0),  # an arch needs width / 2 + 1
        "grade_pct": Uniform(-3.0, 3.0),
        "speed_m_s": _SPEED,
    }),
    "tunnel": Family("tunnel", {
        "length_m": Uniform(300.0, 1500.0),
        "cross_section": Choice(("arch", "box")),
        "width_m": Uniform(9.5, 14.0),
        "height_m": Uniform(8.0, 9.0),  # an arch needs width / 2 + 1
        "curve_radius_m": Choice((0.0, 0.0, 1200.0, 2500.0)),  # <= 90 degrees over 1500 m
        "grade_pct": Uniform(-3.0, 3.0),
        "feature_spacing_m": Uniform(40.0, 200.0),
        "speed_m_s": _SPEED,
    }),
    "highway": Family("highway", {
        "length_m": Uniform(1000.0, 2500.0),
        "lanes": Integers(2, 4),
        "lane": Integers(1, 2),
        "min_curve_radius_m": Uniform(500.0, 2000.0),
        "max_grade_pct": Uniform(0.0, 4.0),
        "sign_spacing_m": Uniform(200.0, 600.0),
        "gantry_spacing_m": Uniform(400.0, 1200.0),
        "land_roughness_m": Uniform(0.5, 6.0),
        "tree_groups": Integers(0, 60),
        "speed_m_s": Uniform(15.0, 30.0),  # highway speeds
    }),
    "open": Family("open", {
        "roughness_m": Uniform(0.3, 4.0),
        "loop_radius_m": Uniform(60.0, 150.0),
        "rocks": Integers(0, 150),
        "shrubs": Integers(0, 250),
        "speed_m_s": Uniform(6.0, 12.0),
    }),
    "forest": Family("forest", {
        "length_m": Uniform(500.0, 1200.0),
        "road_width_m": Uniform(4.0, 8.0),
        "min_curve_radius_m": Uniform(40.0, 150.0),
        "tree_density_per_ha": Uniform(100.0, 450.0),
        "conifer_fraction": Uniform(0.0, 1.0),
        "roughness_m": Uniform(0.5, 5.0),
        "speed_m_s": Uniform(6.0, 14.0),
    }),
    # Worlds stacked on themselves (docs/simulation.md). Appended: a family's place sets its sensors.
    "garage": Family("garage", {
        "levels": Integers(2, 4),
        "clear_height_m": Uniform(2.1, 2.6),
        "slab_thickness_m": Uniform(0.25, 0.35),
        "beam_depth_m": Uniform(0.0, 0.5),
        "bays": Integers(7, 10),  # the longest ramp (3.45 m at 10 %) needs 7 bays of 7.5 m
        "pillar_spacing_m": Uniform(7.5, 8.5),
        "pillar_width_m": Uniform(0.4, 0.6),
        "aisle_width_m": Uniform(6.0, 7.5),
        "stall_depth_m": Uniform(4.9, 5.5),
        "ramp_grade_pct": Uniform(10.0, 15.0),
        "ramp_transition_m": Uniform(3.0, 5.0),
        "helix_radius_m": Uniform(9.0, 13.0),
        "route": Choice(("ramps_up", "helix_up")),
        "closed_sides": Choice(("none", "ground", "covered")),
        "occupancy": Uniform(0.2, 0.95),
        "speed_m_s": Uniform(3.5, 6.0),  # garage driving
    }),
    "bridge": Family("bridge", {
        "lanes": Integers(1, 2),
        "pier": Choice((True, False)),
        "road_b_width_m": Uniform(7.5, 11.0),
        "clearance_m": Uniform(4.6, 5.4),
        "deck_depth_m": Uniform(0.7, 1.4),
        "loop_radius_m": Uniform(21.0, 26.0),  # passing under and over within 20 s
        "b_grade_pct": Uniform(3.0, 6.0),
        "lateral_accel_m_s2": Uniform(3.0, 4.0),
        "approach_m": Uniform(60.0, 200.0),
        "lamp_spacing_m": Uniform(25.0, 60.0),
        "trees": Integers(20, 200),
        "buildings": Integers(0, 25),
        "speed_m_s": Uniform(9.0, 13.0),
    }),
}

FAMILIES: tuple[str, ...] = tuple(_FAMILIES)


def family(name: str) -> Family:
    """The family ``name`` (``ValueError`` naming it if unknown)."""
    try:
        return _FAMILIES[name]
    except KeyError:
        raise ValueError(f"unknown scene family {name!r} (known: {', '.join(FAMILIES)})") from None


def family_scene(name: str) -> str:
    """The scene family ``name`` builds."""
    return family(name).scene


def draw_family_params(name: str, seed: int, traffic: bool = False) -> dict[str, Any]:
    """Parameter overrides of one member of family ``name``, drawn from ``seed``.

    Returns ``{"seed": seed, parameter: value, ...}`` for ``scenes.build_scene(family_scene(name),
    **overrides)``; numbers are clipped to the scene's parameter bounds (integers rounded). traffic: with
    the family's moving traffic (``scenes.traffic.draw_traffic``: densities of a draw of their own, so the
    rest is the member without traffic, its static twin); a family without traffic is refused.
    """
    fam = family(name)
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed {seed}: must be >= 0")
    rng = np.random.default_rng([zlib.crc32(name.encode()), seed])
    bounds = {p.name: p for p in describe(SCENES[fam.scene].Params)}
    out: dict[str, Any] = {"seed": seed}
    for key in sorted(fam.ranges):  # a fixed order: the draws do not depend on the table's layout
        value = fam.ranges[key].draw(rng)
        info = bounds[key]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            lo = -np.inf if info.min is None else info.min
            hi = np.inf if info.max is None else info.max
            value = float(np.clip(value, lo, hi))
            value = int(round(value)) if info.type == "int" else value
        out[key] = value
    if traffic:
        from .traffic import draw_traffic

        section = draw_traffic(name, seed)
        if section is None:
            raise ValueError(f"scene family {name!r} has no traffic")
        out["traffic"] = section
    return out


__all__ = ["FAMILIES", "Choice", "Family", "Integers", "Uniform", "draw_family_params", "family",
           "family_scene"]
