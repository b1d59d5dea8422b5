"""``salo demo`` at a few frames: what it prints and the files it writes."""

from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.mark.slow
def test_demo_prints_the_table_and_writes_the_plots(tmp_path, capsys):
    from matplotlib.image import imread

    from tools.demo import DEMO_METHODS, run_demo

    out = tmp_path / "demo"
    content = run_demo(out, frames=6, progress=False)
    printed = capsys.readouterr().out
    assert "| method | end error, m |" in printed
    for label in ("BL", "NCF", "SALO"):
        assert f"| {label} |" in printed
    assert "too short for the paper's 100 m segments" in printed
    for name in ("scan_preview.png", "trajectory.png", "position_error.png"):
        img = imread(out / name)
        assert img.shape[0] > 400 and img.shape[1] > 400, name
    for name in ("table.md", "summary.md", "results.json", "run.json", "poses/gt.txt"):
        assert (out / name).is_file(), name
    rows = {r["method"]: r for r in content["rows"]}
    assert set(rows) == {m.upper() for m in DEMO_METHODS}
    for r in rows.values():
        # Six frames, a few metres: the error is centimetres to decimetres, never metres.
        assert 0 <= r["end_error_m"] < 0.5 and np.isfinite(r["ate_rmse_m"]) and r["segments_100m"] == 0
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["experiment"] == "demo"
    # Run again: the simulated sequence is reused, not simulated anew.
    folders = sorted((out / "sequences").iterdir())
    run_demo(out, frames=6, progress=False)
    assert sorted((out / "sequences").iterdir()) == folders
