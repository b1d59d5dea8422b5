"""Trajectory error metrics: KITTI relative error, the SALO paper's 100 m variant, ATE and RPE.

All functions take poses as ``(N, 4, 4)`` float64 ``T_world_lidar`` arrays
(ground truth ``T_gt`` and estimate ``T_est``, frame ``k`` of one matching frame
``k`` of the other) and work in metres and radians; degrees and per-cent appear
only in the names of the summary figures that carry them.

Definitions
-----------
KITTI relative error (the odometry devkit's ``evaluate_odometry.cpp``):
  * ``trajectory_distances``: cumulative GT path length, sum of the distances
    between consecutive GT positions.
  * Segments start at every ``step``-th frame (10, "every second" at 10 Hz)
    and have nominal lengths 100, 200, ..., 800 m; a segment ends at the first
    frame whose GT distance *exceeds* (strictly) the start's distance plus the
    length; segments running past the end of the sequence are dropped.
  * ``E = inv(inv(gt_a) gt_b) (inv(est_a) est_b)``: translational error
    ``||t(E)||`` and rotational error ``arccos(clamp(0.5 (trace(R(E)) - 1)))``,
    each divided by the *nominal* length. (The devkit composes the inverse,
    ``inv(est_rel) gt_rel``; both the norm and the angle of a transform equal
    those of its inverse, so the figures are the same.)
  * A figure over many sequences is the mean over *all* segments pooled, not a
    mean of per-sequence means. The devkit stores m/m and rad/m; here they are
    reported as % and deg / 100 m.
SALO paper (Sec. IV-B, Table I): the same segments restricted to 100 m, their
  translational error in metres per 100 m, mean and (population) standard
  deviation, per sequence and pooled overall.
ATE: RMSE of per-frame position differences, as given (no alignment: both
  trajectories in the same frame, e.g. both starting at identity) and after the
  rigid (SE(3), no scale) least-squares alignment of the estimate onto GT.
RPE: for frame pairs ``(i, i + delta)``, ``E = inv(gt_rel) est_rel``;
  translation ``||t(E)||`` (m) and rotation angle (rad; deg in summaries).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from simlidar import se3

KITTI_SEGMENT_LENGTHS_M: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
KITTI_STEP_FRAMES = 10
PAPER_SEGMENT_LENGTH_M = 100.0
_DEG_PER_100M_PER_RAD_PER_M = math.degrees(1.0) * 100.0


# ---------------------------------------------------------------- input checks
def _check_poses(T: np.ndarray, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"{name}: expected poses of shape (N, 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{name}: poses contain non-finite numbers")
    return T


def _check_pair(T_gt: np.ndarray, T_est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    T_gt, T_est = _check_poses(T_gt, "ground truth"), _check_poses(T_est, "estimate")
    if len(T_gt) != len(T_est):
        raise ValueError(
            f"ground truth has {len(T_gt)} poses but the estimate has {len(T_est)}; "
            "metrics need one estimated pose per ground-truth pose"
        )
    if len(T_gt) == 0:
        raise ValueError("no poses to evaluate")
    return T_gt, T_est


# ---------------------------------------------------------------- small statistics
@dataclass(frozen=True)
class ErrorStats:
    """Summary of a 1-D error sample (NaN everywhere when it is empty)."""

    count: int
    mean: float
    median: float
    rmse: float
    std: float
    max: float

    @classmethod
    def of(cls, values: np.ndarray) -> ErrorStats:
        """values: (M,) errors, any unit (the stats keep it)."""
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        if v.size == 0:
            nan = float("nan")
            return cls(0, nan, nan, nan, nan, nan)
        return cls(
            count=int(v.size),
            mean=float(v.mean()),
            median=float(np.median(v)),
            rmse=float(np.sqrt(np.mean(v**2))),
            std=float(v.std()),
            max=float(v.max()),
        )


def _concatenate(cls, parts):
    """Concatenate every (array) field of dataclass instances."""
    return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)})


def _json_float(x: float) -> float | None:
    """JSON has no NaN: a figure that does not exist (too short a sequence) becomes null."""
    return float(x) if math.isfinite(x) else None


# ---------------------------------------------------------------- KITTI segments
def trajectory_distances(T_gt: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses -> (N,) cumulative path length in metres (0 at frame 0)."""
    p = np.asarray(T_gt)[:, :3, 3]
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def last_frame_from_segment_length(dist: np.ndarray, first_frame: int, length_m: float) -> int:
    """First frame whose distance exceeds ``dist[first_frame] + length_m``, or -1 if none.

    dist: (N,) non-decreasing cumulative distances (``trajectory_distances``), m.
    Strictly greater, as in the devkit: at 1 m spacing a 100 m segment from
    frame 0 ends at frame 101.
    """
    k = int(np.searchsorted(dist, dist[first_frame] + length_m, side="right"))
    return k if k < len(dist) else -1


