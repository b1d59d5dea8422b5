"""Correspondence rejectors. All share one signature: ``(matches, source) -> keep mask``.

``matches`` are the current nearest-neighbour pairs; ``source`` is the
registration's source (``odometry.icp.Source``), which carries what a rejector
may need beyond the distances (the GCR's per-point thresholds). The ICP applies
them in order, each to the matches the previous ones kept. The chain the ICP's
configuration makes (``StandardChain``: distance, GCR, trimming) it runs as one
compiled pass with the normal equations (``odometry.kernels.plane_system.standard_rejection_system``:
the same matches kept, save which of several at the trimming's cut distance), any other
chain one rejector after another.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class Matches:
    """Nearest-neighbour correspondences.

    source_index: (m,) rows of the source points; target_index: (m,) rows of the target.
    distance_m: (m,) Euclidean distance between the moved source point and its target point.
    target_normals: (m, 3) the target's normal at each match, once looked up (None before).
    """

    source_index: np.ndarray
    target_index: np.ndarray
    distance_m: np.ndarray
    target_normals: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.source_index)

    def select(self, keep: np.ndarray) -> Matches:
        """The matches where the (m,) bool ``keep`` holds."""
        # (take of the kept rows: a boolean index of an (m, 3) array is several times slower in numpy)
        rows = np.flatnonzero(keep)
        normals = None if self.target_normals is None else self.target_normals.take(rows, axis=0)
        return Matches(self.source_index.take(rows), self.target_index.take(rows), self.distance_m.take(rows), normals)


Rejector = Callable[[Matches, object], np.ndarray]


@dataclass(frozen=True)
class StandardChain:
    """What a chain of the rejectors below does, when it is one: the distance rejector's bound (m),
    then GCR (on or off), then trimming (the fraction dropped, 0: none). ``counted``: each
    rejector's name and its stage among (distance, GCR, trimming), in the chain's order."""

    max_distance_m: float
    gcr: bool
    trim_fraction: float
    counted: tuple[tuple[str, int], ...]


def standard_chain(rejectors) -> StandardChain | None:
    """The ``StandardChain`` a sequence of rejectors is (distance, optionally GCR, optionally trimming,
    in that order, as ``odometry.icp.rejectors_for`` makes), or None for any other chain."""
    rest = list(rejectors)
    if not rest or not hasattr(rest[0], "max_distance_m"):
        return None
    counted = [(rest[0].__name__, 0)]
    max_distance_m = rest.pop(0).max_distance_m
    gcr = bool(rest) and getattr(rest[0], "per_source_bound", False)
    if gcr:
        counted.append((rest.pop(0).__name__, 1))
    trim = 0.0
    if rest and hasattr(rest[0], "trim_fraction"):
        counted.append((rest[0].__name__, 2))
        trim = rest.pop(0).trim_fraction
    return None if rest else StandardChain(float(max_distance_m), gcr, float(trim), tuple(counted))


def distance_rejector(max_distance_m: float) -> Rejector:
    """The baseline's Euclidean distance rejector: keep matches closer than ``max_distance_m``."""

    def reject(matches: Matches, source) -> np.ndarray:
        return matches.distance_m < max_distance_m

    reject.__name__ = "distance"
    reject.max_distance_m = max_distance_m  # (what the ICP's compiled pass of the standard chain reads)
    return reject


def trimmed_rejector(fraction: float) -> Rejector:
    """Trimmed ICP (Chetverikov et al. 2002): drop the ``fraction`` of matches with the largest distances."""

    def reject(matches: Matches, source) -> np.ndarray:
        n = len(matches)
        n_keep = n - int(np.floor(fraction * n))
        keep = np.zeros(n, dtype=bool)
        if n_keep > 0:
            keep[np.argpartition(matches.distance_m, n_keep - 1)[:n_keep]] = True
        return keep

    reject.__name__ = "trimmed"
    reject.trim_fraction = fraction
    return reject


def geometric_rejector() -> Rejector:
    """The geometric correspondence rejector (Sec. III-B): ``||p_k - p'_k|| < max_l d_{k,l}``.

    The neighbour beam distances depend only on the source point, its normal and
    ring, so ``source.gcr_threshold_m`` (``odometry.gcr``) is computed once per scan.
    """

    def reject(matches: Matches, source) -> np.ndarray:
        return matches.distance_m < source.gcr_threshold_m[matches.source_index]

    reject.__name__ = "gcr"
    reject.per_source_bound = True
    return reject
