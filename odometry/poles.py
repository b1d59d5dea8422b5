"""Poles: narrow objects standing clear of what lies behind them, as constraints across the road.

Why. Where the world is a corridor along the direction of travel (a highway's
road, rails and barrier, open land), the direction of travel is constrained
almost only by small objects. On the simulated highways the guard-rail posts
(12 x 10 cm, every 4 m) carry 73-97 % of the along-track information of the
true normals (sum of (n . x)^2 over a scan's returns); the rails, barrier and
road carry almost none. The plane pipeline loses them: a post is one to four
returns per ring, and the voxel that holds them also holds the rail's beam
and the ground, so no normal of the post survives the curvature filter or the
map's plane gate. What the ICP keeps along the road is then the rails' and
the ground's sampling pattern, which favours standing still: every method,
the peers too, stayed near its start on those highways.

What. Along each ring of the scan's range image (``odometry.scan_lines``), a
*pole* is a run of returns at about one range, at most ``poles.max_width_m``
across, with the returns beside it on both sides clearly farther
(``kernels.poles.foreground_runs``): a post, a pole, a trunk, a sign's leg seen
against the land behind it. Its centroid is a point of the object; seen from
another place, the same object gives a centroid within a few centimetres of it
horizontally (the run's height depends on the ring, so only the horizontal
position is a constraint). Each pole of the scan is matched to the nearest
pole of the last ``poles.frames_kept`` frames (horizontally, within the ICP's
correspondence bound), and each match adds two point-to-plane rows to the
ICP's system, with the target frame's horizontal axes as normals: the
horizontal distance between the two is the residual. A post then constrains
both horizontal directions as much as a plane match does its normal's.

The first registration of a sequence has no motion to extrapolate: the
horizontal offset that brings the most poles of the scan onto poles of the
first scan (``pole_translation``) is its initial guess, where enough agree.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from simlidar import se3

from .kdtree import KDTree
from .kernels.poles import consensus_votes, foreground_runs
from .scan_lines import range_image

# A run's returns are at one range within this (m, and a fraction of the range: noise and the
# incidence across a 10-60 cm object), and its neighbours on both sides are farther than its
# farthest return by at least this (m, and a fraction of the range): an object standing clear
# of what is behind it, not a bump on a surface.
RUN_TOLERANCE_M, RUN_TOLERANCE_FRACTION = 0.15, 0.02
MIN_GAP_M, GAP_FRACTION = 0.5, 0.1
# Consecutive returns of a ring may be this many azimuth columns apart (one cell missing: the
# range image's columns do not always fall one per firing).
MAX_COLUMN_GAP = 2
# Weather clutter (fog's backscatter, rain and snow: a volume that returns from a random range on
# each beam) gives isolated foreground returns by the thousand near the sensor, every one a "pole"
# by the rule above. A pole stands clear of other poles: none lies within ISOLATION_RADIUS_M of it
# horizontally, but the same object's runs on other rings (within SAME_OBJECT_COLUMNS azimuth
# columns of its direction). On the tuning seeds (seed 101, every family, two scans each) this kept
# 84-87 % of the poles of structure and 0.15 % (dense fog), 1.0 % (light fog) and 1.7 % (snow) of
# the weather's (docs/weather.md, "The odometry in weather").
ISOLATION_RADIUS_M = 0.5
SAME_OBJECT_COLUMNS = 3
CROWD_NEIGHBOURS = 16  # (a post on more rings than this is as crowded as it is alone: it passes)
# The rule engages only on a cluttered scan: a clear scan keeps its poles as they were (a wood's trunks
# and a real street's clutter stand close together too). A particle or fog's backscatter returns on one
# beam, so a cluttered scan is one with more than CLUTTERED_PER_BEAM crowded one-return poles per beam
# fired (rings x azimuth columns). Per 1000 beams, on the tuning seeds (every family, both kinds, three
# scans each; seeds 101-103, rain and dense fog 101 only): clear air and rain at most 0.08; light fog at
# least 4.7 but in one garage (1.2: its near walls leave the fog few beams, and the scan's ~200 weather
# poles stand among ~370 of structure), snow 13, dense fog 46. The real excerpts in clear air (KITTI 05 and 01, the
# HDL-32E pair): 0.16-0.74, though up to 0.56 of a real street's poles are crowded: a share of crowded
# poles does not separate a street from weather.
CLUTTERED_PER_BEAM = 0.002
# Weather lasts: after a scan over the gate, the scans that follow are taken as in weather while their
# statistic stays over LEAVE_PER_BEAM. Near walls (a tunnel's, a garage's) leave the fog few beams and
# bring the statistic under the gate while nearly every pole is still the weather's (a vlp16 in light
# fog inside a tunnel: 1.2-2 per 1000 beams, 57 of its 60 poles the weather's). Per 1000 beams on the
# tuning seeds: clear air at most 0.08, rain 0.01; weather at least 1.2 (a garage in light fog) and 1.8
# inside the tunnels (docs/weather.md, "The poles in weather").
LEAVE_PER_BEAM = 0.0005
# In weather a pole must also be as wide as a post: its run, returns x range x the column angle, at least
# MIN_WIDTH_M across. A backscatter or a particle is one return near the sensor, a few millimetres
# across at that range; a post of 10 cm or more always spans that much (a one-return run is at most
# two columns across). Tuning seeds 101-103, every family as real, two scans each: 99.5 % of the weather's
# poles are narrower, 0.8 % of the structure's.
MIN_WIDTH_M = 0.05
# Within the clutter's reach (1.25 times the 99th percentile of the crowded one-return poles' horizontal
# ranges, once there are MIN_CLUTTER_POLES of them), a one-return pole no other ring sees is the weather's
# too: fog's backscatter thins out towards its far end, where single returns are as wide as a post and no
# longer crowded (open ground, os1-64 in light fog, tuning seed 103: the crowded ones' 99th percentile at
# 7.4 m; about ten a scan kept at 8.2-8.4 m, every one a false return).
CLUTTER_REACH_QUANTILE = 0.99
CLUTTER_REACH_MARGIN = 1.25
MIN_CLUTTER_POLES = 20
# What clutter is left is sparse and random from scan to scan; a post is where it was. A pole of a
# cluttered scan is a target of the pole map once a pole of the frame before or after it lies within
# CONFIRM_RADIUS_M (as the first registration's poles agree on an offset, CONSENSUS_RADIUS_M).
CONFIRM_RADIUS_M = 0.25
# The first registration: poles that agree on an offset within this, m, and how many must.
CONSENSUS_RADIUS_M = 0.25
MIN_CONSENSUS = 4
# Offsets with at least this fraction of the best one's votes are taken as equally likely: evenly
# spaced posts agree with an offset one spacing off too, and the two counts differ only by the
# posts at the ends of the view, an occluded post and the first scans' motion distortion (on the
# tuning highways the wrong alias had 81-96 % of the true one's votes; over the tuning and other
# seeds' first registrations, offsets neither within 0.6 m of the truth nor an alias of it had at most
# 33 %; an evaluation start at 17 m/s gave the wrong alias one vote more, 75 against 74).
ALIAS_VOTE_RATIO = 0.75


@dataclass
class Poles:
    """A scan's poles. points: (P, 3) run centroids, sensor frame, m; counts: (P,) returns in each run;
    times_s: (P,) their mean firing time, s, or None (the scan has no per-point times).

    With the clutter filter (else these stay at their defaults): clutter_per_beam: the scan's crowded
    one-return poles per beam fired; suspect: (P,) bool, the poles weather would make (crowded, or
    narrower than ``MIN_WIDTH_M``), None once dropped; cluttered: the poles are a scan's in weather
    (``WeatherGate``), and ``dropped`` suspects left them (``without_suspects``)."""

    points: np.ndarray
    counts: np.ndarray
    times_s: np.ndarray | None = None
    cluttered: bool = False
    dropped: int = 0
    clutter_per_beam: float = 0.0
    suspect: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.points)

    def subset(self, keep: np.ndarray) -> Poles:
        """These poles where ``keep`` (P,) bool is True."""
        return replace(self, points=self.points[keep], counts=self.counts[keep],
                       times_s=None if self.times_s is None else self.times_s[keep],
                       suspect=None if self.suspect is None else self.suspect[keep])

    def without_suspects(self) -> Poles:
        """The poles of a scan in weather: the suspects dropped (none without the filter), ``cluttered`` set."""
        if self.suspect is None:
            return replace(self, cluttered=True)
        kept = self.subset(~self.suspect)
        return replace(kept, cluttered=True, dropped=int(self.suspect.sum()), suspect=None)


class WeatherGate:
    """Whether a scan's poles are taken as in weather, from its ``Poles.clutter_per_beam`` and the scans' before:
    over ``CLUTTERED_PER_BEAM``, or over ``LEAVE_PER_BEAM`` while the scan before was in weather."""

    def __init__(self) -> None:
        self.in_weather = False

    def update(self, clutter_per_beam: float) -> bool:
        self.in_weather = clutter_per_beam > LEAVE_PER_BEAM if self.in_weather else cluttered(clutter_per_beam)
        return self.in_weather


def cluttered(clutter_per_beam: float) -> bool:
    """Whether a scan, on its own (no memory of the scans before), is in weather: its crowded one-return poles per
    beam (``Poles.clutter_per_beam``) over ``CLUTTERED_PER_BEAM``. ``WeatherGate`` enters weather by it."""
    return clutter_per_beam > CLUTTERED_PER_BEAM


def extract_poles(points: np.ndarray, rings: np.ndarray, n_rings: int, n_columns: int, max_width_m: float,
                  times_s: np.ndarray | None = None, clutter_filter: bool = False, clutter_reach: bool = True) -> Poles:
    """The poles of a raw scan (module doc).

    points: (N, 3) as measured (or de-skewed), sensor frame, m; rings: (N,) int, 0 the lowest;
    n_rings, n_columns: the sensor's rings and azimuth columns per sweep; max_width_m: the widest
    run kept, m; times_s: (N,) firing times, s, or None. clutter_filter: measure ``clutter_per_beam`` (one-return
    poles ``crowded`` among others, per beam) and mark the ``suspect`` poles; what is dropped depends on the
    scans before (``WeatherGate``, ``Poles.without_suspects``): the caller's, which alone sees a sequence.
    clutter_reach: ``alone_within_the_clutter`` looks only within the clutter's reach (else at any range).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    image = range_image(rings, points, n_rings, n_columns)
    times = np.full(len(points), np.nan) if times_s is None else np.ascontiguousarray(times_s, dtype=np.float64)
    column_rad = 2.0 * math.pi / n_columns
    centroids, counts, mean_times = foreground_runs(
        image, points, times, column_rad, float(max_width_m), MIN_GAP_M, GAP_FRACTION,
        RUN_TOLERANCE_M, RUN_TOLERANCE_FRACTION, MAX_COLUMN_GAP)
    poles = Poles(centroids, counts, None if times_s is None else mean_times)
    if clutter_filter:
        among = crowded(centroids, n_columns) if len(centroids) else np.zeros(0, dtype=bool)
        width_m = counts * np.hypot(centroids[:, 0], centroids[:, 1]) * column_rad
        poles.clutter_per_beam = np.count_nonzero(among & (counts == 1)) / (n_rings * n_columns)
        poles.suspect = among | (width_m < MIN_WIDTH_M) | alone_within_the_clutter(centroids, counts, among, n_columns,
                                                                                    clutter_reach)
    return poles