@dataclass(frozen=True, eq=False)
class SegmentErrors:
    """Per-segment relative errors of the KITTI protocol (M segments, maybe 0).

    first_frame, last_frame: (M,) int frame indices of the segment ends.
    length_m: (M,) nominal segment length (100, 200, ... m), the divisor.
    t_err_m: (M,) ``||t(E)||``, m.  r_err_rad: (M,) rotation angle of E, rad.
    Ordered as the devkit writes them: by first frame, then by length.
    """

    first_frame: np.ndarray
    last_frame: np.ndarray
    length_m: np.ndarray
    t_err_m: np.ndarray
    r_err_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.length_m)

    @property
    def t_err_ratio(self) -> np.ndarray:
        """(M,) translational error per metre of nominal length (the devkit's t_err), m/m."""
        return self.t_err_m / self.length_m

    @property
    def r_err_rad_per_m(self) -> np.ndarray:
        """(M,) rotational error per metre of nominal length (the devkit's r_err), rad/m."""
        return self.r_err_rad / self.length_m

    def with_length(self, length_m: float) -> SegmentErrors:
        """The segments of one nominal length."""
        keep = np.abs(self.length_m - length_m) < 1e-6
        return SegmentErrors(**{f.name: getattr(self, f.name)[keep] for f in fields(self)})

    @classmethod
    def concatenate(cls, parts: Sequence[SegmentErrors]) -> SegmentErrors:
        """Pool segments of several sequences (frame indices stay per sequence)."""
        return _concatenate(cls, parts) if parts else cls.empty()

    @classmethod
    def empty(cls) -> SegmentErrors:
        i, f = np.zeros(0, dtype=np.int64), np.zeros(0)
        return cls(i, i, f, f, f)


def kitti_segment_errors(
    T_gt: np.ndarray,
    T_est: np.ndarray,
    lengths_m: Sequence[float] = KITTI_SEGMENT_LENGTHS_M,
    step_frames: int = KITTI_STEP_FRAMES,
) -> SegmentErrors:
    """Relative errors of all KITTI segments of one sequence.

    T_gt, T_est: (N, 4, 4) poses. lengths_m: nominal segment lengths, m,
    measured along the GT path. step_frames: spacing of the first frames.
    Returns no segments (not an error) when the GT path is shorter than every length.
    """
    T_gt, T_est = _check_pair(T_gt, T_est)
    if step_frames < 1:
        raise ValueError(f"step_frames must be >= 1, got {step_frames}")
    dist = trajectory_distances(T_gt)
    first = np.arange(0, len(T_gt), step_frames)
    lengths = np.asarray(lengths_m, dtype=np.float64)
    # Every (first frame, length) pair, first-frame-major like the devkit's loops.
    a = np.repeat(first, len(lengths))
    L = np.tile(lengths, len(first))
    b = np.searchsorted(dist, dist[a] + L, side="right")
    ok = b < len(dist)
    a, b, L = a[ok], b[ok], L[ok]
    if len(a) == 0:
        return SegmentErrors.empty()
    gt_rel = se3.inverse(T_gt[a]) @ T_gt[b]
    est_rel = se3.inverse(T_est[a]) @ T_est[b]
    E = se3.inverse(gt_rel) @ est_rel
    return SegmentErrors(
        first_frame=a.astype(np.int64),
        last_frame=b.astype(np.int64),
        length_m=L,
        t_err_m=np.linalg.norm(E[:, :3, 3], axis=1),
        # The devkit's arccos of the clamped 0.5 (trace - 1).
        r_err_rad=se3.rotation_angle(E),
    )


