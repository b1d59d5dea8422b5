"""Methods as plug-ins (tools.methods) on staged input without ground truth (tools.staging).

A short simulated sequence is staged; the tests check that nothing of the truth
reaches the method (no file, no link, no truth field), that a command copying the
truth fails, and that every kind of method (ours, a command, a plug-in through an
entry point, a peer) gives poses that the simulator's truth confirms.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from odometry.metrics import evaluate_trajectory
from simlidar.dataset import open_sequence
from tools.methods import (
    CommandMethod,
    FunctionMethod,
    MethodError,
    OursMethod,
    method_from_name,
    run_method,
)
from tools.staging import StagingError, parse_fields, stage_input, staged


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory) -> Path:
    from simlidar.sensor import load_sensor
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    out = tmp_path_factory.mktemp("methods") / "city"
    simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor("vlp16"), out, 5, seed=0,
                   start_s=4.0)
    return out


def _truth_error_m(sequence_dir: Path, poses: np.ndarray) -> float:
    return evaluate_trajectory(open_sequence(sequence_dir).poses, poses).ate_aligned_rmse_m


def test_the_staged_folder_holds_the_sensor_data_and_nothing_of_the_truth(sequence_dir, tmp_path):
    seq = open_sequence(sequence_dir)
    stage = stage_input(seq, tmp_path / "stage")
    files = sorted(p.relative_to(stage.root).as_posix() for p in stage.root.rglob("*") if p.is_file())
    assert files == sorted(["sensor.yaml", "times.txt"] + [f"velodyne/{k:06d}.bin" for k in range(5)]
                           + [f"fields/{k:06d}.npy" for k in range(5)])
    # No path leads back to the sequence: no symbolic links anywhere (hard links share data, not a path).
    assert not any(p.is_symlink() for p in (tmp_path / "stage").rglob("*"))
    assert not (stage.root.parent / "poses.txt").exists()
    # The fields are the sensor's only, and equal to what the simulator wrote.
    staged_seq = open_sequence(stage.root)
    assert staged_seq.poses is None
    frame, original = staged_seq[2], seq[2]
    assert frame.fields.dtype.names == ("ring", "time_s")
    np.testing.assert_array_equal(frame.ring, original.ring)
    np.testing.assert_array_equal(frame.time_s, original.time_s)
    np.testing.assert_array_equal(frame.points, original.points)
    np.testing.assert_array_equal(staged_seq.times, seq.times)


def test_a_command_that_copies_the_ground_truth_finds_none(sequence_dir, tmp_path):
    seq = open_sequence(sequence_dir)
    for template in ("cp {sequence}/poses.txt {out}", "cp {scans}/../poses.txt {out}",
                     "cp $(dirname {scans})/poses.txt {out}", "cp {scans}/../../poses.txt {out}",
                     "cp $(dirname {out})/../poses.txt {out} # {scans}"):
        with pytest.raises(MethodError, match="exited with status"):
            run_method(CommandMethod("cheat", template), seq, log_path=tmp_path / "cheat.log")
    assert "No such file" in (tmp_path / "cheat.log").read_text()


def test_truth_fields_are_refused_and_none_gives_xyz_only(sequence_dir, tmp_path):
    with pytest.raises(StagingError, match="ground truth"):
        parse_fields("ring,true_xyz")
    with pytest.raises(StagingError, match="unknown per-point field 'colour'"):
        parse_fields("colour")
    assert parse_fields("none") == () and parse_fields(None) == ("ring", "time_s")
    with staged(open_sequence(sequence_dir), fields=()) as stage:
        assert not (stage.root / "fields").exists()
        assert open_sequence(stage.root)[0].fields is None


def test_a_command_and_ours_in_process_give_the_same_poses_close_to_the_truth(sequence_dir, tmp_path):
    seq = open_sequence(sequence_dir)
    ours = run_method(method_from_name("bl"), seq)
    command = f"{sys.executable} -m tools.cli odometry {{sequence}} --variant bl --out {{out}}"
    theirs = run_method(CommandMethod("mine", command), seq, workdir=Path(__file__).parents[1],
                        log_path=tmp_path / "command.log")
    np.testing.assert_allclose(theirs.poses, ours.poses, atol=1e-9)
    assert ours.diagnostics is not None and len(ours.degenerate) == 5
    assert _truth_error_m(sequence_dir, ours.poses) < 0.05  # 5 frames at 8 m/s, 3 cm noise


def test_a_sequence_in_memory_is_handed_over_as_the_sensor_view_with_the_same_poses(sequence_dir, tmp_path,
                                                                                    monkeypatch):
    from simlidar.in_memory import InMemorySequence, simulate_in_memory
    from simlidar.sensor import load_sensor
    from tools.staging import sensor_view
    from tools.worlds import build_scene_world

    scene = build_scene_world("city", 0, {"speed_m_s": 8.0})
    memory = simulate_in_memory(scene.world, scene.trajectory, load_sensor("vlp16"), 5, seed=0, t_start=4.0)
    assert isinstance(memory, InMemorySequence) and memory.poses is not None
    view = sensor_view(memory, ("ring",))
    assert view.poses is None and view.degeneracy == [] and view.manifest == {}
    assert view[0].fields.dtype.names == ("ring",)
    np.testing.assert_array_equal(view[3].points, memory[3].points)
    # In memory (the view), staged on disk, and from the simulated folder: the same poses.
    with monkeypatch.context() as patch:  # in memory, an in-process method is handed nothing on disk
        patch.setattr("tools.staging.stage_input", lambda *a, **k: pytest.fail("staged on disk"))
        in_memory = run_method(method_from_name("bl"), memory)
    with staged(memory) as stage:
        on_disk = method_from_name("bl").run_staged(stage)
    np.testing.assert_allclose(in_memory.poses, on_disk.poses, atol=1e-9)  # times.txt is text
    np.testing.assert_allclose(in_memory.poses, run_method(method_from_name("bl"),
                                                           open_sequence(sequence_dir)).poses, atol=1e-9)


def test_a_command_without_out_or_scans_is_refused_naming_the_placeholders():
    with pytest.raises(MethodError, match=r"has no \{out\} and \{scans\}"):
        CommandMethod("x", "true")
    with pytest.raises(MethodError, match=r"has no \{out\}"):
        CommandMethod("x", "my_odometry {scans}")
    with pytest.raises(MethodError, match="unknown method 'nope'.*peers: kiss-icp"):
        method_from_name("nope")
    with pytest.raises(MethodError, match="--set changes our odometry"):
        method_from_name("kiss-icp", {"ncf": {"enabled": False}})
    salo = method_from_name("salo", {"ncf": {"enabled": False}})
    assert isinstance(salo, OursMethod) and salo.name.startswith("salo+") and not salo.config.ncf.enabled
    assert salo.key != method_from_name("salo").key


def test_a_plugin_registered_by_entry_point_runs_on_the_staged_sequence(sequence_dir, tmp_path, monkeypatch):
    # A package that registers "truth-free" in the group salo.methods: it checks what it is handed and
    # answers with a constant-velocity guess of 0.8 m per frame along x.
    pkg = tmp_path / "site"
    (pkg / "my_plugin").mkdir(parents=True)
    (pkg / "my_plugin" / "__init__.py").write_text(textwrap.dedent("""
        import numpy as np

        def run(sequence):
            assert sequence.poses is None, "the ground truth reached the plug-in"
            frame = sequence[0]
            assert frame.field("true_xyz") is None and frame.field("normal") is None
            assert frame.ring is not None and sequence.sensor is not None
            poses = np.tile(np.eye(4), (len(sequence), 1, 1))
            poses[:, 0, 3] = 0.8 * np.arange(len(sequence))
            return poses
    """))
    info = pkg / "my_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[salo.methods]\ntruth-free = my_plugin:run\n")
    monkeypatch.syspath_prepend(str(pkg))
    method = method_from_name("truth-free")
    assert isinstance(method, FunctionMethod) and method.version == "1.0"
    out = run_method(method, open_sequence(sequence_dir))
    assert out.poses.shape == (5, 4, 4) and out.poses[4, 0, 3] == pytest.approx(3.2)
    # 8 m/s at 10 Hz is 0.8 m per frame along the path, not along x alone: the truth tells them apart.
    assert _truth_error_m(sequence_dir, out.poses) > _truth_error_m(
        sequence_dir, run_method(method_from_name("bl"), open_sequence(sequence_dir)).poses)


@pytest.mark.slow
def test_a_peer_runs_through_the_same_interface(sequence_dir):
    method = method_from_name("kiss-icp")
    if method.unavailable():
        pytest.skip(method.unavailable())
    out = run_method(method, open_sequence(sequence_dir))
    assert out.poses.shape == (5, 4, 4) and out.note.startswith("kiss-icp")
    assert _truth_error_m(sequence_dir, out.poses) < 0.2
