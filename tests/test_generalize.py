"""The generalisation suite: in-memory sequences, the seed split, the sequences it draws, a tiny run."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import box_room, constant_velocity

from scenes import build_scene
from scenes.families import draw_family_params
from simlidar.dataset import open_sequence
from simlidar.in_memory import simulate_in_memory
from simlidar.sensor import load_preset
from simlidar.simulate import simulate_sequence
from tools.experiments.generalize import GeneralizeParams, run_generalize, summarize
from tools.family_suite import EVALUATION_SEEDS, KINDS, SENSORS, TUNING_SEEDS, suite, suite_world, trajectory_figures


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


# The evaluation split's draws before the garage and bridge families were added (family, seed,
# sensor, noise, start): appending families must not change them.
EVALUATION_DRAWS = [
    ("city", 1, "hdl32e", 0.0102, 0.0), ("city", 2, "salo32", 0.0174, 4.19),
    ("suburb", 1, "os1-64", 0.02, 4.03), ("suburb", 2, "narrow32", 0.0169, 3.33),
    ("canyon", 1, "vlp16", 0.0177, None), ("canyon", 2, "hdl32e", 0.0108, None),
    ("tunnel", 1, "salo32", 0.0196, None), ("tunnel", 2, "os1-64", 0.0293, None),
    ("highway", 1, "narrow32", 0.0197, 8.19), ("highway", 2, "vlp16", 0.0232, 2.65),
    ("open", 1, "hdl32e", 0.0245, 9.47), ("open", 2, "salo32", 0.0244, 0.0),
    ("forest", 1, "os1-64", 0.0135, 4.08), ("forest", 2, "narrow32", 0.0222, 4.93),
]


def test_the_stacked_families_are_appended_with_the_sparse_sensors():
    drawn = [(s.family, s.seed, s.sensor, s.noise_std_m, s.start_s) for s in suite(EVALUATION_SEEDS, kinds=("real",))]
    assert drawn[:len(EVALUATION_DRAWS)] == EVALUATION_DRAWS
    for seeds in (EVALUATION_SEEDS, TUNING_SEEDS):
        for family in ("garage", "bridge"):
            seqs = suite(seeds, families=(family,), kinds=("simulated",))
            rings = [load_preset(s.sensor).rings for s in seqs]
            assert set(rings) == {16, 32}, (family, seeds, rings)  # a 16-ring and a 32-ring sensor
            assert all(s.start_s is None for s in seqs)  # placed by the path's feature


@pytest.mark.parametrize("family, features", [("garage", ("climb_s",)), ("bridge", ("under_s", "over_s"))])
def test_the_stacked_families_sequences_hold_their_feature(family, features):
    # The garage's window holds its first climb off the ground floor; the bridge's both the pass
    # under the deck and the pass over it.
    for seq in suite(EVALUATION_SEEDS + TUNING_SEEDS, families=(family,), kinds=("real",)):
        _, trajectory, sensor, start = suite_world(seq)
        scene = build_scene(family, **draw_family_params(family, seq.seed))
        end = start + seq.frames * sensor.sweep_period_s
        for key in features:
            t = float(trajectory.time_at_distance(scene.metadata[key])[0])
            assert start + 1.0 <= t <= end - 0.5, (seq.name, key, start, t, end)


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


def test_each_weather_is_read_against_its_clear_twin():
    """``twin_ratios`` pairs each sequence in a weather with the same sequence in clear air, per method."""
    from tools.experiments.generalize import twin_ratios, twin_table_markdown

    def result(family, weather, t_err, failed=False):
        seq = {"family": family, "seed": 1, "sensor": "vlp16", "kind": "real", "weather": weather}
        return {"sequence": seq, "methods": {"a": {"ok": True, "t_err_pct": t_err, "failed": failed},
                                             "b": {"ok": False, "note": "not installed"}}}

    results = [result("city", "clear", 0.10), result("city", "snow", 0.12), result("tunnel", "clear", 1.0),
               result("tunnel", "snow", 20.0, failed=True), result("city", "rain", 0.30)]
    rows = {(r["weather"], r["method"]): r for r in twin_ratios(results, ("a", "b"))}
    snow, rain = rows[("snow", "a")], rows[("rain", "a")]
    assert (snow["pairs"], snow["failures"], snow["over_bound"]) == (2, 1, 1)
    assert snow["ratio_median"] == pytest.approx((1.2 + 20.0) / 2) and snow["ratio_max"] == pytest.approx(20.0)
    assert rain["ratio_max"] == pytest.approx(3.0) and rain["over_bound"] == 1
    assert rows[("snow", "b")]["ran"] == 0
    table = twin_table_markdown(list(rows.values()), ("a", "b"))
    assert "1/2 failed" in table and "n/a" in table
    assert twin_ratios([result("city", None, 0.1)], ("a",)) == []  # no weather: no table


def test_a_stopped_run_resumes_from_what_it_finished(tmp_path, monkeypatch):
    """``resume`` reads a finished sequence back from its poses (the same figures) and runs only the rest."""
    from tools.experiments import generalize
    from tools.records import RunRecord

    params = GeneralizeParams(split="tuning", seeds=(TUNING_SEEDS[0],), families=("city",), kinds=("real",),
                              methods=("bl",), frames=30, segment_lengths_m=(4.0,))
    record = RunRecord(tmp_path, "generalize", params.to_dict()).start()
    first = run_generalize(params, record=record)
    name = first[0]["name"]
    assert (tmp_path / "poses" / name / "result.json").is_file()

    def no_run(*args, **kwargs):
        raise AssertionError("a finished sequence ran again")

    monkeypatch.setattr(generalize, "run_sequence_task", no_run)
    again = run_generalize(params, record=record, resume=True)
    before, after = first[0]["methods"]["bl"], again[0]["methods"]["bl"]
    assert np.isfinite(before["t_err_pct"]) and after["t_err_pct"] == pytest.approx(before["t_err_pct"], rel=1e-6)
    assert after["ate_aligned_m"] == pytest.approx(before["ate_aligned_m"], rel=1e-6)
    assert after["frames_per_second"] == before["frames_per_second"]
    np.testing.assert_allclose(again[0]["gt"], first[0]["gt"], atol=1e-8)
    # a run from before result.json: the figures from the poses, frames/s unknown
    (tmp_path / "poses" / name / "result.json").unlink()
    older = run_generalize(params, record=record, resume=True)[0]["methods"]["bl"]
    assert older["t_err_pct"] == pytest.approx(before["t_err_pct"], rel=1e-6) and np.isnan(older["frames_per_second"])
    # another frame count, or a method without its poses there: run again
    assert generalize.finished_result(tmp_path, params.sequences()[0], replace(params, frames=40)) is None
    assert generalize.finished_result(tmp_path, params.sequences()[0], replace(params, methods=("bl", "ncf"))) is None


def test_the_suite_with_an_imu_runs_the_default_with_and_without_it(tmp_path):
    """``imu``: every sequence carries an IMU of the grade (the lidar's frames unchanged), ``default-imu`` uses it,
    and the summary reads it against the default on the same frames."""
    from tools.experiments.generalize import IMU_METHOD, imu_against_lidar_only, odometry_config, write_generalize
    from tools.family_suite import simulate
    from tools.records import RunRecord

    with pytest.raises(ValueError, match="needs sequences with an IMU"):
        GeneralizeParams(split="tuning", methods=("default", IMU_METHOD))
    with pytest.raises(ValueError, match="unknown IMU grade"):
        GeneralizeParams(split="tuning", imu="navigation")
    assert odometry_config(IMU_METHOD, {}).imu.enabled and not odometry_config("default", {}).imu.enabled
    params = GeneralizeParams(split="tuning", seeds=(TUNING_SEEDS[0],), families=("city",), kinds=("real",),
                              methods=("default", IMU_METHOD), frames=30, segment_lengths_m=(4.0,), imu="consumer")
    (seq,) = params.sequences()
    with_imu, without = simulate(seq), simulate(replace(seq, imu=None))
    assert with_imu.imu is not None and without.imu is None and len(with_imu.imu) > 30 * 0.1 * 200
    np.testing.assert_array_equal(with_imu[7].points, without[7].points)
    results = run_generalize(params, workers=1)
    runs = results[0]["methods"]
    assert runs["default"]["ok"] and runs[IMU_METHOD]["ok"]
    # the IMU's prediction takes over after its first window (20 frames): the poses part from lidar-only's there
    assert not np.array_equal(runs["default"]["poses"], runs[IMU_METHOD]["poses"])
    np.testing.assert_array_equal(runs["default"]["poses"][:20], runs[IMU_METHOD]["poses"][:20])
    (row,) = [r for r in imu_against_lidar_only(results) if r["kind"] == "real"]
    assert row["sequences"] == 1 and row["ratio_max"] == pytest.approx(
        runs[IMU_METHOD]["t_err_pct"] / runs["default"]["t_err_pct"])
    record = RunRecord(tmp_path, "generalize", params.to_dict()).start()
    write_generalize(results, params, record)
    assert "The default with the IMU (consumer grade) against lidar only" in (tmp_path / "summary.md").read_text()