@dataclass(frozen=True)
class LengthSummary:
    """KITTI errors averaged over the segments of one nominal length (the site's error plots)."""

    length_m: float
    count: int
    t_err_pct: float
    r_err_deg_per_100m: float


def per_length_summary(
    segments: SegmentErrors, lengths_m: Sequence[float] = KITTI_SEGMENT_LENGTHS_M
) -> list[LengthSummary]:
    """Mean errors per nominal length (NaN where a length has no segment)."""
    out = []
    for L in lengths_m:
        s = segments.with_length(L)
        out.append(
            LengthSummary(
                length_m=float(L),
                count=len(s),
                t_err_pct=_mean(s.t_err_ratio) * 100.0,
                r_err_deg_per_100m=_mean(s.r_err_rad_per_m) * _DEG_PER_100M_PER_RAD_PER_M,
            )
        )
    return out


def _mean(v: np.ndarray) -> float:
    return float(np.mean(v)) if len(v) else float("nan")


# ---------------------------------------------------------------- ATE
def align_se3(p_est: np.ndarray, p_gt: np.ndarray) -> np.ndarray:
    """Rigid least-squares alignment (Umeyama / Horn, no scale) of estimated positions onto GT.

    p_est, p_gt: (N, 3) positions, m. Returns ``T_gt_est`` (4, 4) minimising
    ``sum ||p_gt - (R p_est + t)||^2``. With fewer than three non-collinear
    points the rotation is not unique, but the minimum (and so the RMSE) is.
    """
    p_est, p_gt = np.asarray(p_est, dtype=np.float64), np.asarray(p_gt, dtype=np.float64)
    mu_est, mu_gt = p_est.mean(axis=0), p_gt.mean(axis=0)
    H = (p_gt - mu_gt).T @ (p_est - mu_est)
    U, _, Vt = np.linalg.svd(H)
    # A reflection would fit better when the points are nearly planar; forbid it.
    D = np.diag([1.0, 1.0, -1.0 if np.linalg.det(U @ Vt) < 0 else 1.0])
    R = U @ D @ Vt
    return se3.make(R, mu_gt - R @ mu_est)


@dataclass(frozen=True, eq=False)
class AbsoluteErrors:
    """Per-frame position errors of one sequence.

    errors_m: (N,) ``||p_gt - p_est||`` without alignment, m.
    aligned_errors_m: (N,) the same after ``T_gt_est`` is applied to the estimate, m.
    T_gt_est: (4, 4) the rigid alignment.
    """

    errors_m: np.ndarray
    aligned_errors_m: np.ndarray
    T_gt_est: np.ndarray


def absolute_trajectory_errors(T_gt: np.ndarray, T_est: np.ndarray) -> AbsoluteErrors:
    """ATE per frame, unaligned and SE(3)-aligned. T_gt, T_est: (N, 4, 4)."""
    T_gt, T_est = _check_pair(T_gt, T_est)
    p_gt, p_est = T_gt[:, :3, 3], T_est[:, :3, 3]
    T_gt_est = align_se3(p_est, p_gt)
    aligned = se3.transform_points(T_gt_est, p_est)
    return AbsoluteErrors(
        errors_m=np.linalg.norm(p_gt - p_est, axis=1),
        aligned_errors_m=np.linalg.norm(p_gt - aligned, axis=1),
        T_gt_est=T_gt_est,
    )


