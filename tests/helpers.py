"""Analytic worlds and trajectories for tests (imported by test modules)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from simlidar.trajectory import SampledTrajectory
from simlidar.world import World


def box_room(size=(40.0, 30.0, 8.0), center=(0.0, 0.0, 0.0)) -> World:
    """A closed box seen from inside: walls, floor and ceiling facing inwards."""
    m = trimesh.creation.box(size)
    m.apply_translation(center)
    m.invert()
    return World(m.vertices, m.faces, np.zeros(len(m.faces)), ["wall"], source="box room")


def ground_plane(z=0.0, half=500.0) -> World:
    """A square of flat ground facing up."""
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return World(v, f, np.zeros(2), ["ground"], source="ground plane")


def wall_x(x: float, half=200.0) -> World:
    """A large wall at x = const, facing -x (towards a sensor near the origin)."""
    v = np.array([[x, -half, -half], [x, half, -half], [x, half, half], [x, -half, half]])
    f = np.array([[0, 2, 1], [0, 3, 2]])
    return World(v, f, np.zeros(2), ["wall"], source="wall")


def sphere_room(radius=5.0, subdivisions=7) -> World:
    """A tessellated sphere seen from inside (faces turned inwards)."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    m.invert()
    return World(m.vertices, m.faces, np.zeros(len(m.faces)), ["wall"], source="sphere")


def constant_velocity(v=(0.0, 0.0, 0.0), yaw_rate=0.0, start=(0.0, 0.0, 0.0), duration=10.0, n=201):
    """Sampled trajectory moving at velocity v (m/s, world) while yawing at yaw_rate (rad/s)."""
    t = np.linspace(0.0, duration, n)
    T = np.tile(np.eye(4), (n, 1, 1))
    yaw = yaw_rate * t
    T[:, 0, 0], T[:, 0, 1] = np.cos(yaw), -np.sin(yaw)
    T[:, 1, 0], T[:, 1, 1] = np.sin(yaw), np.cos(yaw)
    T[:, :3, 3] = np.asarray(start) + np.outer(t, v)
    return SampledTrajectory(t, T)


# The default scenes the per-scene checks run on in the fast suite (`pytest -m "not slow"`): two cheap
# ones; the checks of the other scenes are marked slow and run with the full suite.
FAST_SCENES = ("tunnel", "canyon")


def scene_params(names) -> list:
    """A per-scene parametrisation: ``FAST_SCENES`` as they are, every other scene marked slow."""
    return [n if n in FAST_SCENES else pytest.param(n, marks=pytest.mark.slow) for n in names]


# What a vehicle passes under: anything at least this far above its roof-mounted lidar's optical
# centre (the housing's top, about 0.1 m above it, and 0.2 m for the suspension and a bump), the
# beams of a parking garage 0.4-1 m above the lidar included. The clearance checks of the scenes
# (test_scenes, test_scenes_clearance) hold everything else to a car's width from the lidar.
OVERHEAD_M = 0.3
