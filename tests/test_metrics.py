"""Trajectory metrics against constructed truth, the devkit's conventions, and evo."""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from odometry import metrics as M
from simlidar import se3
from simlidar.formats.kitti import format_kitti_poses, read_kitti_poses
from simlidar.sequence import DatasetError

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- trajectory builders
def compose(increments: np.ndarray) -> np.ndarray:
    """(N-1, 4, 4) body-frame increments -> (N, 4, 4) poses starting at identity."""
    T = [np.eye(4)]
    for d in increments:
        T.append(T[-1] @ d)
    return np.array(T)


def straight_line(n: int, step_m: float = 1.0) -> np.ndarray:
    """n poses along +x, step_m apart (1 m: cumulative distances are exact integers)."""
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 0, 3] = step_m * np.arange(n)
    return T


def smooth_twists(n: int, seed: int, speed_m: float = 1.0) -> np.ndarray:
    """(n-1, 6) per-frame twists of a car-like 3-D drive: smooth yaw, gentle pitch/roll, some heave."""
    rng = np.random.default_rng(seed)
    k = np.arange(n - 1)[:, None]
    xi = np.zeros((n - 1, 6))
    xi[:, 0] = speed_m * (1 + 0.2 * np.sin(k[:, 0] / 37.0 + rng.uniform(0, 6)))
    for axis, amp in ((5, 0.02), (4, 0.002), (3, 0.002), (1, 0.01), (2, 0.005)):
        freq = rng.uniform(1 / 80, 1 / 15, size=3)
        phase = rng.uniform(0, 2 * np.pi, size=3)
        xi[:, axis] = amp * np.sin(k * freq + phase).sum(axis=1) / 3
    return xi


def curved_drive(n: int, seed: int = 0, speed_m: float = 1.0) -> np.ndarray:
    return compose(se3.exp(smooth_twists(n, seed, speed_m)))


def noisy_estimate(T_gt: np.ndarray, seed: int, t_std_m: float = 0.01, r_std_rad: float = 5e-4) -> np.ndarray:
    """An odometry-like estimate: the GT increments with random errors, re-integrated (it drifts)."""
    rng = np.random.default_rng(seed)
    inc = se3.inverse(T_gt[:-1]) @ T_gt[1:]
    noise = np.concatenate(
        [rng.normal(0, t_std_m, (len(inc), 3)), rng.normal(0, r_std_rad, (len(inc), 3))], axis=1
    )
    noise[:, 5] += 2e-4  # a yaw bias, so the estimate drifts like real odometry
    return compose(inc @ se3.exp(noise))


def path_distances(T: np.ndarray) -> np.ndarray:
    """Cumulative path length, written out here rather than taken from the code under test."""
    p = T[:, :3, 3]
    return np.concatenate([[0.0], np.cumsum(np.sqrt(((p[1:] - p[:-1]) ** 2).sum(axis=1)))])


# ---------------------------------------------------------------- devkit conventions
def test_segment_end_is_first_frame_strictly_beyond_the_length():
    dist = np.arange(300, dtype=float)
    # Strictly greater, as the devkit: at 1 m spacing a 100 m segment from frame 0 ends at 101.
    assert M.last_frame_from_segment_length(dist, 0, 100.0) == 101
    assert M.last_frame_from_segment_length(dist, 10, 100.0) == 111
    assert M.last_frame_from_segment_length(dist, 198, 100.0) == 299
    assert M.last_frame_from_segment_length(dist, 199, 100.0) == -1
    uneven = np.array([0.0, 50.0, 99.9, 100.0, 100.1])
    assert M.last_frame_from_segment_length(uneven, 0, 100.0) == 4
    assert M.last_frame_from_segment_length(uneven, 1, 100.0) == -1


