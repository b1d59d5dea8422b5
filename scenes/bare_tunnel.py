"""Bare tunnel: the tunnel scene set where lidar alone must fail.

A straight 600 m bore whose middle 400 m have no fittings (bare walls, nothing
along the axis to register against), and a stop in its middle: the vehicle enters
at 15 m/s (100 m of approach), brakes, waits 5 s and accelerates again, all on the
bare stretch. The speed
profile is smoothed (``accel_smoothing_s`` 1 s) so an IMU riding along sees a
continuous acceleration. Every parameter is the tunnel's (``scenes.tunnel``), with
these defaults; the simulator's degeneracy truth (``degeneracy.csv``) flags the
bare stretch.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import tunnel
from .base import Scene
from .params import default_of

NAME = "bare-tunnel"
DESCRIPTION = ("tunnel with 400 m of bare walls in its middle and a stop there (braking, 5 s waiting, "
               "accelerating): where lidar alone must fail")


@dataclass(frozen=True)
class Params(tunnel.Params):
    length_m: float = default_of(tunnel.Params, "length_m", 600.0)
    approach_m: float = default_of(tunnel.Params, "approach_m", 100.0)
    bare_length_m: float = default_of(tunnel.Params, "bare_length_m", 400.0)
    stop_wait_s: float = default_of(tunnel.Params, "stop_wait_s", 5.0)
    accel_smoothing_s: float = default_of(tunnel.Params, "accel_smoothing_s", 1.0)


def build(p: Params) -> Scene:
    return tunnel.build(p, NAME)
