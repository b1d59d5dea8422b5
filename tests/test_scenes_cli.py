"""The scene commands: parameter overrides, mesh export round trips, the simulator entry, pictures."""

from __future__ import annotations

import argparse
import json
import re

import numpy as np
import pytest
import yaml

import scenes
from simlidar.world import load_world
from tools.cli.common import CommandError, parse_overrides
from tools.cli.scenes import add_commands
from tools.worlds import build_scene_world

SMALL_CITY = ["--set", "streets_x=2", "--set", "streets_y=2", "--set", "route_blocks=1"]


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="salo")
    add_commands(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_overrides_from_yaml_then_pairs(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("length_m: 300\ncross_section: box\nseed: 4\n")
    out = parse_overrides(["length_m=250", "grade_pct = -2"], f)
    assert out == {"length_m": "250", "cross_section": "box", "seed": 4, "grade_pct": "-2"}
    p = scenes.resolve_params("tunnel", **out)
    assert (p.length_m, p.cross_section, p.seed, p.grade_pct) == (250.0, "box", 4, -2.0)


@pytest.mark.parametrize(
    "pairs, text, word",
    [
        (["length_m"], None, "length_m"),  # no '='
        (["=3"], None, "=3"),
        ([], "[1, 2]", "p.yaml"),  # not a mapping
        ([], "a: [1, 2]", "parameter a"),
        ([], "a: [1, 2", "p.yaml"),  # broken YAML
    ],
)
def test_bad_overrides_name_the_pair_or_file(tmp_path, pairs, text, word):
    f = None
    if text is not None:
        f = tmp_path / "p.yaml"
        f.write_text(text)
    with pytest.raises(ValueError, match=word):
        parse_overrides(pairs, f)


def test_missing_parameter_file_is_named(tmp_path):
    with pytest.raises(ValueError, match="nope.yaml"):
        parse_overrides([], tmp_path / "nope.yaml")


def test_scenes_lists_scenes_and_parameters(capsys):
    assert run(["scenes"]) == 0
    listing = capsys.readouterr().out
    assert all(f"{name}:" in listing for name in scenes.SCENES)
    assert run(["scenes", "tunnel"]) == 0
    listing = capsys.readouterr().out
    assert "length_m" in listing and "500" in listing and "cross_section" in listing and "arch|box" in listing
    with pytest.raises(CommandError, match="mars"):
        run(["scenes", "mars"])


def test_yaml_defaults_feed_back_into_a_build(tmp_path, capsys):
    assert run(["scenes", "open", "--yaml"]) == 0
    f = tmp_path / "open.yaml"
    f.write_text(capsys.readouterr().out)
    data = yaml.safe_load(f.read_text())
    assert data["rocks"] == 40 and data["seed"] == 0
    data["rocks"] = 3
    f.write_text(yaml.safe_dump(data))
    out = tmp_path / "open.ply"
    assert run(["scene", "open", "--params", str(f), "--out", str(out)]) == 0
    world = load_world(out)
    assert world.object_labels.count("rock") == 3


def test_scene_export_round_trips_through_ply_and_glb(tmp_path):
    ref = scenes.build_scene("city", seed=7, streets_x=2, streets_y=2, route_blocks=1)
    ref_labels = np.asarray(ref.object_labels)[ref.face_object_id]
    for ext in ("ply", "glb"):
        out = tmp_path / f"city.{ext}"
        assert run(["scene", "city", "--seed", "7", *SMALL_CITY, "--out", str(out)]) == 0
        world = load_world(out)
        assert len(world.faces) == len(ref.faces)
        labels = np.asarray(world.object_labels)[world.face_object_id]
        if ext == "ply":  # same order, same ids, same vertices
            np.testing.assert_array_equal(world.face_object_id, ref.face_object_id)
            np.testing.assert_array_equal(world.vertices, ref.vertices)
            np.testing.assert_array_equal(labels, ref_labels)
        else:  # one node per object: the same objects and labels, in the file's order
            assert len(world.object_labels) == len(ref.object_labels)
            assert sorted(labels.tolist()) == sorted(ref_labels.tolist())


def test_scene_command_errors_name_the_problem(tmp_path):
    with pytest.raises(CommandError, match="x.obj"):
        run(["scene", "tunnel", "--set", "length_m=100", "--out", str(tmp_path / "x.obj")])
    with pytest.raises(CommandError, match="length_m"):
        run(["scene", "tunnel", "--set", "length_m=short", "--out", str(tmp_path / "x.ply")])


def test_world_and_trajectory_for_the_simulator():
    built = build_scene_world("tunnel", 3, {"length_m": "200"})
    world, traj, info = built.world, built.trajectory, built.info
    json.dumps(info)  # goes into the manifest
    assert info["scene"] == "tunnel" and info["scene_seed"] == 3 and info["scene_params"]["length_m"] == 200.0
    again = scenes.build_scene(info["scene"], **info["scene_params"])  # the manifest rebuilds the world
    assert again.mesh_hash() == info["mesh_sha256"]
    assert len(world.faces) == again.n_triangles and world.object_labels == again.object_labels
    assert traj.pose_at(np.array([0.0, 1.0])).shape == (2, 4, 4) and traj.duration_s > 0


def _png_is_a_picture(path, size=(1800, 900)):
    from PIL import Image

    img = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    assert img.shape[1::-1] == size
    # not blank: many distinct colours in each half (3D view, overview)
    for half in (img[:, : size[0] // 2], img[:, size[0] // 2:]):
        assert len(np.unique(half.reshape(-1, 3), axis=0)) > 50


@pytest.mark.slow
def test_view_of_a_scene_and_of_a_sequence(tmp_path):
    from simlidar.sensor import load_sensor
    from simlidar.simulate import simulate_sequence

    png = tmp_path / "tunnel.png"
    assert run(["view", "tunnel", "--set", "length_m=150", "--at", "0.3", "--out", str(png)]) == 0
    _png_is_a_picture(png)

    built = build_scene_world("city", 1, {"streets_x": 2, "streets_y": 2, "route_blocks": 1})
    world, traj, info = built.world, built.trajectory, built.info
    seq = simulate_sequence(world, traj, load_sensor("vlp16"), tmp_path / "seq", frames=2, t_start=5.0, info=info)
    png = tmp_path / "seq.png"
    assert run(["view", str(seq), "--out", str(png)]) == 0
    _png_is_a_picture(png)
    with pytest.raises(CommandError, match="neither a sequence folder nor a scene"):
        run(["view", str(tmp_path / "missing"), "--out", str(png)])


@pytest.fixture
def drawn(monkeypatch):
    """Replace the renderer with a recorder of what it would draw (the choice of frame and pose is under test)."""
    calls = []

    def record(vertices, faces, face_labels, path, out_png, T_world_lidar=None, scan_xyz_world=None,
               scan_ring=None, title="", size=(1800, 900), moving=None, boxes=None, actors=None):
        calls.append({"vertices": vertices, "faces": faces, "path": path, "T": T_world_lidar,
                      "xyz": scan_xyz_world, "title": title, "moving": moving, "boxes": boxes})

    monkeypatch.setattr("tools.view.render_scene", record)
    return calls


@pytest.mark.slow
def test_view_shows_the_frame_asked_for(tmp_path, drawn):
    from simlidar.dataset import open_sequence
    from simlidar.sensor import load_sensor
    from simlidar.simulate import simulate_sequence

    built = build_scene_world("city", 1, {"streets_x": 2, "streets_y": 2, "route_blocks": 1})
    world, traj, info = built.world, built.trajectory, built.info
    folder = simulate_sequence(world, traj, load_sensor("vlp16"), tmp_path / "seq", frames=5, t_start=5.0,
                               info=info)
    seq = open_sequence(folder)
    png = str(tmp_path / "x.png")
    for extra, k in [([], 0), (["--frame", "3"], 3), (["--at", "0.5"], 2), (["--at", "1"], 4), (["--at", "0"], 0),
                     (["--at", "0.6"], 2)]:
        assert run(["view", str(folder), *extra, "--out", png]) == 0
        shown = drawn.pop()
        T = traj.pose_at(np.array([5.0 + 0.1 * k]))[0]  # the frame's own pose along the scene's path
        assert np.allclose(shown["T"], T, atol=1e-9), extra
        assert np.allclose(shown["xyz"], seq[k].points @ T[:3, :3].T + T[:3, 3], atol=1e-6), extra
        assert f"frame {k} of 5 at t = {0.1 * k:.1f} s" in shown["title"], extra
    for extra, words in [(["--frame", "5"], "has 5 frames (0..4)"), (["--at", "1.5"], "--at 1.5: expected a fraction"),
                         (["--at", "0.5", "--frame", "1"], "give --at or --frame, not both")]:
        with pytest.raises(CommandError, match=re.escape(words)):
            run(["view", str(folder), *extra, "--out", png])
    with pytest.raises(CommandError, match="--frame 2: needs a sequence folder"):
        run(["view", "tunnel", "--frame", "2", "--out", png])
    assert drawn == []


def test_view_of_a_mesh_sequence_from_another_folder(tmp_path, monkeypatch, capsys, drawn):
    from simlidar.formats.kitti import format_kitti_poses
    from simlidar.world import World, save_world_ply
    from tools.cli import main as salo

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    work.mkdir()
    elsewhere.mkdir()
    box = trimesh_box((20.0, 16.0, 6.0))
    save_world_ply(World(box.vertices, box.faces, np.zeros(len(box.faces)), ["wall"]), work / "room.ply")
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 0, 3] = np.linspace(-3, 3, 4)
    T[:, 2, 3] = 1.8
    (work / "poses.txt").write_text(format_kitti_poses(T))
    monkeypatch.chdir(work)  # relative paths, as a user types them
    assert salo(["simulate", "--mesh", "room.ply", "--poses", "poses.txt", "--sensor", "vlp16", "--out", "seq"]) == 0
    monkeypatch.chdir(elsewhere)
    seq = str(work / "seq")
    assert salo(["view", seq, "--frame", "2", "--out", "v.png"]) == 0
    shown = drawn.pop()
    assert np.allclose(shown["T"], T[2]) and len(shown["faces"]) == len(box.faces)
    assert np.allclose(shown["path"], T[:, :3, 3])
    capsys.readouterr()
    with open(work / "room.ply", "ab") as fh:  # the mesh changes after the simulation
        fh.write(b"\n")
    assert salo(["view", seq, "--out", "v.png"]) == 2
    err = capsys.readouterr().err
    assert f"{work / 'room.ply'}: the mesh changed since" in err and "sha256" in err and len(err.splitlines()) == 1
    (work / "room.ply").unlink()
    assert salo(["view", seq, "--out", "v.png"]) == 2
    assert f"the world mesh {work / 'room.ply'} is missing" in capsys.readouterr().err
    assert drawn == [] and not (elsewhere / "v.png").exists()


def trimesh_box(size):
    import trimesh

    m = trimesh.creation.box(size)
    m.invert()  # a room seen from inside
    return m