def test_segments_start_every_tenth_frame_and_end_where_the_devkit_says():
    T = straight_line(1001)
    seg = M.kitti_segment_errors(T, T)
    assert set(seg.first_frame % 10) == {0}
    np.testing.assert_array_equal(seg.last_frame, seg.first_frame + seg.length_m.astype(int) + 1)
    # Hand count: a segment of L from frame a exists iff a + L + 1 <= 1000.
    expected = {L: len(range(0, 1000 - int(L), 10)) for L in M.KITTI_SEGMENT_LENGTHS_M}
    assert expected[100.0] == 90 and expected[800.0] == 20
    assert {s.length_m: s.count for s in M.per_length_summary(seg)} == expected
    # Ordered as the devkit writes them: by first frame, then by length.
    assert np.all(np.diff(seg.first_frame) >= 0)


def test_trajectory_distances_sum_position_steps():
    T = curved_drive(400, seed=3)
    np.testing.assert_allclose(M.trajectory_distances(T), path_distances(T), rtol=1e-12)


# ---------------------------------------------------------------- known answers
def test_identical_trajectories_give_zero_everywhere():
    T = curved_drive(1200, seed=1)
    m = M.evaluate_trajectory(T, T)
    assert m.has_relative_errors and len(m.segments) > 100
    for value in (m.t_err_pct, m.r_err_deg_per_100m, m.t100_mean_m, m.t100_std_m,
                  m.ate_rmse_m, m.ate_aligned_rmse_m, m.rpe.t_stats_m.max, m.rpe.r_stats_deg.max):
        assert value == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("x_pct", [0.5, 2.0, 5.0])
def test_scale_drift_on_a_straight_line_gives_x_percent(x_pct):
    gt = straight_line(1001)
    est = gt.copy()
    est[:, :3, 3] *= 1 + x_pct / 100
    m = M.evaluate_trajectory(gt, est)
    seg = m.segments
    # The devkit divides by the nominal length while the segment runs one frame
    # (here 1 m) past it: the exact figure is x (L + 1) / L.
    np.testing.assert_allclose(seg.t_err_ratio * 100, x_pct * (seg.length_m + 1) / seg.length_m, rtol=1e-9)
    assert m.t_err_pct == pytest.approx(x_pct, rel=0.011)
    assert m.r_err_deg_per_100m == pytest.approx(0.0, abs=1e-9)
    assert m.t100_mean_m == pytest.approx(x_pct * 1.01, rel=1e-9)
    assert m.t100_std_m == pytest.approx(0.0, abs=1e-9)


def test_drift_of_x_percent_along_a_curved_3d_path():
    # The error grows by x % of the distance travelled, in a fixed world
    # direction: every segment's error is then x % of its GT length, however
    # the path turns.
    x_pct = 1.5
    gt = curved_drive(1500, seed=2)
    dist = path_distances(gt)
    u = np.array([0.3, -0.8, 0.52])
    u /= np.linalg.norm(u)
    est = gt.copy()
    est[:, :3, 3] += (x_pct / 100) * dist[:, None] * u
    m = M.evaluate_trajectory(gt, est)
    seg = m.segments
    heading = np.degrees(np.ptp(np.unwrap(np.arctan2(gt[:, 1, 0], gt[:, 0, 0]))))
    assert heading > 60, "the test path should actually turn"
    assert len(seg) > 300
    actual = dist[seg.last_frame] - dist[seg.first_frame]
    np.testing.assert_allclose(seg.t_err_m, x_pct / 100 * actual, rtol=1e-9)
    assert m.t_err_pct == pytest.approx(x_pct, rel=0.02)
    assert m.r_err_deg_per_100m == pytest.approx(0.0, abs=1e-6)


def test_scale_error_on_a_curve_is_measured_on_the_chord():
    # A property of the devkit's definition (worth knowing when reading its
    # figures): a pure scale error is seen through the segment's end-to-end
    # displacement, not its arc length, so it reads below x % on curves.
    gt = curved_drive(1000, seed=4)
    est = gt.copy()
    est[:, :3, 3] *= 1.03
    seg = M.kitti_segment_errors(gt, est)
    chord = np.linalg.norm(gt[seg.last_frame, :3, 3] - gt[seg.first_frame, :3, 3], axis=1)
    np.testing.assert_allclose(seg.t_err_m, 0.03 * chord, rtol=1e-9)


