"""Scripted scenes: an ego on a speed profile of its own and the moving objects a scene places itself.

The stress scenes (``red_light``, ``traffic_jam``, ``overtaking_lorry``, ``lead_vehicle``)
take a world of another scene (a city, a highway), drive the ego along a path of their
own with a ``ProfiledTrajectory`` (it stops and waits, creeps, or holds a speed exactly),
and place the actors the situation needs. Their parameter ``moving`` false gives the
static twin: the same world and the same ego motion, nothing else moving.
"""

from __future__ import annotations

import logging

import numpy as np

from .actors import Actor, LanePath, SpeedProfile
from .trajectory import PITCH_PER_ACCEL_RAD

log = logging.getLogger(__name__)


class ProfiledTrajectory:
    """Lidar poses along a path with a given speed profile (``scenes.actors.SpeedProfile``), continuous acceleration.

    path: (m, 3) road-level points of the lane, about 0.5 m apart; profile: distance along it (m) against time;
    duration_s: the trajectory's end (poses stand still after it); mount_height_m: the lidar above the road;
    surface_height: the road's height at (x, y) for the roll across the wheels, or None (level across). The
    heading follows the path, the pitch its grade plus the body's squat and dive (``PITCH_PER_ACCEL_RAD`` per
    m/s^2, at once: the profile's acceleration is smooth); no suspension oscillation, so that standing still
    is still to the last bit.
    """

    def __init__(self, path: np.ndarray, profile: SpeedProfile, duration_s: float, mount_height_m: float,
                 surface_height=None):
        self.lane = LanePath(path, False)
        self.closed = False
        self.length_m = self.lane.length_m
        self.profile = profile
        self._duration = float(duration_s)
        self.mount_height_m = float(mount_height_m)
        self.surface_height = surface_height
        self.speed_m_s = float(np.max(profile.v))
        t = np.linspace(0.0, self._duration, max(2, int(self._duration / 0.01)) + 1)
        self._t_table, self._s_table = t, self.distance_at(t)

    @property
    def duration_s(self) -> float:
        return self._duration

    def distance_at(self, times) -> np.ndarray:
        t = np.clip(np.atleast_1d(np.asarray(times, float)), 0.0, self._duration)
        return np.clip(self.profile.distance(t), 0.0, self.length_m)

    def speed_at(self, times) -> np.ndarray:
        raw = np.atleast_1d(np.asarray(times, float))
        v = self.profile.speed(np.clip(raw, 0.0, self._duration))
        return np.where((raw < 0) | (raw > self._duration), 0.0, v)

    def time_at_distance(self, distance_m) -> np.ndarray:
        """(n,) distance along the path -> (n,) the first time the lidar is there, s."""
        d = np.atleast_1d(np.asarray(distance_m, float))
        i = np.clip(np.searchsorted(self._s_table, d), 0, len(self._t_table) - 1)
        return self._t_table[i]

    def pose_at(self, times) -> np.ndarray:
        t = np.atleast_1d(np.asarray(times, float))
        inside = (t >= 0) & (t <= self._duration)
        state = np.stack([self.distance_at(t), np.where(inside, self.profile.accel(t), 0.0)], 1)
        # one pose per distinct (distance, acceleration): a standing vehicle's poses are equal to the last bit
        # (numpy's vectorised sines may round an element differently by its place in the array)
        state, back = np.unique(state, axis=0, return_inverse=True)
        return self._poses(state[:, 0], state[:, 1])[back.ravel()]

    def _poses(self, s: np.ndarray, accel: np.ndarray) -> np.ndarray:
        p, tan, left, grade = self.lane.frame(s)
        yaw = np.arctan2(tan[:, 1], tan[:, 0])
        pitch = -np.arctan(grade) - PITCH_PER_ACCEL_RAD * accel
        roll = np.zeros(len(s))
        if self.surface_height is not None:
            half = 0.8
            zl = self.surface_height(*(p[:, :2] + half * left).T)
            zr = self.surface_height(*(p[:, :2] - half * left).T)
            roll = np.arctan2(zl - zr, 2 * half)
        cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
        T = np.tile(np.eye(4), (len(s), 1, 1))
        T[:, 0, 0], T[:, 0, 1], T[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
        T[:, 1, 0], T[:, 1, 1], T[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
        T[:, 2, 0], T[:, 2, 1], T[:, 2, 2] = -sp, cp * sr, cp * cr
        T[:, :3, 3] = p + T[:, :3, 2] * self.mount_height_m
        return T


def straight(a: np.ndarray, b: np.ndarray, height=None, step_m: float = 0.5) -> np.ndarray:
    """(m, 3) points from a to b (xy; z from ``height`` at each point, or linear between a's and b's z)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = max(4, int(np.ceil(np.linalg.norm(b[:2] - a[:2]) / step_m)) + 1)
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    if height is not None:
        pts[:, 2] = height(pts[:, 0], pts[:, 1])
    return pts


def place(scene, actors: list[Actor], seed: int, traffic=None) -> list[Actor]:
    """The scene's own actors, each checked against the ego and the others (``scenes.traffic``): one that would
    meet something is left out, with a warning (the script placed it wrongly). With ``traffic`` (enabled
    ``TrafficParams``), the ordinary traffic of its densities around them."""
    from .traffic import EgoMotion, Occupancy, populate

    ego = EgoMotion(scene.trajectory, scene.path, False)
    occupancy = Occupancy(ego)
    kept = []
    for a in actors:
        if occupancy.admits(a):
            kept.append(a)
        else:
            log.warning("%s: a %s (%s) would meet the ego or another actor: left out", scene.name, a.kind,
                        a.behaviour)
    if traffic is not None and traffic.enabled and scene.roads is not None:
        return populate(scene, traffic, seed, existing=kept)
    return kept


__all__ = ["ProfiledTrajectory", "place", "straight"]
