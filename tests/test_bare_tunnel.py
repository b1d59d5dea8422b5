"""The bare tunnel: bare walls for hundreds of metres with a stop on them, flagged by the simulator's own truth."""

from __future__ import annotations

import numpy as np
import pytest

import scenes
from simlidar.sensor import load_preset
from tools.degenerate import TRUTH_THRESHOLD, truth_constraints
from tools.runners import simulate_scene
from tools.worlds import build_scene_world


@pytest.fixture(scope="module")
def built():
    return build_scene_world("bare-tunnel", 0, {})


def test_the_bare_stretch_holds_the_whole_speed_change(built):
    meta = built.info["scene_metadata"]
    traj = built.trajectory
    (b0, b1), stop = meta["bare_s"], meta["stop_s"]
    assert b1 - b0 == pytest.approx(400.0) and b0 < stop < b1 and meta["fittings"] == 2
    # braking from cruise to the stop, 5 s standing, accelerating back to cruise: all between bare walls
    t = np.arange(0.0, traj.duration_s, 0.05)
    s, v = traj.distance_at(t), traj.speed_at(t)
    changing = (s > meta["portal_s"][0]) & (s < meta["portal_s"][1]) & (v < 15.0 - 1e-6)
    assert b0 < s[changing].min() and s[changing].max() < b1
    standing = t[(v < 1e-9) & (s > b0) & (s < b1)]
    assert standing.max() - standing.min() == pytest.approx(5.0 - 1.0, abs=0.06)  # the wait less the smoothing
    # the tunnel with the same parameters but no bare stretch and no stop: the same world outside the stretch
    plain = scenes.build_scene("tunnel", length_m=600.0)
    assert plain.metadata["fittings"] == 7 and "bare_s" not in plain.metadata


def test_the_simulators_degeneracy_truth_flags_the_bare_stretch(built, tmp_path):
    sensor = load_preset("salo32")
    traj = built.trajectory
    meta = built.info["scene_metadata"]
    on_bare = float(traj.time_at_distance(np.array([meta["stop_s"] - 60.0]))[0])  # braking, between bare walls
    for start, weak in ((2.0, False), (on_bare, True)):
        out = simulate_scene(built, sensor, tmp_path / f"seq{start:.0f}", 20, seed=0, start_s=start).path
        truth = truth_constraints(out)  # the sequence's degeneracy.csv, read as salo simulate reads it
        assert np.all(truth.weak == weak), (start, truth.t_eig0)
        if weak:  # the weak direction is the tunnel's axis (x: the lidar looks along it)
            assert np.all(np.abs(truth.directions[:, 0]) > 0.99) and truth.t_eig0.max() < TRUTH_THRESHOLD / 10