def test_constant_yaw_rate_error_gives_its_rotational_error():
    # GT turns at w rad per frame (1 m per frame); the estimate at w + dw, so
    # after n frames its heading is off by dw n.
    n, w, dw = 1200, 0.004, 2e-4
    twist = np.zeros((n - 1, 6))
    twist[:, 0], twist[:, 5] = 1.0, w
    gt = compose(se3.exp(twist))
    twist[:, 5] = w + dw
    est = compose(se3.exp(twist))
    seg = M.kitti_segment_errors(gt, est)
    np.testing.assert_allclose(seg.r_err_rad, dw * (seg.last_frame - seg.first_frame), rtol=1e-6)
    step_m = 2 * math.sin(w / 2) / w  # the chord of one frame's arc
    m = M.evaluate_trajectory(gt, est)
    assert m.r_err_deg_per_100m == pytest.approx(math.degrees(dw / step_m) * 100, rel=0.012)
    assert m.r_err_rad_per_m == pytest.approx(m.r_err_deg_per_100m / (math.degrees(1) * 100))


def test_ate_of_a_rigidly_moved_estimate():
    gt = curved_drive(600, seed=5)
    offset = np.array([3.0, -4.0, 12.0])  # 13 m
    shifted = gt.copy()
    shifted[:, :3, 3] += offset
    m = M.evaluate_trajectory(gt, shifted)
    assert m.ate_rmse_m == pytest.approx(13.0, rel=1e-12)
    assert m.ate_aligned_rmse_m == pytest.approx(0.0, abs=1e-9)
    # A full rigid motion: the unaligned error is each position's displacement.
    T_off = se3.exp(np.array([2.0, -1.0, 0.5, 0.05, -0.02, 0.4]))
    moved = T_off @ gt
    m = M.evaluate_trajectory(gt, moved)
    disp = np.linalg.norm(moved[:, :3, 3] - gt[:, :3, 3], axis=1)
    assert m.ate_rmse_m == pytest.approx(np.sqrt(np.mean(disp**2)), rel=1e-12)
    assert m.ate_aligned_rmse_m == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(m.alignments_T_gt_est[0], se3.inverse(T_off), atol=1e-9)
    # Relative errors do not see a common rigid motion of the whole estimate.
    assert m.t_err_pct == pytest.approx(0.0, abs=1e-9)
    assert m.rpe.t_stats_m.max == pytest.approx(0.0, abs=1e-9)


def test_alignment_is_a_rotation_even_when_a_mirror_image_would_fit():
    gt = curved_drive(300, seed=6)
    mirrored = gt[:, :3, 3] * np.array([1.0, -1.0, 1.0])  # 3-D: no rotation maps it back
    T = M.align_se3(mirrored, gt[:, :3, 3])
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    residual = gt[:, :3, 3] - se3.transform_points(T, mirrored)
    assert np.sqrt(np.mean(np.sum(residual**2, axis=1))) > 0.1
    # Same positions: the identity.
    np.testing.assert_allclose(M.align_se3(gt[:, :3, 3], gt[:, :3, 3]), np.eye(4), atol=1e-9)


def test_the_papers_100m_mean_and_std():
    # A straight 999 m drive whose error grows at 1 m per 100 m for the first
    # 500 m and 3 m per 100 m after, sideways. 100 m segments run 101 frames:
    # 40 wholly in the first part (1.01 m each), 40 wholly in the second
    # (3.03 m), and 10 straddling from frames 400, 410, ..., 490 whose error is
    # 0.01 (500 - a) + 0.03 (a + 101 - 500) = 1.03 + 0.2 k.
    gt = straight_line(1000)
    k = np.arange(1000)
    drift = 0.01 * np.minimum(k, 500) + 0.03 * np.maximum(k - 500, 0)
    est = gt.copy()
    est[:, 1, 3] += drift
    m = M.evaluate_trajectory(gt, est)
    expected = np.array([1.01] * 40 + [1.03 + 0.2 * j for j in range(10)] + [3.03] * 40)
    assert len(m.t100_errors_m) == 90
    np.testing.assert_allclose(np.sort(m.t100_errors_m), np.sort(expected), rtol=1e-9)
    assert m.t100_mean_m == pytest.approx(2.01, rel=1e-12)
    assert m.t100_std_m == pytest.approx(np.sqrt(np.mean((expected - 2.01) ** 2)), rel=1e-9)
    # By hand: squared deviations 40 * 1.0^2 + 40 * 1.02^2 + sum_k (0.2 k - 0.98)^2 = 84.98.
    assert m.t100_std_m == pytest.approx(math.sqrt(84.98 / 90), rel=1e-9)


