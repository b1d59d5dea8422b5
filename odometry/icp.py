"""The ICP of Alg. 1: match, reject, estimate, update, until the termination criteria hold.

Initialisation (the constant-velocity guess) and filtration happen before, in
``odometry.pipeline``; this module registers one prepared source against one
prepared target.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from simlidar import se3

from .config import OdometryConfig
from .constraints import restore_constraints, weakest_translation
from .estimation import plane_step
from .kdtree import KDTree
from .kernels.nearest import reusable_matches
from .kernels.plane_system import more_plane_rows, plane_gate, plane_normal_equations, standard_rejection_system
from .poles import PoleTarget, pole_rows
from .rejectors import Matches, Rejector, distance_rejector, geometric_rejector, standard_chain, trimmed_rejector


@dataclass
class Source:
    """The scan being registered, in its own (de-skewed) sensor frame.

    points: (M, 3) m; normals: (M, 3) unit (nan when the scan has none of its own);
    gcr_threshold_m: (M,) max neighbour beam distance per point (None: no GCR, or not yet known).
    gcr_thresholds: ``(points (m, 3), normals (m, 3), rows (m,)) -> (m,)`` thresholds of
        source rows from given normals, for a source without normals: ``register`` fills
        ``gcr_threshold_m`` from the target's normals at the first matches.
    poles: (P, 3) the scan's poles (``odometry.poles``), m, or None.
    """

    points: np.ndarray
    normals: np.ndarray
    gcr_threshold_m: np.ndarray | None = None
    gcr_thresholds: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None
    poles: np.ndarray | None = None


@dataclass
class NearestCache:
    """The last nearest-neighbour search against one target, which later queries can reuse without a
    search (``match``). Kept by the caller for one target, whose points must not change; empty at first.

    points: (M, 3) the query points searched, target frame, m. index: (M,) the nearest target row
    of each (the target's N where none lay within the bound). clear_m: (M,) no other target point
    lies closer to that query point than this: the second-nearest distance, or the bound.
    bound_m: the search's distance bound, m.
    """

    points: np.ndarray | None = None
    index: np.ndarray | None = None
    clear_m: np.ndarray | None = None
    bound_m: float = math.nan


# Margin of the reuse test, m: far above the rounding of distances of a few hundred metres
# (1e-13 m), far below any distance that separates two target points.
_REUSE_MARGIN_M = 1e-9


@dataclass
class Target:
    """The scan registered against: points, a k-d tree over them, and their normals.

    points: (N, 3) m. normals: (N, 3) unit, or filled on demand by
    ``estimate_normals(indices) -> ((len(indices), 3) normals, (len(indices),) uncertain or None)``
    (a raw scan or a map, where computing every normal would be wasted work); a nan
    normal means "no plane here" and the ICP drops matches to it. ``uncertain`` (N,)
    marks normals the NCF found too uncertain (a map's): the ICP drops those matches
    unless they are the last evidence of a direction (``odometry.constraints``).
    ``known`` (N,) marks the rows estimated (both may be shared with a map's cache).
    ``poles``: poles to match the source's against (``odometry.poles``), or None.
    """

    points: np.ndarray
    tree: KDTree
    normals: np.ndarray
    estimate_normals: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]] | None = None
    known: np.ndarray | None = None
    uncertain: np.ndarray | None = None
    poles: PoleTarget | None = None

    def normals_at(self, index: np.ndarray) -> np.ndarray:
        if self.estimate_normals is not None:
            if self.known is None:
                self.known = np.zeros(len(self.points), dtype=bool)
            missing = ~self.known[index]
            if missing.any():
                # (the distinct rows, ascending: a mark per target row is cheaper than sorting them)
                marked = np.zeros(len(self.points), dtype=bool)
                marked[index[missing]] = True
                rows = np.flatnonzero(marked)
                self.normals[rows], unsure = self.estimate_normals(rows)
                if self.uncertain is not None and unsure is not None:
                    self.uncertain[rows] = unsure
                self.known[rows] = True
        return self.normals.take(index, axis=0)  # (take: the fast gather of rows)


@dataclass
class RegistrationResult:
    """Outcome of one registration (frame-explicit: maps source points into the target frame).

    T_target_source: (4, 4). converged: a termination threshold was met before the
    iteration cap. iterations: steps taken. matches: number of correspondences
    after each stage of the last iteration ("candidates", then each rejector by name, and
    "poles": pole matches); n_matches: the rows of the last step (a plane match one, a pole
    match two).
    rms_m: point-to-plane RMS residual at the last step. H: (6, 6) information of
    the last step's matches. info_eigenvalues: (6,) ascending eigenvalues of H / N;
    translation_eigenvalues: (3,) of its translation block. degenerate: the
    smallest translational eigenvalue is below the config's threshold.
    weakest_direction: (3,) unit eigenvector of that smallest eigenvalue (sign: its
    largest component positive). remapped: directions the last step left at the
    prior (``odometry.constraints``). singular: too few matches or a rank-deficient
    system; the result is then the initial guess.
    """

    T_target_source: np.ndarray
    converged: bool = False
    iterations: int = 0
    matches: dict = field(default_factory=dict)
    n_matches: int = 0
    rms_m: float = float("nan")
    H: np.ndarray = field(default_factory=lambda: np.zeros((6, 6)))
    info_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    translation_eigenvalues: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    degenerate: bool = False
    weakest_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    remapped: int = 0
    singular: bool = False
    seconds: dict = field(default_factory=dict)


def rejectors_for(config: OdometryConfig) -> list[Rejector]:
    """The rejection chain of a config: distance, GCR (when on), then trimming."""
    chain = [distance_rejector(config.match.max_correspondence_distance_m)]
    if config.gcr.enabled:
        chain.append(geometric_rejector())
    if config.match.trim_fraction > 0:
        chain.append(trimmed_rejector(config.match.trim_fraction))
    return chain


def match(points: np.ndarray, target: Target, max_distance_m: float, cache: NearestCache | None = None) -> Matches:
    """Nearest target point of each (M, 3) point within ``max_distance_m``, m (k-d tree, all cores).

    The ICP's query points move by millimetres from one iteration (or de-skew refinement)
    to the next, so most keep their nearest target point, and that can be proven without a
    search: a point moved by ``s`` from where its nearest was found at distance ``d``, with
    no other target point within ``c`` of it then, is now within ``d + s`` of that one and
    beyond ``c - s`` of every other. With a ``cache`` of the last search against this target
    the search (two nearest, for ``c``) is redone only for points where ``d + s < c`` fails
    or that had no neighbour within the bound, and the cache is updated. The answer is the
    search's: the same neighbours and the same distances (a point with two target points at
    one distance is always searched again, and either may be named).
    """
    points = np.asarray(points, dtype=np.float64)
    n = len(target.points)
    if cache is None:
        cache = NearestCache()
    if cache.points is None or cache.bound_m != max_distance_m or len(cache.points) != len(points):
        cache.points, cache.index = points.copy(), np.full(len(points), n, dtype=np.intp)
        cache.clear_m, cache.bound_m = np.zeros(len(points)), max_distance_m
        redo = np.arange(len(points))
        dist = np.full(len(points), np.inf)
    else:
        # (the distance as the k-d tree computes it, so that a reused match carries the same value)
        dist, redo = reusable_matches(np.ascontiguousarray(points), cache.points, cache.index, cache.clear_m,
                                      target.points, float(max_distance_m), _REUSE_MARGIN_M)
    if len(redo):
        q = points.take(redo, axis=0)
        d2, i2 = target.tree.query(q, k=2, distance_upper_bound=max_distance_m)
        dist[redo] = d2[:, 0]
        cache.points[redo] = q
        cache.index[redo] = i2[:, 0]
        cache.clear_m[redo] = np.minimum(d2[:, 1], max_distance_m)
    found = np.flatnonzero(np.isfinite(dist))
    return Matches(found, cache.index.take(found), dist.take(found))


def plane_matches(m: Matches, target: Target, moved: np.ndarray, centre: np.ndarray, config: OdometryConfig
                  ) -> tuple[Matches, dict]:
    """The matches the rejectors see: those whose target point has a usable plane (``usable_planes``).

    Returns the kept matches, carrying their target normals (``Matches.target_normals``), and the counts.
    """
    keep, counts = usable_planes(m, target, moved, centre, config)
    return (m if keep is None else m.select(keep)), counts


# (no NCF verdicts: every plane is sure; no GCR bounds)
_NO_VERDICTS = np.zeros(0, dtype=bool)
_NO_BOUNDS = np.zeros(0)


def usable_planes(m: Matches, target: Target, moved: np.ndarray, centre: np.ndarray, config: OdometryConfig
                  ) -> tuple[np.ndarray | None, dict]:
    """Which matches have a usable plane at their target point: ((m,) bool, or None for all; counts).

    A target with normals on demand (a raw scan, a map) has a nan normal where its
    neighbourhood is no plane: those matches are dropped. A map's normals the NCF
    found too uncertain are dropped too, unless they are the last evidence of a
    direction (``odometry.constraints.restore_constraints``, with
    ``degeneracy.min_constraint_eigenvalue``). A target with fixed normals passes every match.
    Sets ``m.target_normals`` (m, 3), the target's normal at each match.

    Args:
        m: the candidate matches. target: what they index into.
        moved: (M, 3) the source points at the current pose, target frame, m.
        centre: (3,) the point the constraints are taken about (the previous sensor position), m.
        config: its ``degeneracy`` section (``min_constraint_eigenvalue``, ``rotation_scale_m``).

    Returns:
        The keep mask (None: a target with fixed normals keeps all), and the counts:
        {"plane": with a plane, "ncf": of those NCF-sure, "restored": uncertain ones kept},
        or {} for a target with fixed normals.
    """
    m.target_normals = target.normals_at(m.target_index)  # (looked up once: the matches carry them on)
    if target.estimate_normals is None:
        return None, {}
    dg = config.degeneracy
    verdicts = _NO_VERDICTS if target.uncertain is None else target.uncertain
    # (one compiled pass: both gates, and the information of the sure planes for the restore's check)
    plane, sure, H_sure = plane_gate(moved, centre, m.source_index, m.target_index, m.target_normals, verdicts,
                                     float(dg.rotation_scale_m))
    n_plane = int(np.count_nonzero(plane))
    if target.uncertain is None:
        return plane, {"plane": n_plane}
    n_sure = int(np.count_nonzero(sure))
    keep = sure
    if dg.min_constraint_eigenvalue > 0 and n_sure < n_plane \
            and np.linalg.eigh(H_sure / n_plane)[0][0] < dg.min_constraint_eigenvalue:
        # (rare: a direction the sure planes leave weak; ``restore_constraints`` checks the same H first)
        keep = restore_constraints(moved.take(m.source_index, axis=0) - centre, m.target_normals, plane, sure,
                                   dg.min_constraint_eigenvalue, dg.rotation_scale_m)
    return keep, {"plane": n_plane, "ncf": n_sure, "restored": int(np.count_nonzero(keep)) - n_sure}


def converged(xi: np.ndarray, T: np.ndarray, config: OdometryConfig) -> bool:
    """Absolute and relative thresholds on the increment ``xi`` (rho m, omega rad)."""
    dt, dr = np.linalg.norm(xi[:3]), np.linalg.norm(xi[3:])
    abs_t, abs_r = config.icp.abs_translation_tol_m, math.radians(config.icp.abs_rotation_tol_deg)
    rel_t = config.icp.rel_tolerance * np.linalg.norm(T[:3, 3])
    rel_r = config.icp.rel_tolerance * float(se3.rotation_angle(T))
    return bool(dt < max(abs_t, rel_t) and dr < max(abs_r, rel_r))


def register(
    source: Source,
    target: Target,
    T_init: np.ndarray,
    config: OdometryConfig,
    rejectors: Sequence[Rejector] | None = None,
    T_target_previous: np.ndarray | None = None,
    motion_prior: bool = True,
    reskew: Callable[[np.ndarray], np.ndarray] | None = None,
    nearest: NearestCache | None = None,
) -> RegistrationResult:
    """Alg. 1's loop: estimate ``T_target_source`` starting from ``T_init`` (4, 4).

    ``T_target_previous`` (4, 4) is the previous frame's pose in the target frame
    (default: the identity, the target is the previous scan): the relative
    termination threshold is a fraction of the motion from there.

    Matches whose target has no plane (a nan normal: a map point on a line or a
    corner) are dropped before the rejectors. The steps are linearised about the
    previous sensor position in the target frame, not the target frame's origin
    (a map's origin can be hundreds of metres away, where a small rotation is a
    large translation); with ``degeneracy.min_constraint_eigenvalue`` the directions the
    matches constrain too weakly keep ``T_init``'s value (``odometry.constraints``).
    ``motion_prior=False``: ``T_init`` is no prediction (the first registration of a sequence
    starts from a guess, not from a known motion), so no direction is held to it.
    Poles of the source and target (``odometry.poles``) add two horizontal rows per match
    within the same bound (untrimmed: they are few, and the farthest are the evidence of a
    motion the planes do not see).
    ``reskew(T) -> (6,) twist``: after each step, re-de-skews the source (its points and poles, in
    place) for the estimate ``T`` and returns how far the de-skew motion moved (``deskew.joint``);
    the loop ends when both the step and that are below the termination thresholds.
    ``nearest``: the cache of the last search against ``target`` (``match``), kept by the caller
    across the registrations of one frame against it (its matches move by millimetres).
    """
    rejectors = rejectors_for(config) if rejectors is None else rejectors
    T = np.array(T_init, dtype=float)
    centre = np.zeros(3) if T_target_previous is None else np.array(T_target_previous[:3, 3], dtype=float)
    res = RegistrationResult(T_target_source=T.copy())
    seconds = {"match": 0.0, "reject": 0.0, "estimate": 0.0}
    # The distance rejector's bound also limits the k-d tree search.
    bound = config.match.max_correspondence_distance_m
    chain = standard_chain(rejectors)  # (None: a chain of other rejectors, run one by one)
    for it in range(1, config.icp.max_iterations + 1):
        t0 = time.perf_counter()
        moved = source.points @ T[:3, :3].T + T[:3, 3]
        m = match(moved, target, bound, nearest)
        t1 = time.perf_counter()
        keep, gate = usable_planes(m, target, moved, centre, config)
        counts = {"candidates": len(source.points), **gate}
        if source.gcr_threshold_m is None and source.gcr_thresholds is not None:
            # GCR thresholds from the target's normals at these first matches, turned into the
            # source frame (a point without a match now has no bound: inf, the rejector abstains)
            first = m if keep is None else m.select(keep)
            thr = np.full(len(source.points), np.inf)
            n_src = first.target_normals @ T[:3, :3]
            thr[first.source_index] = source.gcr_thresholds(source.points[first.source_index], n_src,
                                                            first.source_index)
            source.gcr_threshold_m = thr
        if chain is not None and (source.gcr_threshold_m is not None or not chain.gcr):
            # the standard chain and the system of what it keeps in one compiled pass (same values)
            left, H, g, sum_r2 = standard_rejection_system(
                moved, target.points, m.target_normals, m.source_index, m.target_index, m.distance_m,
                np.ones(len(m), dtype=bool) if keep is None else keep, chain.max_distance_m,
                source.gcr_threshold_m if chain.gcr else _NO_BOUNDS, chain.trim_fraction, centre)
            counts.update((name, int(left[stage])) for name, stage in chain.counted)
            n_kept = int(left[-1])
        else:
            m = m if keep is None else m.select(keep)
            for reject in rejectors:
                m = m.select(reject(m, source))
                counts[reject.__name__] = len(m)
            n_kept, H = len(m), None
        t2 = time.perf_counter()
        seconds["match"] += t1 - t0
        seconds["reject"] += t2 - t1
        res.matches = counts
        res.n_matches = n_kept
        if n_kept < config.filter.min_points:
            res.singular = True
            break
        deviation = None
        min_eigenvalue = config.degeneracy.min_constraint_eigenvalue if motion_prior else 0.0
        if config.degeneracy.weak_direction_update == "prior" and min_eigenvalue > 0:
            # the estimate's offset from the prior (T_init), as a twist about the centre
            E = T @ se3.inverse(T_init)
            E[:3, 3] += E[:3, :3] @ centre - centre
            deviation = se3.log(E)
        if H is None:
            H, g, sum_r2 = plane_normal_equations(moved.take(m.source_index, axis=0) - centre,
                                                  target.points.take(m.target_index, axis=0) - centre,
                                                  np.ascontiguousarray(m.target_normals, dtype=np.float64))
        n_rows = n_kept
        if source.poles is not None and len(source.poles) and target.poles is not None:
            # the poles' horizontal constraints beside the planes' (``odometry.poles``), summed after them
            p, q, n = pole_rows(source.poles @ T[:3, :3].T + T[:3, 3], target.poles, bound)
            counts["poles"] = len(p) // 2
            H, g, sum_r2 = more_plane_rows(H, g, sum_r2, p - centre, q - centre, n)
            n_rows += len(p)
        step = plane_step(H, g, sum_r2, n_rows, min_eigenvalue=min_eigenvalue,
                          rotation_scale_m=config.degeneracy.rotation_scale_m,
                          mode=config.degeneracy.weak_direction_update, deviation=deviation)
        seconds["estimate"] += time.perf_counter() - t2
        res.iterations, res.rms_m, res.H, res.remapped = it, step.rms_m, step.H, step.remapped
        res.n_matches = n_rows
        if step.rank < 6:
            res.singular = True
            break
        # exp(xi) acts about the centre: T <- C exp(xi) C^-1 T, C the translation by the centre
        inc = step.increment
        T = inc @ T
        T[:3, 3] += centre - inc[:3, :3] @ centre
        motion = T if T_target_previous is None else se3.inverse(T_target_previous) @ T
        done = converged(step.xi, motion, config)
        if reskew is not None:
            done &= converged(reskew(T), motion, config)
        if done:
            res.converged = True
            break
    res.seconds = seconds
    if res.singular:
        res.T_target_source = np.array(T_init, dtype=float)
    else:
        res.T_target_source = T
        n = max(res.n_matches, 1)
        res.info_eigenvalues = np.linalg.eigvalsh(res.H / n)
        res.translation_eigenvalues, res.weakest_direction = weakest_translation(res.H, n)
        res.degenerate = bool(res.translation_eigenvalues[0] < config.degeneracy.degenerate_eigenvalue)
    return res