# ---------------------------------------------------------------- RPE
@dataclass(frozen=True, eq=False)
class RelativePoseErrors:
    """Per-pair relative pose errors (M pairs, maybe 0).

    first_frame, last_frame: (M,) frame indices ``i`` and ``i + delta``.
    t_err_m: (M,) ``||t(E)||``, m.  r_err_rad: (M,) rotation angle of E, rad.
    """

    first_frame: np.ndarray
    last_frame: np.ndarray
    t_err_m: np.ndarray
    r_err_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.t_err_m)

    @property
    def t_stats_m(self) -> ErrorStats:
        return ErrorStats.of(self.t_err_m)

    @property
    def r_stats_deg(self) -> ErrorStats:
        return ErrorStats.of(np.degrees(self.r_err_rad))

    @classmethod
    def concatenate(cls, parts: Sequence[RelativePoseErrors]) -> RelativePoseErrors:
        if not parts:
            i, f = np.zeros(0, dtype=np.int64), np.zeros(0)
            return cls(i, i, f, f)
        return _concatenate(cls, parts)


def relative_pose_errors(
    T_gt: np.ndarray, T_est: np.ndarray, delta_frames: int = 1, all_pairs: bool = True
) -> RelativePoseErrors:
    """RPE over frame pairs ``(i, i + delta_frames)``.

    T_gt, T_est: (N, 4, 4). all_pairs: every ``i`` (overlapping pairs); else
    ``i = 0, delta, 2 delta, ...`` (evo's default "consecutive pairs"). Both
    are the same for ``delta_frames == 1``.
    """
    T_gt, T_est = _check_pair(T_gt, T_est)
    if delta_frames < 1:
        raise ValueError(f"delta_frames must be >= 1, got {delta_frames}")
    i = np.arange(0, len(T_gt) - delta_frames, 1 if all_pairs else delta_frames)
    j = i + delta_frames
    gt_rel = se3.inverse(T_gt[i]) @ T_gt[j]
    est_rel = se3.inverse(T_est[i]) @ T_est[j]
    E = se3.inverse(gt_rel) @ est_rel
    # Per-frame rotation errors are tiny, where arccos of the trace loses digits;
    # scipy's quaternion route keeps them.
    from scipy.spatial.transform import Rotation  # (not at import: start-up)

    r = Rotation.from_matrix(E[:, :3, :3]).magnitude() if len(E) else np.zeros(0)
    return RelativePoseErrors(i, j, np.linalg.norm(E[:, :3, 3], axis=1), np.asarray(r))