def test_suite_pools_segments_rather_than_averaging_sequences():
    def drifted(n, x_pct):
        gt = straight_line(n)
        est = gt.copy()
        est[:, :3, 3] *= 1 + x_pct / 100
        return gt, est

    suite = M.evaluate_suite({"long": drifted(1001, 1.0), "short": drifted(301, 3.0)})
    long_, short = suite.sequences["long"], suite.sequences["short"]
    # By hand: the 1000 m drive has 90, 80, ..., 20 segments (440), the 300 m
    # drive 20 of 100 m and 10 of 200 m (30); each reads x (L + 1) / L.
    assert len(long_.segments) == 440 and len(short.segments) == 30
    assert short.to_dict()["segment_counts"] == {
        "100": 20, "200": 10, "300": 0, "400": 0, "500": 0, "600": 0, "700": 0, "800": 0
    }
    m_short = 3.0 * (20 * 1.01 + 10 * 1.005) / 30
    assert short.t_err_pct == pytest.approx(m_short, rel=1e-9)
    pooled = (440 * long_.t_err_pct + 30 * m_short) / 470
    assert suite.overall.t_err_pct == pytest.approx(pooled, rel=1e-9)
    mean_of_means = (long_.t_err_pct + short.t_err_pct) / 2
    assert suite.overall.t_err_pct == pytest.approx(1.13, abs=0.01)
    assert mean_of_means == pytest.approx(2.01, abs=0.01)
    # The paper's overall figure pools too: 90 segments at 1.01 m, 20 at 3.03 m.
    assert suite.overall.t100_mean_m == pytest.approx((90 * 1.01 + 20 * 3.03) / 110, rel=1e-9)
    assert suite.overall.frames == 1302 and suite.overall.sequences == 2
    assert suite.overall.path_length_m == pytest.approx(1300.0)
    d = suite.to_dict()
    assert set(d) == {"sequences", "overall"} and d["overall"]["segments"] == 470


def test_too_short_sequences_have_nan_relative_errors_but_ate_and_rpe():
    gt = straight_line(10, step_m=0.58)
    est = gt.copy()
    est[:, :3, 3] *= 1.02
    m = M.evaluate_trajectory(gt, est)
    assert not m.has_relative_errors
    for value in (m.t_err_pct, m.r_err_deg_per_100m, m.t100_mean_m, m.t100_std_m):
        assert math.isnan(value)
    assert len(m.rpe) == 9
    np.testing.assert_allclose(m.rpe.t_err_m, 0.02 * 0.58, rtol=1e-9)
    assert m.ate_rmse_m == pytest.approx(0.02 * 0.58 * np.sqrt(np.mean(np.arange(10) ** 2)), rel=1e-9)
    assert m.ate_aligned_rmse_m < m.ate_rmse_m
    d = m.to_dict()
    for key in ("t_err_pct", "r_err_deg_per_100m", "t100_mean_m", "t100_std_m"):
        assert d[key] is None
    json.dumps(d, allow_nan=False)  # strict JSON: no NaN
    assert d["segments"] == 0 and d["rpe_pairs"] == 9


