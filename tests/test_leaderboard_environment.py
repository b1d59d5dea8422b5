"""The leaderboard's per-environment figures (tools.leaderboard.environment) on trajectories whose errors are known.

A straight 100 m path, one frame a metre: an estimate 1 % too long has a 1 % error over
every window (over the window's nominal length, as KITTI's); an estimate that slips
sideways by 1 cm a frame inside a weak stretch whose weakest direction is sideways has
1 % of error along it there, and none along a direction it did not slip in.
"""

from __future__ import annotations

import numpy as np
import pytest

from odometry.diagnostics import DegenerateStretch
from tools.leaderboard.environment import environment_figures, weak_direction_error, windowed_error_pct
from tools.leaderboard.page import family_rows, table_markdown


def _line(x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
    poses = np.tile(np.eye(4), (len(x), 1, 1))
    poses[:, 0, 3] = x
    if y is not None:
        poses[:, 1, 3] = y
    return poses


GT = _line(np.arange(101.0))


def test_windowed_error_of_an_estimate_one_percent_too_long():
    est = _line(1.01 * np.arange(101.0))
    # As KITTI's: a window ends at the first frame past its length (11 m, 51 m here), over the nominal length.
    assert windowed_error_pct(GT, est, 10.0) == pytest.approx(1.0 * 11 / 10, abs=1e-9)
    assert windowed_error_pct(GT, est, 50.0) == pytest.approx(1.0 * 51 / 50, abs=1e-9)
    assert windowed_error_pct(GT, est, 200.0) is None  # no window that long on a 100 m path
    est[70] = np.nan
    assert windowed_error_pct(GT, est, 10.0) is None  # diverged: no figure


def test_error_along_the_weakest_direction_over_the_weak_stretch():
    k = np.arange(101)
    est = _line(k.astype(float), 0.01 * np.clip(k - 39, 0, 21))  # 1 cm a frame sideways in frames 40..60
    sideways = DegenerateStretch(40, 60, np.array([0.0, 1.0, 0.0]), 1e-4, 0)
    forward = DegenerateStretch(40, 60, np.array([1.0, 0.0, 0.0]), 1e-4, 0)
    pct, span = weak_direction_error(GT, est, [sideways])
    assert span == pytest.approx(21.0) and pct == pytest.approx(100 * 0.21 / 21.0, rel=1e-6)
    assert weak_direction_error(GT, est, [forward])[0] == pytest.approx(0.0, abs=1e-9)
    assert weak_direction_error(GT, GT, [sideways])[0] == pytest.approx(0.0, abs=1e-12)
    assert weak_direction_error(GT, est, [])[0] is None  # no weak stretch in the truth: n/a
    figures = environment_figures(GT, est, None)
    assert "weak_dir_err_pct" not in figures and figures["rel_10m_pct"] > 0


def test_the_table_gives_the_success_rate_and_the_new_columns():
    class M:
        def __init__(self, name):
            self.name, self.label = name, name

    ok = {"t_err_pct": 1.0, "rel_10m_pct": 2.0, "rel_50m_pct": 1.5, "weak_dir_err_pct": 0.5, "failed": False}
    results = [{"method": "a", "status": "ok", "figures": ok, "frames_per_second": 10.0},
               {"method": "a", "status": "failed", "figures": {}, "frames_per_second": None},
               {"method": "b", "status": "ok", "figures": {**ok, "weak_dir_err_pct": None}, "frames_per_second": 5}]
    text = table_markdown(family_rows(results, [M("a"), M("b")]))
    header = text.splitlines()[0]
    assert "10 m window %" in header and "50 m window %" in header and "weak-direction err %" in header
    assert header.index("t_err %") < header.index("10 m window %") < header.index("r_err")
    rows = {line.split(" | ")[1]: line for line in text.splitlines()[2:]}
    assert "100 % (1/1)" in rows["b"] and "50 % (1/2)" in rows["a"]
    assert "n/a" in rows["b"]  # no weak stretch figure for b
