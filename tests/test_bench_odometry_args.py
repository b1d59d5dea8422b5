"""The odometry benchmark's command line refuses bad input in one line, before simulating anything."""

from __future__ import annotations

import sys

import pytest

from tools import bench_odometry


@pytest.mark.parametrize(("argv", "message"), [
    (["--set", "map.bogus=1"], "'map.bogus' is unknown"),
    (["--set", "map.min_point_spacing_m=-1"], "map.min_point_spacing_m"),
    (["--methods", "kiss-icp,nope"], "unknown method(s) nope"),
    (["--memory-frames", "-1"], "--memory-frames at least 0"),
    (["--repeat", "0"], "--repeat at least 1"),
])
def test_bad_arguments_are_named(monkeypatch, capsys, argv, message):
    monkeypatch.setattr(sys, "argv", ["bench_odometry", *argv])
    monkeypatch.setattr(bench_odometry, "bench", lambda *a, **k: pytest.fail("simulated despite bad input"))
    with pytest.raises(SystemExit) as exc:
        bench_odometry.main()
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_set_changes_every_variant_of_ours(monkeypatch):
    """--set reaches the config each variant runs with (not only the default)."""
    seen = {}

    def recorder(method, view, **kwargs):  # tools.methods.run_method, as the bench calls it
        seen[method.config.name] = method.config.map.min_point_spacing_m
        raise RuntimeError("stop")

    monkeypatch.setattr(bench_odometry, "run_method", recorder)
    for name in ("salo", "salo-map"):
        with pytest.raises(RuntimeError):
            bench_odometry.run_ours(object(), name, changes={"map": {"min_point_spacing_m": 0.0}})
    assert seen == {"salo": 0.0, "salo-map": 0.0}