def test_real_kitti_excerpt_scores_per_frame(real_data):
    gt = read_kitti_poses(real_data / "kitti" / "lidar_frame_poses" / "05.txt")
    inc = se3.inverse(gt[:-1]) @ gt[1:]
    inc[:, :3, 3] *= 1.01  # 1 % too far every frame
    m = M.evaluate_trajectory(gt, compose(inc))
    assert math.isnan(m.t_err_pct) and len(m.rpe) == len(gt) - 1
    # rtol: the file's 7-digit rotations are orthonormal only to ~1e-7.
    np.testing.assert_allclose(m.rpe.t_err_m, 0.01 * np.linalg.norm(inc[:, :3, 3] / 1.01, axis=1), rtol=1e-6)
    assert m.rpe.r_stats_deg.max == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_relative_errors_ignore_a_common_change_of_world_frame(seed):
    gt = curved_drive(700, seed=seed)
    est = noisy_estimate(gt, seed=seed + 10)
    W = se3.exp(np.random.default_rng(seed).normal(0, [50, 50, 5, 0.3, 0.3, 3]))
    a, b = M.evaluate_trajectory(gt, est), M.evaluate_trajectory(W @ gt, W @ est)
    for key in ("t_err_pct", "r_err_deg_per_100m", "t100_mean_m", "ate_rmse_m", "ate_aligned_rmse_m",
                "rpe_t_rmse_m", "rpe_r_rmse_deg"):
        assert b.to_dict()[key] == pytest.approx(a.to_dict()[key], rel=1e-7, abs=1e-9), key


def test_mismatched_or_malformed_inputs_raise_value_errors():
    gt = straight_line(20)
    with pytest.raises(ValueError, match="20 poses but the estimate has 19"):
        M.evaluate_trajectory(gt, gt[:19])
    with pytest.raises(ValueError, match="shape"):
        M.evaluate_trajectory(gt[:, :3, :], gt[:, :3, :])
    with pytest.raises(ValueError, match="different RPE deltas"):
        M.TrajectoryMetrics.pool(
            [M.evaluate_trajectory(gt, gt), M.evaluate_trajectory(gt, gt, rpe_delta_frames=2)]
        )


def test_rpe_pairs_with_a_delta():
    gt = curved_drive(50, seed=7)
    overlapping = M.relative_pose_errors(gt, gt, delta_frames=5)
    disjoint = M.relative_pose_errors(gt, gt, delta_frames=5, all_pairs=False)
    np.testing.assert_array_equal(overlapping.first_frame, np.arange(45))
    np.testing.assert_array_equal(disjoint.first_frame, np.arange(0, 45, 5))
    np.testing.assert_array_equal(disjoint.last_frame, np.arange(5, 50, 5))
    assert len(M.relative_pose_errors(gt[:3], gt[:3], delta_frames=5)) == 0


# ---------------------------------------------------------------- evo cross-check
@pytest.mark.parametrize("seed", [11, 12])
def test_ate_and_rpe_match_evo(seed):
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.core.trajectory import PoseTrajectory3D

    gt = curved_drive(800, seed=seed, speed_m=1.2)
    est = noisy_estimate(gt, seed=seed + 100)

    def traj(T):
        return PoseTrajectory3D(poses_se3=list(T), timestamps=0.1 * np.arange(len(T)))

    ours = M.evaluate_trajectory(gt, est)

    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((traj(gt), traj(est)))
    np.testing.assert_allclose(ours.ate_errors_m, ape.error, rtol=1e-10, atol=1e-12)
    assert ours.ate_rmse_m == pytest.approx(ape.get_statistic(evo_metrics.StatisticsType.rmse), rel=1e-10)

    aligned = traj(est)
    R, t, _ = aligned.align(traj(gt), correct_scale=False)
    ape.process_data((traj(gt), aligned))
    np.testing.assert_allclose(ours.alignments_T_gt_est[0], se3.make(R, t), atol=1e-9)
    np.testing.assert_allclose(ours.ate_aligned_errors_m, ape.error, rtol=1e-8, atol=1e-10)
    evo_aligned_rmse = ape.get_statistic(evo_metrics.StatisticsType.rmse)
    assert ours.ate_aligned_rmse_m == pytest.approx(evo_aligned_rmse, rel=1e-9)
    assert ours.ate_aligned_rmse_m < 0.8 * ours.ate_rmse_m  # the test data has real drift

    for delta, all_pairs in ((1, False), (5, False), (5, True)):
        mine = M.relative_pose_errors(gt, est, delta_frames=delta, all_pairs=all_pairs)
        for relation, values, scale in (
            (evo_metrics.PoseRelation.translation_part, mine.t_err_m, 1.0),
            (evo_metrics.PoseRelation.rotation_angle_deg, mine.r_err_rad, math.degrees(1)),
        ):
            rpe = evo_metrics.RPE(relation, delta=delta, delta_unit=evo_metrics.Unit.frames, all_pairs=all_pairs)
            rpe.process_data((traj(gt), traj(est)))
            np.testing.assert_allclose(values * scale, rpe.error, rtol=1e-9, atol=1e-12)
            stats = M.ErrorStats.of(values * scale)
            for stat in ("mean", "median", "rmse"):
                evo_value = rpe.get_statistic(getattr(evo_metrics.StatisticsType, stat))
                assert getattr(stats, stat) == pytest.approx(evo_value, rel=1e-9), (relation, stat)


