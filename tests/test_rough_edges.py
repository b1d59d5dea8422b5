"""What a new user hit (issue 39), each as the user met it: the command, and what it must say now.

Every test here failed before its fix: a traceback or a silent exit 0 where one line
and exit 2 belong, a hint that needed a second try, one option under two names, help
text that contradicted itself, a marker that covered a room, an output overwritten
without --force, a prefix said twice, a Python slice in a message, a stretch that read
as a contradiction, a title that rounded 0.59 m to 1 m, a legend entry for nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tools import cli


@pytest.fixture(scope="module")
def seq(tmp_path_factory) -> Path:
    from simlidar.sensor import load_sensor
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    out = tmp_path_factory.mktemp("edges") / "t1"
    simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor("vlp16"), out, 4, seed=0,
                   start_s=4.0)
    return out


def _salo(capsys, *argv) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _one_line(err: str) -> str:
    """The error line (progress bars aside): exactly one."""
    lines = [line for line in err.replace("\r", "\n").splitlines() if "error:" in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_a_zero_step_or_an_empty_frame_range_is_one_line_and_exit_2(seq, tmp_path, capsys):
    for argv in (["odometry", seq, "--frames", "0:10:0", "--out", tmp_path / "p.txt"],
                 ["export", seq, "--format", "tum", "--frames", "0:10:0", "--out", tmp_path / "t.tum"]):
        code, _, err = _salo(capsys, *argv)
        assert code == 2 and "--frames '0:10:0': the step must not be zero" in _one_line(err)
    code, _, err = _salo(capsys, "odometry", seq, "--frames", "5:2", "--out", tmp_path / "p.txt")
    line = _one_line(err)
    assert code == 2 and line.count(str(seq)) == 1 and "selects no frame" in line  # not "t1: t1:"
    code, _, err = _salo(capsys, "export", seq, "--format", "tum", "--frames", "5:2", "--out", tmp_path / "t.tum")
    assert code == 2 and "slice(" not in err and "selects no frame" in _one_line(err)


def test_the_export_library_names_a_frame_range_as_typed(seq, tmp_path):
    from simlidar.dataset import open_sequence
    from tools.export import ExportError, export

    with pytest.raises(ExportError) as caught:
        export(open_sequence(seq), "tum", tmp_path / "t.tum", slice(5, 2))
    assert "frames 5:2 select none of its 4 frames" in str(caught.value) and "slice(" not in str(caught.value)


def test_an_unknown_key_in_a_stage_suggests_the_whole_dotted_key():
    from tools.cli.common import CommandError, parse_config_set

    with pytest.raises(CommandError) as caught:
        parse_config_set(["filter.voxel_sise_m=0.4"])
    assert "did you mean 'filter.voxel_size_m'?" in str(caught.value)
    assert parse_config_set(["filter.voxel_size_m=0.4"]) == {"filter": {"voxel_size_m": 0.4}}  # the hint works


def test_scene_parameters_are_scene_params_in_every_command(capsys, tmp_path):
    code, out, _ = _salo(capsys, "scenes", "tunnel", "--yaml")
    assert code == 0 and "--scene-params FILE" in out and "--params" not in out.replace("--scene-params", "")
    code, out, _ = _salo(capsys, "scenes")
    assert "--scene-params FILE.yaml" in out
    params = tmp_path / "p.yaml"
    parser = cli.build_parser()
    for argv in (["simulate", "--scene", "tunnel", "--out", "x"], ["scene", "tunnel", "--out", "x.ply"],
                 ["view", "tunnel", "--out", "x.png"]):
        args = parser.parse_args([*argv, "--scene-params", str(params)])
        assert Path(getattr(args, "params", None) or args.scene_params) == params
    for argv in (["scene", "tunnel", "--out", "x.ply"], ["view", "tunnel", "--out", "x.png"]):
        assert parser.parse_args([*argv, "--params", str(params)]).params == params  # the older name still works
        help_text = parser._subparsers._group_actions[0].choices[argv[0]].format_help()
        assert "--scene-params" in help_text and "--params " not in help_text


def test_view_of_a_folder_refuses_scene_options(seq, capsys):
    for extra in (["--set", "length_m=100"], ["--sensor", "vlp16"], ["--seed", "3"]):
        code, _, err = _salo(capsys, "view", seq, *extra, "--out", "v.png")
        assert code == 2 and extra[0] in _one_line(err) and "options of a scene" in err


def test_evaluate_help_says_percent_once_and_how_tum_pairs(capsys):
    with pytest.raises(SystemExit):
        cli.main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "%%" not in text and "translation in percent" in text
    assert "both KITTI pose files" not in text and "two TUM files of different lengths pair by time stamp" in text


def test_the_overview_marker_of_a_small_room_covers_little_of_it(tmp_path):
    from helpers import box_room
    from PIL import Image

    from tools.view import render_scene

    room = box_room((10.0, 8.0, 3.0), center=(0.0, 0.0, 1.5))
    T = np.eye(4)
    T[:3, 3] = (1.0, 0.5, 1.2)
    png = render_scene(room.vertices, room.faces, np.array(["wall"] * len(room.faces)),
                       np.array([[-3.0, 0.5, 1.2], [3.0, 0.5, 1.2]]), tmp_path / "room.png", T_world_lidar=T,
                       size=(1000, 500))
    pixels = np.asarray(Image.open(png).convert("RGB")).astype(int)
    def magenta(p: np.ndarray) -> np.ndarray:  # the marker, lit or in shade
        return (p[..., 0] > 150) & (p[..., 1] < 100) & (p[..., 2] > 150)

    left, right = pixels[:, :500], pixels[:, 500:]
    room_px = (np.abs(right - 255).sum(axis=2) > 30)  # everything drawn in the overview, the room included
    assert 20 < magenta(right).sum() < 0.01 * room_px.sum()  # seen, and a speck of the room (was 9 %)
    assert magenta(left).mean() < 0.01


def test_odometry_refuses_an_existing_output_without_force(seq, tmp_path, capsys):
    out = tmp_path / "run" / "poses.txt"
    assert _salo(capsys, "odometry", seq, "--variant", "bl", "--out", out)[0] == 0
    first = out.read_text()
    code, _, err = _salo(capsys, "odometry", seq, "--variant", "bl", "--out", out)
    assert code == 2 and f"{out}: already exists (use --force to replace it" in _one_line(err)
    assert _salo(capsys, "odometry", seq, "--variant", "bl", "--out", out, "--force")[0] == 0
    assert out.read_text() == first


def test_simulating_into_an_existing_folder_from_python_names_force_true(seq):
    from simlidar.sensor import load_sensor
    from simlidar.sequence import DatasetError
    from tools.runners import simulate_scene
    from tools.worlds import build_scene_world

    with pytest.raises(DatasetError, match=r"force=True in Python"):
        simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor("vlp16"), seq, 4, seed=0,
                       start_s=4.0)


def test_a_stretch_says_which_clause_flagged_it():
    from types import SimpleNamespace

    from odometry.diagnostics import DegenerateStretch
    from tools.cli.odometry import flagged_by

    stretch = DegenerateStretch(3, 9, np.array([1.0, 0.0, 0.0]), 0.06, 7)
    kept = [SimpleNamespace(frame=k, degenerate=False, remapped=1) for k in range(3, 10)]
    line = flagged_by(stretch, kept, 0.01)
    assert line.startswith("frames 3-9 (prior kept on 7): ") and "below" not in line and "0.06" in line
    low = [SimpleNamespace(frame=k, degenerate=k < 5, remapped=int(k >= 5)) for k in range(3, 10)]
    assert "(2 frames below 0.01, prior kept on 5)" in flagged_by(stretch, low, 0.01)


def test_the_evaluation_plot_says_short_lengths_and_shades_only_what_is_weak():
    from matplotlib.figure import Figure

    from tools.evaluate import metres_text
    from tools.leaderboard.figures import draw_error_over_distance

    assert metres_text(0.59) == "0.59 m" and metres_text(130.4) == "130 m"
    gt = np.tile(np.eye(4), (5, 1, 1))
    gt[:, 0, 3] = np.arange(5) * 0.15
    for weak, shown in ((np.zeros(5, bool), False), (np.array([0, 1, 1, 0, 0], bool), True)):
        fig = Figure()
        ax, strip = fig.subplots(2, 1)
        draw_error_over_distance(ax, strip, gt, {"estimate": gt.copy()}, weak, {})
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert ("weak in the truth" in labels) == shown
