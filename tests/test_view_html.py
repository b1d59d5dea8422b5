"""The interactive page of a run (tools.view_html, ``salo view --html``), and the page in a real browser.

The encoding is checked against the scans it encodes (every point back within half a
quantum, rings and classes exact), the per-frame error against the truth's, the kept
points against our filters' range limits. In headless Chromium (Debian's package;
skipped, saying so, only when there is no Chromium binary) the page loads without a
console message, draws the frame asked for, and its screenshot's pixels show the
points: coloured in both halves of the side-by-side view, different for another frame,
and only kept-green and dropped-red in the kept / dropped colouring.
"""

from __future__ import annotations

import base64
import json
import re
import zlib
from pathlib import Path

import browser
import numpy as np
import pytest

from simlidar.dataset import open_sequence
from tools import cli
from tools import view_html as vh


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A 6-frame city sequence (VLP-16) and two runs over it: our bl odometry, and a straight-ahead guess."""
    from odometry.config import variant
    from simlidar.formats.kitti import write_kitti_poses
    from simlidar.sensor import load_sensor
    from tools.methods import OursMethod, run_method
    from tools.runners import RunFiles, simulate_scene, write_run_files
    from tools.worlds import build_scene_world

    root = tmp_path_factory.mktemp("view")
    simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor("vlp16"), root / "seq", 6, seed=0,
                   start_s=4.0)
    run = run_method(OursMethod("bl", variant("bl")), open_sequence(root / "seq"))
    write_run_files(RunFiles.beside(root / "bl" / "poses.txt"), run.poses, run.diagnostics, variant("bl"))
    guess = np.tile(np.eye(4), (6, 1, 1))
    guess[:, 0, 3] = 0.5 * np.arange(6)
    write_kitti_poses(root / "guess.txt", guess)
    return root


def _decode(blob: str, n: int, parts: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """What view_html.js does with a frame's blob: the int16 positions, then the uint8 fields."""
    raw = zlib.decompress(base64.b64decode(blob))
    axes = [np.cumsum(np.frombuffer(raw, "<i2", n, 2 * n * a).astype(np.int64)) for a in range(3)]
    q = ((np.column_stack(axes) + 32768) % 65536 - 32768).astype(np.int16)
    fields = [np.frombuffer(raw, np.uint8, n, 6 * n + i * n) for i in range(parts)]
    assert len(raw) == 6 * n + parts * n
    return q, fields


def test_the_page_data_holds_every_point_and_the_runs_errors(run_dir):
    from odometry.config import load_config

    seq = open_sequence(run_dir / "seq")
    config = load_config(run_dir / "bl" / "poses_config.yaml")
    data = vh.sequence_page(run_dir / "seq", {"bl": run_dir / "bl" / "poses.txt", "guess": run_dir / "guess.txt"},
                            configs={"bl": config})
    page = vh.page_json(data)
    assert page["fields"] == {"ring": True, "intensity": True, "class": True, "moving": False, "kept": True}
    for k in (0, 5):
        frame = seq[k]
        order = np.argsort(frame.ring, kind="stable")
        q, (ring, _, cls, kept) = _decode(page["blobs"][k], page["counts"][k], 4)
        assert page["counts"][k] == len(frame.points)  # every point (none beyond the int16 range)
        np.testing.assert_allclose(q * vh.QUANTUM_M, frame.points[order], atol=vh.QUANTUM_M / 2 + 1e-9)
        np.testing.assert_array_equal(ring, frame.ring[order])
        labels = seq.manifest["object_labels"]
        np.testing.assert_array_equal(np.array(page["classes"])[cls], np.array(labels)[frame.field("object_id")[order]])
        r = np.linalg.norm(frame.points[order], axis=1)
        outside = (r < config.clean.min_range_m) | (r > config.clean.max_range_m)
        assert not np.any(kept[outside] & 1) and 0.2 < np.mean(kept & 1) < 1.0  # the filters drop some, not all
    truth = np.asarray(seq.poses)
    (bl, guess) = page["tracks"]
    assert bl["weak"] is not None and guess["weak"] is None and bl["kept_bit"] == 0 and guess["kept_bit"] == -1
    np.testing.assert_allclose(guess["error"], np.linalg.norm(truth[:, :3, 3] - 0.5 * np.outer(np.arange(6),
                                                                                               [1, 0, 0]), axis=1),
                               atol=1e-6)
    assert max(bl["error"]) < 0.05 < max(guess["error"])  # ours tracks the truth; the guess does not


