"""Road alignments: a centre-line from a curvature profile and a grade profile.

A road's plan is described by its curvature along the distance s (straights,
curves and smooth transitions between them, like clothoids), integrated to
heading and position; its elevation by a smooth grade profile. Every array is
sampled at the same distances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Alignment:
    """A road centre-line sampled every ``step`` metres.

    s: (n,) distance, m; xyz: (n, 3) points, m; heading: (n,) rad;
    left: (n, 3) unit horizontal vectors to the left of travel.
    """

    s: np.ndarray
    xyz: np.ndarray
    heading: np.ndarray

    @property
    def left(self) -> np.ndarray:
        return np.column_stack([-np.sin(self.heading), np.cos(self.heading), np.zeros_like(self.heading)])

    @property
    def forward(self) -> np.ndarray:
        return np.column_stack([np.cos(self.heading), np.sin(self.heading), np.zeros_like(self.heading)])

    def index(self, distance: float) -> int:
        """Index of the sample nearest to ``distance`` m."""
        return int(np.clip(np.searchsorted(self.s, distance), 0, len(self.s) - 1))


def integrate(s: np.ndarray, curvature: np.ndarray, z: np.ndarray, heading0: float = 0.0) -> Alignment:
    """Plan from a curvature profile (1/m, left positive) by the midpoint rule; z given (n,)."""
    ds = np.diff(s)
    heading = heading0 + np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]) * ds)])
    mid = 0.5 * (heading[1:] + heading[:-1])
    xy = np.vstack([[0.0, 0.0], np.cumsum(np.stack([np.cos(mid), np.sin(mid)], 1) * ds[:, None], axis=0)])
    return Alignment(s, np.column_stack([xy, z]), heading)


def random_curves(rng: np.random.Generator, s: np.ndarray, min_radius_m: float, mean_gap_m: float,
                  transition_m: float) -> np.ndarray:
    """(n,) curvature: alternating curves of radius >= ``min_radius_m`` separated by straights.

    Each curve is a plateau with cosine transitions of ``transition_m`` (so the
    curvature, and a driver's steering, change smoothly); curves and straights
    last ``mean_gap_m`` on average.
    """
    kappa = np.zeros_like(s)
    pos = s[0] + rng.uniform(0.3, 1.0) * mean_gap_m
    sign = rng.choice([-1.0, 1.0])
    while pos < s[-1]:
        length = rng.uniform(0.5, 1.5) * mean_gap_m
        sign = -sign  # curves alternate, so the road winds but never turns back on itself
        k = sign / rng.uniform(min_radius_m, 2.5 * min_radius_m)
        a, b = pos, pos + length
        rise = np.clip((s - a) / transition_m, 0, 1)
        fall = np.clip((b - s) / transition_m, 0, 1)
        kappa += k * 0.5 * (1 - np.cos(np.pi * np.minimum(rise, fall)))
        pos = b + transition_m + rng.uniform(0.5, 1.5) * mean_gap_m
    return kappa


def random_grades(rng: np.random.Generator, s: np.ndarray, max_grade: float,
                  wavelengths_m=(400.0, 1500.0), n_waves: int = 3) -> np.ndarray:
    """(n,) elevation, m: a sum of long waves whose combined grade stays within ``max_grade``."""
    lam = rng.uniform(*wavelengths_m, n_waves)
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    amp = max_grade * lam / (2 * np.pi * n_waves)  # each wave's slope is at most max_grade / n
    z = (amp[:, None] * np.sin(2 * np.pi * s[None, :] / lam[:, None] + phase[:, None])).sum(0)
    return z - z[0]
