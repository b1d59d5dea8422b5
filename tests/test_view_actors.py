"""``salo view`` of a sequence with moving objects: the returns off them flagged as the truth says, their boxes
and meshes where ``tracks.csv`` puts them, each moving return inside its object's box."""

from __future__ import annotations

import numpy as np
import pytest

from simlidar.dataset import open_sequence
from simlidar.formats.tracks import read_tracks
from tools.stress_suite import StressSequence, simulate_to_folder
from tools.view import sequence_view


@pytest.fixture(scope="module")
def red_light_folder(tmp_path_factory):
    """Two VLP-16 sweeps of the red light while the ego waits and the cross traffic passes in front."""
    out = tmp_path_factory.mktemp("view") / "red"
    return simulate_to_folder(StressSequence("red_light", True, 2, 17.0, sensor="vlp16"), out)


def _box_frame(corners: np.ndarray):
    """(origin (3,), axes (3, 3) rows, size (3,)) of a box from its 8 corners (``tools.view.box_corners``'
    order: corner k at (+-x, +-y, +-z) by the bits of k)."""
    edges = np.stack([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]])
    size = np.linalg.norm(edges, axis=1)
    return corners[0], edges / size[:, None], size


def test_the_view_flags_the_moving_returns_and_places_their_boxes_and_meshes(red_light_folder):
    seq = open_sequence(red_light_folder)
    frames, rows = read_tracks(red_light_folder / "tracks.csv")
    k = 1
    view = sequence_view(red_light_folder, frame_index=k)
    fields = seq[k].fields
    np.testing.assert_array_equal(view.moving, fields["moving"])
    assert view.moving.sum() > 100  # the crossing vehicles in front
    mine = rows[frames == k]
    assert view.boxes.shape == (len(mine), 8, 3)
    # each moving return lies in its object's box at the sweep's start, grown by how far the object went since
    period = seq.sensor.sweep_period_s
    for row, corners in zip(mine, view.boxes, strict=True):
        hits = view.xyz[(fields["object_id"] == row["object_id"]) & view.moving]
        origin, axes, size = _box_frame(corners)
        local = (hits - origin) @ axes.T
        grown = np.linalg.norm(row["velocity"]) * period + 0.05  # (the range noise, the box's rounding)
        assert np.all((local >= -grown) & (local <= size + grown)), row["object_id"]
    # the meshes: each model's vertices, all within the boxes
    vertices, faces = view.actors
    assert len(faces) > 0 and faces.max() < len(vertices)
    inside = np.zeros(len(vertices), bool)
    for corners in view.boxes:
        origin, axes, size = _box_frame(corners)
        local = (vertices - origin) @ axes.T
        inside |= np.all((local >= -1e-3) & (local <= size + 1e-3), axis=1)
    assert inside.all()


@pytest.mark.slow
def test_salo_view_draws_the_moving_returns_and_boxes_in_red(red_light_folder, tmp_path):
    """The same frame of the static twin (the same world, ego pose and sensor) shows red only where the path
    and the far rings are: the moving picture holds more than twice its red pixels."""
    from PIL import Image

    from tools.cli import main

    twin = simulate_to_folder(StressSequence("red_light", False, 2, 17.0, sensor="vlp16"), tmp_path / "twin")
    red = {}
    for name, folder in (("moving", red_light_folder), ("static", twin)):
        png = tmp_path / f"{name}.png"
        assert main(["view", str(folder), "--frame", "1", "--out", str(png)]) == 0
        img = np.asarray(Image.open(png).convert("RGB"), dtype=int)
        red[name] = int(np.sum((img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 90)))
    assert red["moving"] > 2 * red["static"]