# ---------------------------------------------------------------- the result
@dataclass(frozen=True, eq=False)
class TrajectoryMetrics:
    """All error figures of one sequence, or of several pooled (``pool``).

    Holds the per-item errors; the summary figures are properties computed from
    them, so pooling is concatenation and pooled figures weigh every segment,
    pair and frame equally (the devkit's overall figure).

    sequences: number of sequences pooled (1 for one sequence).
    frames: total frames.  path_length_m: total GT path length, m.
    segments: KITTI segments (all lengths).  rpe: per-pair errors.
    rpe_delta_frames: the pair spacing of ``rpe``.
    ate_errors_m, ate_aligned_errors_m: (frames,) per-frame position errors, m.
    alignments_T_gt_est: (sequences, 4, 4) the rigid alignment of each sequence.
    lengths_m: the nominal segment lengths evaluated.
    """

    sequences: int
    frames: int
    path_length_m: float
    segments: SegmentErrors
    rpe: RelativePoseErrors
    rpe_delta_frames: int
    ate_errors_m: np.ndarray
    ate_aligned_errors_m: np.ndarray
    alignments_T_gt_est: np.ndarray
    lengths_m: tuple[float, ...] = field(default=KITTI_SEGMENT_LENGTHS_M)

    # -- KITTI (devkit) figures
    @property
    def t_err_pct(self) -> float:
        """Mean translational error over all segments, % (NaN without segments)."""
        return _mean(self.segments.t_err_ratio) * 100.0

    @property
    def r_err_rad_per_m(self) -> float:
        """Mean rotational error over all segments, rad/m, the devkit's stored unit."""
        return _mean(self.segments.r_err_rad_per_m)

    @property
    def r_err_deg_per_100m(self) -> float:
        """Mean rotational error over all segments, deg / 100 m."""
        return self.r_err_rad_per_m * _DEG_PER_100M_PER_RAD_PER_M

    @property
    def per_length(self) -> list[LengthSummary]:
        return per_length_summary(self.segments, self.lengths_m)

    # -- the SALO paper's 100 m figures
    @property
    def t100_errors_m(self) -> np.ndarray:
        """(M,) translational error of each 100 m segment, metres per 100 m."""
        s = self.segments.with_length(PAPER_SEGMENT_LENGTH_M)
        return s.t_err_ratio * 100.0

    @property
    def t100_mean_m(self) -> float:
        return _mean(self.t100_errors_m)

    @property
    def t100_std_m(self) -> float:
        """Population standard deviation (ddof 0) of the 100 m errors, m."""
        v = self.t100_errors_m
        return float(np.std(v)) if len(v) else float("nan")

    # -- ATE / RPE
    @property
    def ate_rmse_m(self) -> float:
        return ErrorStats.of(self.ate_errors_m).rmse

    @property
    def ate_aligned_rmse_m(self) -> float:
        return ErrorStats.of(self.ate_aligned_errors_m).rmse

    @property
    def has_relative_errors(self) -> bool:
        """False when the GT path is too short for any segment (the KITTI figures are NaN)."""
        return len(self.segments) > 0

    @classmethod
    def pool(cls, parts: Sequence[TrajectoryMetrics]) -> TrajectoryMetrics:
        """Pool sequences: every segment, pair and frame counts once."""
        if not parts:
            raise ValueError("no sequences to pool")
        deltas = {p.rpe_delta_frames for p in parts}
        lengths = {p.lengths_m for p in parts}
        if len(deltas) > 1 or len(lengths) > 1:
            raise ValueError("cannot pool metrics computed with different RPE deltas or segment lengths")
        return cls(
            sequences=sum(p.sequences for p in parts),
            frames=sum(p.frames for p in parts),
            path_length_m=float(sum(p.path_length_m for p in parts)),
            segments=SegmentErrors.concatenate([p.segments for p in parts]),
            rpe=RelativePoseErrors.concatenate([p.rpe for p in parts]),
            rpe_delta_frames=parts[0].rpe_delta_frames,
            ate_errors_m=np.concatenate([p.ate_errors_m for p in parts]),
            ate_aligned_errors_m=np.concatenate([p.ate_aligned_errors_m for p in parts]),
            alignments_T_gt_est=np.concatenate([p.alignments_T_gt_est for p in parts]),
            lengths_m=parts[0].lengths_m,
        )

    def to_dict(self) -> dict:
        """JSON-ready summary (plain floats and ints; a figure that does not exist is None).

        Units are in the key names; ``r_err_deg_per_100m`` is the devkit's rad/m
        times 180/pi times 100 (also given as ``r_err_rad_per_m``).
        """
        ate, ate_al = ErrorStats.of(self.ate_errors_m), ErrorStats.of(self.ate_aligned_errors_m)
        rpe_t, rpe_r = self.rpe.t_stats_m, self.rpe.r_stats_deg
        j = _json_float
        return {
            "sequences": self.sequences,
            "frames": self.frames,
            "path_length_m": j(self.path_length_m),
            # KITTI devkit protocol
            "t_err_pct": j(self.t_err_pct),
            "r_err_deg_per_100m": j(self.r_err_deg_per_100m),
            "r_err_rad_per_m": j(self.r_err_rad_per_m),
            "segments": len(self.segments),
            "segment_counts": {f"{s.length_m:g}": s.count for s in self.per_length},
            "per_length": [
                {
                    "length_m": s.length_m,
                    "count": s.count,
                    "t_err_pct": j(s.t_err_pct),
                    "r_err_deg_per_100m": j(s.r_err_deg_per_100m),
                }
                for s in self.per_length
            ],
            # SALO paper, Table I
            "t100_mean_m": j(self.t100_mean_m),
            "t100_std_m": j(self.t100_std_m),
            "t100_count": len(self.t100_errors_m),
            # ATE
            "ate_rmse_m": j(ate.rmse),
            "ate_mean_m": j(ate.mean),
            "ate_max_m": j(ate.max),
            "ate_aligned_rmse_m": j(ate_al.rmse),
            "ate_aligned_mean_m": j(ate_al.mean),
            "ate_aligned_max_m": j(ate_al.max),
            # RPE
            "rpe_delta_frames": self.rpe_delta_frames,
            "rpe_pairs": len(self.rpe),
            "rpe_t_mean_m": j(rpe_t.mean),
            "rpe_t_median_m": j(rpe_t.median),
            "rpe_t_rmse_m": j(rpe_t.rmse),
            "rpe_r_mean_deg": j(rpe_r.mean),
            "rpe_r_median_deg": j(rpe_r.median),
            "rpe_r_rmse_deg": j(rpe_r.rmse),
        }


