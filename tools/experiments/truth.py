"""True correspondences between two simulated scans, from the simulator's per-point truth.

The simulator records, for every return, the object it hit (``object_id``), the
noise-free hit point (``true_xyz``) and the surface's true normal (``normal``),
both in the sweep-start frame of that scan (undistorted). An ICP point is a
raw return or a voxel centroid; it stands for the raw return nearest to it
(its *anchor*), whose truth it takes.

Definition. A correspondence (source point p, target point q), with anchors
a_p and a_q and the true relative pose ``T = T_target_source``, is **true**
when all three hold:

1. same object: ``object_id(a_p) == object_id(a_q)``;
2. same surface: the angle between ``R n(a_p)`` and ``n(a_q)`` is below
   ``max_normal_angle_deg`` (15 deg: excludes the other face of the same
   building, kerb versus road, while tolerating a tessellated trunk's facets);
3. on the plane: the point-to-plane residual the match would contribute at
   the true pose, computed from noise-free positions,
   ``|n(a_q) . (T x(a_p) - x(a_q))|``, is below ``max_plane_distance_m``, a few
   range-noise sigmas (3 sigma = 6 cm for the 2 cm sensor).

In words: at the true pose the match constrains the registration correctly,
up to the sensor's noise. It does not require the two points to be the same
spot on the surface: point-to-plane ICP needs only the same plane, so a match
anywhere on the same flat wall is true, while one across a curved surface
fails test 3 and one onto a neighbouring object fails test 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simlidar import se3

DEFAULT_NOISE_SIGMAS = 3.0
DEFAULT_MAX_NORMAL_ANGLE_DEG = 15.0


@dataclass(frozen=True)
class PointTruth:
    """The truth of M ICP points (that of their anchors).

    object_id: (M,) int. true_xyz: (M, 3) noise-free position, the scan's
    sweep-start frame, m. normal: (M, 3) unit surface normal, same frame.
    anchor_distance_m: (M,) distance from each ICP point to its anchor, m.
    """

    object_id: np.ndarray
    true_xyz: np.ndarray
    normal: np.ndarray
    anchor_distance_m: np.ndarray

    def __len__(self) -> int:
        return len(self.object_id)

    def take(self, rows: np.ndarray) -> PointTruth:
        """The truth of the points at ``rows`` (K,) indices."""
        rows = np.asarray(rows)
        return PointTruth(self.object_id[rows], self.true_xyz[rows], self.normal[rows], self.anchor_distance_m[rows])

    def transformed(self, T: np.ndarray) -> PointTruth:
        """The same truth in another frame: positions and normals moved by ``T`` (4, 4), e.g. a scan's
        ``T_world_scan``."""
        return PointTruth(self.object_id, se3.transform_points(T, self.true_xyz), self.normal @ T[:3, :3].T,
                          self.anchor_distance_m)


def concatenate_truth(parts: list[PointTruth]) -> PointTruth:
    """One ``PointTruth`` of the points of ``parts`` in order (all in one frame)."""
    if not parts:
        return PointTruth(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    return PointTruth(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in ("object_id", "true_xyz", "normal", "anchor_distance_m")))


@dataclass(frozen=True)
class TruthCriteria:
    """Thresholds of the definition (module notes): plane distance, m; normal angle, deg."""

    max_plane_distance_m: float
    max_normal_angle_deg: float = DEFAULT_MAX_NORMAL_ANGLE_DEG

    @classmethod
    def for_noise(cls, range_noise_std_m: float, sigmas: float = DEFAULT_NOISE_SIGMAS,
                  max_normal_angle_deg: float = DEFAULT_MAX_NORMAL_ANGLE_DEG) -> TruthCriteria:
        """``sigmas`` range-noise standard deviations (at least 1 cm, for noise-free scans)."""
        return cls(max(sigmas * range_noise_std_m, 0.01), max_normal_angle_deg)


def truth_of_rows(sidecar: np.ndarray, rows: np.ndarray) -> PointTruth:
    """The truth of raw returns themselves: ``sidecar`` (N,) structured, ``rows`` (M,) indices."""
    rows = np.asarray(rows)
    return PointTruth(
        object_id=np.asarray(sidecar["object_id"][rows], dtype=np.int64),
        true_xyz=np.asarray(sidecar["true_xyz"][rows], dtype=np.float64),
        normal=np.asarray(sidecar["normal"][rows], dtype=np.float64),
        anchor_distance_m=np.zeros(len(rows)),
    )


def truth_of_points(points: np.ndarray, raw_tree, raw_rows: np.ndarray, sidecar: np.ndarray) -> PointTruth:
    """The truth of ICP points (e.g. voxel centroids) from their nearest raw return.

    points: (M, 3) in the frame of the raw points the tree holds, m.
    raw_tree: k-d tree (``odometry.kdtree.KDTree`` or scipy's) over the (N', 3) raw points
        the ICP points were made from.
    raw_rows: (N',) sidecar row of each of those raw points (after range cleaning).
    sidecar: the frame's structured per-point record (``simlidar.sweep.SIDECAR_DTYPE``).
    """
    dist, idx = raw_tree.query(points, k=1)
    t = truth_of_rows(sidecar, np.asarray(raw_rows)[idx])
    return PointTruth(t.object_id, t.true_xyz, t.normal, np.asarray(dist, dtype=np.float64))


def true_matches(source: PointTruth, target: PointTruth, source_index: np.ndarray, target_index: np.ndarray,
                 T_target_source: np.ndarray, criteria: TruthCriteria) -> np.ndarray:
    """(m,) bool: which of the m correspondences ``(source_index, target_index)`` are true.

    T_target_source: (4, 4) the true pose of the source scan in the target scan's frame.
    """
    si, ti = np.asarray(source_index), np.asarray(target_index)
    same_object = source.object_id[si] == target.object_id[ti]
    R = T_target_source[:3, :3]
    n_s = source.normal[si] @ R.T
    n_t = target.normal[ti]
    cos_min = math.cos(math.radians(criteria.max_normal_angle_deg))
    # Surfaces face the sensor in both scans, so their normals agree in sign too.
    same_surface = np.einsum("ij,ij->i", n_s, n_t) > cos_min
    x_s = se3.transform_points(T_target_source, source.true_xyz[si])
    residual = np.abs(np.einsum("ij,ij->i", n_t, x_s - target.true_xyz[ti]))
    return same_object & same_surface & (residual < criteria.max_plane_distance_m)
