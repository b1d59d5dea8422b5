"""A local map of recent registered scans: the target of scan-to-map registration.

Why a map. Scan-to-scan registration matches a scan against the previous one,
whose sampling pattern (the rings on the ground) moves with the sensor: on
sparse-ring ground the two patterns pull the estimate towards zero motion, and
a normal fitted to points of one ring is tilted by the beam's elevation. Both
biases add up frame after frame (vertical drift, an estimate that stops). A map
of many scans, held in the world frame, breaks both: its points come from many
sensor positions, so the rings of different scans cross every patch of ground
and a neighbourhood spans several of them.

Design (the voxel map of KISS-ICP, Vizzo et al. 2023, with normals computed in
the map): points in world coordinates, bucketed in cubic voxels of
``voxel_size_m`` holding at most ``max_points_per_voxel`` points each (a full
voxel takes no more points, so the map keeps its first, stable observations and
its size is bounded by the volume, not the time), and a point within
``min_spacing_m`` of a map point is not added (the surface is already there);
points farther than ``max_distance_m`` from the sensor are dropped. A target normal is the PCA
normal of the target point's ``normal_neighbours`` nearest map points, computed
only for points that are matched and kept until a point enters or leaves that
neighbourhood (within the farthest neighbour's distance), and only where it is a plane:
it must extend along its second axis well beyond the range noise (points of
one scan line do not define a plane) and its curvature be below
``max_curvature``. Other targets get a nan normal: the ICP drops those matches
(a line or a corner does not define a plane).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .filters import background
from .icp import Target
from .kdtree import KDTree
from .kernels.normals import gathered_scatter, map_normal_verdicts
from .kernels.voxel_hash import keys_near, within_reach_of_any
from .ncf import DEFAULT_GAP_SIGNIFICANCE_Z, DEGENERATE_GAP, ncf_keep
from .normals import knn, symmetric_eigh_descending
from .voxels import neighbour_key_steps, voxel_centres, voxel_keys

# A map neighbourhood is a plane only if it extends this many range-noise sigmas along its second axis,
MIN_PLANE_EXTENT_SIGMAS = 3.0
# and holds two scan lines: beam elevations this far apart (a quarter of the finest ring pitch of
# the presets, 0.26 deg; one scan's rings differ by a whole pitch), or scans this far apart.
MIN_ELEVATION_SPREAD_RAD = np.radians(0.065)
MIN_BASELINE_M = 0.3
# The map drops far voxels each time the sensor has moved this far, m.
PRUNE_STRIDE_M = 5.0
# Key differences from a voxel to itself and its 26 neighbours (the map's normal cache checks them).
_NEIGHBOUR_KEY_STEPS = neighbour_key_steps()

def places_in_sorted(values: np.ndarray, sorted_set: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N,) each value's place in the sorted array ``sorted_set`` (``searchsorted``), (N,) bool: it is there)."""
    pos = np.searchsorted(sorted_set, values)
    found = np.zeros(len(values), dtype=bool)
    inside = pos < len(sorted_set)
    found[inside] = sorted_set[pos[inside]] == values[inside]
    return pos, found


def rank_within_groups(sorted_keys: np.ndarray) -> np.ndarray:
    """(N,) 0, 1, 2, ... counting up within each run of equal values of a sorted array."""
    n = len(sorted_keys)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(n)
    first = np.ones(n, dtype=bool)
    first[1:] = sorted_keys[1:] != sorted_keys[:-1]
    return idx - np.maximum.accumulate(np.where(first, idx, 0))


def plane_normals_valid(estimate, noise_std_m: float, max_curvature: float,
                        min_extent_sigmas: float = MIN_PLANE_EXTENT_SIGMAS) -> np.ndarray:
    """(M,) bool: the neighbourhoods of a ``NormalEstimate`` define a plane.

    A plane needs two axes: the neighbourhood's standard deviation along its second
    axis must exceed ``min_extent_sigmas`` range-noise sigmas. Points of one scan
    line (one ring on the ground) spread across the line only by their noise, and
    their "normal" is then perpendicular to the beams, not to the surface. And the
    PCL curvature must be at most ``max_curvature`` (not a corner, not foliage).
    """
    lam = estimate.scatter_eigenvalues / estimate.k  # variances along the axes, m^2
    with np.errstate(invalid="ignore"):
        wide = lam[:, 1] > (min_extent_sigmas * noise_std_m) ** 2
        flat = estimate.curvature <= max_curvature
    return wide & flat & np.isfinite(estimate.normals).all(axis=1)