def crowded(points: np.ndarray, n_columns: int, radius_m: float = ISOLATION_RADIUS_M,
            same_object_columns: int = SAME_OBJECT_COLUMNS) -> np.ndarray:
    """(P,) bool: the poles (P, 3) (sensor frame, m) with another within ``radius_m`` horizontally that is not
    the same object seen by another ring (more than ``same_object_columns`` azimuth columns of a sweep
    of ``n_columns`` away in direction). Among a pole's ``CROWD_NEIGHBOURS`` nearest."""
    near, turn = _horizontal_neighbours(points, radius_m)
    return np.any(near & (turn > same_object_columns * 2.0 * math.pi / n_columns), axis=1)


def _horizontal_neighbours(points: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Each pole's (P, 3) other poles within ``radius_m`` horizontally, among its ``CROWD_NEIGHBOURS`` nearest:
    (P, k) bool, which slots hold one, and (P, k) the angle between their directions from the sensor, rad."""
    xy = horizontal(points)
    k = min(CROWD_NEIGHBOURS + 1, len(xy))
    dist, idx = KDTree(xy).query(xy, k=k, distance_upper_bound=radius_m)
    dist, idx = dist.reshape(len(xy), k), idx.reshape(len(xy), k)
    near = np.isfinite(dist) & (idx != np.arange(len(xy))[:, None])
    azimuth = np.arctan2(xy[:, 1], xy[:, 0])
    return near, np.abs(np.angle(np.exp(1j * (azimuth[np.where(near, idx, 0)] - azimuth[:, None]))))


def alone_within_the_clutter(points: np.ndarray, counts: np.ndarray, crowded_poles: np.ndarray,
                             n_columns: int, within_reach: bool = True) -> np.ndarray:
    """(P,) bool: one-return poles (P, 3) (sensor frame, m) that no other ring sees (``seen_by_another_ring``)
    and that stand within the clutter's reach: ``CLUTTER_REACH_MARGIN`` times the ``CLUTTER_REACH_QUANTILE``
    of the crowded one-return poles' horizontal ranges, when there are at least ``MIN_CLUTTER_POLES`` of
    them (else none: no clutter to measure). The weather's clutter has a reach (fog's backscatter a few
    metres; ``crowded_poles`` (P,) bool marks it); a post beyond it, seen on one ring by one return, as far
    posts are, is left alone. Without ``within_reach``, at any range: snow's flakes reach beyond where they are
    crowded (open ground, os1-64, tuning seed 103: crowded to about 8 m, the snow's returns to 14 m at their 99th
    percentile; 4,518 of the 4,546 poles kept over the sequence were flakes at 7-10 m)."""
    single = counts == 1
    crowded_single = crowded_poles & single
    if np.count_nonzero(crowded_single) < MIN_CLUTTER_POLES:
        return np.zeros(len(points), dtype=bool)
    r = np.hypot(points[:, 0], points[:, 1])
    reach = CLUTTER_REACH_MARGIN * float(np.quantile(r[crowded_single], CLUTTER_REACH_QUANTILE)) if within_reach \
        else np.inf
    return single & (r <= reach) & ~seen_by_another_ring(points, n_columns)


def seen_by_another_ring(points: np.ndarray, n_columns: int, radius_m: float = CONFIRM_RADIUS_M,
                         same_object_columns: int = SAME_OBJECT_COLUMNS) -> np.ndarray:
    """(P,) bool: the poles (P, 3) (sensor frame, m) with another within ``radius_m`` horizontally and within
    ``same_object_columns`` azimuth columns (of a sweep of ``n_columns``) of its direction: the same upright
    object on another ring. A one-return pole that is not may be the weather's (``alone_within_the_clutter``)."""
    near, turn = _horizontal_neighbours(points, radius_m)
    return np.any(near & (turn <= same_object_columns * 2.0 * math.pi / n_columns), axis=1)


