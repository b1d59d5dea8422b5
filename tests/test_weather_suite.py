"""The weather suite: conditions drawn over the generalisation suite's sequences, each with its clear twin;
it simulates, and ``salo bench --suite weather`` lays it out a table per condition."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from simlidar.in_memory import simulate_in_memory
from simlidar.weather import FOG, KINDS
from tools.family_suite import EVALUATION_SEEDS, suite, suite_world, weather_suite
from tools.weather_conditions import CONDITIONS, DRAWS, draw


def test_the_weather_suite_draws_every_condition_beside_its_clear_twin():
    seqs = weather_suite(EVALUATION_SEEDS)
    base = suite(EVALUATION_SEEDS, kinds=("simulated",))
    assert len(seqs) == len(CONDITIONS) * len(base) and len({s.name for s in seqs}) == len(seqs)
    twins = {}
    for s in seqs:
        twins.setdefault(replace(s, weather=None), set()).add(s.weather)
    assert set(twins) == set(base) and all(v == set(CONDITIONS) for v in twins.values())
    assert weather_suite(EVALUATION_SEEDS) == seqs  # deterministic
    subset = weather_suite(EVALUATION_SEEDS, families=("tunnel",), conditions=("dense-fog",))
    assert subset == [s for s in seqs if s.family == "tunnel" and s.weather == "dense-fog"]
    for s in seqs:
        keys = draw(s.weather, s.family, s.seed)
        if s.weather == "clear":
            assert keys == {}
            continue
        section, key, lo, hi = DRAWS[s.weather]
        assert keys[section]["enabled"] and lo <= keys[section][key] <= hi
    assert draw("rain", "city", 1) != draw("rain", "city", 2)
    with pytest.raises(ValueError, match="unknown weather condition 'hail'"):
        weather_suite(EVALUATION_SEEDS, conditions=("hail",))


def test_each_condition_simulates_its_weather_on_the_twins_path():
    seqs = weather_suite((EVALUATION_SEEDS[0],), frames=2, families=("tunnel",))
    got = {}
    for s in seqs:
        world, trajectory, sensor, start = suite_world(s)
        assert sensor.receiver.enabled and sensor.weather.on == (s.weather != "clear")
        mem = simulate_in_memory(world, trajectory, sensor, 2, seed=s.seed, t_start=start, fields="truth")
        got[s.weather] = (mem, sensor)
    poses = got["clear"][0].poses
    for condition, (mem, _) in got.items():
        np.testing.assert_array_equal(mem.poses, poses)  # the twin's path, frames and start
        names = mem.fields[0].dtype.names
        assert ("weather" in names) == (condition != "clear")
    kinds = {c: np.bincount(np.concatenate([f["weather"] for f in m.fields]), minlength=len(KINDS))
             for c, (m, _) in got.items() if c != "clear"}
    assert kinds["dense-fog"][FOG] > kinds["light-fog"][FOG] > 0
    assert kinds["snow"][KINDS.index("snow")] > 0
    assert kinds["rain"][FOG] == kinds["snow"][FOG] == 0
    # dense fog leaves the fewest surface returns
    surface = {c: int(k[0]) for c, k in kinds.items()}
    assert surface["dense-fog"] == min(surface.values())


@pytest.mark.slow
def test_bench_over_the_weather_suite_groups_by_condition(tmp_path):
    from tools.leaderboard.suites import bench_sequences

    seqs = bench_sequences("weather", tmp_path, frames=2, families=("tunnel",))
    assert sorted({s.family for s in seqs}) == sorted(CONDITIONS)
    for s in seqs:
        manifest = json.loads((s.path / "manifest.json").read_text())
        assert manifest["format_version"] == (2 if s.family == "clear" else 3)
        assert manifest["suite_sequence"]["weather"] == s.family
