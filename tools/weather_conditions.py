"""Weather as drawn conditions of the generalisation suite: clear air, light and dense fog, rain, snow.

Every sequence of the weather suite (``tools.family_suite.weather_suite``) is a sequence of the
generalisation suite (its family, seed, sensor, noise and start; the "simulated" kind) in one of
``CONDITIONS``; the "clear" one is the twin of the others: the same seed, path, sensor and receiver, in
clear air. Every condition has the sensor's receiver on (``simlidar.weather``: a 10 % target detected at
100 m, its defaults), so a twin differs from its weather sequences by the weather alone (and, in clear air,
from the generalisation suite's own sequence by the receiver's threshold: far, dark and grazing returns).

What each condition draws, log-uniformly from its range and from (family, seed, condition) alone, so a
subset of families or conditions draws the same weather as the whole suite:

- light fog: visibility (MOR) 500 to 1000 m; dense fog: 50 to 120 m (the two ends of the meteorological
  fog, visibility below 1 km; the dense end around the 60 m of issue 41's measurement);
- rain: 4 to 25 mm/h (moderate to heavy);
- snow: 0.3 to 2 mm/h melted (light to heavy).
"""

from __future__ import annotations

import math
import zlib

import numpy as np

CONDITIONS = ("clear", "light-fog", "dense-fog", "rain", "snow")
# condition -> (weather section, key, low, high): the key drawn log-uniformly in [low, high].
DRAWS = {
    "light-fog": ("fog", "mor_m", 500.0, 1000.0),
    "dense-fog": ("fog", "mor_m", 50.0, 120.0),
    "rain": ("rain", "rate_mm_h", 4.0, 25.0),
    "snow": ("snow", "rate_mm_h", 0.3, 2.0),
}


def check_condition(condition: str) -> str:
    if condition not in CONDITIONS:
        raise ValueError(f"unknown weather condition {condition!r} (known: {', '.join(CONDITIONS)})")
    return condition


def draw(condition: str, family: str, seed: int) -> dict:
    """The weather section (YAML-style dict, ``simlidar.weather.Weather`` keys) a condition draws for a sequence."""
    check_condition(condition)
    if condition == "clear":
        return {}
    section, key, lo, hi = DRAWS[condition]
    rng = np.random.default_rng([zlib.crc32(family.encode()), int(seed), zlib.crc32(condition.encode()), 0x3EA])
    value = round(math.exp(rng.uniform(math.log(lo), math.log(hi))), 3 if hi < 10 else 1)
    return {section: {"enabled": True, key: value}}


def sensor_in(sensor, condition: str, family: str, seed: int):
    """``sensor`` (a ``LidarModel``) with its receiver on, in the condition's drawn weather."""
    from simlidar.weather import ReceiverParams, Weather

    return sensor.with_overrides(receiver=ReceiverParams(enabled=True),
                                 weather=Weather.from_dict(draw(condition, family, seed)))


__all__ = ["CONDITIONS", "DRAWS", "check_condition", "draw", "sensor_in"]