def test_view_html_refuses_what_it_cannot_show(run_dir, tmp_path, capsys):
    page = tmp_path / "p.html"
    (tmp_path / "short.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    cases = [(["--run", str(tmp_path / "short.txt")], "short.txt: 1 poses, the sequence has 6 frames"),
             (["--run", str(tmp_path / "missing.txt")], "no such poses file"),
             (["--frames", "4:2"], "selects no frame"),
             (["--frames", "0:6:0"], "--frames '0:6:0': the step must not be zero"),
             (["--frame", "2"], "leave out --out, --frame and --at")]
    for extra, message in cases:
        assert cli.main(["view", str(run_dir / "seq"), "--html", str(page), *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert cli.main(["view", str(run_dir / "seq"), "--run", str(run_dir / "guess.txt"), "--out", "x.png"]) == 2
    assert "--run: options of the interactive page; add --html" in capsys.readouterr().err


@pytest.mark.slow
def test_the_page_draws_the_points_in_headless_chromium(run_dir, tmp_path):
    browser.chromium()  # skipped, saying how to install it, without one
    page = tmp_path / "run.html"
    assert cli.main(["view", str(run_dir / "seq"), "--html", str(page), "--run", f"bl={run_dir / 'bl' / 'poses.txt'}",
                     "--run", f"guess={run_dir / 'guess.txt'}"]) == 0
    n3 = len(open_sequence(run_dir / "seq")[3].points)
    dom, console = browser.run(page.as_uri() + "#frame=3", tmp_path / "profile-dom", "--dump-dom")
    assert console == []  # no message at all: no error, no warning
    body = re.search(r"<body([^>]*)>", dom).group(1)
    assert 'data-status="drawn"' in body and 'data-frame="3"' in body and f'data-points="{n3}"' in body
    assert "data-errors" not in body

    def shot(fragment: str, name: str) -> np.ndarray:
        from PIL import Image

        png = tmp_path / f"{name}.png"
        _, console = browser.run(page.as_uri() + fragment, tmp_path / f"profile-{name}", f"--screenshot={png}")
        assert console == []
        pixels = np.asarray(Image.open(png).convert("RGB")).astype(int)
        return pixels[140:600]  # the 3D view, below the controls, above the legend (a 1400 x 950 window)

    def coloured(p: np.ndarray) -> np.ndarray:  # a point's pixel: saturated (the page is white, lines dark)
        return (p.max(axis=2) - p.min(axis=2)) > 60

    ring = shot("#frame=3", "ring")
    left, right = ring[:, :700], ring[:, 700:]  # ours and the guess side by side
    assert coloured(left).mean() > 0.01 and coloured(right).mean() > 0.01
    other = shot("#frame=0", "frame0")
    assert np.mean(np.any(other != ring, axis=2)) > 0.01  # another frame draws other points
    def green(p: np.ndarray) -> np.ndarray:  # kept (drawn #1a8c33, lighter where a point's edge meets white)
        return p[:, 1] - np.maximum(p[:, 0], p[:, 2]) > 25

    def red(p: np.ndarray) -> np.ndarray:  # dropped (#d93326)
        return p[:, 0] - np.maximum(p[:, 1], p[:, 2]) > 60

    kept = shot("#frame=3&colour=kept&split=0&trail=0", "kept")
    points = kept[coloured(kept)]
    assert len(points) > 2000 and np.mean(green(points) | red(points)) > 0.95
    assert green(points).sum() > 10 * red(points).sum() > 0  # our filters keep most of a city scan, not all
    by_ring = ring[coloured(ring)]
    assert np.mean(green(by_ring) | red(by_ring)) < 0.5  # coloured by ring: blues, yellows, ...


def test_the_page_is_one_file_that_needs_no_network(run_dir, tmp_path):
    page = vh.write_page(vh.sequence_page(run_dir / "seq", frames=slice(0, 2)), tmp_path / "p.html")
    text = page.read_text()
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text) and "import(" not in text
    data = json.loads(re.search(r'<script id="salo-data" type="application/json">(.*?)</script>', text,
                                re.S).group(1).replace("<\\/", "</"))
    assert data["frames"] == 2 and data["truth"] is not None and data["tracks"] == []


@pytest.mark.slow
def test_a_bench_page_shows_ours_and_a_peer_side_by_side(tmp_path, monkeypatch):
    """The bench writes a page per sequence, linked from the leaderboard; ours and KISS-ICP side by side.

    With SALO_SCREENSHOT_DIR set, the screenshot is kept there (docs/images/ holds one).
    """
    import os
    import shutil

    import yaml
    from PIL import Image

    from tools.leaderboard import run_bench
    from tools.methods import method_from_name
    from tools.peers import peer_unavailable_reason

    browser.chromium()
    why = peer_unavailable_reason("kiss-icp")
    if why:
        pytest.skip(f"kiss-icp: {why} (pip install -e '.[peer]')")
    suite = tmp_path / "tiny.yaml"
    suite.write_text(yaml.safe_dump({"name": "tiny", "scenes": ["city"], "sensors": ["vlp16"], "frames": 8,
                                     "speed_m_s": 8.0, "start_s": 4.0}))
    result = run_bench(suite, [method_from_name("default"), method_from_name("kiss-icp")], tmp_path / "bench")
    (seq,) = result.sequences
    page = result.outputs[f"view {seq.id}"]
    assert page == tmp_path / "bench" / "views" / f"{seq.id}.html"
    assert f"(views/{seq.id}.html)" in (tmp_path / "bench" / "leaderboard.md").read_text()
    assert f'href="views/{seq.id}.html"' in (tmp_path / "bench" / "leaderboard.html").read_text()
    png = tmp_path / "bench-side-by-side.png"
    _, console = browser.run(page.as_uri() + "#frame=7", tmp_path / "profile", f"--screenshot={png}")
    assert console == []
    pixels = np.asarray(Image.open(png).convert("RGB")).astype(int)[140:600]
    saturated = (pixels.max(axis=2) - pixels.min(axis=2)) > 60
    assert saturated[:, :700].mean() > 0.01 and saturated[:, 700:].mean() > 0.01  # points in both halves
    if os.environ.get("SALO_SCREENSHOT_DIR"):
        shutil.copy(png, Path(os.environ["SALO_SCREENSHOT_DIR"]) / png.name)