def spans_two_scan_lines(neighbours: np.ndarray, elevations_rad: np.ndarray, origins: np.ndarray,
                         min_elevation_spread_rad: float = MIN_ELEVATION_SPREAD_RAD,
                         min_baseline_m: float = MIN_BASELINE_M) -> np.ndarray:
    """(M,) bool: a neighbourhood holds points of more than one scan line.

    neighbours: (M, k) rows of the points in each neighbourhood;
    elevations_rad: (N,) elevation of the beam that measured each point, rad (``beam_elevation_rad``);
    origins: (N, 3) where from, m.
    Points of one ring seen from one place lie on one cone: their best plane contains
    the beams, whatever the surface (a ring on rolling ground gives a normal tilted by
    the ground's curvature along the ring), and motion along the beams, which is what a
    pitch or a climb does to ground returns, leaves no residual. Two scan lines are two
    rings (beam elevations differing by more than ``min_elevation_spread_rad``), or the
    same ring seen from places more than ``min_baseline_m`` apart.
    """
    spans = np.ptp(elevations_rad.take(neighbours), axis=1) > min_elevation_spread_rad
    # (the places are looked at only where the rings do not already differ: most neighbourhoods span rings)
    one_ring = np.flatnonzero(~spans)
    if len(one_ring):
        spread = np.ptp(origins.take(neighbours[one_ring], axis=0), axis=1)
        spans[one_ring] = np.linalg.norm(spread, axis=1) > min_baseline_m
    return spans


def beam_elevation_rad(beams: np.ndarray) -> np.ndarray:
    """(N, 3) unit beams -> (N,) their elevations, rad."""
    return np.arcsin(np.clip(beams[:, 2], -1.0, 1.0))


@dataclass
class MapStats:
    """Size of the map after an update: points, occupied voxels, points added and dropped."""

    points: int
    voxels: int
    added: int
    dropped: int


