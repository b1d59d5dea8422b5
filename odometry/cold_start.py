"""The cold start: a sequence's first registration, which has no motion to extrapolate.

The sensor may already move by metres a frame, beyond the correspondence bound, and the
points that see it (few, in a corridor) would be trimmed first. So the first registration:

1. with poles on both sides, starts from the horizontal offset most of them agree on
   (``poles.pole_translation``): where poles are the evidence along the road, a coarse pass
   would let the rails' and the ground's sampling pattern (the same in both scans) pull it
   back to standing still;
2. otherwise runs a coarse registration first, with a wide bound and no trimming or GCR
   (``match.initial_correspondence_distance_m``), and the ICP from its estimate;
3. from the guess (standing still) when the coarse pass failed.

None of these holds the estimate to the guess (``motion_prior=False``): it is no known motion.
A map variant registers against two targets, the map of the first scan and the first scan's
own points and normals, and keeps the better constrained (``better_constrained``): a map of one
scan has a normal only where two scan lines meet, which on open ground leaves the direction of
travel to a few objects, while against the scan a sensor moving on weak ground is pulled towards
standing still by the scans' rings falling on each other (docs/method.md).
"""

from __future__ import annotations

import math

import numpy as np

from simlidar import se3

from .config import OdometryConfig
from .icp import NearestCache, RegistrationResult, Source, Target, register
from .poles import pole_translation
from .rejectors import Rejector


def coarse_config(config: OdometryConfig) -> OdometryConfig:
    """The coarse pass's config: the wide initial bound, no trimming, no GCR."""
    return config.replace(gcr={"enabled": False}, match={
        "max_correspondence_distance_m": config.match.initial_correspondence_distance_m, "trim_fraction": 0.0})


def first_registration(source: Source, target: Target, T_init: np.ndarray, config: OdometryConfig,
                       chain: list[Rejector], coarse: OdometryConfig, coarse_chain: list[Rejector],
                       T_target_prev: np.ndarray, nearest: NearestCache | None = None
                       ) -> tuple[RegistrationResult, list[RegistrationResult]]:
    """A sequence's first registration of ``source`` on ``target`` from the guess ``T_init`` (4, 4).

    chain: the rejectors (without GCR: it needs a close guess). coarse, coarse_chain: the coarse
    pass's config (``coarse_config``) and rejectors. T_target_prev: (4, 4) the previous pose in the
    target frame. nearest: the target's search cache. Returns the result and every run made.
    """
    runs: list[RegistrationResult] = []
    if source.poles is not None and target.poles is not None:
        moved = se3.transform_points(T_init, source.poles)
        offset = pole_translation(moved, target.poles, config.match.initial_correspondence_distance_m)
        if offset is not None:
            T_start = T_init.copy()
            T_start[:3, 3] += offset
            result = register(source, target, T_start, config, chain, T_target_prev, motion_prior=False,
                              nearest=nearest)
            runs.append(result)
            if not result.singular:
                return result, runs
    result = None
    first = register(source, target, T_init, coarse, coarse_chain, T_target_prev, motion_prior=False, nearest=nearest)
    runs.append(first)
    if not first.singular:
        result = register(source, target, first.T_target_source, config, chain, T_target_prev, motion_prior=False,
                          nearest=nearest)
        runs.append(result)
    if result is None:
        result = register(source, target, T_init, config, chain, T_target_prev, motion_prior=False, nearest=nearest)
        runs.append(result)
    return result, runs


def better_constrained(results: list[RegistrationResult]) -> int:
    """Of first registrations against different targets, the index of the one whose weakest direction of
    translation is best constrained: the largest smallest eigenvalue of its information per match
    (``RegistrationResult.translation_eigenvalues``); a singular result only when all are; on a tie
    the earlier. A registration that slid along a weakly constrained direction (a map of one scan on
    open ground, whose single-ring ground has no normals) has the smaller one.
    """
    def weakest(i: int) -> float:
        w = float(results[i].translation_eigenvalues[0])
        return -math.inf if results[i].singular or not math.isfinite(w) else w

    return max(range(len(results)), key=weakest)  # (max keeps the first of equal keys)