@dataclass
class PoleTarget:
    """Poles to match against, in the registration's target frame: points (Q, 3), m, and a k-d tree
    over their horizontal positions (x, y, 0): the frame's z is taken as up."""

    points: np.ndarray
    tree: KDTree

    @classmethod
    def of(cls, points: np.ndarray) -> PoleTarget:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return cls(points, KDTree(horizontal(points)))

    def __len__(self) -> int:
        return len(self.points)


def horizontal(points: np.ndarray) -> np.ndarray:
    """(N, 3) points with z set to 0."""
    out = np.array(points, dtype=np.float64).reshape(-1, 3)
    out[:, 2] = 0.0
    return out


class PoleMap:
    """The poles of the last ``frames_kept`` frames, in the world frame (the first scan's).

    confirmed_only: a pole of a cluttered frame (``add``) is a target once confirmed, a pole of the frame
    before or after it lying within ``CONFIRM_RADIUS_M`` horizontally (while the map holds one frame,
    every pole is: the first registration's own consensus confirms them); a clear frame's poles are
    targets at once. Without it every pole is.
    """

    def __init__(self, frames_kept: int, confirmed_only: bool = False):
        self.frames_kept = frames_kept
        self.confirmed_only = confirmed_only
        self._frames: deque[np.ndarray] = deque(maxlen=frames_kept)
        self._confirmed: deque[np.ndarray] = deque(maxlen=frames_kept)

    def add(self, points_world: np.ndarray, cluttered: bool = False) -> None:
        """One frame's poles (P, 3), world frame, m (an empty frame counts as a frame); cluttered: they wait
        for a neighbouring frame's confirmation (``Poles.cluttered``)."""
        points = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        confirmed = np.full(len(points), not cluttered)
        waiting = cluttered or (self._frames and not self._confirmed[-1].all())  # (clear air: nothing to confirm)
        if self.confirmed_only and waiting and self._frames and len(points) and len(self._frames[-1]):
            before = self._frames[-1]
            d, _ = KDTree(horizontal(before)).query(horizontal(points), distance_upper_bound=CONFIRM_RADIUS_M)
            confirmed |= np.isfinite(d)
            d, _ = KDTree(horizontal(points)).query(horizontal(before), distance_upper_bound=CONFIRM_RADIUS_M)
            self._confirmed[-1] |= np.isfinite(d)
        self._frames.append(points)
        self._confirmed.append(confirmed)

    def __len__(self) -> int:
        return sum(len(p) for p in self._frames)

    def target(self, T_target_world: np.ndarray | None = None) -> PoleTarget | None:
        """The poles as a target, moved into a frame by ``T_target_world`` (4, 4; None: the world); None if none."""
        if self.confirmed_only and len(self._frames) > 1:
            points = np.vstack([p[c] for p, c in zip(self._frames, self._confirmed, strict=True)])
        elif len(self):
            points = np.vstack(self._frames)
        else:
            return None
        if len(points) == 0:
            return None
        if T_target_world is not None:
            points = se3.transform_points(T_target_world, points)
        return PoleTarget.of(points)


