"""The stress suite: each scripted scene beside its static twin on the same ego motion; its figures (the end's
error, the motion invented while standing still) against the scenes' own truth; ``salo bench --suite stress``."""

from __future__ import annotations

import json

import numpy as np
import pytest

import scenes
from simlidar import se3
from tools.family_suite import standstill_motion_m, trajectory_figures
from tools.leaderboard.standstill import motion_table
from tools.stress_suite import STRESS, stress_suite


def test_the_stress_suite_puts_each_scene_beside_its_static_twin():
    seqs = stress_suite()
    assert [s.name for s in seqs] == [f"{s.scene}-{m}" for s in STRESS for m in ("moving", "static")]
    assert [s.scene for s in stress_suite(("lead_vehicle",), frames=12)] == ["lead_vehicle"] * 2
    assert {s.frames for s in stress_suite(frames=12)} == {12}
    with pytest.raises(ValueError, match="unknown stress scene 'roundabout'"):
        stress_suite(("roundabout",))


@pytest.mark.parametrize("name", [s.scene for s in STRESS])
def test_a_stress_scene_and_its_twin_share_the_world_and_the_ego_motion(name):
    moving, twin = scenes.build_scene(name), scenes.build_scene(name, moving=False)
    assert len(moving.actors) > 0 and twin.actors == []
    assert moving.mesh_hash() == twin.mesh_hash()
    t = np.linspace(0.0, moving.trajectory.duration_s, 300)
    np.testing.assert_array_equal(moving.trajectory.pose_at(t), twin.trajectory.pose_at(t))


def _red_light_truth():
    """The red light's true poses at its suite sequence's frames (10 Hz from its start), relative to the first."""
    seq = next(s for s in STRESS if s.scene == "red_light")
    scene = scenes.build_scene("red_light")
    T = scene.trajectory.pose_at(seq.start_s + 0.1 * np.arange(seq.frames))
    return se3.inverse(T[0]) @ T, scene.metadata["wait_s"], seq.start_s


def test_the_motion_invented_standing_still_is_summed_where_the_truth_stands_still():
    gt, (t_stop, t_go), start = _red_light_truth()
    assert standstill_motion_m(gt, gt) == 0.0
    # the frames wholly inside the wait: their steps are the ones counted
    frame_t = start + 0.1 * np.arange(len(gt))
    still = np.flatnonzero((frame_t[:-1] > t_stop) & (frame_t[1:] < t_go))
    assert 90 <= len(still) <= 100  # the 10 s wait at 10 Hz
    est = gt.copy()
    # a 1 cm step forward at one still frame pair and 2 cm sideways at another; a 5 cm error while moving
    # is not counted
    k1, k2 = still[10], still[50]
    shifts = {k1 + 1: np.array([0.01, 0, 0]), k2 + 1: np.array([0, 0.02, 0]), 2: np.array([0.05, 0, 0])}
    for k, d in shifts.items():
        est[k:, :3, 3] += d  # from frame k on: one step of d between k - 1 and k
    assert standstill_motion_m(gt, est) == pytest.approx(0.03, abs=1e-9)
    # never still: the lead vehicle's drive
    lead = scenes.build_scene("lead_vehicle").trajectory.pose_at(0.1 * np.arange(50))
    assert standstill_motion_m(lead, lead) is None
    figures = trajectory_figures(gt, est)
    assert figures["end_error_m"] == pytest.approx(np.linalg.norm([0.06, 0.02, 0.0]))
    assert figures["standstill_motion_m"] == pytest.approx(0.03, abs=1e-9)


def test_the_table_lists_each_sequences_end_error_and_motion_standing_still():
    gt, _, _ = _red_light_truth()
    est = gt.copy()
    est[-1, :3, 3] += (0.3, 0.4, 0.0)

    class Method:
        name = label = "m"

    class Seq:
        def __init__(self, id_):
            self.id = id_

    results = [{"method": "m", "sequence": "red_light-moving", "status": "ok", "figures": trajectory_figures(gt, est)},
               {"method": "m", "sequence": "red_light-static", "status": "failed", "figures": {}}]
    table = motion_table(results, [Method()], [Seq("red_light-moving"), Seq("red_light-static"), Seq("other")])
    rows = table.splitlines()
    assert rows[2] == "| red_light-moving | 0.500 / 0.000 |"
    assert rows[3] == "| red_light-static | failed |" and rows[4] == "| other |  |"


@pytest.mark.slow
def test_bench_over_the_stress_suite_simulates_each_scene_and_its_twin(tmp_path):
    from simlidar.dataset import open_sequence
    from tools.leaderboard.suites import bench_sequences

    seqs = bench_sequences("stress", tmp_path, frames=3, families=("overtaking_lorry",))
    assert [s.family for s in seqs] == ["overtaking_lorry (moving)", "overtaking_lorry (static twin)"]
    moving, static = (open_sequence(s.path) for s in seqs)
    np.testing.assert_array_equal(moving.poses, static.poses)
    assert json.loads((seqs[0].path / "manifest.json").read_text())["format_version"] == 3
    assert static.manifest["format_version"] == 2 and not (seqs[1].path / "tracks.csv").exists()
    assert all(np.any(moving[k].fields["moving"]) for k in range(3))  # the lorry and the oncoming traffic