# ---------------------------------------------------------------- the command
def run_evaluate(argv):
    from tools.cli.evaluate import add_commands

    parser = argparse.ArgumentParser(prog="salo")
    add_commands(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["evaluate", *argv])
    return args.func(args)


def write_poses(path, T):
    path.write_text(format_kitti_poses(T))
    return path


def test_evaluate_command_json_table_and_plot(tmp_path, capsys):
    gt = curved_drive(1100, seed=8)
    est = noisy_estimate(gt, seed=9)
    g, e = write_poses(tmp_path / "gt.txt", gt), write_poses(tmp_path / "est.txt", est)
    expected = M.evaluate_trajectory(read_kitti_poses(g), read_kitti_poses(e))

    assert run_evaluate([str(g), str(e), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("t_err_pct", "r_err_deg_per_100m", "t100_mean_m", "t100_std_m", "ate_rmse_m",
                "ate_aligned_rmse_m", "rpe_t_rmse_m", "rpe_r_mean_deg", "segments", "path_length_m"):
        assert out[key] == pytest.approx(expected.to_dict()[key], rel=1e-12), key
    assert out["t_err_pct"] > 0 and out["segments"] > 100

    png = tmp_path / "plots" / "eval.png"
    assert run_evaluate([str(g), str(e), "--plot", str(png)]) == 0
    table = capsys.readouterr().out
    assert f"{expected.t_err_pct:.3f} %" in table and "deg/100 m" in table and "SE(3)-aligned" in table
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    assert not list(png.parent.glob(".*tmp*"))


def test_evaluate_command_on_a_short_sequence_says_why_figures_are_missing(tmp_path, capsys):
    gt = straight_line(10, step_m=0.6)
    g, e = write_poses(tmp_path / "gt.txt", gt), write_poses(tmp_path / "est.txt", gt)
    assert run_evaluate([str(g), str(e)]) == 0
    table = capsys.readouterr().out
    assert "n/a" in table and "shorter than the shortest segment" in table
    assert run_evaluate([str(g), str(e), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["t_err_pct"] is None and out["ate_rmse_m"] == 0.0 and out["notes"]


def test_evaluate_command_names_the_files_when_counts_differ(tmp_path):
    gt = straight_line(12)
    g, e = write_poses(tmp_path / "gt.txt", gt), write_poses(tmp_path / "est.txt", gt[:11])
    with pytest.raises(DatasetError) as info:
        run_evaluate([str(g), str(e)])
    msg = str(info.value)
    assert str(g) in msg and str(e) in msg and "11" in msg and "12" in msg


def test_metrics_import_no_plotting_or_embree():
    code = (
        "import sys, odometry.metrics, tools.cli.evaluate; "
        "bad = [m for m in sys.modules if m.split('.')[0] in ('matplotlib', 'embreex', 'pyvista')]; "
        "sys.exit(str(bad) if bad else 0)"
    )
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True)