def evaluate_trajectory(
    T_gt: np.ndarray,
    T_est: np.ndarray,
    *,
    lengths_m: Sequence[float] = KITTI_SEGMENT_LENGTHS_M,
    step_frames: int = KITTI_STEP_FRAMES,
    rpe_delta_frames: int = 1,
) -> TrajectoryMetrics:
    """Every metric of one sequence. T_gt, T_est: (N, 4, 4) poses, same frame, same N.

    Too short a sequence for any segment gives NaN KITTI and 100 m figures
    (``has_relative_errors`` is False); ATE and RPE are still computed.
    """
    T_gt, T_est = _check_pair(T_gt, T_est)
    ate = absolute_trajectory_errors(T_gt, T_est)
    return TrajectoryMetrics(
        sequences=1,
        frames=len(T_gt),
        path_length_m=float(trajectory_distances(T_gt)[-1]),
        segments=kitti_segment_errors(T_gt, T_est, lengths_m, step_frames),
        rpe=relative_pose_errors(T_gt, T_est, rpe_delta_frames),
        rpe_delta_frames=rpe_delta_frames,
        ate_errors_m=ate.errors_m,
        ate_aligned_errors_m=ate.aligned_errors_m,
        alignments_T_gt_est=ate.T_gt_est[None],
        lengths_m=tuple(float(x) for x in lengths_m),
    )


@dataclass(frozen=True, eq=False)
class SuiteMetrics:
    """Per-sequence metrics and the pooled overall figures of a suite of sequences."""

    sequences: dict[str, TrajectoryMetrics]
    overall: TrajectoryMetrics

    def to_dict(self) -> dict:
        return {
            "sequences": {name: m.to_dict() for name, m in self.sequences.items()},
            "overall": self.overall.to_dict(),
        }


def evaluate_suite(pairs: Mapping[str, tuple[np.ndarray, np.ndarray]], **kwargs) -> SuiteMetrics:
    """Evaluate sequences ``name -> (T_gt, T_est)`` and pool them (kwargs: ``evaluate_trajectory``'s)."""
    per = {name: evaluate_trajectory(gt, est, **kwargs) for name, (gt, est) in pairs.items()}
    return SuiteMetrics(per, TrajectoryMetrics.pool(list(per.values())))


__all__ = [
    "KITTI_SEGMENT_LENGTHS_M",
    "KITTI_STEP_FRAMES",
    "AbsoluteErrors",
    "ErrorStats",
    "LengthSummary",
    "RelativePoseErrors",
    "SegmentErrors",
    "SuiteMetrics",
    "TrajectoryMetrics",
    "absolute_trajectory_errors",
    "align_se3",
    "evaluate_suite",
    "evaluate_trajectory",
    "kitti_segment_errors",
    "last_frame_from_segment_length",
    "per_length_summary",
    "relative_pose_errors",
    "trajectory_distances",
]