class LocalMap:
    """Voxel-bucketed world points of recent scans with lazily estimated plane normals.

    Args:
        voxel_size_m: edge of the map's voxels, m.
        max_points_per_voxel: a voxel holding this many points takes no more.
        max_distance_m: points farther than this from the sensor are dropped, m.
        normal_neighbours: k of the target normals' kNN among the map points.
        noise_std_m: the range noise sigma, for the planarity test of target normals, m.
        max_curvature: PCL curvature above which a target neighbourhood is not a plane.
        prune_stride_m: how far the sensor moves between two prunings of far voxels, m.
        ncf_c_tau_rad2: when given, the normal covariance filter also judges the map's
            normals: each neighbour's noise lies along the beam that measured it (kept
            per point from the sensor position at insertion), propagated to the normal
            as in ``odometry.ncf``; a normal whose variance reaches this is no plane.
        min_spacing_m: a new point closer than this to a point already in the map is not
            added (0: every point while its voxel has room), m. The map then keeps its first
            observation of a surface instead of a copy per scan: each copy would be matched
            next (a scan resamples the same places), need its own normal and grow the k-d tree,
            and adds nothing the first one does not already say.
    """

    def __init__(self, voxel_size_m: float, max_points_per_voxel: int, max_distance_m: float,
                 normal_neighbours: int, noise_std_m: float, max_curvature: float,
                 ncf_c_tau_rad2: float | None = None, prune_stride_m: float = PRUNE_STRIDE_M,
                 min_spacing_m: float = 0.0):
        self.voxel_size_m = float(voxel_size_m)
        self.max_points_per_voxel = int(max_points_per_voxel)
        self.max_distance_m = float(max_distance_m)
        self.normal_neighbours = int(normal_neighbours)
        self.noise_std_m = float(noise_std_m)
        self.max_curvature = float(max_curvature)
        self.ncf_c_tau_rad2 = ncf_c_tau_rad2
        self.points = np.zeros((0, 3))
        self._keys = np.zeros(0, dtype=np.int64)  # voxel key of each point
        self._beams = np.zeros((0, 3))  # unit direction from the sensor that saw each point
        self._origins = np.zeros((0, 3))  # sensor position of each point's scan
        self._elevations = np.zeros(0)  # elevation of each point's beam, rad
        self._pruned_at: np.ndarray | None = None  # sensor position at the last pruning
        self.prune_stride_m = float(prune_stride_m)
        self.min_spacing_m = float(min_spacing_m)
        # Target normals, estimated when first matched and kept while their neighbourhood stands:
        # nan where no plane; ``_known`` marks the rows estimated since their neighbourhood changed,
        # ``_reach`` the distance to the farthest of those neighbours, m.
        self._normals = np.zeros((0, 3))
        self._known = np.zeros(0, dtype=bool)
        self._reach = np.zeros(0)
        self._uncertain = np.zeros(0, dtype=bool)  # the NCF's verdict on each estimated normal
        self._voxel_keys = np.zeros(0, dtype=np.int64)  # sorted occupied voxels
        self._voxel_counts = np.zeros(0, dtype=np.int64)
        # Optional (N,) values carried with the points (``update``'s payload), None when not used.
        self._payload: np.ndarray | None = None
        self._buffers: dict[str, np.ndarray] = {}  # (the per-point arrays' room to grow: ``_append``)
        self._tree = background("map").submit(KDTree, self.points)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def empty(self) -> bool:
        return len(self.points) == 0

    @property
    def payload(self) -> np.ndarray | None:
        """(len,) the payload value of each map point, row for row with ``points``; None without payloads."""
        return self._payload

    def update(self, points_world: np.ndarray, sensor_position_m: np.ndarray,
               payload: np.ndarray | None = None, nearest_m: np.ndarray | None = None) -> MapStats:
        """Add (N, 3) world points where their voxels have room, then drop far points.

        ``payload`` (N,): optional values (any dtype, e.g. row numbers into a table kept
        elsewhere) that stay with their points through the voxel caps and the pruning
        (``payload``). A map either carries one from its first update on, or never.
        ``nearest_m`` (N,): each point's distance to its nearest map point, m, when the caller
        knows it (inf where none is within ``min_spacing_m``): the spacing check then does not search.

        The k-d tree of the new map is built on a background thread (it releases the GIL)
        while the next scan is cleaned and filtered; ``target`` waits for it.
        """
        points_world = np.asarray(points_world, dtype=np.float64)
        if payload is not None:
            payload = np.asarray(payload)
            if payload.shape != (len(points_world),):
                raise ValueError(f"payload must be ({len(points_world)},), got {payload.shape}")
            if self._payload is None:
                if not self.empty:
                    raise ValueError("this map holds points without a payload: give one from the first update")
                self._payload = np.zeros(0, dtype=payload.dtype)
        elif self._payload is not None:
            raise ValueError("this map carries a payload: give one with every update")
        if nearest_m is not None and np.shape(nearest_m) != (len(points_world),):
            raise ValueError(f"nearest_m must be ({len(points_world)},), got {np.shape(nearest_m)}")
        inserted = self._insert(points_world, np.asarray(sensor_position_m, dtype=float), payload, nearest_m)
        dropped = self._prune(np.asarray(sensor_position_m, dtype=np.float64))
        # (built on the background thread while the cached normals are checked and the next scan
        # is cleaned and filtered)
        self._tree = background("map").submit(KDTree, self.points)
        self._forget_normals_near(np.concatenate([inserted, dropped]))
        return MapStats(len(self.points), len(self._voxel_keys), len(inserted), len(dropped))

    def _insert(self, points: np.ndarray, origin: np.ndarray, payload: np.ndarray | None = None,
                nearest_m: np.ndarray | None = None) -> np.ndarray:
        """Append the points the spacing check and the voxel caps accept; returns them (K, 3), m."""
        if len(points) == 0:
            return points
        if self.min_spacing_m > 0 and len(self.points):
            # (the points of one update are a scan's voxel centroids, already spaced by its voxel grid)
            if nearest_m is None:
                nearest_m, _ = self._tree.result().query(points, k=1, distance_upper_bound=self.min_spacing_m)
            new = ~(nearest_m < self.min_spacing_m)  # (as the k-d tree's bound: strictly within)
            points = np.compress(new, points, axis=0)  # (compress, take: numpy's fast row gathers)
            if payload is not None:
                payload = payload[new]
            if len(points) == 0:
                return points
        keys = voxel_keys(points, self.voxel_size_m)
        order = np.argsort(keys, kind="stable")
        keys, points = keys[order], points.take(order, axis=0)
        if payload is not None:
            payload = payload[order]
        pos, known = places_in_sorted(keys, self._voxel_keys)
        held = np.zeros(len(keys), dtype=np.int64)
        held[known] = self._voxel_counts[pos[known]]
        accept = held + rank_within_groups(keys) < self.max_points_per_voxel
        if not accept.any():
            return points[:0]
        keys, points = keys[accept], np.compress(accept, points, axis=0)
        if payload is not None:
            self._append("_payload", payload[accept])
        beams = points - origin
        beams /= np.linalg.norm(beams, axis=1, keepdims=True)
        for name, rows in (("points", points), ("_keys", keys), ("_beams", beams),
                           ("_elevations", beam_elevation_rad(beams)), ("_origins", origin),
                           ("_normals", np.nan), ("_known", False), ("_reach", 0.0), ("_uncertain", False)):
            self._append(name, rows, len(points))
        self._count_in(keys)
        return points

    def _append(self, name: str, rows, count: int | None = None) -> None:
        """Append ``rows`` (``count`` rows; a scalar or a row is repeated) to the per-point array ``name``.

        The arrays are views of the first rows of buffers with room to grow (doubling): an
        update writes only its new rows, where copying every array of the map each frame took
        about as long as the rest of the update. A view handed out earlier (a target, a k-d
        tree being built) keeps its rows: they are never written again, and a pruning makes new arrays.
        """
        view = getattr(self, name)
        n = len(view)
        count = len(rows) if count is None else count
        buffer = self._buffers.get(name)
        if buffer is None or view.base is not buffer or len(buffer) < n + count:
            buffer = np.empty((max(2 * (n + count), 1024),) + view.shape[1:], dtype=view.dtype)
            buffer[:n] = view
            self._buffers[name] = buffer
        buffer[n:n + count] = rows
        setattr(self, name, buffer[:n + count])

    def _prune(self, position: np.ndarray) -> np.ndarray:
        """Drop the voxels whose centre is farther than ``max_distance_m`` (a check per voxel, not per point).

        Checked once the sensor has moved ``prune_stride_m`` since the last check: a map a few
        metres wider than ``max_distance_m`` for a moment costs nothing, rebuilding every array
        of the map each frame does. Returns the (K, 3) points dropped, m.
        """
        if self._pruned_at is not None and np.linalg.norm(position - self._pruned_at) < self.prune_stride_m:
            return self.points[:0]
        self._pruned_at = position.copy()
        d = voxel_centres(self._voxel_keys, self.voxel_size_m) - position
        far = np.einsum("ij,ij->i", d, d) > self.max_distance_m**2
        if not far.any():
            return self.points[:0]
        _, drop = places_in_sorted(self._keys, self._voxel_keys[far])  # (faster than np.isin here)
        dropped_points = np.compress(drop, self.points, axis=0)
        self._voxel_keys, self._voxel_counts = self._voxel_keys[~far], self._voxel_counts[~far]
        kept = np.flatnonzero(~drop)
        self.points, self._keys, self._beams = (a.take(kept, axis=0) for a in (self.points, self._keys, self._beams))
        self._origins, self._elevations = self._origins.take(kept, axis=0), self._elevations.take(kept)
        self._normals, self._known, self._uncertain, self._reach = (
            a.take(kept, axis=0) for a in (self._normals, self._known, self._uncertain, self._reach))
        if self._payload is not None:
            self._payload = self._payload.take(kept)
        return dropped_points

    def _forget_normals_near(self, changed: np.ndarray) -> None:
        """Forget the cached normals whose neighbourhood ``changed`` (K, 3) points entered or left, m.

        A point's k nearest neighbours change exactly when a point arrives closer than the
        farthest of them, or one of them goes; both are within that reach. Called once the arrays
        changed: the rows of new points have no cached normal yet, dropped ones are gone.
        """
        rows = np.flatnonzero(self._known)
        if len(rows) == 0 or len(changed) == 0:
            return
        # (with a margin for rounding: the farthest neighbour itself may be the one that left)
        reach = self._reach[rows] * (1 + 1e-9)
        changed_keys = voxel_keys(changed, self.voxel_size_m)
        # A row reaching at most a voxel's edge can meet a changed point only in its voxel or one of the
        # 26 around it: those rows are checked against the changed points there (compiled, most rows
        # have no changed voxel around them); the farther-reaching (about a tenth in a city) are searched.
        short = reach <= self.voxel_size_m
        row_keys = self._keys.take(rows)
        near = short & keys_near(row_keys, changed_keys, _NEIGHBOUR_KEY_STEPS)
        forget = np.zeros(len(rows), dtype=bool)
        at = np.flatnonzero(near)
        forget[at] = within_reach_of_any(self.points.take(rows[at], axis=0), row_keys[at], reach[at],
                                         changed, changed_keys, _NEIGHBOUR_KEY_STEPS)
        far = np.flatnonzero(~short)
        if len(far):
            d, _ = KDTree(changed).query(self.points.take(rows[far], axis=0), k=1,
                                         distance_upper_bound=float(reach[far].max()))
            forget[far] = d <= reach[far]
        self._known[rows[forget]] = False

    def _count_in(self, keys: np.ndarray) -> None:
        """Add (K,) sorted voxel keys of points just inserted to the occupied voxels and their counts."""
        distinct, added = np.unique(keys, return_counts=True)
        pos, held = places_in_sorted(distinct, self._voxel_keys)
        self._voxel_counts[pos[held]] += added[held]
        # (new voxels go in at their sorted places: one copy of the map's voxels, no sort of them)
        fresh = ~held
        self._voxel_keys = np.insert(self._voxel_keys, pos[fresh], distinct[fresh])
        self._voxel_counts = np.insert(self._voxel_counts, pos[fresh], added[fresh])

    def target(self) -> Target:
        """The map as a registration target (world frame): a k-d tree over its points and
        normals estimated on demand for the matched points (nan where no plane)."""
        points, beams, origins, elevations = self.points, self._beams, self._origins, self._elevations
        reach = self._reach  # (the map's array: filled for the rows the ICP estimates)
        tree = self._tree.result()
        k = min(self.normal_neighbours, len(points))

        def normals_of(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
            if k < 3:
                return np.full((len(rows), 3), np.nan), None
            # (a normal's sign does not matter to a point-to-plane residual: r and J flip together)
            at = points.take(rows, axis=0)  # (take: numpy's fast gather of rows)
            nb = knn(points, at, k, tree=tree)
            # (compiled: ``plane_normals_valid``, ``spans_two_scan_lines`` and the NCF of
            # ``normal_covariance_along_beams`` in one pass over the neighbourhoods, as tested)
            mean, scatter, reach[rows] = gathered_scatter(points, nb, at)
            lam, V = symmetric_eigh_descending(scatter)
            n, variance = map_normal_verdicts(
                points, beams, elevations, origins, nb, at, mean, lam, V,
                (MIN_PLANE_EXTENT_SIGMAS * self.noise_std_m) ** 2, self.max_curvature, MIN_ELEVATION_SPREAD_RAD,
                MIN_BASELINE_M, self.noise_std_m**2, DEGENERATE_GAP,
                DEFAULT_GAP_SIGNIFICANCE_Z * math.sqrt(2.0 / max(k - 1, 1)))
            if self.ncf_c_tau_rad2 is None:
                return n, None
            return n, ~ncf_keep(variance, self.ncf_c_tau_rad2)

        return Target(points, tree, self._normals, normals_of, self._known,
                      self._uncertain if self.ncf_c_tau_rad2 is not None else None)

