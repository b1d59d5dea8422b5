"""The generalisation suite: in-memory sequences, the seed split, the sequences it draws, a tiny run."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import box_room, constant_velocity

from simlidar.dataset import open_sequence
from simlidar.in_memory import simulate_in_memory
from simlidar.sensor import load_preset
from simlidar.simulate import simulate_sequence
from tools.experiments.generalize import GeneralizeParams, run_generalize, summarize
from tools.family_suite import EVALUATION_SEEDS, KINDS, SENSORS, TUNING_SEEDS, suite, trajectory_figures


def test_in_memory_frames_are_the_written_ones(tmp_path):
    """Same simulator, seeds and poses as a sequence folder; "real" drops distortion and the fields."""
    world, traj = box_room(), constant_velocity(v=(4.0, 0.5, 0.0), yaw_rate=0.2, start=(-5.0, 0.0, 1.5))
    sensor = load_preset("vlp16")
    simulate_sequence(world, traj, sensor, tmp_path / "s", frames=3, seed=4, t_start=0.5)
    disk = open_sequence(tmp_path / "s")
    mem = simulate_in_memory(world, traj, sensor, 3, seed=4, t_start=0.5, fields="simulated")
    assert len(mem) == 3 and np.allclose(mem.poses, disk.poses) and np.allclose(mem.times, disk.times)
    for k in range(3):
        a, b = mem[k], disk[k]
        assert np.allclose(a.points, b.points, atol=1e-5)  # float32 in both
        assert np.array_equal(a.ring, b.ring) and np.allclose(a.time_s, b.time_s, atol=1e-7)
    real = simulate_in_memory(world, traj, sensor, 3, seed=4, t_start=0.5, fields="real")
    f = real[2]
    assert f.ring is None and f.time_s is None and f.fields is None
    # no motion distortion: every point lies on the box seen from the sweep-start pose
    p = f.points @ real.poses[2][:3, :3].T + real.poses[2][:3, 3]  # in the first scan's frame
    assert len(real.degeneracy) == 3 and real.degeneracy[0].points > 0
    assert not np.allclose(mem[2].points[:100], f.points[:100])
    assert np.isfinite(p).all()
    with pytest.raises(ValueError, match="fields must be one of"):
        simulate_in_memory(world, traj, sensor, 1, fields="kitti")


def test_seed_split_and_what_the_suite_draws():
    assert not set(TUNING_SEEDS) & set(EVALUATION_SEEDS)
    seqs = suite(EVALUATION_SEEDS)
    families = {s.family for s in seqs}
    assert {"city", "suburb", "canyon", "tunnel", "highway", "open", "forest"} <= families
    assert {s.sensor for s in seqs} == set(SENSORS)  # every sensor appears
    assert {s.kind for s in seqs} == set(KINDS)
    # each (family, seed) runs in both kinds with the same sensor, noise and start
    pairs = {}
    for s in seqs:
        pairs.setdefault((s.family, s.seed), set()).add((s.sensor, s.noise_std_m, s.start_s, s.kind))
    assert all(len(v) == 2 and len({x[:3] for x in v}) == 1 for v in pairs.values())
    assert all(0.01 <= s.noise_std_m <= 0.03 for s in seqs)
    assert suite(EVALUATION_SEEDS) == seqs  # deterministic
    # a subset of the families draws the same sequences as the whole suite
    subset = suite(EVALUATION_SEEDS, families=("tunnel", "forest"))
    assert subset and set(subset) == {s for s in seqs if s.family in ("tunnel", "forest")}
    with pytest.raises(ValueError, match="unknown family"):
        suite(EVALUATION_SEEDS, families=("moon",))
    with pytest.raises(ValueError, match="other split"):
        GeneralizeParams(split="evaluation", seeds=(TUNING_SEEDS[0],))
    with pytest.raises(ValueError, match="unknown method"):
        GeneralizeParams(methods=("default", "loam"))


def test_trajectory_figures_against_a_constructed_error():
    """A straight 200 m path estimated 1 % short and climbing 0.5 m per 100 m."""
    n = 201
    gt = np.tile(np.eye(4), (n, 1, 1))
    gt[:, 0, 3] = np.linspace(0, 200, n)
    est = gt.copy()
    est[:, 0, 3] *= 0.99
    est[:, 2, 3] = gt[:, 0, 3] * 0.005
    f = trajectory_figures(gt, est)
    assert f["vertical_drift_pct"] == pytest.approx(0.5, rel=1e-6)
    # (a segment ends at the first frame at least L along: up to 1 m more than L here, 2 % on 50 m)
    assert f["t_err_pct"] == pytest.approx(100 * np.hypot(0.01, 0.005), rel=0.03)
    assert not f["diverged"]
    bad = est.copy()
    bad[50:, 0, 3] = np.nan
    assert trajectory_figures(gt, bad)["diverged"]


@pytest.mark.slow
def test_a_tiny_suite_runs_and_summarises(tmp_path):
    """Two families, one seed, both kinds, 30 frames: every sequence simulates and every method runs."""
    params = GeneralizeParams(split="tuning", seeds=(TUNING_SEEDS[0],), families=("city", "canyon"),
                              methods=("bl", "bl-map"), frames=30, segment_lengths_m=(4.0,))
    results = run_generalize(params, workers=1)
    assert [r["name"] for r in results] == [s.name for s in params.sequences()]
    for r in results:
        assert not r.get("error"), r.get("error")
        for m in ("bl", "bl-map"):
            x = r["methods"][m]
            assert x["ok"] and x["poses"].shape == (30, 4, 4) and np.isfinite(x["t_err_pct"])
        # scan-to-map holds in the city and where the canyon's street enters its tunnel
        assert r["methods"]["bl-map"]["t_err_pct"] < 5.0, (r["name"], r["methods"]["bl-map"]["t_err_pct"])
    rows = summarize(results, params.methods)
    all_rows = [r for r in rows if r["family"] == "all"]
    assert {(r["kind"], r["method"]) for r in all_rows} == {(k, m) for k in KINDS for m in ("bl", "bl-map")}
    assert all(r["ran"] == 2 and r["sequences"] == 2 for r in all_rows)