def pole_rows(moved: np.ndarray, target: PoleTarget, bound_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point-to-plane rows of the poles' matches: (2K, 3) source points, target points and normals.

    moved: (P, 3) the scan's poles at the current estimate, target frame, m. Each is matched to the
    horizontally nearest target pole within ``bound_m``. A match gives two rows with normals x and
    y of the target frame, whose residuals are the two components of the horizontal distance.
    No trimming: poles are few, and while the estimate is still short of a motion only they see,
    their matches are the farthest (on the highway seeds 103-107, trimming a fifth of them as the
    planes are trimmed doubled or quadrupled t_err: 0.75 to 1.48 %, 0.17 to 0.69 %).
    """
    dist, idx = target.tree.query(horizontal(moved), k=1, distance_upper_bound=bound_m)
    found = np.flatnonzero(np.isfinite(dist))
    src = moved.take(found, axis=0)
    tgt = target.points.take(idx.take(found), axis=0)
    k = len(found)
    normals = np.zeros((2 * k, 3))
    normals[:k, 0] = 1.0
    normals[k:, 1] = 1.0
    return np.vstack([src, src]), np.vstack([tgt, tgt]), normals


def pole_translation(source: np.ndarray, target: PoleTarget, bound_m: float) -> np.ndarray | None:
    """The horizontal offset (3,) (z 0) that brings the most of (P, 3) ``source`` poles onto target poles, m.

    Every pair of a source and a target pole within ``bound_m`` of each other horizontally proposes
    its offset, and counts the source poles that agree with it (a target pole within
    ``CONSENSUS_RADIUS_M`` of each). Of the offsets with nearly the most votes (at least
    ``ALIAS_VOTE_RATIO`` of them: evenly spaced posts agree with an offset of one spacing off too)
    the smallest wins, the one nearest the guess, as an ICP from the guess would converge to; the
    mean offset of its agreeing pairs is returned. None when fewer than ``MIN_CONSENSUS`` agree.
    """
    src = np.asarray(source, dtype=np.float64).reshape(-1, 3)[:, :2]
    dst = target.points[:, :2]
    if len(src) < MIN_CONSENSUS or len(dst) < MIN_CONSENSUS:
        return None
    offsets = dst[None, :, :] - src[:, None, :]  # (P, Q, 2): target minus source
    near = np.hypot(offsets[..., 0], offsets[..., 1]) <= bound_m
    candidates = offsets[near]  # (K, 2), grouped by source pole
    if len(candidates) == 0:
        return None
    owner = np.nonzero(near)[0]  # (K,) the source pole of each candidate
    starts = np.searchsorted(owner, np.arange(len(src) + 1))  # source pole i's candidates: starts[i]:starts[i + 1]
    # Candidate k gets source pole i's vote when one of i's candidates lies within the radius of it
    # (compiled: a pole on many rings is many poles at one place, so the candidates crowd, and a dense
    # sensor's first scans give thousands; numpy's all-pairs test took half a second there).
    order = np.lexsort((candidates[:, 0], owner))
    votes = np.empty(len(candidates), dtype=np.int64)
    votes[order] = consensus_votes(np.ascontiguousarray(candidates[order]), starts, CONSENSUS_RADIUS_M)
    if votes.max() < MIN_CONSENSUS:
        return None
    likely = np.flatnonzero(votes >= max(ALIAS_VOTE_RATIO * votes.max(), MIN_CONSENSUS))
    best = likely[np.argmin(np.hypot(candidates[likely, 0], candidates[likely, 1]))]
    # the mean of each agreeing pole's offset nearest the winner
    d = np.hypot(*(candidates - candidates[best]).T)
    chosen = []
    for i in np.unique(owner[d <= CONSENSUS_RADIUS_M]):
        s, e = starts[i], starts[i + 1]
        chosen.append(candidates[s + np.argmin(d[s:e])])
    mean = np.mean(chosen, axis=0)
    return np.array([mean[0], mean[1], 0.0])
